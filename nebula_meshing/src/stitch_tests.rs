//! Stitched seams (`crate::stitch`) close up between chunks of any two LODs,
//! on one cube face and across cube edges, for arbitrary voxels.

use std::collections::{HashMap, HashSet};
use std::sync::OnceLock;

use nebula_math::{CubeFace, DVec3, LatticePoint};
use nebula_voxel::{
    CHUNK_SIZE, ChunkColumn, ChunkKey, ChunkLayout, ChunkVoxels, PlanetSettings, ProceduralPlanet, SurfaceBounds,
    Voxel, VoxelCoord, VoxelError, VoxelSource,
};
use proptest::prelude::*;

use crate::mesh::on_one_line;
use crate::mesher::StitchParts;
use crate::*;

fn layout() -> &'static ChunkLayout {
    static PLANET: OnceLock<ProceduralPlanet> = OnceLock::new();
    PLANET.get_or_init(|| ProceduralPlanet::new(PlanetSettings::small(5)).unwrap()).layout()
}

/// Random voxels under the planet's LOD rule: a voxel of any LOD is the
/// LOD-0 voxel in its far corner, each LOD-0 voxel solid with probability
/// `density` / 256 (from a hash of its coordinates and `seed`).
struct RandomSource {
    layout: ChunkLayout,
    seed: u64,
    density: u8,
}

impl RandomSource {
    fn hash(&self, at: VoxelCoord) -> u8 {
        let span = self.layout.voxel_span(at.lod);
        let far = |c: i64| (c + 1) * span - 1;
        let mut h = self.seed ^ (at.face as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        for c in [far(at.i.into()), far(at.j.into()), far(at.h.into())] {
            h = (h ^ c as u64).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            h ^= h >> 31;
        }
        (h >> 56) as u8
    }
}

impl VoxelSource for RandomSource {
    fn layout(&self) -> &ChunkLayout {
        &self.layout
    }

    fn voxel(&self, at: VoxelCoord) -> Result<Voxel, VoxelError> {
        self.layout.check_voxel(at)?;
        let b = self.hash(at);
        Ok(if b < self.density { Voxel::from_material(1 + b % 3) } else { Voxel::AIR })
    }

    fn fill_chunk(&self, key: ChunkKey, out: &mut ChunkVoxels) -> Result<(), VoxelError> {
        self.layout.check_key(key)?;
        out.set_key(key);
        let size = i64::from(CHUNK_SIZE);
        let per_edge = i64::from(self.layout.voxels_per_edge(key.lod));
        for z in 0..34u32 {
            for x in 0..34u32 {
                let (ci, cj) = (i64::from(key.x) * size + i64::from(x) - 1, i64::from(key.y) * size + i64::from(z) - 1);
                let Some((face, i, j)) = key.face.wrap_cell(ci, cj, per_edge) else { continue };
                for y in 0..34u32 {
                    let h = (i64::from(key.layer) * size + i64::from(y) - 1) as i32;
                    let at = VoxelCoord { face, lod: key.lod, i: i as u32, j: j as u32, h };
                    out.set([x, y, z], self.voxel(at)?);
                }
            }
        }
        Ok(())
    }

    fn surface_bounds(&self, _column: ChunkColumn) -> Result<SurfaceBounds, VoxelError> {
        Err(VoxelError::VoxelOutOfRange {
            at: VoxelCoord { face: CubeFace::PosX, lod: 0, i: 0, j: 0, h: 0 },
            reason: "no bounds for random voxels".into(),
        })
    }

