//! Headless renders through the demo's wgpu renderer (Mesa's lavapipe on a
//! machine with no GPU) over a sentinel background, checked by the crack
//! oracle (`nebula_render::crack`): a background pixel is a crack if its ray
//! meets the sphere of the lowest ground under the chunks drawn, or hits a
//! triangle that frame drew.
//!
//! Settled views of the small planet; random poses and flights on an
//! Earth-sized planet, every frame checked while meshing streams; the
//! finest LOD drawn unmorphed; edits shown live with no hole in any frame;
//! and the controls that show each check can
//! fail (skirts off, the first version's morph rule, a blank frame).
//!
//! With no adapter at all these tests print a loud SKIPPED line and pass,
//! unless `NEBULA_REQUIRE_ADAPTER=1` (as in CI), where they fail.

use nebula_demo::app::{DrawOptions, MorphRule, OpaqueSea, PlanetApp};
use nebula_demo::flight::{Flight, FlightReport, Keyframe, fly};
use nebula_demo::headless::{
    Picture, Shot, draw_frame, prepare_shot, render_app, report_json, seen_chunks, settle_and_draw, shot_view,
    write_png,
};
use nebula_render::DebugView;
use nebula_render::context::GpuContext;

use nebula_math::DVec3;
use nebula_voxel::{PlanetSettings, ProceduralPlanet, VoxelSource};
use nebula_world::seams::SeamStrategy;

const SENTINEL: [u8; 3] = [255, 0, 255];
const SIZE: (u32, u32) = (640, 400);

fn adapter_or_skip(test: &str) -> bool {
    match GpuContext::headless() {
        Ok(_) => true,
        Err(error) => {
            if std::env::var("NEBULA_REQUIRE_ADAPTER").is_ok_and(|v| v == "1") {
                panic!("{test}: NEBULA_REQUIRE_ADAPTER=1 but {error}");
            }
            eprintln!("SKIPPED: no GPU adapter — apt-get install mesa-vulkan-drivers ({test}: {error})");
            false
        }
    }
}

fn small() -> PlanetSettings {
    PlanetSettings::scaled(7, 2_000.0, 1.5)
}

fn earth() -> PlanetSettings {
    PlanetSettings::scaled(11, 6_371_000.0, 1.0)
}

fn ground(settings: &PlanetSettings, dir: DVec3) -> DVec3 {
    ProceduralPlanet::new(settings.clone()).expect("valid planet").surface_point(dir)
}

fn shot(position: DVec3, look_at: DVec3, fov: f64) -> Shot {
    Shot { fov_y_degrees: fov, background: Some(SENTINEL), ..Shot::looking_at(position, look_at, SIZE) }
}

fn app(settings: &PlanetSettings, shot: &Shot, options: DrawOptions) -> PlanetApp {
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let mut app = PlanetApp::new(
        planet,
        shot.lod_settings(),
        GpuContext::headless().expect("adapter"),
        shot_view(shot).expect("view"),
    )
    .expect("app");
    app.set_draw_options(options);
    app
}

fn folder() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("nebula-render-tests")
}

/// Renders a settled view, saves the PNG and report, and returns it.
fn settled(name: &str, settings: &PlanetSettings, shot: &Shot, options: DrawOptions) -> Picture {
    let mut app = app(settings, shot, options);
    let picture = render_app(&mut app, shot).expect("renders");
    write_png(&folder().join(format!("{name}.png")), &picture.rgba, picture.size).expect("png written");
    let report = report_json(&picture.figures, &picture.adapter);
    println!("{name}: {report}");
    // The report carries the figures a user compares views by.
    let pixels = f64::from(picture.size.0) * f64::from(picture.size.1);
    let per_pixel = report["triangles_per_pixel"].as_f64().expect("triangles per pixel");
    assert!((per_pixel - picture.figures.frame.triangles as f64 / pixels).abs() < 1e-9, "{report}");
    if cfg!(target_os = "linux") {
        assert!(report["peak_rss_bytes"].as_u64().is_some_and(|bytes| bytes > 1 << 20), "{report}");
    }
    picture
}

/// A settled view with no crack pixels, the planet filling what it must and
/// skirts a small share of the triangles drawn.
fn check(name: &str, settings: &PlanetSettings, shot: &Shot, min_planet_fraction: f64) -> Picture {
    let picture = settled(name, settings, shot, DrawOptions::default());
    let figures = &picture.figures;
    let pixels = f64::from(shot.size.0 * shot.size.1);
    assert_eq!(figures.crack_pixels, Some(0), "{name}: crack pixels at {:?}", figures.cracks.samples);
    assert!(figures.planet_pixels as f64 >= min_planet_fraction * pixels, "{name}: planet covers too little");
    let f = &figures.frame;
    let share = f.skirt_triangles as f64 / f.triangles as f64;
    println!("{name}: skirts are {:.1} % of the triangles drawn", 100.0 * share);
    // Seed 000 aims at 5 %; a view straight down over many LOD rings of a
    // small planet draws about 11 % (whole chunk sides are lowered).
    assert!(share <= 0.15, "{name}: skirts {:.1} % of the triangles", 100.0 * share);
    picture
}

/// Flies `flight` (every frame checked), saves its frames' report, and
/// asserts every frame is crack-free.
fn check_flight(name: &str, settings: &PlanetSettings, flight: &Flight, fps: f64) -> FlightReport {
    check_flight_in_budget(
        name,
        settings,
        flight,
        fps,
        nebula_demo::app::MeshCache::<nebula_render::GpuMesh>::default_max_bytes(),
        SeamStrategy::Skirts,
    )
    .0
}

/// [`check_flight`] with the mesh cache held to `max_bytes` and seams
/// closed by `seams`.
fn check_flight_in_budget(
    name: &str,
    settings: &PlanetSettings,
    flight: &Flight,
    fps: f64,
    max_bytes: u64,
    seams: SeamStrategy,
) -> (FlightReport, PlanetApp) {
    let first = flight.pose(0.0);
    let template = Shot { up: first.up, ..shot(first.pos, first.look_at, 60.0) };
    let mut app = app(settings, &template, DrawOptions::default());
    app.streamer_mut().0.cache.max_bytes = max_bytes;
    app.streamer_mut().0.set_seam_strategy(seams);
    let dir = folder().join(name);
    let report = fly(&mut app, flight, &template, fps, Some(&dir)).expect("flies");
    std::fs::write(dir.join("report.json"), serde_json::to_string_pretty(&report.json()).expect("json"))
        .expect("report written");
    let worst = report.worst_frame().map(|(i, f)| (i, f.figures.crack_pixels, f.figures.cracks.samples.clone()));
    let stand_ins: usize = report.frames.iter().map(|f| f.figures.frame.stand_ins).max().unwrap_or(0);
    println!(
        "{name}: {} frames, first frame after {:.0} ms, worst {:?}, most stand-ins in a frame {stand_ins}, frames in {}",
        report.frames.len(),
        report.first_frame_ms,
        worst,
        dir.display()
    );
    for (k, frame) in report.frames.iter().enumerate() {
        assert_eq!(
            frame.figures.crack_pixels,
            Some(0),
            "{name}: frame {k} (t = {:.2} s) has cracks at {:?}",
            frame.time_s,
            frame.figures.cracks.samples
        );
        assert!(frame.figures.planet_pixels > 0, "{name}: frame {k} checks nothing");
    }
    (report, app)
}

/// A camera `altitude` m above the ground in direction `dir`, looking
/// `pitch` degrees below the horizon towards `heading` (a tangent).
fn pose(settings: &PlanetSettings, dir: DVec3, altitude: f64, heading: DVec3, pitch: f64) -> (DVec3, DVec3) {
    let up = dir.normalize();
    let heading = (heading - up * heading.dot(up)).normalize();
    let eye = ground(settings, up) + up * altitude;
    let p = pitch.to_radians();
    (eye, eye + (heading * p.cos() - up * p.sin()) * 100.0)
}

/// A small deterministic generator (tests must not depend on luck).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.next()
    }
}

#[test]
fn small_planet_settled_views_have_no_cracks() {
    if !adapter_or_skip("small planet views") {
        return;
    }
    let settings = small();
    check("orbit", &settings, &shot(DVec3::new(2_500.0, 3_200.0, 3_600.0), DVec3::ZERO, 60.0), 0.15);
    // Along a cube edge, 20 m up, 12° field of view, grazing.
    let edge = DVec3::new(1.0, 1.0, 0.0).normalize();
    let eye = ground(&settings, edge) + edge * 20.0;
    let target = ground(&settings, (edge + DVec3::Z * 0.0175).normalize());
    check("grazing-edge", &settings, &shot(eye, target, 12.0), 0.3);
    // Straight down from 150 m over land (a place from a fixed seed).
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let dir = place_with_ground(&planet, &mut Rng(0x5D), 10.0..100.0);
    let eye = ground(&settings, dir) + dir * 150.0;
    check("straight-down", &settings, &shot(eye, DVec3::ZERO, 60.0), 0.99);
}

/// A 20 km planet (LODs 0..=9), 800 m over a cube corner, looking at the
/// horizon: near blocks and far hills, many LOD seams in one picture.
fn low_over_a_corner() -> (PlanetSettings, Shot) {
    let settings = PlanetSettings::scaled(7, 20_000.0, 1.5);
    let corner = DVec3::ONE.normalize();
    let eye = corner * (20_000.0 + 800.0);
    let target = (corner + DVec3::new(0.25, -0.1, -0.1)).normalize() * 20_000.0;
    (settings, shot(eye, target, 60.0))
}

#[test]
fn low_over_a_cube_corner_spans_many_lods() {
    if !adapter_or_skip("corner") {
        return;
    }
    let (settings, view) = low_over_a_corner();
    let picture = check("low-corner", &settings, &view, 0.1);
    let lods = picture.figures.frame.lod_histogram.iter().filter(|n| **n > 0).count();
    assert!(lods >= 4, "LOD spread {lods} < 4: {:?}", picture.figures.frame.lod_histogram);
}

