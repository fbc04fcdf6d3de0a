//! The finished mesh of one chunk and the queries the seam code and tests use.

use std::collections::{HashMap, HashSet};

use nebula_math::{DVec3, FaceDirection, LatticePoint, Vec3, relative_position};
use nebula_voxel::{CHUNK_SIZE, ChunkKey, ChunkLayout};

/// One vertex as uploaded to the GPU: 40 bytes, `#[repr(C)]`.
///
/// | bytes | field |
/// |---|---|
/// | 0–11 | `position`: f32 × 3, metres from the chunk's origin |
/// | 12–23 | `normal`: f32 × 3, unit |
/// | 24–35 | `morph_target`: f32 × 3, where the vertex goes as it morphs towards the coarser LOD |
/// | 36 | `material`: u8 voxel material id |
/// | 37 | `sky_light`: u8, 0 (in a cave) to 255 (open ground) |
/// | 38–39 | `flags`: u16, [`MeshVertex::SKIRT`] / [`MeshVertex::CONSTRAINED`] |
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct MeshVertex {
    /// Position relative to the mesh origin ([`ChunkMesh::origin`]).
    pub position: Vec3,
    /// Unit normal. Skirt vertices carry the normal of the surface vertex
    /// they hang from (normal locking).
    pub normal: Vec3,
    /// Geomorph target relative to the mesh origin: where the vertex lies
    /// on the parent LOD's surface. For a lattice vertex that is the vertex
    /// with every local coordinate rounded down to even, which by the voxel
    /// LOD rule (`nebula_voxel`: a coarse voxel is its far-corner fine
    /// voxel) makes a fully morphed chunk coincide with its parent (but
    /// for the octaves a band-limited parent leaves out,
    /// `PlanetSettings::band_limit`). A
    /// constrained vertex targets the same chord between its segment's two
    /// (morphed) ends. Same-LOD neighbours share targets, so their seams
    /// stay closed while morphing; across a LOD boundary the skirts, sized
    /// for every morph state, cover the gap.
    pub morph_target: Vec3,
    /// Voxel material id of the face.
    pub material: u8,
    /// How much sky lights the vertex, 0 (none: deep in a cave) to 255
    /// (open ground): see `ChunkMesher`'s `sky_light`. Skirt vertices carry
    /// their surface vertex's.
    pub sky_light: u8,
    /// Bit set of [`MeshVertex::SKIRT`] and [`MeshVertex::CONSTRAINED`],
    /// and for a skirt vertex the side it hangs on
    /// ([`MeshVertex::skirt_side`]).
    pub flags: u16,
}

impl MeshVertex {
    /// The vertex is the lower end of a skirt.
    pub const SKIRT: u16 = 1;
    /// The vertex was moved onto a coarser neighbour's edge.
    pub const CONSTRAINED: u16 = 2;
    /// Bits 2–3 of a skirt vertex's flags: which horizontal side it hangs
    /// on, as an index into [`FaceDirection::HORIZONTAL`].
    pub const SIDE_SHIFT: u16 = 2;

    /// The side a skirt vertex hangs on; `None` for other vertices.
    #[must_use]
    pub fn skirt_side(&self) -> Option<FaceDirection> {
        (self.flags & Self::SKIRT != 0)
            .then(|| FaceDirection::HORIZONTAL[usize::from((self.flags >> Self::SIDE_SHIFT) & 3)])
    }

    /// The flags of a skirt vertex on `side`.
    pub(crate) fn skirt_flags(side: FaceDirection) -> u16 {
        let index = FaceDirection::HORIZONTAL.iter().position(|&s| s == side).unwrap_or(0) as u16;
        Self::SKIRT | (index << Self::SIDE_SHIFT)
    }
}

/// One edge of a mesh's outline on a side (see [`ChunkMesh::outline`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutlineEdge {
    /// Its end points as canonical lattice points, in the surface's winding
    /// order.
    pub lattice: [LatticePoint; 2],
    /// Their f64 world positions (after constraining).
    pub world: [DVec3; 2],
    /// Whether the edge lies on the chunk's top or bottom plane, where it is
    /// shared with the chunk above or below rather than with the neighbour
    /// on this side.
    pub on_radial_boundary: bool,
}

