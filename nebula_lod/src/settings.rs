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
    /// A bound on the nodes the tree may hold (default 400,000): where τ,
    /// the field of view and the screen height would ask for more, the
    /// tree refines to a larger τ that keeps it within this
    /// ([`LodSettings::effective_threshold_px`]), so any view renders
    /// within memory instead of refining for minutes. The default takes a
    /// 1080-line screen at 60° and τ = 1 as asked (a bound of 338,000;
    /// such a tree holds about 170,000 nodes); a 640×400 Earth view at
    /// τ = 0.01 px is drawn at 0.27 px.
    pub max_nodes: usize,
    /// The field of view, degrees, the tree refines for outside the view
    /// when the view's own is narrower (default 60°): a zoom lens refines
    /// its frustum (opened by a margin, [`LodTree`](crate::LodTree)'s
    /// focus) with its own K and the planet around as a view of this field
    /// would, so that a 12° lens pays for what it sees instead of for
    /// every direction at its magnification. Turning such a lens refines
    /// the new view then (what comes into view is drawn first as this
    /// field of view would draw it); a view at least this wide refines by
    /// distance alone, as if this were not set.
    pub surround_fov_y_degrees: f64,
}

/// Radians each side of a narrow view's frustum is opened by for its focus:
/// the frustum the tree refines with the view's own K.
pub(crate) const FOCUS_MARGIN_ANGLE: f64 = 6.0 * std::f64::consts::PI / 180.0;

/// Radians of margin the focus keeps around the camera's own frustum before
/// it is made again (the LOD tree refocuses once the view opened by this
/// no longer fits in it): the 3° by which a streamer culls ahead of the
/// camera (`nebula_world`'s prediction margin), so that every leaf it draws
/// was refined with the view's K.
pub(crate) const FOCUS_KEPT_ANGLE: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// How far, in LOD-0 voxel edges, the eye may move from where the focus
/// was made before it is made again (its apex is set back so that every
/// eye that near is inside).
pub(crate) const FOCUS_MARGIN_VOXELS: f64 = 32.0;

/// The widest aspect (width over height) the node bound of a focused tree
/// allows for ([`LodSettings::node_bound_focused`]): 21:9 screens fit.
pub(crate) const FOCUS_BOUND_ASPECT: f64 = 2.5;

