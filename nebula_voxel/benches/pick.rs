//! Picking speed on the Earth-sized planet: rays that hit the ground about
//! 1 km away (from 300 m up, 17° down) and straight down from 1 km, against
//! the cost of reading one voxel (a noise evaluation) in the same run. Run:
//! `cargo bench -p nebula_voxel --bench pick`.
//!
//! Measured 2026-11-22 on the 2-core dev machine: straight down 63 µs,
//! grazing 239 µs (331 µs before LOD-3 columns were skipped first), one
//! voxel read 1.12 µs.

use criterion::{Criterion, criterion_group, criterion_main};
use nebula_voxel::{DVec3, PlanetSettings, ProceduralPlanet, VoxelSource, pick};

fn rays(planet: &ProceduralPlanet, altitude: f64, dip: f64) -> Vec<(DVec3, DVec3)> {
    (0..16)
        .map(|n| {
            let a = f64::from(n) * 0.37;
            let up = DVec3::new(a.cos(), 0.4 + 0.1 * a.sin(), a.sin()).normalize();
            let origin = planet.surface_point(up) + up * altitude;
            let east = DVec3::Y.cross(up).normalize();
            (origin, (east + up * dip).normalize())
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(11)).expect("valid planet");
    let mut group = c.benchmark_group("pick");
    for (name, altitude, dip) in [("1km_grazing", 300.0, -0.3), ("1km_down", 1000.0, -1e6)] {
        let rays = rays(&planet, altitude, dip);
        let mean: f64 = rays
            .iter()
            .map(|&(o, d)| pick(&planet, o, d, 5_000.0).expect("valid ray").map_or(0.0, |hit| hit.distance))
            .sum::<f64>()
            / rays.len() as f64;
        println!("{name}: mean hit distance {mean:.0} m");
        let mut next = rays.iter().cycle();
        group.bench_function(name, |b| {
            b.iter(|| {
                let &(origin, dir) = next.next().expect("cycle");
                pick(&planet, origin, dir, 5_000.0).expect("valid ray")
            });
        });
    }
    let (origin, dir) = rays(&planet, 300.0, -0.3)[0];
    let hit = pick(&planet, origin, dir, 5_000.0).expect("valid ray").expect("hits");
    group.bench_function("one_voxel_read", |b| b.iter(|| planet.voxel(hit.voxel).expect("valid voxel")));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
