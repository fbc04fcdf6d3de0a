//! Tests of faces, edge folding and the canonical position function.

use proptest::prelude::*;

use crate::*;

fn planet(resolution: u32) -> Cubesphere {
    Cubesphere::new(6_371_000.0, resolution, 1.0, SphereMap::EquiAngular).unwrap()
}

#[test]
fn face_frames_are_right_handed_and_outward() {
    for face in CubeFace::ALL {
        assert_eq!(face.u_axis().cross(face.v_axis()), face.normal(), "{face:?}");
        assert_eq!(face.normal().abs().max_element(), 1);
        assert_eq!(CubeFace::from_axis(face.axis(), face.is_positive()), face);
        assert_eq!(CubeFace::from_index(face as usize), Some(face));
    }
    assert_eq!(CubeFace::from_index(6), None);
}

#[test]
fn edge_adjacency_is_symmetric_and_covers_24_pairings() {
    let mut pairs = std::collections::HashSet::new();
    for face in CubeFace::ALL {
        for edge in FaceEdge::ALL {
            let there = face.neighbor(edge);
            assert_ne!(there.face, face);
            assert_ne!(there.face.axis(), face.axis(), "{face:?} {edge:?} meets its opposite face");
            let back = there.face.neighbor(there.edge);
            assert_eq!((back.face, back.edge, back.reversed), (face, edge, there.reversed));
            pairs.insert((face, edge));
        }
    }
    assert_eq!(pairs.len(), 24);
    // Nebula's cyclic frames glue every edge without a flip (documented in
    // `face`): the along-edge coordinate is preserved.
    assert!(CubeFace::ALL.iter().all(|f| FaceEdge::ALL.iter().all(|&e| !f.neighbor(e).reversed)));
}

#[test]
fn shared_edge_points_have_the_same_cube_coordinates() {
    let n = 64;
    for face in CubeFace::ALL {
        for edge in FaceEdge::ALL {
            let there = face.neighbor(edge);
            for t in 0..=n {
                let here = edge_point(edge, t, n);
                let t_there = if there.reversed { n - t } else { t };
                let other = edge_point(there.edge, t_there, n);
                assert_eq!(
                    face.face_to_cube(here.0, here.1, n),
                    there.face.face_to_cube(other.0, other.1, n),
                    "{face:?} {edge:?} t={t}"
                );
            }
        }
    }
}

/// In-face coordinates of the point `t` along `edge` (t runs along the
/// face's other axis).
fn edge_point(edge: FaceEdge, t: i64, n: i64) -> (i64, i64) {
    match edge {
        FaceEdge::NegU => (0, t),
        FaceEdge::PosU => (n, t),
        FaceEdge::NegV => (t, 0),
        FaceEdge::PosV => (t, n),
    }
}

#[test]
fn corners_touch_three_faces_at_their_face_corners() {
    let n = 32;
    for corner in CubeCorner::ALL {
        let faces = corner.faces(n);
        let cubes: Vec<_> = faces.iter().map(|&(f, i, j)| f.face_to_cube(i, j, n)).collect();
        assert!(cubes.iter().all(|c| *c == cubes[0]));
        for (_, i, j) in faces {
            assert!((i == 0 || i == n) && (j == 0 || j == n));
        }
    }
    let distinct: std::collections::HashSet<_> = CubeCorner::ALL.iter().map(|c| c.signs).collect();
    assert_eq!(distinct.len(), 8);
}

