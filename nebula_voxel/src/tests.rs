//! Tests of chunk layout, the procedural planet and edits.

use std::sync::OnceLock;

use proptest::prelude::*;

use crate::*;
use nebula_math::{DVec3, unit_random};

fn small() -> &'static ProceduralPlanet {
    static PLANET: OnceLock<ProceduralPlanet> = OnceLock::new();
    PLANET.get_or_init(|| ProceduralPlanet::new(PlanetSettings::small(7)).unwrap())
}

/// The LOD-0-layer index of the top of the solid voxels in a column (the
/// first air voxel above solid), found by bisection between two layers known
/// to be solid and air.
fn column_top(source: &impl VoxelSource, face: CubeFace, lod: u8, i: u32, j: u32) -> i64 {
    let span = source.layout().voxel_span(lod);
    let limit = (source.layout().sphere().radius() * 0.4 / source.layout().sphere().layer_height()) as i64 / span;
    let solid = |h: i64| source.voxel(VoxelCoord { face, lod, i, j, h: h as i32 }).unwrap().is_solid();
    let (mut low, mut high) = (-limit, limit);
    assert!(solid(low) && !solid(high));
    while high - low > 1 {
        let mid = (low + high) / 2;
        if solid(mid) { low = mid } else { high = mid }
    }
    high * span
}

/// `settings` with every octave at every LOD (`band_limit` 0, the terrain
/// of planets saved before [`PlanetSettings::band_limit`]; the presets
/// leave the octaves a coarse LOD can only alias out).
fn every_octave(settings: PlanetSettings) -> PlanetSettings {
    PlanetSettings { band_limit: 0.0, ..settings }
}

/// A random column of `face` at `lod`, from `unit` (uniform in [0, 1)).
fn random_column_at(layout: &ChunkLayout, face: CubeFace, lod: u8, unit: &mut impl FnMut() -> f64) -> ChunkColumn {
    let per_edge = f64::from(layout.chunks_per_edge(lod));
    ChunkColumn { face, lod, x: (unit() * per_edge) as u32, y: (unit() * per_edge) as u32 }
}

#[test]
fn settings_are_checked() {
    let bad = |change: fn(&mut PlanetSettings)| {
        let mut settings = PlanetSettings::small(1);
        change(&mut settings);
        ProceduralPlanet::new(settings).unwrap_err()
    };
    assert!(matches!(bad(|s| s.radius = f64::NAN), VoxelError::NonFinite { name: "radius", .. }));
    assert!(matches!(bad(|s| s.radius = -1.0), VoxelError::OutOfRange { name: "radius", .. }));
    assert!(matches!(bad(|s| s.voxel_size = 0.0), VoxelError::OutOfRange { name: "voxel size", .. }));
    assert!(matches!(bad(|s| s.voxel_size = 1e-9), VoxelError::OutOfRange { name: "voxel size", .. }));
    assert!(matches!(bad(|s| s.amplitude = f64::INFINITY), VoxelError::NonFinite { name: "amplitude", .. }));
    assert!(matches!(bad(|s| s.amplitude = 500.0), VoxelError::OutOfRange { name: "amplitude", .. }));
    assert!(matches!(bad(|s| s.amplitude = -1.0), VoxelError::OutOfRange { name: "amplitude", .. }));
    assert!(matches!(bad(|s| s.feature_size = 0.0), VoxelError::OutOfRange { name: "feature size", .. }));
    assert!(matches!(bad(|s| s.detail_size = -2.0), VoxelError::OutOfRange { name: "detail size", .. }));
    assert!(matches!(bad(|s| s.detail_amplitude = f64::NAN), VoxelError::NonFinite { name: "detail amplitude", .. }));
    assert!(matches!(bad(|s| s.detail_amplitude = 900.0), VoxelError::OutOfRange { name: "detail amplitude", .. }));
    assert!(matches!(bad(|s| s.octave_grid = f64::NAN), VoxelError::NonFinite { name: "octave grid", .. }));
    assert!(matches!(bad(|s| s.octave_grid = -1.0), VoxelError::OutOfRange { name: "octave grid", .. }));
    assert!(matches!(
        bad(|s| s.octave_grid_error = f64::INFINITY),
        VoxelError::NonFinite { name: "octave grid error", .. }
    ));
    assert!(matches!(bad(|s| s.band_limit = f64::NAN), VoxelError::NonFinite { name: "band limit", .. }));
    assert!(matches!(bad(|s| s.octave_grid_error = -0.5), VoxelError::OutOfRange { name: "octave grid error", .. }));
    assert!(matches!(bad(|s| s.band_limit = -1.0), VoxelError::OutOfRange { name: "band limit", .. }));
    let message = bad(|s| s.radius = -3.0).to_string();
    assert!(message.contains("-3"), "{message}");
}

#[test]
fn keys_and_arrays_are_checked() {
    let layout = small().layout();
    let max = layout.max_lod();
    let key = |lod, x, y, layer| ChunkKey { face: CubeFace::NegZ, lod, x, y, layer };
    assert!(layout.check_key(key(max, 0, 0, 0)).is_ok());
    assert!(matches!(layout.check_key(key(max + 1, 0, 0, 0)), Err(VoxelError::LodOutOfRange { .. })));
    assert!(matches!(layout.check_key(key(max, 1, 0, 0)), Err(VoxelError::ChunkOutOfRange { .. })));
    assert!(matches!(layout.check_key(key(0, 0, 1 << max, 0)), Err(VoxelError::ChunkOutOfRange { .. })));
    assert!(matches!(layout.check_key(key(0, 0, 0, -1_000_000)), Err(VoxelError::ChunkOutOfRange { .. })));
    assert!(matches!(layout.check_key(key(0, 0, 0, i32::MAX)), Err(VoxelError::ChunkOutOfRange { .. })));
    let mut out = ChunkVoxels::new(key(0, 0, 0, 0));
    assert!(small().fill_chunk(key(max + 3, 0, 0, 0), &mut out).is_err());
    assert!(matches!(
        ChunkVoxels::from_voxels(key(0, 0, 0, 0), vec![Voxel::AIR; 32 * 32 * 32]),
        Err(VoxelError::WrongVoxelCount { expected: 39_304, got: 32_768 })
    ));
    assert!(ChunkVoxels::from_voxels(key(0, 0, 0, 0), vec![Voxel::STONE; PADDED_CHUNK_VOLUME]).is_ok());
    assert_eq!(out.get([34, 0, 0]), None);
    assert!(!out.set([0, 34, 0], Voxel::STONE));
    assert!(out.set([33, 33, 33], Voxel::STONE));
    assert_eq!(out.get([33, 33, 33]), Some(Voxel::STONE));
    let at = VoxelCoord { face: CubeFace::PosX, lod: 0, i: 32 << max, j: 0, h: 0 };
    assert!(matches!(small().voxel(at), Err(VoxelError::VoxelOutOfRange { .. })));
}

#[test]
fn a_layout_checks_its_resolution() {
    let sphere = nebula_math::Cubesphere::new(100.0, 64, 1.0, nebula_math::SphereMap::EquiAngular).unwrap();
    assert!(ChunkLayout::new(sphere, 1).is_ok());
    assert!(matches!(
        ChunkLayout::new(sphere, 3),
        Err(VoxelError::ResolutionMismatch { resolution: 64, expected: 256 })
    ));
    assert!(matches!(ChunkLayout::new(sphere, MAX_LOD + 1), Err(VoxelError::LodOutOfRange { .. })));
}

#[test]
fn earth_sized_planet_is_valid() {
    let earth = ProceduralPlanet::new(PlanetSettings::earth(3)).unwrap();
    let layout = earth.layout();
    assert_eq!(layout.max_lod(), 18);
    assert!((earth.voxel_size() - 1.193).abs() < 0.001, "{}", earth.voxel_size());
    // A LOD-0 chunk at the surface, somewhere on face -X.
    let column = ChunkColumn { face: CubeFace::NegX, lod: 0, x: 91_234, y: 200_001 };
    let mut voxels = ChunkVoxels::new(column.chunk(0));
    let layers = earth.surface_chunk_layers(column).unwrap();
    assert!(layers.end() - layers.start() < 8, "{layers:?}");
    let mut solid = 0;
    for layer in layers.clone() {
        earth.fill_chunk(column.chunk(layer), &mut voxels).unwrap();
        solid += voxels.solid_count();
    }
    assert!(solid > 0 && solid < 32 * 32 * 32 * (layers.count()), "{solid}");
    println!(
        "earth: max slope S = {:.2} layers/cell, δ(1) = {:.2} m, δ(10) = {:.0} m",
        earth.max_slope(),
        earth.geometric_error(1),
        earth.geometric_error(10)
    );
    // Chunk origins at Earth scale stay on the sphere.
    let origin = layout.chunk_origin(column.chunk(0)).unwrap();
    assert!((origin.length() - 6_371_000.0).abs() < 1e-6);
}

#[test]
fn geometric_error_bounds_the_voxel_tops() {
    for settings in [PlanetSettings::small(7), every_octave(PlanetSettings::small(7))] {
        geometric_error_bounds_the_voxel_tops_on(&ProceduralPlanet::new(settings).unwrap());
    }
}

/// [`geometric_error_bounds_the_voxel_tops`] on one planet.
fn geometric_error_bounds_the_voxel_tops_on(planet: &ProceduralPlanet) {
    // For random coarse columns, every LOD-0 column below has its top within
    // δ(L) of the coarse top (places unrelated to the ones S was measured at).
    let layout = planet.layout();
    let mut worst_ratio = 0.0_f64;
    let mut state = 12345u64;
    for sample in 0..48 {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let lod = 1 + (sample % 4) as u8;
        let face = CubeFace::ALL[sample % 6];
        let per_edge = layout.voxels_per_edge(lod);
        let (ci, cj) = ((state >> 20) as u32 % per_edge, (state >> 40) as u32 % per_edge);
        let coarse_top = column_top(planet, face, lod, ci, cj);
        let span = layout.voxel_span(lod) as u32;
        let bound = planet.geometric_error(lod) / layout.sphere().layer_height();
        for a in 0..span {
            for b in 0..span {
                let fine_top = column_top(planet, face, 0, ci * span + a, cj * span + b);
                let error = (fine_top - coarse_top).abs() as f64;
                assert!(error <= bound, "LOD {lod} column ({ci}, {cj}): error {error} > bound {bound}");
                worst_ratio = worst_ratio.max(error / bound);
            }
        }
    }
    // How loose δ may be is S's to say (`max_slope_holds_where_the_mountains_are_steepest`):
    // S is the steepest anywhere, and these places are anywhere.
    println!("worst voxel-top error / δ bound: {worst_ratio:.2} (S = {:.2})", planet.max_slope());
}

/// The top voxels of an Earth's land follow its climate: deserts only in
/// the subtropical belts (and there only inland), forests in the wet belts
/// (tropical and temperate) and none in the dry subtropics, rock on the
/// mountains, snow towards the poles, sand at the shores.
#[test]
fn biomes_follow_latitude_coasts_and_mountains() {
    let planet = &ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
    let sphere = planet.layout().sphere();
    let mut state = 77_u64;
    // Top materials of land columns by 10° band of latitude.
    let mut bands = [[0_usize; 8]; 9];
    let mut land = 0;
    while land < 6000 {
        let d = DVec3::new(
            unit_random(&mut state) * 2.0 - 1.0,
            unit_random(&mut state) * 2.0 - 1.0,
            unit_random(&mut state) * 2.0 - 1.0,
        );
        if !(0.1..=1.0).contains(&d.length()) || planet.height_at(d.normalize()) < 0.0 {
            continue;
        }
        land += 1;
        let d = d.normalize();
        let (face, i, j) = sphere.face_coords_of(d * sphere.radius()).unwrap();
        let top = column_top(planet, face, 0, i as u32, j as u32);
        let voxel = planet.voxel(VoxelCoord { face, lod: 0, i: i as u32, j: j as u32, h: (top - 1) as i32 }).unwrap();
        let band = (d.z.abs().asin().to_degrees() / 10.0) as usize;
        bands[band.min(8)][usize::from(voxel.material())] += 1;
    }
    let share = |band: usize, voxel: Voxel| {
        bands[band][usize::from(voxel.material())] as f64 / bands[band].iter().sum::<usize>().max(1) as f64
    };
    for (band, counts) in bands.iter().enumerate() {
        println!("{:2}–{:2}°: {counts:?}", band * 10, band * 10 + 10);
    }
    // Sand inland in the subtropics only (the shore's sand is a sliver).
    let subtropical_sand = share(2, Voxel::SAND).max(share(1, Voxel::SAND));
    assert!(subtropical_sand > 0.04, "no subtropical deserts: {subtropical_sand}");
    for band in [0, 4, 5, 6] {
        assert!(share(band, Voxel::SAND) < 0.02, "sand at {band}0°: {}", share(band, Voxel::SAND));
    }
    assert!(share(0, Voxel::FOREST) > 0.25 && share(5, Voxel::FOREST) > 0.25, "no tropical or temperate forest");
    assert!(share(2, Voxel::FOREST) < 0.05, "forest in the dry subtropics: {}", share(2, Voxel::FOREST));
    assert!(share(3, Voxel::STONE) + share(4, Voxel::STONE) > 0.005, "no rock on the mountains");
    assert!(share(8, Voxel::SNOW) > 0.9 && share(0, Voxel::SNOW) < 0.01, "snow not by latitude");
}

