//! Per-frame LOD update along a flight over the Earth-sized planet, 60
//! frames per second: incremental update vs. full traversal in the same run.
//!
//! Segments (each timed as 60 consecutive frames from the same prepared
//! tree; divide by 60 for a frame):
//! - `orbit`: 2,000 km up, circling at 7 km/s;
//! - `descent`: from 20 km down at 500 m/s;
//! - `low_flight`: 300 m/s level flight 150 m above the ground.
//!
//! `cull` times horizon + frustum culling of the same 60 frames on the tree
//! of the first frame. Settings are the defaults (1 px error threshold,
//! 1080 lines, 60°).
//! Run: `cargo bench -p nebula_lod`.

use criterion::{BatchSize, BenchmarkId, Criterion, criterion_group, criterion_main};
use nebula_lod::{Camera, LodSettings, LodTree};
use nebula_math::DVec3;
use nebula_voxel::{PlanetSettings, ProceduralPlanet};

const FPS: f64 = 60.0;
const RADIUS: f64 = 6_371_000.0;

/// Cameras along a great circle, `speed` m/s, `height(frame)` metres above
/// the ground (`ground`) or above the base radius (not `ground`).
fn path(
    planet: &ProceduralPlanet,
    frames: usize,
    speed: f64,
    height: impl Fn(usize) -> f64,
    ground: bool,
) -> Vec<Camera> {
    let start = DVec3::new(0.21, 0.93, -0.3).normalize();
    let axis = start.cross(DVec3::Z).normalize();
    (0..frames)
        .map(|frame| {
            let angle = speed * frame as f64 / FPS / RADIUS;
            let dir = rotate(start, axis, angle);
            let base = if ground { planet.surface_point(dir) } else { dir * RADIUS };
            let position = base + dir * height(frame);
            let forward = axis.cross(dir) * 4.0 - dir; // ahead and a little down
            Camera { position, forward, up: dir, aspect: 16.0 / 9.0 }
        })
        .collect()
}

fn rotate(v: DVec3, axis: DVec3, angle: f64) -> DVec3 {
    v * angle.cos() + axis.cross(v) * angle.sin() + axis * axis.dot(v) * (1.0 - angle.cos())
}

fn flight(c: &mut Criterion) {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(1)).expect("valid planet");
    let settings = LodSettings::default();
    let segments = [
        ("orbit", path(&planet, 61, 7_000.0, |_| 2_000_000.0, false)),
        ("descent", path(&planet, 61, 200.0, |f| 20_000.0 - 500.0 * f as f64 / FPS, true)),
        ("low_flight", path(&planet, 61, 300.0, |_| 150.0, true)),
    ];
    let mut group = c.benchmark_group("lod_update_60_frames");
    group.sample_size(10);
    for (name, cameras) in &segments {
        let mut tree = LodTree::new(&planet, settings).expect("valid settings");
        tree.update(&planet, &cameras[0]).expect("valid camera");
        tree.cull(&cameras[0]).expect("valid camera");
        let stats = tree.stats();
        eprintln!(
            "{name}: {} leaves, {} in view, max neighbour LOD difference {}, LODs {:?}",
            stats.leaves, stats.visible_leaves, stats.max_neighbor_lod_diff, stats.lod_histogram
        );
        for full in [false, true] {
            let id = BenchmarkId::new(*name, if full { "full" } else { "incremental" });
            group.bench_function(id, |b| {
                b.iter_batched(
                    || tree.clone(),
                    |mut tree| {
                        for camera in &cameras[1..] {
                            if full {
                                tree.update_full(&planet, camera).expect("valid camera");
                            } else {
                                tree.update(&planet, camera).expect("valid camera");
                            }
                        }
                        tree
                    },
                    BatchSize::LargeInput,
                );
            });
        }
        // Culling alone (once per frame in a renderer), on the same tree.
        group.bench_function(BenchmarkId::new(*name, "cull"), |b| {
            b.iter(|| {
                for camera in &cameras[1..] {
                    tree.cull(camera).expect("valid camera");
                }
            });
        });
    }
    group.finish();
}

criterion_group!(benches, flight);
criterion_main!(benches);
