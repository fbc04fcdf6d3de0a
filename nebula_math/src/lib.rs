//! Cubesphere math for Nebula: cube faces and their edges, the canonical
//! lattice-to-world map, and screen-space-error math.
//!
//! A Nebula planet is a cube whose six faces are split into an `N × N`
//! lattice and projected onto a sphere. Every vertex is first an integer
//! [`LatticePoint`] (cube coordinates + radial layer); [`Cubesphere::position`]
//! is the *only* function that turns one into an f64 world position, and it
//! reads nothing but the integers, so chunks and faces that share a point
//! agree bit for bit. Planet-scale numbers are f64; only offsets from a
//! nearby origin ([`relative_position`]) become f32.
//!
//! Choices:
//! - **Equi-angular map** ([`SphereMap::EquiAngular`]): largest/smallest cell
//!   area 1.41 against 5.16 for the plain normalised cube, cells no more
//!   than 1.41× longer than wide (measured by
//!   [`area_distortion`]; `cargo test -p nebula_math area_distortion --
//!   --nocapture` prints it). Costs one `tan` per component.
//! - **Integer topology, f64 geometry**: faces, edges and corners are types
//!   ([`CubeFace`], [`FaceEdge`], [`CubeCorner`]); crossing an edge is an exact
//!   integer fold ([`CubeFace::wrap_point`]).
//! - **SSE** per seed `001`: K = Res/(2·tan(fov/2)); for 1024 px and 12° that
//!   is 4871.35 px/rad, 17.9 px/rad (0.37 %) below the seed's small-angle
//!   4889.2 ([`ScreenSpace`]).
//!
//! Conventions (face frames, handedness, chunk axes) live in [`face`].
//!
//! ```
//! use nebula_math::{CubeFace, Cubesphere, SphereMap};
//!
//! // A 1 km planet, 1024 cells per face edge, 1.5 m radial layers.
//! let planet = Cubesphere::new(1000.0, 1024, 1.5, SphereMap::EquiAngular)?;
//!
//! // The corner shared by +X, +Y and +Z, asked from each of its faces.
//! let from_x = planet.lattice_point(CubeFace::PosX, 1024, 1024, 2)?;
//! let from_y = planet.lattice_point(CubeFace::PosY, 1024, 1024, 2)?;
//! let from_z = planet.lattice_point(CubeFace::PosZ, 1024, 1024, 2)?;
//! assert_eq!(from_x, from_y);
//! assert_eq!(planet.position(from_x), planet.position(from_z));
//! // Layer 2 is 3 m above the 1 km radius.
//! assert!((planet.position(from_x).length() - 1003.0).abs() < 1e-9);
//! # Ok::<(), nebula_math::MathError>(())
//! ```

pub mod face;

mod error;
mod lattice;
mod sphere_map;
mod sse;

pub use error::MathError;
pub use face::{CubeCorner, CubeFace, EdgeNeighbor, FaceDirection, FaceEdge};
pub use glam::{DQuat, DVec3, I64Vec3, IVec3, Vec3};
pub use lattice::{Cubesphere, LatticePoint, MAX_RESOLUTION, ray_sphere, relative_position, view_basis};
pub use sphere_map::{SphereMap, area_distortion};

/// The next number in [0, 1) of a fixed xorshift64 sequence: sample
/// places that must not depend on any seed (slope sampling, test poses), the
/// same on every machine.
#[must_use]
pub fn unit_random(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64
}
pub use sse::{
    MORPH_FULL, ScreenSpace, horizon_distance, morph_factor, projection_constant, projection_constant_small_angle,
};

#[cfg(test)]
mod tests;
