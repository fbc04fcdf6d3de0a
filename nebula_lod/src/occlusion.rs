//! Occlusion by the ground around the eye: a horizon for every bearing.
//!
//! [`crate::Horizon`] hides what lies behind one sphere, the lowest ground
//! out to that sphere's own horizon: one valley or one coarse bound near
//! the eye lowers it all round. [`TerrainHorizon`] keeps, for each bearing,
//! how high the ground in front rises (as an elevation angle seen from the
//! eye, by distance), so a far leaf is hidden where nearer ground on its
//! bearings rises above its highest point: a plain's own horizon, a ridge
//! in front of a valley.
//!
//! Why it hides. Each leaf's surface, at its LOD and every finer one, cave
//! air included, lies above its bound's lowest radius (its *floor*): below
//! the floor, inside the leaf's patch, is rock. Take a point `Q` inside the
//! patch at angular distance φ from the eye's direction, on bearing β, below
//! the floor. A straight line of sight from the eye on bearing β whose
//! elevation is lower than `Q`'s passes below `Q`'s radius at φ, so it runs
//! through the rock under that leaf there; everything on that line farther
//! than φ is hidden. A leaf whose every point is lower, on every bearing it
//! spans, than such a point nearer than the leaf's nearest point, is hidden.
//!
//! The patches are spherical quads bounded by great circles (lines of one
//! lattice coordinate on a cube face), so the disc of the leaf's inscribed
//! radius ([`NodeBounds::inner_angular_radius`]) around its centre is inside
//! it; the horizon takes from each leaf the arc of that disc at the centre's
//! distance.
//!
//! From every eye within `margin` metres: a point of the segment from the
//! eye to a target moves by at most `margin` when the eye does, so each
//! floor is lowered by the margin and each disc shrunk by it.
//!
//! A renderer's floors are what it draws: the lowest point of a leaf's
//! meshes where it holds them (`RenderMesh::lowest_radius` in
//! `nebula_meshing`), its bounds elsewhere; a floor under the drawn
//! surface of a watertight picture is what makes a line of sight under it
//! cross that surface first. Being made of leaves all round (not of the
//! view's pixels), a horizon does not change when the camera turns.

use std::f64::consts::{FRAC_PI_2, TAU};

use nebula_math::DVec3;

use crate::NodeBounds;

/// Bearing bins all round the eye at most: a bin is about a third of a
/// typical occluder's arc ([`TerrainHorizon::new`]).
const MAX_BEARING_BINS: usize = 1 << 14;

/// Bearing bins all round the eye at least.
const MIN_BEARING_BINS: usize = 1 << 8;

/// The ground's horizon around an eye, bearing by bearing, built from the
/// floors of leaves in front ([`TerrainHorizon::new`]).
#[derive(Clone, Debug)]
pub struct TerrainHorizon {
    /// The eye's direction from the centre.
    up: DVec3,
    /// |eye|.
    distance: f64,
    /// Two unit vectors across `up`: bearing 0 and bearing π/2.
    east: DVec3,
    north: DVec3,
    /// How many bearing bins there are.
    bins: usize,
    /// The rises of the horizon, bin after bin: bin `b`'s are
    /// `bin_starts[b]..bin_starts[b + 1]`, ordered by angle, each higher
    /// than the one before. A rise: from `angles[i]` (radians from the
    /// eye's direction) on, lines of sight with an elevation slope below
    /// `slopes[i]` are blocked. (In two flat lists, not a list a bin: the
    /// clearance test's binary searches over every bin a leaf spans were
    /// most of its time, waiting on memory.)
    bin_starts: Vec<usize>,
    angles: Vec<f64>,
    slopes: Vec<f64>,
}

/// tan of the elevation angle, seen from distance `d` from the centre on
/// the axis, of a point at radius `r` and `angle` from the axis.
fn slope(d: f64, r: f64, angle: f64) -> f64 {
    slope_at(d, r, angle.sin_cos())
}

/// [`slope`] with the angle's sine and cosine already at hand.
fn slope_at(d: f64, r: f64, (sin, cos): (f64, f64)) -> f64 {
    (r * cos - d) / (r * sin)
}

