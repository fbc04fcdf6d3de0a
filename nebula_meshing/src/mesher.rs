//! Greedy quads → T-junction-free triangles on the sphere.
//!
//! ```text
//!   Bitmask greedy meshing (`GreedyQuads`: block-mesh-bgm's quads, the
//!   faces block-mesh's `greedy_quads` covers) gives rectangles (greedy
//!   quads) in lattice space. On the sphere each is curved, so a vertex of
//!   a neighbouring quad that lies on a rectangle's edge would float off
//!   that edge's chord (a T-junction that leaks light). Every such vertex becomes part of the rectangle's
//!   outline, and the outline is triangulated as two chains zipped together:
//!
//!      tl ── t ──── t ── tr         chain A: tl ↓ left ↓ bl → bottom → br
//!      │  ╲     ╲    ╲   │          chain B: tl → top → tr ↓ right ↓ br
//!      l    ╲     ╲    ╲ r
//!      │ ╲    ╲     ╲   ╲│          Each triangle takes one step on one
//!      bl ── b ── b ───── br        chain; no triangle has all three
//!                                   corners on one side, so none is flat.
//! ```
//!
//! Which lattice points are on a rectangle's edge is decided in integers.
//! Inside the chunk: the corners of every quad in the chunk. On the chunk's
//! boundary planes the two chunks sharing a plane must agree without
//! seeing each other's quads, so there the vertex set is *canonical*, a
//! function of the voxels on both sides alone (DESIGN rule 4):
//!
//! - a greedy quad touching a boundary plane is kept when its corners on
//!   that plane are in the canonical set; otherwise, and always for faces
//!   lying in a boundary plane, the faces next to the plane are meshed as
//!   strips one voxel wide running along it, ended where the face changes
//!   (or, near a chunk edge, where the next plane begins, or where a kept
//!   quad does);
//! - an edge in a boundary plane is split at every lattice point whose
//!   2×2×2 voxels are not *plain* (plain: they vary along one axis at most,
//!   so the surface there is one flat face or none), at every point on a
//!   chunk edge, and at every point within one voxel of a chunk edge where
//!   a face not lying in the boundary plane meets it (there the strips
//!   along the plane end; a face lying in the plane, or none, needs no
//!   vertex there); on a radial plane's edge along its faces' strips
//!   (`FlatEdges`), only where something other than that plane's faces
//!   meets it.
//!
//! Every strip end is such a point, so both chunks put the same vertices on
//! every line they share. The first version split boundary edges at every
//! lattice point instead, which made 45 % of an Earth view's triangles.
//!
//! A side facing another LOD can still ask for every lattice point
//! ([`ChunkMesher::mesh_with_dense_sides`]): edge constraining
//! (`constrain_edge_vertices`) moves the odd ones onto the coarse chords, so
//! both chunks there must be dense. Both know the LOD relation, so they
//! agree; streaming meshes, whose skirts close LOD seams, stay canonical.

use block_mesh::ndshape::ConstShape;
use block_mesh::{OrientedBlockFace, RIGHT_HANDED_Y_UP_CONFIG, UnorientedQuad};
use nebula_math::{Cubesphere, DVec3, FaceDirection, LatticePoint, Vec3};
use nebula_voxel::{
    CHUNK_SIZE, ChunkKey, ChunkLayout, ChunkVoxels, PADDED_CHUNK_SIZE, PADDED_CHUNK_VOLUME, PADDED_COLUMNS,
    PADDED_ROWS, PaddedChunkShape, Voxel,
};

use crate::MeshError;
use crate::collapse::FlatInteriors;
use crate::greedy::GreedyQuads;
use crate::mesh::{ChunkMesh, VertexSource};
use crate::stitch::{StitchedSide, padded, plane_cells, solid};

/// Lattice points per axis of a chunk: 0..=32.
const POINTS: usize = CHUNK_SIZE as usize + 1;

/// The last lattice coordinate of a chunk (its far boundary plane).
const LAST: i32 = CHUNK_SIZE as i32;

/// Which lattice points on a chunk's boundary planes become vertices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BoundaryVertices {
    /// The canonical set (see the module docs): what meshing uses.
    Canonical,
    /// Only the corners of this chunk's own quads, as inside the chunk:
    /// what two neighbours cannot agree on. Tests use it to show that the
    /// seam checks fail without the canonical set.
    #[cfg(test)]
    OwnCornersOnly,
}

/// The parts of a stitched seam ([`crate::stitch`]) a mesher makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct StitchParts {
    /// The coarse neighbour's faces in the plane, looking into the chunk.
    pub mirror_faces: bool,
    /// The zero-area fans zipping coarse edges to the fine vertices on them.
    pub zips: bool,
}

impl StitchParts {
    pub(crate) const ALL: Self = Self { mirror_faces: true, zips: true };
}

/// Reusable scratch memory for greedy meshing one chunk after another.
pub struct ChunkMesher {
    greedy: GreedyQuads,
    /// A bit per lattice point: some quad has a corner there.
    corners: Vec<u64>,
    /// A bit per padded voxel: a kept greedy quad touching a boundary
    /// plane covers its face (of the face direction being meshed).
    covered: Vec<u64>,
    /// Per (side, lattice point), `vertex_slot`: `(stamp, vertex index)`.
    vertex_slot: Vec<(u32, u32)>,
    /// Per lattice column (x, z): `(stamp, unit direction)`.
    column_direction: Vec<(u32, DVec3)>,
    /// The radius of each of the chunk's lattice layers (local y), as
    /// [`Cubesphere::position_on_column`] scales a direction by it.
    layer_radius: [f64; POINTS],
    /// The chunk's columns on the cube and their coordinates' warps.
    column_warps: ColumnWarps,
    /// Per side-wall plane (x planes then z planes): `(stamp, unit normal
    /// towards growing coordinate)`.
    wall_normal: Vec<(u32, DVec3)>,
    stamp: u32,
    chain_a: Vec<[i32; 3]>,
    chain_b: Vec<[i32; 3]>,
    index_a: Vec<u32>,
    index_b: Vec<u32>,
    pub(crate) boundary_vertices: BoundaryVertices,
    /// Per horizontal side (index as in [`FaceDirection::HORIZONTAL`]):
    /// every lattice point on its plane is a vertex.
    dense_sides: [bool; 4],
    /// The radial planes' edges that may go without vertices where only
    /// flat ground lying in the plane meets them.
    flat_edges: FlatEdges,
    /// Per horizontal side: `Some(d)` where the neighbour is `d` LODs
    /// coarser and this chunk stitches the seam (`crate::stitch`).
    stitch_coarser: [Option<u8>; 4],
    /// Which parts of a stitch are made: all of them, except where a test
    /// leaves one out to see its check fail.
    pub(crate) stitch_parts: StitchParts,
    /// The chunk's [`ChunkVoxels::sky_floors`]: where each padded column
    /// is open to the sky.
    sky_floors: [u8; PADDED_COLUMNS],
    /// The chunk being meshed has no plugs and no dark air
    /// ([`ChunkVoxels::dark_air_columns_from`]): every face's vertices are
    /// lit.
    all_lit: bool,
    /// Per padded voxel (a bit each): dark air that
    /// [`ChunkMesher::plug_dark_air`] filled with rock.
    plugs: Vec<u64>,
    /// The chunk `plugs` was made for (taken by the next meshing).
    plugs_for: Option<ChunkKey>,
    /// Per padded voxel: 1 + the side (`FaceDirection as usize`) whose
    /// stub it is ([`ChunkMesher::find_stubs`]), 0 for none.
    stub_sides: Vec<u8>,
    /// The chunk `stub_sides` was made for.
    stubs_for: Option<ChunkKey>,
    /// Whether some dark air a side shares, off the other sides, borders
    /// this chunk's unplugged air ([`ChunkMesher::find_stubs`]).
    pub(crate) stubs_exposed: bool,
    /// Whether a pocket of dark air in a horizontal side's shared layers
    /// that is no stub reaches the layers shared with the chunk above
    /// (`[0]`) or below (`[1]`) ([`ChunkMesher::find_stubs`]).
    pub(crate) pockets_beyond: [bool; 2],
    /// How far [`ChunkMesher::plug_dark_air`] reaches towards the sides.
    pub(crate) plug_reach: PlugReach,
    /// Of a chunk plugged inside ([`PlugReach::Interior`]), the horizontal
    /// sides (as in [`FaceDirection::HORIZONTAL`]) whose neighbour is of
    /// its plug group ([`crate::plug_group`]), plugged alike: there the
    /// plugs reach the padding as `Padding`'s do.
    pub(crate) padded_sides: [bool; 4],
    /// Scratch of the flat regions' inner vertices' removal.
    pub(crate) flat_interiors: FlatInteriors,
    /// Whether those are removed (tests compare with them kept).
    pub(crate) collapse_flat_interiors: bool,
}

/// The layers of padded voxels a chunk shares with its neighbour on each
/// side, from that side in: the padding (the neighbour's boundary layer)
/// and its own boundary layer (the neighbour's padding). Plugs that keep
/// off a side keep off these; a side's stubs lie in them.
const SHARED_LAYERS: u32 = 2;

/// How far towards a chunk's sides [`ChunkMesher::plug_dark_air`] fills
/// dark air.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PlugReach {
    /// The whole padded chunk: chunks of one LOD that both plug fill the
    /// voxels they share alike (what streaming's skirted meshes take).
    Padding,
    /// One voxel off every horizontal side: the chunk's boundary layers
    /// and padding stay as the source has them, for stitched seams, where
    /// a finer neighbour reads this chunk's boundary layer from the source
    /// and closes the seam against it ([`crate::stitch`]).
    OffSides,
    /// One voxel off every horizontal side towards a column of another
    /// plug group ([`crate::plug_group`]; `ChunkMesher::padded_sides`), as
    /// `OffSides`: the layers the chunk shares with those neighbours stay
    /// as the source has them, so it closes up against any neighbour
    /// there, plugged or not (a tunnel crossing a side keeps a voxel-deep
    /// stub, capped by the plug), for a chunk plugged by a choice those
    /// neighbours need not share
    /// ([`MeshOptions::plug_dark_air_inside`](crate::MeshOptions::plug_dark_air_inside)).
    /// Radially and towards its own group it plugs as `Padding` does, so
    /// the chunks of a group must all plug inside or all not (the streamer
    /// swaps a group's meshes at once); the stubs of the other sides are
    /// found ([`ChunkMesher::find_stubs`]).
    Interior,
    /// The chunk's own voxels alone, not its padding: a test's control
    /// (the seams open).
    #[cfg(test)]
    OwnVoxels,
}

