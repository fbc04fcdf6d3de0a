//! The pop: how far, in pixels, anything on screen jumps at the moment a
//! chunk is replaced by its parent (merge) or by its children (split), with
//! the geomorph the shader applies (`RenderVertex::drawn_relative`, the
//! shader's CPU twin).
//!
//! For random columns P (LODs 1–8, the small planet and Earth) the eye is
//! put where the LOD tree switches P — at P's merge distance
//! D_split/(1 − hysteresis) and at its split distance D_split, from several
//! elevations. At that moment the children C are drawn with their μ and P
//! with its own; each child vertex sits on a lattice point q of P (its
//! morph target), and the pop at that vertex is the screen distance between
//! where C draws it and where P draws q. The largest over all vertices is
//! the pop; the goal is ≤ 0.5 px at τ = 1 (640×400 and 1280×720, 60°).
//!
//! Controls: with geomorphing off the same measure must show a clear pop,
//! so the measure can see one.

use nebula_lod::{LodSettings, NodeBounds};
use nebula_math::DVec3;
use nebula_meshing::{ChunkDraw, ChunkLodContext, ChunkMesh, ChunkMeshBuffer, FrameDraw, MeshOptions, mesh_chunk};
use nebula_voxel::{CHUNK_SIZE, ChunkColumn, CubeFace, PlanetSettings, ProceduralPlanet, VoxelSource};

struct Case {
    children: Vec<ChunkMesh>,
    parent: ChunkColumn,
}

fn meshes(planet: &ProceduralPlanet, column: ChunkColumn) -> Vec<ChunkMesh> {
    let mut buffer = ChunkMeshBuffer::new();
    planet
        .surface_chunk_layers(column)
        .expect("column on the planet")
        .map(|layer| {
            let key = column.chunk(layer);
            mesh_chunk(planet, key, &ChunkLodContext::uniform(key.lod), MeshOptions::NO_SEAMS, &mut buffer)
                .expect("meshes")
        })
        .collect()
}

/// The largest screen jump, in pixels, between the children drawn at
/// `eye` and the parent drawn at `eye`.
fn pop_px(planet: &ProceduralPlanet, case: &Case, eye: DVec3, k: f64, morph: bool) -> f64 {
    let layout = planet.layout();
    let frame = FrameDraw::new(eye, k, 1.0, morph);
    let child_draw =
        ChunkDraw { parent_error: layout.merge_error(case.parent.lod - 1), skirt_depths: [0.0; 4], hidden_sides: 0 };
    let parent_draw =
        ChunkDraw { parent_error: layout.merge_error(case.parent.lod), skirt_depths: [0.0; 4], hidden_sides: 0 };
    let sphere = layout.sphere();
    let parent_span = layout.voxel_span(case.parent.lod);
    let mut worst = 0.0_f64;
    for mesh in &case.children {
        let key = mesh.key();
        let render = mesh.render_vertices();
        for (index, vertex) in render.iter().enumerate() {
            let Some(local) = mesh.local_lattice(index) else { continue };
            let child_at = vertex.drawn_relative(&frame, &child_draw);
            // The child vertex's target q, in the parent's lattice units
            // (face-global), and q's own morph target one LOD up.
            let global = |c: i32, chunk: u32| i64::from(chunk) * i64::from(CHUNK_SIZE) + i64::from(c - c.rem_euclid(2));
            let q = [
                global(local[0], key.x) / 2,
                i64::from(key.layer) * 16 + i64::from(local[1] - local[1].rem_euclid(2)) / 2,
                global(local[2], key.y) / 2,
            ];
            let position = |p: [i64; 3]| -> DVec3 {
                let point = sphere
                    .lattice_point(key.face, p[0] * parent_span, p[2] * parent_span, p[1] * parent_span)
                    .expect("on the planet");
                sphere.position(point)
            };
            let q_pos = position(q);
            let q_target = position(q.map(|c| c - c.rem_euclid(2)));
            let mu = nebula_meshing::vertex_morph_factor(&frame, &parent_draw, (q_pos - frame.eye()).length());
            let parent_at = if morph { q_pos + (q_target - q_pos) * (1.0 - mu) } else { q_pos } - frame.eye();
            let angle = child_at.normalize().angle_between(parent_at.normalize());
            worst = worst.max(angle * k);
        }
    }
    worst
}

