//! Per-face quadtrees of chunks chosen by screen-space error, with neighbour
//! LOD relations across chunk and cube-face edges.
//!
//! This crate so far holds the vocabulary the mesher and the quadtree share:
//! [`NeighborLodRelation`] and [`ChunkLodContext`] (seam spec `003`). The
//! quadtree itself lands with its own issue.
//!
//! ```
//! use nebula_lod::{ChunkLodContext, FaceDirection, NeighborLodRelation};
//!
//! let mut context = ChunkLodContext::uniform(2);
//! context.set(FaceDirection::PosX, NeighborLodRelation::HigherThanNeighbor { lod_diff: 1 });
//! assert_eq!(context.coarser_neighbor_diff(FaceDirection::PosX), Some(1));
//! assert!(context.needs_skirt(FaceDirection::PosX));
//! assert!(!context.needs_skirt(FaceDirection::NegZ));
//! ```

mod relation;

pub use nebula_math::FaceDirection;
pub use relation::{ChunkLodContext, NeighborLodRelation};
