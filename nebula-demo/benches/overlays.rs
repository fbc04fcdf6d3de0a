//! What the looks cost per frame, in one run on the same settled view (the
//! small planet from 2.6 radii, 640×400), each drawn and waited for:
//! - `terrain_only`: the frame over a `--background` (no sky, sea or haze);
//! - `terrain_and_sky`: the same frame with the sky pass (sky, sea, haze);
//! - `hud`: the HUD's seven lines drawn over it, alone;
//! - `empty_submit`: an empty command buffer and the wait, the floor the
//!   others stand on.
//!
//! And the Earth 2.5 km over a mountain range (the README's picture), where
//! the sky pass also shades the relief: `earth_terrain_only`,
//! `earth_terrain_and_sky`.
//!
//! Run: `cargo bench -p nebula-demo`. Without a GPU adapter it says so and
//! measures nothing.

use criterion::{Criterion, criterion_group, criterion_main};
use nebula_demo::app::PlanetApp;
use nebula_demo::headless::{Shot, render_app, shot_view};
use nebula_demo::hud::Hud;
use nebula_math::DVec3;
use nebula_render::DebugView;
use nebula_render::context::GpuContext;
use nebula_render::readback::Offscreen;
use nebula_voxel::{PlanetSettings, ProceduralPlanet};

const SIZE: (u32, u32) = (640, 400);

fn wait(app: &PlanetApp) {
    let _ = app.gpu().device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None });
}

fn overlays(c: &mut Criterion) {
    let gpu = match GpuContext::headless() {
        Ok(gpu) => gpu,
        Err(error) => {
            eprintln!("SKIPPED: no GPU adapter ({error}); nothing measured");
            return;
        }
    };
    let settings = PlanetSettings::small(7);
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let eye = DVec3::new(0.35, 0.55, 0.76).normalize() * settings.radius * 2.6;
    let shot = Shot { background: None, ..Shot::looking_at(eye, DVec3::ZERO, SIZE) };
    let (mut app, target) = settled(planet, gpu, &shot);
    let mut hud = Hud::new(app.gpu(), SIZE, app.gpu().color_format).expect("HUD");
    hud.set_text(
        "16.4 ms/frame\n5266 chunks, 948367 triangles\n0 meshing jobs\nLOD 3 to 18\naltitude 4200 m, 0 m/s\n\
         PosX 123 456 789 at 12.3 m\nplaces stone (M), H hides this"
            .to_owned(),
    );
    let mut group = c.benchmark_group("overlays_640x400");
    group.sample_size(20);
    terrain_with_and_without_sky(&mut group, "", &mut app, &target);
    group.bench_function("hud", |b| {
        b.iter(|| {
            hud.draw(app.gpu(), &target.view).expect("HUD drawn");
            wait(&app);
        });
    });
    group.bench_function("empty_submit", |b| {
        b.iter(|| {
            let encoder = app.gpu().device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            app.gpu().queue.submit([encoder.finish()]);
            wait(&app);
        });
    });
    group.finish();

    // The Earth over a mountain range: haze and relief shading at work.
    let settings = PlanetSettings::earth(11);
    let planet = ProceduralPlanet::new(settings).expect("valid planet");
    let eye = DVec3::new(-2_853_425.89, 5_698_159.83, -144_616.37);
    let look = DVec3::new(-2_921_362.76, 5_660_036.65, -77_821.85);
    let shot = Shot { background: None, sun: Some((30.0, -70.0)), ..Shot::looking_at(eye, look, SIZE) };
    let (mut app, target) = settled(planet, GpuContext::headless().expect("adapter, as above"), &shot);
    let mut group = c.benchmark_group("overlays_640x400");
    group.sample_size(20);
    terrain_with_and_without_sky(&mut group, "earth_", &mut app, &target);
    group.finish();
}

/// `planet` settled for `shot`, and a target to draw it into again.
fn settled(planet: ProceduralPlanet, gpu: GpuContext, shot: &Shot) -> (PlanetApp, Offscreen) {
    let mut app = PlanetApp::new(planet, shot.lod_settings(), gpu, shot_view(shot).expect("view")).expect("app");
    render_app(&mut app, shot).expect("settles");
    let target = Offscreen::new(app.gpu(), SIZE).expect("target");
    (app, target)
}

/// `{prefix}terrain_only` (over a background: no sky pass) and
/// `{prefix}terrain_and_sky`.
fn terrain_with_and_without_sky(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    prefix: &str,
    app: &mut PlanetApp,
    target: &Offscreen,
) {
    for (name, background) in [("terrain_only", Some([0, 0, 0])), ("terrain_and_sky", None)] {
        group.bench_function(format!("{prefix}{name}"), |b| {
            b.iter(|| {
                app.draw(&target.view, SIZE, background, DebugView::Shaded);
                wait(app);
            });
        });
    }
}

criterion_group!(benches, overlays);
criterion_main!(benches);
