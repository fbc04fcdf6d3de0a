//! Greedy quads → T-junction-free triangles on the sphere.
//!
//! ```text
//!   block-mesh gives rectangles (greedy quads) in lattice space. On the
//!   sphere each is curved, so a vertex of a neighbouring quad that lies on
//!   a rectangle's edge would float off that edge's chord (a T-junction that
//!   leaks light). Every such vertex becomes part of the rectangle's
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
//! Which lattice points are on a rectangle's edge is decided in integers:
//! the corners of every quad in the chunk, plus, on the chunk's boundary
//! planes, *every* lattice point along the edge. The latter makes the
//! boundary vertex set a function of the edge alone, so two chunks that
//! greedy-merge differently still put the same vertices on their shared
//! boundary.

use block_mesh::{GreedyQuadsBuffer, RIGHT_HANDED_Y_UP_CONFIG, greedy_quads};
use nebula_math::{DVec3, FaceDirection, Vec3};
use nebula_voxel::{CHUNK_SIZE, ChunkKey, ChunkLayout, ChunkVoxels, PADDED_CHUNK_VOLUME, PaddedChunkShape};

use crate::MeshError;
use crate::mesh::{ChunkMesh, VertexSource};

/// Lattice points per axis of a chunk: 0..=32.
const POINTS: usize = CHUNK_SIZE as usize + 1;

/// Reusable scratch memory for greedy meshing one chunk after another.
pub struct ChunkMesher {
    greedy: GreedyQuadsBuffer,
    /// Per lattice point: equal to `stamp` when some quad has a corner there.
    corner_stamp: Vec<u32>,
    /// Per (lattice point, side): `(stamp, vertex index)`.
    vertex_slot: Vec<(u32, u32)>,
    /// Per lattice column (x, z): `(stamp, unit direction)`.
    column_direction: Vec<(u32, DVec3)>,
    /// Per lattice point: `(stamp, world position)`.
    point_world: Vec<(u32, DVec3)>,
    /// Per side-wall plane (x planes then z planes): `(stamp, unit normal
    /// towards growing coordinate)`.
    wall_normal: Vec<(u32, DVec3)>,
    stamp: u32,
    chain_a: Vec<[i32; 3]>,
    chain_b: Vec<[i32; 3]>,
    index_a: Vec<u32>,
    index_b: Vec<u32>,
}

impl Default for ChunkMesher {
    fn default() -> Self {
        Self::new()
    }
}

impl ChunkMesher {
    /// Scratch memory for one thread (about 2.5 MB).
    #[must_use]
    pub fn new() -> Self {
        Self {
            greedy: GreedyQuadsBuffer::new(PADDED_CHUNK_VOLUME),
            corner_stamp: vec![0; POINTS * POINTS * POINTS],
            vertex_slot: vec![(0, 0); POINTS * POINTS * POINTS * 6],
            column_direction: vec![(0, DVec3::ZERO); POINTS * POINTS],
            point_world: vec![(0, DVec3::ZERO); POINTS * POINTS * POINTS],
            wall_normal: vec![(0, DVec3::ZERO); 2 * POINTS],
            stamp: 0,
            chain_a: Vec::new(),
            chain_b: Vec::new(),
            index_a: Vec::new(),
            index_b: Vec::new(),
        }
    }

    /// The surface mesh of `voxels` (no constraining, no skirts), placed on
    /// the sphere of `layout`.
    ///
    /// # Errors
    /// [`MeshError`] if the chunk key is not on the planet.
    pub fn mesh(&mut self, voxels: &ChunkVoxels, layout: &ChunkLayout) -> Result<ChunkMesh, MeshError> {
        let key = voxels.key();
        let origin = layout.chunk_origin(key)?;
        let mut mesh = ChunkMesh::empty(key, *layout, origin);
        self.mesh_into(voxels, layout, &mut mesh)?;
        Ok(mesh)
    }

    /// How many greedy quads the last [`ChunkMesher::mesh`] call made.
    #[must_use]
    pub fn quad_count(&self) -> usize {
        self.greedy.quads.num_quads()
    }