impl TerrainHorizon {
    /// The horizon seen from every eye within `margin` metres of `eye`,
    /// made of the floors of `leaves` (node bounds with a floor radius at
    /// or under the node's own lowest surface: the radius under which its
    /// patch is rock as drawn; `None` where none is known yet). Every leaf
    /// sizes the bearing bins, so that a view's bins do not depend on
    /// which of its leaves have floors yet. Leaves past 90° from the eye
    /// add nothing.
    pub fn new(eye: DVec3, margin: f64, leaves: impl IntoIterator<Item = (NodeBounds, Option<f64>)>) -> Self {
        let distance = eye.length();
        let up = eye.normalize_or_zero();
        let east = up.any_orthonormal_vector();
        let north = up.cross(east);
        let mut horizon = Self {
            up,
            distance,
            east,
            north,
            bins: MIN_BEARING_BINS,
            bin_starts: vec![0; MIN_BEARING_BINS + 1],
            angles: Vec::new(),
            slopes: Vec::new(),
        };
        if !(distance > 0.0 && distance.is_finite() && margin.is_finite()) {
            return horizon;
        }
        let margin = margin.max(0.0);
        // Half the bearings over which the disc inscribed in `bounds`'
        // patch, shrunk by the margin at `radius`, runs at its centre's
        // angle from the eye (`angle`, its sine and cosine); `None` where
        // it adds nothing.
        let half_arc = |bounds: &NodeBounds, radius: f64, angle: f64, (sin, cos): (f64, f64)| {
            // A point of the segment moves by the margin at most; the
            // deepest such point is at 0.7 of the floor (within 90°).
            let inner = bounds.inner_angular_radius - 2.0 * margin / radius;
            if !(radius > 0.0 && inner > 0.0 && angle > inner && angle < FRAC_PI_2) {
                return None;
            }
            let cos_half = (inner.cos() - cos * cos) / (sin * sin);
            Some(cos_half.clamp(-1.0, 1.0).acos())
        };
        // The arcs of every leaf (for the bins' size, from its lowest
        // surface, whether or not it has a floor yet), and the floors'
        // rises as (angle, slope, bearing, half the arc). A leaf's angle
        // and its sine and cosine are found once for both.
        let mut halves = Vec::new();
        let mut rises: Vec<(f64, f64, f64, f64)> = Vec::new();
        for (bounds, floor) in leaves {
            let angle = horizon.angle_to(bounds.center_direction);
            if !(angle > 0.0 && angle < FRAC_PI_2) {
                // No arc from either radius (each needs `0 < inner < angle`).
                continue;
            }
            let sin_cos = angle.sin_cos();
            if let Some(half) = half_arc(&bounds, bounds.min_radius - margin, angle, sin_cos) {
                halves.push(half);
            }
            let Some(floor) = floor.map(|floor| floor - margin) else { continue };
            if let Some(half) = half_arc(&bounds, floor, angle, sin_cos) {
                let rise = slope_at(distance, floor, sin_cos);
                rises.push((angle, rise, horizon.bearing(bounds.center_direction), half));
            }
        }
        // Bins about a third of the median arc: an arc then covers two or
        // more whole bins (it counts only for bins it covers wholly), and a
        // far leaf spans a handful, not hundreds (a test visits each).
        if !halves.is_empty() {
            let middle = halves.len() / 2;
            let (_, median, _) = halves.select_nth_unstable_by(middle, f64::total_cmp);
            let wanted = TAU / (2.0 * *median / 3.0);
            let bins = if wanted.is_finite() { (wanted as usize).next_power_of_two() } else { MAX_BEARING_BINS };
            horizon.bins = bins.clamp(MIN_BEARING_BINS, MAX_BEARING_BINS);
        }
        rises.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let count = horizon.bins as i64;
        let width = TAU / count as f64;
        // Each bin's highest rise so far, and the rises kept, in order.
        let mut highest: Vec<Option<f64>> = vec![None; horizon.bins];
        let mut kept: Vec<(usize, f64, f64)> = Vec::new();
        for (angle, rise, bearing, half) in rises {
            // The bins wholly inside [bearing − half, bearing + half].
            let first = ((bearing - half) / width).ceil() as i64;
            let last = ((bearing + half) / width).floor() as i64 - 1;
            for bin in first..=last.min(first + count - 1) {
                let bin = bin.rem_euclid(count) as usize;
                if highest[bin].is_none_or(|slope| rise > slope) {
                    highest[bin] = Some(rise);
                    kept.push((bin, angle, rise));
                }
            }
        }
        // Bin by bin, each bin's in the order kept (by angle).
        let starts = &mut horizon.bin_starts;
        starts.clear();
        starts.resize(horizon.bins + 1, 0);
        for &(bin, _, _) in &kept {
            starts[bin + 1] += 1;
        }
        for bin in 0..horizon.bins {
            starts[bin + 1] += starts[bin];
        }
        let mut next = starts.clone();
        (horizon.angles, horizon.slopes) = (vec![0.0; kept.len()], vec![0.0; kept.len()]);
        for (bin, angle, rise) in kept {
            let at = next[bin];
            (horizon.angles[at], horizon.slopes[at]) = (angle, rise);
            next[bin] += 1;
        }
        horizon
    }