#[test]
fn earth_random_poses_near_the_ground_have_no_cracks_while_streaming() {
    if !adapter_or_skip("earth poses") {
        return;
    }
    // Random spots, cube edges and cube corners of an Earth-sized planet,
    // 3–300 m up, from grazing to steeply down. Each pose is held for a
    // half second of real time with meshing streaming, every frame checked.
    let settings = earth();
    let mut rng = Rng(0x00c0_ffee_1234_5678);
    for n in 0..4 {
        let base = match n % 3 {
            0 => DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
            1 => DVec3::new(1.0, 1.0, rng.range(-0.9, 0.9)),
            _ => DVec3::new(1.0, -1.0, 1.0),
        };
        // Within a few hundred metres of the edge or corner, either side.
        let jitter = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * 4e-5;
        let dir = (base.normalize() + jitter).normalize();
        let altitude = 3.0 * 100f64.powf(rng.next());
        let pitch = rng.range(-2.0, 75.0);
        let heading = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let (eye, look_at) = pose(&settings, dir, altitude, heading, pitch);
        let hold = |t| Keyframe { t, pos: eye, look_at, up: None };
        let flight = Flight::from_keyframes(vec![hold(0.0), hold(0.5)]).expect("flight");
        println!("pose {n}: {altitude:.0} m up, {pitch:.0}° down, at {dir:?}");
        check_flight(&format!("earth-pose-{n}"), &settings, &flight, 6.0);
    }
}

/// Keyframes every `step` seconds along a great circle from `start`
/// towards `heading` at `speed` m/s, `altitude` m over the ground, looking
/// ahead and `pitch` degrees down.
fn ground_flight(
    settings: &PlanetSettings,
    start: DVec3,
    heading: DVec3,
    speed: f64,
    altitude: f64,
    pitch: f64,
    seconds: f64,
) -> Flight {
    let radius = settings.radius;
    let up = start.normalize();
    let heading = (heading - up * heading.dot(up)).normalize();
    let mut keys = Vec::new();
    let steps = (seconds / 0.25).ceil() as usize;
    for k in 0..=steps {
        let t = k as f64 * 0.25;
        let angle = speed * t / radius;
        let dir = up * angle.cos() + heading * angle.sin();
        let ahead = (heading * angle.cos() - up * angle.sin()).normalize();
        let (pos, look_at) = pose(settings, dir, altitude, ahead, pitch);
        keys.push(Keyframe { t, pos, look_at, up: None });
    }
    Flight::from_keyframes(keys).expect("flight")
}

#[test]
fn earth_flight_across_a_cube_edge_at_300_m_s_is_crack_free_in_every_frame() {
    if !adapter_or_skip("earth edge flight") {
        return;
    }
    // 600 m before the edge between +X and +Y, 80 m up, across it and on.
    let settings = earth();
    let edge = DVec3::new(1.0, 1.0, 0.3).normalize();
    let across = DVec3::new(-1.0, 1.0, 0.0);
    let start = (edge - across.normalize() * (600.0 / settings.radius)).normalize();
    let flight = ground_flight(&settings, start, across, 300.0, 80.0, 20.0, 3.0);
    let report = check_flight("earth-edge-flight", &settings, &flight, 8.0);
    // The frames checked are those of trees made ahead on the LOD thread
    // (a cull with a margin around a predicted camera), bar two: the first
    // step off the still start (made ahead for a still camera) and the one
    // after it (a step from standing still is taken for a jump, after
    // which the camera is expected to stay). The count includes the still
    // frames the streamer settles in before the flight.
    let (ahead, missed) = report.lod_thread_frames;
    let frames = report.frames.len() as u64;
    println!("earth-edge-flight: {ahead} updates made ahead for {frames} frames, {missed} missed");
    assert!(ahead + 2 >= frames && missed <= 2, "{ahead} updates made ahead for {frames} frames, {missed} missed");
}

#[test]
fn earth_fast_low_flights_are_crack_free_and_stay_in_the_mesh_budget() {
    if !adapter_or_skip("earth fast low flights") {
        return;
    }
    // Random flights from a fixed seed: 15–150 m over the ground at
    // 600–3,000 m/s, any heading, 10–50° down, the whole flight checked
    // frame by frame, with a mesh budget small enough (64 MiB) that the
    // cache must free meshes while streaming cannot keep up: held to it,
    // still complete.
    let settings = earth();
    let mut state = 0xf1_1e5_u64;
    let mut unit = move || nebula_math::unit_random(&mut state);
    let budget = 64 << 20;
    let mut fullest = 0;
    let mut last = None;
    for n in 0..3 {
        let start = DVec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5).normalize();
        let heading = start.any_orthonormal_vector().lerp(start.cross(DVec3::Y), unit());
        let (altitude, speed, pitch) = (15.0 + unit() * 135.0, 600.0 + unit() * 2_400.0, 10.0 + unit() * 40.0);
        let flight = ground_flight(&settings, start, heading, speed, altitude, pitch, 2.0);
        let name = format!("earth-fast-flight-{n}");
        let (report, app) = check_flight_in_budget(&name, &settings, &flight, 8.0, budget, SeamStrategy::Skirts);
        let held = report.frames.iter().map(|f| f.figures.frame.held_bytes).max().unwrap_or(0);
        println!("{name}: {altitude:.0} m up at {speed:.0} m/s, {pitch:.0} deg down: meshes held <= {} MB", held >> 20);
        assert!(held <= budget + budget / 10, "{name}: {held} bytes of meshes held, budget {budget}");
        fullest = fullest.max(held);
        last = Some(app);
    }
    // A loaded machine meshes less in the flights themselves: then the
    // last one stands still at its end, streaming and prefetching, until
    // the cache is half its budget, every step still held to it and whole.
    let mut app = last.expect("three flights");
    let standing = std::time::Instant::now();
    while fullest <= budget / 2 && standing.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(20));
        app.step();
        app.submit_uploads();
        let held = app.streamer().cache.held_bytes();
        assert!(held <= budget + budget / 10, "standing still: {held} bytes of meshes held, budget {budget}");
        assert_eq!(app.draw_list().holes, 0, "standing still: a hole");
        fullest = fullest.max(held);
    }
    assert!(fullest > budget / 2, "the budget was never approached ({fullest} bytes): the check cannot tell");
}

#[test]
fn every_seam_strategy_is_crack_free_in_every_frame_and_stitches_need_no_skirt() {
    if !adapter_or_skip("seam strategies") {
        return;
    }
    // The meshes of `constrained` and `stitched` depend on the LODs drawn
    // around them: every frame of these, seams waiting to be meshed again
    // included (closed by fallback skirts meanwhile), is checked. Poses from
    // a fixed seed (a spot, near a cube edge, near a cube corner; 5-200 m up),
    // each held 1 s while streaming, then settled and checked again with
    // skirts and with none (the control: with none, skirted and
    // constrained seams open where the LODs differ, stitched ones stay
    // closed); and a 300 m/s flight over a cube edge.
    let settings = earth();
    let mut rng = Rng(0x5ea_5eed);
    let bases = [
        DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)),
        DVec3::new(-1.0, 1.0, rng.range(-0.9, 0.9)),
        DVec3::new(1.0, 1.0, -1.0),
    ];
    let budget = nebula_demo::app::MeshCache::<nebula_render::GpuMesh>::default_max_bytes();
    let mut open_without_skirts = 0;
    for (n, base) in bases.iter().enumerate() {
        let jitter = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * 4e-5;
        let dir = (base.normalize() + jitter).normalize();
        let altitude = 5.0 * 40f64.powf(rng.next());
        let heading = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let (eye, look_at) = pose(&settings, dir, altitude, heading, rng.range(0.0, 40.0));
        let hold = |t| Keyframe { t, pos: eye, look_at, up: None };
        let flight = Flight::from_keyframes(vec![hold(0.0), hold(1.0)]).expect("flight");
        for seams in SeamStrategy::ALL {
            let name = format!("earth-{seams}-pose-{n}");
            let (report, mut app) = check_flight_in_budget(&name, &settings, &flight, 6.0, budget, seams);
            let waited = report.frames.iter().map(|f| f.figures.frame.unsettled).max().unwrap_or(0);
            let view = shot(eye, look_at, 60.0);
            let settled = render_app(&mut app, &view).expect("renders");
            let f = &settled.figures.frame;
            println!(
                "{name}: at most {waited} columns waiting for their seams in a frame; settled: {} chunks, {} \
                 triangles, {} skirt triangles, LOD difference across a side up to {}",
                f.chunks, f.triangles, f.skirt_triangles, f.max_drawn_lod_diff
            );
            assert_eq!(
                settled.figures.crack_pixels,
                Some(0),
                "{name}: settled, cracks at {:?}",
                settled.figures.cracks.samples
            );
            assert_eq!(f.unsettled, 0, "{name}: seams still waiting once settled");
            app.set_draw_options(DrawOptions { skirts: false, ..DrawOptions::default() });
            let bare = render_app(&mut app, &view).expect("renders");
            let cracks = bare.figures.crack_pixels.expect("checked");
            println!("{name}: without skirts, {cracks} crack pixels");
            match seams {
                SeamStrategy::Stitched => {
                    assert_eq!(f.skirt_triangles, 0, "{name}: a settled stitched view drew skirts");
                    assert_eq!(cracks, 0, "{name}: stitches alone leave cracks at {:?}", bare.figures.cracks.samples);
                }
                _ => open_without_skirts += cracks,
            }
        }
    }
    assert!(open_without_skirts > 0, "seams without skirts never opened: the control cannot tell");
    let edge = DVec3::new(1.0, 0.3, -1.0).normalize();
    let across = DVec3::new(1.0, 0.0, 1.0);
    let start = (edge - across.normalize() * (400.0 / settings.radius)).normalize();
    let edge_flight = ground_flight(&settings, start, across, 300.0, 60.0, 15.0, 2.0);
    for seams in [SeamStrategy::Constrained, SeamStrategy::Stitched] {
        check_flight_in_budget(&format!("earth-{seams}-edge-flight"), &settings, &edge_flight, 8.0, budget, seams);
    }
}

#[test]
fn small_planet_low_sideways_flight_is_crack_free_in_every_frame() {
    if !adapter_or_skip("small flight") {
        return;
    }
    // The first version's failure: 30 m over the ground looking down,
    // flying sideways at about 190 m/s.
    let settings = small();
    let start = DVec3::new(0.35, 0.55, 0.76).normalize();
    let flight = ground_flight(&settings, start, DVec3::Z, 190.0, 30.0, 60.0, 3.0);
    check_flight("small-sideways-flight", &settings, &flight, 8.0);
}