/// The steepest steps of H between neighbouring lattice cells, hunted
/// where they are (high up, on the mountains: the steepest of many random
/// places up there, then climbing from those to steeper places nearby),
/// stay within S, and S is within a few times of them. On an
/// Earth, H's own steepest step at 4,096 random places, times 1.5 (how
/// the first version measured S), falls short of them: mountains are
/// steepest along their crests, which random places seldom hit.
#[test]
fn max_slope_holds_where_the_mountains_are_steepest() {
    let earth = &ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
    for (planet, places) in [(earth, 200_000), (small(), 60_000)] {
        let sphere = planet.layout().sphere();
        let (n, layer) = (f64::from(sphere.resolution()), sphere.layer_height());
        let height = |face: CubeFace, i: f64, j: f64| planet.height_at(sphere.direction(face, i, j)) / layer;
        let high_up = 0.3 * planet.settings().amplitude / layer;
        let mut state = 41_u64;
        let mut next = || unit_random(&mut state);
        let step_at = |face: CubeFace, i: f64, j: f64| {
            let (i, j) = (i.clamp(0.0, n - 2.0), j.clamp(0.0, n - 2.0));
            let here = height(face, i, j);
            (height(face, i + 1.0, j) - here).abs().max((height(face, i, j + 1.0) - here).abs())
        };
        let mut steepest_at_random = 0.0_f64;
        let mut found = Vec::new();
        for k in 0..places {
            let face = CubeFace::ALL[k % 6];
            let (i, j) = (next() * (n - 2.0), next() * (n - 2.0));
            if k < 4096 {
                steepest_at_random = steepest_at_random.max(step_at(face, i, j));
            } else if height(face, i, j) >= high_up {
                found.push((step_at(face, i, j), face, i, j));
            }
        }
        found.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut steepest = steepest_at_random;
        for &(mut step, face, mut i, mut j) in found.iter().take(16) {
            for _ in 0..300 {
                let reach = 1.0 + next() * 24.0;
                let (a, b) = (i + (next() * 2.0 - 1.0) * reach, j + (next() * 2.0 - 1.0) * reach);
                let there = step_at(face, a, b);
                if there > step {
                    (step, i, j) = (there, a, b);
                }
            }
            steepest = steepest.max(step);
        }
        let s = planet.max_slope();
        println!("S = {s:.2}, steepest found {steepest:.2}, at random places ×1.5 {:.2}", steepest_at_random * 1.5);
        assert!(steepest <= s, "a step of {steepest} layers beyond S = {s}");
        assert!(s < 4.0 * steepest, "S = {s} is far above the steepest step found, {steepest}");
        if std::ptr::eq(planet, earth) {
            assert!(steepest_at_random * 1.5 < steepest, "random places found the steepest: {steepest_at_random}");
        }
    }
}

#[test]
fn edits_show_at_lod_0_survive_refills_and_mark_dirty_chunks() {
    let mut edited = EditedSource::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
    let layout = *edited.layout();
    // The top solid voxel of a column on a chunk's +U border.
    let (face, i, j) = (CubeFace::PosZ, 31, 40);
    let top = column_top(&edited, face, 0, i, j) as i32;
    let at = VoxelCoord { face, lod: 0, i, j, h: top - 1 };
    assert!(edited.voxel(at).unwrap().is_solid());
    let dirty = edited.set_voxel(at, Voxel::AIR).unwrap();
    let key = layout.chunk_of(at);
    assert!(dirty.contains(&key));
    assert!(dirty.contains(&layout.neighbor(key, FaceEdge::PosU)), "neighbour holding it as padding");
    assert!(dirty.iter().all(|k| k.lod == 0), "one voxel changes no coarse voxel: {dirty:?}");
    assert_eq!(edited.voxel(at).unwrap(), Voxel::AIR);
    let mut voxels = ChunkVoxels::new(key);
    for _ in 0..2 {
        edited.fill_chunk(key, &mut voxels).unwrap();
        let local = [at.i % 32 + 1, (at.h.rem_euclid(32) + 1) as u32, at.j % 32 + 1];
        assert_eq!(voxels.get(local), Some(Voxel::AIR));
    }
    // The neighbour sees it in its padding (x = 0).
    edited.fill_chunk(layout.neighbor(key, FaceEdge::PosU), &mut voxels).unwrap();
    assert_eq!(voxels.get([0, (at.h.rem_euclid(32) + 1) as u32, at.j % 32 + 1]), Some(Voxel::AIR));
    // Setting it back to what the base has removes the edit entirely.
    let base = edited.base().voxel(at).unwrap();
    edited.set_voxel(at, base).unwrap();
    assert_eq!(edited.edits().count(), 0);
    assert!(edited.set_voxel(VoxelCoord { lod: 1, ..at }, Voxel::AIR).is_err());
}

/// An edit in a chunk's corner column is padding of the chunks across the
/// corner too (the mesher reads padding corners for the light at a
/// chunk's corner edges): on a face and across a cube-face edge, every
/// chunk whose padded region holds the edited voxel is dirty and shows it.
#[test]
fn an_edit_at_a_chunk_corner_reaches_the_chunks_across_the_corner() {
    let planet = ProceduralPlanet::new(PlanetSettings::small(7)).unwrap();
    let layout = *planet.layout();
    let last = layout.voxels_per_edge(0) - 1;
    for (i, j) in [(5 * CHUNK_SIZE + CHUNK_SIZE - 1, 9 * CHUNK_SIZE), (last, 3 * CHUNK_SIZE + CHUNK_SIZE - 1)] {
        let mut edited = EditedSource::new(planet.clone());
        let top = column_top(&edited, CubeFace::PosY, 0, i, j);
        // Low in the chunk's top voxel layer's air: a block on the ground.
        let at = VoxelCoord { face: CubeFace::PosY, lod: 0, i, j, h: top as i32 };
        let dirty = edited.set_voxel(at, Voxel::STONE).unwrap();
        // Every chunk around at the same layer whose padded region holds it.
        let per_edge = i64::from(layout.voxels_per_edge(0));
        let mut holders = 0;
        for key in dirty.iter().filter(|k| k.lod == 0) {
            let mut voxels = ChunkVoxels::new(*key);
            edited.fill_chunk(*key, &mut voxels).unwrap();
            let size = i64::from(CHUNK_SIZE);
            for (x, z) in
                (0..PADDED_CHUNK_SIZE * PADDED_CHUNK_SIZE).map(|n| (n % PADDED_CHUNK_SIZE, n / PADDED_CHUNK_SIZE))
            {
                let (ci, cj) = (i64::from(key.x) * size + i64::from(x) - 1, i64::from(key.y) * size + i64::from(z) - 1);
                let y = i64::from(at.h) - i64::from(key.layer) * size + 1;
                if key.face.wrap_cell(ci, cj, per_edge) == Some((at.face, i64::from(i), i64::from(j)))
                    && (0..i64::from(PADDED_CHUNK_SIZE)).contains(&y)
                {
                    assert_eq!(voxels.get([x, y as u32, z]), Some(Voxel::STONE), "{key:?} padded ({x}, {y}, {z})");
                    holders += 1;
                }
            }
        }
        // The chunk, the two across its sides and the one across the corner
        // (on a cube edge, two of them on the neighbour face).
        assert_eq!(holders, 4, "chunks showing the edit at ({i}, {j})");
    }
}

#[test]
fn a_crater_across_a_face_edge_shows_at_coarse_lods_and_replays() {
    let mut edited = EditedSource::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
    let layout = *edited.layout();
    let sphere = *layout.sphere();
    let n = f64::from(sphere.resolution());
    // On the edge between +X and its +V neighbour (+Z), at the surface.
    let face = CubeFace::PosX;
    let other_face = face.neighbor(FaceEdge::PosV).face;
    let direction = sphere.direction(face, n / 2.0, n);
    let top = column_top(&edited, face, 0, (n / 2.0) as u32, (n - 1.0) as u32);
    let center = direction * sphere.layer_radius(top as f64);
    let radius = 12.0 * sphere.layer_height();
    let dirty = edited.fill_sphere(center, radius, Voxel::AIR).unwrap();
    let faces: std::collections::BTreeSet<_> = dirty.iter().map(|k| k.face).collect();
    assert!(faces.contains(&face) && faces.contains(&other_face), "{faces:?}");
    let max_dirty_lod = dirty.iter().map(|k| k.lod).max().unwrap();
    assert!(max_dirty_lod >= 3, "a 24-voxel crater reaches LOD 3: {max_dirty_lod}");
    // The crater centre is air at LOD 0 and at LOD 3 on both faces.
    for lod in [0, 3] {
        for f in [face, other_face] {
            let (fi, fj) = {
                let (g, a, b) = sphere.face_coords_of(center * 0.999_99).unwrap();
                if g == f {
                    (a, b)
                } else {
                    // The point on the other face: step just across the edge.
                    let other = sphere.face_coords_of(center + f.normal().as_dvec3() * 2.0).unwrap();
                    (other.1, other.2)
                }
            };
            let span = layout.voxel_span(lod) as f64;
            let at = VoxelCoord {
                face: f,
                lod,
                i: ((fi / span) as u32).min(layout.voxels_per_edge(lod) - 1),
                j: ((fj / span) as u32).min(layout.voxels_per_edge(lod) - 1),
                h: ((top as f64 - 2.0) / span).floor() as i32,
            };
            assert_eq!(edited.voxel(at).unwrap(), Voxel::AIR, "{at:?}");
        }
    }
    // Filled chunks agree with single-voxel reads, and a replay of the saved
    // edits on a fresh planet gives the same voxels.
    let mut replay = EditedSource::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
    for (at, voxel) in edited.edits().collect::<Vec<_>>() {
        replay.set_voxel(at, voxel).unwrap();
    }
    let (mut a, mut b) = (ChunkVoxels::new(dirty[0]), ChunkVoxels::new(dirty[0]));
    for &key in &dirty {
        edited.fill_chunk(key, &mut a).unwrap();
        replay.fill_chunk(key, &mut b).unwrap();
        assert_eq!(a, b, "{key:?}");
    }
    // Bounds include the crater floor.
    for &key in &dirty {
        let bounds = edited.surface_bounds(key.column()).unwrap();
        assert!(bounds.min_layer < top - 12, "{bounds:?}");
    }
    assert!(edited.fill_sphere(center, f64::NAN, Voxel::AIR).is_err());
    assert!(edited.fill_sphere(center, 1e6, Voxel::AIR).is_err());
}