#[test]
fn wrapping_across_an_edge_and_back_is_the_identity() {
    let n = 16;
    for face in CubeFace::ALL {
        for edge in FaceEdge::ALL {
            let (di, dj) = edge.step();
            for t in 0..n {
                for depth in 0..3 {
                    // The cell `depth` cells beyond `edge`, at position t along it.
                    let (i, j) = match edge {
                        FaceEdge::NegU => (-1 - depth, t),
                        FaceEdge::PosU => (n + depth, t),
                        FaceEdge::NegV => (t, -1 - depth),
                        FaceEdge::PosV => (t, n + depth),
                    };
                    let (there, a, b) = face.wrap_cell(i, j, n).unwrap();
                    assert_eq!(there, face.neighbor(edge).face);
                    assert!((0..n).contains(&a) && (0..n).contains(&b));
                    // Stepping back out of the neighbour across its shared
                    // edge from the first cell returns to our edge cell.
                    if depth == 0 {
                        let back = face.neighbor(edge).edge;
                        let (bi, bj) = back.step();
                        let (home, x, y) = there.wrap_cell(a + bi, b + bj, n).unwrap();
                        assert_eq!(home, face);
                        assert_eq!((x + di, y + dj), (i, j));
                    }
                }
            }
        }
    }
    // Corner gap: beyond two edges at once.
    assert_eq!(CubeFace::PosZ.wrap_cell(-1, -1, n), None);
    assert_eq!(CubeFace::PosZ.wrap_point(n + 1, -2, n), None);
    assert_eq!(CubeFace::PosZ.wrap_cell(3, 4, n), Some((CubeFace::PosZ, 3, 4)));
}

#[test]
fn wrapped_cells_are_spatial_neighbours() {
    // The cell just across an edge is the nearest cell on the other face.
    let planet = planet(64);
    let n = 64;
    for face in CubeFace::ALL {
        for edge in FaceEdge::ALL {
            let t = 17;
            let (i, j) = match edge {
                FaceEdge::NegU => (0, t),
                FaceEdge::PosU => (n - 1, t),
                FaceEdge::NegV => (t, 0),
                FaceEdge::PosV => (t, n - 1),
            };
            let (di, dj) = edge.step();
            let (there, a, b) = face.wrap_cell(i + di, j + dj, n).unwrap();
            let here_dir = planet.direction(face, i as f64 + 0.5, j as f64 + 0.5);
            let there_dir = planet.direction(there, a as f64 + 0.5, b as f64 + 0.5);
            // Compare with the step to the next cell inwards on our own face
            // (3 % apart: the cells meet at the edge at an angle).
            let inward = planet.direction(face, (i - di) as f64 + 0.5, (j - dj) as f64 + 0.5);
            let cell_angle = here_dir.angle_between(inward);
            let angle = here_dir.angle_between(there_dir);
            assert!((angle - cell_angle).abs() < 0.05 * cell_angle, "{face:?} {edge:?}: {angle} vs {cell_angle}");
        }
    }
}

#[test]
fn lattice_points_are_checked() {
    let p = planet(1024);
    assert!(matches!(p.lattice_point(CubeFace::PosX, -1, 0, 0), Err(MathError::OutsideFace { .. })));
    assert!(matches!(p.lattice_point(CubeFace::PosX, 0, 1025, 0), Err(MathError::OutsideFace { .. })));
    assert!(matches!(p.lattice_point(CubeFace::PosX, 0, 0, -7_000_000), Err(MathError::LayerBelowCentre { .. })));
    assert!(matches!(p.lattice_point(CubeFace::PosX, 0, 0, i64::MAX), Err(MathError::LayerBelowCentre { .. })));
    assert!(matches!(Cubesphere::new(1.0, 3, 1.0, SphereMap::EquiAngular), Err(MathError::BadResolution { .. })));
    assert!(matches!(Cubesphere::new(1.0, 0, 1.0, SphereMap::EquiAngular), Err(MathError::BadResolution { .. })));
    assert!(matches!(Cubesphere::new(f64::NAN, 2, 1.0, SphereMap::EquiAngular), Err(MathError::NonFinite { .. })));
    assert!(matches!(Cubesphere::new(1.0, 2, 0.0, SphereMap::EquiAngular), Err(MathError::NotPositive { .. })));
    assert!(matches!(p.face_coords_of(DVec3::ZERO), Err(MathError::NotPositive { .. })));
    assert!(matches!(p.face_coords_of(DVec3::new(f64::NAN, 0.0, 1.0)), Err(MathError::NonFinite { .. })));
}

