//! The frame thread's share of a streamed Earth view: one
//! `Streamer::update` on a settled view 300 m over land at 640×400, its
//! out-of-view prefetching done and meshing paused, against the baseline
//! of merely walking the tree's visible leaves once in the same run.
//! `step_settled`: the LOD thread repeats its plan before for a still
//! camera over a settled view (nothing can change it), so this is applying
//! a plan; `step_settled_planned`: the same update with no LOD thread,
//! planned on the frame thread each time (the LOD tree has nothing to
//! change, so this is the selection: which columns are drawn, their
//! stand-ins, skirt depths and sides, the job list), what every still frame
//! cost before. Run: `cargo bench -p nebula_world --bench step`.
//!
//! `step_waiting`: the frame after the camera jumped 30 km on, every leaf
//! of the new view waiting for its meshes and drawn through a stand-in or
//! not at all (meshing is paused, so each iteration sees the same state).
//! `step_prefetching`: that view settled, with its whole out-of-view
//! prefetch set still to mesh. `step_turning`: the first view, settled
//! and prefetched, turning 0.5° a frame, a frame being the update and 4 ms
//! of drawing, the plan before drawn while the LOD thread makes the next
//! (the default), against `step_turning_waiting`, which waits for each
//! plan; `_meshing`: the same with meshing running (what comes into view
//! is meshed as it comes; later runs find more of it meshed).

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use nebula_lod::{Camera, LodSettings};
use nebula_math::{DQuat, DVec3};
use nebula_meshing::RenderMesh;
use nebula_voxel::{ChunkKey, PlanetSettings, ProceduralPlanet};
use nebula_world::stream::{MeshHandle, Streamer};

/// A mesh handle that only knows its size, as a renderer's would.
struct Sized(u64);

impl MeshHandle for Sized {
    fn bytes(&self) -> u64 {
        self.0
    }
}

fn upload(_key: ChunkKey, mesh: &RenderMesh) -> Sized {
    Sized(mesh.bytes())
}

/// 300 m over land, `east_m` east of the first land a fixed sequence of
/// directions finds, looking east 10° down.
fn camera(planet: &ProceduralPlanet, east_m: f64) -> Camera {
    let mut direction = DVec3::new(0.31, 0.62, -0.72).normalize();
    let mut n = 0.0;
    while planet.height_at(direction) < 40.0 {
        n += 1.0;
        direction = DVec3::new((n * 0.7_f64).sin(), 0.6, (n * 0.7_f64).cos()).normalize();
    }
    let east = DVec3::Y.cross(direction).normalize();
    let up = (direction + east * (east_m / planet.settings().radius)).normalize();
    let east = DVec3::Y.cross(up).normalize();
    let forward = (east - up * 10f64.to_radians().tan()).normalize();
    Camera { position: planet.surface_point(up) + up * 300.0, forward, up, aspect: 1.6 }
}

