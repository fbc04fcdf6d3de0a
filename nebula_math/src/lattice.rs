//! Canonical lattice points and the one function that turns them into world
//! positions.
//!
//! Every mesh vertex in Nebula starts as a [`LatticePoint`]: integer cube
//! coordinates at the finest resolution plus an integer radial layer. Two
//! chunks, or two cube faces, that share a lattice point hold the same integer
//! value, and [`Cubesphere::position`] depends on nothing else, so they get the
//! bit-identical f64 world position. Never build a position by adding float
//! offsets per chunk.

use glam::{DVec3, I64Vec3, IVec3};

use crate::error::{MathError, finite, positive};
use crate::{CubeFace, SphereMap};

/// Each face's normal, `u` and `v` axes as floats, by face index: read by
/// every direction of a chunk's columns and grid nodes, which found them
/// from the integer axes one call at a time (a tenth of a cold chunk's
/// directions).
static FLOAT_AXES: std::sync::LazyLock<[[DVec3; 3]; 6]> = std::sync::LazyLock::new(|| {
    CubeFace::ALL.map(|face| [face.normal(), face.u_axis(), face.v_axis()].map(|axis| axis.as_dvec3()))
});

/// The largest lattice resolution (cells per face edge): 2³⁰, so cube
/// coordinates and their doubles fit in `i32`/`i64` with room to spare.
pub const MAX_RESOLUTION: u32 = 1 << 30;

/// A point of the planet lattice in canonical form: integer cube coordinates
/// (each in `[−N/2, N/2]`, one of them ±N/2) and a radial layer.
///
/// Equal points compare equal and hash equal whichever face they were made
/// from. Build them with [`Cubesphere::lattice_point`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct LatticePoint {
    /// Cube coordinates (see the [`crate::face`] conventions).
    pub cube: IVec3,
    /// Radial layer: 0 at [`Cubesphere::radius`], growing outward.
    pub layer: i32,
}

/// The geometry of one planet: its lattice resolution, radial spacing and
/// cube-to-sphere map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cubesphere {
    radius: f64,
    resolution: u32,
    layer_height: f64,
    map: SphereMap,
}

impl Cubesphere {
    /// A cubesphere with `resolution` lattice cells along each face edge
    /// (even, at most [`MAX_RESOLUTION`]), radial layer 0 at `radius` metres
    /// and `layer_height` metres between radial layers.
    ///
    /// # Errors
    /// [`MathError`] for a non-finite or non-positive radius or layer height,
    /// or a resolution that is odd, zero or too large.
    pub fn new(radius: f64, resolution: u32, layer_height: f64, map: SphereMap) -> Result<Self, MathError> {
        positive("radius", radius)?;
        positive("layer height", layer_height)?;
        if resolution < 2 || !resolution.is_multiple_of(2) || resolution > MAX_RESOLUTION {
            return Err(MathError::BadResolution { got: u64::from(resolution), max: u64::from(MAX_RESOLUTION) });
        }
        Ok(Self { radius, resolution, layer_height, map })
    }

    /// Radius of radial layer 0, in metres.
    #[must_use]
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Lattice cells along each face edge at the finest resolution.
    #[must_use]
    pub fn resolution(&self) -> u32 {
        self.resolution
    }

    /// Metres between consecutive radial layers.
    #[must_use]
    pub fn layer_height(&self) -> f64 {
        self.layer_height
    }

    /// The cube-to-sphere map.
    #[must_use]
    pub fn map(&self) -> SphereMap {
        self.map
    }

    /// Width of a lattice cell at layer 0 along a face's centre line, in
    /// metres (equal for every cell on that line with the equi-angular map).
    #[must_use]
    pub fn cell_width(&self) -> f64 {
        self.radius * std::f64::consts::FRAC_PI_2 / f64::from(self.resolution)
    }

    /// Radius of radial layer `layer` (may be fractional), in metres.
    #[must_use]
    pub fn layer_radius(&self, layer: f64) -> f64 {
        self.radius + layer * self.layer_height
    }

    /// The radial layer (fractional) at `radius` metres from the centre.
    #[must_use]
    pub fn radius_to_layer(&self, radius: f64) -> f64 {
        (radius - self.radius) / self.layer_height
    }

    /// The canonical lattice point at in-face coordinates `(i, j)` of `face`
    /// and radial layer `layer`.
    ///
    /// # Errors
    /// [`MathError::OutsideFace`] unless `0 ≤ i, j ≤ N`;
    /// [`MathError::LayerBelowCentre`] if the layer's radius is not positive.
    pub fn lattice_point(&self, face: CubeFace, i: i64, j: i64, layer: i64) -> Result<LatticePoint, MathError> {
        let n = i64::from(self.resolution);
        if !(0..=n).contains(&i) || !(0..=n).contains(&j) {
            return Err(MathError::OutsideFace { face, i, j, resolution: self.resolution });
        }
        let radius = self.layer_radius(layer as f64);
        let Some(layer_i32) = i32::try_from(layer).ok().filter(|_| radius > 0.0) else {
            return Err(MathError::LayerBelowCentre { layer, radius });
        };
        let layer = layer_i32;
        let cube = face.face_to_cube(i, j, n);
        // In range by the check above: every component is within ±N/2 ≤ 2²⁹.
        let cube = IVec3::new(cube.x as i32, cube.y as i32, cube.z as i32);
        Ok(LatticePoint { cube, layer })
    }