#[test]
fn earth_scale_chunk_relative_offsets_keep_millimetres() {
    // Earth radius, 2²³ cells per face edge (~1.19 m voxels), a 32-voxel chunk
    // at a face corner where f64 → f32 of absolute positions would be worst.
    let p = Cubesphere::new(6_371_000.0, 1 << 23, 1.19, SphereMap::EquiAngular).unwrap();
    let origin = p.position(p.lattice_point(CubeFace::PosZ, 0, 0, 0).unwrap());
    let mut worst = 0.0_f64;
    for (i, j, h) in [(32, 32, 32), (1, 0, 0), (17, 5, -3), (0, 32, 32)] {
        let world = p.position(p.lattice_point(CubeFace::PosZ, i, j, h).unwrap());
        let rel = relative_position(world, origin);
        let back = origin + rel.as_dvec3();
        worst = worst.max((back - world).length());
    }
    // f32 offsets of < 60 m carry ~4 µm of rounding; absolute f32 would be ~0.5 m.
    assert!(worst < 1e-5, "{worst}");
    let absolute_f32_error = (origin.as_vec3().as_dvec3() - origin).length();
    assert!(absolute_f32_error > 0.01, "{absolute_f32_error}");
}

#[test]
fn cell_width_matches_neighbouring_positions() {
    let p = planet(1 << 12);
    let n = 1 << 12;
    let a = p.position(p.lattice_point(CubeFace::NegY, n / 2, n / 2, 0).unwrap());
    let b = p.position(p.lattice_point(CubeFace::NegY, n / 2 + 1, n / 2, 0).unwrap());
    assert!(((a - b).length() - p.cell_width()).abs() / p.cell_width() < 1e-6);
}

fn any_face() -> impl Strategy<Value = CubeFace> {
    (0usize..6).prop_map(|i| CubeFace::ALL[i])
}