/// What a vertex is made for: a face looking towards `side` of voxel
/// material `material`; `on_face` when the point is on the outline of
/// such a face of the chunk (so a cell in front of it is air), not only
/// on a stitch's zip.
#[derive(Clone, Copy, Debug)]
struct VertexKind {
    side: FaceDirection,
    material: u8,
    on_face: bool,
}

impl Default for ChunkMesher {
    fn default() -> Self {
        Self::new()
    }
}

impl ChunkMesher {
    /// Scratch memory for one thread (about 1.8 MB, mostly vertex slots
    /// by lattice point and side).
    #[must_use]
    pub fn new() -> Self {
        Self {
            greedy: GreedyQuads::new(),
            corners: vec![0; (POINTS * POINTS * POINTS).div_ceil(64)],
            covered: vec![0; PADDED_CHUNK_VOLUME.div_ceil(64)],
            vertex_slot: vec![(0, 0); POINTS * POINTS * POINTS * 6],
            column_direction: vec![(0, DVec3::ZERO); POINTS * POINTS],
            layer_radius: [0.0; POINTS],
            column_warps: ColumnWarps::default(),
            wall_normal: vec![(0, DVec3::ZERO); 2 * POINTS],
            stamp: 0,
            chain_a: Vec::new(),
            chain_b: Vec::new(),
            index_a: Vec::new(),
            index_b: Vec::new(),
            boundary_vertices: BoundaryVertices::Canonical,
            dense_sides: [false; 4],
            flat_edges: FlatEdges::default(),
            stitch_coarser: [None; 4],
            stitch_parts: StitchParts::ALL,
            sky_floors: [0; PADDED_COLUMNS],
            all_lit: false,
            plugs: vec![0; PADDED_CHUNK_VOLUME.div_ceil(64)],
            plugs_for: None,
            stub_sides: vec![0; PADDED_CHUNK_VOLUME],
            stubs_for: None,
            stubs_exposed: false,
            pockets_beyond: [false; 2],
            plug_reach: PlugReach::Padding,
            padded_sides: [false; 4],
            flat_interiors: FlatInteriors::default(),
            collapse_flat_interiors: true,
        }
    }

    /// Fills the chunk's dark air (cave air under its column's
    /// [`ChunkVoxels::sky_floors`]) with stone, as far as its reach
    /// (the padding included, for the plugs of a whole LOD), and
    /// remembers it for the next meshing of this chunk: its
    /// faces towards the open air are then dark, as the cave behind them
    /// would be ([`ChunkMesher`]'s `sky_light`). What a cave looks like
    /// from afar, at a fraction of its triangles: seen from outside, a
    /// cave's inside shows only through its mouths, as a dark hole; its
    /// walls under the ground are what most of its triangles are. Returns
    /// how many voxels were filled.
    ///
    /// Why the padding too: whether a voxel is dark is its column's own
    /// property (solid somewhere above it, which a source that knows what
    /// lies over a chunk records for every column,
    /// [`ChunkVoxels::set_covered_above`]; without a record the two layers
    /// a chunk shares with each radial neighbour stay open), so two chunks
    /// of one LOD that both plug fill the voxels they share alike, and the
    /// faces and vertices on their boundary agree. One material for every
    /// plug: the rock a chunk holds of a column is not its radial
    /// neighbour's, and quads and boundary vertices split where materials
    /// change. (Plugs kept one voxel off every side before: every tunnel
    /// crossing a side left a voxel-deep stub of walls on both chunks, 53 %
    /// of a narrow lens's triangles at LOD 1: they are kept off the
    /// horizontal sides only where those neighbours may not plug alike:
    /// stitched seams at LODs plugged by themselves, and sides towards
    /// another plug group of a chunk plugged inside,
    /// [`MeshOptions::plug_dark_air_inside`](crate::MeshOptions::plug_dark_air_inside).) A chunk of another LOD
    /// shares no voxels; the skirts, as deep as the deepest cave, cover a
    /// tunnel's cross-section there, as they do where a coarse chunk is
    /// solid.
    pub fn plug_dark_air(&mut self, voxels: &mut ChunkVoxels) -> usize {
        self.plugs.fill(0);
        self.plugs_for = None;
        self.stubs_for = None;
        self.stubs_exposed = false;
        self.pockets_beyond = [false; 2];
        voxels.solid_rows(&mut self.greedy.rows);
        // Most chunks have no dark air: nothing to fill, and the meshing
        // then takes them as unplugged (open ground lit without looking).
        let dark_columns = voxels.dark_air_columns_from(&self.greedy.rows);
        if dark_columns.iter().all(|&columns| columns == 0) {
            return 0;
        }
        self.plugs_for = Some(voxels.key());
        // Plugs lie under the floors, so the meshing reuses them.
        self.sky_floors = voxels.sky_floors_from(&self.greedy.rows);
        let floors = self.sky_floors;
        let (low, high) = match self.plug_reach {
            PlugReach::Padding => (0, PADDED_CHUNK_SIZE),
            PlugReach::OffSides | PlugReach::Interior => (SHARED_LAYERS, PADDED_CHUNK_SIZE - SHARED_LAYERS),
            #[cfg(test)]
            PlugReach::OwnVoxels => (1, PADDED_CHUNK_SIZE - 1),
        };
        // Radially, a chunk knows its top layers dark only from what its
        // source recorded above it; a source that records nothing (a
        // world a game brings may not) leaves the two layers shared with
        // each radial neighbour as they are, as both neighbours then do.
        let (bottom, top) = match self.plug_reach {
            #[cfg(test)]
            PlugReach::OwnVoxels => (low, high),
            PlugReach::Padding | PlugReach::OffSides | PlugReach::Interior
                if voxels.covered_above((0, 0)).is_some() =>
            {
                (0, PADDED_CHUNK_SIZE)
            }
            _ => (SHARED_LAYERS, PADDED_CHUNK_SIZE - SHARED_LAYERS),
        };
        // Plugged inside, the sides towards the chunk's own plug group
        // reach the padding.
        let group = |side: usize, end: u32, margin: u32| {
            if self.plug_reach == PlugReach::Interior && self.padded_sides[side] { end } else { margin }
        };
        let (x_low, x_high) = (group(1, 0, low), group(0, PADDED_CHUNK_SIZE, high));
        let (z_low, z_high) = (group(3, 0, low), group(2, PADDED_CHUNK_SIZE, high));
        let slice = voxels.as_mut_slice();
        let mut filled = 0;
        for z in z_low..z_high {
            // The columns with air under their floor: the only ones with
            // anything to fill (most chunks have none, and walking each
            // column up to its floor was most of the cost).
            let mut dark = dark_columns[z as usize] & ((1_u64 << x_high) - (1_u64 << x_low));
            while dark != 0 {
                let x = dark.trailing_zeros();
                dark &= dark - 1;
                let floor = u32::from(floors[(x + PADDED_CHUNK_SIZE * z) as usize]).min(top);
                for y in bottom..floor {
                    let index = PaddedChunkShape::linearize([x, y, z]) as usize;
                    if slice[index].is_solid() {
                        continue;
                    }
                    slice[index] = Voxel::STONE;
                    self.plugs[index / 64] |= 1 << (index % 64);
                    filled += 1;
                }
            }
        }
        if filled == 0 {
            // Dark air only where these plugs do not reach: as unplugged.
            self.plugs_for = None;
        }
        if self.plug_reach == PlugReach::Interior {
            self.find_stubs(voxels);
        }
        filled
    }