    /// The in-face coordinates of `point` on `face`, if the point lies on it.
    #[must_use]
    pub fn face_coords(&self, point: LatticePoint, face: CubeFace) -> Option<(i64, i64)> {
        let half = i64::from(self.resolution / 2);
        let cube = I64Vec3::new(point.cube.x.into(), point.cube.y.into(), point.cube.z.into());
        (cube.dot(face.normal()) == half).then(|| face.cube_to_face(cube, i64::from(self.resolution)))
    }

    /// **The** canonical world position of a lattice point, in metres, planet
    /// centre at the origin.
    ///
    /// Depends only on the point's integer value, so every face and chunk
    /// that shares a point gets the bit-identical result.
    #[must_use]
    pub fn position(&self, point: LatticePoint) -> DVec3 {
        self.position_on_column(self.column_direction(point), point.layer)
    }

    /// The unit direction of the radial column through `point` (the same
    /// for every layer). With [`Cubesphere::position_on_column`] it splits
    /// [`Cubesphere::position`] so a mesher can compute each column's
    /// direction once; the two calls do exactly the arithmetic of
    /// `position`, so the result is bit-identical.
    #[must_use]
    pub fn column_direction(&self, point: LatticePoint) -> DVec3 {
        self.column_direction_with(point, |_, c| self.cube_warp(c))
    }

    /// [`Cubesphere::column_direction`] with each cube coordinate's warp
    /// from `warp(axis, coordinate)`, which must give
    /// [`Cubesphere::cube_warp`] of the coordinate: a mesher keeps the
    /// warps of a chunk's columns, which share their coordinates along
    /// rows and columns (a `tan` each on the equi-angular map).
    #[must_use]
    pub fn column_direction_with(&self, point: LatticePoint, mut warp: impl FnMut(usize, i32) -> f64) -> DVec3 {
        // `SphereMap::direction` of `cube / half`, one component at a time.
        DVec3::new(warp(0, point.cube.x), warp(1, point.cube.y), warp(2, point.cube.z)).normalize()
    }

    /// A cube coordinate of a lattice point warped by the sphere map, as
    /// [`Cubesphere::column_direction`] warps it before normalising.
    #[must_use]
    pub fn cube_warp(&self, c: i32) -> f64 {
        self.map.warp(f64::from(c) / f64::from(self.resolution / 2))
    }

    /// The position at radial layer `layer` on the column with unit
    /// direction `direction` (from [`Cubesphere::column_direction`]).
    #[must_use]
    #[inline]
    pub fn position_on_column(&self, direction: DVec3, layer: i32) -> DVec3 {
        direction * self.layer_radius(f64::from(layer))
    }

    /// Unit normal of the plane through the planet centre that holds every
    /// lattice point with in-face coordinate `coord` along `axis` (`u` when
    /// `along_u`, else `v`) on `face`, pointing towards growing `coord`.
    ///
    /// Both maps warp each cube coordinate separately, so a lattice line of
    /// constant `i` is a great circle and the side walls of voxels are flat
    /// pieces of these planes: this is their exact normal.
    #[must_use]
    pub fn lattice_plane_normal(&self, face: CubeFace, along_u: bool, coord: i64) -> DVec3 {
        let half = f64::from(self.resolution / 2);
        let t = (coord as f64 - half) / half;
        self.warped_plane_normal(face, along_u, self.map.warp(t))
    }

    /// [`Cubesphere::lattice_plane_normal`] from the warp of the plane's
    /// cube coordinate ([`Cubesphere::cube_warp`] of `coord − N/2`), bit
    /// for bit, for a caller that has it (a mesher keeps a chunk's).
    #[must_use]
    pub fn warped_plane_normal(&self, face: CubeFace, along_u: bool, warp: f64) -> DVec3 {
        // `SphereMap::direction` of (t, 0, 1): both maps warp 0 to 0 and 1
        // to 1 exactly.
        let warped = DVec3::new(warp, 0.0, 1.0).normalize();
        // `warped` is (w, 0, 1) normalised: the plane is p·axis = w·(p·n).
        let w = warped.x / warped.z;
        let axis = if along_u { face.u_axis() } else { face.v_axis() }.as_dvec3();
        (axis - face.normal().as_dvec3() * w).normalize()
    }

    /// Unit direction from the centre through in-face coordinates `(i, j)`
    /// of `face`, which may be fractional (e.g. a cell centre). For sampling
    /// terrain, not for mesh vertices: those go through
    /// [`Cubesphere::position`].
    #[must_use]
    pub fn direction(&self, face: CubeFace, i: f64, j: f64) -> DVec3 {
        self.direction_warped(face, self.warp(i), self.warp(j))
    }