/// The height cache is invisible: chunks filled through a warm cache (the
/// column's other layers, the same x and y at another LOD and face just
/// before, more columns than the cache holds, evicted columns again) equal
/// chunks from a copy of the planet with an empty cache.
#[test]
fn cached_heights_give_the_same_voxels() {
    let warm = ProceduralPlanet::new(PlanetSettings::small(3)).unwrap();
    let columns: Vec<ChunkColumn> = (0..320u32)
        .map(|n| {
            let lod = (n / 2 % 4) as u8;
            let per_edge = warm.layout().chunks_per_edge(lod + 1);
            // Pairs share x and y at two LODs (and faces, every third pair).
            let (x, y) = ((n / 2 * 7) % per_edge, (n / 2 * 3) % per_edge);
            ChunkColumn { face: CubeFace::ALL[(n / 6 + n % 2) as usize % 6], lod: lod + (n % 2) as u8, x, y }
        })
        .collect();
    let mut checked = 0;
    for column in columns.iter().chain(&columns[..16]) {
        for layer in warm.surface_chunk_layers(*column).unwrap() {
            let key = column.chunk(layer);
            let (mut cached, mut cold) = (ChunkVoxels::new(key), ChunkVoxels::new(key));
            warm.fill_chunk(key, &mut cached).unwrap();
            warm.with_empty_cache().fill_chunk(key, &mut cold).unwrap();
            assert_eq!(cached, cold, "{key:?}");
            checked += 1;
        }
    }
    assert!(checked > 336, "only {checked} chunks checked");
}

/// The surface bounds the LOD tree asks for while it splits (each node,
/// then its four children, then theirs, sharing corner and centre
/// heights through the planet's memo) equal the bounds from a copy with
/// an empty cache, on every face of Earth and the small planet.
#[test]
fn surface_bounds_through_the_height_memo_equal_cold_ones() {
    let mut checked = 0;
    for settings in [PlanetSettings::earth(6), PlanetSettings::small(6)] {
        let warm = ProceduralPlanet::new(settings).unwrap();
        let max_lod = warm.layout().max_lod();
        for face in CubeFace::ALL {
            // Down one branch of the face's quadtree, every child of each
            // node on the way, as a splitting tree asks.
            let mut column = ChunkColumn { face, lod: max_lod, x: 0, y: 0 };
            while column.lod > 0 {
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let child = ChunkColumn { face, lod: column.lod - 1, x: column.x * 2 + dx, y: column.y * 2 + dy };
                    let cold = warm.with_empty_cache().surface_bounds(child).unwrap();
                    assert_eq!(warm.surface_bounds(child).unwrap(), cold, "{child:?}");
                    checked += 1;
                }
                let turn = u32::from(column.lod) % 4;
                column =
                    ChunkColumn { face, lod: column.lod - 1, x: column.x * 2 + turn % 2, y: column.y * 2 + turn / 2 };
            }
        }
    }
    assert!(checked >= 2 * 6 * 4 * 6, "only {checked} bounds checked");
}

/// Coarse LODs band-limited (`PlanetSettings::band_limit`): LOD 0 holds the same voxels with and without it (saved
/// edits, picking and walking read LOD 0), and coarse chunks over high
/// mountains differ, with fewer faces between solid and air (the bumps
/// that octaves sampled a few times a wavelength add are gone). That
/// their tops stay within δ of LOD 0, and within the surface bounds and
/// tight tops, the tests of those check on band-limited planets too.
#[test]
fn band_limited_coarse_lods_keep_lod_0_and_lose_aliased_faces() {
    let on = ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
    let off = ProceduralPlanet::new(every_octave(PlanetSettings::earth(11))).unwrap();
    assert!(on.settings().band_limit > 0.0, "the preset is band-limited");
    let layout = *on.layout();
    // Faces between a solid voxel and air, inside the chunk and to its padding.
    let faces = |voxels: &ChunkVoxels| {
        let solid = |p: [u32; 3]| voxels.get(p).is_some_and(Voxel::is_solid);
        let mut count = 0;
        for p in (1..33u32).flat_map(|x| (1..33u32).flat_map(move |y| (1..33u32).map(move |z| [x, y, z]))) {
            if solid(p) {
                for axis in 0..3 {
                    for step in [-1i32, 1] {
                        let mut q = p;
                        q[axis] = q[axis].wrapping_add_signed(step);
                        count += usize::from(!solid(q));
                    }
                }
            }
        }
        count
    };
    // Columns over high mountains (H over 1,500 m), from a fixed seed.
    let mut state = 0x0B1_u64;
    let mut mountains = Vec::new();
    while mountains.len() < 6 {
        let mut unit = || unit_random(&mut state) * 2.0 - 1.0;
        let Some(direction) = DVec3::new(unit(), unit(), unit()).try_normalize() else { continue };
        if on.height_at(direction) >= 1_500.0 {
            mountains.push(direction);
        }
    }
    let (mut lod_0_voxels, mut coarse_differ) = (0, 0);
    let (mut faces_on, mut faces_off) = (0, 0);
    let mut chunk_on = ChunkVoxels::new(ChunkKey { face: CubeFace::PosX, lod: 0, x: 0, y: 0, layer: 0 });
    let mut chunk_off = chunk_on.clone();
    for (n, direction) in mountains.iter().enumerate() {
        for lod in [0u8, 2, 4, 6] {
            let at = layout.voxel_at(*direction * layout.sphere().radius()).unwrap();
            let span = layout.voxel_span(lod) as u32;
            let column = ChunkColumn { face: at.face, lod, x: at.i / span / 32, y: at.j / span / 32 };
            let (a, b) = (on.surface_chunk_layers(column).unwrap(), off.surface_chunk_layers(column).unwrap());
            for layer in *a.start().min(b.start())..=*a.end().max(b.end()) {
                on.fill_chunk(column.chunk(layer), &mut chunk_on).unwrap();
                off.fill_chunk(column.chunk(layer), &mut chunk_off).unwrap();
                if lod == 0 {
                    assert!(chunk_on.as_slice() == chunk_off.as_slice(), "mountain {n}: LOD 0 layer {layer} differs");
                    lod_0_voxels += chunk_on.as_slice().len();
                } else {
                    coarse_differ +=
                        chunk_on.as_slice().iter().zip(chunk_off.as_slice()).filter(|(x, y)| x != y).count();
                    faces_on += faces(&chunk_on);
                    faces_off += faces(&chunk_off);
                }
            }
        }
    }
    println!(
        "LOD 0: {lod_0_voxels} voxels the same; LODs 2, 4, 6: {coarse_differ} voxels differ, faces {faces_off} → \
         {faces_on} band-limited"
    );
    assert!(lod_0_voxels > 0 && coarse_differ > 0, "the band limit changed nothing where it should");
    assert!(faces_on < faces_off, "{faces_on} faces band-limited against {faces_off}");
}

/// A chunk's voxels, whose column heights are computed all at once
/// (octave by octave, sharing noise cells), equal the voxels read one at a
/// time: Earth and the small planet, surface chunks from LOD 0 to near the
/// coarsest, on every face.
#[test]
fn filled_chunks_equal_voxels_read_one_by_one() {
    let mut checked = 0;
    for (planet, lods) in [
        (ProceduralPlanet::new(PlanetSettings::earth(5)).unwrap(), [0u8, 3, 9, 16]),
        (ProceduralPlanet::new(every_octave(PlanetSettings::earth(5))).unwrap(), [0u8, 2, 5, 12]),
        (ProceduralPlanet::new(PlanetSettings::small(5)).unwrap(), [0u8, 1, 3, 5]),
    ] {
        let layout = *planet.layout();
        for (n, lod) in lods.into_iter().enumerate() {
            let per_edge = layout.chunks_per_edge(lod);
            let face = CubeFace::ALL[(n + usize::from(lod)) % 6];
            let column = ChunkColumn { face, lod, x: per_edge / 3, y: (per_edge * 2 / 3).min(per_edge - 1) };
            let key = column.chunk(*planet.surface_chunk_layers(column).unwrap().start());
            let mut voxels = ChunkVoxels::new(key);
            planet.fill_chunk(key, &mut voxels).unwrap();
            for (x, y, z) in (0..32u32).flat_map(|x| (0..32u32).flat_map(move |y| (0..32u32).map(move |z| (x, y, z)))) {
                let at = VoxelCoord { face, lod, i: key.x * 32 + x, j: key.y * 32 + z, h: key.layer * 32 + y as i32 };
                assert_eq!(voxels.get([x + 1, y + 1, z + 1]), Some(planet.voxel(at).unwrap()), "{at:?}");
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 12 * 32 * 32 * 32);
}

/// Fills every surface chunk of `column` from `warm` (its height cache as
/// earlier fills left it) and from a copy with an empty cache, asserts they are equal,
/// and returns how many chunks it compared.
fn assert_fills_as_cold(warm: &ProceduralPlanet, column: ChunkColumn) -> usize {
    let mut checked = 0;
    for layer in warm.surface_chunk_layers(column).unwrap() {
        let key = column.chunk(layer);
        let (mut cached, mut cold) = (ChunkVoxels::new(key), ChunkVoxels::new(key));
        warm.fill_chunk(key, &mut cached).unwrap();
        warm.with_empty_cache().fill_chunk(key, &mut cold).unwrap();
        assert!(cached == cold, "{key:?}");
        checked += 1;
    }
    checked
}

/// A column filled just after its parent (whose heights it shares every
/// other column of) equals the same column from a cold planet: all four
/// children, at face edges and corners too, on Earth and the small planet.
#[test]
fn columns_after_their_parent_give_the_same_voxels() {
    let mut checked = 0;
    for settings in [PlanetSettings::earth(4), PlanetSettings::small(4)] {
        let warm = ProceduralPlanet::new(settings).unwrap();
        for (n, lod) in [1u8, 2, 5].into_iter().enumerate() {
            let per_edge = warm.layout().chunks_per_edge(lod + 1);
            let face = CubeFace::ALL[n * 2];
            for (px, py) in [(0, 0), (per_edge - 1, 0), (per_edge / 2, per_edge - 1), (per_edge / 3, per_edge / 3)] {
                let parent = ChunkColumn { face, lod: lod + 1, x: px, y: py };
                let layer = *warm.surface_chunk_layers(parent).unwrap().start();
                warm.fill_chunk(parent.chunk(layer), &mut ChunkVoxels::new(parent.chunk(layer))).unwrap();
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let child = ChunkColumn { face, lod, x: px * 2 + dx, y: py * 2 + dy };
                    checked += assert_fills_as_cold(&warm, child);
                }
            }
        }
    }
    assert!(checked >= 96, "only {checked} chunks checked");
}

/// Columns filled after some of their neighbours (whose cached heights
/// they copy for their padding ring and edge rows) hold the voxels of a
/// cold fill, at face edges and corners too.
#[test]
fn columns_after_their_neighbours_give_the_same_voxels() {
    let mut checked = 0;
    for settings in [PlanetSettings::earth(5), PlanetSettings::small(5)] {
        let warm = ProceduralPlanet::new(settings).unwrap();
        // LODs with at least 2×2 columns per face.
        for (n, lod) in [0u8, 2, 4].into_iter().enumerate() {
            let per_edge = warm.layout().chunks_per_edge(lod);
            assert!(per_edge >= 2);
            let face = CubeFace::ALL[n * 2 + 1];
            for (x, y) in [(0, 0), (per_edge - 2, 1), (per_edge / 2, per_edge - 2), (per_edge / 3, per_edge / 3)] {
                // A 2×2 block of columns in order: each later one finds
                // one to three of its neighbours cached.
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    checked += assert_fills_as_cold(&warm, ChunkColumn { face, lod, x: x + dx, y: y + dy });
                }
            }
        }
    }
    assert!(checked >= 48, "only {checked} chunks checked");
}

/// The materials of the solid voxels in a column's surface chunks (not
/// their padding), and the radius of the highest one's top.
fn surface_materials(planet: &ProceduralPlanet, column: ChunkColumn) -> (std::collections::HashSet<Voxel>, f64) {
    let layout = planet.layout();
    let span = layout.voxel_span(column.lod);
    let mut found = std::collections::HashSet::new();
    let mut top = f64::NEG_INFINITY;
    let mut voxels = ChunkVoxels::new(column.chunk(0));
    for layer in planet.surface_chunk_layers(column).unwrap() {
        planet.fill_chunk(column.chunk(layer), &mut voxels).unwrap();
        for z in 1..=CHUNK_SIZE {
            for y in 1..=CHUNK_SIZE {
                for x in 1..=CHUNK_SIZE {
                    let voxel = voxels.get([x, y, z]).unwrap();
                    if voxel.is_solid() {
                        found.insert(voxel);
                        let h = i64::from(layer) * i64::from(CHUNK_SIZE) + i64::from(y) - 1;
                        top = top.max(layout.sphere().layer_radius(((h + 1) * span) as f64));
                    }
                }
            }
        }
    }
    (found, top)
}

