//! Voxel generation speed: one 32³ chunk (plus padding) at LOD 0 and at a
//! coarse LOD on the Earth-sized planet, and 64 chunks sequentially vs. in
//! parallel with rayon (same run, so the ratio is meaningful on a noisy
//! machine). Run: `cargo bench -p nebula_voxel`.
//!
//! Measured 2026-11-22 on the 2-core dev machine (Earth planet with hills),
//! cold (no cached heights): LOD 0 chunk 1.35 ms, LOD 8 chunk 1.35 ms
//! (24.3 M voxels/s; with `noise::Perlin` they were 1.38 and 3.10 ms: its
//! gradient `match` mispredicts where samples are far apart); both surface
//! layers of a column 1.43 / 1.49 ms (heights computed once); 64 LOD-2
//! chunks on rayon 1.7× faster than sequentially on 2 threads. With the
//! heights of a chunk's columns computed octave by octave, sharing noise
//! cells (`perlin::Fractal::get_many`): LOD 0 1.00 ms, LOD 8 1.11 ms;
//! with two neighbours in one cell blended at once (`wide::f64x2`, one
//! SSE2 register): 0.70 / 0.85 ms. Four lanes (`f64x4`, two SSE2 halves
//! on baseline x86-64) were slower: 0.99 ms where all four share a cell,
//! 1.81 ms gathering each lane's gradients.
//! Column directions from one `tan` per row and per column of the chunk:
//! 0.67 / 0.82 ms. Each column's octaves stopped once the bounds of what
//! the rest can add leave no voxel or material threshold open (the same
//! voxels, `ProceduralPlanet::columns_at`), same run against the build
//! before: LOD 0 652 → 663 µs, LOD 8 818 → 397 µs.
//!
//! 2026-11-27: these benches had timed warm fills since clones came to
//! share the height cache (28 µs); each iteration now starts from
//! `with_empty_cache`. Cold, same run: LOD 0 587 µs, LOD 8 438 µs, a LOD-0
//! chunk under the mountain flight 547 µs. The ridges stopped where the
//! continents leave no mountain (the mask is 0, so they cannot move H)
//! and the material thresholds found once per column instead of at every
//! look: 423 / 296 / 409 µs (the same voxels, bit for bit).
//! Octave grids (`PlanetSettings::octave_grid` 16, the presets' default;
//! `_no_grids` is the same planet with every octave at every column, in
//! the same run): LOD 0 451 → 272 µs, under the mountain flight 431 →
//! 263 µs (1.6–1.7×), LOD 8 unchanged (its columns are nodes of every
//! grid: 324 µs).
//! The caves' swell summed in one batch only where the course lets a
//! tunnel pass, and the climate belts' bells shared by a chunk's columns
//! (the same voxels), against the session's first build: LOD 0
//! 290 → 236 µs, under the mountain flight 276 → 209 µs, LOD 8 327 µs
//! either way.
//! `fill_mountains_warm_lod` is the fill alone, the columns cached: 23 µs.
//! The hills' octaves after the continents' (a coarse column is mostly
//! decided before the hills' later octaves count): LOD 5 288 → 261–270 µs,
//! LOD 8 325 → 294–300 µs.
//! 2026-11-29: the octaves' step four points a blend in an AVX2 build
//! (`Fractal::step`, chosen at run time; corners found four at once in
//! floating point), alternated in one session against the build before:
//! LOD 0 227–229 → 202–205 µs, under the mountain flight 208–209 →
//! 182–184 µs, LOD 8 267–269 → 234–238 µs (the same voxels).
//! That "mountain flight" chunk turned out to be the sea bed (the flight
//! starts over the sea): it is `fill_flight_start_seabed_lod` now, and
//! `fill_mountains_lod` a chunk 1.5 km up or more. No caves' noise where
//! the column's relief rules caves out (under the sea, out of every cave
//! region), same run: random places 7.58–7.79 → 6.95–7.04 ms (32 chunks),
//! sea bed 184–188 → 141–144 µs, PosZ LOD 0 207–209 → 146–151 µs,
//! mountains 229–233 → 224–227 µs (caves there: the same work).
//! 2026-11-29 (morning), the session's first build against the last,
//! alternated five times: `fill_mountains_lod` (the high-mountain
//! column's lowest surface chunk, mostly buried rock) 230 → 153 µs,
//! `fill_mountains_middle_lod` (new: its middle surface chunk, cut by the
//! slope) 216 → 157 µs, PosZ LOD 0 / 8 154 → 106 / 241 → 181 µs, random
//! places 7.11 → 5.84 ms: rows of voxels copied whole where a row lies
//! over or deep under all its columns, looks that cannot decide skipped,
//! the caves' possibility read from the noise's ranges (README,
//! "Generation a third faster, the same voxels").
//! 2026-12-02: coarse octave grids (`PlanetSettings::octave_grid_error`,
//! the continents' long octaves from grids of 64 and 256 columns within
//! 1 cm each); `_no_coarse_grids` is the same planet without them. Mean
//! cold chunk over 24 random surface chunks per LOD, the two planets
//! alternated 40 times in one process: LOD 0 +2–3 % (two more grid
//! passes; +0.4–0.7 % with the surface bounds' corner samples summed
//! together), LOD 3 −4 %, LOD 5 −28 %, LOD 7 −27 %, LOD 9 ±0 (no grid is
//! coarser than its columns).

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use nebula_voxel::{ChunkColumn, ChunkKey, ChunkVoxels, CubeFace, PlanetSettings, ProceduralPlanet, VoxelSource};
use rayon::prelude::*;