/// Share of the pixels in the lower third of a morph-view image (the
/// ground next to the camera) drawn unmorphed (red over blue).
fn unmorphed_share(picture: &Picture) -> f64 {
    let (w, h) = picture.size;
    let mut red = 0;
    let mut total = 0;
    for y in (2 * h / 3)..h {
        for x in 0..w {
            let i = ((y * w + x) * 4) as usize;
            let p = &picture.rgba[i..i + 3];
            if p == SENTINEL {
                continue;
            }
            total += 1;
            red += usize::from(p[0] > p[2]);
        }
    }
    red as f64 / total.max(1) as f64
}

#[test]
fn lod_0_ground_next_to_the_camera_is_drawn_unmorphed() {
    if !adapter_or_skip("unmorphed ground") {
        return;
    }
    // Earth, 25 m over the ground looking 50° down, in the morph view
    // (red = μ 1, the voxels as they are; blue = μ 0). With the first
    // version's rule (μ from the chunk's own error, 0 at LOD 0) the same
    // ground is all blue: the control that shows the check can fail.
    let settings = earth();
    let (eye, look_at) = pose(&settings, DVec3::new(0.2, -0.6, 0.7), 25.0, DVec3::X, 50.0);
    let morph_view = Shot { view: DebugView::Morph, ..shot(eye, look_at, 60.0) };
    let exact = settled("unmorphed-ground", &settings, &morph_view, DrawOptions::default());
    let share = unmorphed_share(&exact);
    let old_rule = DrawOptions { morph: MorphRule::Own, ..DrawOptions::default() };
    let old = settled("unmorphed-ground-old-rule", &settings, &morph_view, old_rule);
    let old_share = unmorphed_share(&old);
    println!("ground next to the camera drawn unmorphed: {share:.4} (first version's rule: {old_share:.4})");
    assert!(share > 0.999, "LOD 0 next to the camera is morphed: {share}");
    assert!(old_share < 0.01, "the control does not show the old defect: {old_share}");
    assert_eq!(exact.figures.crack_pixels, Some(0));
}

#[test]
fn the_crack_check_sees_drawn_geometry_missing_from_a_frame() {
    if !adapter_or_skip("negative controls") {
        return;
    }
    // Skirts off on a 20 km planet seen low over a corner, many LOD seams
    // in view. Reported, not asserted: with far-corner LOD sampling a
    // coarser LOD lies below the finer one, so from the camera (always on
    // the finer side) the open slits face away and show no background; the
    // CPU oracle's seams-off control (`seams.rs`) casts from other places
    // and does see them.
    let (settings, view) = low_over_a_corner();
    let off = settled("skirts-off", &settings, &view, DrawOptions { skirts: false, ..DrawOptions::default() });
    println!("skirts off: {:?} crack pixels ({:?})", off.figures.crack_pixels, off.figures.cracks);

    // The geometry rule alone: the same drawn meshes checked against a
    // frame where nothing was drawn. Pixels over the horizon of the
    // sentinel sphere (the far hills) can only be caught by casting rays
    // at the drawn triangles.
    let mut app = app(&settings, &view, DrawOptions::default());
    let on = render_app(&mut app, &view).expect("renders");
    assert_eq!(on.figures.crack_pixels, Some(0));
    let blank = [SENTINEL[0], SENTINEL[1], SENTINEL[2], 255].repeat((SIZE.0 * SIZE.1) as usize);
    let camera = shot_view(&view).expect("view").camera;
    let count =
        nebula_render::crack::count_cracks(&blank, SIZE, SENTINEL, &camera, view.fov_y_degrees, &app.drawn_geometry());
    println!("blank frame: {count:?}");
    assert!(count.geometry_cracks > 0, "the geometry rule must see drawn terrain above the sentinel sphere");
    let covered = on.rgba.chunks_exact(4).filter(|p| p[..3] != SENTINEL).count();
    assert!(count.cracks <= covered + 16, "a blank frame has more cracks than the real frame drew pixels");
}

/// The mesh arena packs meshes into a page until it is full, opens a new
/// page then, hands freed space (a dropped slot) to the next mesh, never
/// lets two live meshes overlap, and keeps a mesh's indices right after
/// its vertices in one range, whatever their proportion, as u16 where the
/// mesh has at most 65,536 vertices, and its skirt edges right after its
/// indices (one word per edge with u16 indices, two with u32).
#[test]
fn the_mesh_arena_reuses_freed_space_and_opens_pages_when_full() {
    use nebula_meshing::RenderVertex;
    use nebula_render::arena::{MeshArena, PAGE_UNITS};
    if !adapter_or_skip("arena") {
        return;
    }
    let gpu = GpuContext::headless().expect("adapter");
    let arena = MeshArena::default();
    let vertex = RenderVertex {
        position_high: [0.0; 3],
        offset: Default::default(),
        target_low: Default::default(),
        normal: [0; 2],
        packed: 0,
    };
    // One unit (a vertex's size) holds the three indices: a quarter page.
    let quarter = vec![vertex; PAGE_UNITS as usize / 4 - 1];
    let write_with_edges = |vertices, indices: &[u32], edges: &[[u32; 2]]| {
        arena.upload(
            &gpu.device,
            &mut |target, offset, bytes| gpu.queue.write_buffer(target, offset, bytes),
            vertices,
            indices,
            edges,
        )
    };
    let write = |vertices, indices: &[u32]| write_with_edges(vertices, indices, &[]);
    let upload = || write(&quarter, &[0, 1, 2]).expect("uploaded");
    assert!(write(&[], &[]).is_none(), "an empty mesh takes no space");
    let mut slots: Vec<_> = (0..4).map(|_| upload()).collect();
    assert!(slots.iter().all(|s| s.page == 0), "four quarters fill the first page");
    let mut starts: Vec<u32> = slots.iter().map(|s| s.first_vertex()).collect();
    starts.sort_unstable();
    assert!(starts.windows(2).all(|w| w[1] - w[0] >= PAGE_UNITS / 4), "overlap: {starts:?}");
    let index_bytes = |slot: &nebula_render::arena::Slot| u64::from(slot.first_index()) * 4;
    let vertex_bytes = |slot: &nebula_render::arena::Slot| u64::from(slot.first_vertex()) * unit_bytes();
    assert!(
        slots.iter().all(|s| index_bytes(s) == vertex_bytes(s) + quarter.len() as u64 * unit_bytes()),
        "a mesh's indices start right after its vertices"
    );
    let fifth = upload();
    assert_eq!(fifth.page, 1, "a full page opens a new one");
    let freed = slots.remove(2).first_vertex();
    let again = upload();
    assert_eq!((again.page, again.first_vertex()), (0, freed), "freed space is reused");
    assert_eq!(arena.lock().capacity_bytes(), 2 * u64::from(PAGE_UNITS) * unit_bytes());
    assert!(slots.iter().all(|s| s.index_format() == wgpu::IndexFormat::Uint32), "more than 65,536 vertices");
    // Mostly indices: a mesh of 4 vertices (u16 indices) and a page's worth
    // of indices less its vertices fits one page (pages with a fixed vertex
    // part and index part filled one part first).
    let indices = vec![0_u32; (PAGE_UNITS as usize - 4) * (unit_bytes() as usize / 2)];
    drop((slots, fifth, again));
    let index_heavy = write(&quarter[..4], &indices).expect("uploaded");
    assert_eq!(index_heavy.index_format(), wgpu::IndexFormat::Uint16);
    assert_eq!(u64::from(index_heavy.first_index()) * 2, vertex_bytes(&index_heavy) + 4 * unit_bytes());
    assert_eq!((index_heavy.page, arena.lock().capacity_bytes()), (0, 2 * u64::from(PAGE_UNITS) * unit_bytes()));
    assert_eq!(index_heavy.bytes(), u64::from(PAGE_UNITS) * unit_bytes());
    // Skirt edges after the indices (padded to a word): 4 vertices, 3 u16
    // indices (2 words) and 5 one-word edges take 5 units; with u32
    // indices (a mesh past 65,536 vertices) each edge takes two words.
    let edges = [[0, 1]; 5];
    let skirted = write_with_edges(&quarter[..4], &[0, 1, 2], &edges).expect("uploaded");
    assert_eq!(u64::from(skirted.first_edge_word()) * 4, u64::from(skirted.first_index()) * 2 + 8);
    assert_eq!(skirted.bytes(), 5 * unit_bytes());
    let wide = vec![vertex; (1 << 16) + 1];
    let wide_skirted = write_with_edges(&wide, &[0, 1, 2], &edges).expect("uploaded");
    assert_eq!(wide_skirted.index_format(), wgpu::IndexFormat::Uint32);
    assert_eq!(u64::from(wide_skirted.first_edge_word()) * 4, u64::from(wide_skirted.first_index()) * 4 + 12);
    // 65,539 units rounded up to the allocator's size class (4 significant
    // bits): 9 × 2^13.
    assert_eq!(wide_skirted.bytes(), 9 * (1 << 13) * unit_bytes());
    // A range freed by a mesh of an odd size is reused by the next mesh of
    // that size: ranges are whole size classes (the allocator files a free
    // range under the class its size rounds down to and serves a mesh from
    // the class its size rounds up to).
    let fresh = MeshArena::default();
    let write_fresh = |vertices| {
        fresh
            .upload(
                &gpu.device,
                &mut |target, offset, bytes| gpu.queue.write_buffer(target, offset, bytes),
                vertices,
                &[0, 1, 2],
                &[],
            )
            .expect("uploaded")
    };
    let odd = vec![vertex; 1000];
    let first = write_fresh(&odd);
    // Keeps the first range from merging with the free space after it.
    let _after = write_fresh(&odd);
    assert_eq!(first.bytes(), 1024 * unit_bytes(), "1,001 units rounded up to their class");
    let at = (first.page, first.first_vertex());
    drop(first);
    let same = write_fresh(&odd);
    assert_eq!((same.page, same.first_vertex()), at, "a freed range fits the next mesh of its size");
}

fn unit_bytes() -> u64 {
    size_of::<nebula_meshing::RenderVertex>() as u64
}

