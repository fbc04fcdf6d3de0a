//! Conservative bounds of a quadtree node: the patch of the cube face it
//! covers, between the lowest and highest surface the voxel source allows.

use std::f64::consts::FRAC_PI_2;

use nebula_math::DVec3;
use nebula_voxel::{CHUNK_SIZE, ChunkColumn, ChunkLayout, SurfaceBounds};

use crate::Camera;

/// World-space bounds of one node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeBounds {
    /// Axis-aligned box that contains every surface point of the node.
    pub min: DVec3,
    /// See `min`.
    pub max: DVec3,
    /// Unit direction through the centre of the node's patch.
    pub center_direction: DVec3,
    /// Largest angle (radians) between `center_direction` and a point of
    /// the patch.
    pub angular_radius: f64,
    /// Largest angle (radians) of a disc around `center_direction` inside
    /// the patch: the nearest of its four sides (great circles).
    pub inner_angular_radius: f64,
    /// Lowest surface radius in the node, metres.
    pub min_radius: f64,
    /// Highest surface radius in the node, metres.
    pub max_radius: f64,
}

impl NodeBounds {
    /// Bounds of `column`'s patch between the radii of `surface`.
    ///
    /// The box holds a 3 × 3 grid of patch points at both radii, grown by
    /// how far the sphere bulges between grid points
    /// (`r·(1 − cos(φ/2))` for grid spacing φ), so it holds the whole
    /// curved patch.
    #[must_use]
    pub fn new(layout: &ChunkLayout, column: ChunkColumn, surface: &SurfaceBounds) -> Self {
        let sphere = layout.sphere();
        let size = f64::from(CHUNK_SIZE) * layout.voxel_span(column.lod) as f64;
        let (i0, j0) = (f64::from(column.x) * size, f64::from(column.y) * size);
        // The 3 × 3 grid's directions, once each: `grid[a][b]` at
        // `(a / 2, b / 2)` of the patch.
        let grid = sphere.patch_directions(column.face, i0, j0, size);
        let center_direction = grid[1][1];
        let (mut min, mut max) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        // Largest angles as smallest cosines: one `acos` each at the end.
        let mut radius_cosine = 1.0_f64;
        let mut spacing_cosine = 1.0_f64;
        for a in 0..3 {
            for b in 0..3 {
                let d = grid[a][b];
                radius_cosine = radius_cosine.min(center_direction.dot(d));
                if a < 2 && b < 2 {
                    spacing_cosine = spacing_cosine.min(d.dot(grid[a + 1][b + 1]));
                }
                for radius in [surface.min_radius, surface.max_radius] {
                    min = min.min(d * radius);
                    max = max.max(d * radius);
                }
            }
        }
        let angular_radius = radius_cosine.clamp(-1.0, 1.0).acos();
        // The sides are great circles (one lattice coordinate held): the
        // disc reaches the nearest one's plane.
        let corners = [grid[0][0], grid[2][0], grid[2][2], grid[0][2]];
        let nearest_side_sine = (0..4)
            .map(|k| center_direction.dot(corners[k].cross(corners[(k + 1) % 4]).normalize()).abs())
            .fold(1.0_f64, f64::min);
        let inner_angular_radius = nearest_side_sine.asin();
        let spacing = spacing_cosine.clamp(-1.0, 1.0).acos();
        let bulge = surface.max_radius * (1.0 - (spacing / 2.0).cos());
        Self {
            min: min - DVec3::splat(bulge),
            max: max + DVec3::splat(bulge),
            center_direction,
            angular_radius,
            inner_angular_radius,
            min_radius: surface.min_radius,
            max_radius: surface.max_radius,
        }
    }

    /// Distance from `point` to the box (0 inside).
    #[must_use]
    pub fn distance(&self, point: DVec3) -> f64 {
        let outside = (self.min - point).max(point - self.max).max(DVec3::ZERO);
        outside.length()
    }