/// An eye at node distance `distance` from `column`'s bounds, above its
/// centre at `elevation` degrees over the local horizon.
fn eye_at(planet: &ProceduralPlanet, column: ChunkColumn, distance: f64, elevation: f64, azimuth: f64) -> DVec3 {
    let layout = planet.layout();
    let bounds = NodeBounds::new(layout, column, &planet.surface_bounds(column).expect("bounds"));
    let centre = planet.surface_point(bounds.center_direction);
    let up = centre.normalize();
    let east = up.any_orthonormal_vector();
    let north = up.cross(east);
    let (e, a) = (elevation.to_radians(), azimuth.to_radians());
    let dir = up * e.sin() + (east * a.cos() + north * a.sin()) * e.cos();
    // Bisect the scale along `dir` at which the node distance is `distance`.
    let (mut low, mut high) = (0.0, distance * 4.0 + bounds.max_radius - bounds.min_radius);
    for _ in 0..80 {
        let mid = 0.5 * (low + high);
        if bounds.distance(centre + dir * mid) < distance { low = mid } else { high = mid }
    }
    centre + dir * high
}

fn cases(planet: &ProceduralPlanet, seed: u64, count: usize) -> Vec<Case> {
    let layout = planet.layout();
    let mut state = seed;
    let mut next = |n: u32| {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        ((state >> 33) % u64::from(n)) as u32
    };
    (0..count)
        .map(|i| {
            let lod = 1 + (i % usize::from(layout.max_lod().min(8))) as u8;
            let face = CubeFace::ALL[i % 6];
            let per_edge = layout.chunks_per_edge(lod);
            let parent = ChunkColumn { face, lod, x: next(per_edge), y: next(per_edge) };
            let children = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .into_iter()
                .flat_map(|(dx, dy)| {
                    meshes(planet, ChunkColumn { face, lod: lod - 1, x: parent.x * 2 + dx, y: parent.y * 2 + dy })
                })
                .collect();
            Case { children, parent }
        })
        .collect()
}

#[test]
fn the_pop_at_a_lod_switch_is_within_half_a_pixel() {
    let earth = ProceduralPlanet::new(PlanetSettings::earth(3)).expect("earth");
    let small = ProceduralPlanet::new(PlanetSettings::small(3)).expect("small");
    let hysteresis = LodSettings::default().hysteresis;
    let mut report = Vec::new();
    for (name, planet) in [("earth", &earth), ("small", &small)] {
        let cases = cases(planet, 0x9e37, 16);
        for height in [400.0, 720.0] {
            let settings = LodSettings { screen_height_px: height, ..LodSettings::default() };
            let k = settings.screen_space().expect("settings").k();
            let (mut worst_on, mut worst_off) = (0.0_f64, 0.0_f64);
            for case in &cases {
                let split = planet.layout().voxel_edge(case.parent.lod) * k / settings.threshold_px;
                for distance in [split, split / (1.0 - hysteresis)] {
                    for (elevation, azimuth) in [(5.0, 0.0), (25.0, 130.0), (60.0, 250.0)] {
                        let eye = eye_at(planet, case.parent, distance, elevation, azimuth);
                        worst_on = worst_on.max(pop_px(planet, case, eye, k, true));
                        worst_off = worst_off.max(pop_px(planet, case, eye, k, false));
                    }
                }
            }
            println!(
                "{name}, {height} px tall, τ = 1: largest pop {worst_on:.5} px with geomorphing, {worst_off:.3} px without"
            );
            report.push((name, height, worst_on, worst_off));
        }
    }
    for (name, height, on, off) in report {
        assert!(on <= 0.5, "{name} at {height} px: pop {on:.3} px > 0.5");
        assert!(
            off > 0.3 && off > 3.0 * on,
            "{name} at {height} px: the measure cannot see a pop ({off:.3} px off, {on:.3} on)"
        );
    }
}