/// On an Earth, at every LOD up to a twentieth of a face, the voxel tops of
/// columns lie within their column's bounds; and from LOD 8 up those are
/// most often several times narrower than the steepest slope allows over
/// the column (the noise's own ranges, `ProceduralPlanet::sum_ranges`).
#[test]
fn earth_surface_bounds_hold_the_tops_and_stay_narrow() {
    for settings in [PlanetSettings::earth(11), every_octave(PlanetSettings::earth(11))] {
        earth_surface_bounds_hold_the_tops_and_stay_narrow_on(&ProceduralPlanet::new(settings).unwrap());
    }
}

/// [`earth_surface_bounds_hold_the_tops_and_stay_narrow`] on one planet.
fn earth_surface_bounds_hold_the_tops_and_stay_narrow_on(planet: &ProceduralPlanet) {
    let layout = planet.layout();
    let mut state = 23_u64;
    let mut next = || unit_random(&mut state);
    let mut ratios = Vec::new();
    for n in 0..150 {
        let lod = (n % 15) as u8;
        let column = random_column_at(layout, CubeFace::ALL[n % 6], lod, &mut next);
        let bounds = planet.surface_bounds(column).unwrap();
        let span = layout.voxel_span(lod);
        for _ in 0..6 {
            let (a, b) = ((next() * 32.0) as u32, (next() * 32.0) as u32);
            let top = column_top(planet, column.face, lod, column.x * 32 + a, column.y * 32 + b);
            assert!(
                top - span >= bounds.min_layer && top - 1 <= bounds.max_layer,
                "{column:?}: top {top} outside {bounds:?}"
            );
        }
        if lod >= 8 {
            let slope_width = planet.max_slope() * f64::from(CHUNK_SIZE) * span as f64;
            ratios.push(slope_width / (bounds.max_layer - bounds.min_layer) as f64);
        }
    }
    ratios.sort_by(f64::total_cmp);
    println!("slope bound / these bounds from LOD 8 up: {ratios:.1?}");
    assert!(ratios[ratios.len() / 2] > 2.0, "{ratios:?}");
}

/// On an Earth, a column's tight top ([`VoxelSource::surface_top_radius`])
/// holds its highest voxel at its own LOD and at LOD 0 (each found where a
/// 17 × 17 grid of H peaks, and at random columns), and at LODs 5–8 over
/// land (50–300 km from an eye near the ground: the far columns a narrow
/// lens might hide) it often lies well under the bounds' top. The control:
/// a 9 × 9 grid of H alone (no allowance for the slope between samples)
/// misses the 17 × 17 grid's peak.
#[test]
fn earth_surface_tops_hold_every_lod_and_are_tighter_than_the_bounds() {
    for settings in [PlanetSettings::earth(11), every_octave(PlanetSettings::earth(11))] {
        earth_surface_tops_hold_every_lod_and_are_tighter_than_the_bounds_on(&ProceduralPlanet::new(settings).unwrap());
    }
}

/// [`earth_surface_tops_hold_every_lod_and_are_tighter_than_the_bounds`] on one planet.
fn earth_surface_tops_hold_every_lod_and_are_tighter_than_the_bounds_on(planet: &ProceduralPlanet) {
    let layout = planet.layout();
    let sphere = layout.sphere();
    let mut state = 29_u64;
    let mut next = || unit_random(&mut state);
    let (mut lowered, mut checked, mut missed_peaks) = (Vec::new(), 0, 0);
    for n in 0..120 {
        // Every LOD, then LODs 5–8 again.
        let lod = if n < 60 { (n % 15) as u8 } else { 5 + (n % 4) as u8 };
        let column = random_column_at(layout, CubeFace::ALL[n % 6], lod, &mut next);
        let top = planet.surface_top_radius(column).unwrap();
        let bounds = planet.surface_bounds(column).unwrap();
        assert!(top <= bounds.max_radius, "{column:?}: top {top} over the bounds' {}", bounds.max_radius);
        let span = layout.voxel_span(lod);
        let cells = (i64::from(CHUNK_SIZE) * span) as f64;
        // LOD-0 column (i, j) at (a, b) across the patch, and its H.
        let at = |a: f64, b: f64| {
            let (x, y) = (f64::from(column.x), f64::from(column.y));
            ((x * cells + a * cells).min((x + 1.0) * cells - 1.0), (y * cells + b * cells).min((y + 1.0) * cells - 1.0))
        };
        let height = |(i, j): (f64, f64)| planet.height_at(sphere.direction(column.face, i + 0.5, j + 0.5));
        let grid = |n: u32| {
            (0..=n).flat_map(move |a| (0..=n).map(move |b| (f64::from(a) / f64::from(n), f64::from(b) / f64::from(n))))
        };
        let peak_of =
            |n: u32| grid(n).map(|(a, b)| (height(at(a, b)), (a, b))).max_by(|x, y| x.0.total_cmp(&y.0)).unwrap();
        let (peak, coarse_peak) = (peak_of(16), peak_of(8));
        missed_peaks += usize::from(peak.0 > coarse_peak.0 + 0.5 * sphere.layer_height());
        let mut places = vec![peak.1];
        places.extend((0..4).map(|_| (next(), next())));
        for (a, b) in places {
            let (i, j) = at(a, b);
            let lod_0 = column_top(planet, column.face, 0, i as u32, j as u32);
            let own = column_top(planet, column.face, lod, (i as i64 / span) as u32, (j as i64 / span) as u32);
            for voxel_top in [lod_0, own] {
                let radius = sphere.layer_radius(voxel_top as f64);
                assert!(radius <= top, "{column:?}: a voxel's top {radius} over the tight top {top}");
                checked += 1;
            }
        }
        if (5..=8).contains(&lod) && height(at(0.5, 0.5)) > 0.0 {
            lowered.push(bounds.max_radius - top);
        }
    }
    lowered.sort_by(f64::total_cmp);
    println!(
        "{checked} voxel tops under their tight tops; over land at LODs 5–8 the tight top lies under the bounds' by \
         {lowered:.0?} m; a 9 × 9 grid misses the 17 × 17 peak by over half a layer in {missed_peaks} columns"
    );
    let well_under = lowered.iter().filter(|&&d| d > 10.0).count();
    assert!(well_under * 3 >= lowered.len(), "{lowered:?}");
    assert!(missed_peaks > 0, "the control cannot tell");
}

/// A column said to be sea bed below a radius holds no other solid voxel,
/// at any latitude, and nothing above that radius; and the snow line is
/// why "under sea level" is not enough: near the poles, columns wholly
/// under the sea hold snow (polar ice).
#[test]
fn sea_bed_below_holds_nothing_but_sea_bed_below() {
    let planet = &ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
    let layout = planet.layout();
    let sea = layout.sphere().radius();
    let mut state = 17_u64;
    let (mut sea_bed, mut polar_ice) = (0, 0);
    for n in 0..200 {
        let lod = 2 + (unit_random(&mut state) * 10.0) as u8;
        let per_edge = f64::from(layout.chunks_per_edge(lod));
        // Half the columns near a pole, where the snow line is under the sea.
        let (face, spread) = if n % 2 == 0 {
            ([CubeFace::PosZ, CubeFace::NegZ][n / 2 % 2], 0.3)
        } else {
            (CubeFace::ALL[n / 2 % 6], 1.0)
        };
        let mut at = || ((0.5 + (unit_random(&mut state) - 0.5) * spread) * per_edge) as u32;
        let column = ChunkColumn { face, lod, x: at(), y: at() };
        let below = sea - 4.0 * unit_random(&mut state) * layout.sphere().layer_height();
        let (materials, top) = surface_materials(planet, column);
        if planet.sea_bed_below(column, below).unwrap() {
            sea_bed += 1;
            assert_eq!(materials, [Voxel::SEABED].into(), "{column:?} is not all sea bed");
            assert!(top <= below, "{column:?}: a voxel top at {top} over {below}");
            let bounds = planet.surface_bounds(column).unwrap();
            assert!(!bounds.sea_bed_only || materials == [Voxel::SEABED].into());
        } else if top < sea && materials.contains(&Voxel::SNOW) {
            polar_ice += 1;
        }
    }
    println!("{sea_bed} columns all sea bed, {polar_ice} under the sea with polar ice");
    assert!(sea_bed >= 30, "too few sea-bed columns to say anything: {sea_bed}");
    assert!(polar_ice >= 3, "no polar ice under the sea: the snow-line clause is untested ({polar_ice})");
}

fn any_face() -> impl Strategy<Value = CubeFace> {
    (0usize..6).prop_map(|i| CubeFace::ALL[i])
}

/// Random padded voxels: air above a random ground per column, with random
/// holes and overhangs, several materials, and some columns recorded as
/// covered above (or no record at all).
fn random_chunk(seed: u64, record_cover: bool) -> ChunkVoxels {
    let mut state = seed | 1;
    let mut voxels = ChunkVoxels::new(ChunkKey { face: CubeFace::PosX, lod: 0, x: 0, y: 0, layer: 0 });
    for z in 0..PADDED_CHUNK_SIZE {
        for x in 0..PADDED_CHUNK_SIZE {
            let ground = (unit_random(&mut state) * 40.0) as u32;
            for y in 0..PADDED_CHUNK_SIZE {
                let roll = unit_random(&mut state);
                let solid = if y < ground { roll > 0.1 } else { roll < 0.05 };
                let material = 1 + (unit_random(&mut state) * 3.0) as u8;
                voxels.set([x, y, z], if solid { Voxel::from_material(material) } else { Voxel::AIR });
            }
            if record_cover {
                voxels.set_covered_above((x, z), unit_random(&mut state) < 0.3);
            }
        }
    }
    voxels
}

