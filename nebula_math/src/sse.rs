//! Screen-space error (SSE), LOD transition distances and geomorph factors
//! (seed `001`).
//!
//! ```text
//!   K = Res_y / (2·tan(fov_y/2))      pixels per radian at the screen centre
//!   ρ = δ·K / D                       projected error in pixels of a chunk with
//!                                     geometric error δ seen from distance D
//!   D_τ = δ·K / τ                     distance at which ρ reaches the threshold τ
//!   μ = smoothstep(clamp((ρ/τ − 0.5) / 0.5, 0, 1))
//!                                     morph factor: 0 where the coarse level is
//!                                     good enough, 1 where the fine one is needed
//! ```

use crate::error::{MathError, finite, positive};

/// Camera and threshold constants for screen-space error, checked once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenSpace {
    k: f64,
    threshold_px: f64,
}

impl ScreenSpace {
    /// Constants for a viewport `screen_height_px` pixels tall with a vertical
    /// field of view of `fov_y_degrees` and an error threshold of
    /// `threshold_px` pixels (τ; 1.0 is the usual choice).
    ///
    /// # Errors
    /// [`MathError`] for NaN or infinite values, a non-positive height or
    /// threshold, or a field of view outside (0°, 180°).
    pub fn new(screen_height_px: f64, fov_y_degrees: f64, threshold_px: f64) -> Result<Self, MathError> {
        let k = projection_constant(screen_height_px, fov_y_degrees)?;
        let threshold_px = positive("SSE threshold", threshold_px)?;
        Ok(Self { k, threshold_px })
    }

    /// The projection constant K in pixels per radian.
    #[must_use]
    pub fn k(&self) -> f64 {
        self.k
    }

    /// The error threshold τ in pixels.
    #[must_use]
    pub fn threshold_px(&self) -> f64 {
        self.threshold_px
    }

    /// Projected error ρ = δ·K / D in pixels. A distance of zero (or less)
    /// gives +∞: the camera touches the chunk.
    #[must_use]
    pub fn projected_error(&self, geometric_error: f64, distance: f64) -> f64 {
        if distance <= 0.0 { f64::INFINITY } else { geometric_error * self.k / distance }
    }

    /// Distance D = δ·K / τ below which a chunk with geometric error δ must
    /// be refined.
    #[must_use]
    pub fn transition_distance(&self, geometric_error: f64) -> f64 {
        geometric_error * self.k / self.threshold_px
    }

    /// Geomorph factor μ in [0, 1] for a vertex with geometric error δ at
    /// distance D: see [`morph_factor`].
    #[must_use]
    pub fn morph_factor(&self, geometric_error: f64, distance: f64) -> f64 {
        morph_factor(self.projected_error(geometric_error, distance) / self.threshold_px)
    }
}

/// K = `screen_height_px` / (2·tan(fov_y/2)), pixels per radian.
///
/// # Errors
/// [`MathError`] for NaN/infinite input, a non-positive height, or a field of
/// view outside (0°, 180°).
pub fn projection_constant(screen_height_px: f64, fov_y_degrees: f64) -> Result<f64, MathError> {
    let height = positive("screen height", screen_height_px)?;
    let fov = check_fov(fov_y_degrees)?;
    Ok(height / (2.0 * (fov.to_radians() / 2.0).tan()))
}

/// The small-angle approximation K ≈ `screen_height_px` / fov_y (radians)
/// that seed `001` quotes; it overestimates K by a factor
/// (fov/2) / tan(fov/2) (0.37 % at 12°).
///
/// # Errors
/// As [`projection_constant`].
pub fn projection_constant_small_angle(screen_height_px: f64, fov_y_degrees: f64) -> Result<f64, MathError> {
    let height = positive("screen height", screen_height_px)?;
    Ok(height / check_fov(fov_y_degrees)?.to_radians())
}

fn check_fov(fov_y_degrees: f64) -> Result<f64, MathError> {
    let fov = finite("field of view", fov_y_degrees)?;
    if fov > 0.0 && fov < 180.0 { Ok(fov) } else { Err(MathError::FovOutOfRange { degrees: fov }) }
}

/// Morph factor μ = smoothstep(clamp((r − 0.5) / 0.5, 0, 1)) for a projected
/// error `r` = ρ/τ in units of the threshold. 0 at or below half the
/// threshold (fully coarse), 1 at or above it (fully fine). NaN gives 0.
#[must_use]
pub fn morph_factor(error_over_threshold: f64) -> f64 {
    let x = ((error_over_threshold - 0.5) / 0.5).clamp(0.0, 1.0);
    if x.is_nan() { 0.0 } else { x * x * (3.0 - 2.0 * x) }
}