    /// Of a chunk plugged inside ([`PlugReach::Interior`], its plugs
    /// made): its stubs, side by side. A horizontal side's stubs are the
    /// pockets of air in the two layers it shares with the neighbour there
    /// (its own boundary layer and the padding: the same voxels both
    /// chunks hold), connected within those layers, that are dark, lie off
    /// the layers the chunk shares with its other horizontal neighbours,
    /// and border no air of this chunk (its plugs around them): what a
    /// tunnel crossing the side leaves of itself under the margin plugged
    /// inside keeps. Such a pocket is closed by this chunk's rock on one
    /// side; where the neighbour is plugged inside too and its rock closes
    /// the other, the faces around it look into a cavity no eye outside the
    /// rock can reach, and a renderer leaves both chunks' out
    /// ([`ChunkDraw::hidden_stubs`](crate::ChunkDraw::hidden_stubs)). A
    /// dark pocket off the other sides that borders this chunk's air (a
    /// lit shaft beside the side) is seen from here: `stubs_exposed` says
    /// so, and the neighbour then draws its stubs on that side.
    ///
    /// Radially the chunk plugs its padding (with a record of what covers
    /// it; its column's chunks all plug alike), so a pocket may run up or
    /// down into the layers shared with the chunk above or below, where
    /// those chunks (and the neighbour's above or below) see the rest of
    /// it. So that every chunk holding part of one agrees, a pocket of air
    /// that is no stub here (lit somewhere, or reaching another side's
    /// layers) with a dark voxel in the layers shared with the chunk above
    /// or below raises `pockets_beyond` for that direction: a chunk there
    /// may see that voxel's part of it as a stub, and must then draw it
    /// (the streamer leaves no stub out between two columns where one
    /// holds such a chunk and either holds the layer it reaches into).
    /// Without a record the radial shared layers stay open, and stubs keep
    /// off them as off the horizontal sides' ones.
    fn find_stubs(&mut self, voxels: &ChunkVoxels) {
        const SIZE: usize = PADDED_CHUNK_SIZE as usize;
        /// Cells of one side's two shared layers.
        const SLAB: usize = 2 * SIZE * SIZE;
        self.stub_sides.fill(0);
        self.stubs_for = Some(voxels.key());
        let floors = self.sky_floors;
        let slice = voxels.as_slice();
        let at = |p: [usize; 3]| PaddedChunkShape::linearize(p.map(|c| c as u32)) as usize;
        let dark = |p: [usize; 3]| p[1] < usize::from(floors[p[0] + SIZE * p[2]]);
        const SHARED: usize = SHARED_LAYERS as usize;
        let off_other_sides = |c: usize| (SHARED..SIZE - SHARED).contains(&c);
        // The layers shared radially are plugged alike by the chunks of a
        // column only by the source's record of what covers a chunk.
        let recorded = voxels.covered_above((0, 0)).is_some();
        let mut seen = vec![false; SLAB];
        let (mut stack, mut pocket) = (Vec::new(), Vec::new());
        // (Towards its own plug group the padding is plugged: no dark air
        // is left there.)
        let sides = FaceDirection::HORIZONTAL.into_iter().zip(self.padded_sides).filter(|(_, padded)| !padded);
        for (side, _) in sides {
            let axis = side.axis();
            let (u_axis, v_axis) = ((axis + 1) % 3, (axis + 2) % 3);
            // Where a pocket may reach along an axis of the slab: radially
            // anywhere (with a record), across the side off the others.
            let within = |along: usize, c: usize| (recorded && along == 1) || off_other_sides(c);
            // Layer 0 of the slab: the chunk's own boundary layer; 1: the
            // padding. `inner`: the chunk's layer beside the slab.
            let (layers, inner) =
                if side.is_positive() { ([SIZE - 2, SIZE - 1], SIZE - 1 - SHARED) } else { ([1, 0], SHARED) };
            let cell = |(layer, u, v): (usize, usize, usize)| {
                let mut p = [0; 3];
                p[axis] = layers[layer];
                p[u_axis] = u;
                p[v_axis] = v;
                p
            };
            seen.fill(false);
            for start in 0..SLAB {
                let first = (start / (SIZE * SIZE), start / SIZE % SIZE, start % SIZE);
                if seen[start] || slice[at(cell(first))].is_solid() {
                    continue;
                }
                seen[start] = true;
                stack.push(first);
                pocket.clear();
                // Dark voxels in the layers shared with the chunk above and
                // below.
                let (mut enclosed, mut borders_air, mut dark_beyond) = (true, false, [false; 2]);
                while let Some((layer, u, v)) = stack.pop() {
                    let p = cell((layer, u, v));
                    pocket.push(at(p));
                    let is_dark = dark(p);
                    enclosed &= within(u_axis, u) && within(v_axis, v) && is_dark;
                    dark_beyond[0] |= is_dark && p[1] >= SIZE - SHARED;
                    dark_beyond[1] |= is_dark && p[1] < SHARED;
                    if layer == 0 {
                        let mut beside = p;
                        beside[axis] = inner;
                        borders_air |= !slice[at(beside)].is_solid();
                    }
                    let near = [
                        (layer ^ 1, u, v),
                        (layer, u.wrapping_sub(1), v),
                        (layer, u + 1, v),
                        (layer, u, v.wrapping_sub(1)),
                        (layer, u, v + 1),
                    ];
                    for next in near {
                        let (l, nu, nv) = next;
                        if nu >= SIZE || nv >= SIZE {
                            continue;
                        }
                        let n = l * SIZE * SIZE + nu * SIZE + nv;
                        if !seen[n] && !slice[at(cell(next))].is_solid() {
                            seen[n] = true;
                            stack.push(next);
                        }
                    }
                }
                if enclosed && !borders_air {
                    for &index in &pocket {
                        self.stub_sides[index] = side as u8 + 1;
                    }
                } else if enclosed {
                    self.stubs_exposed = true;
                } else if recorded {
                    self.pockets_beyond[0] |= dark_beyond[0];
                    self.pockets_beyond[1] |= dark_beyond[1];
                }
            }
        }
    }

    /// Marks `mesh`, of the chunk this mesher plugged inside last, as
    /// plugged inside, its stubs' faces set apart by side
    /// ([`ChunkMesh::surface_parts`]).
    pub(crate) fn set_aside_stubs(&self, mesh: &mut ChunkMesh) {
        let key = mesh.key;
        mesh.set_aside_stubs(|air| self.stub_side(key, air));
        mesh.plugged_inside = true;
        mesh.stubs_exposed = self.stubs_for == Some(key) && self.stubs_exposed;
        mesh.pockets_beyond = if self.stubs_for == Some(key) { self.pockets_beyond } else { [false; 2] };
    }

    /// The side whose stub ([`ChunkMesher::find_stubs`]) the air voxel at
    /// `padded` of chunk `key` lies in, if any.
    fn stub_side(&self, key: ChunkKey, padded: [i32; 3]) -> Option<FaceDirection> {
        if self.stubs_for != Some(key) || padded.iter().any(|&c| !(0..PADDED_CHUNK_SIZE as i32).contains(&c)) {
            return None;
        }
        let side = self.stub_sides[PaddedChunkShape::linearize(padded.map(|c| c as u32)) as usize];
        side.checked_sub(1).map(|side| FaceDirection::ALL[usize::from(side)])
    }

    /// Whether padded voxel `padded` is a plug of the chunk being meshed.
    fn is_plug(&self, padded: [u32; 3]) -> bool {
        self.is_plug_at(PaddedChunkShape::linearize(padded) as usize)
    }

    /// [`Self::is_plug`] by padded index.
    fn is_plug_at(&self, index: usize) -> bool {
        self.plugs_for.is_some() && self.plugs[index / 64] & (1 << (index % 64)) != 0
    }

    /// The surface mesh of `voxels` (no constraining, no skirts), placed on
    /// the sphere of `layout`.
    ///
    /// # Errors
    /// [`MeshError`] if the chunk key is not on the planet.
    pub fn mesh(&mut self, voxels: &ChunkVoxels, layout: &ChunkLayout) -> Result<ChunkMesh, MeshError> {
        self.mesh_with_dense_sides(voxels, layout, &[])
    }

    /// [`ChunkMesher::mesh`], with every lattice point on the planes of
    /// `dense_sides` (horizontal sides) a vertex, as edge constraining
    /// towards a coarser neighbour needs, and as that neighbour then needs
    /// on its side too. Radial sides in `dense_sides` are ignored: chunks
    /// above and below are always at the same LOD.
    ///
    /// # Errors
    /// [`MeshError`] if the chunk key is not on the planet.
    pub fn mesh_with_dense_sides(
        &mut self,
        voxels: &ChunkVoxels,
        layout: &ChunkLayout,
        dense_sides: &[FaceDirection],
    ) -> Result<ChunkMesh, MeshError> {
        self.mesh_stitched(voxels, layout, dense_sides, &[])
    }

    /// [`ChunkMesher::mesh_with_dense_sides`], with the seams of `stitched`
    /// sides closed in their boundary planes (`crate::stitch`; the padding
    /// of those sides already prepared for it).
    pub(crate) fn mesh_stitched(
        &mut self,
        voxels: &ChunkVoxels,
        layout: &ChunkLayout,
        dense_sides: &[FaceDirection],
        stitched: &[StitchedSide],
    ) -> Result<ChunkMesh, MeshError> {
        self.dense_sides = FaceDirection::HORIZONTAL.map(|side| dense_sides.contains(&side));
        self.stitch_coarser =
            FaceDirection::HORIZONTAL.map(|side| stitched.iter().find(|s| s.side == side).and_then(|s| s.coarser_by));
        // Faces lying in a radial plane are stripped along z (their `u`).
        debug_assert!(
            RIGHT_HANDED_Y_UP_CONFIG.faces.iter().map(FaceAxes::of).filter(|axes| axes.n == 1).all(|axes| axes.u == 2)
        );
        let key = voxels.key();
        let open = |side: FaceDirection| {
            let index = crate::render::side_index(side);
            let on_cube_edge = side.face_edge().is_some_and(|edge| layout.neighbor(key, edge).face != key.face);
            !on_cube_edge && !self.dense_sides[index] && self.stitch_coarser[index].is_none()
        };
        self.flat_edges = FlatEdges { open: [open(FaceDirection::NegX), open(FaceDirection::PosX)] };
        let origin = layout.chunk_origin(key)?;
        let mut mesh = ChunkMesh::empty(key, *layout, origin);
        self.mesh_into(voxels, layout, &mut mesh)?;
        Ok(mesh)
    }

    /// How many quads the last [`ChunkMesher::mesh`] call triangulated:
    /// greedy quads (clipped off the boundary rows where their corners
    /// there are not canonical) and boundary strips.
    #[must_use]
    pub fn quad_count(&self) -> usize {
        self.greedy.quads.num_quads()
    }