    /// In-face coordinate `c` (an `i` or a `j`) warped by the sphere map,
    /// for [`Cubesphere::direction_warped`]: a grid of directions costs one
    /// warp (a `tan`) per row and per column instead of two per point.
    #[must_use]
    pub fn warp(&self, c: f64) -> f64 {
        let half = f64::from(self.resolution / 2);
        self.map.warp((c - half) / half)
    }

    /// [`Cubesphere::direction`] from warped coordinates
    /// ([`Cubesphere::warp`] of `i` and of `j`), bit for bit: the face's
    /// normal component is ±1 and the map is odd, so warping the cube point
    /// componentwise is warping `i` and `j`.
    #[must_use]
    pub fn direction_warped(&self, face: CubeFace, warped_i: f64, warped_j: f64) -> DVec3 {
        let [normal, u_axis, v_axis] = FLOAT_AXES[face as usize];
        (normal + u_axis * warped_i + v_axis * warped_j).normalize()
    }

    /// The directions of the square patch of `face` from `(i0, j0)` with
    /// side `size`, at its corners, edge midpoints and centre:
    /// `grid[a][b]` at `(i0 + a·size/2, j0 + b·size/2)`, bit for bit
    /// [`Cubesphere::direction`] there, from one warp (a `tan`) per row and
    /// per column (building a 12° lens's LOD tree spent a tenth of its
    /// time in two a point).
    #[must_use]
    pub fn patch_directions(&self, face: CubeFace, i0: f64, j0: f64, size: f64) -> [[DVec3; 3]; 3] {
        let warps = |c0: f64| -> [f64; 3] { std::array::from_fn(|k| self.warp(c0 + k as f64 * 0.5 * size)) };
        let (warp_i, warp_j) = (warps(i0), warps(j0));
        std::array::from_fn(|a| std::array::from_fn(|b| self.direction_warped(face, warp_i[a], warp_j[b])))
    }

    /// The face and fractional in-face coordinates `(i, j)` whose
    /// [`Cubesphere::direction`] is closest to `world` (the inverse map).
    ///
    /// # Errors
    /// [`MathError::NonFinite`] for NaN or infinite input,
    /// [`MathError::NotPositive`] at the planet centre.
    pub fn face_coords_of(&self, world: DVec3) -> Result<(CubeFace, f64, f64), MathError> {
        for value in world.to_array() {
            finite("world position", value)?;
        }
        let largest = world.abs().max_element();
        positive("distance from the planet centre", largest)?;
        let axis = if world.x.abs() == largest {
            0
        } else if world.y.abs() == largest {
            1
        } else {
            2
        };
        let face = CubeFace::from_axis(axis, world[axis] > 0.0);
        let (i, j) = self
            .face_coords_in(face, world)
            .ok_or(MathError::NotPositive { name: "distance from the planet centre", value: largest })?;
        Ok((face, i, j))
    }

    /// Fractional in-face coordinates `(i, j)` of `world` in `face`'s frame
    /// (the inverse of [`Cubesphere::direction`] on that face), also for
    /// directions just past the face's edges; `None` unless `world` is in
    /// front of the face (positive along its normal).
    #[must_use]
    pub fn face_coords_in(&self, face: CubeFace, world: DVec3) -> Option<(f64, f64)> {
        let depth = world.dot(face.normal().as_dvec3());
        if depth.is_nan() || depth <= 0.0 {
            return None;
        }
        let on_plane = world / depth;
        let a = on_plane.dot(face.u_axis().as_dvec3());
        let b = on_plane.dot(face.v_axis().as_dvec3());
        let unwarp = |x: f64| match self.map {
            SphereMap::Gnomonic => x,
            SphereMap::EquiAngular => x.atan() / std::f64::consts::FRAC_PI_4,
        };
        let half = f64::from(self.resolution / 2);
        Some((unwarp(a) * half + half, unwarp(b) * half + half))
    }
}

/// `point − origin` as an f32 offset: a vertex relative to its chunk origin,
/// or a chunk origin relative to the camera for drawing.
///
/// The subtraction happens in f64, so the result is exact to f32 rounding of
/// the *difference*, however far from the planet centre both points are.
#[must_use]
pub fn relative_position(point: DVec3, origin: DVec3) -> glam::Vec3 {
    (point - origin).as_vec3()
}

/// Distance along unit `dir` from `origin` to the sphere of `radius` around
/// the planet centre, where the ray first enters it; `None` if it misses or
/// the sphere is behind.
#[must_use]
pub fn ray_sphere(origin: DVec3, dir: DVec3, radius: f64) -> Option<f64> {
    let b = origin.dot(dir);
    let c = origin.length_squared() - radius * radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 0.0).then_some(t)
}

/// The right-handed view basis `(forward, right, up)` for a view direction
/// and an up hint (neither need be unit; `up` need not be orthogonal): the
/// one place cameras, culling and pixel rays get their axes from.
#[must_use]
pub fn view_basis(forward: DVec3, up: DVec3) -> (DVec3, DVec3, DVec3) {
    let forward = forward.normalize();
    let right = forward.cross(up).normalize();
    (forward, right, right.cross(forward))
}