/// Steps and draws `app` from `shot`, crack-checking every frame, until
/// the view settles (after an edit, say). Returns the settled picture and
/// the frames it took.
fn settle_checking_every_frame(app: &mut PlanetApp, shot: &Shot, what: &str) -> (Picture, usize) {
    let view = shot_view(shot).expect("view");
    let mut frames = 0;
    loop {
        app.step();
        frames += 1;
        let picture = draw_frame(app, shot, &view).expect("draws");
        assert_eq!(
            picture.figures.crack_pixels,
            Some(0),
            "frame {frames} after {what} has cracks at {:?}",
            picture.figures.cracks.samples
        );
        if app.settled() {
            return (picture, frames);
        }
        assert!(frames < 600, "{what} did not settle in 600 frames");
    }
}

#[test]
fn live_edits_show_within_frames_and_no_frame_has_a_hole() {
    use nebula_voxel::Voxel;
    use nebula_world::{Edit, World};
    if !adapter_or_skip("live edits") {
        return;
    }
    // A settled view 40 m over the small planet; then a crater is dug and a
    // block wall built where the camera looks. Every frame after the edit
    // is drawn and crack-checked until the view settles again, and the
    // settled picture must be the one a fresh start on the edited world
    // draws (and differ from the one before the edit).
    let settings = small();
    let up = DVec3::new(-0.4, 0.7, 0.6).normalize();
    let ahead = (up.any_orthonormal_vector() * 40.0 / settings.radius + up).normalize();
    let target = ground(&settings, ahead);
    let eye = ground(&settings, up) + up * 40.0;
    let shot = shot(eye, target, 60.0);
    let mut world = World::open(settings.clone(), None).expect("planet");
    let new_app = |world: &World| {
        PlanetApp::with_voxels(
            world.voxels(),
            shot.lod_settings(),
            GpuContext::headless().expect("adapter"),
            shot_view(&shot).expect("view"),
        )
        .expect("app")
    };
    let mut app = new_app(&world);
    let before = render_app(&mut app, &shot).expect("renders");
    assert_eq!(before.figures.crack_pixels, Some(0));

    let size = world.source().base().voxel_size();
    let wall = target + (target - eye).normalize() * 12.0;
    let applied = world
        .apply(&[
            Edit::Sphere { center: target, radius: 6.0 * size, voxel: Voxel::AIR },
            Edit::Box {
                min: wall - DVec3::splat(3.0 * size),
                max: wall + DVec3::splat(3.0 * size),
                voxel: Voxel::SNOW,
            },
        ])
        .expect("edits");
    app.set_voxels(world.voxels(), &applied.dirty).expect("shown");
    let stale_at_start = app.stale_chunks();
    let (after, frames) = settle_checking_every_frame(&mut app, &shot, "the edit");
    write_png(&folder().join("live-edit.png"), &after.rgba, after.size).expect("png written");
    let changed = changed_pixels(&before.rgba, &after.rgba);
    println!(
        "live edit: {} dirty chunks, {} drawn ones kept until re-meshed, settled after {frames} frames, {changed} pixels changed",
        applied.dirty.len(),
        stale_at_start
    );
    assert!(changed > 2_000, "the edit barely shows: {changed} pixels changed");
    let fresh = render_app(&mut new_app(&world), &shot).expect("renders");
    let differ = changed_pixels(&fresh.rgba, &after.rgba);
    assert!(differ == 0, "the live-edited view differs from a fresh start on the edited world in {differ} pixels");
}

/// The top voxels of LOD-0 chunk sides drawn against a coarser chunk (a
/// skirt lowered), half a cell inside the side's middle, that the eye sees,
/// nearest first.
fn visible_lod0_seams(app: &PlanetApp, world: &nebula_world::World, eye: DVec3) -> Vec<nebula_voxel::VoxelHit> {
    use nebula_math::FaceDirection;
    let sphere = *world.source().layout().sphere();
    let base = world.source().base();
    let mut seams: Vec<nebula_voxel::VoxelHit> = app
        .draw_list()
        .columns
        .iter()
        .filter(|(column, _)| column.lod == 0)
        .flat_map(|(column, draw)| {
            let (x0, y0) = (f64::from(column.x) * 32.0, f64::from(column.y) * 32.0);
            FaceDirection::HORIZONTAL.iter().zip(draw.skirt_depths).filter(|(_, depth)| *depth > 0.0).map(
                move |(&side, _)| {
                    let (i, j) = match side {
                        FaceDirection::PosX => (x0 + 31.5, y0 + 16.5),
                        FaceDirection::NegX => (x0 + 0.5, y0 + 16.5),
                        FaceDirection::PosZ => (x0 + 16.5, y0 + 31.5),
                        _ => (x0 + 16.5, y0 + 0.5),
                    };
                    sphere.direction(column.face, i, j)
                },
            )
        })
        .filter_map(|direction| {
            let above = base.surface_point(direction) + direction * 20.0;
            let top = world.pick(above, -direction, 100.0).ok()??;
            let seen = world.pick(eye, top.point - eye, 1e5).ok()??;
            ((seen.point - top.point).length() < 0.01).then_some(top)
        })
        .collect();
    seams.sort_by(|a, b| (a.point - eye).length().total_cmp(&(b.point - eye).length()));
    seams
}

#[test]
fn a_shaft_dug_against_a_lod_seam_opens_no_hole() {
    use nebula_voxel::{Voxel, VoxelCoord};
    use nebula_world::{Edit, World};
    if !adapter_or_skip("shaft at a seam") {
        return;
    }
    // Low over the small planet, at the nearest place on screen where a
    // LOD-0 chunk is drawn against a coarser one, a one-voxel shaft six
    // voxels deep is dug right against that seam (the
    // skirts and bounds there must follow the edit). Every frame after the
    // edit and the settled view must be crack-free, and the shaft must
    // show. τ = 6 px brings the LOD-0 ring close enough that the shaft is
    // a few pixels wide.
    let settings = small();
    let up = DVec3::new(0.2, 0.9, -0.4).normalize();
    let eye = ground(&settings, up) + up * 25.0;
    let mut world = World::open(settings.clone(), None).expect("planet");
    let app_for = |world: &World, shot: &Shot| {
        PlanetApp::with_voxels(
            world.voxels(),
            shot.lod_settings(),
            GpuContext::headless().expect("adapter"),
            shot_view(shot).expect("view"),
        )
        .expect("app")
    };
    // Headings around the compass; the one whose nearest such seam on
    // screen is nearest.
    let (north, east) = (up.any_orthonormal_vector(), up.cross(up.any_orthonormal_vector()));
    let found = (0..8).filter_map(|k| {
        let heading = f64::from(k) * std::f64::consts::FRAC_PI_4;
        let ahead = (up + (north * heading.cos() + east * heading.sin()) * 60.0 / settings.radius).normalize();
        let shot = Shot { sse_px: 6.0, ..shot(eye, ground(&settings, ahead), 60.0) };
        let mut app = app_for(&world, &shot);
        let before = render_app(&mut app, &shot).expect("renders");
        let (forward, right, screen_up) = nebula_math::view_basis(shot.look_at - eye, eye.normalize());
        let (tan_v, tan_h) = (30f64.to_radians().tan(), 30f64.to_radians().tan() * 1.6);
        let on_screen = |p: DVec3| {
            let v = p - eye;
            let z = v.dot(forward);
            z > 0.0 && (v.dot(right) / z).abs() < 0.95 * tan_h && (v.dot(screen_up) / z).abs() < 0.95 * tan_v
        };
        let seam = visible_lod0_seams(&app, &world, eye).into_iter().find(|s| on_screen(s.point))?;
        Some((shot, app, before, seam))
    });
    let (shot, mut app, before, seam) = found
        .min_by(|a, b| (a.3.point - eye).length().total_cmp(&(b.3.point - eye).length()))
        .expect("no heading shows a LOD-0 side against a coarser chunk");
    assert_eq!(before.figures.crack_pixels, Some(0));
    let shaft: Vec<Edit> = (0..6)
        .map(|k| Edit::Voxel { at: VoxelCoord { h: seam.voxel.h - k, ..seam.voxel }, voxel: Voxel::AIR })
        .collect();
    let applied = world.apply(&shaft).expect("shaft dug");
    assert_eq!(world.edit_count(), 6, "the shaft removed {} voxels", world.edit_count());
    app.set_voxels(world.voxels(), &applied.dirty).expect("shown");
    let stale = app.stale_chunks();
    assert!(stale > 0, "no drawn chunk waits for the shaft's mesh");
    let (after, frames) = settle_checking_every_frame(&mut app, &shot, "the shaft");
    write_png(&folder().join("seam-shaft.png"), &after.rgba, after.size).expect("png written");
    // At a seam the LOD-0 chunk is nearly morphed into its parent, where a
    // one-voxel shaft shows only if it is a coarse voxel's far corner: it
    // may show as a few pixels or not at all, as the coarser LOD draws it.
    let changed = changed_pixels(&before.rgba, &after.rgba);
    println!(
        "seam shaft: 6 voxels dug {:.0} m away at a LOD-0 side against a coarser chunk, {stale} drawn chunks re-meshed, settled after {frames} frames, {changed} pixels changed",
        (seam.point - eye).length()
    );
    assert_eq!(app.stale_chunks(), 0);
}

/// Earth 1 km up looking 5° down, so the top rows are sky: the view of the
/// sky tests. Planet settings, eye, point looked at.
fn sky_view() -> (PlanetSettings, DVec3, DVec3) {
    let settings = earth();
    let dir = DVec3::new(0.3, 0.8, -0.5).normalize();
    let (eye, look) = pose(&settings, dir, 1_000.0, dir.cross(DVec3::Z), 5.0);
    (settings, eye, look)
}

/// The sky, sea and haze are drawn only without a background: with one
/// (as every crack check here sets), the sky is the clear colour exactly;
/// without, it is a blue sky, not the clear colour. (Earth, 1 km up,
/// looking 5° down: the top rows are sky.)
#[test]
fn the_sky_is_drawn_only_without_a_background() {
    if !adapter_or_skip("sky") {
        return;
    }
    let (settings, eye, look) = sky_view();
    let with_background = settled("sky-off", &settings, &shot(eye, look, 60.0), DrawOptions::default());
    let plain = Shot { background: None, ..shot(eye, look, 60.0) };
    let with_sky = settled("sky-on", &settings, &plain, DrawOptions::default());
    let (width, _) = SIZE;
    let top_row = |picture: &Picture| -> Vec<[u8; 3]> {
        (0..width as usize).map(|x| [0, 1, 2].map(|c| picture.rgba[x * 4 + c])).collect()
    };
    assert!(top_row(&with_background).iter().all(|p| *p == SENTINEL), "something drawn over the background");
    let sky = top_row(&with_sky);
    assert!(sky.iter().all(|p| *p != nebula_demo::app::SPACE && p[2] > p[0] + 40), "no blue sky: {:?}", &sky[..4]);
    println!("sky at the top: {:?}", sky[width as usize / 2]);
}

