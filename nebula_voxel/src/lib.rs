//! Voxel chunks of a cubesphere planet: keys, padded arrays, a seeded
//! procedural planet, LOD sampling and edits.
//!
//! Every chunk is 32³ voxels at every LOD (a voxel at LOD `L` is `2^L` lattice
//! cells wide and tall) and is handed out as a 34³ [`ChunkVoxels`] array: the
//! chunk plus one voxel of padding read from its neighbours, across chunk and
//! cube-face edges, in the index order block-mesh takes
//! ([`PaddedChunkShape`]).
//!
//! Choices:
//! - **LODs by the far-corner rule**: a coarse voxel *is* the LOD-0 voxel in
//!   its far corner (see [`ProceduralPlanet`]), so a finer chunk collapsed
//!   by the geomorph (coordinates rounded down to even) is its parent:
//!   exactly with every octave at every LOD, and but for the octaves a
//!   band-limited LOD leaves out in the presets
//!   ([`PlanetSettings::band_limit`]). Any LOD is generated directly at
//!   the same cost per chunk; the error bound
//!   δ(L) = (s + min(2·S·(s − 1) + dropped(L), relief)) layers (s = 2^L,
//!   S = steepest slope, measured by sampling; dropped(L) what the
//!   octaves left out can move H) is derived and tested in
//!   [`ProceduralPlanet`]'s docs.
//! - **Caves** under the ground of the procedural planet: two networks of
//!   winding tunnels (the shallow one opening at the surface in cave
//!   mouths, arches and overhangs; the deep one swelling into chambers),
//!   above the sea, regional; `PlanetSettings::cave_size` (0: none). A
//!   coarse voxel is cave only in a tunnel's core, so thin tunnels vanish
//!   at coarse LODs instead of leaving a speckle of holes (`caves.rs`).
//! - **Edits as an overlay** ([`EditedSource`]) on any [`VoxelSource`]: LOD-0
//!   voxels, seen by coarse LODs through the same far-corner rule, so
//!   nothing is lost when chunks are regenerated.
//! - **Picking** ([`pick`]) walks a ray voxel by voxel through the exact
//!   cell walls (planes through the centre and spheres), skipping chunk
//!   columns whose surface bounds the ray stays above.
//! - **Noise**: the `noise` crate's fBm and ridged multifractal, evaluated
//!   on the sphere so terrain is seamless across faces, over our own
//!   branch-free Perlin kernel that returns the `noise` crate's values
//!   (2.3× faster where samples are far apart; see `perlin.rs`). Octaves
//!   many voxels long are read from grids on the face lattice instead of
//!   at every column (`octave_grid.rs`, `PlanetSettings::octave_grid`; 0
//!   for the exact noise of planets saved before), the same at every LOD;
//!   the continents' longest from grids hundreds of columns apart, as
//!   far as an error budget allows (`PlanetSettings::octave_grid_error`),
//!   so coarse chunks do not sum them at every column.
//!   Heights are computed once per chunk column and shared by its radial
//!   layers.
//!
//! Generation speed: `cargo bench -p nebula_voxel` (figures in the bench
//! file's header).
//!
//! ```
//! use nebula_voxel::{ChunkVoxels, PlanetSettings, ProceduralPlanet, VoxelSource};
//!
//! let planet = ProceduralPlanet::new(PlanetSettings::small(7))?;
//! let layout = planet.layout();
//! // The chunk column at the middle of face +Y, LOD 2, in the layers that
//! // hold the surface.
//! let column = nebula_voxel::ChunkColumn {
//!     face: nebula_voxel::CubeFace::PosY,
//!     lod: 2,
//!     x: layout.chunks_per_edge(2) / 2,
//!     y: layout.chunks_per_edge(2) / 2,
//! };
//! let mut voxels = ChunkVoxels::new(column.chunk(0));
//! let mut solid = 0;
//! for layer in planet.surface_chunk_layers(column)? {
//!     planet.fill_chunk(column.chunk(layer), &mut voxels)?;
//!     solid += voxels.solid_count();
//! }
//! // Some ground, some sky.
//! assert!(solid > 0 && solid < 32 * 32 * 32 * 4);
//! # Ok::<(), nebula_voxel::VoxelError>(())
//! ```

mod caves;
mod chunk;
mod edits;
mod error;
mod layout;
mod octave_grid;
mod perlin;
mod pick;
mod planet;
mod source;
mod voxel;

pub use chunk::{ChunkVoxels, PADDED_CHUNK_SIZE, PADDED_CHUNK_VOLUME, PADDED_COLUMNS, PADDED_ROWS, PaddedChunkShape};
pub use edits::EditedSource;
pub use error::VoxelError;
pub use layout::{CHUNK_SIZE, ChunkColumn, ChunkKey, ChunkLayout, MAX_LOD, VoxelCoord};
pub use nebula_math::{CubeFace, DVec3, FaceDirection, FaceEdge};
pub use pick::{VoxelHit, pick};
pub use planet::{PlanetSettings, ProceduralPlanet};
pub use source::{LayerView, SurfaceBounds, SurfaceSurvey, VoxelSource};
pub use voxel::Voxel;

#[cfg(test)]
mod tests;