    /// Starts a chunk under a new stamp (every stamped entry goes stale).
    fn next_stamp(&mut self) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // Wrapped: forget every old stamp.
            self.vertex_slot.fill((0, 0));
            self.column_direction.fill((0, DVec3::ZERO));
            self.column_warps = ColumnWarps::default();
            self.wall_normal.fill((0, DVec3::ZERO));
            self.stamp = 1;
        }
    }

    fn mesh_into(&mut self, voxels: &ChunkVoxels, layout: &ChunkLayout, mesh: &mut ChunkMesh) -> Result<(), MeshError> {
        let faces = &RIGHT_HANDED_Y_UP_CONFIG.faces;
        self.next_stamp();
        self.column_warps.start(voxels.key(), layout)?;
        self.start_layers(voxels.key(), layout);
        self.greedy.mesh(voxels);
        let mut groups = std::mem::take(&mut self.greedy.quads.groups);
        if self.plugs_for != Some(voxels.key()) {
            self.plugs_for = None;
            self.sky_floors = voxels.sky_floors_from(&self.greedy.rows);
        }
        // Open ground (most chunks): every air voxel sees the sky, so every
        // vertex is lit and no quad is split for light.
        self.all_lit = self.plugs_for.is_none()
            && voxels.dark_air_columns_from(&self.greedy.rows).iter().all(|&columns| columns == 0);
        let canonical = self.boundary_vertices == BoundaryVertices::Canonical;
        let flat_edges = self.flat_edges;
        for (group, face) in groups.iter_mut().zip(faces) {
            let axes = FaceAxes::of(face);
            let covered = &mut self.covered;
            let mut covers_any = false;
            // The layers (along the normal) holding a quad that touches a
            // boundary plane and is not kept whole: the only ones whose
            // faces strips may cover. (Every face touching a boundary
            // plane is of a quad that does; where each such quad of a
            // layer is kept, they cover all of them: on mountain ground
            // most layers, and their scan was a tenth of the meshing.)
            let mut boundary_layers = 0u64;
            group.retain_mut(|quad| {
                if !axes.touches_boundary(quad) {
                    return true;
                }
                if canonical && axes.keeps_canonical_corners(quad, voxels, flat_edges) {
                    axes.for_each_face(quad, |padded| {
                        let index = PaddedChunkShape::linearize(padded) as usize;
                        covered[index / 64] |= 1 << (index % 64);
                    });
                    covers_any = true;
                    return true;
                }
                boundary_layers |= 1 << (quad.minimum[axes.n] - 1);
                axes.clip_to_interior(quad)
            });
            let is_covered = |index: usize| covered[index / 64] & (1 << (index % 64)) != 0;
            axes.push_boundary_strips(voxels.as_slice(), &is_covered, boundary_layers, group);
            if covers_any {
                self.covered.fill(0);
            }
            if !self.all_lit {
                let is_plug = |padded| self.is_plug(padded);
                let plugs = self.plugs_for.is_some().then_some(&is_plug as &dyn Fn([u32; 3]) -> bool);
                split_by_sky(&axes, group, voxels, &self.sky_floors, plugs);
            }
        }
        self.push_mirror_faces(voxels, &mut groups);
        self.corners.fill(0);
        for (group, face) in groups.iter().zip(faces) {
            for quad in group {
                for corner in local_corners(face, quad) {
                    let index = point_index(corner);
                    self.corners[index / 64] |= 1 << (index % 64);
                }
            }
        }
        let quads: usize = groups.iter().map(Vec::len).sum();
        // A quad has 4 corners and 2 triangles before T-junction repair;
        // after it an Earth chunk's quads have about 4 vertices and 2.9
        // triangles each: room for a little more, so that the lists are
        // not copied to grow at the end (2 % of a mountain chunk).
        mesh.vertices.reserve(5 * quads);
        mesh.world.reserve(5 * quads);
        mesh.morph_world.reserve(5 * quads);
        mesh.sources.reserve(5 * quads);
        mesh.indices.reserve(10 * quads);
        for (group, face) in groups.iter().zip(faces) {
            let normal = face.signed_normal().to_array();
            let first = mesh.indices.len();
            for quad in group {
                let corners = local_corners(face, quad);
                let material = voxels.get(quad.minimum).map_or(0, |v| v.material());
                self.triangulate(corners, normal, material, voxels, layout, mesh);
            }
            mesh.surface_side_ranges[side_of(normal) as usize] = first..mesh.indices.len();
        }
        self.greedy.quads.groups = groups;
        let result = self.zip_coarse_edges(voxels, layout, mesh);
        if self.collapse_flat_interiors {
            let moving = [0, 1, 2, 3].map(|k| self.dense_sides[k] || self.stitch_coarser[k].is_some());
            // The four cells around the point in its plane: solid of one
            // material behind the face, not solid in front. A rough chunk
            // asks this of most of its vertices, and most fail on the
            // faces alone (`faces_around`, from the solid rows: the voxel
            // reads of the cells were a tenth of meshing a mountain chunk);
            // the materials are read from the padded array after.
            let slice = voxels.as_slice();
            let stride = [1i32, PADDED_CHUNK_SIZE as i32, (PADDED_CHUNK_SIZE * PADDED_CHUNK_SIZE) as i32];
            let rows = &*self.greedy.rows;
            let flat_around = |local: [i32; 3], side: FaceDirection| {
                if !faces_around(rows, local, side) {
                    return false;
                }
                let axis = side.axis();
                let (p, q) = ((axis + 1) % 3, (axis + 2) % 3);
                // The cell at the point's padded coordinates is the one on
                // the far side of it along every axis.
                let at = (local[0] + 1) * stride[0] + (local[1] + 1) * stride[1] + (local[2] + 1) * stride[2];
                debug_assert_eq!(at as u32, PaddedChunkShape::linearize(local.map(|c| (c + 1) as u32)));
                let behind = at - stride[p] - stride[q] - if side.is_positive() { stride[axis] } else { 0 };
                let first = slice[behind as usize].material();
                [stride[p], stride[q], stride[p] + stride[q]]
                    .iter()
                    .all(|&across| slice[(behind + across) as usize].material() == first)
            };
            self.flat_interiors.collapse(mesh, moving, flat_around);
        }
        mesh.surface_index_count = mesh.indices.len();
        self.plugs_for = None;
        result
    }

    /// On each side stitched to a coarser neighbour, a face in the boundary
    /// plane looking into the chunk for every padding cell (the coarse
    /// neighbour's voxel) that is solid across from the chunk's air: the
    /// neighbour's side of the seam, at this chunk's resolution.
    fn push_mirror_faces(&self, voxels: &ChunkVoxels, groups: &mut [Vec<UnorientedQuad>]) {
        if !self.stitch_parts.mirror_faces {
            return;
        }
        let faces = &RIGHT_HANDED_Y_UP_CONFIG.faces;
        for (side, _) in FaceDirection::HORIZONTAL.into_iter().zip(self.stitch_coarser).filter(|(_, d)| d.is_some()) {
            let mut inward = [0i32; 3];
            inward[side.axis()] = if side.is_positive() { -1 } else { 1 };
            let Some(group) = faces.iter().position(|face| face.signed_normal().to_array() == inward) else {
                continue;
            };
            for (height, along) in plane_cells() {
                let pad = padded(side, true, height, along);
                if solid(voxels, pad) && !solid(voxels, padded(side, false, height, along)) {
                    groups[group].push(UnorientedQuad { minimum: pad, width: 1, height: 1 });
                }
            }
        }
    }

    /// On each side stitched to a coarser neighbour, zips every coarse edge
    /// of the neighbour lying in the boundary plane (on its lattice lines,
    /// where its voxels on the two sides differ) to the vertices of this
    /// chunk strictly inside it: a fan of zero-area triangles from the
    /// edge's first end, in both windings (which way rounding opens the
    /// sliver is not known), spliced into the range of the faces looking up:
    /// a renderer leaves out the faces looking towards a side the eye is
    /// behind (`ChunkDraw::hidden_sides`), and a zip's winding on screen is
    /// rounding's, not its plane's (in the range of its plane's faces, one
    /// winding was left out and the other seen from behind: a pinhole).
    /// On the chunk's own corner lines the neighbour's
    /// voxels beyond are not at hand, so those edges are zipped wherever a
    /// vertex lies inside them.
    fn zip_coarse_edges(
        &mut self,
        voxels: &ChunkVoxels,
        layout: &ChunkLayout,
        mesh: &mut ChunkMesh,
    ) -> Result<(), MeshError> {
        if self.stitch_coarser.iter().all(Option::is_none) || !self.stitch_parts.zips {
            return Ok(());
        }
        let key = mesh.key;
        let mut extra: [Vec<u32>; 6] = Default::default();
        let mut chain: Vec<[i32; 3]> = Vec::new();
        for (side, lod_diff) in FaceDirection::HORIZONTAL.into_iter().zip(self.stitch_coarser) {
            let Some(lod_diff) = lod_diff else { continue };
            let step = 1i64 << lod_diff;
            let along_axis = if side.axis() == 0 { 2 } else { 0 };
            let along_offset = i64::from(if along_axis == 0 { key.x } else { key.y }) * i64::from(CHUNK_SIZE);
            let height_offset = i64::from(key.layer) * i64::from(CHUNK_SIZE);
            let plane = if side.is_positive() { LAST } else { 0 };
            let local = |along: i64, height: i64| {
                let mut point = [0i32; 3];
                point[side.axis()] = plane;
                point[along_axis] = along as i32;
                point[1] = height as i32;
                point
            };
            // Solidity of the coarse neighbour's voxel holding fine cell
            // (along, height) of the plane (local, each in -1..=32).
            let coarse_solid = |along: i64, height: i64| {
                solid(voxels, padded(side, true, (height + 1) as u32, (along.clamp(0, 31) + 1) as u32))
            };
            let first_line = |offset: i64| (step - offset.rem_euclid(step)) % step;
            // Coarse lines along the plane (constant height), then across it
            // (constant along): (fixed coordinate, is_horizontal).
            let horizontal = (first_line(height_offset)..=i64::from(LAST)).step_by(step as usize).map(|h| (h, true));
            let vertical = (first_line(along_offset)..=i64::from(LAST)).step_by(step as usize).map(|a| (a, false));
            for (fixed, is_horizontal) in horizontal.chain(vertical).collect::<Vec<_>>() {
                let offset = if is_horizontal { along_offset } else { height_offset };
                // Coarse segments [start, start + step] meeting the chunk's span.
                let mut start = -((offset).rem_euclid(step));
                while start < i64::from(LAST) {
                    let end = start + step;
                    let point = |t: i64| if is_horizontal { local(t, fixed) } else { local(fixed, t) };
                    let is_edge = if is_horizontal {
                        let at = start.max(0);
                        coarse_solid(at, fixed - 1) != coarse_solid(at, fixed)
                    } else if fixed == 0 || fixed == i64::from(LAST) {
                        true
                    } else {
                        let at = start.max(0);
                        coarse_solid(fixed - 1, at) != coarse_solid(fixed, at)
                    };
                    chain.clear();
                    if is_edge {
                        for t in (start + 1).max(0)..end.min(i64::from(LAST) + 1) {
                            let p = point(t);
                            let index = point_index(p);
                            if (0..6).any(|s| self.vertex_slot[vertex_slot(index, s)].0 == self.stamp) {
                                chain.push(p);
                            }
                        }
                    }
                    if !chain.is_empty() {
                        let material = (start.max(0)..end.min(i64::from(LAST)))
                            .find_map(|t| {
                                let (a, h) = if is_horizontal { (t, fixed) } else { (fixed, t) };
                                [(a, h), (a, h - 1)].into_iter().find_map(|(a, h)| {
                                    voxels
                                        .get(padded(
                                            side,
                                            true,
                                            (h + 1).clamp(0, 33) as u32,
                                            (a.clamp(0, 31) + 1) as u32,
                                        ))
                                        .filter(|v| v.is_solid())
                                })
                            })
                            .map_or(0, |v| v.material());
                        for (facing, forward) in [(side, true), (side.opposite(), false)] {
                            let first = self.any_vertex(point(start), facing, material, voxels, layout, mesh)?;
                            let mut previous = self.any_vertex(chain[0], facing, material, voxels, layout, mesh)?;
                            let next_points: Vec<[i32; 3]> = chain[1..].iter().copied().chain([point(end)]).collect();
                            for next in next_points {
                                let next = self.any_vertex(next, facing, material, voxels, layout, mesh)?;
                                // Both windings where no side culling drops
                                // them: the radial faces' range.
                                extra[FaceDirection::PosY as usize].extend(if forward {
                                    [first, previous, next]
                                } else {
                                    [first, next, previous]
                                });
                                previous = next;
                            }
                        }
                    }
                    start = end;
                }
            }
        }
        // Splice the zips into their faces' ranges (ranges stay in order).
        let old = std::mem::take(&mut mesh.indices);
        let order = RIGHT_HANDED_Y_UP_CONFIG.faces.map(|face| side_of(face.signed_normal().to_array()));
        for side in order {
            let range = mesh.surface_side_ranges[side as usize].clone();
            let start = mesh.indices.len();
            mesh.indices.extend_from_slice(&old[range]);
            mesh.indices.extend_from_slice(&extra[side as usize]);
            mesh.surface_side_ranges[side as usize] = start..mesh.indices.len();
        }
        Ok(())
    }

    /// The vertex at lattice point `local` looking towards `side`, which
    /// may lie outside the chunk (the far end of a coarse edge longer than
    /// the chunk): made there from the same canonical position.
    fn any_vertex(
        &mut self,
        local: [i32; 3],
        side: FaceDirection,
        material: u8,
        voxels: &ChunkVoxels,
        layout: &ChunkLayout,
        mesh: &mut ChunkMesh,
    ) -> Result<u32, MeshError> {
        if local.iter().all(|&c| (0..=LAST).contains(&c)) {
            let kind = VertexKind { side, material, on_face: false };
            return Ok(self.vertex(local, kind, voxels, layout, mesh));
        }
        let key = mesh.key;
        let sphere = layout.sphere();
        let point = layout.column_point(key, i64::from(local[0]), i64::from(local[2]))?;
        let span = layout.voxel_span(key.lod);
        let layer = (i64::from(key.layer) * i64::from(CHUNK_SIZE) + i64::from(local[1])) * span;
        let world = sphere.position_on_column(sphere.column_direction(point), layer as i32);
        let normal = self.normal(key, layout, local, side, world);
        Ok(mesh.push_vertex(world, world, normal, (material, 0), 0, VertexSource::Surface { local, side }))
    }

    /// Triangulates one greedy quad with every lattice vertex on its edges.
    fn triangulate(
        &mut self,
        corners: [[i32; 3]; 4],
        normal: [i32; 3],
        material: u8,
        voxels: &ChunkVoxels,
        layout: &ChunkLayout,
        mesh: &mut ChunkMesh,
    ) {
        let side = side_of(normal);
        // block-mesh order: 0 = (min u, min v), 1 = (max u, min v),
        // 2 = (min u, max v), 3 = (max u, max v).
        let [bl, br, tl, tr] = corners;
        let (mut chain_a, mut chain_b) = (std::mem::take(&mut self.chain_a), std::mem::take(&mut self.chain_b));
        chain_a.clear();
        chain_b.clear();
        // A: tl → bl → br; B: tl → tr → br.
        self.walk_edge(tl, bl, voxels, &mut chain_a);
        self.walk_edge(bl, br, voxels, &mut chain_a);
        chain_a.push(br);
        self.walk_edge(tl, tr, voxels, &mut chain_b);
        self.walk_edge(tr, br, voxels, &mut chain_b);
        chain_b.push(br);

        // Resolve every chain point to its vertex once.
        let (mut index_a, mut index_b) = (std::mem::take(&mut self.index_a), std::mem::take(&mut self.index_b));
        index_a.clear();
        index_b.clear();
        let kind = VertexKind { side, material, on_face: true };
        for &point in &chain_a {
            index_a.push(self.vertex(point, kind, voxels, layout, mesh));
        }
        // Chain B shares its ends, tl and br, with chain A.
        index_b.push(index_a[0]);
        for &point in &chain_b[1..chain_b.len() - 1] {
            index_b.push(self.vertex(point, kind, voxels, layout, mesh));
        }
        index_b.extend(index_a.last().copied());
        // Lattice space (x = u, y = radial, z = v) is left-handed in the
        // world, so a triangle facing `normal` counter-clockwise in the
        // world is clockwise here. A step along chain A, (a, a', b), and
        // a step along chain B, (a, b, b'), turn opposite ways, so one
        // test per quad orients them all.
        let (ab, ac) = (sub(chain_a[1], chain_a[0]), sub(chain_b[1], chain_a[0]));
        let cross = [ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0]];
        let step_a_keeps_order = cross[0] * normal[0] + cross[1] * normal[1] + cross[2] * normal[2] < 0;
        let indices = &mut mesh.indices;
        let mut step_a = |a0: u32, a1: u32, b: u32| {
            indices.extend(if step_a_keeps_order { [a0, a1, b] } else { [a0, b, a1] });
        };
        // The first triangle (tl, a1, b1) is a step along A from tl.
        step_a(index_a[0], index_a[1], index_b[1]);
        let (len_a, len_b) = (chain_a.len(), chain_b.len());
        // Both chains run from tl to br, so the lattice distance from tl
        // is arc length: advance the chain that lags.
        let progress = |chain: &[[i32; 3]], k: usize| quad_len(chain[0], chain[k]);
        let (mut i, mut j) = (1, 1);
        while i < len_a - 2 || j < len_b - 2 {
            if j == len_b - 2 || (i < len_a - 2 && progress(&chain_a, i + 1) <= progress(&chain_b, j + 1)) {
                i += 1;
                step_a(index_a[i - 1], index_a[i], index_b[j]);
            } else {
                j += 1;
                // (a, b, b') turns the other way: reversed order.
                step_a(index_b[j], index_b[j - 1], index_a[i]);
            }
        }
        // Last triangle (a, br, b) closes with a step along A onto br.
        step_a(index_a[len_a - 2], index_a[len_a - 1], index_b[len_b - 2]);
        self.chain_a = chain_a;
        self.chain_b = chain_b;
        self.index_a = index_a;
        self.index_b = index_b;
    }

    /// Pushes `from` and every vertex strictly between `from` and `to` (not
    /// `to` itself) onto `chain`.
    fn walk_edge(&self, from: [i32; 3], to: [i32; 3], voxels: &ChunkVoxels, chain: &mut Vec<[i32; 3]>) {
        chain.push(from);
        let axis = (0..3).find(|&k| from[k] != to[k]).unwrap_or(0);
        if (to[axis] - from[axis]).abs() < 2 {
            // No point strictly inside (half of a mountain chunk's edges).
            return;
        }
        let step = (to[axis] - from[axis]).signum();
        let planes = || (0..3).filter(|&k| k != axis && (from[k] == 0 || from[k] == LAST));
        let dense = planes().any(|k| {
            let side =
                FaceDirection::HORIZONTAL.iter().position(|s| s.axis() == k && s.is_positive() == (from[k] == LAST));
            side.is_some_and(|i| self.dense_sides[i])
        });
        let canonical = planes().next().is_some() && self.boundary_vertices == BoundaryVertices::Canonical;
        // The points along the edge, and their indices, by arithmetic:
        // stepping a coordinate picked at run time through the array
        // (`point[axis] += step`) left each point in memory, read back
        // whole before its store had landed (a stall a point: a tenth of
        // meshing a surface chunk went to walking edges).
        let unit = unit_along(axis);
        let point_at =
            |t: i32| [from[0] + t * step * unit[0], from[1] + t * step * unit[1], from[2] + t * step * unit[2]];
        let index_step = (point_index(unit_along(axis)) as isize) * step as isize;
        let mut index = point_index(from);
        for t in 1..(to[axis] - from[axis]).abs() {
            index = index.wrapping_add_signed(index_step);
            debug_assert_eq!(index, point_index(point_at(t)));
            let corner = self.corners[index / 64] & (1 << (index % 64)) != 0;
            // Every corner on a boundary plane is canonical (strips end
            // only there), so the canonical set includes them.
            debug_assert!(
                !canonical || !corner || is_boundary_vertex(voxels, point_at(t), self.flat_edges),
                "corner {:?} off the canonical set",
                point_at(t)
            );
            let vertex = if dense {
                true
            } else if canonical {
                is_boundary_vertex(voxels, point_at(t), self.flat_edges)
            } else {
                corner
            };
            if vertex {
                chain.push(point_at(t));
            }
        }
    }

    /// The vertex for lattice point `local` on a face of `kind`, made on
    /// first use.
    fn vertex(
        &mut self,
        local: [i32; 3],
        kind: VertexKind,
        voxels: &ChunkVoxels,
        layout: &ChunkLayout,
        mesh: &mut ChunkMesh,
    ) -> u32 {
        let VertexKind { side, material, on_face } = kind;
        let slot = vertex_slot(point_index(local), side as usize);
        if self.vertex_slot[slot].0 == self.stamp {
            return self.vertex_slot[slot].1;
        }
        let key = mesh.key;
        let world = self.world_position(key, layout, local);
        // Rounded down to even (local coordinates are not negative).
        let even = [local[0] & !1, local[1] & !1, local[2] & !1];
        let morph = self.world_position(key, layout, even);
        let normal = self.normal(key, layout, local, side, world);
        // A face's cell in front is air, and in a chunk without dark air
        // or plugs every air cell is open to the sky: lit, without reading
        // the cells (a zip's point may have none of them air).
        let sky_light = if on_face && self.all_lit {
            debug_assert_eq!(self.sky_light(voxels, local, side), 255);
            255
        } else {
            self.sky_light(voxels, local, side)
        };
        let index =
            mesh.push_vertex(world, morph, normal, (material, sky_light), 0, VertexSource::Surface { local, side });
        self.vertex_slot[slot] = (self.stamp, index);
        index
    }

    /// How much sky lights lattice point `local` on a face looking towards
    /// `side`: 255 where, in one of the (up to four) voxel cells around the
    /// point, the air in front of the face is open to the sky
    /// ([`ChunkVoxels::sky_floors`]) and the voxel behind it is not a plug
    /// ([`ChunkMesher::plug_dark_air`]: the dark cave it stands for), else
    /// 0. Between a quad's corners the light is interpolated, so it fades
    /// from a cave mouth or an overhang's edge (where the quads are split,
    /// `split_by_sky`) into the dark, and open ground is never darkened. A
    /// function of the point, the side and the voxels around it (padding
    /// included) alone, so the chunks sharing a vertex give it the same
    /// light (both plug the voxels they share alike, `plug_dark_air`).
    fn sky_light(&self, voxels: &ChunkVoxels, local: [i32; 3], side: FaceDirection) -> u8 {
        let axis = side.axis();
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        // Padded index of the voxel layer in front of the face: voxel
        // `local[axis]` (padded `+ 1`) in front of a face looking up the
        // axis, the one before it otherwise; the layer behind it next to it.
        let front = if side.is_positive() { local[axis] + 1 } else { local[axis] };
        // The four cells in front, by padded index (a lattice point's
        // cells lie in the padded chunk: coordinates 0..=33), and the
        // step to the one behind each.
        let stride =
            |axis: usize| [1, PADDED_CHUNK_SIZE as usize, (PADDED_CHUNK_SIZE * PADDED_CHUNK_SIZE) as usize][axis];
        // Built by arithmetic, not by stores to picked coordinates (see
        // `walk_edge`).
        let pick = |k: usize| if k == axis { front } else { local[k] } as usize;
        let corner = [pick(0), pick(1), pick(2)];
        let first = corner[0] + stride(1) * corner[1] + stride(2) * corner[2];
        let slice = voxels.as_slice();
        let (unit_u, unit_v) = (unit_along(u), unit_along(v));
        let lit = [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().any(|(du, dv)| {
            let index = first + du * stride(u) + dv * stride(v);
            let at = |k: usize| corner[k] + du * unit_u[k] as usize + dv * unit_v[k] as usize;
            let at = [at(0), at(1), at(2)];
            let floor = usize::from(self.sky_floors[at[0] + PADDED_CHUNK_SIZE as usize * at[2]]);
            let back = if side.is_positive() { index - stride(axis) } else { index + stride(axis) };
            !slice[index].is_solid() && at[1] >= floor && !self.is_plug_at(back)
        });
        debug_assert_eq!(lit, self.sky_light_as_read(voxels, local, side));
        if lit { 255 } else { 0 }
    }

    /// [`Self::sky_light`]'s test read voxel by voxel (what it was): its
    /// debug twin.
    fn sky_light_as_read(&self, voxels: &ChunkVoxels, local: [i32; 3], side: FaceDirection) -> bool {
        let axis = side.axis();
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let front = if side.is_positive() { local[axis] + 1 } else { local[axis] };
        let back = if side.is_positive() { front - 1 } else { front + 1 };
        [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().any(|(du, dv)| {
            let at = |layer: i32| {
                let mut padded = [0i32; 3];
                padded[axis] = layer;
                padded[u] = local[u] + du;
                padded[v] = local[v] + dv;
                padded.map(|c| c as u32)
            };
            open_to_sky(voxels, &self.sky_floors, at(front)) && !self.is_plug(at(back))
        })
    }

    /// Makes the radius of each of chunk `key`'s lattice layers.
    fn start_layers(&mut self, key: ChunkKey, layout: &ChunkLayout) {
        let sphere = layout.sphere();
        // The point's radial layer, exactly as `ChunkLayout::lattice_point`
        // counts it (the chunk key is valid, so it fits).
        let span = layout.voxel_span(key.lod);
        let first = i64::from(key.layer) * i64::from(CHUNK_SIZE);
        for (local, radius) in self.layer_radius.iter_mut().enumerate() {
            let layer = (first + local as i64) * span;
            *radius = sphere.layer_radius(f64::from(layer as i32));
        }
    }

    /// The unit direction of local lattice column `column` (`x · 33 + z`),
    /// made once per chunk.
    #[inline(always)]
    fn column_direction(&mut self, layout: &ChunkLayout, column: usize) -> DVec3 {
        if self.column_direction[column].0 != self.stamp {
            let (x, z) = ((column / POINTS) as i32, (column % POINTS) as i32);
            let direction = self.column_warps.direction(layout.sphere(), self.stamp, x, z);
            self.column_direction[column] = (self.stamp, direction);
        }
        self.column_direction[column].1
    }

    /// The canonical world position of local lattice point `local`: the
    /// column's direction is made once per chunk, the layer's radius
    /// too. (The position is a multiplication from there: a table of
    /// positions by lattice point, 1.2 MB, saved nothing measurable.)
    // Always inlined, as `column_direction` and `normal`: out of line
    // the calls and their spills were 8 % of meshing a surface chunk.
    #[inline(always)]
    fn world_position(&mut self, key: ChunkKey, layout: &ChunkLayout, local: [i32; 3]) -> DVec3 {
        let direction = self.column_direction(layout, local[0] as usize * POINTS + local[2] as usize);
        debug_assert_eq!(
            Ok(direction),
            layout
                .column_point(key, i64::from(local[0]), i64::from(local[2]))
                .map(|p| layout.sphere().column_direction(p))
        );
        let world = direction * self.layer_radius[local[1] as usize];
        debug_assert_eq!(world, {
            let span = layout.voxel_span(key.lod);
            let layer = (i64::from(key.layer) * i64::from(CHUNK_SIZE) + i64::from(local[1])) * span;
            layout.sphere().position_on_column(direction, layer as i32)
        });
        world
    }

    /// The exact normal of a voxel face looking towards `side` at `local`:
    /// radial for top and bottom faces, the normal of the lattice plane
    /// through the planet centre for side walls (see
    /// `Cubesphere::lattice_plane_normal`). A function of the lattice point
    /// alone, so neighbouring chunks agree.
    #[inline(always)]
    fn normal(
        &mut self,
        key: ChunkKey,
        layout: &ChunkLayout,
        local: [i32; 3],
        side: FaceDirection,
        world: DVec3,
    ) -> Vec3 {
        let sign = if side.is_positive() { 1.0 } else { -1.0 };
        let axis = side.axis();
        if axis == 1 {
            // Radial: the column's direction (set by `world_position`).
            let column = local[0] as usize * POINTS + local[2] as usize;
            debug_assert!((self.column_direction[column].1 - world.normalize()).length() < 1e-9);
            return (self.column_direction[column].1 * sign).as_vec3();
        }
        let slot = if axis == 0 { local[0] as usize } else { POINTS + local[2] as usize };
        if self.wall_normal[slot].0 != self.stamp {
            // The plane's coordinate is its columns' (local x is u, local z
            // is v), whose warp the chunk keeps.
            let sphere = layout.sphere();
            let along_u = axis == 0;
            let warp = self.column_warps.warp(sphere, self.stamp, usize::from(!along_u), local[axis]);
            let normal = sphere.warped_plane_normal(key.face, along_u, warp);
            debug_assert_eq!(normal, {
                let span = layout.voxel_span(key.lod);
                let first = if along_u { key.x } else { key.y };
                let coord = i64::from(first) * i64::from(CHUNK_SIZE) * span + i64::from(local[axis]) * span;
                sphere.lattice_plane_normal(key.face, along_u, coord)
            });
            self.wall_normal[slot] = (self.stamp, normal);
        }
        (self.wall_normal[slot].1 * sign).as_vec3()
    }
}

/// A chunk's lattice columns on the cube: which cube axis the face normal
/// and the chunk's x (u) and z (v) run along, and the warps
/// ([`Cubesphere::cube_warp`], a `tan` each on the equi-angular map) of
/// its columns' coordinates, each made once per chunk: a column shares its
/// x coordinate's warp with the 32 others of its row, and the normal's with
/// every column. Looking each column up through the chunk layout, and the
/// warps through a hashed memo, was a fifth of meshing a surface chunk.
#[derive(Clone, Copy, Debug)]
struct ColumnWarps {
    /// Cube axes of the face normal, of local x and of local z.
    axes: [usize; 3],
    /// Cube coordinates of the chunk's first column (local x = z = 0).
    first: [i32; 3],
    /// Lattice steps per local step.
    span: i32,
    /// The warp of the normal's coordinate, the same for every column.
    normal: f64,
    /// Per local x, then per local z: `(stamp, warp)`.
    along: [[(u32, f64); POINTS]; 2],
}

impl Default for ColumnWarps {
    fn default() -> Self {
        Self { axes: [0, 1, 2], first: [0; 3], span: 1, normal: 0.0, along: [[(0, 0.0); POINTS]; 2] }
    }
}

impl ColumnWarps {
    /// Sets up for chunk `key` (the warps along x and z are made as the
    /// stamp's columns ask for them).
    fn start(&mut self, key: ChunkKey, layout: &ChunkLayout) -> Result<(), MeshError> {
        // Layer 0 names the column even when the chunk's bottom lies below
        // the planet centre (the coarsest chunks of a planet do).
        let first = layout.column_point(key, 0, 0)?.cube.to_array();
        let axis_of = |unit: nebula_math::I64Vec3| (0..3).find(|&k| unit[k] != 0).unwrap_or(0);
        self.axes = [key.face.axis(), axis_of(key.face.u_axis()), axis_of(key.face.v_axis())];
        self.first = first;
        // A chunk's 33 columns an axis are on the face: the step fits.
        self.span = layout.voxel_span(key.lod) as i32;
        self.normal = layout.sphere().cube_warp(first[self.axes[0]]);
        Ok(())
    }

    /// [`Cubesphere::column_direction`] of local column `(x, z)`, bit for
    /// bit (the same warps, through [`Cubesphere::column_direction_with`]).
    fn direction(&mut self, sphere: &Cubesphere, stamp: u32, x: i32, z: i32) -> DVec3 {
        let [normal_axis, x_axis, z_axis] = self.axes;
        // Picked by comparison, not stored at a picked index (see
        // `walk_edge`).
        let step = |k: usize| {
            if k == x_axis {
                x * self.span
            } else if k == z_axis {
                z * self.span
            } else {
                0
            }
        };
        let cube = nebula_math::IVec3::new(self.first[0] + step(0), self.first[1] + step(1), self.first[2] + step(2));
        let point = LatticePoint { cube, layer: 0 };
        let (x_warp, z_warp) = (self.warp(sphere, stamp, 0, x), self.warp(sphere, stamp, 1, z));
        let normal = self.normal;
        sphere.column_direction_with(point, |axis, _| {
            if axis == normal_axis {
                normal
            } else if axis == x_axis {
                x_warp
            } else {
                z_warp
            }
        })
    }

    /// The warp of the cube coordinate of the chunk's lattice line at
    /// `local` along its x (`along` 0) or z (`along` 1), made on first
    /// use under `stamp`.
    fn warp(&mut self, sphere: &Cubesphere, stamp: u32, along: usize, local: i32) -> f64 {
        let slot = &mut self.along[along][local as usize];
        if slot.0 != stamp {
            let c = self.first[self.axes[1 + along]] + local * self.span;
            *slot = (stamp, sphere.cube_warp(c));
        }
        slot.1
    }
}

/// Whether the voxel at `padded` is air open to the sky (`sky_floors`:
/// [`ChunkVoxels::sky_floors`]).
fn open_to_sky(voxels: &ChunkVoxels, sky_floors: &[u8; PADDED_COLUMNS], padded: [u32; 3]) -> bool {
    voxels.get(padded).is_some_and(|voxel| !voxel.is_solid())
        && padded[1] >= u32::from(sky_floors[(padded[0] + PADDED_CHUNK_SIZE * padded[2]) as usize])
}

/// Splits each interior greedy quad of `group` whose faces are not all
/// open to the sky (and no plug's), or all covered, into runs along `u`
/// that are: so that
/// the light interpolated across a quad ([`ChunkMesher`]'s `sky_light`)
/// fades only over covered ground, from its edge. Quads touching a
/// boundary plane stay as they are (their vertices there must be the
/// canonical set, which knows nothing of light). Open ground and caves
/// away from their mouths are one kind throughout and not split.
/// `is_plug` is `None` where the chunk has no plugs.
fn split_by_sky(
    axes: &FaceAxes,
    group: &mut Vec<UnorientedQuad>,
    voxels: &ChunkVoxels,
    floors: &[u8; PADDED_COLUMNS],
    is_plug: Option<&dyn Fn([u32; 3]) -> bool>,
) {
    let front = |padded: [u32; 3]| {
        let mut front = padded;
        front[axes.n] = if axes.positive { front[axes.n] + 1 } else { front[axes.n] - 1 };
        match is_plug {
            Some(is_plug) => open_to_sky(voxels, floors, front) && !is_plug(padded),
            // A greedy quad's faces have air in front (solid is opaque,
            // the rest empty), so open to the sky is over the floor, and
            // without plugs that is all: a read of the floors alone (the
            // voxel read and the call were most of meshing's per-face
            // work).
            None => {
                debug_assert!(voxels.get(front).is_some_and(|voxel| !voxel.is_solid()));
                front[1] >= u32::from(floors[(front[0] + PADDED_CHUNK_SIZE * front[2]) as usize])
            }
        }
    };
    // Whether every face of `quad` is lit alike, face by face.
    let uniform_by_faces = |quad: &UnorientedQuad| {
        let first = front(quad.minimum);
        let mut uniform = true;
        axes.for_each_face(quad, |padded| uniform &= front(padded) == first);
        uniform
    };
    let mut runs = Vec::new();
    group.retain(|quad| {
        if axes.touches_boundary(quad) {
            return true;
        }
        let uniform = if is_plug.is_some() {
            uniform_by_faces(quad)
        } else {
            // The cells in front of the faces are a box: every face is
            // open where its height is over every floor of the box's
            // columns, and none where under every one.
            let mut low = quad.minimum;
            low[axes.n] = if axes.positive { low[axes.n] + 1 } else { low[axes.n] - 1 };
            let mut high = low;
            high[axes.u] += quad.width - 1;
            high[axes.v] += quad.height - 1;
            let (mut least, mut most) = (u8::MAX, u8::MIN);
            for z in low[2]..=high[2] {
                let row = (PADDED_CHUNK_SIZE * z) as usize;
                for &floor in &floors[row + low[0] as usize..=row + high[0] as usize] {
                    least = least.min(floor);
                    most = most.max(floor);
                }
            }
            let uniform = u32::from(most) <= low[1] || u32::from(least) > high[1];
            debug_assert_eq!(uniform, uniform_by_faces(quad));
            uniform
        };
        if uniform {
            return true;
        }
        for dv in 0..quad.height {
            let mut start = 0;
            while start < quad.width {
                let at = |du: u32| {
                    let mut padded = quad.minimum;
                    padded[axes.u] += du;
                    padded[axes.v] += dv;
                    padded
                };
                let open = front(at(start));
                let mut end = start + 1;
                while end < quad.width && front(at(end)) == open {
                    end += 1;
                }
                runs.push(UnorientedQuad { minimum: at(start), width: end - start, height: 1 });
                start = end;
            }
        }
        false
    });
    group.append(&mut runs);
}

/// Whether the four voxel faces around lattice point `local` (each
/// coordinate in `1..LAST`) looking towards `side` are all there: solid
/// behind the point's plane, not solid in front, read from the chunk's
/// [`ChunkVoxels::solid_rows`] (`rows`, bit x of row `y + 34·z`).
#[inline(always)]
fn faces_around(rows: &[u64; PADDED_ROWS], local: [i32; 3], side: FaceDirection) -> bool {
    let axis = side.axis();
    // Padded coordinates of the point's far cells; the near ones are one
    // less on each axis but the normal's.
    let [x, y, z] = local.map(|c| (c + 1) as usize);
    let (behind, front) = if side.is_positive() { (-1, 0) } else { (0, -1) };
    let row = |y: usize, z: usize| rows[y + PADDED_CHUNK_SIZE as usize * z];
    let (solid, open) = match axis {
        // Two cells of each row: bits x − 1 and x.
        1 => {
            let (yb, yf) = (y.wrapping_add_signed(behind), y.wrapping_add_signed(front));
            let pair = |bits: u64| (bits >> (x - 1)) & 3;
            (pair(row(yb, z - 1)) & pair(row(yb, z)), pair(row(yf, z - 1)) | pair(row(yf, z)))
        }
        2 => {
            let (zb, zf) = (z.wrapping_add_signed(behind), z.wrapping_add_signed(front));
            let pair = |bits: u64| (bits >> (x - 1)) & 3;
            (pair(row(y - 1, zb)) & pair(row(y, zb)), pair(row(y - 1, zf)) | pair(row(y, zf)))
        }
        // Faces across x: one bit of each of the four rows, behind and in
        // front.
        _ => {
            let (xb, xf) = (x.wrapping_add_signed(behind), x.wrapping_add_signed(front));
            let cells = [row(y - 1, z - 1), row(y, z - 1), row(y - 1, z), row(y, z)];
            let all = cells.iter().fold(1, |all, bits| all & (bits >> xb));
            let any = cells.iter().fold(0, |any, bits| any | (bits >> xf));
            (all & 1 | (all & 1) << 1, any & 1)
        }
    };
    solid == 3 && open == 0
}

/// Whether lattice point `local`, on a boundary plane, is in the canonical
/// boundary vertex set: on a chunk edge, where its 2×2×2 voxels are not
/// plain, or within one voxel of a chunk edge where a face not lying in
/// the boundary plane meets the point (see the module docs). Reads only
/// voxels every chunk sharing the point holds (their padding).
fn is_boundary_vertex(voxels: &ChunkVoxels, local: [i32; 3], flat_edges: FlatEdges) -> bool {
    let on_plane = |c: i32| c == 0 || c == LAST;
    let near_plane = |c: i32| c <= 1 || c >= LAST - 1;
    let mut planes = (0..3).filter(|&k| on_plane(local[k]));
    let Some(mut plane) = planes.next() else { return false };
    if let Some(mut second) = planes.next() {
        if second == 1 {
            // The radial plane first.
            (plane, second) = (second, plane);
        }
        // On a chunk edge, shared by four chunks: a vertex at every chunk
        // corner and on every edge the strips of faces lying in a plane
        // may end on; on a radial plane's edge that those strips run
        // along (`FlatEdges`), only where something other than the radial
        // plane's own faces meets the point (below).
        let along = plane == 1 && flat_edges.along(second, local[second]);
        if !along || planes.next().is_some() {
            return true;
        }
    }
    // (Every point on an edge is near one.)
    let near_edge = (0..3).any(|j| j != plane && near_plane(local[j]));
    // The voxels below and above the point on each axis: local p − 1 and
    // p, padded p and p + 1.
    let at = |d: [i32; 3]| voxels.get([0, 1, 2].map(|k| (local[k] + d[k]) as u32)).unwrap_or(Voxel::AIR);
    let mut cube = [Voxel::AIR; 8];
    for (i, voxel) in cube.iter_mut().enumerate() {
        *voxel = at([(i & 1) as i32, ((i >> 1) & 1) as i32, ((i >> 2) & 1) as i32]);
    }
    // Along axis k the two halves of the cube are equal.
    let invariant = |k: usize| (0..8).filter(|i| i & (1 << k) == 0).all(|i| cube[i] == cube[i | (1 << k)]);
    let varying = (0..3).filter(|&k| !invariant(k)).fold(0u8, |mask, k| mask | 1 << k);
    if varying.count_ones() >= 2 {
        return true;
    }
    // Plain: one flat face through the point, or none. Within a voxel of
    // an edge the strips of faces touching the plane end (where the next
    // plane begins), so a face across the plane makes the point a vertex.
    // A face lying in the plane (or none) does not: nothing but this
    // plane's own faces, whose strips end on the edge or where the face
    // changes, meets the point, and dropping these points cuts the
    // triangles of flat ground lying in a boundary plane (the sea level,
    // where every coarse LOD puts lowland: 366 -> 126 triangles a chunk).
    // The same holds on a radial plane's edge along its strips (`edge`,
    // near an edge too): its faces meet it only along their strips'
    // sides (126 -> 64).
    near_edge && varying != 0 && varying != 1 << plane
}

/// Which edges of the radial boundary planes (those along the sides
/// across local x) may go without a vertex where only the radial plane's
/// own faces meet them: edges along the strips of faces lying in a radial
/// plane (which run along z), on a side that is neither on a cube-face
/// edge (the chunk across has other axes, its strips may end there), nor
/// dense, nor stitched (its vertices there are set by the neighbour's
/// LOD). A function of the chunk's key and its column's LOD relations,
/// which the chunks sharing such an edge (the same column's layers, and
/// the column across at the same LOD) agree on.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FlatEdges {
    /// The sides x = 0 and x = `LAST`.
    open: [bool; 2],
}