/// The sun placed over a view (`Shot::sun`) lights the sky: low on the
/// horizon it turns the sky above the horizon towards orange, high it is
/// blue. (Same Earth view as above, the sun off to the side.)
#[test]
fn a_low_sun_turns_the_sky_orange() {
    if !adapter_or_skip("sun") {
        return;
    }
    let (settings, eye, look) = sky_view();
    let (width, height) = SIZE;
    // Mean red minus blue over the top quarter of the picture (sky).
    let warmth = |elevation: f64| -> f64 {
        let shot = Shot { background: None, sun: Some((elevation, 120.0)), ..shot(eye, look, 60.0) };
        let picture = settled(&format!("sun-{elevation}"), &settings, &shot, DrawOptions::default());
        let rows = (height / 4) as usize;
        let pixels = (0..rows).flat_map(|y| (0..width as usize).map(move |x| (y * width as usize + x) * 4));
        let sum: f64 = pixels.map(|i| f64::from(picture.rgba[i]) - f64::from(picture.rgba[i + 2])).sum();
        sum / (rows * width as usize) as f64
    };
    let (low, high) = (warmth(2.0), warmth(60.0));
    println!("sky red − blue: sun at 2°: {low:.1}, at 60°: {high:.1}");
    assert!(high < -40.0, "a high sun should give a blue sky: {high:.1}");
    assert!(low > high + 30.0, "a low sun should warm the sky: {low:.1} vs {high:.1}");
}

/// Leaving out the side walls that look away from the eye
/// (`DrawOptions::cull_back_sides`; only those wide enough on screen that
/// rounding cannot turn them) changes no pixel and draws fewer
/// triangles: they are back faces of a closed surface, which the
/// rasteriser culls when drawn. Earth, 300 m over the ground looking 20°
/// down, and the small planet from orbit.
#[test]
fn culled_back_sides_change_no_pixel() {
    if !adapter_or_skip("back sides") {
        return;
    }
    let earth = earth();
    let dir = DVec3::new(-0.4, 0.7, 0.6).normalize();
    let (eye, look) = pose(&earth, dir, 300.0, dir.cross(DVec3::Y), 20.0);
    let small = PlanetSettings::small(7);
    let orbit = DVec3::new(0.35, 0.55, 0.76).normalize() * small.radius * 2.6;
    for (name, settings, view) in
        [("earth", &earth, shot(eye, look, 60.0)), ("small", &small, shot(orbit, DVec3::ZERO, 60.0))]
    {
        let all = DrawOptions { cull_back_sides: false, ..DrawOptions::default() };
        let with_all = settled(&format!("sides-all-{name}"), settings, &view, all);
        let culled = settled(&format!("sides-culled-{name}"), settings, &view, DrawOptions::default());
        let (before, after) = (with_all.figures.frame.triangles, culled.figures.frame.triangles);
        println!("{name}: {before} triangles with every side, {after} with the back sides left out");
        assert!(with_all.rgba == culled.rgba, "{name}: culling changed the picture");
        assert_eq!(culled.figures.crack_pixels, Some(0), "{name}");
        assert!((after as f64) < 0.97 * before as f64, "{name}: culling saved too little to tell: {before} → {after}");
    }
}

/// Leaving out what the ground in front hides
/// (`DrawOptions::terrain_occlusion`, the occlusion of
/// `nebula_lod::TerrainHorizon`; settled, nothing is drawn for it) changes
/// no pixel, with the background showing through every crack: random
/// Earth poses over land (fixed seed), two through a 12° lens a few
/// degrees down (where the far ground sinks behind the near) and one with
/// 60°; together they draw fewer triangles with it than without. The check
/// can fail: ground left out where it shows bares the background.
#[test]
fn the_ground_hides_only_what_changes_no_pixel() {
    if !adapter_or_skip("terrain occlusion") {
        return;
    }
    let settings = earth();
    let (mut with, mut without) = (0, 0);
    for (n, view) in views_over_land(&settings, 0x0cc1_0de5_0f1a_0d00).into_iter().enumerate() {
        let off = DrawOptions { terrain_occlusion: false, ..DrawOptions::default() };
        let all = settled(&format!("occlusion-off-{n}"), &settings, &view, off);
        let hidden = settled(&format!("occlusion-on-{n}"), &settings, &view, DrawOptions::default());
        let (before, after) = (all.figures.frame.triangles, hidden.figures.frame.triangles);
        println!("pose {n}: {before} triangles drawing everything, {after} with the hidden ground left out");
        assert_eq!(changed_pixels(&all.rgba, &hidden.rgba), 0, "pose {n}: the hidden ground showed");
        assert_eq!(hidden.figures.crack_pixels, Some(0), "pose {n}");
        (with, without) = (with + after, without + before);
    }
    assert!((with as f64) < 0.97 * without as f64, "the hidden ground saved too little to tell: {without} → {with}");
}

/// The chunk-number view (`DebugView::Ids`) covers exactly the pixels the
/// shaded view covers over the background, and names only chunks that are
/// drawn: low over a cube corner (many LODs), several chunks at several
/// LODs show, never more at a LOD than are drawn there. An id view that
/// drew one number everywhere, or lit colours, or left out chunks, fails.
#[test]
fn the_chunks_a_view_shows_are_counted_among_those_drawn() {
    if !adapter_or_skip("seen chunks") {
        return;
    }
    let (settings, shot) = low_over_a_corner();
    let mut app = app(&settings, &shot, DrawOptions::default());
    let picture = render_app(&mut app, &shot).expect("renders");
    let seen = seen_chunks(&mut app, &shot).expect("reads back");
    let frame = &picture.figures.frame;
    println!(
        "{} of {} drawn chunks show: {:?} of {:?} by LOD",
        seen.chunks, frame.chunks, seen.by_lod, frame.lod_histogram
    );
    let covered = picture.rgba.chunks_exact(4).filter(|pixel| pixel[..3] != SENTINEL).count();
    assert_eq!(seen.pixels, covered as u64, "the same pixels covered");
    assert_eq!(seen.by_lod.iter().sum::<usize>(), seen.chunks);
    assert!(seen.chunks > 10 && seen.chunks <= frame.chunks, "{} of {}", seen.chunks, frame.chunks);
    for (lod, &shown) in seen.by_lod.iter().enumerate() {
        assert!(shown <= frame.lod_histogram.get(lod).copied().unwrap_or(0), "LOD {lod}: {shown} shown");
    }
    assert!(seen.by_lod.iter().filter(|&&shown| shown > 0).count() >= 3, "{:?}", seen.by_lod);
}

/// Occlusion culling on the GPU (`PlanetRenderer::set_occlusion_culling`,
/// two phases against a depth pyramid) changes no pixel: random Earth
/// poses over land (fixed seed), two through a 12° lens a few degrees down
/// and one at 60°, each settled once and drawn with culling and without,
/// over the background (every crack shows) and shaded with sky and sea,
/// one sample per pixel and four; together they rasterise fewer triangles
/// than their lists hold. The check can fail: boxes shrunk to a quarter of
/// their size leave out chunks that show.
#[test]
fn occlusion_culling_changes_no_pixel() {
    if !adapter_or_skip("occlusion culling") {
        return;
    }
    let settings = earth();
    let (mut rasterised, mut listed, mut wrong) = (0, 0, 0);
    for (n, bare) in views_over_land(&settings, 0xc011_0c0d_e5ee_0001).into_iter().enumerate() {
        let mut app = app(&settings, &bare, DrawOptions::default());
        // Culling is on by default only where a GPU draws (lavapipe draws
        // no faster with it); on wherever draws are indirect when asked.
        let on_a_gpu = !nebula_render::context::is_cpu(&app.gpu().adapter);
        assert_eq!(app.renderer().occlusion_culling(), on_a_gpu, "culling by default where a GPU draws");
        assert!(app.renderer_mut().set_occlusion_culling(true), "culling can be on where draws are indirect");
        let view = prepare_shot(&mut app, &bare).expect("a view");
        let culled = settle_and_draw(&mut app, &bare, &view).expect("drawn");
        let figures = culled.figures.culling.expect("a culled frame has figures");
        let shaded = Shot { background: None, ..bare.clone() };
        let draw = |app: &mut PlanetApp, shot: &Shot, culling: bool, multisampling: bool| {
            app.renderer_mut().set_occlusion_culling(culling);
            app.renderer_mut().set_multisampling(multisampling);
            draw_frame(app, shot, &view).expect("drawn")
        };
        let all = draw(&mut app, &bare, false, false);
        assert!(all.figures.culling.is_none(), "pose {n}: a frame drawn whole has no culling figures");
        assert_eq!(changed_pixels(&all.rgba, &culled.rgba), 0, "pose {n}: culling changed the picture");
        assert_eq!(culled.figures.crack_pixels, Some(0), "pose {n}");
        for multisampling in [false, true] {
            let (with, without) =
                (draw(&mut app, &shaded, true, multisampling), draw(&mut app, &shaded, false, multisampling));
            let changed = changed_pixels(&with.rgba, &without.rgba);
            assert_eq!(changed, 0, "pose {n}, shaded, multisampling {multisampling}: culling changed the picture");
        }
        app.renderer_mut().scale_cull_boxes_for_tests(0.25);
        wrong += changed_pixels(&all.rgba, &draw(&mut app, &bare, true, false).rgba);
        println!(
            "pose {n}: {} of {} triangles rasterised ({} in the first phase), {} draws of {}",
            figures.triangles(),
            figures.listed_triangles,
            figures.first_phase_triangles,
            figures.draws[0] + figures.draws[1],
            figures.listed_draws
        );
        assert!(figures.triangles() <= figures.listed_triangles, "pose {n}: {figures:?}");
        (rasterised, listed) = (rasterised + figures.triangles(), listed + figures.listed_triangles);
    }
    assert!((rasterised as f64) < 0.9 * listed as f64, "culling saved too little to tell: {listed} → {rasterised}");
    println!("boxes a quarter of their size change {wrong} pixels");
    assert!(wrong > 100, "shrunk boxes should leave out chunks that show: {wrong} pixels changed");
}