fn surface_chunk(planet: &ProceduralPlanet, face: CubeFace, lod: u8, x: u32, y: u32) -> ChunkKey {
    let column = ChunkColumn { face, lod, x, y };
    let layers = planet.surface_chunk_layers(column).expect("column is on the planet");
    column.chunk(*layers.start())
}

/// The LOD-0 surface chunk under the start of the 1 km/s mountain flight
/// (`docs/flight-1kms-mountains.json`). Its ground is the sea bed, 470 m
/// down (the flight starts over the sea, 1.1 km up, and reaches the range
/// later): notes before 2026-11-29 called this case "mountains".
fn flight_start_chunk(planet: &ProceduralPlanet) -> ChunkKey {
    let eye = nebula_math::DVec3::new(-2_852_441.14, 5_696_193.33, -144_566.46);
    let at = planet.layout().voxel_at(eye).expect("the eye is over the planet");
    surface_chunk(planet, at.face, 0, at.i / 32, at.j / 32)
}

/// A unit direction from `state`'s next three random numbers (`None` in
/// the rare draw too short to normalise).
fn random_direction(state: &mut u64) -> Option<nebula_math::DVec3> {
    let mut unit = || nebula_math::unit_random(state) * 2.0 - 1.0;
    nebula_math::DVec3::new(unit(), unit(), unit()).try_normalize()
}

/// The LOD-0 surface chunk at unit `direction`.
fn chunk_at(planet: &ProceduralPlanet, direction: nebula_math::DVec3) -> ChunkKey {
    let at = planet.layout().voxel_at(direction * 6.4e6).expect("over the planet");
    surface_chunk(planet, at.face, 0, at.i / 32, at.j / 32)
}

/// A LOD-0 surface chunk in high mountains: at the first of a fixed
/// sequence of random places whose ground is 1,500 m up or more.
fn mountain_chunk(planet: &ProceduralPlanet) -> ChunkKey {
    let mut state = 0x0A1_u64;
    loop {
        if let Some(direction) = random_direction(&mut state).filter(|&d| planet.height_at(d) >= 1_500.0) {
            return chunk_at(planet, direction);
        }
    }
}

/// The middle one of the surface chunks of `key`'s column (`key` its
/// lowest): in high mountains the lowest is mostly buried rock, the middle
/// one cut by the slope, most of its rows part ground and part air.
fn middle_surface_chunk(planet: &ProceduralPlanet, key: ChunkKey) -> ChunkKey {
    let layers = planet.surface_chunk_layers(key.column()).expect("column is on the planet");
    key.column().chunk((layers.start() + layers.end()) / 2)
}

/// Fills `keys` one after another, from an empty height cache each
/// iteration: chunks whose columns were never filled.
fn fill_cold(b: &mut criterion::Bencher<'_>, planet: &ProceduralPlanet, keys: &[ChunkKey], voxels: &mut ChunkVoxels) {
    b.iter_batched(
        || planet.with_empty_cache(),
        |planet| {
            for &key in keys {
                planet.fill_chunk(key, voxels).expect("valid key");
            }
        },
        BatchSize::SmallInput,
    );
}