/// [`ChunkVoxels::sky_floors`] as it was read, column by column down from
/// the top: the reference the row-mask version must equal.
fn sky_floors_voxel_by_voxel(voxels: &ChunkVoxels) -> Vec<u8> {
    let size = PADDED_CHUNK_SIZE;
    let mut floors = Vec::new();
    for z in 0..size {
        for x in 0..size {
            let solid = |y: u32| voxels.get([x, y, z]).unwrap().is_solid();
            if voxels.covered_above((x, z)).unwrap_or_else(|| solid(size - 1)) {
                floors.push(size as u8);
                continue;
            }
            let mut floor = size;
            while floor > 0 && !solid(floor - 1) {
                floor -= 1;
            }
            floors.push(floor as u8);
        }
    }
    floors
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Solid rows hold each row's solid voxels bit by bit, and the sky
    /// floors found from them are the floors read voxel by voxel.
    #[test]
    fn solid_rows_and_sky_floors_match_the_voxels(seed in any::<u64>(), record_cover in any::<bool>()) {
        let voxels = random_chunk(seed, record_cover);
        let mut rows = [0; PADDED_ROWS];
        voxels.solid_rows(&mut rows);
        for (n, &row) in rows.iter().enumerate() {
            let (y, z) = (n as u32 % PADDED_CHUNK_SIZE, n as u32 / PADDED_CHUNK_SIZE);
            let expected = (0..PADDED_CHUNK_SIZE)
                .filter(|&x| voxels.get([x, y, z]).unwrap().is_solid())
                .fold(0u64, |bits, x| bits | 1 << x);
            prop_assert_eq!(row, expected, "row y {} z {}", y, z);
        }
        let floors = sky_floors_voxel_by_voxel(&voxels);
        prop_assert_eq!(voxels.sky_floors().to_vec(), floors.clone());
        let dark_columns: Vec<u64> = (0..PADDED_CHUNK_SIZE)
            .map(|z| {
                (0..PADDED_CHUNK_SIZE)
                    .filter(|&x| {
                        let floor = u32::from(floors[(x + PADDED_CHUNK_SIZE * z) as usize]);
                        (0..floor).any(|y| !voxels.get([x, y, z]).unwrap().is_solid())
                    })
                    .fold(0, |bits, x| bits | 1 << x)
            })
            .collect();
        prop_assert_eq!(voxels.dark_air_columns_from(&rows).to_vec(), dark_columns);
    }

    /// Ground with no cave, overhang or cover has no dark air; one air
    /// voxel under a solid one, or a covered column, has.
    #[test]
    fn dark_air_is_air_under_a_floor(seed in any::<u64>(), x in 0u32..34, z in 0u32..34, y in 1u32..33) {
        let mut voxels = ChunkVoxels::new(ChunkKey { face: CubeFace::PosX, lod: 0, x: 0, y: 0, layer: 0 });
        let mut state = seed | 1;
        for (cz, cx) in (0..PADDED_CHUNK_SIZE).flat_map(|cz| (0..PADDED_CHUNK_SIZE).map(move |cx| (cz, cx))) {
            let ground = 1 + (unit_random(&mut state) * 32.0) as u32;
            for cy in 0..ground {
                voxels.set([cx, cy, cz], Voxel::STONE);
            }
        }
        let mut rows = [0; PADDED_ROWS];
        voxels.solid_rows(&mut rows);
        prop_assert_eq!(voxels.dark_air_columns_from(&rows), [0; PADDED_CHUNK_SIZE as usize]);
        let only = |z: u32, x: u32| {
            let mut dark = [0; PADDED_CHUNK_SIZE as usize];
            dark[z as usize] = 1 << x;
            dark
        };
        let mut overhang = voxels.clone();
        overhang.set([x, y, z], Voxel::AIR);
        overhang.set([x, y + 1, z], Voxel::STONE);
        overhang.solid_rows(&mut rows);
        prop_assert_eq!(overhang.dark_air_columns_from(&rows), only(z, x));
        let mut covered = voxels.clone();
        covered.set_covered_above((x, z), true);
        covered.set([x, PADDED_CHUNK_SIZE - 1, z], Voxel::AIR);
        covered.solid_rows(&mut rows);
        prop_assert_eq!(covered.dark_air_columns_from(&rows), only(z, x));
    }

    /// Every face-adjacent padding voxel, across chunk and cube-face edges,
    /// equals the voxel it stands for.
    #[test]
    fn padding_matches_the_neighbours(
        face in any_face(), lod in 0u8..=6, xf in 0.0f64..1.0, yf in 0.0f64..1.0, edge in 0usize..4,
        near_edge in any::<bool>(), t in 0u32..34, y in 0u32..34, depth in 0usize..2,
    ) {
        let planet = small();
        let layout = planet.layout();
        let per_edge = layout.chunks_per_edge(lod);
        let (mut x, mut yy) = ((xf * f64::from(per_edge)) as u32, (yf * f64::from(per_edge)) as u32);
        if near_edge { x = 0; yy = per_edge - 1; }
        let column = ChunkColumn { face, lod, x, y: yy };
        let layers = planet.surface_chunk_layers(column).unwrap();
        let layer = if depth == 0 { *layers.start() } else { *layers.end() };
        let key = column.chunk(layer);
        let mut voxels = ChunkVoxels::new(key);
        planet.fill_chunk(key, &mut voxels).unwrap();
        // A padding voxel on side `edge` (padded x or z = 0 or 33), not on a
        // padded edge line.
        let t = t.clamp(1, 32);
        let padded = match edge { 0 => [0, y, t], 1 => [33, y, t], 2 => [t, y, 0], _ => [t, y, 33] };
        let ci = i64::from(key.x) * 32 + i64::from(padded[0]) - 1;
        let cj = i64::from(key.y) * 32 + i64::from(padded[2]) - 1;
        let (f, i, j) = face.wrap_cell(ci, cj, i64::from(layout.voxels_per_edge(lod))).unwrap();
        let at = VoxelCoord { face: f, lod, i: i as u32, j: j as u32, h: key.layer * 32 + y as i32 - 1 };
        prop_assert_eq!(voxels.get(padded).unwrap(), planet.voxel(at).unwrap());
    }

    /// Chunks just outside the surface layers have nothing to mesh, and the
    /// surface of each column lies within its bounds.
    #[test]
    fn surface_bounds_are_conservative(face in any_face(), lod in 0u8..=6, xf in 0.0f64..1.0, yf in 0.0f64..1.0) {
        let planet = small();
        let layout = planet.layout();
        let per_edge = layout.chunks_per_edge(lod);
        let column = ChunkColumn { face, lod, x: (xf * f64::from(per_edge)) as u32, y: (yf * f64::from(per_edge)) as u32 };
        let layers = planet.surface_chunk_layers(column).unwrap();
        let mut voxels = ChunkVoxels::new(column.chunk(0));
        for layer in [layers.start() - 1, layers.end() + 1] {
            if layout.check_key(column.chunk(layer)).is_err() {
                continue; // below the planet centre: no chunk at all
            }
            planet.fill_chunk(column.chunk(layer), &mut voxels).unwrap();
            prop_assert!(voxels.has_no_surface(), "layer {} outside {:?} has surface", layer, layers);
        }
        let bounds = planet.surface_bounds(column).unwrap();
        let span = layout.voxel_span(lod) as u32;
        for (a, b) in [(0, 0), (31, 31), (16, 3), (7, 29)] {
            let (i, j) = (column.x * 32 + a, column.y * 32 + b);
            let top = column_top(planet, face, lod, i, j);
            prop_assert!(top - i64::from(span) >= bounds.min_layer && top - 1 <= bounds.max_layer,
                "top {} outside {:?}", top, bounds);
        }
        prop_assert!(bounds.min_radius < bounds.max_radius);
    }

    /// The same seed gives the same voxels; another seed gives other ones.
    #[test]
    fn generation_is_deterministic(seed in any::<u32>(), face in any_face(), lod in 2u8..=6) {
        let a = ProceduralPlanet::new(PlanetSettings::small(seed)).unwrap();
        let b = ProceduralPlanet::new(PlanetSettings::small(seed)).unwrap();
        let c = ProceduralPlanet::new(PlanetSettings::small(seed.wrapping_add(1))).unwrap();
        let column = ChunkColumn { face, lod, x: 0, y: 0 };
        let key = column.chunk(*a.surface_chunk_layers(column).unwrap().start());
        let (mut va, mut vb, mut vc) = (ChunkVoxels::new(key), ChunkVoxels::new(key), ChunkVoxels::new(key));
        a.fill_chunk(key, &mut va).unwrap();
        b.fill_chunk(key, &mut vb).unwrap();
        c.fill_chunk(key, &mut vc).unwrap();
        prop_assert_eq!(&va, &vb);
        let heights: Vec<_> = (0..8).map(|k| {
            let d = a.layout().sphere().direction(face, f64::from(k) * 97.0, 300.0);
            (a.height_at(d), c.height_at(d))
        }).collect();
        prop_assert!(heights.iter().any(|(x, y)| x != y));
    }
}

/// The first solid voxel along a ray by brute force: sample every `step`
/// metres, locate the voxel holding the sample with the inverse map, and
/// read it (once per voxel). Returns the voxel and the sample distance.
fn pick_by_sampling(
    source: &impl VoxelSource,
    origin: DVec3,
    dir: DVec3,
    max: f64,
    step: f64,
) -> Option<(VoxelCoord, f64)> {
    let mut last = None;
    let mut t = 0.0;
    while t <= max {
        let at = source.layout().voxel_at(origin + dir * t).unwrap();
        if last != Some(at) {
            if source.voxel(at).unwrap().is_solid() {
                return Some((at, t));
            }
            last = Some(at);
        }
        t += step;
    }
    None
}

/// Random rays near the ground of `source`: origins 1–60 m over the
/// surface, some of them next to cube edges and corners, directions from
/// straight down to grazing and a few upwards.
fn ground_rays(planet: &ProceduralPlanet, count: usize, seed: u64) -> Vec<(DVec3, DVec3)> {
    let mut state = seed;
    let mut unit = move || unit_random(&mut state);
    (0..count)
        .map(|n| {
            let mut direction = DVec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5).normalize();
            if n % 3 == 0 {
                // Near a cube edge or corner: push two components to ±max.
                let big = direction.abs().max_element();
                let axis = (n / 3) % 3;
                direction[axis] = big.copysign(direction[axis]) * (1.0 - unit() * 1e-4);
                if n % 2 == 0 {
                    let other = (axis + 1) % 3;
                    direction[other] = big.copysign(direction[other]) * (1.0 - unit() * 1e-4);
                }
                direction = direction.normalize();
            }
            let up = direction;
            let origin = planet.surface_point(direction) + up * (1.0 + unit() * 59.0);
            let tangent = up.any_orthonormal_vector();
            let around = up.cross(tangent);
            let angle = unit() * std::f64::consts::TAU;
            let horizontal = tangent * angle.cos() + around * angle.sin();
            let dip = if n % 10 == 9 { 0.3 } else { -0.02 - unit() * 1.2 };
            (origin, (horizontal + up * dip).normalize())
        })
        .collect()
}

#[test]
fn pick_finds_the_voxel_a_fine_march_finds() {
    // Against brute force on the small planet and on Earth, with edits (a
    // crater and a floating block), over cube edges and corners. The march
    // samples every 2 cm, so it may step over a corner the ray clips for
    // less than that: such a disagreement must be a voxel the exact walk
    // enters for under 2 cm before the march's voxel.
    let earth = ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
    let (mut rays, mut hits, mut corner_clips) = (0, 0, 0);
    for planet in [small(), &earth] {
        let mut edited = EditedSource::new(planet.clone());
        let all = ground_rays(planet, 160, 0x51ce_u64);
        for (origin, dir) in all.iter().step_by(16) {
            let below = planet.surface_point(origin.normalize());
            edited.fill_sphere(below, 4.0 * planet.voxel_size(), Voxel::AIR).unwrap();
            let ahead = *origin + *dir * 6.0 * planet.voxel_size();
            let (face, fi, fj) = planet.layout().sphere().face_coords_of(ahead).unwrap();
            let h = planet.layout().sphere().radius_to_layer(ahead.length()).floor() as i32;
            edited.set_voxel(VoxelCoord { face, lod: 0, i: fi as u32, j: fj as u32, h }, Voxel::STONE).unwrap();
        }
        let max = 300.0 * planet.voxel_size();
        for (origin, dir) in all {
            rays += 1;
            let exact = pick(&edited, origin, dir, max).unwrap();
            let sampled = pick_by_sampling(&edited, origin, dir, max, 0.02);
            match (exact, sampled) {
                (None, None) => {}
                (Some(hit), Some((voxel, t))) => {
                    hits += 1;
                    assert!(
                        hit.distance <= t + 1e-9,
                        "{origin} {dir}: exact hit at {} after the march's {t}",
                        hit.distance
                    );
                    if hit.voxel != voxel {
                        assert!(t - hit.distance < 0.02, "{origin} {dir}: {hit:?} vs march {voxel:?} at {t}");
                        corner_clips += 1;
                    }
                    // The hit lies on the side it names, entered against its normal.
                    assert!(hit.normal.dot(dir) <= 1e-12, "{hit:?} entered along its normal");
                    let before = hit.before.expect("rays start in air");
                    assert!(!edited.voxel(before).unwrap().is_solid(), "{hit:?}: the voxel before is solid");
                    assert!((hit.point - (origin + dir * hit.distance)).length() < 1e-6);
                }
                (exact, sampled) => {
                    let near_end = exact.map_or_else(|| sampled.unwrap().1, |h| h.distance) > max - 0.05;
                    assert!(near_end, "{origin} {dir}: exact {exact:?}, march {sampled:?}");
                }
            }
        }
    }
    println!("{rays} rays, {hits} hits, {corner_clips} corners the 2 cm march stepped over");
    assert!(hits > rays / 2, "too few rays reach the ground: {hits}/{rays}");
    assert!(corner_clips < hits / 20);
}

#[test]
fn pick_refuses_bad_rays_and_misses_from_space() {
    let planet = small();
    let up = DVec3::Y * planet.layout().sphere().radius() * 3.0;
    assert!(matches!(pick(planet, DVec3::NAN, DVec3::Y, 10.0), Err(VoxelError::NonFinite { .. })));
    assert!(matches!(pick(planet, up, DVec3::ZERO, 10.0), Err(VoxelError::OutOfRange { .. })));
    assert!(matches!(pick(planet, up, DVec3::Y, -1.0), Err(VoxelError::OutOfRange { .. })));
    assert_eq!(pick(planet, up, DVec3::Y, 1e9).unwrap(), None, "looking away from the planet");
    let hit = pick(planet, up, -DVec3::Y, 1e9).unwrap().expect("looking at the planet");
    assert_eq!(hit.face, Some(FaceDirection::PosY));
    assert!((hit.distance - (up.length() - hit.point.length())).abs() < 1e-6);
    assert!(pick(planet, up, -DVec3::Y, 100.0).unwrap().is_none(), "out of reach");
    // From inside the ground: the voxel the ray starts in.
    let inside = planet.surface_point(DVec3::Y) * 0.999;
    let hit = pick(planet, inside, DVec3::X, 10.0).unwrap().expect("inside rock");
    assert_eq!((hit.distance, hit.face, hit.before), (0.0, None, None));
}