fn any_edge() -> impl Strategy<Value = FaceEdge> {
    (0usize..4).prop_map(|i| FaceEdge::ALL[i])
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// A direction from warped coordinates is the direction of the cube
    /// point warped componentwise (the map's definition), bit for bit, for
    /// both maps, at lattice points, cell centres and anywhere between.
    #[test]
    fn warped_directions_are_the_cube_point_warped(
        face in any_face(), log_n in 1u32..24, a in 0.0f64..=1.0, b in 0.0f64..=1.0, snap in 0usize..3,
        equi_angular in any::<bool>(),
    ) {
        let n = 1u32 << log_n;
        let map = if equi_angular { SphereMap::EquiAngular } else { SphereMap::Gnomonic };
        let sphere = Cubesphere::new(6_371_000.0, n, 1.0, map).unwrap();
        let coord = |f: f64| match snap {
            0 => (f * f64::from(n)).floor(),
            1 => (f * f64::from(n)).floor() + 0.5,
            _ => f * f64::from(n),
        };
        let (i, j) = (coord(a), coord(b));
        let half = f64::from(n / 2);
        let t = face.normal().as_dvec3() + face.u_axis().as_dvec3() * ((i - half) / half) + face.v_axis().as_dvec3() * ((j - half) / half);
        let expected = map.direction(t);
        prop_assert_eq!(sphere.direction(face, i, j).to_array().map(f64::to_bits), expected.to_array().map(f64::to_bits));
        let warped = sphere.direction_warped(face, sphere.warp(i), sphere.warp(j));
        prop_assert_eq!(warped.to_array().map(f64::to_bits), expected.to_array().map(f64::to_bits));
    }

    /// A patch's 3 × 3 grid of directions (one warp per row and column) is
    /// `direction` at each of its points, bit for bit: chunk patches of any
    /// LOD (a power-of-two side at a multiple of it) on Earth.
    #[test]
    fn patch_directions_are_the_points_directions(
        face in any_face(), lod in 0u32..=18, a in 0.0f64..1.0, b in 0.0f64..1.0, equi_angular in any::<bool>(),
    ) {
        let n = 1u32 << 23;
        let map = if equi_angular { SphereMap::EquiAngular } else { SphereMap::Gnomonic };
        let sphere = Cubesphere::new(6_371_000.0, n, 1.0, map).unwrap();
        let size = f64::from(32u32 << lod);
        let patches = f64::from(n) / size;
        let (i0, j0) = ((a * patches).floor() * size, (b * patches).floor() * size);
        let grid = sphere.patch_directions(face, i0, j0, size);
        for (x, row) in grid.iter().enumerate() {
            for (y, direction) in row.iter().enumerate() {
                let expected = sphere.direction(face, i0 + x as f64 * 0.5 * size, j0 + y as f64 * 0.5 * size);
                prop_assert_eq!(direction.to_array().map(f64::to_bits), expected.to_array().map(f64::to_bits));
            }
        }
    }

    /// A lattice point on a face edge gives the bit-identical position from
    /// both faces, at any resolution and layer.
    #[test]
    fn edge_points_are_bit_identical_from_both_faces(
        face in any_face(), edge in any_edge(), log_n in 1u32..24, t_frac in 0.0f64..=1.0, layer in -500i64..5000,
    ) {
        let n = 1i64 << log_n;
        let p = Cubesphere::new(6_371_000.0, n as u32, 1.0, SphereMap::EquiAngular).unwrap();
        let t = ((n as f64) * t_frac) as i64;
        let (i, j) = edge_point(edge, t, n);
        let there = face.neighbor(edge);
        let t_there = if there.reversed { n - t } else { t };
        let (a, b) = edge_point(there.edge, t_there, n);
        let here = p.lattice_point(face, i, j, layer).unwrap();
        let other = p.lattice_point(there.face, a, b, layer).unwrap();
        prop_assert_eq!(here, other);
        let (x, y) = (p.position(here), p.position(other));
        prop_assert_eq!(x.to_array().map(f64::to_bits), y.to_array().map(f64::to_bits));
        // The point really is on both faces.
        prop_assert_eq!(p.face_coords(here, there.face), Some((a, b)));
        prop_assert_eq!(p.face_coords(here, face), Some((i, j)));
    }

    /// Corner points agree bit for bit from all three faces.
    #[test]
    fn corner_points_are_bit_identical_from_three_faces(corner in 0usize..8, log_n in 1u32..24, layer in -100i64..100) {
        let n = 1i64 << log_n;
        let p = Cubesphere::new(1_000.0, n as u32, 0.5, SphereMap::EquiAngular).unwrap();
        let faces = CubeCorner::ALL[corner].faces(n);
        let positions: Vec<[u64; 3]> = faces
            .iter()
            .map(|&(f, i, j)| p.position(p.lattice_point(f, i, j, layer).unwrap()).to_array().map(f64::to_bits))
            .collect();
        prop_assert_eq!(positions[0], positions[1]);
        prop_assert_eq!(positions[0], positions[2]);
    }

    /// Positions lie at the layer's radius, and the inverse map finds the
    /// face coordinates back.
    #[test]
    fn positions_have_the_layer_radius_and_invert(
        face in any_face(), i in 0i64..=4096, j in 0i64..=4096, layer in -100i64..100, gnomonic in any::<bool>(),
    ) {
        let map = if gnomonic { SphereMap::Gnomonic } else { SphereMap::EquiAngular };
        let p = Cubesphere::new(2_000.0, 4096, 0.5, map).unwrap();
        let world = p.position(p.lattice_point(face, i, j, layer).unwrap());
        prop_assert!((world.length() - (2_000.0 + 0.5 * layer as f64)).abs() < 1e-9);
        let (f, a, b) = p.face_coords_of(world).unwrap();
        // On an edge either face is a valid answer; compare world positions.
        let again = p.direction(f, a, b) * world.length();
        prop_assert!((again - world).length() < 1e-7, "{} vs {}", again, world);
        if (1..4096).contains(&i) && (1..4096).contains(&j) {
            prop_assert_eq!(f, face);
            prop_assert!((a - i as f64).abs() < 1e-6 && (b - j as f64).abs() < 1e-6);
        }
    }

    /// `direction` at integer coordinates agrees with `position`.
    #[test]
    fn fractional_direction_matches_lattice_position(face in any_face(), i in 0i64..=256, j in 0i64..=256) {
        let p = Cubesphere::new(10.0, 256, 0.1, SphereMap::EquiAngular).unwrap();
        let exact = p.position(p.lattice_point(face, i, j, 0).unwrap());
        let sampled = p.direction(face, i as f64, j as f64) * 10.0;
        prop_assert!((exact - sampled).length() < 1e-12);
    }
}