impl Default for LodSettings {
    fn default() -> Self {
        Self {
            threshold_px: 1.0,
            screen_height_px: 1080.0,
            fov_y_degrees: 60.0,
            hysteresis: 0.2,
            finest_lod: 0,
            balance: BalanceMode::Unrestricted,
            max_nodes: 400_000,
            surround_fov_y_degrees: 60.0,
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

    /// The screen-space constants outside a narrow view's focus: K of the
    /// settings' screen at [`LodSettings::surround_fov_y_degrees`], or of
    /// the view's own field where that is wider (then there is no focus:
    /// the same constants as [`LodSettings::screen_space`]), and τ.
    ///
    /// # Errors
    /// As [`LodSettings::screen_space`], and for a surround field of view
    /// outside (0°, 180°).
    pub fn surround_screen_space(&self) -> Result<ScreenSpace, LodError> {
        let view = self.screen_space()?;
        let surround = ScreenSpace::new(self.screen_height_px, self.surround_fov_y_degrees, self.threshold_px)?;
        Ok(if surround.k() < view.k() { surround } else { view })
    }

    /// Whether the view is narrower than the surround's field of view: the
    /// tree then refines its focus with the view's K and the rest with the
    /// surround's.
    ///
    /// # Errors
    /// As [`LodSettings::surround_screen_space`].
    pub fn is_focused(&self) -> Result<bool, LodError> {
        Ok(self.surround_screen_space()?.k() < self.screen_space()?.k())
    }

    /// The τ a tree of a planet whose coarsest LOD is `max_lod` refines to:
    /// [`LodSettings::threshold_px`], or the least larger τ whose bound on
    /// the node count ([`LodSettings::node_bound`], or
    /// [`LodSettings::node_bound_focused`] for a narrow view) is within
    /// [`LodSettings::max_nodes`].
    ///
    /// # Errors
    /// As [`LodSettings::surround_screen_space`];
    /// [`LodError::NodeBudget`] for a budget too small for the face roots
    /// and their children.
    pub fn effective_threshold_px(&self, max_lod: u8) -> Result<f64, LodError> {
        // Checked once here; `tree_node_bound` cannot fail after it.
        self.surround_screen_space()?;
        let bound =
            |tau: f64| LodSettings { threshold_px: tau, ..*self }.tree_node_bound(max_lod).unwrap_or(f64::INFINITY);
        let fits = |tau: f64| bound(tau) <= self.max_nodes as f64;
        if fits(self.threshold_px) {
            return Ok(self.threshold_px);
        }
        // The bound falls as τ grows and is 6 + 24 + … past the point where
        // no node splits, so bisect between τ and a τ that fits.
        let mut high = self.threshold_px;
        let mut tries = 0;
        while !fits(high) {
            high *= 2.0;
            tries += 1;
            if tries > 2_000 || !high.is_finite() {
                return Err(LodError::NodeBudget { max_nodes: self.max_nodes });
            }
        }
        let mut low = self.threshold_px;
        for _ in 0..60 {
            let mid = 0.5 * (low + high);
            if fits(mid) { high = mid } else { low = mid }
        }
        Ok(high)
    }

    /// The bound on the nodes of a tree with these settings (as given, τ
    /// not raised): [`LodSettings::node_bound`], or for a narrow view
    /// [`LodSettings::node_bound_focused`].
    ///
    /// # Errors
    /// As [`LodSettings::surround_screen_space`].
    pub fn tree_node_bound(&self, max_lod: u8) -> Result<f64, LodError> {
        let (screen, surround) = (self.screen_space()?, self.surround_screen_space()?);
        let tau = self.threshold_px;
        Ok(if self.is_focused()? {
            Self::node_bound_focused(screen.k() / tau, surround.k() / tau, self.focus_half_angle(), max_lod)
        } else {
            Self::node_bound(screen.k() / tau, max_lod)
        })
    }

    /// The half-angle, radians, of the narrowest circular cone around the
    /// view direction that holds a focus (the view's frustum opened by its
    /// margin) at any aspect up to 2.5.
    fn focus_half_angle(&self) -> f64 {
        let half_y = self.fov_y_degrees.to_radians() / 2.0;
        let half_x = (half_y.tan() * FOCUS_BOUND_ASPECT).atan();
        let open = |half: f64| (half + FOCUS_MARGIN_ANGLE).min(std::f64::consts::FRAC_PI_2 - 1e-6).tan();
        open(half_x).hypot(open(half_y)).atan()
    }

    /// An upper bound on the nodes of a tree whose split distance at each
    /// LOD is `k_over_tau` voxel edges of that LOD (D_split = e·K/τ):
    /// a LOD-L node exists only under a LOD-(L+1) parent closer than its
    /// split distance, that is `K/τ / 32` parent widths; parents whose
    /// bounds come that close lie in a disc of that radius (plus a cell
    /// diagonal) around the point under the eye, at most 1.5 times as
    /// many cells as its area holds (the cube map's area distortion is
    /// 1.41); four children each; and never more than the planet has.
    /// Measured on Earth views near the ground it is 2–3 times the nodes
    /// the tree holds.
    #[must_use]
    pub fn node_bound(k_over_tau: f64, max_lod: u8) -> f64 {
        let per_lod = 4.0 * 1.5 * std::f64::consts::PI * (k_over_tau / 32.0 + 1.5).powi(2);
        6.0 + (0..max_lod).map(|lod| per_lod.min(6.0 * 4f64.powi(i32::from(max_lod - lod)))).sum::<f64>()
    }

    /// An upper bound on the nodes of a focused tree
    /// ([`LodSettings::surround_fov_y_degrees`]): split distances of
    /// `surround_k_over_tau` voxel edges everywhere, as
    /// [`LodSettings::node_bound`] counts them, and of `k_over_tau` for
    /// parents inside a cone of half-angle `focus_half_angle` radians from
    /// the eye (set back by its margin, so the disc grows by that much).
    ///
    /// Why the cone holds so few: the ground at distance ρ from the point
    /// under an eye at height h is a circle whose directions from the eye
    /// lie on a circle of radius cos e on the unit sphere (e its
    /// depression); a cone of half-angle β takes at most an arc πβ long of
    /// it, a share β / (2 cos e) = β √(ρ² + h²) / (2ρ). Over a disc of
    /// radius r ≥ h that is at most πβ (r² / 2 + h r) of its π r²: β/2 of
    /// every LOD's disc, plus β h / r, which summed over the LODs whose
    /// disc reaches the ground (r ≥ h, doubling from one to the next) is
    /// at most 2β in all; and where a circle lies wholly inside the cone
    /// (an eye looking steeply down, ρ ≤ h·tan β) all of it, at most
    /// (4/3)·tan² β of a disc more over those LODs.
    #[must_use]
    pub fn node_bound_focused(k_over_tau: f64, surround_k_over_tau: f64, focus_half_angle: f64, max_lod: u8) -> f64 {
        let disc =
            |k_over_tau: f64, extra: f64| 4.0 * 1.5 * std::f64::consts::PI * (k_over_tau / 32.0 + 1.5 + extra).powi(2);
        // The apex set back by the eye's margin over the sine of the
        // narrowest opened half-angle (at least the margin itself), in the
        // finest parents' widths (64 LOD-0 voxels): coarser ones less.
        let back = FOCUS_MARGIN_VOXELS / FOCUS_MARGIN_ANGLE.sin() / 64.0;
        let beta = focus_half_angle.clamp(0.0, std::f64::consts::PI);
        let (surround, focus) = (disc(surround_k_over_tau, 0.0), disc(k_over_tau, back));
        let per_lod = surround + 0.5 * beta * focus;
        // Where the ground's circle lies wholly inside the cone (an eye
        // looking steeply down) its share is 1, not the arc's: within
        // ρ ≤ h·tan β, π h² tan² β of each LOD's disc, at most (4/3)·tan² β
        // of a disc over the LODs whose disc reaches the ground.
        let inside = 4.0 / 3.0 * beta.min(1.5).tan().powi(2) * focus;
        6.0 + 2.0 * beta * focus
            + inside
            + (0..max_lod).map(|lod| per_lod.min(6.0 * 4f64.powi(i32::from(max_lod - lod)))).sum::<f64>()
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
    /// A node budget too small for any tree of the planet.
    #[error("a LOD tree budget of {max_nodes} nodes is too small for this planet")]
    NodeBudget {
        /// The budget given.
        max_nodes: usize,
    },
    /// The camera is inside the planet: below the lowest possible surface.
    #[error("camera is {distance} m from the centre, inside the planet (lowest surface at {min_surface_radius} m)")]
    CameraInsidePlanet {
        /// Distance of the camera from the planet centre.
        distance: f64,
        /// Radius below which everything is solid.
        min_surface_radius: f64,
    },
    /// A cull was narrowed for a camera it does not cover
    /// (`LodTree::narrow_cull`).
    #[error("the last cull does not cover this camera: cull again")]
    NotCovered,
}
