//! The error type of `nebula_meshing`.

use nebula_math::{FaceDirection, MathError};
use nebula_voxel::VoxelError;

/// Bad input to the mesher or a seam operation.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The voxel source refused the chunk (bad key, …).
    #[error(transparent)]
    Voxel(#[from] VoxelError),
    /// A lattice point off the planet (a chunk below the planet centre).
    #[error(transparent)]
    Math(#[from] MathError),
    /// A LOD difference of 0, or one that reaches past the planet's coarsest
    /// LOD.
    #[error("lod_diff {lod_diff} is out of range for a chunk at LOD {lod}: it must be in 1..={max}")]
    LodDiffOutOfRange {
        /// The chunk's LOD.
        lod: u8,
        /// The difference asked for.
        lod_diff: u8,
        /// The largest difference possible from this chunk (max LOD − LOD).
        max: u8,
    },
    /// Constraining or skirting was asked for a radial side (±Y): radial
    /// neighbours always share the chunk's LOD.
    #[error("side {side:?} is radial: chunks above and below always share the LOD")]
    RadialSide {
        /// The side given.
        side: FaceDirection,
    },
    /// A skirt depth that is negative, NaN or infinite.
    #[error("skirt depth must be finite and >= 0, got {depth}")]
    BadSkirtDepth {
        /// The depth given.
        depth: f32,
    },
    /// A NaN or infinite planet centre.
    #[error("planet centre must be finite, got {center:?}")]
    BadPlanetCenter {
        /// The centre given.
        center: [f32; 3],
    },
    /// A [`ChunkLodContext`](crate::ChunkLodContext) whose LOD is not the
    /// chunk's, or that claims a radial neighbour of another LOD.
    #[error("LOD context does not fit chunk at LOD {chunk_lod}: {reason}")]
    ContextMismatch {
        /// The chunk's LOD.
        chunk_lod: u8,
        /// What is wrong.
        reason: String,
    },
}
