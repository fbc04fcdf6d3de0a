//! LOD settings, the camera, and the error type.

use nebula_math::{DVec3, MathError, ScreenSpace};
use nebula_voxel::VoxelError;

/// How neighbouring leaves may differ in LOD.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BalanceMode {
    /// Any difference: leaves follow screen-space error alone, and seams
    /// across differences of 2, 3, 4… are the mesher's job.
    #[default]
    Unrestricted,
    /// Neighbours differ by at most one LOD: a monotone filter (Flip-Flop
    /// style, seed `004`) splits leaves until every neighbour pair is valid.
    /// It only ever adds detail, so it converges.
    Restricted,
}

/// Settings of the LOD selection (the "LOD thresholds").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodSettings {
    /// τ: largest projected error allowed, pixels (default 1.0).
    pub threshold_px: f64,
    /// Viewport height, pixels.
    pub screen_height_px: f64,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f64,
    /// A split node merges only once its error is below τ·(1 − hysteresis),
    /// so a node that just split does not merge on the next frame
    /// (default 0.2).
    pub hysteresis: f64,
    /// Finest LOD the tree may reach (default 0).
    pub finest_lod: u8,
    /// Neighbour LOD rule.
    pub balance: BalanceMode,
}

impl Default for LodSettings {
    fn default() -> Self {
        Self {
            threshold_px: 1.0,
            screen_height_px: 1080.0,
            fov_y_degrees: 60.0,
            hysteresis: 0.2,
            finest_lod: 0,
            balance: BalanceMode::Unrestricted,
        }
    }
}

impl LodSettings {
    /// The checked SSE constants.
    ///
    /// # Errors
    /// [`LodError::Math`] for a bad height, field of view or threshold;
    /// [`LodError::BadHysteresis`] outside [0, 1).
    pub fn screen_space(&self) -> Result<ScreenSpace, LodError> {
        if !(0.0..1.0).contains(&self.hysteresis) {
            return Err(LodError::BadHysteresis { value: self.hysteresis });
        }
        Ok(ScreenSpace::new(self.screen_height_px, self.fov_y_degrees, self.threshold_px)?)
    }
}

/// Where the camera is and where it looks. World space, planet centre at
/// the origin, f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position, metres.
    pub position: DVec3,
    /// View direction (need not be unit length).
    pub forward: DVec3,
    /// Up direction (need not be unit or orthogonal to `forward`).
    pub up: DVec3,
    /// Width over height of the viewport.
    pub aspect: f64,
}

impl Camera {
    /// Checks the camera: finite values, a usable `forward` and `up`, a
    /// positive aspect.
    ///
    /// # Errors
    /// [`LodError::BadCamera`].
    pub fn check(&self) -> Result<(), LodError> {
        let bad = |reason: &str| Err(LodError::BadCamera { reason: reason.to_string() });
        if !self.position.is_finite() || !self.forward.is_finite() || !self.up.is_finite() || !self.aspect.is_finite() {
            return bad("NaN or infinite value");
        }
        if self.forward.length_squared() == 0.0 {
            return bad("forward is zero");
        }
        if self.forward.cross(self.up).length_squared()
            <= 1e-24 * self.forward.length_squared() * self.up.length_squared()
        {
            return bad("up is zero or parallel to forward");
        }
        if self.aspect <= 0.0 {
            return bad("aspect must be > 0");
        }
        Ok(())
    }
}

impl Camera {
    /// Unit direction of the ray through the centre of pixel `(px, py)` of
    /// a `width` × `height` image (row 0 at the top) with vertical field of
    /// view `fov_y_degrees`: the one place that maps pixels to rays, for
    /// crack counting and ray-cast checks.
    #[must_use]
    pub fn pixel_ray(&self, fov_y_degrees: f64, (width, height): (u32, u32), (px, py): (u32, u32)) -> DVec3 {
        let (forward, right, up) = nebula_math::view_basis(self.forward, self.up);
        let tan_y = (fov_y_degrees.to_radians() / 2.0).tan();
        let tan_x = tan_y * f64::from(width) / f64::from(height.max(1));
        let x = (2.0 * (f64::from(px) + 0.5) / f64::from(width.max(1)) - 1.0) * tan_x;
        let y = (1.0 - 2.0 * (f64::from(py) + 0.5) / f64::from(height.max(1))) * tan_y;
        (forward + right * x + up * y).normalize()
    }
}

/// Bad input to the LOD selection.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LodError {
    /// Bad SSE settings (screen height, field of view, threshold).
    #[error(transparent)]
    Math(#[from] MathError),
    /// The voxel source refused a node.
    #[error(transparent)]
    Voxel(#[from] VoxelError),
    /// Hysteresis outside [0, 1).
    #[error("hysteresis must be in [0, 1), got {value}")]
    BadHysteresis {
        /// The value given.
        value: f64,
    },
    /// A finest LOD beyond the planet's coarsest.
    #[error("finest LOD {finest_lod} is beyond the planet's coarsest LOD {max_lod}")]
    BadFinestLod {
        /// The value given.
        finest_lod: u8,
        /// The planet's coarsest LOD.
        max_lod: u8,
    },
    /// NaN or infinite camera data, or a degenerate view.
    #[error("bad camera: {reason}")]
    BadCamera {
        /// What is wrong.
        reason: String,
    },
    /// The camera is inside the planet: below the lowest possible surface.
    #[error("camera is {distance} m from the centre, inside the planet (lowest surface at {min_surface_radius} m)")]
    CameraInsidePlanet {
        /// Distance of the camera from the planet centre.
        distance: f64,
        /// Radius below which everything is solid.
        min_surface_radius: f64,
    },
}