/// Where a vertex came from.
///
/// `repr(u32)`: with Rust's own layout (16 bytes) the mesher built a
/// `Surface` from its lattice point stored in two pieces and read it back
/// across them, a store-forwarding stall a vertex (a quarter of making one);
/// laid out as C does (20 bytes), the point is copied whole.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub(crate) enum VertexSource {
    /// A lattice point of the chunk (local coordinates at the chunk's LOD,
    /// each in `0..=32`, or beyond for the far end of a coarse edge a
    /// stitch zips) on a face looking towards `side`.
    Surface { local: [i32; 3], side: FaceDirection },
    /// The lower end of a skirt hanging from vertex `top`.
    Skirt { top: u32 },
    /// Added by [`ChunkMesh::push_triangle`].
    Loose,
}

/// The mesh of one chunk: vertices relative to an f64 origin, u32 indices,
/// surface triangles first, then skirts and pushed triangles.
#[derive(Clone, Debug)]
pub struct ChunkMesh {
    pub(crate) key: ChunkKey,
    pub(crate) layout: ChunkLayout,
    pub(crate) origin: DVec3,
    pub(crate) vertices: Vec<MeshVertex>,
    /// f64 world position of each vertex: the truth `position` is cast from.
    pub(crate) world: Vec<DVec3>,
    /// f64 world position of each morph target.
    pub(crate) morph_world: Vec<DVec3>,
    pub(crate) sources: Vec<VertexSource>,
    pub(crate) indices: Vec<u32>,
    /// `indices[..surface_index_count]` are the surface triangles.
    pub(crate) surface_index_count: usize,
    /// The surface triangles of the faces looking towards each side (index
    /// `FaceDirection as usize`), consecutive ranges of `indices`.
    pub(crate) surface_side_ranges: [std::ops::Range<usize>; 6],
    /// Of each wall side's range (index as in
    /// [`FaceDirection::HORIZONTAL`]), how many indices at its end are of
    /// triangles the morph keeps at least a voxel tall
    /// ([`ChunkMesh::surface_parts`]); 0 until ordered (every triangle
    /// taken as flattened).
    pub(crate) steady_wall_indices: [usize; 4],
    pub(crate) skirt_triangles: usize,
    /// Depth of the skirt generated on each horizontal side (index as in
    /// [`FaceDirection::HORIZONTAL`]), metres; 0 where there is none.
    pub(crate) skirt_depths: [f32; 4],
    /// The index range of each side's skirt triangles.
    pub(crate) skirt_ranges: [std::ops::Range<usize>; 4],
    /// Whether some of the chunk's dark cave air was meshed as rock
    /// ([`ChunkMesher::plug_dark_air`](crate::ChunkMesher::plug_dark_air)).
    pub(crate) dark_air_plugged: bool,
    /// The surface triangles around each side's stubs (index
    /// `FaceDirection as usize`; [`ChunkMesh::surface_parts`]), after the
    /// side ranges.
    pub(crate) stub_ranges: [std::ops::Range<usize>; 6],
    /// Meshed plugged inside
    /// ([`MeshOptions::plug_dark_air_inside`](crate::MeshOptions::plug_dark_air_inside)).
    pub(crate) plugged_inside: bool,
    /// Its stubs must be drawn: [`ChunkMesh::stubs_exposed`].
    pub(crate) stubs_exposed: bool,
    /// [`ChunkMesh::pockets_beyond`].
    pub(crate) pockets_beyond: [bool; 2],
}

impl ChunkMesh {
    /// An empty mesh for `key`, with the chunk's origin.
    pub(crate) fn empty(key: ChunkKey, layout: ChunkLayout, origin: DVec3) -> Self {
        Self {
            key,
            layout,
            origin,
            vertices: Vec::new(),
            world: Vec::new(),
            morph_world: Vec::new(),
            sources: Vec::new(),
            indices: Vec::new(),
            surface_index_count: 0,
            surface_side_ranges: [0..0, 0..0, 0..0, 0..0, 0..0, 0..0],
            steady_wall_indices: [0; 4],
            skirt_triangles: 0,
            skirt_depths: [0.0; 4],
            skirt_ranges: [0..0, 0..0, 0..0, 0..0],
            dark_air_plugged: false,
            stub_ranges: [0..0, 0..0, 0..0, 0..0, 0..0, 0..0],
            plugged_inside: false,
            stubs_exposed: false,
            pockets_beyond: [false; 2],
        }
    }

    /// Whether the chunk was meshed plugged inside
    /// ([`MeshOptions::plug_dark_air_inside`](crate::MeshOptions::plug_dark_air_inside),
    /// whether or not it held dark air to plug): its dark air lies in rock
    /// but in the layers it shares with the columns of other plug groups
    /// ([`crate::plug_group`]), and the faces around the pockets a side
    /// keeps there (its stubs) are surface parts of their own
    /// ([`ChunkMesh::surface_parts`]). Under stitched seams, whose zips lie
    /// in the side planes, the stubs are drawn with the rest.
    #[must_use]
    pub fn plugged_inside(&self) -> bool {
        self.plugged_inside
    }

