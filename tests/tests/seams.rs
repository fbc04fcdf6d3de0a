//! Whole-planet seam verification: cameras that stress cube-face corners and
//! edges, grazing views, LOD differences 1–3, a camera path and an edited
//! planet, each checked with the ray-cast crack oracle and the lattice
//! topology check.

use std::time::Instant;

use nebula_lod::{BalanceMode, Camera, ChunkLodContext, LodSettings, LodTree, NeighborLodRelation};
use nebula_math::{DVec3, FaceDirection, FaceEdge};
use nebula_meshing::MeshOptions;
use nebula_tests::{PlanetView, assemble, assemble_leaves, boundary_topology, cast_cracks, view_of_tree};
use nebula_voxel::{ChunkColumn, CubeFace, EditedSource, PlanetSettings, ProceduralPlanet, Voxel, VoxelSource};
use proptest::prelude::*;

const RAYS: u32 = 192;

fn planet(seed: u32) -> ProceduralPlanet {
    ProceduralPlanet::new(PlanetSettings::small(seed)).expect("valid planet")
}

/// A camera at `position` looking at `target`, up roughly radial.
fn look(position: DVec3, target: DVec3) -> Camera {
    let forward = target - position;
    let radial = position.normalize();
    let up = if forward.normalize().cross(radial).length() > 1e-3 { radial } else { forward.any_orthonormal_vector() };
    Camera { position, forward, up, aspect: 1.0 }
}

/// The point `height` metres above the ground in direction `dir`.
fn above(source: &ProceduralPlanet, dir: DVec3, height: f64) -> DVec3 {
    source.surface_point(dir) + dir.normalize() * height
}

fn settings(fov: f64, balance: BalanceMode) -> LodSettings {
    LodSettings {
        screen_height_px: f64::from(RAYS),
        fov_y_degrees: fov,
        threshold_px: 1.0,
        balance,
        ..LodSettings::default()
    }
}

/// Checks one view: no cracks, no leaking T-junctions, no unmatched
/// same-LOD outline edges, and the planet covers the image where it must.
fn check(name: &str, view: &PlanetView, camera: &Camera, min_planet_fraction: f64) {
    let start = Instant::now();
    let report = cast_cracks(view, camera, RAYS, RAYS);
    let seconds = start.elapsed().as_secs_f64();
    let topology = boundary_topology(view);
    let stats = view.stats.clone().unwrap_or_default();
    let skirts: usize = view.meshes.iter().map(|m| m.skirt_triangle_count()).sum();
    println!(
        "{name}: {} chunks, {} triangles ({:.1} % skirts), LODs {:?}, max diff {}, balance passes {}; rays {} \
         ({:.0}/s), on planet {}, cracks {}; pairs {} ({} across LODs), t-junctions {}, unmatched {}",
        view.meshes.len(),
        report.triangles,
        100.0 * skirts as f64 / report.triangles.max(1) as f64,
        stats.lod_histogram,
        stats.max_neighbor_lod_diff,
        stats.balance_passes,
        report.rays,
        report.rays as f64 / seconds,
        report.rays_on_planet,
        report.cracks,
        topology.pairs,
        topology.lod_boundary_pairs,
        topology.t_junctions,
        topology.unmatched_edges
    );
    assert_eq!(report.cracks, 0, "{name}: cracks near {:?}", report.first_crack_chunks);
    assert!(report.rays_on_planet as f64 >= min_planet_fraction * report.rays as f64, "{name}: planet not in view");
    assert_eq!(topology.t_junctions, 0, "{name}");
    assert_eq!(topology.unmatched_edges, 0, "{name}");
    if view.stats.is_some() {
        // Seed 000's promise for a real view: skirts are at most 5 %.
        assert!(skirts as f64 <= 0.05 * report.triangles as f64, "{name}: too many skirt triangles");
    }
}

#[test]
fn fixed_cameras_show_no_cracks_in_both_balance_modes() {
    let source = planet(7);
    let corner = DVec3::ONE.normalize();
    let edge = DVec3::new(1.0, 1.0, 0.0).normalize();
    let cameras = [
        ("orbit", 60.0, look(DVec3::new(3_000.0, 4_000.0, 5_000.0), DVec3::ZERO), 0.1),
        (
            "low over a cube corner",
            60.0,
            look(above(&source, corner, 40.0), above(&source, corner + DVec3::X * 0.05, 0.0)),
            0.4,
        ),
        (
            "grazing along a cube edge, 12°",
            12.0,
            look(above(&source, edge, 15.0), above(&source, (edge + DVec3::Z * 0.08).normalize(), 0.0)),
            0.3,
        ),
        ("straight down", 60.0, look(above(&source, DVec3::new(0.2, -0.9, 0.4), 200.0), DVec3::ZERO), 0.99),
    ];
    for balance in [BalanceMode::Unrestricted, BalanceMode::Restricted] {
        for (name, fov, camera, fraction) in &cameras {
            let view = assemble(&source, camera, settings(*fov, balance), MeshOptions::default()).unwrap();
            check(&format!("{name} ({balance:?})"), &view, camera, *fraction);
            if balance == BalanceMode::Restricted {
                assert!(view.stats.as_ref().unwrap().max_neighbor_lod_diff <= 1);
            }
        }
    }
}