    /// Whether the whole node is hidden behind the horizon of the sphere of
    /// radius `occluder_radius` (the lowest surface anywhere), seen from
    /// `camera` ([`Horizon::hides`]; a [`Horizon`] made once serves many
    /// nodes).
    #[must_use]
    pub fn behind_horizon(&self, camera: DVec3, occluder_radius: f64) -> bool {
        Horizon::new(camera, occluder_radius).hides(self)
    }

    /// Whether the box lies entirely outside the view frustum of `camera`
    /// with vertical field of view `fov_y_degrees` (no near or far plane;
    /// [`Frustum::excludes`], whose planes are worth making once for many
    /// nodes).
    #[must_use]
    pub fn outside_frustum(&self, camera: &Camera, fov_y_degrees: f64) -> bool {
        Frustum::new(camera, fov_y_degrees).excludes(self)
    }
}

/// The horizon of a sphere (the lowest surface anywhere) seen from an eye:
/// what of the angle test of [`NodeBounds::behind_horizon`] depends on the
/// eye alone, computed once.
#[derive(Clone, Copy, Debug)]
pub struct Horizon {
    eye: DVec3,
    /// `eye` as a unit vector.
    eye_direction: DVec3,
    occluder_radius: f64,
    /// acos(R / d): how far round the sphere the eye sees; `None` where the
    /// eye is inside the sphere (it hides nothing).
    eye_reach: Option<f64>,
    /// cos(`eye_reach`).
    cos_reach: f64,
}

impl Horizon {
    /// The horizon of the sphere of radius `occluder_radius` from `eye`.
    #[must_use]
    pub fn new(eye: DVec3, occluder_radius: f64) -> Self {
        Self::around(eye, 0.0, occluder_radius)
    }

    /// What is behind the horizon from every eye within `margin` metres of
    /// `eye`: the eye's angle to a node can shrink by up to
    /// asin(margin / d), and the eye can see as far round as from d +
    /// margin.
    #[must_use]
    pub fn around(eye: DVec3, margin: f64, occluder_radius: f64) -> Self {
        let d = eye.length();
        let eye_reach = (d - margin > occluder_radius)
            .then(|| (occluder_radius / (d + margin)).acos() + (margin / d).clamp(0.0, 1.0).asin());
        let cos_reach = eye_reach.map_or(1.0, f64::cos);
        Self { eye, eye_direction: eye.normalize_or_zero(), occluder_radius, eye_reach, cos_reach }
    }

    /// Whether the whole node is hidden behind the horizon. A point at
    /// radius r is seen from distance d over the sphere iff its angle from
    /// the eye's direction is at most acos(R/d) + acos(R/r); the node's
    /// nearest point is at least `angle − angular_radius` away.
    #[must_use]
    pub fn hides(&self, bounds: &NodeBounds) -> bool {
        let Some(eye_reach) = self.eye_reach else { return false };
        if bounds.max_radius <= self.occluder_radius {
            return false;
        }
        // A node whose centre is within the eye's own reach is seen (the
        // limit below is larger still): most leaves of a view near the
        // ground, told without the two `acos` (a fifth of the frame's
        // selection). Both directions are unit vectors.
        if self.eye_direction.dot(bounds.center_direction) >= self.cos_reach {
            return false;
        }
        let limit = eye_reach + (self.occluder_radius / bounds.max_radius).acos();
        let nearest = self.eye.angle_between(bounds.center_direction) - bounds.angular_radius;
        nearest > limit
    }
}

/// A camera's view frustum: the inward normals of its four side planes
/// through the eye (no near or far plane), made once for many boxes.
#[derive(Clone, Copy, Debug)]
pub struct Frustum {
    eye: DVec3,
    planes: [DVec3; 4],
}

/// How far a cull reaches past its camera, so that one cull serves every
/// camera near it ([`Frustum::covers`]): its sides opened by `angle`
/// radians, and its apex moved back so that every eye within `distance`
/// metres is inside.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CullMargin {
    /// Radians added to each side's half-angle.
    pub angle: f64,
    /// Metres the eye may move.
    pub distance: f64,
}