    /// Whether a pocket of dark air the chunk shares with a horizontal
    /// neighbour, off its other horizontal sides, borders the chunk's own
    /// unplugged air (a lit shaft beside a side): seen through that air, so
    /// the neighbour, which cannot see this chunk's voxels, draws its stubs
    /// towards it
    /// ([`ChunkDraw::hidden_stubs`](crate::ChunkDraw::hidden_stubs)).
    #[must_use]
    pub fn stubs_exposed(&self) -> bool {
        self.stubs_exposed
    }

    /// Of a chunk plugged inside: whether a pocket of air in the layers it
    /// shares with a horizontal neighbour that is no stub here (lit
    /// somewhere, or reaching another side's layers) is dark in the layers
    /// shared with the chunk above (`[0]`) or below (`[1]`). A chunk of
    /// that layer, in this column or the neighbour's, may see its part of
    /// the pocket as a stub, which must then be drawn: a renderer leaves
    /// out no stub between two columns where one holds such a chunk and
    /// either holds the layer it reaches into. (A chunk plugged inside
    /// plugs the layers it shares radially, so its column's chunks hold
    /// one pocket between them.)
    #[must_use]
    pub fn pockets_beyond(&self) -> [bool; 2] {
        self.pockets_beyond
    }

    /// Moves the surface triangles around stubs out of their side ranges
    /// into a range per stub side, after the side ranges (before the
    /// walls are ordered for the morph and skirts are added):
    /// `stub_side(air)` names the side whose stub the air voxel `air`
    /// (padded coordinates) lies in, if any. A triangle's air voxel is the
    /// one in front of the face it lies on, at its centroid (inside one
    /// greedy quad or flat region, whose faces all look into air linked in
    /// their plane: one pocket).
    pub(crate) fn set_aside_stubs(&mut self, stub_side: impl Fn([i32; 3]) -> Option<FaceDirection>) {
        let surface = self.surface_index_count;
        if self.surface_side_ranges.iter().map(ExactSizeIterator::len).sum::<usize>() != surface {
            // Triangles outside the side ranges (none a mesher makes): the
            // surface is kept whole, nothing set apart.
            return;
        }
        let mut order: Vec<usize> = (0..6).collect();
        order.sort_by_key(|&d| self.surface_side_ranges[d].start);
        let mut kept = Vec::with_capacity(surface);
        let mut stubs: [Vec<u32>; 6] = Default::default();
        let mut ranges = self.surface_side_ranges.clone();
        for d in order {
            let facing = FaceDirection::ALL[d];
            let axis = facing.axis();
            let start = kept.len();
            for triangle in self.indices[self.surface_side_ranges[d].clone()].chunks_exact(3) {
                let locals = [0, 1, 2].map(|k| self.local(triangle[k] as usize));
                let side = match locals {
                    [Some(a), Some(b), Some(c)] => {
                        let mut air = [0; 3];
                        for k in 0..3 {
                            air[k] = if k == axis {
                                if facing.is_positive() { a[k] } else { a[k] - 1 }
                            } else {
                                (a[k] + b[k] + c[k]).div_euclid(3)
                            } + 1;
                        }
                        stub_side(air)
                    }
                    _ => None,
                };
                match side {
                    Some(side) => stubs[side as usize].extend_from_slice(triangle),
                    None => kept.extend_from_slice(triangle),
                }
            }
            ranges[d] = start..kept.len();
        }
        let mut stub_ranges: [std::ops::Range<usize>; 6] = Default::default();
        for (side, triangles) in stubs.iter().enumerate() {
            let start = kept.len();
            kept.extend_from_slice(triangles);
            stub_ranges[side] = start..kept.len();
        }
        self.indices.splice(..surface, kept);
        self.surface_side_ranges = ranges;
        self.stub_ranges = stub_ranges;
    }

    /// Whether some of the chunk's dark cave air was meshed as rock
    /// ([`MeshOptions::plug_dark_air_from_lod`](crate::MeshOptions::plug_dark_air_from_lod),
    /// [`MeshOptions::plug_dark_air_inside`](crate::MeshOptions::plug_dark_air_inside)):
    /// its mesh differs from the chunk's whole caves. A streamer that
    /// plugged it by distance (the second) meshes it again, open, as the
    /// eye comes near.
    #[must_use]
    pub fn dark_air_plugged(&self) -> bool {
        self.dark_air_plugged
    }