impl FlatEdges {
    /// Whether the edge on the side plane `axis` = `coordinate` (a
    /// horizontal axis; the edge's other plane radial) may go without a
    /// vertex where only the radial plane's faces meet it.
    fn along(self, axis: usize, coordinate: i32) -> bool {
        axis == 0 && self.open[usize::from(coordinate == LAST)]
    }
}

/// A block-mesh face's axes: normal `n` (with its sign) and the quad's
/// `u` (width) and `v` (height) axes.
struct FaceAxes {
    face: OrientedBlockFace,
    n: usize,
    u: usize,
    v: usize,
    positive: bool,
}

impl FaceAxes {
    fn of(face: &OrientedBlockFace) -> Self {
        let unit = UnorientedQuad { minimum: [1; 3], width: 1, height: 1 };
        let [c0, c1, c2, _] = face.quad_corners(&unit).map(|c| c.to_array());
        let axis_of = |a: [u32; 3], b: [u32; 3]| (0..3).find(|&k| a[k] != b[k]).unwrap_or(0);
        let normal = face.signed_normal().to_array();
        let n = (0..3).find(|&k| normal[k] != 0).unwrap_or(0);
        Self { face: *face, n, u: axis_of(c0, c1), v: axis_of(c0, c2), positive: normal[n] > 0 }
    }

