//! The error type of `nebula_voxel`.

use nebula_math::MathError;

use crate::{ChunkKey, VoxelCoord};

/// Bad input to a `nebula_voxel` constructor, query or edit.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum VoxelError {
    /// Bad planet geometry (radius, resolution, …).
    #[error(transparent)]
    Math(#[from] MathError),
    /// A LOD beyond the planet's coarsest level.
    #[error("LOD {lod} is out of range: this planet's LODs are 0..={max_lod}")]
    LodOutOfRange {
        /// The LOD asked for.
        lod: u8,
        /// The coarsest LOD of the planet.
        max_lod: u8,
    },
    /// A lattice resolution that does not give 32-voxel chunks at the
    /// requested LOD count.
    #[error("lattice resolution {resolution} does not match the LOD count: it must be 32 · 2^max_lod = {expected}")]
    ResolutionMismatch {
        /// The sphere's resolution.
        resolution: u32,
        /// 32 · 2^max_lod.
        expected: u32,
    },
    /// Chunk coordinates outside the face at the key's LOD, or a radial
    /// layer at or below the planet centre.
    #[error("chunk {key:?} is out of range: {reason}")]
    ChunkOutOfRange {
        /// The key given.
        key: ChunkKey,
        /// What is wrong with it.
        reason: String,
    },
    /// Voxel coordinates outside the face, or below the planet centre.
    #[error("voxel {at:?} is out of range: {reason}")]
    VoxelOutOfRange {
        /// The coordinates given.
        at: VoxelCoord,
        /// What is wrong with them.
        reason: String,
    },
    /// A voxel array of the wrong length.
    #[error("a padded chunk holds {expected} voxels (34³), got {got}")]
    WrongVoxelCount {
        /// 34³ = 39,304.
        expected: usize,
        /// The length given.
        got: usize,
    },
    /// A NaN or infinite planet parameter.
    #[error("{name} must be finite, got {value}")]
    NonFinite {
        /// Which parameter.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A planet parameter that must be positive (or non-negative) was not.
    #[error("{name} must be {requirement}, got {value}")]
    OutOfRange {
        /// Which parameter.
        name: &'static str,
        /// What it must be.
        requirement: &'static str,
        /// The value given.
        value: f64,
    },
}