/// Hand-built leaves: a coarse column at LOD `k` next to its neighbour's
/// area cut into LOD-0 columns, across `edge` of `face` (on the same face,
/// or over a cube edge when the coarse column sits on the face border).
fn lod_step(
    source: &ProceduralPlanet,
    k: u8,
    face: CubeFace,
    at_face_edge: bool,
    options: MeshOptions,
) -> (PlanetView, Camera) {
    let layout = source.layout();
    let per_edge = layout.chunks_per_edge(k);
    let coarse =
        ChunkColumn { face, lod: k, x: if at_face_edge { per_edge - 1 } else { per_edge / 2 }, y: per_edge / 2 };
    let across = layout.neighbor(coarse.chunk(0), FaceEdge::PosU).column();
    let back = if across.face == face { FaceEdge::NegU } else { face.neighbor(FaceEdge::PosU).edge };
    let mut coarse_context = ChunkLodContext::uniform(k);
    coarse_context.set(FaceDirection::PosX, NeighborLodRelation::LowerThanNeighbor);
    let mut leaves = vec![(coarse, coarse_context)];
    let n = 1u32 << k;
    for dx in 0..n {
        for dy in 0..n {
            let fine = ChunkColumn { face: across.face, lod: 0, x: across.x * n + dx, y: across.y * n + dy };
            let mut context = ChunkLodContext::uniform(0);
            // Only the fine columns along the shared edge meet the coarse one.
            let on_edge = match back {
                FaceEdge::NegU => dx == 0,
                FaceEdge::PosU => dx == n - 1,
                FaceEdge::NegV => dy == 0,
                FaceEdge::PosV => dy == n - 1,
            };
            if on_edge {
                context
                    .set(FaceDirection::from_face_edge(back), NeighborLodRelation::HigherThanNeighbor { lod_diff: k });
            }
            leaves.push((fine, context));
        }
    }
    // Look down at the middle of the seam from above the coarse side, so
    // the 30° view stays inside the two blocks.
    let sphere = layout.sphere();
    let size = f64::from(32u32 << k);
    let width = size * sphere.cell_width();
    let middle = sphere.direction(face, (f64::from(coarse.x) + 1.0) * size, (f64::from(coarse.y) + 0.5) * size);
    let back_in = sphere.direction(face, (f64::from(coarse.x) + 0.8) * size, (f64::from(coarse.y) + 0.45) * size);
    let camera = look(above(source, back_in, 0.8 * width), above(source, middle, 0.0));
    let view = assemble_leaves(source, &leaves, 30.0, options).expect("meshable leaves");
    (view, camera)
}

#[test]
fn lod_differences_1_to_3_on_one_edge_are_closed() {
    let source = planet(3);
    for k in 1..=3 {
        for (face, at_face_edge) in [(CubeFace::PosY, false), (CubeFace::NegZ, true)] {
            let (view, camera) = lod_step(&source, k, face, at_face_edge, MeshOptions::default());
            check(
                &format!("LOD step {k} on {face:?}{}", if at_face_edge { " across a cube edge" } else { "" }),
                &view,
                &camera,
                0.9,
            );
        }
    }
}

#[test]
fn the_oracle_finds_cracks_when_seams_are_off() {
    let source = planet(3);
    let off = MeshOptions::NO_SEAMS;
    let mut cracks_off = 0;
    let mut t_junctions_off = 0;
    for k in 1..=3 {
        let (view, camera) = lod_step(&source, k, CubeFace::PosY, false, off);
        let report = cast_cracks(&view, &camera, RAYS, RAYS);
        let topology = boundary_topology(&view);
        println!("seams off, LOD step {k}: cracks {}, t-junctions {}", report.cracks, topology.t_junctions);
        cracks_off += report.cracks;
        t_junctions_off += topology.t_junctions;
        let (view_on, _) = lod_step(&source, k, CubeFace::PosY, false, MeshOptions::default());
        let on = cast_cracks(&view_on, &camera, RAYS, RAYS);
        println!(
            "seams on,  LOD step {k}: cracks {}, t-junctions {}",
            on.cracks,
            boundary_topology(&view_on).t_junctions
        );
    }
    assert!(cracks_off > 0, "with skirts and constraining off the oracle must see light through the seams");
    // (The lattice T-junction count only compares fine vertices on the
    // radial layer of a coarse edge; with far-corner LOD sampling the two
    // sides of these steps rarely share a layer, so it is printed, not
    // asserted: the ray-cast count above is the check that sees the gaps.)
    println!("t-junctions with seams off: {t_junctions_off}");
}