#[test]
fn pick_sees_a_block_placed_far_above_the_terrain() {
    // Empty space is skipped by coarse columns' bounds, so an edit must
    // raise the bounds of every column over it, not only of the LODs that
    // show it. Blocks 300 m over the ground, hit by level rays from 50 m.
    for planet in [small().clone(), ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap()] {
        let mut edited = EditedSource::new(planet.clone());
        let mut state = 0xb10c_u64;
        let mut unit = move || unit_random(&mut state);
        for _ in 0..8 {
            let up = DVec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5).normalize();
            let block = planet.surface_point(up) + up * 300.0;
            let at = edited.layout().voxel_at(block).unwrap();
            edited.set_voxel(at, Voxel::STONE).unwrap();
            let side = up.any_orthonormal_vector();
            let origin = block + side * 50.0;
            let hit = pick(&edited, origin, block - origin, 100.0).unwrap().expect("the floating block");
            assert_eq!(hit.voxel, at);
            assert!(pick(&planet, origin, block - origin, 100.0).unwrap().is_none(), "the unedited sky is empty");
        }
    }
}

#[test]
fn a_ray_straight_up_along_an_axis_misses() {
    // It never leaves its column's wedge (an infinite exit): no hit, not
    // an error.
    for axis in [DVec3::X, DVec3::Y, DVec3::Z, -DVec3::X] {
        let origin = small().surface_point(axis) + axis * 10.0;
        assert_eq!(pick(small(), origin, axis, 10_000.0).unwrap(), None, "{axis}");
    }
}

/// FNV-1a over the materials of chunks around the surface of a few
/// columns (LOD 0 and 4, both presets, edges and corners among them), with
/// or without the presets' caves, octave grids and band limit.
fn terrain_fingerprint(caves: bool, grids: bool, coarse_grids: bool, band_limited: bool) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325_u64;
    let mut chunk = ChunkVoxels::new(ChunkKey { face: CubeFace::PosX, lod: 0, x: 0, y: 0, layer: 0 });
    for settings in [PlanetSettings::small(7), PlanetSettings::earth(11)] {
        let cave_size = if caves { settings.cave_size } else { 0.0 };
        let octave_grid = if grids { settings.octave_grid } else { 0.0 };
        let octave_grid_error = if coarse_grids { settings.octave_grid_error } else { 0.0 };
        let band_limit = if band_limited { settings.band_limit } else { 0.0 };
        let planet =
            ProceduralPlanet::new(PlanetSettings { cave_size, octave_grid, octave_grid_error, band_limit, ..settings })
                .unwrap();
        let layout = *planet.layout();
        for (n, face) in CubeFace::ALL.into_iter().enumerate() {
            for lod in [0u8, 4] {
                let per_edge = layout.chunks_per_edge(lod);
                let (x, y) = match n % 3 {
                    0 => (0, 0),
                    1 => (per_edge / 2, per_edge / 3),
                    _ => (per_edge - 1, per_edge / 5),
                };
                let column = ChunkColumn { face, lod, x, y };
                for layer in planet.surface_chunk_layers(column).unwrap() {
                    planet.fill_chunk(column.chunk(layer), &mut chunk).unwrap();
                    for voxel in chunk.as_slice() {
                        hash = (hash ^ u64::from(voxel.material())).wrapping_mul(0x0100_0000_01b3);
                    }
                }
            }
        }
    }
    hash
}

#[test]
fn the_terrain_is_the_one_its_version_names() {
    // Saved worlds name the terrain they were edited on by
    // `ProceduralPlanet::TERRAIN_VERSION`. This fingerprint of the voxels
    // changes when the terrain code does: then bump TERRAIN_VERSION (old
    // worlds are refused, never replayed onto other ground) and record the
    // new fingerprints here with its version: without caves or grids (the
    // planets saved before caves existed, `cave_size` 0), with the presets'
    // caves (saved before octave grids, `octave_grid` 0), with both (saved
    // before coarse grids, `octave_grid_error` 0), with all three (saved
    // before the band limit, `band_limit` 0), and with all four as the
    // presets have them (the fifth was taken at band limit 8 before the
    // presets' 6: the same code, other settings).
    // A setting added since (`PlanetSettings::ADDED_SETTINGS`) leaves the
    // earlier fingerprints as they were: its old value is the old terrain.
    const FINGERPRINTS: &[(u32, [u64; 5])] = &[(
        1,
        [
            0xb127_8bc9_e17b_fc98,
            0x30e7_fa30_f1d4_9dff,
            0x4232_3f04_11fe_6ee7,
            0x10cf_5945_b87d_7cf9,
            0x938c_3c97_87c5_5dc2,
        ],
    )];
    let fingerprints = [
        terrain_fingerprint(false, false, false, false),
        terrain_fingerprint(true, false, false, false),
        terrain_fingerprint(true, true, false, false),
        terrain_fingerprint(true, true, true, false),
        terrain_fingerprint(true, true, true, true),
    ];
    let recorded = FINGERPRINTS.iter().find(|(version, ..)| *version == ProceduralPlanet::TERRAIN_VERSION);
    assert_eq!(
        recorded.map(|&(_, prints)| prints),
        Some(fingerprints),
        "the terrain changed ({fingerprints:#x?}): bump ProceduralPlanet::TERRAIN_VERSION and record it"
    );
    assert_ne!(fingerprints[0], fingerprints[1], "the caves are not in the fingerprint");
    assert_ne!(fingerprints[1], fingerprints[2], "the grids are not in the fingerprint");
    assert_ne!(fingerprints[2], fingerprints[3], "the coarse grids are not in the fingerprint");
    assert_ne!(fingerprints[3], fingerprints[4], "the band limit is not in the fingerprint");
    // Versions that were released stay distinct.
    assert!(FINGERPRINTS.windows(2).all(|w| w[0].0 < w[1].0 && (0..5).all(|n| w[0].1[n] != w[1].1[n])));
}

#[test]
fn canonical_settings_name_every_field_once_sorted() {
    let settings = PlanetSettings::earth(11);
    let pairs = settings.canonical();
    assert!(pairs.windows(2).all(|w| w[0].0 < w[1].0), "{pairs:?}");
    assert_eq!(pairs.len(), 12);
    // Values read back to the same settings, and a change shows.
    let radius: f64 = pairs.iter().find(|(n, _)| *n == "radius").unwrap().1.parse().unwrap();
    assert_eq!(radius, settings.radius);
    let other = PlanetSettings { seed: 12, ..settings.clone() };
    assert_ne!(other.canonical(), pairs);
    let nudged = PlanetSettings { amplitude: settings.amplitude.next_up(), ..settings };
    assert_ne!(nudged.canonical(), pairs);
}

/// Every setting added since worlds were first saved has a field to take
/// a saved value over into, whose canonical text is the setting's, and
/// whose old value gives that text back; no other name has one.
#[test]
fn every_added_setting_has_its_field() {
    for &(name, old) in PlanetSettings::ADDED_SETTINGS {
        let mut settings = PlanetSettings::earth(11);
        let canonical = settings.canonical();
        let value = |pairs: &[(&str, String)]| pairs.iter().find(|(n, _)| *n == name).unwrap().1.clone();
        let field = settings.added_setting_mut(name).unwrap_or_else(|| panic!("{name} has no field"));
        assert_eq!(format!("{field:?}"), value(&canonical), "{name}");
        *field = old.parse().unwrap();
        assert_eq!(value(&settings.canonical()), old, "{name}");
    }
    let mut settings = PlanetSettings::earth(11);
    for name in ["radius", "seed", "band limit", ""] {
        assert!(settings.added_setting_mut(name).is_none(), "{name}");
    }
}

/// A random voxel column of some face, `per_edge` columns along its edge.
fn random_column(state: &mut u64, per_edge: u32) -> (CubeFace, u32, u32) {
    let face = CubeFace::ALL[(unit_random(state) * 6.0) as usize % 6];
    let mut coord = || (unit_random(state) * f64::from(per_edge)) as u32;
    (face, coord(), coord())
}

/// Marches `count` random land columns (H above sea level) of `planet` at
/// LOD 0 from above the ground down to `depth_m` under it, and returns the
/// share holding air under solid ground and the deepest such air under
/// the column's top, metres.
fn air_under_the_ground(planet: &ProceduralPlanet, count: usize, depth_m: f64, seed: u64) -> (f64, f64) {
    let layout = planet.layout();
    let sphere = layout.sphere();
    let layer = sphere.layer_height();
    let per_edge = layout.voxels_per_edge(0);
    let mut state = seed;
    let (mut land, mut hollow, mut deepest) = (0, 0, 0.0_f64);
    while land < count {
        let (face, i, j) = random_column(&mut state, per_edge);
        let height = planet.height_at(sphere.direction(face, f64::from(i) + 0.5, f64::from(j) + 0.5));
        if height < 2.0 * layer {
            continue;
        }
        land += 1;
        let top = (height / layer).floor() as i64 + 1;
        let voxel = |h: i64| planet.voxel(VoxelCoord { face, lod: 0, i, j, h: h as i32 }).unwrap();
        let mut ground = None;
        let mut found = false;
        for h in (top - (depth_m / layer) as i64 - 2..=top).rev() {
            let solid = voxel(h).is_solid();
            match ground {
                None if solid => ground = Some(h),
                Some(g) if !solid => {
                    found = true;
                    deepest = deepest.max((g - h) as f64 * layer);
                }
                _ => {}
            }
        }
        hollow += usize::from(found);
    }
    (hollow as f64 / count as f64, deepest)
}

#[test]
fn caves_hollow_the_land_and_none_without_them() {
    for settings in [PlanetSettings::earth(3), PlanetSettings::small(3)] {
        let planet = ProceduralPlanet::new(settings.clone()).unwrap();
        let (share, deepest) = air_under_the_ground(&planet, 400, 300.0, 77);
        println!(
            "radius {} m: {:.1} % of land columns hold air under the ground, the deepest {deepest:.1} m down",
            settings.radius,
            share * 100.0
        );
        assert!(share >= 0.04, "{share}");
        assert!(deepest >= 15.0, "{deepest}");
        let flat = ProceduralPlanet::new(PlanetSettings { cave_size: 0.0, ..settings }).unwrap();
        assert_eq!(
            air_under_the_ground(&flat, 100, 300.0, 77).0,
            0.0,
            "a heightfield planet has no air under its ground"
        );
    }
}

/// LOD-0 voxels of cave air (air under solid ground) in land columns of
/// `planet`, found by marching random columns down from the ground.
fn cave_voxels(planet: &ProceduralPlanet, count: usize, seed: u64) -> Vec<VoxelCoord> {
    let layout = planet.layout();
    let sphere = layout.sphere();
    let layer = sphere.layer_height();
    let per_edge = layout.voxels_per_edge(0);
    let mut state = seed;
    let mut found = Vec::new();
    while found.len() < count {
        let (face, i, j) = random_column(&mut state, per_edge);
        let height = planet.height_at(sphere.direction(face, f64::from(i) + 0.5, f64::from(j) + 0.5)) / layer;
        if height < 2.0 {
            continue;
        }
        let top = height.floor() as i32;
        let caves =
            (top - 60..top).filter(|&h| !planet.voxel(VoxelCoord { face, lod: 0, i, j, h }).unwrap().is_solid());
        found.extend(caves.map(|h| VoxelCoord { face, lod: 0, i, j, h }).take(1));
    }
    found
}