    /// The local plane coordinate of faces of voxels in local layer `layer`
    /// along the normal.
    fn plane_of(&self, layer: i32) -> i32 {
        layer + i32::from(self.positive)
    }

    /// The local lattice corners of `quad`.
    fn corners(&self, quad: &UnorientedQuad) -> [[i32; 3]; 4] {
        local_corners(&self.face, quad)
    }

    /// Whether some face of `quad` has an edge on a boundary plane: a
    /// corner coordinate ([`Self::corners`]) of 0 or `LAST`. The corners
    /// span the quad's plane along `n` and its two ends along `u` and `v`,
    /// so those five numbers are checked (building the four corners for it
    /// was 8 % of meshing a surface chunk).
    fn touches_boundary(&self, quad: &UnorientedQuad) -> bool {
        let plane = self.plane_of(quad.minimum[self.n] as i32 - 1);
        let (u, v) = (quad.minimum[self.u] as i32 - 1, quad.minimum[self.v] as i32 - 1);
        let touches = [plane, u, u + quad.width as i32, v, v + quad.height as i32].iter().any(|&c| c == 0 || c == LAST);
        debug_assert_eq!(touches, self.corners(quad).iter().flatten().any(|&c| c == 0 || c == LAST));
        touches
    }

    /// Whether `quad` may stay whole although it touches a boundary plane:
    /// it does not lie in one, and each of its corners on one is in the
    /// canonical set.
    fn keeps_canonical_corners(&self, quad: &UnorientedQuad, voxels: &ChunkVoxels, flat_edges: FlatEdges) -> bool {
        let plane = self.plane_of(quad.minimum[self.n] as i32 - 1);
        plane != 0
            && plane != LAST
            && self.corners(quad).into_iter().all(|corner| {
                !corner.iter().any(|&c| c == 0 || c == LAST) || is_boundary_vertex(voxels, corner, flat_edges)
            })
    }

