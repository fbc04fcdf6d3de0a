//! Edit speed on the Earth-sized planet: a 5 m sphere dug into the ground
//! in memory, and the same saved to a world file (one durable redb
//! transaction each), against the in-memory edit as the baseline in the
//! same run. Run: `cargo bench -p nebula_world`.
//!
//! Measured 2026-11-22 on the 2-core dev machine (ext4): 0.46 ms in
//! memory, 0.61 ms saved.
//!
//! `edit_voxel_with_snapshot`: one block placed while a renderer holds a
//! snapshot, with no edits before and after 64 craters (371,038 edited
//! voxels). 2026-11-24: 1.53 / 1.56 µs with the edits in persistent maps;
//! the same bench on the build before them: 5.5 µs / 1.29 ms (every apply
//! deep-copied the edits and emptied the height memo).

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use nebula_math::DVec3;
use nebula_voxel::{PlanetSettings, Voxel, VoxelSource};
use nebula_world::{Edit, World};

fn bench(c: &mut Criterion) {
    let settings = PlanetSettings::earth(11);
    let dir = std::env::temp_dir().join(format!("nebula-edit-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut group = c.benchmark_group("edit_sphere_5m");
    let spots: Vec<DVec3> = {
        let world = World::open(settings.clone(), None).expect("planet");
        (0..64)
            .map(|n| {
                let a = f64::from(n) * 0.77;
                world.source().base().surface_point(DVec3::new(a.cos(), 0.3, a.sin()).normalize())
            })
            .collect()
    };
    for (name, path) in [("in_memory", None), ("saved", Some(dir.join("bench.redb")))] {
        let mut world = World::open(settings.clone(), path.as_deref()).expect("world");
        let mut next = spots.iter().cycle();
        let mut material = [Voxel::AIR, Voxel::STONE].into_iter().cycle();
        group.bench_function(name, |b| {
            b.iter_batched(
                || Edit::Sphere {
                    center: *next.next().expect("cycle"),
                    radius: 5.0,
                    voxel: material.next().expect("cycle"),
                },
                |edit| world.apply(&[edit]).expect("edit"),
                BatchSize::SmallInput,
            );
        });
    }
    group.finish();

    // What a game does: a renderer holds a snapshot of the voxels
    // (`World::voxels`, as the streamer does) while the player edits, after
    // many edits. Each apply then clones the edited source: with the edits
    // in persistent maps that costs the edit, not the edits so far.
    let mut group = c.benchmark_group("edit_voxel_with_snapshot");
    for craters in [0usize, 64] {
        let mut world = World::open(settings.clone(), None).expect("planet");
        for spot in spots.iter().take(craters) {
            world.apply(&[Edit::Sphere { center: *spot, radius: 16.0, voxel: Voxel::AIR }]).expect("edit");
        }
        let edited = world.edit_count();
        let mut next = spots.iter().cycle();
        let mut material = [Voxel::SAND, Voxel::STONE].into_iter().cycle();
        group.bench_function(format!("after_{edited}_edited_voxels"), |b| {
            b.iter(|| {
                let snapshot = world.voxels();
                // One block placed 40 m over a crater (outside it).
                let above = *next.next().expect("cycle") * (1.0 + 40.0 / settings.radius);
                let at = world.source().layout().voxel_at(above).expect("on the planet");
                world.apply(&[Edit::Voxel { at, voxel: material.next().expect("cycle") }]).expect("edit");
                snapshot
            });
        });
    }
    group.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