/// Random Earth views over land (the generator seeded with `seed`): two
/// through a 12° lens a few degrees down, 300–800 m and 50–200 m up (where
/// the far ground sinks behind the near), and one at 60°, 30–300 m up.
fn views_over_land(settings: &PlanetSettings, seed: u64) -> Vec<Shot> {
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let mut rng = Rng(seed);
    [(12.0, (300.0, 800.0), (1.0, 4.0)), (60.0, (30.0, 300.0), (0.0, 10.0)), (12.0, (50.0, 200.0), (0.0, 2.0))]
        .into_iter()
        .map(|(fov, altitude, pitch)| {
            let dir = place_with_ground(&planet, &mut rng, 5.0..800.0);
            let heading = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let (eye, look) =
                pose(settings, dir, rng.range(altitude.0, altitude.1), heading, rng.range(pitch.0, pitch.1));
            shot(eye, look, fov)
        })
        .collect()
}

/// How many pixels of two same-sized RGBA pictures differ.
fn changed_pixels(a: &[u8], b: &[u8]) -> usize {
    a.chunks(4).zip(b.chunks(4)).filter(|(a, b)| a != b).count()
}

/// A random direction (away from the poles) whose ground height lies in
/// `heights`, metres.
fn place_with_ground(planet: &ProceduralPlanet, rng: &mut Rng, heights: std::ops::Range<f64>) -> DVec3 {
    loop {
        let dir = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-0.6, 0.6)).normalize();
        if heights.contains(&planet.height_at(dir)) {
            return dir;
        }
    }
}

/// Settles `shot` (no background: sky and sea drawn) with the streamer told
/// `sea` (`None`: no sea, every leaf in detail), whatever the shot would
/// choose, and draws it.
fn settled_with_sea(
    name: &str,
    settings: &PlanetSettings,
    shot: &Shot,
    sea: Option<OpaqueSea>,
    multisampling: bool,
) -> Picture {
    let mut app = app(settings, shot, DrawOptions::default());
    app.renderer_mut().set_multisampling(multisampling);
    let view = prepare_shot(&mut app, shot).expect("a view");
    app.streamer_mut().0.set_opaque_sea(sea);
    let picture = settle_and_draw(&mut app, shot, &view).expect("drawn");
    write_png(&folder().join(format!("{name}.png")), &picture.rgba, picture.size).expect("png written");
    println!("{name}: {}", report_json(&picture.figures, &picture.adapter));
    picture
}

/// Drawing the sea bed the sea hides as coarse stand-ins (`OpaqueSea`)
/// changes no pixel: over the deep sea 4 km up (where it draws far fewer
/// triangles), and 150 m over shallow water off a coast (a place from a fixed seed
/// where the sea bed is 3–12 m down, so it shows through the water, and
/// over 60 m down 20 or 40 km ahead, within the terrain's horizon: the
/// Earth's shelves slope gently, about 100 m down 80 km out). And
/// the check can fail: the same stand-ins with no sea drawn over them
/// change the deep view. With one sample per pixel, and with four up to
/// one pixel in 10,000. Where the edge of the drawn sea bed crosses a pixel
/// (ground behind the horizon is left out, the sea drawn over nothing
/// there), some of its samples see sea bed or nothing depending on which
/// sea bed is drawn; the sky pass reads such a pixel as sea either way
/// (the sea mask's share among the samples drawn), and the hidden sea
/// bed's own colour is one deep-water colour whichever is drawn, so a
/// partly covered pixel comes out the same. Lavapipe changes 0 pixels; an
/// H100 changed 3 of 256,000 before the sky pass read the mask so, and
/// lavapipe 37 once hidden ground was left out.
#[test]
fn the_sea_hides_only_what_changes_no_pixel() {
    if !adapter_or_skip("sea") {
        return;
    }
    let settings = earth();
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let radius = settings.radius;
    let opaque = OpaqueSea { radius, hiding_depth: nebula_render::sea_hiding_depth(radius) };
    let mut rng = Rng(0x5EA);
    // Shallow water with deep water ahead in the view: sea bed the sea
    // hides within the terrain's horizon, near sea bed that shows.
    let deep_ahead = |dir: DVec3| {
        let heading = dir.cross(DVec3::Z).normalize();
        [20_000.0, 40_000.0].iter().any(|d| planet.height_at((dir + heading * (d / radius)).normalize()) < -60.0)
    };
    let shallow = (0..2_000)
        .map(|_| place_with_ground(&planet, &mut rng, -12.0..-3.0))
        .find(|&dir| deep_ahead(dir))
        .expect("shallow water with deep water ahead");
    let deep = place_with_ground(&planet, &mut rng, -1200.0..-400.0);
    let poses = [("deep", deep, 4_200.0, 3.0), ("shallow", shallow, 150.0, 25.0)];
    for ((name, dir, altitude, pitch), multisampling) in poses.into_iter().flat_map(|p| [(p, false), (p, true)]) {
        let (eye, look) = pose(&settings, dir, altitude, dir.cross(DVec3::Z), pitch);
        let shot = Shot { background: None, sun: Some((50.0, 30.0)), ..shot(eye, look, 60.0) };
        let samples = if multisampling { 4 } else { 1 };
        let detailed =
            settled_with_sea(&format!("sea-{name}-{samples}-detailed"), &settings, &shot, None, multisampling);
        let coarse =
            settled_with_sea(&format!("sea-{name}-{samples}-coarse"), &settings, &shot, Some(opaque), multisampling);
        let (before, after) = (detailed.figures.frame.triangles, coarse.figures.frame.triangles);
        println!("{name}, {samples} samples: {before} triangles in detail, {after} with the hidden sea bed coarse");
        let changed = changed_pixels(&detailed.rgba, &coarse.rgba);
        let allowed = if multisampling { detailed.rgba.len() / 4 / 10_000 } else { 0 };
        assert!(changed <= allowed, "{name}, {samples} samples: the coarse sea bed changed {changed} pixels");
        assert!(coarse.figures.frame.under_sea > 0, "{name}: nothing under the sea");
        if name == "deep" && !multisampling {
            assert!((after as f64) < 0.8 * before as f64, "{name}: too little saved to tell: {before} → {after}");
            // The same stand-ins where no sea is drawn over them show.
            let bare = Shot { background: Some(SENTINEL), ..shot };
            let detailed = settled_with_sea("sea-deep-bare-detailed", &settings, &bare, None, false);
            let coarse = settled_with_sea("sea-deep-bare-coarse", &settings, &bare, Some(opaque), false);
            let changed = changed_pixels(&detailed.rgba, &coarse.rgba);
            println!("without the sea drawn, the coarse sea bed changes {changed} pixels");
            assert!(changed > 1000, "the coarse sea bed should show without the sea: {changed} pixels changed");
        }
    }
}

/// Under the sea the view is water: 3 m under the surface over a sea bed
/// 6–14 m down (a place from a fixed seed), the top of the picture is dim
/// blue-green murk, where 3 m above the same place it is the sky; the sea
/// bed below shows through the water, darker with distance.
#[test]
fn under_the_sea_the_view_is_water() {
    if !adapter_or_skip("under water") {
        return;
    }
    let settings = earth();
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let mut rng = Rng(0xD1FE);
    let dir = place_with_ground(&planet, &mut rng, -14.0..-6.0);
    let heading = dir.cross(DVec3::Z).normalize();
    let pitch = 20f64.to_radians();
    let (width, height) = SIZE;
    // Mean colour of a band of rows.
    let mean = |picture: &Picture, rows: std::ops::Range<u32>| -> [f64; 3] {
        let count = f64::from(rows.len() as u32 * width);
        let mut sum = [0.0; 3];
        for y in rows {
            for x in 0..width {
                let i = ((y * width + x) * 4) as usize;
                for (c, total) in sum.iter_mut().enumerate() {
                    *total += f64::from(picture.rgba[i + c]);
                }
            }
        }
        sum.map(|s| s / count)
    };
    let picture = |name: &str, offset: f64| {
        let eye = dir * (settings.radius + offset);
        let look = eye + (heading * pitch.cos() - dir * pitch.sin()) * 100.0;
        let shot = Shot { background: None, sun: Some((50.0, 30.0)), ..shot(eye, look, 60.0) };
        settled(name, &settings, &shot, DrawOptions::default())
    };
    let (under, above) = (picture("under-water", -3.0), picture("above-water", 3.0));
    let (under_top, above_top) = (mean(&under, 0..height / 4), mean(&above, 0..height / 4));
    let under_bottom = mean(&under, height * 3 / 4..height);
    println!("top rows under water {under_top:.0?}, above {above_top:.0?}; bottom rows under water {under_bottom:.0?}");
    let brightness = |c: [f64; 3]| c.iter().sum::<f64>();
    assert!(
        under_top[1] > under_top[0] + 20.0 && under_top[2] > under_top[0] + 20.0,
        "no blue-green water: {under_top:?}"
    );
    assert!(
        brightness(under_top) < 0.7 * brightness(above_top),
        "the sky shows under water: {under_top:?} vs {above_top:?}"
    );
    assert!(under_bottom != under_top, "the sea bed does not show: {under_bottom:?}");
}