    fn next_stamp(&mut self) -> u32 {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // Wrapped: forget every old stamp.
            self.corner_stamp.fill(0);
            self.vertex_slot.fill((0, 0));
            self.column_direction.fill((0, DVec3::ZERO));
            self.point_world.fill((0, DVec3::ZERO));
            self.wall_normal.fill((0, DVec3::ZERO));
            self.stamp = 1;
        }
        self.stamp
    }

    fn mesh_into(&mut self, voxels: &ChunkVoxels, layout: &ChunkLayout, mesh: &mut ChunkMesh) -> Result<(), MeshError> {
        let faces = &RIGHT_HANDED_Y_UP_CONFIG.faces;
        let last = CHUNK_SIZE + 1;
        greedy_quads(voxels.as_slice(), &PaddedChunkShape {}, [0; 3], [last; 3], faces, &mut self.greedy);
        let stamp = self.next_stamp();
        for (group, face) in self.greedy.quads.groups.iter().zip(faces) {
            for quad in group {
                for corner in face.quad_corners(quad) {
                    let local = corner.to_array().map(|c| c as i32 - 1);
                    self.corner_stamp[point_index(local)] = stamp;
                }
            }
        }
        let quads = self.greedy.quads.num_quads();
        // A quad has 4 corners and 2 triangles before T-junction repair.
        mesh.vertices.reserve(4 * quads);
        mesh.world.reserve(4 * quads);
        mesh.morph_world.reserve(4 * quads);
        mesh.sources.reserve(4 * quads);
        mesh.indices.reserve(8 * quads);
        let groups = std::mem::take(&mut self.greedy.quads.groups);
        let mut result = Ok(());
        'faces: for (group, face) in groups.iter().zip(faces) {
            let normal = face.signed_normal().to_array();
            let side = side_of(normal);
            for quad in group {
                let corners = face.quad_corners(quad).map(|c| c.to_array().map(|v| v as i32 - 1));
                let material = voxels.get(quad.minimum).map_or(0, |v| v.material());
                if let Err(error) = self.triangulate(corners, normal, side, u16::from(material), layout, mesh) {
                    result = Err(error);
                    break 'faces;
                }
            }
        }
        self.greedy.quads.groups = groups;
        mesh.surface_index_count = mesh.indices.len();
        result
    }

    /// Triangulates one greedy quad with every lattice vertex on its edges.
    fn triangulate(
        &mut self,
        corners: [[i32; 3]; 4],
        normal: [i32; 3],
        side: FaceDirection,
        material: u16,
        layout: &ChunkLayout,
        mesh: &mut ChunkMesh,
    ) -> Result<(), MeshError> {
        // block-mesh order: 0 = (min u, min v), 1 = (max u, min v),
        // 2 = (min u, max v), 3 = (max u, max v).
        let [bl, br, tl, tr] = corners;
        let (mut chain_a, mut chain_b) = (std::mem::take(&mut self.chain_a), std::mem::take(&mut self.chain_b));
        chain_a.clear();
        chain_b.clear();
        // A: tl → bl → br; B: tl → tr → br.
        self.walk_edge(tl, bl, &mut chain_a);
        self.walk_edge(bl, br, &mut chain_a);
        chain_a.push(br);
        self.walk_edge(tl, tr, &mut chain_b);
        self.walk_edge(tr, br, &mut chain_b);
        chain_b.push(br);

        // Resolve every chain point to its vertex once.
        let (mut index_a, mut index_b) = (std::mem::take(&mut self.index_a), std::mem::take(&mut self.index_b));
        index_a.clear();
        index_b.clear();
        let mut result = Ok(());
        for (chain, indices) in [(&chain_a, &mut index_a), (&chain_b, &mut index_b)] {
            for &point in chain.iter() {
                match self.vertex(point, side, material, layout, mesh) {
                    Ok(index) => indices.push(index),
                    Err(error) => result = Err(error),
                }
            }
        }
        if result.is_ok() {
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
        }
        self.chain_a = chain_a;
        self.chain_b = chain_b;
        self.index_a = index_a;
        self.index_b = index_b;
        result
    }

    /// Pushes `from` and every vertex strictly between `from` and `to` (not
    /// `to` itself) onto `chain`.
    fn walk_edge(&self, from: [i32; 3], to: [i32; 3], chain: &mut Vec<[i32; 3]>) {
        chain.push(from);
        let axis = (0..3).find(|&k| from[k] != to[k]).unwrap_or(0);
        let step = (to[axis] - from[axis]).signum();
        // An edge lying in a chunk boundary plane takes every lattice point.
        let on_boundary = (0..3).any(|k| k != axis && (from[k] == 0 || from[k] == CHUNK_SIZE as i32));
        let mut point = from;
        point[axis] += step;
        while point[axis] != to[axis] {
            if on_boundary || self.corner_stamp[point_index(point)] == self.stamp {
                chain.push(point);
            }
            point[axis] += step;
        }
    }

    /// The vertex for lattice point `local` on a face looking towards
    /// `side`, made on first use.
    fn vertex(
        &mut self,
        local: [i32; 3],
        side: FaceDirection,
        material: u16,
        layout: &ChunkLayout,
        mesh: &mut ChunkMesh,
    ) -> Result<u32, MeshError> {
        let slot = point_index(local) * 6 + side as usize;
        if self.vertex_slot[slot].0 == self.stamp {
            return Ok(self.vertex_slot[slot].1);
        }
        let key = mesh.key;
        let world = self.world_position(key, layout, local)?;
        let even = local.map(|c| c - c.rem_euclid(2));
        let morph = self.world_position(key, layout, even)?;
        let normal = self.normal(key, layout, local, side, world);
        let index = mesh.push_vertex(world, morph, normal, material, 0, VertexSource::Surface { local, side });
        self.vertex_slot[slot] = (self.stamp, index);
        Ok(index)
    }

    /// The canonical world position of local lattice point `local`: the
    /// column's direction is computed once per chunk, each point once.
    fn world_position(&mut self, key: ChunkKey, layout: &ChunkLayout, local: [i32; 3]) -> Result<DVec3, MeshError> {
        let index = point_index(local);
        if self.point_world[index].0 == self.stamp {
            return Ok(self.point_world[index].1);
        }
        let sphere = layout.sphere();
        let column = local[0] as usize * POINTS + local[2] as usize;
        if self.column_direction[column].0 != self.stamp {
            // Layer 0 names the column even when the chunk's bottom lies below
            // the planet centre (the coarsest chunks of a planet do).
            let point = layout.column_point(key, i64::from(local[0]), i64::from(local[2]))?;
            self.column_direction[column] = (self.stamp, sphere.column_direction(point));
        }
        // The point's radial layer, exactly as `ChunkLayout::lattice_point`
        // counts it (the chunk key is valid, so it fits).
        let span = layout.voxel_span(key.lod);
        let layer = (i64::from(key.layer) * i64::from(CHUNK_SIZE) + i64::from(local[1])) * span;
        let world = sphere.position_on_column(self.column_direction[column].1, layer as i32);
        self.point_world[index] = (self.stamp, world);
        Ok(world)
    }

    /// The exact normal of a voxel face looking towards `side` at `local`:
    /// radial for top and bottom faces, the normal of the lattice plane
    /// through the planet centre for side walls (see
    /// `Cubesphere::lattice_plane_normal`). A function of the lattice point
    /// alone, so neighbouring chunks agree.
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
            let span = layout.voxel_span(key.lod);
            let chunk = i64::from(CHUNK_SIZE) * span;
            let (along_u, first) = if axis == 0 { (true, key.x) } else { (false, key.y) };
            let coord = i64::from(first) * chunk + i64::from(local[axis]) * span;
            self.wall_normal[slot] = (self.stamp, layout.sphere().lattice_plane_normal(key.face, along_u, coord));
        }
        (self.wall_normal[slot].1 * sign).as_vec3()
    }
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
