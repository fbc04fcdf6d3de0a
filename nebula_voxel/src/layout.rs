//! Chunk keys and the chunk layout of a planet.
//!
//! ```text
//!   LOD 0 = finest. A chunk at LOD L is 32 × 32 × 32 voxels, each voxel
//!   s = 2^L lattice cells wide and s radial layers tall:
//!
//!      face (u, v)  ── chunks per face edge at LOD L = 2^(max_lod − L)
//!      ┌────┬────┐
//!      │ 0,1│ 1,1│     chunk (x, y) covers lattice cells
//!      ├────┼────┤       i ∈ [x·32s, (x+1)·32s),  j ∈ [y·32s, (y+1)·32s)
//!      │ 0,0│ 1,0│     and radial layer ℓ covers layers
//!      └────┴────┘       h ∈ [ℓ·32s, (ℓ+1)·32s)
//!
//!   Local voxel axes: x = u (i), y = radial (h), z = v (j); see
//!   `nebula_math::face` for why that frame is left-handed in world space.
//! ```

use nebula_math::{CubeFace, Cubesphere, DVec3, FaceEdge, LatticePoint};

use crate::VoxelError;

/// Voxels along each edge of a chunk, at every LOD.
pub const CHUNK_SIZE: u32 = 32;

/// The coarsest LOD any planet may have: 2³⁰ cells per face edge is the
/// limit of `nebula_math`'s lattice, and 32 · 2²⁴ < 2³⁰.
pub const MAX_LOD: u8 = 24;

/// A column of chunks: a quadtree node of one cube face at one LOD.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ChunkColumn {
    /// The cube face.
    pub face: CubeFace,
    /// Level of detail: 0 is the finest.
    pub lod: u8,
    /// Chunk index along the face's u axis.
    pub x: u32,
    /// Chunk index along the face's v axis.
    pub y: u32,
}

/// One chunk: a column and a radial layer of chunks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ChunkKey {
    /// The cube face.
    pub face: CubeFace,
    /// Level of detail: 0 is the finest.
    pub lod: u8,
    /// Chunk index along the face's u axis.
    pub x: u32,
    /// Chunk index along the face's v axis.
    pub y: u32,
    /// Radial layer of chunks; layer 0 starts at the planet's base radius.
    pub layer: i32,
}

impl ChunkKey {
    /// The column this chunk stands in.
    #[must_use]
    pub fn column(self) -> ChunkColumn {
        ChunkColumn { face: self.face, lod: self.lod, x: self.x, y: self.y }
    }
}

impl ChunkColumn {
    /// The chunk of this column in radial layer `layer`.
    #[must_use]
    pub fn chunk(self, layer: i32) -> ChunkKey {
        ChunkKey { face: self.face, lod: self.lod, x: self.x, y: self.y, layer }
    }
}

/// A voxel at some LOD: face, column `(i, j)` and layer `h`, all counted in
/// voxels of that LOD (so `i, j < N / 2^lod`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct VoxelCoord {
    /// The cube face.
    pub face: CubeFace,
    /// Level of detail: 0 is the finest.
    pub lod: u8,
    /// Column index along u.
    pub i: u32,
    /// Column index along v.
    pub j: u32,
    /// Radial index; 0 is the first voxel above the base radius.
    pub h: i32,
}

impl VoxelCoord {
    /// The voxel one LOD coarser that contains this one, or `None` at
    /// [`MAX_LOD`] and beyond.
    #[must_use]
    pub fn parent(self) -> Option<VoxelCoord> {
        (self.lod < MAX_LOD).then(|| VoxelCoord {
            lod: self.lod + 1,
            i: self.i / 2,
            j: self.j / 2,
            h: self.h.div_euclid(2),
            ..self
        })
    }
}

/// How a planet is cut into chunks: its lattice and its number of LODs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChunkLayout {
    sphere: Cubesphere,
    max_lod: u8,
}

