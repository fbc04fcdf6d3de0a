//! The padded voxel array of one chunk.

use ndshape::{ConstShape, ConstShape3u32};

use crate::{CHUNK_SIZE, ChunkKey, Voxel, VoxelError};

/// Voxels along each edge of a padded chunk: 32 plus one layer of padding on
/// each side, read from the neighbours so the mesher can see across.
pub const PADDED_CHUNK_SIZE: u32 = CHUNK_SIZE + 2;

/// The shape of a padded chunk as block-mesh expects it: index
/// `x + 34·y + 34²·z` (x fastest), with x = u, y = radial, z = v.
pub type PaddedChunkShape = ConstShape3u32<PADDED_CHUNK_SIZE, PADDED_CHUNK_SIZE, PADDED_CHUNK_SIZE>;

/// Voxels in a padded chunk: 34³ = 39,304.
pub const PADDED_CHUNK_VOLUME: usize = PaddedChunkShape::USIZE;

/// The voxels of one chunk plus a one-voxel padding layer, in
/// [`PaddedChunkShape`] order. Padded coordinates run `0..34`; the chunk's own
/// voxel `(x, y, z)` sits at padded `(x + 1, y + 1, z + 1)`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChunkVoxels {
    key: ChunkKey,
    voxels: Box<[Voxel]>,
}

impl ChunkVoxels {
    /// An all-air chunk for `key` (fill it with
    /// [`VoxelSource::fill_chunk`](crate::VoxelSource::fill_chunk)).
    #[must_use]
    pub fn new(key: ChunkKey) -> Self {
        Self { key, voxels: vec![Voxel::AIR; PADDED_CHUNK_VOLUME].into_boxed_slice() }
    }

    /// Wraps a caller-made voxel array.
    ///
    /// # Errors
    /// [`VoxelError::WrongVoxelCount`] unless `voxels.len()` is 34³.
    pub fn from_voxels(key: ChunkKey, voxels: Vec<Voxel>) -> Result<Self, VoxelError> {
        if voxels.len() != PADDED_CHUNK_VOLUME {
            return Err(VoxelError::WrongVoxelCount { expected: PADDED_CHUNK_VOLUME, got: voxels.len() });
        }
        Ok(Self { key, voxels: voxels.into_boxed_slice() })
    }

    /// The chunk these voxels belong to.
    #[must_use]
    pub fn key(&self) -> ChunkKey {
        self.key
    }

    /// Re-labels the buffer for another chunk (contents unchanged), so one
    /// allocation can be reused across chunks.
    pub fn set_key(&mut self, key: ChunkKey) {
        self.key = key;
    }

    /// All voxels in [`PaddedChunkShape`] order (what block-mesh takes).
    #[must_use]
    pub fn as_slice(&self) -> &[Voxel] {
        &self.voxels
    }

    /// All voxels, mutable, in [`PaddedChunkShape`] order.
    #[must_use]
    pub fn as_mut_slice(&mut self) -> &mut [Voxel] {
        &mut self.voxels
    }

    /// The voxel at padded coordinates `[x, y, z]` (each `0..34`), or `None`
    /// outside the padded chunk.
    #[must_use]
    pub fn get(&self, padded: [u32; 3]) -> Option<Voxel> {
        padded.iter().all(|&c| c < PADDED_CHUNK_SIZE).then(|| self.voxels[PaddedChunkShape::linearize(padded) as usize])
    }

    /// Sets the voxel at padded coordinates `[x, y, z]` (each `0..34`).
    /// Returns `false`, changing nothing, outside the padded chunk.
    pub fn set(&mut self, padded: [u32; 3], voxel: Voxel) -> bool {
        if padded.iter().all(|&c| c < PADDED_CHUNK_SIZE) {
            self.voxels[PaddedChunkShape::linearize(padded) as usize] = voxel;
            true
        } else {
            false
        }
    }

    /// Solid voxels inside the chunk proper (padding excluded).
    #[must_use]
    pub fn solid_count(&self) -> usize {
        let mut count = 0;
        for z in 1..=CHUNK_SIZE {
            for y in 1..=CHUNK_SIZE {
                let row = PaddedChunkShape::linearize([1, y, z]) as usize;
                count += self.voxels[row..row + CHUNK_SIZE as usize].iter().filter(|v| v.is_solid()).count();
            }
        }
        count
    }

    /// Whether meshing can be skipped: the chunk proper is all air, or all
    /// solid with solid padding on all six sides (no visible face).
    #[must_use]
    pub fn has_no_surface(&self) -> bool {
        let first = self.voxels[PaddedChunkShape::linearize([1, 1, 1]) as usize].is_solid();
        if !first {
            return self.solid_count() == 0;
        }
        // All solid, including every face-adjacent padding voxel (edge and
        // corner padding is never a face neighbour of the chunk proper).
        (0..PADDED_CHUNK_SIZE).all(|z| {
            (0..PADDED_CHUNK_SIZE).all(|y| {
                (0..PADDED_CHUNK_SIZE).all(|x| {
                    let outside = [x, y, z].iter().filter(|&&c| c == 0 || c == PADDED_CHUNK_SIZE - 1).count();
                    outside > 1 || self.voxels[PaddedChunkShape::linearize([x, y, z]) as usize].is_solid()
                })
            })
        })
    }
}