impl Frustum {
    /// The frustum of `camera` with vertical field of view `fov_y_degrees`.
    #[must_use]
    pub fn new(camera: &Camera, fov_y_degrees: f64) -> Self {
        Self::with_margin(camera, fov_y_degrees, CullMargin::default())
    }

    /// The frustum of `camera` opened by `margin`: it holds the frustum of
    /// every camera [`Frustum::covers`] accepts.
    #[must_use]
    pub fn with_margin(camera: &Camera, fov_y_degrees: f64, margin: CullMargin) -> Self {
        let (forward, right, up) = nebula_math::view_basis(camera.forward, camera.up);
        let half_y = fov_y_degrees.to_radians() / 2.0;
        let half_x = (half_y.tan() * camera.aspect).atan();
        // Without a margin, the camera's own tangents (not a round trip
        // through atan and tan): the exact cull is unchanged.
        let open = |half: f64| (half + margin.angle).min(FRAC_PI_2 - 1e-6);
        let (tan_x, tan_y) = if margin.angle > 0.0 {
            (open(half_x).tan(), open(half_y).tan())
        } else {
            (half_y.tan() * camera.aspect, half_y.tan())
        };
        let planes = [
            (forward * tan_x + right).normalize(),
            (forward * tan_x - right).normalize(),
            (forward * tan_y + up).normalize(),
            (forward * tan_y - up).normalize(),
        ];
        // A ball of radius r around the eye is inside once the apex is
        // r / sin(narrowest half-angle) behind it.
        let back = if margin.distance > 0.0 { margin.distance / open(half_x.min(half_y)).sin() } else { 0.0 };
        Self { eye: camera.position - forward * back, planes }
    }

    /// Whether the whole frustum of `camera` (field of view
    /// `fov_y_degrees`) lies inside this one: its eye inside, and the four
    /// rays along its edges pointing inside (the frustum is the convex
    /// hull of those rays, and this one is convex).
    #[must_use]
    pub fn covers(&self, camera: &Camera, fov_y_degrees: f64) -> bool {
        self.covers_opened(camera, fov_y_degrees, 0.0)
    }

    /// [`Frustum::covers`] for the frustum of `camera` with each side
    /// opened by `angle` radians (what a cull with that margin reaches).
    #[must_use]
    pub fn covers_opened(&self, camera: &Camera, fov_y_degrees: f64, angle: f64) -> bool {
        if camera.check().is_err() {
            return false;
        }
        let (forward, right, up) = nebula_math::view_basis(camera.forward, camera.up);
        let tan_y = (fov_y_degrees.to_radians() / 2.0).tan();
        let tan_x = tan_y * camera.aspect;
        let (tan_x, tan_y) = if angle > 0.0 {
            let open = |tan: f64| (tan.atan() + angle).min(FRAC_PI_2 - 1e-6).tan();
            (open(tan_x), open(tan_y))
        } else {
            (tan_x, tan_y)
        };
        let edges = [
            forward + right * tan_x + up * tan_y,
            forward + right * tan_x - up * tan_y,
            forward - right * tan_x + up * tan_y,
            forward - right * tan_x - up * tan_y,
        ];
        self.planes.iter().all(|&n| n.dot(camera.position - self.eye) >= 0.0 && edges.iter().all(|&e| n.dot(e) >= 0.0))
    }

    /// Whether `bounds`' box lies entirely outside: behind one plane.
    #[must_use]
    pub fn excludes(&self, bounds: &NodeBounds) -> bool {
        self.planes.iter().any(|&n| {
            // The box corner furthest along the plane normal.
            let corner = DVec3::new(
                if n.x >= 0.0 { bounds.max.x } else { bounds.min.x },
                if n.y >= 0.0 { bounds.max.y } else { bounds.min.y },
                if n.z >= 0.0 { bounds.max.z } else { bounds.min.z },
            );
            n.dot(corner - self.eye) < 0.0
        })
    }
}