impl ChunkLayout {
    /// A layout on `sphere`, whose resolution must be `32 · 2^max_lod`.
    ///
    /// # Errors
    /// [`VoxelError::LodOutOfRange`] if `max_lod > MAX_LOD`;
    /// [`VoxelError::ResolutionMismatch`] if the resolution is not
    /// `32 · 2^max_lod`.
    pub fn new(sphere: Cubesphere, max_lod: u8) -> Result<Self, VoxelError> {
        if max_lod > MAX_LOD {
            return Err(VoxelError::LodOutOfRange { lod: max_lod, max_lod: MAX_LOD });
        }
        let wanted = CHUNK_SIZE << max_lod;
        if sphere.resolution() != wanted {
            return Err(VoxelError::ResolutionMismatch { resolution: sphere.resolution(), expected: wanted });
        }
        Ok(Self { sphere, max_lod })
    }

    /// The planet's lattice geometry.
    #[must_use]
    pub fn sphere(&self) -> &Cubesphere {
        &self.sphere
    }

    /// The coarsest LOD: one chunk column covers a whole face.
    #[must_use]
    pub fn max_lod(&self) -> u8 {
        self.max_lod
    }

    /// Lattice cells (and radial layers) per voxel at `lod`: 2^lod. LODs
    /// past 62 (never a planet's) saturate at 2^62 instead of overflowing.
    #[must_use]
    #[inline]
    pub fn voxel_span(&self, lod: u8) -> i64 {
        1 << lod.min(62)
    }

    /// The edge of a voxel at `lod`, metres (2^lod layer heights): what the
    /// LOD selection projects to the screen. A coarse LOD is drawn where
    /// its voxels subtend at most τ pixels.
    #[must_use]
    pub fn voxel_edge(&self, lod: u8) -> f64 {
        self.sphere.layer_height() * (self.voxel_span(lod) as f64)
    }

    /// The error a chunk at `lod` geomorphs towards: the voxel edge of the
    /// LOD it would merge into. +∞ at the coarsest LOD, which has no parent
    /// and never morphs.
    #[must_use]
    pub fn merge_error(&self, lod: u8) -> f64 {
        if lod >= self.max_lod { f64::INFINITY } else { self.voxel_edge(lod + 1) }
    }

    /// The in-face lattice coordinate that voxel column `c` of `lod`
    /// samples under the far-corner rule (a coarse voxel is the LOD-0 voxel
    /// in its far corner, `ProceduralPlanet`'s module docs): the centre of
    /// that LOD-0 column. One owner, so every source's per-column and
    /// per-row directions agree bit for bit.
    #[must_use]
    pub fn sample_coord(&self, c: i64, lod: u8) -> f64 {
        (c as f64 + 1.0) * self.voxel_span(lod) as f64 - 0.5
    }

    /// The radial layer (fractional, LOD-0 layers) that radial voxel `h`
    /// of `lod` samples under the far-corner rule: the centre of the LOD-0
    /// voxel in its far corner.
    #[must_use]
    pub fn sample_layer(&self, h: i64, lod: u8) -> f64 {
        (h + 1) as f64 * self.voxel_span(lod) as f64 - 0.5
    }

    /// The unit direction voxel column `(ci, cj)` of `lod` on `face`
    /// samples ([`ChunkLayout::sample_coord`]). Columns beyond a face edge
    /// are read on the neighbouring face, in that face's frame; in the gap
    /// beyond two edges (a cube corner) the nearest column on the face
    /// stands in (such voxels are never face neighbours of a chunk's own).
    #[must_use]
    pub fn sample_direction(&self, face: CubeFace, lod: u8, ci: i64, cj: i64) -> DVec3 {
        let (face, ci, cj) = self.sample_cell(face, lod, ci, cj);
        self.sphere.direction(face, self.sample_coord(ci, lod), self.sample_coord(cj, lod))
    }