    fn geometric_error(&self, _lod: u8) -> f64 {
        0.0
    }
}

/// A lattice point of a seam's plane: (along, height) in the fine chunk.
type PlanePoint = (i32, i32);

/// A fine chunk and the coarser chunk across one of its sides.
#[derive(Clone, Copy, Debug)]
struct Seam {
    fine: ChunkKey,
    side: FaceDirection,
    coarse: ChunkKey,
    coarse_side: FaceDirection,
    lod_diff: u8,
}

/// The seam on `side` of a chunk at `lod` next to a chunk `lod_diff` LODs
/// coarser, on `face`, at the cube edge when `cube_edge`, else inside the
/// face; `pick` chooses the chunk along the seam and its layer.
fn seam(face: CubeFace, lod: u8, lod_diff: u8, side: FaceDirection, cube_edge: bool, pick: u32) -> Seam {
    let layout = layout();
    let per_edge = layout.chunks_per_edge(lod);
    let block = 1u32 << lod_diff;
    // Across the side, the fine chunk's neighbour must be the first of its
    // coarse ancestor's: the fine chunk sits at the end of a block.
    let across = if cube_edge {
        if side.is_positive() { per_edge - 1 } else { 0 }
    } else {
        let k = 1 + pick % (per_edge / block - 1);
        if side.is_positive() { k * block - 1 } else { k * block }
    };
    let along = pick.wrapping_mul(7) % per_edge;
    let (x, y) = if side.axis() == 0 { (across, along) } else { (along, across) };
    let fine = ChunkKey { face, lod, x, y, layer: (pick % 5) as i32 - 1 };
    let near = layout.neighbor(fine, side.face_edge().unwrap());
    let up = |key: ChunkKey| ChunkKey {
        lod: key.lod + lod_diff,
        x: key.x >> lod_diff,
        y: key.y >> lod_diff,
        layer: key.layer.div_euclid(1 << lod_diff),
        ..key
    };
    let coarse = up(near);
    let coarse_side = FaceDirection::HORIZONTAL
        .into_iter()
        .find(|s| layout.neighbor(coarse, s.face_edge().unwrap()) == up(fine))
        .expect("the coarse chunk borders the fine chunk's ancestor");
    Seam { fine, side, coarse, coarse_side, lod_diff }
}

fn context(lod: u8, side: FaceDirection, relation: NeighborLodRelation) -> ChunkLodContext {
    let mut context = ChunkLodContext::uniform(lod);
    context.set(side, relation);
    context
}

/// What is wrong with a stitched seam: directed edges in the boundary
/// plane not matched by the reverse (an open seam, counted per unit of
/// lattice line), fine vertices inside a coarse edge not zipped to it,
/// and lattice points the two chunks place apart.
#[derive(Debug, Default, PartialEq, Eq)]
struct SeamDefects {
    open: usize,
    unzipped: usize,
    apart: usize,
}

/// Meshes both chunks of `seam` from `source` (the coarse one told of its
/// finer neighbour unless `coarse_told` is false) and checks the boundary
/// plane inside the fine chunk's side (its outer lines are shared with the
/// chunks above, below and along, and left out).
fn stitched_seam_defects(source: &RandomSource, seam: Seam, parts: StitchParts, coarse_told: bool) -> SeamDefects {
    let layout = source.layout();
    let mut buffer = ChunkMeshBuffer::new();
    buffer.mesher.stitch_parts = parts;
    let fine_context =
        context(seam.fine.lod, seam.side, NeighborLodRelation::HigherThanNeighbor { lod_diff: seam.lod_diff });
    let fine = mesh_chunk(source, seam.fine, &fine_context, MeshOptions::STITCHED, &mut buffer).unwrap();
    let coarse_relation = if coarse_told { NeighborLodRelation::LowerThanNeighbor } else { NeighborLodRelation::Same };
    let coarse_context = context(seam.coarse.lod, seam.coarse_side, coarse_relation);
    let coarse = mesh_chunk(source, seam.coarse, &coarse_context, MeshOptions::STITCHED, &mut buffer).unwrap();

    // The plane's lattice points, in the fine chunk's (along, height).
    let along_axis = if seam.side.axis() == 0 { 2 } else { 0 };
    let plane = if seam.side.is_positive() { 32 } else { 0 };
    let mut on_plane: HashMap<LatticePoint, (i32, i32)> = HashMap::new();
    for height in 0..=32 {
        for along in 0..=32 {
            let mut local = [0i64; 3];
            local[seam.side.axis()] = plane;
            local[1] = i64::from(height);
            local[along_axis] = i64::from(along);
            on_plane.insert(layout.lattice_point(seam.fine, local).unwrap(), (along, height));
        }
    }
    let mut defects = SeamDefects::default();
    // Every vertex at a lattice point of the plane, from either mesh, in one place.
    let mut world: HashMap<LatticePoint, DVec3> = HashMap::new();
    // Directed edges in the plane, off its outer lines; degenerate triangles.
    let mut edges: Vec<((i32, i32), (i32, i32))> = Vec::new();
    let mut fans: Vec<[(i32, i32); 3]> = Vec::new();
    let mut fine_points: HashSet<(i32, i32)> = HashSet::new();
    for (mesh, is_fine) in [(&fine, true), (&coarse, false)] {
        assert_eq!(mesh.skirt_triangle_count(), 0, "stitched meshes hang no skirt");
        for triangle in mesh.indices().chunks_exact(3) {
            let points: Vec<Option<(i32, i32)>> = triangle
                .iter()
                .map(|&i| {
                    let point = mesh.lattice_point(i as usize)?;
                    let at = *on_plane.get(&point)?;
                    let position = mesh.world_position(i as usize).unwrap();
                    // The coarse lattice's points must be bit-identical in
                    // both chunks; fine points off it were constrained.
                    if let Some(&known) = world.get(&point) {
                        if known != position && (is_fine || at.0 % (1 << seam.lod_diff) == 0) {
                            defects.apart += 1;
                        }
                    } else {
                        world.insert(point, position);
                    }
                    Some(at)
                })
                .collect();
            if is_fine {
                fine_points.extend(points.iter().flatten());
            }
            let [Some(a), Some(b), Some(c)] = [points[0], points[1], points[2]] else {
                // Edges with one end off the plane: check those in it.
                for k in 0..3 {
                    if let (Some(p), Some(q)) = (points[k], points[(k + 1) % 3]) {
                        edges.push((p, q));
                    }
                }
                continue;
            };
            let cross = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
            if cross == 0 {
                fans.push([a, b, c]);
            }
            edges.extend([(a, b), (b, c), (c, a)]);
        }
    }
    let outer = |p: (i32, i32), q: (i32, i32)| {
        (p.0 == q.0 && (p.0 == 0 || p.0 == 32)) || (p.1 == q.1 && (p.1 == 0 || p.1 == 32))
    };
    // Balance per lattice line, per unit interval (so a fine chain along a
    // coarse edge balances it); slanted edges by identity.
    let mut units: HashMap<(PlanePoint, PlanePoint), i32> = HashMap::new();
    for &(p, q) in edges.iter().filter(|&&(p, q)| !outer(p, q)) {
        if p.0 == q.0 || p.1 == q.1 {
            let (dx, dy) = ((q.0 - p.0).signum(), (q.1 - p.1).signum());
            let mut at = p;
            while at != q {
                let next = (at.0 + dx, at.1 + dy);
                let (key, sign) = if at < next { ((at, next), 1) } else { ((next, at), -1) };
                *units.entry(key).or_insert(0) += sign;
                at = next;
            }
        } else {
            let (key, sign) = if p < q { ((p, q), 1) } else { ((q, p), -1) };
            *units.entry(key).or_insert(0) += sign;
        }
    }
    defects.open = units.values().filter(|&&n| n != 0).count();
    // Each coarse edge in the plane with fine vertices strictly inside must
    // be zipped to all of them by zero-area triangles from its first end.
    for triangle in coarse.indices().chunks_exact(3) {
        for k in 0..3 {
            let (i, j) = (triangle[k] as usize, triangle[(k + 1) % 3] as usize);
            let (Some(p), Some(q)) = (
                coarse.lattice_point(i).and_then(|l| on_plane.get(&l).copied()),
                coarse.lattice_point(j).and_then(|l| on_plane.get(&l).copied()),
            ) else {
                continue;
            };
            if outer(p, q) {
                continue;
            }
            let inside: Vec<(i32, i32)> = lattice_between(p, q).filter(|x| fine_points.contains(x)).collect();
            let zipped: HashSet<(i32, i32)> = fans
                .iter()
                .filter(|fan| (fan.contains(&p) || fan.contains(&q)) && fan.iter().all(|&x| on_segment(x, p, q)))
                .flatten()
                .copied()
                .collect();
            defects.unzipped += inside.iter().filter(|x| !zipped.contains(x)).count();
        }
    }
    defects
}

fn lattice_between(p: (i32, i32), q: (i32, i32)) -> impl Iterator<Item = (i32, i32)> {
    let (dx, dy) = ((q.0 - p.0).signum(), (q.1 - p.1).signum());
    let n = (q.0 - p.0).abs().max((q.1 - p.1).abs());
    (1..n).map(move |k| (p.0 + k * dx, p.1 + k * dy))
}

fn on_segment(x: (i32, i32), p: (i32, i32), q: (i32, i32)) -> bool {
    let cross = (q.0 - p.0) * (x.1 - p.1) - (q.1 - p.1) * (x.0 - p.0);
    cross == 0 && x.0 >= p.0.min(q.0) && x.0 <= p.0.max(q.0) && x.1 >= p.1.min(q.1) && x.1 <= p.1.max(q.1)
}

fn random_source(seed: u64, density: u8) -> RandomSource {
    RandomSource { layout: *layout(), seed, density }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Arbitrary voxels, any side, LOD differences 1–3, inside a face and
    /// across cube edges: the stitched seam is closed, every coarse edge is
    /// zipped to the fine vertices on it, and the two chunks place the
    /// coarse lattice bit for bit alike.
    #[test]
    fn stitched_seams_close_up(
        seed in any::<u64>(),
        density in 0u8..=255,
        lod in 0u8..=1,
        lod_diff in 1u8..=3,
        side in 0usize..4,
        face in 0usize..6,
        cube_edge in any::<bool>(),
        pick in any::<u32>(),
    ) {
        let seam = seam(CubeFace::ALL[face], lod, lod_diff, FaceDirection::HORIZONTAL[side], cube_edge, pick);
        let defects = stitched_seam_defects(&random_source(seed, density), seam, StitchParts::ALL, true);
        prop_assert_eq!(defects, SeamDefects::default(), "{:?}", seam);
    }
}

/// The check above fails when a part of the stitch is left out: the
/// coarse neighbour's faces in the plane, the zips, or the coarse chunk's
/// share (not told of its finer neighbour, it draws its own faces in the
/// plane at its own resolution and keeps only its canonical vertices).
#[test]
fn a_stitch_left_out_opens_the_seam() {
    let source = random_source(7, 128);
    for (lod_diff, cube_edge) in [(1, false), (2, true), (3, false)] {
        let seam = seam(CubeFace::PosY, 0, lod_diff, FaceDirection::PosZ, cube_edge, 3);
        assert_eq!(stitched_seam_defects(&source, seam, StitchParts::ALL, true), SeamDefects::default());
        let no_mirror = StitchParts { mirror_faces: false, ..StitchParts::ALL };
        assert!(stitched_seam_defects(&source, seam, no_mirror, true).open > 0, "{seam:?}");
        let no_zips = StitchParts { zips: false, ..StitchParts::ALL };
        assert!(stitched_seam_defects(&source, seam, no_zips, true).unzipped > 0, "{seam:?}");
        assert!(stitched_seam_defects(&source, seam, StitchParts::ALL, false).open > 0, "{seam:?}");
    }
}

/// A stitch's zips cover no surface, so the outline a fallback skirt hangs
/// from (the edges in the plane only one surface triangle uses) is the same
/// with them and without: a zip over an outline edge must not hide it.
#[test]
fn zips_leave_the_outline_where_it_was() {
    let mut zipped_outlines = 0;
    for (seed, lod_diff, side) in [(3, 1, 0), (4, 2, 2), (5, 1, 1), (6, 3, 3), (7, 1, 2), (8, 2, 0)] {
        let source = random_source(seed, 150);
        let seam = seam(CubeFace::NegX, 0, lod_diff, FaceDirection::HORIZONTAL[side], seed % 2 == 0, seed as u32);
        let relation = NeighborLodRelation::HigherThanNeighbor { lod_diff };
        let options = MeshOptions { draw_time_skirts: true, skirts: true, ..MeshOptions::STITCHED };
        let outline = |parts: StitchParts| {
            let mut buffer = ChunkMeshBuffer::new();
            buffer.mesher.stitch_parts = parts;
            let mesh = mesh_chunk(&source, seam.fine, &context(0, seam.side, relation), options, &mut buffer).unwrap();
            let mut edges: Vec<_> = mesh
                .outline_edges(seam.side)
                .into_iter()
                .map(|(a, b)| (mesh.local(a as usize).unwrap(), mesh.local(b as usize).unwrap()))
                .collect();
            edges.sort_unstable();
            (edges, mesh.triangle_count())
        };
        let (with, triangles_with) = outline(StitchParts::ALL);
        let (without, triangles_without) = outline(StitchParts { zips: false, ..StitchParts::ALL });
        assert!(triangles_with > triangles_without, "{seam:?}: no zip made");
        assert_eq!(with, without, "{seam:?}");
        zipped_outlines += usize::from(!with.is_empty());
    }
    assert!(zipped_outlines > 0, "no outline to compare");
}

/// A zip's winding on screen is rounding's, so both of its windings are
/// drawn whichever sides' faces a renderer leaves out for looking away
/// from the eye (`ChunkDraw::hidden_sides`): none is in a culled range.
#[test]
fn zips_are_drawn_whatever_sides_are_culled() {
    let source = random_source(11, 140);
    let mut zips = 0;
    for (side, lod_diff) in [(0, 1), (1, 2), (2, 1), (3, 3)] {
        let seam = seam(CubeFace::PosZ, 0, lod_diff, FaceDirection::HORIZONTAL[side], false, 5);
        let relation = NeighborLodRelation::HigherThanNeighbor { lod_diff };
        let mut buffer = ChunkMeshBuffer::new();
        let mesh = mesh_chunk(&source, seam.fine, &context(0, seam.side, relation), MeshOptions::STITCHED, &mut buffer)
            .unwrap();
        let zip_starts: Vec<usize> = (0..mesh.indices().len())
            .step_by(3)
            .filter(|&start| {
                let [p, q, r] = [0, 1, 2].map(|k| mesh.local_lattice(mesh.indices()[start + k] as usize).unwrap());
                on_one_line(p, q, r)
            })
            .collect();
        zips += zip_starts.len();
        // Every way of leaving out a column's walls (and their flattening
        // faces) draws the zips: they lie among the faces looking up,
        // which are never left out.
        for hidden_sides in 0..16u8 {
            let draw = ChunkDraw {
                parent_error: 1.0,
                skirt_depths: [0.0; 4],
                hidden_sides,
                hidden_flattening: hidden_sides,
                hidden_stubs: 0,
            };
            let ranges: Vec<_> = drawn_ranges(&mesh.surface_parts(), &draw).collect();
            for &start in &zip_starts {
                assert!(
                    ranges.iter().any(|r| r.contains(&start)),
                    "{seam:?}: a zip culled with sides {hidden_sides:#b}"
                );
            }
        }
    }
    assert!(zips > 0, "no zip to check");
}
