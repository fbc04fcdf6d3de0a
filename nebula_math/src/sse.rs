//! Screen-space error (SSE), LOD transition distances and geomorph factors
//! (seed `001`).
//!
//! ```text
//!   K = Res_y / (2·tan(fov_y/2))      pixels per radian at the screen centre
//!   ρ = δ·K / D                       projected error in pixels of a chunk with
//!                                     geometric error δ seen from distance D
//!   D_τ = δ·K / τ                     distance at which ρ reaches the threshold τ
//!   μ = smoothstep(clamp((ρ_p/τ − 1) / (M − 1), 0, 1)),  M = MORPH_FULL
//!                                     morph factor of a leaf, from ρ_p, the
//!                                     projected error of its *parent* (the
//!                                     LOD it would merge into): 0 where the
//!                                     parent is good enough, 1 where the leaf
//!                                     is needed
//! ```
//!
//! Why the parent's error drives μ (not the leaf's own): the finest LOD has
//! no error of its own, so a leaf-driven μ pins every LOD-0 chunk at its
//! morph target and the voxels next to the camera are never drawn as they
//! are. With the parent's error:
//!
//! ```text
//!   ρ_p/τ:   ≤ 1−h ........ 1 .......... M ......... 2 ....... ∞
//!   tree:    merge here     split here   (a leaf exists between the two)
//!   μ:       0              0            1           1         1
//! ```
//!
//! - At the merge (ρ_p < τ(1 − h)) μ = 0 at every vertex (a vertex is never
//!   nearer than its node's bounds), so the leaf looks exactly like the
//!   parent that replaces it.
//! - At the split (ρ_p just above τ) the new children start at μ ≈ 0, i.e.
//!   as their parent, and reach their true geometry at ρ_p = M·τ.
//! - LOD 0 next to the camera has ρ_p ≫ M·τ: μ = 1, drawn exactly.
//!
//! `M` = [`MORPH_FULL`] = 1.4 leaves room for the far side of a chunk: the
//! parent must be fully unmorphed (μ = 1 at all its vertices) when its
//! children merge into it, where ρ of the grandparent is 2τ(1 − h) = 1.6τ
//! at the nearest point and less farther away (see the pop test in
//! `nebula_tests`).

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

    /// Geomorph factor μ in [0, 1] of a vertex at `distance` from the eye in
    /// a leaf whose parent has error `parent_error` (metres): see
    /// [`morph_factor`]. The shader's `morph_factor` is this function in
    /// f32.
    #[must_use]
    pub fn morph_factor(&self, parent_error: f64, distance: f64) -> f64 {
        morph_factor(self.projected_error(parent_error, distance) / self.threshold_px)
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

/// Where a leaf reaches its true geometry: μ = 1 once its parent's
/// projected error is `MORPH_FULL`·τ (see the module docs for the choice).
pub const MORPH_FULL: f64 = 1.4;

/// Morph factor μ = smoothstep(clamp((r − 1) / (M − 1), 0, 1)) for
/// `parent_error_over_threshold` r = ρ_p/τ, the projected error of the
/// leaf's parent in units of the threshold, M = [`MORPH_FULL`]. 0 at or
/// below the split threshold (the leaf looks like its parent), 1 at or above
/// M (the leaf's own geometry). +∞ (no parent: the coarsest LOD, or the
/// camera touching the chunk) gives 1; NaN gives 1 as well, so bad input
/// never hides the true voxels.
#[must_use]
pub fn morph_factor(parent_error_over_threshold: f64) -> f64 {
    let x = ((parent_error_over_threshold - 1.0) / (MORPH_FULL - 1.0)).clamp(0.0, 1.0);
    if x.is_nan() { 1.0 } else { x * x * (3.0 - 2.0 * x) }
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
        assert_eq!(morph_factor(0.8), 0.0, "at the merge threshold (hysteresis 0.2)");
        assert_eq!(morph_factor(1.0), 0.0, "at the split threshold");
        assert!((morph_factor(1.2) - 0.5).abs() < 1e-12);
        assert_eq!(morph_factor(MORPH_FULL), 1.0);
        assert_eq!(morph_factor(2.0), 1.0);
        assert_eq!(morph_factor(f64::INFINITY), 1.0, "no parent: true geometry");
        assert_eq!(morph_factor(f64::NAN), 1.0);
        // Monotone and smooth: zero slope at both ends.
        let h = 1e-6;
        assert!((morph_factor(1.0 + h) - morph_factor(1.0)) / h < 1e-4);
        assert!((morph_factor(MORPH_FULL) - morph_factor(MORPH_FULL - h)) / h < 1e-4);
        let samples: Vec<f64> = (0..=300).map(|i| morph_factor(f64::from(i) / 100.0)).collect();
        assert!(samples.windows(2).all(|w| w[0] <= w[1]));
    }

    #[test]
    fn morph_factor_at_every_lod_from_the_parents_error() {
        // A leaf at LOD L with voxel edge e·2^L: its parent's error is the
        // parent's voxel edge e·2^(L+1). For every LOD, a vertex where the
        // parent's projected error is ≥ 2τ is drawn as it is (μ = 1), and at
        // the merge threshold τ(1 − h) it matches the parent (μ = 0).
        let sse = ScreenSpace::new(720.0, 60.0, 1.0).unwrap();
        let edge = 1.19;
        let hysteresis = 0.2;
        for lod in 0..=18 {
            let parent_error = edge * f64::from(1u32 << (lod + 1));
            let at = |ratio: f64| sse.morph_factor(parent_error, parent_error * sse.k() / (ratio * 1.0));
            assert_eq!(at(2.0), 1.0, "LOD {lod}: parent error 2τ");
            assert_eq!(at(5.0), 1.0, "LOD {lod}: parent error 5τ");
            assert!(at(1.0 - hysteresis) < 1e-12, "LOD {lod}: merge threshold");
            assert!(at(1.0) < 1e-12, "LOD {lod}: split threshold");
        }
        // LOD 0 a few metres from the camera: exact voxels.
        assert_eq!(sse.morph_factor(2.0 * edge, 5.0), 1.0);
        assert_eq!(sse.morph_factor(2.0 * edge, 0.0), 1.0, "camera on the vertex");
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