    /// The face and voxel column of `lod` whose sample
    /// [`ChunkLayout::sample_direction`] reads for column `(ci, cj)` of
    /// `face`: itself on the face, wrapped beyond an edge, the nearest on
    /// the face in a cube corner's gap.
    #[must_use]
    pub fn sample_cell(&self, face: CubeFace, lod: u8, ci: i64, cj: i64) -> (CubeFace, i64, i64) {
        let per_edge = i64::from(self.voxels_per_edge(lod));
        face.wrap_cell(ci, cj, per_edge).unwrap_or((face, ci.clamp(0, per_edge - 1), cj.clamp(0, per_edge - 1)))
    }

    /// Voxel columns along each face edge at `lod`.
    #[must_use]
    pub fn voxels_per_edge(&self, lod: u8) -> u32 {
        self.sphere.resolution() >> lod
    }

    /// Chunk columns along each face edge at `lod`.
    #[must_use]
    pub fn chunks_per_edge(&self, lod: u8) -> u32 {
        1 << (self.max_lod.saturating_sub(lod))
    }

    /// Checks that `lod` exists on this planet.
    ///
    /// # Errors
    /// [`VoxelError::LodOutOfRange`].
    pub fn check_lod(&self, lod: u8) -> Result<(), VoxelError> {
        if lod > self.max_lod { Err(VoxelError::LodOutOfRange { lod, max_lod: self.max_lod }) } else { Ok(()) }
    }

    /// Checks that `key` names a chunk of this planet: LOD in range, column
    /// on the face, and the chunk's top above the planet centre. (A coarse
    /// chunk may reach below the centre: on a small planet one LOD-max chunk
    /// is taller than the radius. Its voxels there are solid and never
    /// meshed.)
    ///
    /// # Errors
    /// [`VoxelError::LodOutOfRange`] or [`VoxelError::ChunkOutOfRange`].
    pub fn check_key(&self, key: ChunkKey) -> Result<(), VoxelError> {
        self.check_lod(key.lod)?;
        let per_edge = self.chunks_per_edge(key.lod);
        if key.x >= per_edge || key.y >= per_edge {
            return Err(VoxelError::ChunkOutOfRange {
                key,
                reason: format!("column ({}, {}) is not below {per_edge} at LOD {}", key.x, key.y, key.lod),
            });
        }
        let bottom = i64::from(key.layer) * i64::from(CHUNK_SIZE) * self.voxel_span(key.lod);
        let top = bottom + i64::from(CHUNK_SIZE) * self.voxel_span(key.lod);
        if self.sphere.layer_radius(top as f64) <= 0.0
            || top > i64::from(i32::MAX / 2)
            || bottom < i64::from(i32::MIN / 2)
        {
            return Err(VoxelError::ChunkOutOfRange {
                key,
                reason: format!("radial layers {bottom}..{top} are below the planet centre or too high"),
            });
        }
        Ok(())
    }

    /// Checks that `at` names a voxel of this planet: LOD and column in
    /// range and a radial index within ±2²⁹ LOD-0 layers.
    ///
    /// # Errors
    /// [`VoxelError::LodOutOfRange`] or [`VoxelError::VoxelOutOfRange`].
    pub fn check_voxel(&self, at: VoxelCoord) -> Result<(), VoxelError> {
        self.check_lod(at.lod)?;
        let per_edge = self.voxels_per_edge(at.lod);
        if at.i >= per_edge || at.j >= per_edge {
            return Err(VoxelError::VoxelOutOfRange { at, reason: format!("column not below {per_edge}") });
        }
        // Voxels below the centre exist (solid) so that every chunk's
        // padding can be read; only the lattice range is limited.
        let bottom = i64::from(at.h) * self.voxel_span(at.lod);
        if bottom.abs() > i64::from(i32::MAX / 4) {
            return Err(VoxelError::VoxelOutOfRange { at, reason: format!("radial layer {bottom} is out of range") });
        }
        Ok(())
    }