#[test]
fn side_walls_lie_in_their_lattice_planes() {
    let p = planet(256);
    for face in CubeFace::ALL {
        for coord in [0, 1, 77, 128, 255, 256] {
            for along_u in [true, false] {
                let normal = p.lattice_plane_normal(face, along_u, coord);
                let (a, b) = if along_u { ((coord, 3), (coord, 250)) } else { ((3, coord), (250, coord)) };
                for (i, j) in [a, b] {
                    for layer in [-3, 0, 40] {
                        let world = p.position(p.lattice_point(face, i, j, layer).unwrap());
                        assert!(normal.dot(world).abs() < 1e-6 * world.length(), "{face:?} {coord}");
                    }
                }
                // Points towards growing coord.
                let (c, d) = if along_u {
                    ((coord.min(255), 9), (coord.min(255) + 1, 9))
                } else {
                    ((9, coord.min(255)), (9, coord.min(255) + 1))
                };
                let step = p.position(p.lattice_point(face, d.0, d.1, 0).unwrap())
                    - p.position(p.lattice_point(face, c.0, c.1, 0).unwrap());
                assert!(normal.dot(step) > 0.0);
            }
        }
    }
}

#[test]
fn face_directions_map_to_face_edges() {
    for dir in FaceDirection::HORIZONTAL {
        let edge = dir.face_edge().unwrap();
        assert_eq!(FaceDirection::from_face_edge(edge), dir);
        assert_eq!(dir.opposite().face_edge(), Some(edge.opposite()));
        assert_ne!(dir.axis(), 1);
    }
    assert_eq!(FaceDirection::PosY.face_edge(), None);
    assert!(FaceDirection::ALL.iter().enumerate().all(|(i, d)| *d as usize == i));
}

#[test]
fn rays_meet_spheres_where_expected() {
    let eye = DVec3::new(0.0, 0.0, 10.0);
    assert_eq!(ray_sphere(eye, -DVec3::Z, 4.0), Some(6.0));
    assert_eq!(ray_sphere(eye, DVec3::Z, 4.0), None, "sphere behind");
    assert_eq!(ray_sphere(eye, DVec3::X, 4.0), None, "miss");
    let grazing = DVec3::new(0.6, 0.0, -0.8);
    let t = ray_sphere(eye, grazing, 6.0).unwrap();
    assert!(((eye + grazing * t).length() - 6.0).abs() < 1e-12);
}

#[test]
fn view_basis_is_orthonormal_and_right_handed() {
    let (f, r, u) = view_basis(DVec3::new(0.0, 0.0, -3.0), DVec3::new(0.2, 5.0, 0.1));
    assert!((f - DVec3::NEG_Z).length() < 1e-12);
    assert!((r - DVec3::X).length() < 0.05 && (r.length() - 1.0).abs() < 1e-12);
    assert!(f.dot(u).abs() < 1e-12 && r.dot(u).abs() < 1e-12 && (u.length() - 1.0).abs() < 1e-12);
    assert!((r.cross(u) - (-f)).length() < 1e-12, "right × up points back at the viewer");
}

#[test]
fn a_layer_below_the_centre_is_reported_as_given() {
    let p = planet(1024);
    let error = p.lattice_point(CubeFace::PosX, 0, 0, -7_000_000).unwrap_err();
    assert!(matches!(error, MathError::LayerBelowCentre { layer: -7_000_000, .. }), "{error:?}");
}