    /// Angle from the eye's direction to unit vector `direction`.
    fn angle_to(&self, direction: DVec3) -> f64 {
        self.up.angle_between(direction)
    }

    /// Bearing of unit vector `direction` around the eye, in [0, 2π).
    fn bearing(&self, direction: DVec3) -> f64 {
        direction.dot(self.north).atan2(direction.dot(self.east)).rem_euclid(TAU)
    }

    /// Whether the ground in front hides all of `bounds` from every eye the
    /// horizon was made for.
    #[must_use]
    pub fn hides(&self, bounds: &NodeBounds) -> bool {
        self.clearance(bounds).is_some_and(|clearance| clearance.hides(bounds.max_radius))
    }

    /// How high the ground in front rises over all of `bounds`' bearings,
    /// nearer than its nearest point: what tells, for any top, whether
    /// the bounds would be hidden with it ([`Clearance::hides`]). `None`
    /// where even its lowest surface is seen (so no top can be hidden),
    /// found without reading every bearing.
    #[must_use]
    pub fn clearance(&self, bounds: &NodeBounds) -> Option<Clearance> {
        let centre = self.angle_to(bounds.center_direction);
        let (near, far) = (centre - bounds.angular_radius, centre + bounds.angular_radius);
        // (NaN bounds fail this too.)
        if !(near > 0.0 && far < FRAC_PI_2) {
            return None;
        }
        let half = (bounds.angular_radius.sin() / centre.sin()).min(1.0).asin();
        let count = self.bins as i64;
        let width = TAU / count as f64;
        let bearing = self.bearing(bounds.center_direction);
        let first = ((bearing - half) / width).floor() as i64;
        let last = ((bearing + half) / width).floor() as i64;
        if last - first >= count {
            return None;
        }
        // Seen where a line of sight over some bin clears the lowest
        // surface: where a bin's highest rise nearer than the bounds is no
        // higher than the lowest surface's highest elevation, or where a
        // bin has none. Asked bin by bin, so a leaf seen (most of a
        // view's) is told at its first such bin.
        let mut clearance = Clearance { slope: f64::INFINITY, distance: self.distance, near, far };
        let lowest_surface = clearance.highest(bounds.min_radius);
        for bin in first..=last {
            let bin = bin.rem_euclid(count) as usize;
            let start = self.bin_starts[bin];
            let nearer = self.angles[start..self.bin_starts[bin + 1]].partition_point(|&angle| angle < near);
            if nearer == 0 || self.slopes[start + nearer - 1] <= lowest_surface {
                return None;
            }
            clearance.slope = clearance.slope.min(self.slopes[start + nearer - 1]);
        }
        Some(clearance)
    }
}

/// How high the ground in front of some bounds rises
/// ([`TerrainHorizon::clearance`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clearance {
    /// The lowest rise over the bounds' bearings (an elevation's tangent).
    slope: f64,
    /// The eye's distance from the centre.
    distance: f64,
    /// The bounds' nearest and farthest angle from the eye's direction.
    near: f64,
    far: f64,
}

impl Clearance {
    /// Whether the bounds, with their top at radius `top`, are hidden.
    #[must_use]
    pub fn hides(&self, top: f64) -> bool {
        self.highest(top) < self.slope
    }

    /// The highest elevation (its tangent) of a point of the bounds under
    /// radius `top`: at that radius, where that sphere's elevation peaks
    /// (its tangent point), clamped to the bounds' angles.
    fn highest(&self, top: f64) -> f64 {
        let peak = (top / self.distance).min(1.0).acos();
        slope(self.distance, top, peak.clamp(self.near, self.far))
    }
}