    /// The range of [`ChunkMesh::indices`] holding each side's skirt (index
    /// as in [`FaceDirection::HORIZONTAL`]; the last
    /// [`generate_skirt`](crate::generate_skirt) call on that side). A
    /// renderer drawing skirts at draw-time depths draws only the sides it
    /// lowers.
    #[must_use]
    pub fn skirt_index_ranges(&self) -> [std::ops::Range<usize>; 4] {
        self.skirt_ranges.clone()
    }

    /// The range of [`ChunkMesh::indices`] holding the surface triangles of
    /// the faces looking towards each side (index `FaceDirection as usize`;
    /// but those around stubs, which a mesh plugged inside holds in parts
    /// of their own); a renderer leaves parts of them out by
    /// [`ChunkMesh::surface_parts`] (see `ChunkDraw::hidden_sides`).
    #[must_use]
    pub fn surface_side_ranges(&self) -> [std::ops::Range<usize>; 6] {
        self.surface_side_ranges.clone()
    }

    /// The surface's triangles in the parts a renderer may leave out apart
    /// ([`SURFACE_PARTS`](crate::SURFACE_PARTS) index
    /// ranges of [`ChunkMesh::indices`], together the surface): part
    /// `FaceDirection as usize`, a side's faces (of a wall side, those the
    /// morph keeps at least a voxel tall); part 6 + k, the faces of wall
    /// side `FaceDirection::HORIZONTAL[k]` the morph flattens (their
    /// corners' morph targets on one radial layer: their height shrinks
    /// with μ, to nothing at μ = 0); part 10 + `FaceDirection as usize`,
    /// the faces around that side's stubs, of any direction (a chunk
    /// meshed plugged inside, [`ChunkMesh::plugged_inside`]; horizontal
    /// sides only, the radial ones' parts empty: it plugs what it shares
    /// radially).
    #[must_use]
    pub fn surface_parts(&self) -> [std::ops::Range<usize>; crate::SURFACE_PARTS] {
        let mut parts: [std::ops::Range<usize>; crate::SURFACE_PARTS] = Default::default();
        parts[..6].clone_from_slice(&self.surface_side_ranges);
        parts[10..].clone_from_slice(&self.stub_ranges);
        for (k, side) in FaceDirection::HORIZONTAL.into_iter().enumerate() {
            let range = self.surface_side_ranges[side as usize].clone();
            let split = range.end - self.steady_wall_indices[k];
            parts[side as usize] = split..range.end;
            parts[6 + k] = range.start..split;
        }
        parts
    }

    /// Orders each wall side's triangles so that those the morph flattens
    /// come first, and counts the others ([`ChunkMesh::surface_parts`]). A
    /// triangle is taken as flattened unless each corner is a lattice
    /// point of the surface, none constrained onto a coarser neighbour's
    /// lattice, and their morph targets (their local coordinates rounded
    /// down to even) lie on two radial layers at least and two lattice
    /// lines along the wall: then its height and its length between them
    /// are at least a voxel at every μ (linear in μ between a voxel or
    /// more at μ = 1 and two or more at μ = 0, rounding keeping the
    /// order). A wall left out must be wide on screen both ways: across
    /// its height between the faces above and below it, across its length
    /// between the walls at its ends.
    pub(crate) fn order_flattening_walls(&mut self) {
        for (k, side) in FaceDirection::HORIZONTAL.into_iter().enumerate() {
            let range = self.surface_side_ranges[side as usize].clone();
            // A two-ended partition of whole triangles.
            let (mut front, mut back) = (range.start, range.end);
            while front < back {
                let triangle = [self.indices[front], self.indices[front + 1], self.indices[front + 2]];
                if self.flattens(triangle, side) {
                    front += 3;
                } else {
                    back -= 3;
                    for c in 0..3 {
                        self.indices.swap(front + c, back + c);
                    }
                }
            }
            self.steady_wall_indices[k] = range.end - front;
        }
    }