fn bench(c: &mut Criterion) {
    let planet = std::sync::Arc::new(ProceduralPlanet::new(PlanetSettings::earth(11)).expect("planet"));
    let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
    let ahead = camera(&planet, 0.0);
    let mut streamer = Streamer::new(planet.clone(), lod, ahead, 2, &mut upload).expect("streamer");
    for frame in 0.. {
        streamer.update(ahead, &mut upload);
        if streamer.settled() && streamer.prefetched() {
            break;
        }
        assert!(frame < 100_000, "the view did not settle");
        std::thread::sleep(Duration::from_millis(2));
    }
    let figures = streamer.figures();
    println!(
        "settled: {} chunks drawn, {} held ({} MB), {} jobs ({} prefetching)",
        figures.chunks,
        figures.chunks_held,
        figures.held_bytes >> 20,
        figures.jobs_in_flight,
        figures.prefetch_jobs
    );

    // Nothing changes while measuring: no job starts.
    streamer.set_meshing_paused(true);
    let mut group = c.benchmark_group("step");
    group.bench_function("walk_visible_leaves (baseline)", |b| {
        b.iter(|| {
            black_box(
                streamer.tree().visible_leaves_with_bounds().map(|(c, b)| b.min_radius + f64::from(c.x)).sum::<f64>(),
            )
        });
    });
    group.bench_function("step_settled", |b| b.iter(|| streamer.update(ahead, &mut upload)));
    streamer.set_lod_thread(false);
    group.bench_function("step_settled_planned", |b| b.iter(|| streamer.update(ahead, &mut upload)));
    streamer.set_lod_thread(true);

    // The settled view (its out-of-view prefetching done) turning 0.5° a
    // frame, each frame the update and 4 ms of drawing (a GPU's frame,
    // while the LOD thread plans the next): the frame's whole
    // time, drawing the plan before while the next is made
    // (`step_turning`, the default) against waiting for each plan; printed
    // after each, the update's own time and its wait for the LOD thread
    // (median, 95th percentile and mean over every frame run).
    group.sample_size(20);
    let turns = [
        ("step_turning", true, true),
        ("step_turning_waiting", false, true),
        ("step_turning_meshing", true, false),
        ("step_turning_meshing_waiting", false, false),
    ];
    for (name, draw_while_planning, paused) in turns {
        streamer.set_draw_while_planning(draw_while_planning);
        streamer.set_meshing_paused(paused);
        let mut angle = 0.0_f64;
        let drawn_again = streamer.frames_drawn_while_planning();
        let (mut updates, mut waits) = (Vec::new(), Vec::new());
        group.bench_function(name, |b| {
            b.iter_custom(|iterations| {
                let start = Instant::now();
                for _ in 0..iterations {
                    angle += 0.5;
                    let turn = DQuat::from_axis_angle(ahead.up, angle.to_radians());
                    let update = Instant::now();
                    streamer.update(Camera { forward: turn * ahead.forward, ..ahead }, &mut upload);
                    updates.push(update.elapsed().as_secs_f64() * 1e3);
                    waits.push(streamer.figures().times.lod_wait_ms);
                    std::thread::sleep(Duration::from_millis(4));
                }
                start.elapsed()
            });
        });
        let spread = |values: &mut Vec<f64>| {
            values.sort_by(f64::total_cmp);
            let n = values.len().max(1);
            let at = |share: usize| values.get(n * share / 100).copied().unwrap_or(0.0);
            format!(
                "median {:.2} ms, p95 {:.2} ms, mean {:.2} ms",
                at(50),
                at(95),
                values.iter().sum::<f64>() / n as f64
            )
        };
        println!(
            "{name}: {} of {} frames drew the plan before; update {}; wait for the LOD thread {}",
            streamer.frames_drawn_while_planning() - drawn_again,
            updates.len(),
            spread(&mut updates),
            spread(&mut waits)
        );
    }
    streamer.set_draw_while_planning(true);
    streamer.set_meshing_paused(true);
    group.sample_size(100);

    let figures = streamer.figures();
    println!(
        "after: {} chunks drawn, {} held ({} MB), {} jobs ({} prefetching)",
        figures.chunks,
        figures.chunks_held,
        figures.held_bytes >> 20,
        figures.jobs_in_flight,
        figures.prefetch_jobs
    );
    let behind = camera(&planet, 30_000.0);
    // The LOD tree refines towards the new view over a few frames (and on
    // its own thread): let it finish before measuring.
    for _ in 0..100 {
        streamer.update(behind, &mut upload);
        std::thread::sleep(Duration::from_millis(5));
    }
    let figures = streamer.figures();
    println!("turned: {} chunks drawn, {} stand-ins", figures.chunks, figures.stand_ins);
    group.bench_function("step_waiting", |b| b.iter(|| streamer.update(behind, &mut upload)));

    // The new view settled, its out-of-view prefetching not begun.
    streamer.set_meshing_paused(false);
    while !streamer.settled() {
        streamer.update(behind, &mut upload);
        std::thread::sleep(Duration::from_millis(2));
    }
    streamer.set_meshing_paused(true);
    for _ in 0..20 {
        streamer.update(behind, &mut upload);
    }
    let figures = streamer.figures();
    println!("prefetching: {} chunks drawn, {} jobs queued", figures.chunks, figures.jobs_in_flight);
    group.bench_function("step_prefetching", |b| b.iter(|| streamer.update(behind, &mut upload)));

    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