    /// The LOD-0 voxel that holds world point `point` (planet centre at the
    /// origin): the cell its direction falls in and the layer its radius
    /// falls in. Points on a cell wall go to the cell above the wall.
    ///
    /// # Errors
    /// [`VoxelError::Math`] for NaN, infinite or centre points,
    /// [`VoxelError::VoxelOutOfRange`] beyond the radial range.
    pub fn voxel_at(&self, point: DVec3) -> Result<VoxelCoord, VoxelError> {
        let (face, fi, fj) = self.sphere.face_coords_of(point)?;
        let last = f64::from(self.voxels_per_edge(0) - 1);
        let h = self.sphere.radius_to_layer(point.length()).floor();
        let at = VoxelCoord {
            face,
            lod: 0,
            i: fi.floor().clamp(0.0, last) as u32,
            j: fj.floor().clamp(0.0, last) as u32,
            h: h.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32,
        };
        self.check_voxel(at)?;
        Ok(at)
    }

    /// The chunk that contains voxel `at` (at the voxel's LOD).
    #[must_use]
    pub fn chunk_of(&self, at: VoxelCoord) -> ChunkKey {
        ChunkKey {
            face: at.face,
            lod: at.lod,
            x: at.i / CHUNK_SIZE,
            y: at.j / CHUNK_SIZE,
            layer: at.h.div_euclid(CHUNK_SIZE as i32),
        }
    }

    /// The same-LOD chunk across `edge` of `key`'s column, on this face or
    /// the neighbouring one. Its `x`/`y` are in the neighbour face's frame.
    #[must_use]
    pub fn neighbor(&self, key: ChunkKey, edge: FaceEdge) -> ChunkKey {
        let (di, dj) = edge.step();
        let per_edge = i64::from(self.chunks_per_edge(key.lod));
        let (face, x, y) = key.face.wrap_cell(i64::from(key.x) + di, i64::from(key.y) + dj, per_edge).unwrap_or((
            key.face,
            i64::from(key.x),
            i64::from(key.y),
        ));
        ChunkKey { face, x: x as u32, y: y as u32, ..key }
    }

    /// The canonical lattice point at local lattice coordinates
    /// `(lx, ly, lz)` (each in `0..=32`, in voxels of the chunk's LOD) of
    /// chunk `key`. `key` must be valid ([`ChunkLayout::check_key`]).
    ///
    /// # Errors
    /// [`VoxelError::Math`] if the point is off the face or below the centre.
    pub fn lattice_point(&self, key: ChunkKey, local: [i64; 3]) -> Result<LatticePoint, VoxelError> {
        let span = self.voxel_span(key.lod);
        let chunk = i64::from(CHUNK_SIZE) * span;
        let i = i64::from(key.x) * chunk + local[0] * span;
        let j = i64::from(key.y) * chunk + local[2] * span;
        let h = i64::from(key.layer) * chunk + local[1] * span;
        Ok(self.sphere.lattice_point(key.face, i, j, h)?)
    }

    /// World position (f64, metres) of the chunk's origin: its lattice corner
    /// with the smallest `(i, j, h)`, or, for a coarse chunk that reaches
    /// below the planet centre, that corner's column at radial layer 0.
    ///
    /// # Errors
    /// As [`ChunkLayout::check_key`].
    pub fn chunk_origin(&self, key: ChunkKey) -> Result<DVec3, VoxelError> {
        self.check_key(key)?;
        let corner = self.lattice_point(key, [0, 0, 0]).or_else(|_| self.column_point(key, 0, 0))?;
        Ok(self.sphere.position(corner))
    }

    /// The lattice point at local column `(lx, lz)` of chunk `key` on radial
    /// layer 0 (always above the centre): for the column's direction.
    ///
    /// # Errors
    /// [`VoxelError::Math`] if the column is off the face.
    pub fn column_point(&self, key: ChunkKey, lx: i64, lz: i64) -> Result<LatticePoint, VoxelError> {
        let span = self.voxel_span(key.lod);
        let chunk = i64::from(CHUNK_SIZE) * span;
        let i = i64::from(key.x) * chunk + lx * span;
        let j = i64::from(key.y) * chunk + lz * span;
        Ok(self.sphere.lattice_point(key.face, i, j, 0)?)
    }
}
