//! The error type of `nebula_math`.

use crate::CubeFace;

/// Bad input to a `nebula_math` constructor or query.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MathError {
    /// A number that must be finite was NaN or infinite.
    #[error("{name} must be finite, got {value}")]
    NonFinite {
        /// Which parameter.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A number that must be strictly positive was not.
    #[error("{name} must be > 0, got {value}")]
    NotPositive {
        /// Which parameter.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A field of view outside the open interval (0°, 180°).
    #[error("vertical field of view must be in (0, 180) degrees, got {degrees}")]
    FovOutOfRange {
        /// The field of view given, in degrees.
        degrees: f64,
    },
    /// A lattice resolution that is odd, zero or too large.
    #[error("lattice resolution must be even and in [2, {max}], got {got}")]
    BadResolution {
        /// The resolution given.
        got: u64,
        /// The largest resolution supported.
        max: u64,
    },
    /// Lattice coordinates outside the face.
    #[error("lattice point ({i}, {j}) is outside face {face:?} of resolution {resolution}")]
    OutsideFace {
        /// The face asked for.
        face: CubeFace,
        /// First in-face coordinate.
        i: i64,
        /// Second in-face coordinate.
        j: i64,
        /// The lattice resolution.
        resolution: u32,
    },
    /// A radial layer at or below the planet centre.
    #[error("radial layer {layer} lies at radius {radius} m, not above the planet centre")]
    LayerBelowCentre {
        /// The layer given.
        layer: i64,
        /// The radius it would have.
        radius: f64,
    },
}

/// Checks that `value` is finite.
pub(crate) fn finite(name: &'static str, value: f64) -> Result<f64, MathError> {
    if value.is_finite() { Ok(value) } else { Err(MathError::NonFinite { name, value }) }
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<f64, MathError> {
    if finite(name, value)? > 0.0 { Ok(value) } else { Err(MathError::NotPositive { name, value }) }
}