/// Chunks holding cave air equal their voxels read column by column (each
/// column alone, every octave in) at LODs 0–3 of an Earth: the batch that
/// fills a chunk (its caves' noises stopped early, its columns decided
/// before their last octave where no threshold is near) puts the air
/// where a lone column does. (With columns under a tunnel decided as any
/// other, their air's depths not among the thresholds, chunks differ.)
#[test]
fn chunks_around_caves_equal_their_voxels_read_column_by_column() {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(5)).unwrap();
    let layout = *planet.layout();
    let (mut compared, mut air) = (0, 0);
    for at in cave_voxels(&planet, 4, 0xca7e) {
        for lod in 0..=3u8 {
            let coarse = VoxelCoord { lod, i: at.i >> lod, j: at.j >> lod, h: at.h >> lod, ..at };
            let key = layout.chunk_of(coarse);
            let mut voxels = ChunkVoxels::new(key);
            planet.with_empty_cache().fill_chunk(key, &mut voxels).unwrap();
            for (x, z) in (0..32u32).flat_map(|x| (0..32u32).map(move |z| (x, z))) {
                let bottom =
                    VoxelCoord { face: key.face, lod, i: key.x * 32 + x, j: key.y * 32 + z, h: key.layer * 32 };
                let mut column = [Voxel::AIR; 32];
                planet.column_voxels(bottom, &mut column).unwrap();
                for (y, voxel) in column.iter().enumerate() {
                    assert_eq!(voxels.get([x + 1, y as u32 + 1, z + 1]), Some(*voxel), "{bottom:?} + {y}");
                }
                compared += 1;
                // Air under rock: a cave.
                air += column.windows(2).filter(|w| !w[0].is_solid() && w[1].is_solid()).count();
            }
        }
    }
    println!("{compared} columns compared, {air} cave ceilings among them");
    assert!(air > 0, "no cave in the chunks compared");
}

/// The LOD rule for caves (module docs of `caves.rs`): a coarse voxel is
/// cave air only in a tunnel's core. Against the majority of the LOD-0
/// voxels it stands for, the core rule leaves far fewer coarse voxels air
/// over mostly solid ground (the speckle of holes) than the far-corner
/// rule (a coarse voxel is its far-corner LOD-0 voxel), and gets the
/// coarse voxels around caves right as often or more.
#[test]
fn coarse_cave_voxels_are_mostly_cave_at_lod_0() {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(5)).unwrap();
    // The same ground without caves: a voxel solid there and air here is cave.
    let flat = ProceduralPlanet::new(PlanetSettings { cave_size: 0.0, ..planet.settings().clone() }).unwrap();
    let caves = cave_voxels(&planet, 24, 31);
    for lod in 1u8..=3 {
        let s = 1i64 << lod;
        // (coarse voxels, air by the core rule over a mostly solid block,
        // same by the far corner, wrong by the core rule, wrong by the far corner)
        let (mut total, mut core_holes, mut corner_holes, mut core_wrong, mut corner_wrong) = (0, 0, 0, 0, 0);
        let (mut core_air, mut corner_air) = (0, 0);
        for cave in &caves {
            let (ci, cj, ch) = (i64::from(cave.i) / s, i64::from(cave.j) / s, i64::from(cave.h).div_euclid(s));
            for (di, dj, dh) in (0..27).map(|n| (n % 3 - 1, n / 3 % 3 - 1, n / 9 - 1)) {
                let (a, b, c) = (ci + di, cj + dj, ch + dh);
                let coarse_at = VoxelCoord { face: cave.face, lod, i: a as u32, j: b as u32, h: c as i32 };
                // Under the ground: whatever air it holds is cave.
                if !flat.voxel(coarse_at).unwrap().is_solid() {
                    continue;
                }
                let coarse = planet.voxel(coarse_at).unwrap();
                let lod0 = |source: &ProceduralPlanet, i: i64, j: i64, h: i64| {
                    source.voxel(VoxelCoord { face: cave.face, lod: 0, i: i as u32, j: j as u32, h: h as i32 }).unwrap()
                };
                let corner = lod0(&planet, (a + 1) * s - 1, (b + 1) * s - 1, (c + 1) * s - 1);
                // LOD-0 cave air in the block the coarse voxel stands for.
                let mut air = 0;
                for n in 0..s * s * s {
                    let (x, y, z) = (a * s + n % s, b * s + n / s % s, c * s + n / (s * s));
                    air += i64::from(!lod0(&planet, x, y, z).is_solid() && lod0(&flat, x, y, z).is_solid());
                }
                let majority_air = 2 * air > s * s * s;
                let mostly_solid = 2 * air < s * s * s;
                total += 1;
                core_air += i32::from(!coarse.is_solid());
                corner_air += i32::from(!corner.is_solid());
                core_holes += i32::from(!coarse.is_solid() && mostly_solid);
                corner_holes += i32::from(!corner.is_solid() && mostly_solid);
                core_wrong += i32::from(coarse.is_solid() == majority_air);
                corner_wrong += i32::from(corner.is_solid() == majority_air);
            }
        }
        println!(
            "LOD {lod}: {total} coarse voxels around caves; air over mostly solid LOD 0 (holes): core rule {core_holes} of {core_air} air, \
             far corner {corner_holes} of {corner_air}; against the LOD-0 majority: core rule {core_wrong} wrong, far corner {corner_wrong}"
        );
        assert!(
            core_holes * 2 <= corner_holes.max(1),
            "LOD {lod}: the core rule leaves holes: {core_holes} vs {corner_holes}"
        );
        assert!(core_wrong <= corner_wrong, "LOD {lod}: {core_wrong} vs {corner_wrong}");
    }
}

/// Fills `key` from `source` and checks every air voxel of the padded
/// columns `columns`: one its sky floors call open has only air above it up
/// to the sky, one they call covered has something solid above it (read
/// voxel by voxel up past the column's surface bounds, over which nothing
/// is solid). Returns the voxels said open and covered.
fn assert_sky_floors_match(
    source: &impl VoxelSource,
    key: ChunkKey,
    columns: impl IntoIterator<Item = (u32, u32)>,
) -> (usize, usize) {
    let layout = source.layout();
    let mut voxels = ChunkVoxels::new(key);
    source.fill_chunk(key, &mut voxels).unwrap();
    let floors = voxels.sky_floors();
    let size = PADDED_CHUNK_SIZE;
    let per_edge = i64::from(layout.voxels_per_edge(key.lod));
    let chunk = i64::from(CHUNK_SIZE);
    let (mut open, mut covered) = (0, 0);
    for (x, z) in columns {
        let (ci, cj) = (i64::from(key.x) * chunk + i64::from(x) - 1, i64::from(key.y) * chunk + i64::from(z) - 1);
        let Some((face, i, j)) = key.face.wrap_cell(ci, cj, per_edge) else { continue };
        let column = ChunkColumn { face, lod: key.lod, x: (i / chunk) as u32, y: (j / chunk) as u32 };
        let top = source.surface_bounds(column).unwrap().max_layer.div_euclid(layout.voxel_span(key.lod)) + 2;
        for y in 0..size {
            if voxels.get([x, y, z]).unwrap().is_solid() {
                continue;
            }
            let said_open = y >= u32::from(floors[(x + size * z) as usize]);
            let first = i64::from(key.layer) * chunk + i64::from(y) - 1;
            let sees_sky = (first..=top).all(|h| {
                !source
                    .voxel(VoxelCoord { face, lod: key.lod, i: i as u32, j: j as u32, h: h as i32 })
                    .unwrap()
                    .is_solid()
            });
            assert_eq!(said_open, sees_sky, "{key:?} padded ({x}, {y}, {z})");
            if said_open { open += 1 } else { covered += 1 }
        }
    }
    (open, covered)
}

/// The padded column of `at` in its chunk, and those up to `reach` around it.
fn padded_columns_around(at: VoxelCoord, reach: u32) -> impl Iterator<Item = (u32, u32)> {
    let (ci, cj) = ((at.i % CHUNK_SIZE) + 1, (at.j % CHUNK_SIZE) + 1);
    let width = 2 * reach + 1;
    let last = PADDED_CHUNK_SIZE - 1;
    (0..width * width).map(move |n| {
        ((ci + n % width).saturating_sub(reach).min(last), (cj + n / width).saturating_sub(reach).min(last))
    })
}

/// Around random Earth caves (a fixed seed), at LODs 0 and 1: a voxel the
/// chunk's sky floors call open has only air above it up to the sky, and
/// an air voxel they call covered has something solid above it.
#[test]
fn sky_floors_say_which_air_sees_the_sky() {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(5)).unwrap();
    let layout = planet.layout();
    let (mut open, mut covered) = (0, 0);
    // Deep caves, and cave mouths (a column whose heightfield top is cave
    // air): their rims, where a tunnel's top lies just under the ground,
    // and the chunks under them.
    let sphere = layout.sphere();
    let mut state = 4242u64;
    let mut mouths = Vec::new();
    while mouths.len() < 6 {
        let per_edge = layout.voxels_per_edge(0);
        let (face, i, j) = random_column(&mut state, per_edge);
        let height =
            planet.height_at(sphere.direction(face, f64::from(i) + 0.5, f64::from(j) + 0.5)) / sphere.layer_height();
        let top = (height - 0.5).ceil() as i32 - 1;
        if height > 3.0 && !planet.voxel(VoxelCoord { face, lod: 0, i, j, h: top }).unwrap().is_solid() {
            mouths.push(VoxelCoord { face, lod: 0, i, j, h: top });
            mouths.push(VoxelCoord { face, lod: 0, i, j, h: top - CHUNK_SIZE as i32 });
        }
    }
    for cave in cave_voxels(&planet, 6, 44).into_iter().chain(mouths) {
        for lod in [0u8, 1] {
            let at = VoxelCoord { lod, i: cave.i >> lod, j: cave.j >> lod, h: cave.h >> lod, ..cave };
            let (x, z) = ((at.i % CHUNK_SIZE) + 1, (at.j % CHUNK_SIZE) + 1);
            let last = PADDED_CHUNK_SIZE - 1;
            let far = [(x.saturating_sub(3), z), (x, (z + 5).min(last))];
            let (o, c) = assert_sky_floors_match(
                &planet,
                layout.chunk_of(at),
                far.into_iter().chain(padded_columns_around(at, 2)),
            );
            open += o;
            covered += c;
        }
    }
    println!("{open} open and {covered} covered air voxels checked");
    assert!(open > 100 && covered > 100, "{open} / {covered}");
}

/// Edits change what sees the sky, in the chunks they touch and in those
/// under them: a shaft dug from a cave up through the ground opens the
/// cave to the sky; a roof built over open ground covers it. The sky
/// floors match the edited voxels (LODs 0 and 1), and every chunk of the
/// columns whose voxels or sky floors changed is among the dirty ones;
/// some chunks change their sky floors alone (the edit is above them).
#[test]
fn sky_floors_follow_edits_over_the_chunk() {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(5)).unwrap();
    let layout = *planet.layout();
    let sphere = layout.sphere();
    let ground = |at: VoxelCoord| {
        let up = sphere.direction(at.face, f64::from(at.i) + 0.5, f64::from(at.j) + 0.5);
        (planet.height_at(up) / sphere.layer_height()).ceil() as i32
    };
    let (mut opened, mut shaded) = (0, 0);
    // Caves deeper than a chunk under the ground, so that a shaft reaches
    // over the cave's chunk and a roof over the ground's.
    let caves = cave_voxels(&planet, 24, 77).into_iter().filter(|&cave| ground(cave) - cave.h > 40);
    for (n, cave) in caves.take(6).enumerate() {
        let mut edited = EditedSource::new(planet.clone());
        let mut dirty = std::collections::BTreeSet::new();
        // A 2×2 (LOD 1's far corner dug too) shaft from the cave up past
        // the ground; or a 4×4 roof 40 voxels over the ground.
        let (i0, j0) = (cave.i & !1, cave.j & !1);
        let roof = n % 2 == 1;
        let width = if roof { 4 } else { 2 };
        for (di, dj) in (0..width * width).map(|k| (k % width, k / width)) {
            let column = VoxelCoord { i: i0 + di, j: j0 + dj, ..cave };
            let top = ground(column) + 2;
            let (heights, voxel) =
                if roof { (top + 40..=top + 40, Voxel::STONE) } else { (cave.h + 1..=top, Voxel::AIR) };
            for h in heights {
                dirty.extend(edited.set_voxel(VoxelCoord { h, ..column }, voxel).unwrap());
            }
        }
        // What the edit lights or shades: the cave, or the ground's air.
        let target = if roof { VoxelCoord { h: ground(cave) + 2, ..cave } } else { cave };
        for lod in [0u8, 1] {
            let at = VoxelCoord { lod, i: target.i >> lod, j: target.j >> lod, h: target.h >> lod, ..target };
            let key = layout.chunk_of(at);
            // Every chunk of the column whose voxels or floors changed is dirty.
            let bounds = edited.surface_bounds(key.column()).unwrap().chunk_layers(&layout, lod);
            for layer in bounds {
                let key = ChunkKey { layer, ..key };
                let (mut before, mut after) = (ChunkVoxels::new(key), ChunkVoxels::new(key));
                planet.fill_chunk(key, &mut before).unwrap();
                edited.fill_chunk(key, &mut after).unwrap();
                let changed = before.as_slice() != after.as_slice() || before.sky_floors() != after.sky_floors();
                assert!(!changed || dirty.contains(&key), "{key:?} changed and is not dirty");
                if before.as_slice() == after.as_slice() && before.sky_floors() != after.sky_floors() {
                    if roof { shaded += 1 } else { opened += 1 }
                }
            }
            // The floors match the edited voxels around what it lights.
            assert_sky_floors_match(&edited, key, padded_columns_around(at, 3));
        }
    }
    println!("{opened} chunks opened to the sky and {shaded} shaded by edits over them");
    assert!(opened > 0 && shaded > 0, "{opened} / {shaded}");
}