    /// Whether the morph may flatten `triangle`, of a wall looking
    /// towards `side`, to no height or no length (see
    /// [`ChunkMesh::order_flattening_walls`]).
    fn flattens(&self, triangle: [u32; 3], side: FaceDirection) -> bool {
        // The coordinate along the wall: z for walls looking along x.
        let along = if side.axis() == 0 { 2 } else { 0 };
        let target = |index: u32| {
            let index = index as usize;
            match self.sources.get(index) {
                Some(VertexSource::Surface { local, .. }) if !self.is_constrained(index) => {
                    Some([local[1] & !1, local[along] & !1])
                }
                _ => None,
            }
        };
        match triangle.map(target) {
            [Some(a), Some(b), Some(c)] => (0..2).any(|k| a[k] == b[k] && b[k] == c[k]),
            _ => true,
        }
    }

    /// The depth each side's skirt was generated with (index as in
    /// [`FaceDirection::HORIZONTAL`]), metres; 0 where there is none. A
    /// renderer may draw skirts at other depths (see
    /// [`RenderVertex`](crate::RenderVertex)).
    #[must_use]
    pub fn skirt_depths(&self) -> [f32; 4] {
        self.skirt_depths
    }

    /// The chunk this mesh belongs to.
    #[must_use]
    pub fn key(&self) -> ChunkKey {
        self.key
    }