fn generate(c: &mut Criterion) {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(1)).expect("valid planet");
    // The baseline in the same run: every octave at every column (the
    // terrain of planets saved before octave grids).
    let exact =
        ProceduralPlanet::new(PlanetSettings { octave_grid: 0.0, ..PlanetSettings::earth(1) }).expect("valid planet");
    // And with no grid coarser than the ratio's 16 columns (the terrain of
    // planets saved before coarse grids).
    let fine_grids = ProceduralPlanet::new(PlanetSettings { octave_grid_error: 0.0, ..PlanetSettings::earth(1) })
        .expect("valid planet");
    let mut group = c.benchmark_group("voxel_chunk");
    group.throughput(Throughput::Elements(32 * 32 * 32));
    let cases = [
        ("fill_lod", &planet, 0u8, surface_chunk(&planet, CubeFace::PosZ, 0, 5, 7)),
        ("fill_lod", &planet, 2, surface_chunk(&planet, CubeFace::PosZ, 2, 5, 7)),
        ("fill_lod", &planet, 5, surface_chunk(&planet, CubeFace::PosZ, 5, 5, 7)),
        ("fill_lod", &planet, 8, surface_chunk(&planet, CubeFace::PosZ, 8, 5, 7)),
        ("fill_mountains_lod", &planet, 0, mountain_chunk(&planet)),
        ("fill_mountains_middle_lod", &planet, 0, middle_surface_chunk(&planet, mountain_chunk(&planet))),
        ("fill_flight_start_seabed_lod", &planet, 0, flight_start_chunk(&planet)),
        ("fill_lod_no_grids", &exact, 0, surface_chunk(&exact, CubeFace::PosZ, 0, 5, 7)),
        ("fill_lod_no_coarse_grids", &fine_grids, 0, surface_chunk(&fine_grids, CubeFace::PosZ, 0, 5, 7)),
        ("fill_lod_no_coarse_grids", &fine_grids, 5, surface_chunk(&fine_grids, CubeFace::PosZ, 5, 5, 7)),
        ("fill_lod_no_coarse_grids", &fine_grids, 8, surface_chunk(&fine_grids, CubeFace::PosZ, 8, 5, 7)),
        ("fill_mountains_lod_no_coarse_grids", &fine_grids, 0, mountain_chunk(&fine_grids)),
        ("fill_mountains_lod_no_grids", &exact, 0, mountain_chunk(&exact)),
    ];
    for (name, planet, lod, key) in cases {
        let mut voxels = ChunkVoxels::new(key);
        // An empty height cache per iteration: the cost of a chunk whose
        // column was never filled.
        group.bench_with_input(BenchmarkId::new(name, lod), &key, |b, &key| {
            b.iter_batched(
                || planet.with_empty_cache(),
                |planet| planet.fill_chunk(key, &mut voxels).expect("valid key"),
                BatchSize::SmallInput,
            );
        });
    }
    // Whether a chunk has anything to mesh, asked of every chunk filled:
    // one of buried rock (under the high mountains' surface layers, where
    // the whole chunk and its padding are read), the slope's middle chunk.
    let mountain = mountain_chunk(&planet);
    let buried = mountain.column().chunk(mountain.layer - 1);
    for (name, key) in
        [("has_no_surface_buried", buried), ("has_no_surface_slope", middle_surface_chunk(&planet, mountain))]
    {
        let mut voxels = ChunkVoxels::new(key);
        planet.fill_chunk(key, &mut voxels).expect("valid key");
        group.bench_function(name, |b| b.iter(|| voxels.has_no_surface()));
    }
    // LOD-0 surface chunks at 32 places drawn at random (a fixed seed) over
    // the whole Earth, sea and land, mountains and plains: the mean cold
    // chunk, not one hand-picked (each place far from the others, so none
    // borrows another's heights).
    let mut state = 0x5EED_u64;
    let places: Vec<ChunkKey> = std::iter::from_fn(|| Some(random_direction(&mut state)))
        .flatten()
        .take(32)
        .map(|d| chunk_at(&planet, d))
        .collect();
    let mut voxels = ChunkVoxels::new(places[0]);
    group.throughput(Throughput::Elements(32 * 32 * 32 * 32));
    group.bench_function("fill_32_random_places_lod_0", |b| fill_cold(b, &planet, &places, &mut voxels));
    group.throughput(Throughput::Elements(32 * 32 * 32));
    // The voxels alone: the chunk's columns already in the height cache.
    let key = mountain_chunk(&planet);
    let mut voxels = ChunkVoxels::new(key);
    planet.fill_chunk(key, &mut voxels).expect("valid key");
    group.bench_with_input(BenchmarkId::new("fill_mountains_warm_lod", 0), &key, |b, &key| {
        b.iter(|| planet.fill_chunk(key, &mut voxels).expect("valid key"));
    });
    group.finish();

    // Every surface layer of one column, cold: what a streaming view asks
    // for. The layers after the first reuse the column's heights.
    let mut group = c.benchmark_group("voxel_column");
    for lod in [0u8, 8] {
        let column = ChunkColumn { face: CubeFace::PosZ, lod, x: 5, y: 7 };
        let layers: Vec<ChunkKey> =
            planet.surface_chunk_layers(column).expect("on the planet").map(|layer| column.chunk(layer)).collect();
        let mut voxels = ChunkVoxels::new(layers[0]);
        group.throughput(Throughput::Elements(32 * 32 * 32 * layers.len() as u64));
        group.bench_with_input(BenchmarkId::new(format!("fill_{}_layers_lod", layers.len()), lod), &lod, |b, _| {
            fill_cold(b, &planet, &layers, &mut voxels);
        });
    }
    group.finish();

    let keys: Vec<ChunkKey> =
        (0..64).map(|n| surface_chunk(&planet, CubeFace::PosZ, 2, 100 + n % 8, 200 + n / 8)).collect();
    let mut group = c.benchmark_group("voxel_many_chunks");
    group.throughput(Throughput::Elements(64 * 32 * 32 * 32));
    group.sample_size(20);
    let mut voxels = ChunkVoxels::new(keys[0]);
    group.bench_function("sequential_64", |b| fill_cold(b, &planet, &keys, &mut voxels));
    group.bench_function("rayon_64", |b| {
        b.iter_batched(
            || planet.with_empty_cache(),
            |planet| {
                keys.par_iter().for_each_init(
                    || ChunkVoxels::new(keys[0]),
                    |voxels, &key| planet.fill_chunk(key, voxels).expect("valid key"),
                );
            },
            BatchSize::SmallInput,
        );
    });
    group.finish();
}

criterion_group!(benches, generate);
criterion_main!(benches);