/// Distance to the horizon, √(2·R·h + h²), for an eye `height` metres above
/// a sphere of `radius` metres. An eye on or below the surface sees no
/// horizon: 0.
///
/// # Errors
/// [`MathError`] for NaN/infinite input or a non-positive radius.
pub fn horizon_distance(radius: f64, height: f64) -> Result<f64, MathError> {
    let radius = positive("radius", radius)?;
    let height = finite("height", height)?.max(0.0);
    Ok((2.0 * radius * height + height * height).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_projection_constant() {
        // Seed 001: 1024 px, 12° vertical field of view.
        let exact = projection_constant(1024.0, 12.0).unwrap();
        let small = projection_constant_small_angle(1024.0, 12.0).unwrap();
        assert!((exact - 4871.35).abs() < 0.01, "{exact}");
        assert!((small - 4889.24).abs() < 0.01, "{small}");
        // The seed's approximation overestimates K by 17.9 px/rad (0.37 %).
        let excess = small - exact;
        let expected = 1024.0 / 12f64.to_radians() - 512.0 / 6f64.to_radians().tan();
        assert!((excess - expected).abs() < 1e-9);
        assert!((excess - 17.89).abs() < 0.01, "{excess}");
        assert!((excess / exact - 0.003_67).abs() < 0.000_01, "{}", excess / exact);
    }

    #[test]
    fn seed_transition_distance() {
        let sse = ScreenSpace::new(1024.0, 12.0, 1.0).unwrap();
        // 0.1 m of error may be seen from 487 m on (the seed's 489 m uses the
        // small-angle K).
        let d = sse.transition_distance(0.1);
        assert!((d - 487.135).abs() < 0.001, "{d}");
        // At exactly that distance the error is the threshold.
        assert!((sse.projected_error(0.1, d) - 1.0).abs() < 1e-12);
        assert_eq!(sse.projected_error(0.1, 0.0), f64::INFINITY);
        // Doubling δ doubles the distance (linear, as the seed notes).
        assert!((sse.transition_distance(0.2) - 2.0 * d).abs() < 1e-9);
    }

    #[test]
    fn seed_horizon() {
        let d = horizon_distance(6_371_000.0, 100.0).unwrap();
        assert!((d - 35_696.0).abs() < 1.0, "{d}");
        assert_eq!(horizon_distance(6_371_000.0, -5.0).unwrap(), 0.0);
    }

    #[test]
    fn morph_factor_shape() {
        assert_eq!(morph_factor(0.0), 0.0);
        assert_eq!(morph_factor(0.5), 0.0);
        assert_eq!(morph_factor(0.75), 0.5);
        assert_eq!(morph_factor(1.0), 1.0);
        assert_eq!(morph_factor(7.0), 1.0);
        assert_eq!(morph_factor(f64::NAN), 0.0);
        // Smooth: zero slope at both ends.
        let h = 1e-6;
        assert!((morph_factor(0.5 + h) - morph_factor(0.5)) / h < 1e-4);
        assert!((morph_factor(1.0) - morph_factor(1.0 - h)) / h < 1e-4);
        let sse = ScreenSpace::new(1024.0, 12.0, 2.0).unwrap();
        // ρ = τ → fully fine; ρ = τ/2 → fully coarse.
        let d = sse.transition_distance(0.1);
        assert!((sse.morph_factor(0.1, d) - 1.0).abs() < 1e-9);
        assert!(sse.morph_factor(0.1, 2.0 * d) < 1e-9);
    }

    #[test]
    fn bad_camera_constants_are_errors() {
        assert!(matches!(ScreenSpace::new(f64::NAN, 60.0, 1.0), Err(MathError::NonFinite { .. })));
        assert!(matches!(ScreenSpace::new(0.0, 60.0, 1.0), Err(MathError::NotPositive { .. })));
        assert!(matches!(ScreenSpace::new(1080.0, 0.0, 1.0), Err(MathError::FovOutOfRange { .. })));
        assert!(matches!(ScreenSpace::new(1080.0, 180.0, 1.0), Err(MathError::FovOutOfRange { .. })));
        assert!(matches!(ScreenSpace::new(1080.0, f64::INFINITY, 1.0), Err(MathError::NonFinite { .. })));
        assert!(matches!(ScreenSpace::new(1080.0, 60.0, -1.0), Err(MathError::NotPositive { .. })));
        assert!(matches!(horizon_distance(0.0, 1.0), Err(MathError::NotPositive { .. })));
        let message = ScreenSpace::new(1080.0, 200.0, 1.0).unwrap_err().to_string();
        assert!(message.contains("200"), "{message}");
    }
}