/// Multisampling (four samples per pixel) smooths the shaded view: edge
/// pixels change, the picture as a whole does not. It never applies over a
/// background, where the crack checks need every pixel to be terrain or
/// the clear colour: there the picture is the same bit for bit. (On by
/// default only on a GPU; switched on and off here.) Earth, 1.5 km over a
/// place from a fixed seed, 10° down.
#[test]
fn multisampling_smooths_the_shaded_view_and_leaves_crack_checks_alone() {
    if !adapter_or_skip("multisampling") {
        return;
    }
    let settings = earth();
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let dir = place_with_ground(&planet, &mut Rng(0x55A), 200.0..1500.0);
    let (eye, look) = pose(&settings, dir, 1500.0, dir.cross(DVec3::Z), 10.0);
    for background in [None, Some(SENTINEL)] {
        let shot = Shot { background, ..shot(eye, look, 60.0) };
        let mut pictures = Vec::new();
        for on in [false, true] {
            let mut app = app(&settings, &shot, DrawOptions::default());
            if app.renderer_mut().set_multisampling(on) != on {
                // lavapipe and every GPU we run on can: CI must not pass by
                // skipping.
                assert!(
                    std::env::var("NEBULA_REQUIRE_ADAPTER").as_deref() != Ok("1"),
                    "NEBULA_REQUIRE_ADAPTER=1 but this adapter cannot multisample every target"
                );
                eprintln!("SKIPPED: this adapter cannot multisample every target");
                return;
            }
            pictures.push(render_app(&mut app, &shot).expect("renders"));
        }
        let (one, four) = (&pictures[0].rgba, &pictures[1].rgba);
        let changed = changed_pixels(one, four);
        let mean_shift =
            one.iter().zip(four).map(|(&a, &b)| f64::from(a) - f64::from(b)).sum::<f64>() / one.len() as f64;
        let pixels = one.len() / 4;
        println!("background {background:?}: {changed} of {pixels} pixels changed, mean shift {mean_shift:.3}");
        if background.is_some() {
            assert_eq!(changed, 0, "multisampling reached a view over a background");
        } else {
            // What the README says: about a quarter of the pixels change
            // (25.3 % on lavapipe), the mean by less than 0.1 of 255 (0.076).
            assert!(changed > pixels / 6, "too few pixels smoothed: {changed} of {pixels}");
            assert!(mean_shift.abs() < 0.2, "the picture as a whole changed: {mean_shift}");
        }
    }
}

/// A frame of thousands of chunks is a handful of draw commands (per mesh
/// buffer page a multi-draw-indirect for surfaces and one for skirts, one
/// for the sky), and those
/// indirect draws draw exactly the picture that a draw call per chunk
/// range draws (the control: thousands of draw calls). Random Earth poses
/// 300–1,500 m over land, shaded with the sky and over a background. (That
/// each draw reads its own chunk's constants, both paths alike, the crack
/// checks guard: with every draw starting at instance 0 the small planet's
/// orbit view shows crack pixels.)
#[test]
fn thousands_of_chunks_are_a_handful_of_draw_calls_drawing_the_same_picture() {
    if !adapter_or_skip("draw calls") {
        return;
    }
    let settings = earth();
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let mut rng = Rng(0x0d1a_3c11_5eed_0022);
    for n in 0..2 {
        let dir = place_with_ground(&planet, &mut rng, 20.0..2_000.0);
        let heading = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let (eye, look_at) = pose(&settings, dir, rng.range(300.0, 1_500.0), heading, rng.range(2.0, 20.0));
        let background = if n == 0 { None } else { Some(SENTINEL) };
        let shot = Shot { background, ..shot(eye, look_at, 60.0) };
        let mut app = app(&settings, &shot, DrawOptions::default());
        if !app.renderer().indirect_draws() {
            assert!(
                std::env::var("NEBULA_REQUIRE_ADAPTER").is_err(),
                "lavapipe and GPUs start indirect draws at an instance; this adapter cannot"
            );
            eprintln!("SKIPPED: {} cannot start indirect draws at an instance", app.gpu().adapter_name);
            return;
        }
        let indirect = render_app(&mut app, &shot).expect("renders");
        let stats = indirect.figures.render;
        println!("pose {n}: {} chunks, {stats:?}", indirect.figures.frame.chunks);
        assert!(indirect.figures.frame.chunks > 1_000, "pose {n}: only {} chunks", indirect.figures.frame.chunks);
        assert!(
            stats.draw_calls <= 16,
            "pose {n}: {} draw calls for {} chunk ranges",
            stats.draw_calls,
            stats.chunk_draws
        );
        app.renderer_mut().set_direct_draws(true);
        let direct = draw_frame(&mut app, &shot, &shot_view(&shot).expect("view")).expect("draws");
        let sky = u32::from(background.is_none());
        assert_eq!(
            direct.figures.render.draw_calls,
            direct.figures.render.chunk_draws + sky,
            "pose {n}: one per range"
        );
        assert_eq!(direct.figures.render.chunk_draws, stats.chunk_draws, "pose {n}: the same draws");
        assert!(
            direct.rgba == indirect.rgba,
            "pose {n}: {} pixels differ",
            changed_pixels(&direct.rgba, &indirect.rgba)
        );
    }
}

/// A random LOD-0 voxel column of `planet` and the unit direction of its
/// centre.
fn random_lod0_column(planet: &ProceduralPlanet, rng: &mut Rng) -> (nebula_voxel::CubeFace, u32, u32, DVec3) {
    let per_edge = f64::from(planet.layout().voxels_per_edge(0));
    let face = nebula_voxel::CubeFace::ALL[(rng.next() * 6.0) as usize % 6];
    let (i, j) = ((rng.next() * per_edge) as u32, (rng.next() * per_edge) as u32);
    (face, i, j, planet.layout().sphere().direction(face, f64::from(i) + 0.5, f64::from(j) + 0.5))
}

/// An eye inside a generated cave of `planet` and a point it looks at: the
/// middle of a LOD-0 voxel of cave air (air under solid ground, with air
/// over it for the head) in a random land column, looking level along the
/// tunnel (of eight headings, the one with the farthest rock, up to 60 m).
fn inside_a_cave(planet: &ProceduralPlanet, rng: &mut Rng) -> (DVec3, DVec3) {
    let sphere = planet.layout().sphere();
    loop {
        let (face, i, j, up) = random_lod0_column(planet, rng);
        let top = (planet.height_at(up) / sphere.layer_height()).floor() as i32;
        let air = |h: i32| !planet.voxel(nebula_voxel::VoxelCoord { face, lod: 0, i, j, h }).expect("voxel").is_solid();
        // Cave air two voxels tall, at least 3 voxels under solid ground.
        let Some(h) = (top - 50..top - 3).find(|&h| air(h) && air(h + 1) && !air(top - 1)) else { continue };
        let eye = up * sphere.layer_radius(f64::from(h) + 0.5);
        let east = up.any_orthonormal_vector();
        let north = up.cross(east);
        let (heading, _) = (0..8)
            .map(|k| {
                let a = f64::from(k) * std::f64::consts::FRAC_PI_4;
                let heading = east * a.cos() + north * a.sin();
                let reach =
                    nebula_voxel::pick(planet, eye, heading, 60.0).expect("pick").map_or(60.0, |hit| hit.distance);
                (heading, reach)
            })
            .fold((east, -1.0), |best, next| if next.1 > best.1 { next } else { best });
        return (eye, eye + heading * 10.0);
    }
}

#[test]
fn views_from_inside_caves_show_all_the_rock_near_them_and_no_crack() {
    // From inside generated caves of the Earth and the small planet
    // (random ones, a fixed seed), settled: no
    // crack pixel, and no background pixel whose ray meets LOD-0 rock
    // within 60 m (what the voxels hold there must be drawn: the chunks
    // under the ground around the cave, the tunnel's walls).
    if !adapter_or_skip("views_from_inside_caves_show_all_the_rock_near_them_and_no_crack") {
        return;
    }
    let mut rng = Rng(0x000c_a7e5);
    for (n, settings) in [earth(), earth(), earth(), small(), small()].into_iter().enumerate() {
        let planet = ProceduralPlanet::new(settings.clone()).expect("planet");
        let (eye, look_at) = inside_a_cave(&planet, &mut rng);
        let shot = shot(eye, look_at, 70.0);
        let name = format!("{}-inside-cave-{n}", if n < 3 { "earth" } else { "small" });
        let picture = settled(&name, &settings, &shot, DrawOptions::default());
        assert_eq!(picture.figures.crack_pixels, Some(0), "{name}: cracks at {:?}", picture.figures.cracks.samples);
        let camera = nebula_lod::Camera { position: eye, forward: look_at - eye, up: eye.normalize(), aspect: 1.6 };
        let (mut background, mut missing) = (0, Vec::new());
        for (k, pixel) in picture.rgba.chunks_exact(4).enumerate() {
            if pixel[..3] != SENTINEL {
                continue;
            }
            background += 1;
            let (x, y) = (k as u32 % SIZE.0, k as u32 / SIZE.0);
            let ray = camera.pixel_ray(shot.fov_y_degrees, SIZE, (x, y));
            if nebula_voxel::pick(&planet, eye, ray, 60.0).expect("pick").is_some() {
                missing.push((x, y));
            }
        }
        println!(
            "{name} (--camera-pos={:.2},{:.2},{:.2} --look-at={:.2},{:.2},{:.2}): {background} background pixels, \
             {} of them with rock within 60 m",
            eye.x,
            eye.y,
            eye.z,
            look_at.x,
            look_at.y,
            look_at.z,
            missing.len()
        );
        assert!(missing.is_empty(), "{name}: rock within 60 m not drawn at {:?}", &missing[..missing.len().min(8)]);
        assert!(background < picture.rgba.len() / 4, "{name}: the view is mostly background");
    }
}

/// Pixels `(x, y)` of the skirts view's skirt colour (magenta-pink, lit;
/// never the sentinel): what of the skirts a frame shows.
fn skirt_pixels(rgba: &[u8], width: u32) -> Vec<(u32, u32)> {
    rgba.chunks_exact(4)
        .enumerate()
        .filter(|(_, p)| {
            p[..3] != SENTINEL && u16::from(p[0]) > 2 * u16::from(p[1]) + 8 && u16::from(p[2]) > 2 * u16::from(p[1])
        })
        .map(|(k, _)| (k as u32 % width, k as u32 / width))
        .collect()
}

