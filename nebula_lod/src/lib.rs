//! Per-face quadtrees of chunks chosen by screen-space error, with neighbour
//! LOD relations across chunk and cube-face edges.
//!
//! [`LodTree`] holds one quadtree per cube face; a node is a
//! [`ChunkColumn`](nebula_voxel::ChunkColumn) (LOD 0 finest, 32³ voxels per
//! chunk at every LOD). Each [`LodTree::update`] splits a leaf whose
//! projected error ρ = δ(L)·K/D exceeds τ (seed `001`; D = distance from
//! the camera to the node's box, which spans the node's surface bounds from
//! the voxel source) and merges a split node once ρ < τ·(1 − hysteresis).
//! δ(L) is the voxel edge at `L` (`ChunkLayout::voxel_edge`): τ is the
//! largest size, in pixels, of a drawn voxel, which is what a player sees
//! of detail (the surface's worst-case distance to LOD 0,
//! `VoxelSource::geometric_error`, sizes the skirts instead). It doubles
//! from one LOD to the next, which the geomorph relies on (`nebula_math`'s
//! `morph_factor`).
//! It reports the leaf chunks added and removed and the leaves whose
//! neighbour relations changed ([`LodChanges`]), so a renderer re-meshes
//! only those. Relations cover chunk edges, cube-face edges and corners and
//! any LOD difference ([`NeighborLodRelation`], [`ChunkLodContext`]);
//! [`BalanceMode::Restricted`] keeps neighbours within one LOD.
//!
//! Choices:
//! - **View-independent tree, view-dependent drawing**: refinement depends
//!   on distance only, so turning the camera never re-meshes; horizon and
//!   frustum culling pick the leaves to draw ([`LodTree::cull`], a walk
//!   from the roots that skips hidden subtrees). Except through a lens
//!   narrower than [`LodSettings::surround_fov_y_degrees`] (60°): such a
//!   view refines its own frustum, opened by a margin
//!   ([`LodTree::focus`]), with its own K and the rest as a 60° view would,
//!   so that a 12° lens holds a third of the nodes or fewer and is drawn
//!   at the τ asked, not one the node budget raised;
//!   turning it past the margin refines the new view.
//!   A culled leaf stays in the tree, so a visible neighbour's seam is never
//!   computed against a missing chunk. That culling is conservative (the
//!   planet-wide lowest bound, hundreds of kilometres deep on an Earth);
//!   [`LodTree::horizon_occluder`] gives the terrain's real horizon, behind
//!   which a renderer draws leaves coarse instead of meshing them, and
//!   [`TerrainHorizon`] the ground's horizon bearing by bearing, made of
//!   the floors of the leaves in front (a far plain behind its own
//!   horizon, a valley behind a ridge).
//! - **Incremental by distance margins**: a node's decision can only flip
//!   after the camera has travelled its margin to the split or merge
//!   distance, so only due nodes are evaluated (see `tree` docs);
//!   [`LodTree::update_full`] evaluates everything and must agree (tested
//!   along random camera paths). `cargo bench -p nebula_lod` compares them.
//!
//! ```
//! use nebula_lod::{Camera, LodSettings, LodTree};
//! use nebula_math::DVec3;
//! use nebula_voxel::{PlanetSettings, ProceduralPlanet};
//!
//! let planet = ProceduralPlanet::new(PlanetSettings::small(1))?;
//! let settings = LodSettings { threshold_px: 8.0, ..LodSettings::default() };
//! let mut tree = LodTree::new(&planet, settings)?;
//! let eye = DVec3::new(0.0, 0.0, 2_300.0);
//! let camera = Camera { position: eye, forward: -eye, up: DVec3::X, aspect: 1.5 };
//! let changes = tree.update(&planet, &camera)?;
//! assert!(!changes.added.is_empty());
//! tree.cull(&camera)?;
//! // The finest leaves are right under the camera.
//! let finest = tree.leaves().into_iter().min_by_key(|c| c.lod).unwrap();
//! assert_eq!(finest.face, nebula_voxel::CubeFace::PosZ);
//! assert!(tree.stats().visible_leaves < tree.stats().leaves);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod bounds;
mod occlusion;
mod relation;
mod settings;
mod tree;

pub use bounds::{CullMargin, Frustum, Horizon, NodeBounds};
pub use nebula_math::FaceDirection;
pub use occlusion::{Clearance, TerrainHorizon};
pub use relation::{ChunkLodContext, NeighborLodRelation};
pub use settings::{BalanceMode, Camera, LodError, LodSettings};
pub use tree::{Cull, LodChanges, LodStats, LodTree, children, cull_reaches, parent};

#[cfg(test)]
mod tests;