/// The deep cave network is sealed at the LODs whose columns leave its
/// layers out for an eye over the ground, and the rest for an eye in it
/// (`surface_chunk_layers_seen`): flooding the air of deep caves (a fixed
/// seed, LODs 0–2) through voxel faces never reaches air that is open or in
/// a shallow cave, so no ray from out there reaches their walls, and the
/// layers an eye in them is given hold every voxel of that air and the
/// rock over it.
#[test]
fn deep_caves_are_sealed_where_their_layers_are_left_out() {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
    let layout = planet.layout();
    let sphere = layout.sphere();
    let layer = sphere.layer_height();
    let shallow = planet.caves().shallow_deepest() + 0.5 * planet.caves().separation();
    let mut state = 99u64;
    let (mut flooded, mut components) = (0usize, 0);
    let mut tries = 0;
    while components < 16 {
        tries += 1;
        assert!(tries < 100_000, "no deep cave found");
        let lod = (components % 3) as u8;
        let per_edge = layout.voxels_per_edge(lod);
        // Every other cave in a mountain range (around the highest peak of
        // this seed, the README's), where the two networks come nearest
        // across neighbouring columns; the rest anywhere.
        let (face, i, j) = if components % 2 == 1 {
            let offset =
                DVec3::new(unit_random(&mut state) - 0.5, unit_random(&mut state) - 0.5, unit_random(&mut state) - 0.5);
            let at = layout.voxel_at(DVec3::new(-2_901_622.7, 5_671_976.6, -85_292.8) + offset * 40_000.0).unwrap();
            (at.face, at.i >> lod, at.j >> lod)
        } else {
            random_column(&mut state, per_edge)
        };
        let span = layout.voxel_span(lod) as f64;
        let direction = |i: u32, j: u32| {
            sphere.direction(face, (f64::from(i) + 1.0) * span - 0.5, (f64::from(j) + 1.0) * span - 0.5)
        };
        let height = planet.height_at(direction(i, j)) / layer;
        if height < 2.0 {
            continue;
        }
        // The first air down where the deep network lies: a deep cave, if any.
        let depth_of =
            |i: u32, j: u32, h: i32| planet.height_at(direction(i, j)) / layer - ((f64::from(h) + 1.0) * span - 0.5);
        let air = |i: u32, j: u32, h: i32| !planet.voxel(VoxelCoord { face, lod, i, j, h }).unwrap().is_solid();
        let top = (height / span) as i32;
        let (deepest, shallowest) = ((planet.caves().deepest() / span) as i32 + 1, (shallow / span) as i32);
        let Some(h) = (top - deepest..top - shallowest).find(|&h| air(i, j, h)) else { continue };
        if depth_of(i, j, h) <= shallow {
            continue;
        }
        components += 1;
        // Flood the deep air (bounded), never leaving the face.
        let mut seen = std::collections::HashSet::from([(i, j, h)]);
        let mut queue = std::collections::VecDeque::from([(i, j, h)]);
        let chunk_layer = |c: i32| c.div_euclid(CHUNK_SIZE as i32);
        while let Some((a, b, c)) = queue.pop_front() {
            assert!(
                depth_of(a, b, c) > planet.caves().shallow_deepest(),
                "LOD {lod}: deep air at ({a}, {b}, {c}) reaches shallow or open air"
            );
            let column = layout.chunk_of(VoxelCoord { face, lod, i: a, j: b, h: c }).column();
            let sealed = planet.surface_chunk_layers_seen(column, LayerView::FromSealedCaves).unwrap();
            assert!(
                sealed.contains(&chunk_layer(c)) && sealed.contains(&chunk_layer(c + 1)),
                "LOD {lod}: ({a}, {b}, {c}) outside {sealed:?}"
            );
            if seen.len() > 4_000 {
                break;
            }
            for (da, db, dc) in [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)] {
                let (na, nb, nc) = (i64::from(a) + da, i64::from(b) + db, c + dc);
                if na < 0 || nb < 0 || na >= i64::from(per_edge) || nb >= i64::from(per_edge) {
                    continue;
                }
                let next = (na as u32, nb as u32, nc);
                if air(next.0, next.1, next.2) && seen.insert(next) {
                    queue.push_back(next);
                }
            }
        }
        flooded += seen.len();
        // The layers each view is given are some of the column's.
        let column = layout.chunk_of(VoxelCoord { face, lod, i, j, h }).column();
        let all = planet.surface_chunk_layers(column).unwrap();
        for view in [LayerView::FromAbove, LayerView::FromSealedCaves] {
            let seen = planet.surface_chunk_layers_seen(column, view).unwrap();
            assert!(seen.is_empty() || (all.start() <= seen.start() && seen.end() <= all.end()), "{all:?} / {seen:?}");
        }
    }
    println!("{components} deep caves, {flooded} air voxels flooded, none open");
    assert!(flooded > 1_000);
}

#[test]
fn a_survey_answers_each_view_as_the_source_does_one_by_one() {
    // The LOD tree asks `surface_survey` once per node and the streamer
    // reads each view's layers from it: it must say what
    // `surface_bounds` and `surface_chunk_layers_seen` say, on planets
    // with and without caves, edited or not, at every LOD with caves and
    // above. (A survey that gave every view all layers would pass the
    // `All` rows and fail the others: the control below.)
    let mut edited = EditedSource::new(ProceduralPlanet::new(PlanetSettings::small(3)).unwrap());
    let up = DVec3::new(0.2, 0.9, 0.4).normalize();
    let ground = edited.base().surface_point(up);
    let half = DVec3::splat(3.0 * edited.base().voxel_size());
    edited.fill_box(ground - half, ground + half * 4.0, Voxel::STONE).unwrap();
    // The edited voxel's columns at every LOD, then random ones.
    let mut edited_columns = Vec::new();
    let mut at = Some(edited.layout().voxel_at(ground).unwrap());
    while let Some(voxel) = at.filter(|v| v.lod <= 5) {
        edited_columns.push(edited.layout().chunk_of(voxel).column());
        at = voxel.parent();
    }
    let sources: [(&str, Box<dyn VoxelSource>); 4] = [
        ("earth", Box::new(ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap())),
        ("small", Box::new(ProceduralPlanet::new(PlanetSettings::small(3)).unwrap())),
        (
            "no caves",
            Box::new(ProceduralPlanet::new(PlanetSettings { cave_size: 0.0, ..PlanetSettings::small(3) }).unwrap()),
        ),
        ("edited", Box::new(edited)),
    ];
    let mut state = 0x5eed_u64;
    let mut narrower = 0;
    for (name, source) in &sources {
        let layout = *source.layout();
        let random = (0..=5u8).flat_map(|lod| std::iter::repeat_n(lod, 40)).map(|lod| {
            let (face, x, y) = random_column(&mut state, layout.chunks_per_edge(lod));
            ChunkColumn { face, lod, x, y }
        });
        for column in edited_columns.iter().copied().chain(random.collect::<Vec<_>>()) {
            let survey = source.surface_survey(column).unwrap();
            assert_eq!(survey.bounds, source.surface_bounds(column).unwrap(), "{name} {column:?}");
            for view in LayerView::ALL {
                let seen = source.surface_chunk_layers_seen(column, view).unwrap();
                assert_eq!(survey.layers(view), seen, "{name} {column:?} {view:?}");
                narrower += usize::from(seen != source.surface_chunk_layers(column).unwrap());
            }
        }
    }
    println!("{narrower} column views narrower than all layers");
    assert!(narrower > 0, "no view left a layer out: the check cannot tell");
}

/// `column_voxels` is `voxel` asked up a column, at every LOD, for the
/// planet and for an edited planet (inside and beside a crater).
#[test]
fn column_voxels_are_the_voxels_one_by_one() {
    let planet = small().clone();
    let layout = *planet.layout();
    let up = DVec3::new(0.3, 0.8, -0.5).normalize();
    let ground = planet.surface_point(up);
    let mut edited = EditedSource::new(planet.clone());
    edited.fill_sphere(ground, 6.0, Voxel::AIR).expect("crater");
    let sources: [&dyn VoxelSource; 2] = [&planet, &edited];
    let mut state = 0x0c01_u64;
    for lod in 0..=3u8 {
        for n in 0..6 {
            // The crater's column, then random ones near it.
            let jitter = if n == 0 { 0.0 } else { 2e-3 };
            let direction = (up
                + DVec3::new(unit_random(&mut state), unit_random(&mut state), unit_random(&mut state)) * jitter)
                .normalize();
            let at = layout.voxel_at(direction * ground.length()).expect("voxel");
            let bottom = VoxelCoord { lod, i: at.i >> lod, j: at.j >> lod, h: (at.h >> lod) - 12, ..at };
            for source in sources {
                let mut column = [Voxel::AIR; 24];
                source.column_voxels(bottom, &mut column).expect("column");
                for (k, voxel) in column.iter().enumerate() {
                    let one = source.voxel(VoxelCoord { h: bottom.h + k as i32, ..bottom }).expect("voxel");
                    assert_eq!(*voxel, one, "LOD {lod}, column {bottom:?}, voxel {k}");
                }
                assert!(column.iter().any(|v| v.is_solid()) && column.iter().any(|v| !v.is_solid()), "{bottom:?}");
            }
        }
    }
    // Its first voxel on the planet, its last past the lattice's range.
    let near_top = VoxelCoord { h: i32::MAX / 4 - 5, ..layout.voxel_at(ground).expect("voxel") };
    assert!(planet.voxel(near_top).is_ok());
    assert!(planet.column_voxels(near_top, &mut [Voxel::AIR; 100]).is_err(), "a column past the lattice");
}

/// A chunk has no surface when all rock but for one air voxel, exactly
/// where that voxel is no face neighbour of the chunk proper (edge or
/// corner padding), and when all air but for one rock voxel, exactly where
/// that voxel is padding: every one of the 34³ places.
#[test]
fn one_voxel_off_has_a_surface_where_it_borders_the_chunk() {
    let key = ChunkKey { face: CubeFace::PosX, lod: 0, x: 1, y: 1, layer: 0 };
    for (fill, odd) in [(Voxel::STONE, Voxel::AIR), (Voxel::AIR, Voxel::STONE)] {
        let mut chunk = ChunkVoxels::from_voxels(key, vec![fill; PADDED_CHUNK_VOLUME]).unwrap();
        for (x, y, z) in (0..34).flat_map(|x| (0..34).flat_map(move |y| (0..34).map(move |z| (x, y, z)))) {
            let in_padding = [x, y, z].iter().filter(|&&c| c == 0 || c == 33).count();
            let expected = if fill.is_solid() { in_padding > 1 } else { in_padding > 0 };
            chunk.set([x, y, z], odd);
            assert_eq!(chunk.has_no_surface(), expected, "{odd:?} at {:?} in {fill:?}", [x, y, z]);
            chunk.set([x, y, z], fill);
        }
    }
}