/// A cave mouth of `planet` and a camera outside looking into it: a random
/// land column whose top voxel by the heightfield is cave air (the shallow
/// tunnels open there), seen from `distance` m away over the ground at a
/// random heading, `height` m over the ground there.
fn at_a_cave_mouth(planet: &ProceduralPlanet, rng: &mut Rng, distance: f64, height: f64) -> (DVec3, DVec3) {
    let sphere = planet.layout().sphere();
    loop {
        let (face, i, j, up) = random_lod0_column(planet, rng);
        let height_layers = planet.height_at(up) / sphere.layer_height();
        // The heightfield's top voxel: its centre under H.
        let top = (height_layers - 0.5).ceil() as i32 - 1;
        if height_layers < 3.0 {
            continue;
        }
        let air = |h: i32| !planet.voxel(nebula_voxel::VoxelCoord { face, lod: 0, i, j, h }).expect("voxel").is_solid();
        if !(air(top) && air(top - 1) && air(top - 2)) {
            continue;
        }
        let mouth = up * sphere.layer_radius(f64::from(top) - 1.0);
        let east = up.any_orthonormal_vector();
        let north = up.cross(east);
        let a = rng.range(0.0, std::f64::consts::TAU);
        let away = (up * planet.settings().radius + (east * a.cos() + north * a.sin()) * distance).normalize();
        let eye = planet.surface_point(away) + away * height;
        return (eye, mouth);
    }
}

#[test]
fn cave_mouths_seen_from_the_surface_are_crack_free_with_no_skirt_showing() {
    // Random cave mouths of the Earth and the small planet (a fixed seed)
    // from 15–40 m away, 8–25 m over
    // the ground, in the skirts view over the sentinel: no crack pixel,
    // and no skirt pixel whose ray meets LOD-0 ground within 150 m (the
    // mouth's surroundings; a skirt at a distant silhouette, the grazing
    // residue of every view, is counted apart).
    if !adapter_or_skip("cave_mouths_seen_from_the_surface_are_crack_free_with_no_skirt_showing") {
        return;
    }
    let mut rng = Rng(0x0000_0bee_f00d);
    for (n, settings) in [earth(), earth(), earth(), earth(), small(), small()].into_iter().enumerate() {
        let planet = ProceduralPlanet::new(settings.clone()).expect("planet");
        let (distance, height) = (rng.range(15.0, 40.0), rng.range(8.0, 25.0));
        let (eye, mouth) = at_a_cave_mouth(&planet, &mut rng, distance, height);
        let shot = Shot { view: DebugView::Skirts, ..shot(eye, mouth, 60.0) };
        let name = format!("{}-cave-mouth-{n}", if n < 4 { "earth" } else { "small" });
        let picture = settled(&name, &settings, &shot, DrawOptions::default());
        let skirts = skirt_pixels(&picture.rgba, SIZE.0);
        let camera = nebula_lod::Camera { position: eye, forward: mouth - eye, up: eye.normalize(), aspect: 1.6 };
        let near: Vec<_> = skirts
            .iter()
            .filter(|&&pixel| {
                let ray = camera.pixel_ray(shot.fov_y_degrees, SIZE, pixel);
                nebula_voxel::pick(&planet, eye, ray, 150.0).expect("pick").is_some()
            })
            .collect();
        println!(
            "{name} (--camera-pos={:.2},{:.2},{:.2} --look-at={:.2},{:.2},{:.2}): {} skirt pixels, {} of them within 150 m",
            eye.x,
            eye.y,
            eye.z,
            mouth.x,
            mouth.y,
            mouth.z,
            skirts.len(),
            near.len()
        );
        assert_eq!(picture.figures.crack_pixels, Some(0), "{name}: cracks at {:?}", picture.figures.cracks.samples);
        assert!(picture.figures.planet_pixels > 10_000, "{name}: looks at too little ground");
        assert!(near.is_empty(), "{name}: skirts show near the mouth at {:?}", &near[..near.len().min(8)]);
    }
    // The control: from inside solid rock, where every face of the ground
    // looks away and is culled, the skirts hanging under the LOD seams in
    // view are what is drawn, and they are counted.
    let settings = earth();
    let planet = ProceduralPlanet::new(settings.clone()).expect("planet");
    let up = DVec3::new(0.62, 0.55, 0.56).normalize();
    let eye = planet.surface_point(up) - up * 12.0;
    assert!(planet.voxel(planet.layout().voxel_at(eye).expect("voxel")).expect("voxel").is_solid());
    let heading = up.any_orthonormal_vector();
    let shot = Shot { view: DebugView::Skirts, ..shot(eye, eye + heading * 100.0 + up * 10.0, 60.0) };
    let picture = settled("earth-skirts-from-inside-rock", &settings, &shot, DrawOptions::default());
    let skirts = skirt_pixels(&picture.rgba, SIZE.0).len();
    println!("from inside the rock: {skirts} skirt pixels");
    assert!(skirts > 100, "the skirt count sees no skirt from inside the rock ({skirts})");
}

#[test]
fn floating_islands_stream_and_draw_crack_free() {
    // A world a game brings (`nebula_tests::islands`: rock islands over an
    // ocean floor, its own VoxelSource) through the same Streamer and
    // PlanetRenderer: from random places around random islands (a fixed
    // seed), settled, over the sentinel: no crack pixel.
    if !adapter_or_skip("floating_islands_stream_and_draw_crack_free") {
        return;
    }
    use nebula_render::readback::Offscreen;
    use nebula_render::{FrameParams, PlanetRenderer, RendererOptions};
    let world = std::sync::Arc::new(nebula_tests::islands::FloatingIslands::new(2_000.0, 6, 7).expect("world"));
    let gpu = GpuContext::headless().expect("adapter");
    let mut renderer =
        PlanetRenderer::new(&gpu.adapter, &gpu.device, &gpu.queue, &RendererOptions { color_format: gpu.color_format })
            .expect("renderer");
    let tops = world.island_tops();
    let mut rng = Rng(0x1514_a2d5);
    let fov = 60.0;
    for n in 0..4 {
        let (up, top) = tops[(rng.next() * tops.len() as f64) as usize % tops.len()];
        let aside = up.any_orthonormal_vector();
        let around = up.cross(aside);
        let a = rng.range(0.0, std::f64::consts::TAU);
        let (distance, height) = (rng.range(60.0, 160.0), rng.range(-40.0, 60.0));
        let out = (aside * a.cos() + around * a.sin()) * distance;
        let eye = up * (top + height) + out;
        let camera =
            nebula_lod::Camera { position: eye, forward: up * (top - 20.0) - eye, up: eye.normalize(), aspect: 1.6 };
        let settings =
            nebula_lod::LodSettings { screen_height_px: f64::from(SIZE.1), fov_y_degrees: fov, ..Default::default() };
        let mut streamer = nebula_world::stream::Streamer::new(world.clone(), settings, camera, 2, &mut |key, mesh| {
            renderer.upload(key, mesh)
        })
        .expect("streamer");
        streamer.keep_cpu_meshes(true);
        let started = std::time::Instant::now();
        while !streamer.settled() {
            streamer.update(camera, &mut |key, mesh| renderer.upload(key, mesh));
            renderer.finish_uploads();
            assert!(started.elapsed().as_secs() < 120, "islands view {n} does not settle");
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let frame_draw = streamer.frame_draw(eye);
        let frame = FrameParams {
            background: SENTINEL,
            atmosphere: None,
            ..FrameParams::for_source(&*world, &camera, fov, &frame_draw, 250.0)
        };
        let target = Offscreen::new(&gpu, SIZE).expect("target");
        renderer.render(&target.view, SIZE, &frame, streamer.drawn().map(|(_, chunk, draw)| (&chunk.handle, draw)));
        let rgba = target.read(&gpu).expect("read back");
        let drawn =
            streamer.drawn().filter_map(|(_, chunk, draw)| chunk.cpu.as_deref().map(|mesh| (mesh, draw))).collect();
        let geometry = nebula_render::crack::DrawnGeometry {
            drawn,
            frame: frame_draw,
            sentinel_radius: streamer.view_min_surface_radius(),
        };
        let cracks = nebula_render::crack::count_cracks(&rgba, SIZE, SENTINEL, &camera, fov, &geometry);
        let name = format!("islands-{n}");
        write_png(&folder().join(format!("{name}.png")), &rgba, SIZE).expect("png");
        let figures = streamer.figures();
        println!(
            "{name}: {} chunks, {} triangles, {} planet pixels, {} crack pixels, max LOD difference {}",
            figures.chunks, figures.triangles, cracks.planet_pixels, cracks.cracks, figures.max_neighbor_lod_diff
        );
        assert_eq!(cracks.cracks, 0, "{name}: cracks at {:?}", cracks.samples);
        assert!(cracks.planet_pixels > 10_000, "{name}: sees too little");
    }
}

/// The picture-error measure (`nebula_render::picture_error`) on Earth
/// views 300 m over land from a fixed seed, against a reference at
/// τ = 0.5: at τ = 1 a small share of pixels is off by more than a pixel's
/// worth; drawing coarser than τ promises (τ = 4, the "bug") is caught.
#[test]
fn the_picture_error_measure_sees_detail_drawn_coarser_than_promised() {
    if !adapter_or_skip("picture error") {
        return;
    }
    let settings = earth();
    let planet = ProceduralPlanet::new(settings.clone()).expect("valid planet");
    let mut rng = Rng(0x91C7);
    for n in 0..2 {
        let dir = place_with_ground(&planet, &mut rng, 20.0..400.0);
        let heading = dir.any_orthonormal_vector().lerp(dir.cross(DVec3::Y), rng.next()).normalize();
        let (eye, look_at) = pose(&settings, dir, 300.0, heading, rng.range(3.0, 20.0));
        let depth = |sse_px: f64| {
            let view = Shot { sse_px, background: None, ..shot(eye, look_at, 60.0) };
            let mut app = app(&settings, &view, DrawOptions::default());
            app.renderer_mut().set_multisampling(false);
            render_app(&mut app, &view).expect("renders");
            app.renderer().read_view_depth().expect("depth read back")
        };
        let reference = depth(0.5);
        let share = |sse_px| {
            nebula_render::picture_error::depth_error(&depth(sse_px), &reference, SIZE).expect("same size").share()
        };
        let (fine, coarse) = (share(1.0), share(4.0));
        println!("picture error {n}: {:.3} % at τ = 1, {:.2} % at τ = 4", 100.0 * fine, 100.0 * coarse);
        assert!(fine < 0.005, "{:.3} % of pixels off at τ = 1", 100.0 * fine);
        assert!(
            coarse > 0.02 && coarse > 10.0 * fine,
            "τ = 4 drew {:.3} %, τ = 1 {:.3} %",
            100.0 * coarse,
            100.0 * fine
        );
    }
}