    /// Calls `f` with the padded voxel of every face of `quad`.
    fn for_each_face(&self, quad: &UnorientedQuad, mut f: impl FnMut([u32; 3])) {
        let (unit_u, unit_v) = (unit_along(self.u).map(|c| c as u32), unit_along(self.v).map(|c| c as u32));
        let m = quad.minimum;
        for dv in 0..quad.height {
            for du in 0..quad.width {
                let at = |k: usize| m[k] + du * unit_u[k] + dv * unit_v[k];
                f([at(0), at(1), at(2)]);
            }
        }
    }

    /// Clips a greedy quad to the faces touching no boundary plane: none
    /// lies in one, and none is in the first or last row along `u` or `v`.
    /// Returns `false` when nothing is left.
    fn clip_to_interior(&self, quad: &mut UnorientedQuad) -> bool {
        let plane = self.plane_of(quad.minimum[self.n] as i32 - 1);
        if plane == 0 || plane == LAST {
            return false;
        }
        let clip = |start: u32, len: u32| {
            // Padded voxel rows 2..=31 are local 1..=30.
            let (low, high) = (start.max(2), (start + len).min(LAST as u32));
            (low < high).then_some((low, high - low))
        };
        let (Some((u0, width)), Some((v0, height))) =
            (clip(quad.minimum[self.u], quad.width), clip(quad.minimum[self.v], quad.height))
        else {
            return false;
        };
        quad.minimum[self.u] = u0;
        quad.minimum[self.v] = v0;
        quad.width = width;
        quad.height = height;
        true
    }

