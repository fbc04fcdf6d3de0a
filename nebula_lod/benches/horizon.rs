//! The ground's horizon (`TerrainHorizon`) as the streamer's plan uses it,
//! once per plan: made from the visible leaves' floors, then asked for
//! the clearance of every visible leaf.
//!
//! Views: the Earth through a 12° lens 500 m over the ground, 3° down,
//! at 640×400 (the README's issue lens over a plain and seed 71's third
//! lens in the mountains), and a 60° view 1 km up at 1280×720. Each
//! leaf's floor is taken as its bounds' lowest radius (the streamer
//! takes the lowest point its meshes draw, which lies over it).
//! `new` times making the horizon, `clearance` asking it of every visible
//! leaf (`hides` as the plan asks: its clearance, then its top).
//! Run: `cargo bench -p nebula_lod --bench horizon`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nebula_lod::{Camera, LodSettings, LodTree, NodeBounds, TerrainHorizon};
use nebula_math::DVec3;
use nebula_voxel::{PlanetSettings, ProceduralPlanet};

/// A tree refined and culled for the view from `eye` towards `look_at`.
fn view_tree(planet: &ProceduralPlanet, eye: DVec3, look_at: DVec3, size: (f64, f64), fov: f64) -> (LodTree, Camera) {
    let settings = LodSettings { screen_height_px: size.1, fov_y_degrees: fov, ..LodSettings::default() };
    let mut tree = LodTree::new(planet, settings).expect("valid settings");
    let camera = Camera { position: eye, forward: look_at - eye, up: eye, aspect: size.0 / size.1 };
    // Updates until the tree settles (a narrow lens refocuses once).
    for _ in 0..4 {
        tree.update(planet, &camera).expect("valid camera");
    }
    tree.cull(&camera).expect("valid camera");
    (tree, camera)
}

fn horizon(c: &mut Criterion) {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(1)).expect("valid planet");
    let views = [
        (
            "lens_plain",
            DVec3::new(6_218_042.78, 1_243_608.56, 621_804.28),
            DVec3::new(6_218_128.37, 1_242_703.83, 622_221.58),
            (640.0, 400.0),
            12.0,
        ),
        (
            "lens_mountains",
            DVec3::new(-4_593_192.434, -2_099_817.499, -3_884_950.885),
            DVec3::new(-4_593_157.844, -2_098_920.194, -3_885_390.939),
            (640.0, 400.0),
            12.0,
        ),
        (
            "land_1km",
            DVec3::new(6_219_094.00, 1_243_818.80, 621_909.40),
            DVec3::new(6_219_057.74, 1_243_911.98, 621_907.71),
            (1280.0, 720.0),
            60.0,
        ),
    ];
    let mut group = c.benchmark_group("terrain_horizon");
    for (name, eye, look_at, size, fov) in views {
        let (tree, camera) = view_tree(&planet, eye, look_at, size, fov);
        let leaves: Vec<NodeBounds> = tree.visible_leaves_with_bounds().map(|(_, b)| *b).collect();
        let occluders = || leaves.iter().map(|b| (*b, Some(b.min_radius)));
        let margin = 1.0;
        let terrain = TerrainHorizon::new(camera.position, margin, occluders());
        let hidden = leaves.iter().filter(|b| terrain.hides(b)).count();
        eprintln!("{name}: {} visible leaves, {hidden} hidden by the ground in front", leaves.len());
        group.bench_function(BenchmarkId::new(name, "new"), |b| {
            b.iter(|| TerrainHorizon::new(camera.position, margin, occluders()));
        });
        group.bench_function(BenchmarkId::new(name, format!("clearance/leaves={}", leaves.len())), |b| {
            b.iter(|| leaves.iter().filter(|b| terrain.hides(b)).count());
        });
    }
    group.finish();
}

criterion_group!(benches, horizon);
criterion_main!(benches);