    /// The f64 world position vertices are relative to (the chunk's lattice
    /// corner unless [`ChunkMesh::rebase`]d).
    #[must_use]
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The planet centre in this mesh's frame (`−origin`), for
    /// [`generate_skirt`](crate::generate_skirt).
    #[must_use]
    pub fn planet_center(&self) -> Vec3 {
        relative_position(DVec3::ZERO, self.origin)
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// All vertices.
    #[must_use]
    pub fn vertices(&self) -> &[MeshVertex] {
        &self.vertices
    }

    /// Triangle list indices into [`ChunkMesh::vertices`].
    #[must_use]
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// All triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Triangles of the voxel surface (no skirts, nothing pushed).
    #[must_use]
    pub fn surface_triangle_count(&self) -> usize {
        self.surface_index_count / 3
    }

    /// Triangles added by [`generate_skirt`](crate::generate_skirt).
    #[must_use]
    pub fn skirt_triangle_count(&self) -> usize {
        self.skirt_triangles
    }

    /// Whether the mesh has no triangles.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// The f64 world position of vertex `index`.
    #[must_use]
    pub fn world_position(&self, index: usize) -> Option<DVec3> {
        self.world.get(index).copied()
    }

    /// The canonical lattice point of vertex `index`, for surface vertices
    /// (what two chunks compare to find shared vertices).
    #[must_use]
    pub fn lattice_point(&self, index: usize) -> Option<LatticePoint> {
        match self.sources.get(index)? {
            VertexSource::Surface { local, .. } => self.layout.lattice_point(self.key, local.map(i64::from)).ok(),
            _ => None,
        }
    }

    /// The local lattice coordinates (each in `0..=32`, at the chunk's LOD;
    /// a stitch's zip may end beyond, `crate::stitch`)
    /// of surface vertex `index`; `None` for skirt and pushed vertices.
    #[must_use]
    pub fn local_lattice(&self, index: usize) -> Option<[i32; 3]> {
        self.local(index)
    }

    /// Whether vertex `index` was moved onto a coarser neighbour's edge.
    #[must_use]
    pub fn is_constrained(&self, index: usize) -> bool {
        self.vertices.get(index).is_some_and(|v| v.flags & MeshVertex::CONSTRAINED != 0)
    }

    /// Re-expresses every vertex relative to `origin` (e.g. a common origin
    /// for comparing two chunks, or the planet centre). Positions are cast
    /// from the f64 truth again, so no error accumulates.
    pub fn rebase(&mut self, origin: DVec3) {
        self.origin = origin;
        for ((vertex, world), morph) in self.vertices.iter_mut().zip(&self.world).zip(&self.morph_world) {
            vertex.position = relative_position(*world, origin);
            vertex.morph_target = relative_position(*morph, origin);
        }
    }

    /// Appends a triangle by positions (relative to the mesh origin) as three
    /// new vertices with the triangle's flat normal, wound as given.
    pub fn push_triangle(&mut self, a: Vec3, b: Vec3, c: Vec3) {
        let normal = (b - a).cross(c - a).normalize_or_zero();
        for position in [a, b, c] {
            let world = self.origin + position.as_dvec3();
            self.push_vertex(world, world, normal, (0, 255), 0, VertexSource::Loose);
        }
        let first = (self.vertices.len() - 3) as u32;
        self.indices.extend([first, first + 1, first + 2]);
    }

    #[inline(always)]
    pub(crate) fn push_vertex(
        &mut self,
        world: DVec3,
        morph_world: DVec3,
        normal: Vec3,
        (material, sky_light): (u8, u8),
        flags: u16,
        source: VertexSource,
    ) -> u32 {
        let index = self.vertices.len() as u32;
        self.vertices.push(MeshVertex {
            position: relative_position(world, self.origin),
            normal,
            morph_target: relative_position(morph_world, self.origin),
            material,
            sky_light,
            flags,
        });
        self.world.push(world);
        self.morph_world.push(morph_world);
        self.sources.push(source);
        index
    }

    /// Drops every vertex `removed` marks (none of them in a triangle any
    /// more), keeping the others' order, from every per-vertex list, and
    /// renumbers the indices; `remap` is scratch (each vertex's new index).
    pub(crate) fn remove_vertices(&mut self, removed: &[bool], remap: &mut Vec<u32>) {
        debug_assert_eq!(removed.len(), self.vertices.len());
        remap.clear();
        let mut next = 0u32;
        for &gone in removed {
            remap.push(next);
            next += u32::from(!gone);
        }
        fn keep<T>(list: &mut Vec<T>, removed: &[bool]) {
            let mut gone = removed.iter();
            list.retain(|_| !gone.next().copied().unwrap_or(false));
        }
        keep(&mut self.vertices, removed);
        keep(&mut self.world, removed);
        keep(&mut self.morph_world, removed);
        keep(&mut self.sources, removed);
        for index in &mut self.indices {
            debug_assert!(!removed[*index as usize], "a removed vertex is still in a triangle");
            *index = remap[*index as usize];
        }
    }

    /// Moves vertex `index` to `world` (f64) with morph target `morph`, and
    /// marks it constrained.
    pub(crate) fn move_vertex(&mut self, index: usize, world: DVec3, morph: DVec3) {
        self.world[index] = world;
        self.morph_world[index] = morph;
        self.vertices[index].position = relative_position(world, self.origin);
        self.vertices[index].morph_target = relative_position(morph, self.origin);
        self.vertices[index].flags |= MeshVertex::CONSTRAINED;
    }

    /// The f64 world position of vertex `index`'s morph target.
    #[must_use]
    pub fn morph_world_position(&self, index: usize) -> Option<DVec3> {
        self.morph_world.get(index).copied()
    }

    /// The vertex a skirt vertex hangs from.
    pub(crate) fn skirt_top(&self, index: usize) -> Option<u32> {
        match self.sources.get(index)? {
            VertexSource::Skirt { top } => Some(*top),
            _ => None,
        }
    }

    /// Local lattice coordinates of surface vertex `index`.
    pub(crate) fn local(&self, index: usize) -> Option<[i32; 3]> {
        match self.sources[index] {
            VertexSource::Surface { local, .. } => Some(local),
            _ => None,
        }
    }

    /// Indices of the surface vertices on `side`'s boundary plane.
    pub(crate) fn boundary_indices(&self, side: FaceDirection) -> Vec<usize> {
        (0..self.vertices.len()).filter(|&i| self.is_on_plane(i, side)).collect()
    }

    /// Whether vertex `index` is a surface vertex on `side`'s boundary plane.
    fn is_on_plane(&self, index: usize, side: FaceDirection) -> bool {
        self.local(index).is_some_and(|l| l[side.axis()] == side_plane(side))
    }

    /// All surface vertices on the chunk's boundary plane on `side`
    /// (`x = 32` for +X, …), in no particular order.
    #[must_use]
    pub fn boundary_vertices(&self, side: FaceDirection) -> Vec<MeshVertex> {
        self.boundary_indices(side).into_iter().map(|i| self.vertices[i]).collect()
    }

    /// The directed surface edges on `side`'s boundary plane that only one
    /// surface triangle uses: where the surface leaves the chunk, and where
    /// a neighbour's surface (or a crack) begins. Radial edges are left out:
    /// a skirt hanging from one would have no area.
    pub(crate) fn outline_edges(&self, side: FaceDirection) -> Vec<(u32, u32)> {
        let index = crate::side_index(side);
        let wanted = std::array::from_fn(|k| k == index);
        self.outlines(wanted).into_iter().nth(index).unwrap_or_default()
    }

    /// [`ChunkMesh::outline_edges`] of each horizontal side `wanted` (index
    /// as in [`FaceDirection::HORIZONTAL`]; empty for the others), in one
    /// pass over the vertices and triangles (a pass a side was a tenth of
    /// meshing a chunk for streaming).
    pub(crate) fn outlines(&self, wanted: [bool; 4]) -> [Vec<(u32, u32)>; 4] {
        let wanted_bits = (0..4).fold(0u8, |bits, k| bits | (u8::from(wanted[k]) << k));
        // The boundary planes each vertex lies on, a bit a side, looked up
        // once each: most triangles have at most one vertex on a plane and
        // no edge to count.
        let planes: Vec<u8> = self
            .sources
            .iter()
            .map(|source| match source {
                VertexSource::Surface { local, .. } => {
                    FaceDirection::HORIZONTAL
                        .iter()
                        .enumerate()
                        .fold(0, |bits, (k, &side)| bits | (u8::from(local[side.axis()] == side_plane(side)) << k))
                        & wanted_bits
                }
                _ => 0,
            })
            .collect();
        // Every surface edge in a plane as (undirected lattice edge,
        // directed edge), by side, sorted, so that an edge one triangle
        // alone uses is a run of one (a hash map of counts was a fifth of
        // meshing a chunk for streaming, four sides a chunk).
        let mut found: [Vec<(LatticeEdge, (u32, u32))>; 4] = Default::default();
        for triangle in self.indices[..self.surface_index_count].chunks_exact(3) {
            let on = [0, 1, 2].map(|k| planes[triangle[k] as usize]);
            if (on[0] & on[1]) | (on[1] & on[2]) | (on[2] & on[0]) == 0 {
                continue;
            }
            let locals =
                [self.local(triangle[0] as usize), self.local(triangle[1] as usize), self.local(triangle[2] as usize)];
            // A stitch's zip (three lattice points on one line, `crate::stitch`)
            // covers no surface: its edges are not where the surface ends.
            if let [Some(p), Some(q), Some(r)] = locals
                && on_one_line(p, q, r)
            {
                continue;
            }
            for k in 0..3 {
                let next = (k + 1) % 3;
                // On a plane, so surface vertices with lattice points.
                let (shared, Some(la), Some(lb)) = (on[k] & on[next], locals[k], locals[next]) else { continue };
                let key = if la < lb { (la, lb) } else { (lb, la) };
                for (side, found) in found.iter_mut().enumerate() {
                    if shared & (1 << side) != 0 {
                        found.push((key, (triangle[k], triangle[next])));
                    }
                }
            }
        }
        found.map(|mut found| {
            found.sort_unstable_by_key(|&(key, _)| key);
            let mut edges = Vec::new();
            for run in found.chunk_by(|a, b| a.0 == b.0) {
                let ((la, lb), edge) = run[0];
                if run.len() == 1 && !(la[0] == lb[0] && la[2] == lb[2]) {
                    edges.push(edge);
                }
            }
            edges
        })
    }

    /// The outline on `side`: the surface edges on the chunk's boundary
    /// plane that only one surface triangle of this chunk uses (where the
    /// surface leaves the chunk), radial edges left out, as lattice points
    /// and world positions. A same-LOD neighbour's outline on the facing
    /// side is the same set of edges.
    #[must_use]
    pub fn outline(&self, side: FaceDirection) -> Vec<OutlineEdge> {
        self.outline_edges(side)
            .into_iter()
            .filter_map(|(a, b)| {
                let (a, b) = (a as usize, b as usize);
                let (la, lb) = (self.local(a)?, self.local(b)?);
                let top = CHUNK_SIZE as i32;
                Some(OutlineEdge {
                    lattice: [self.lattice_point(a)?, self.lattice_point(b)?],
                    world: [self.world[a], self.world[b]],
                    on_radial_boundary: (la[1] == 0 && lb[1] == 0) || (la[1] == top && lb[1] == top),
                })
            })
            .collect()
    }

    /// The vertices of the outline on `side` (see
    /// [`ChunkMesh::outline`]), walked as polylines in the order of
    /// growing along-edge coordinate: what a neighbour's edge must meet.
    #[must_use]
    pub fn ordered_boundary_vertices(&self, side: FaceDirection) -> Vec<MeshVertex> {
        self.ordered_boundary_indices(side).into_iter().map(|i| self.vertices[i]).collect()
    }

    pub(crate) fn ordered_boundary_indices(&self, side: FaceDirection) -> Vec<usize> {
        let along = along_axis(side);
        // Chain by lattice point: faces of different directions meeting at a
        // point have separate vertices there.
        let mut neighbours: HashMap<[i32; 3], Vec<[i32; 3]>> = HashMap::new();
        let mut vertex_at: HashMap<[i32; 3], usize> = HashMap::new();
        for (a, b) in self.outline_edges(side) {
            let (Some(la), Some(lb)) = (self.local(a as usize), self.local(b as usize)) else { continue };
            neighbours.entry(la).or_default().push(lb);
            neighbours.entry(lb).or_default().push(la);
            for (l, v) in [(la, a), (lb, b)] {
                let slot = vertex_at.entry(l).or_insert(v as usize);
                *slot = (*slot).min(v as usize);
            }
        }
        let order_key = |l: &[i32; 3]| (l[along], l[1]);
        let mut starts: Vec<[i32; 3]> = neighbours.keys().copied().collect();
        // Chain ends first, then whatever is left (closed loops).
        starts.sort_by_key(|l| (neighbours[l].len() != 1, order_key(l)));
        let mut visited = HashSet::new();
        let mut ordered = Vec::new();
        for start in starts {
            if visited.contains(&start) {
                continue;
            }
            let mut chain = vec![start];
            visited.insert(start);
            let mut here = start;
            while let Some(&next) =
                neighbours[&here].iter().filter(|n| !visited.contains(*n)).min_by_key(|n| order_key(n))
            {
                visited.insert(next);
                chain.push(next);
                here = next;
            }
            if chain.last().map(order_key) < chain.first().map(order_key) {
                chain.reverse();
            }
            ordered.push(chain);
        }
        ordered.sort_by_key(|chain| order_key(&chain[0]));
        ordered.into_iter().flatten().map(|l| vertex_at[&l]).collect()
    }

    /// The position of the outline vertex on `side` whose along-edge local
    /// coordinate is `coord`, if there is one (the first in
    /// [`ChunkMesh::ordered_boundary_vertices`] order).
    #[must_use]
    pub fn vertex_at_edge_coord(&self, side: FaceDirection, coord: i32) -> Option<Vec3> {
        let along = along_axis(side);
        self.ordered_boundary_indices(side)
            .into_iter()
            .find(|&i| self.local(i).is_some_and(|l| l[along] == coord))
            .map(|i| self.vertices[i].position)
    }

    /// Whether any vertex of a surface triangle lies strictly inside an edge
    /// of a surface triangle, decided exactly in lattice coordinates. Skirt and pushed
    /// vertices are not lattice points and are not considered.
    #[must_use]
    pub fn has_t_junctions(&self) -> bool {
        let surface = &self.indices[..self.surface_index_count];
        let points: HashSet<[i32; 3]> = surface.iter().filter_map(|&i| self.local(i as usize)).collect();
        surface.chunks_exact(3).any(|triangle| {
            (0..3).any(|k| {
                let (a, b) = (self.local(triangle[k] as usize), self.local(triangle[(k + 1) % 3] as usize));
                let (Some(a), Some(b)) = (a, b) else { return false };
                lattice_points_inside(a, b).any(|p| points.contains(&p))
            })
        })
    }
}

/// Two local lattice points, smaller first.
type LatticeEdge = ([i32; 3], [i32; 3]);

/// Whether three lattice points lie on one line: a triangle of them covers
/// nothing (a stitch's zip, `crate::stitch`).
pub(crate) fn on_one_line(p: [i32; 3], q: [i32; 3], r: [i32; 3]) -> bool {
    let (u, v) = ([q[0] - p[0], q[1] - p[1], q[2] - p[2]], [r[0] - p[0], r[1] - p[1], r[2] - p[2]]);
    u[1] * v[2] == u[2] * v[1] && u[2] * v[0] == u[0] * v[2] && u[0] * v[1] == u[1] * v[0]
}

/// The lattice points strictly between `a` and `b`.
pub(crate) fn lattice_points_inside(a: [i32; 3], b: [i32; 3]) -> impl Iterator<Item = [i32; 3]> {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let steps = gcd(gcd(d[0].unsigned_abs(), d[1].unsigned_abs()), d[2].unsigned_abs()).max(1) as i32;
    let step = d.map(|c| c / steps);
    (1..steps).map(move |k| [a[0] + k * step[0], a[1] + k * step[1], a[2] + k * step[2]])
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The local coordinate of `side`'s boundary plane.
pub(crate) fn side_plane(side: FaceDirection) -> i32 {
    if side.is_positive() { CHUNK_SIZE as i32 } else { 0 }
}

/// The local axis that runs along a horizontal side (z for ±X, x for ±Z).
pub(crate) fn along_axis(side: FaceDirection) -> usize {
    match side.axis() {
        0 => 2,
        2 => 0,
        _ => 0,
    }
}