#[test]
fn every_frame_of_a_camera_path_is_closed() {
    let source = planet(11);
    let mut tree = LodTree::new(&source, settings(60.0, BalanceMode::Unrestricted)).unwrap();
    let start = DVec3::new(-0.3, 0.2, 1.0).normalize();
    let heading = DVec3::X;
    for frame in 0..6 {
        let dir = (start + heading * (0.02 * f64::from(frame))).normalize();
        let eye = above(&source, dir, 30.0 + 10.0 * f64::from(frame));
        let ahead = above(&source, (dir + heading * 0.03).normalize(), 0.0);
        let camera = look(eye, ahead);
        tree.update(&source, &camera).unwrap();
        tree.cull(&camera).unwrap();
        let view = view_of_tree(&source, &tree, MeshOptions::default()).unwrap();
        check(&format!("path frame {frame}"), &view, &camera, 0.4);
    }
}

#[test]
fn a_crater_across_a_chunk_and_a_face_edge_is_closed() {
    let mut source = EditedSource::new(planet(5));
    let sphere = *source.layout().sphere();
    let n = f64::from(sphere.resolution());
    // On the border of +X and its +V neighbour, off a chunk corner.
    let dir = sphere.direction(CubeFace::PosX, n * 0.5 + 40.0, n);
    let ground = source.base().surface_point(dir).length();
    let dirty = source.fill_sphere(dir * ground, 20.0, Voxel::AIR).unwrap();
    assert!(dirty.iter().any(|k| k.face != CubeFace::PosX));
    let camera = look(dir * (ground + 60.0) + dir.any_orthonormal_vector() * 40.0, dir * (ground - 10.0));
    for balance in [BalanceMode::Unrestricted, BalanceMode::Restricted] {
        let view = assemble(&source, &camera, settings(60.0, balance), MeshOptions::default()).unwrap();
        check(&format!("crater ({balance:?})"), &view, &camera, 0.9);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4, ..ProptestConfig::default() })]

    #[test]
    fn random_cameras_and_seeds_show_no_cracks(
        seed in any::<u32>(), x in -1.0f64..1.0, y in -1.0f64..1.0, z in 0.1f64..1.0, height in 20.0f64..2_000.0,
        tilt in 0.0f64..0.9,
    ) {
        let source = planet(seed);
        let dir = DVec3::new(x, y, z).normalize();
        let eye = above(&source, dir, height);
        let side = dir.any_orthonormal_vector();
        let camera = look(eye, eye - dir * height + side * height * tilt);
        let view = assemble(&source, &camera, settings(60.0, BalanceMode::Unrestricted), MeshOptions::default()).unwrap();
        let report = cast_cracks(&view, &camera, 96, 96);
        prop_assert_eq!(report.cracks, 0, "cracks near {:?}", report.first_crack_chunks);
        prop_assert_eq!(boundary_topology(&view).t_junctions, 0);
    }
}

#[test]
fn stitched_seams_close_every_view_and_lod_step_without_a_skirt() {
    // The same LOD steps and cameras as above, meshed with stitches in the
    // boundary planes instead of skirts (`nebula_meshing::stitch`): no
    // crack, no skirt triangle. (With no seam closure at all the same
    // steps leak: `the_oracle_finds_cracks_when_seams_are_off`.)
    let source = planet(3);
    for k in 1..=3 {
        for (face, at_face_edge) in [(CubeFace::PosY, false), (CubeFace::NegZ, true)] {
            let (view, camera) = lod_step(&source, k, face, at_face_edge, MeshOptions::STITCHED);
            let name =
                format!("stitched LOD step {k} on {face:?}{}", if at_face_edge { " across a cube edge" } else { "" });
            let report = cast_cracks(&view, &camera, RAYS, RAYS);
            let skirts: usize = view.meshes.iter().map(|m| m.skirt_triangle_count()).sum();
            println!("{name}: {} triangles, cracks {}", report.triangles, report.cracks);
            assert_eq!(report.cracks, 0, "{name}: cracks near {:?}", report.first_crack_chunks);
            assert_eq!(skirts, 0, "{name}");
        }
    }
    let source = planet(7);
    let corner = DVec3::ONE.normalize();
    let edge = DVec3::new(1.0, 1.0, 0.0).normalize();
    let cameras = [
        (
            "low over a cube corner",
            60.0,
            look(above(&source, corner, 40.0), above(&source, corner + DVec3::X * 0.05, 0.0)),
        ),
        (
            "grazing along a cube edge, 12°",
            12.0,
            look(above(&source, edge, 15.0), above(&source, (edge + DVec3::Z * 0.08).normalize(), 0.0)),
        ),
    ];
    for (name, fov, camera) in &cameras {
        let view = assemble(&source, camera, settings(*fov, BalanceMode::Unrestricted), MeshOptions::STITCHED).unwrap();
        let report = cast_cracks(&view, camera, RAYS, RAYS);
        let diff = view.stats.as_ref().map_or(0, |s| s.max_neighbor_lod_diff);
        println!(
            "stitched {name}: {} triangles, cracks {}, max LOD difference {diff}",
            report.triangles, report.cracks
        );
        assert_eq!(report.cracks, 0, "stitched {name}: cracks near {:?}", report.first_crack_chunks);
    }
}