    /// Pushes the faces touching a boundary plane as strips: the faces in
    /// the plane along `u`, and the others along the plane they touch
    /// (single faces where they touch two), each strip ended where the
    /// face changes. Only in `layers` (a bit per voxel layer along the
    /// normal): a face touching a boundary plane belongs to a greedy quad
    /// that does, so layers with none have nothing to strip (most of them:
    /// this scan was a third of a chunk's meshing).
    fn push_boundary_strips(
        &self,
        voxels: &[Voxel],
        is_covered: &impl Fn(usize) -> bool,
        layers: u64,
        quads: &mut Vec<UnorientedQuad>,
    ) {
        let edge_rows = [0, LAST - 1];
        let boundary_layer = if self.positive { LAST - 1 } else { 0 };
        let in_layers = |layer: i32| layers & (1 << layer) != 0;
        // The faces lying in the boundary plane.
        if in_layers(boundary_layer) {
            for v in 0..LAST {
                self.push_runs(voxels, is_covered, [boundary_layer, 0, v], self.u, LAST, quads);
            }
        }
        for layer in (0..LAST).filter(|&layer| layer != boundary_layer && in_layers(layer)) {
            for row in edge_rows {
                // Faces along a boundary plane across `v`, then across `u`.
                self.push_runs(voxels, is_covered, [layer, 1, row], self.u, LAST - 2, quads);
                self.push_runs(voxels, is_covered, [layer, row, 1], self.v, LAST - 2, quads);
                for column in edge_rows {
                    self.push_runs(voxels, is_covered, [layer, column, row], self.u, 1, quads);
                }
            }
        }
    }

    /// Pushes one quad per run of equal visible faces among `count` faces
    /// from the face of local voxel `(layer, u, v) = start` along `along`;
    /// faces covered by a kept quad end a run.
    fn push_runs(
        &self,
        voxels: &[Voxel],
        is_covered: &impl Fn(usize) -> bool,
        start: [i32; 3],
        along: usize,
        count: i32,
        quads: &mut Vec<UnorientedQuad>,
    ) {
        // Coordinates picked by comparison, not stored at picked indices
        // (see `ChunkMesher::walk_edge`).
        let pick = |k: usize| if k == self.n { start[0] } else if k == self.u { start[1] } else { start[2] } as u32 + 1;
        let padded = [pick(0), pick(1), pick(2)];
        let stride = |axis: usize| PaddedChunkShape::linearize(unit_along(axis).map(|c| c as u32)) as usize;
        let (first, step_along, step_out) =
            (PaddedChunkShape::linearize(padded) as usize, stride(along), stride(self.n));
        let unit = unit_along(along).map(|c| c as u32);
        // The run so far: its first step and its material (air's, 0, while
        // there is none).
        let (mut run_from, mut run_material) = (0, Voxel::AIR.material());
        for step in 0..=count as u32 {
            let mut material = Voxel::AIR.material();
            if step < count as u32 {
                let at = first + step as usize * step_along;
                let beyond = if self.positive { at + step_out } else { at - step_out };
                let voxel = voxels[at];
                if voxel.is_solid() && !voxels[beyond].is_solid() && !is_covered(at) {
                    material = voxel.material();
                }
            }
            if material != run_material {
                if run_material != Voxel::AIR.material() {
                    let at = |k: usize| padded[k] + run_from * unit[k];
                    let minimum = [at(0), at(1), at(2)];
                    let length = step - run_from;
                    let (width, height) = if along == self.u { (length, 1) } else { (1, length) };
                    quads.push(UnorientedQuad { minimum, width, height });
                }
                (run_from, run_material) = (step, material);
            }
        }
    }
}

/// The local lattice corners of `quad` on `face`: block-mesh's corners
/// (padded) less one, in its order. Written out: as nested array maps the
/// conversion stayed a call per corner (5 % of meshing a surface chunk).
#[inline]
fn local_corners(face: &OrientedBlockFace, quad: &UnorientedQuad) -> [[i32; 3]; 4] {
    let local = |corner: [u32; 3]| [corner[0] as i32 - 1, corner[1] as i32 - 1, corner[2] as i32 - 1];
    let [a, b, c, d] = face.quad_corners(quad);
    [local(a.to_array()), local(b.to_array()), local(c.to_array()), local(d.to_array())]
}

/// The unit step along `axis`.
fn unit_along(axis: usize) -> [i32; 3] {
    [i32::from(axis == 0), i32::from(axis == 1), i32::from(axis == 2)]
}

/// The index in `ChunkMesher::vertex_slot` of the vertex at the lattice
/// point with index `point` on a face looking towards side `side`: side
/// by side, so that a side's quads, meshed together, read one region.
fn vertex_slot(point: usize, side: usize) -> usize {
    side * POINTS * POINTS * POINTS + point
}

fn point_index(local: [i32; 3]) -> usize {
    (local[0] as usize * POINTS + local[1] as usize) * POINTS + local[2] as usize
}

fn sub(a: [i32; 3], b: [i32; 3]) -> [i32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn quad_len(a: [i32; 3], b: [i32; 3]) -> i32 {
    (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs()
}

fn side_of(normal: [i32; 3]) -> FaceDirection {
    match normal {
        [1, _, _] => FaceDirection::PosX,
        [-1, _, _] => FaceDirection::NegX,
        [_, 1, _] => FaceDirection::PosY,
        [_, -1, _] => FaceDirection::NegY,
        [_, _, 1] => FaceDirection::PosZ,
        _ => FaceDirection::NegZ,
    }
}
