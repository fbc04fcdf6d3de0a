//! Maps from the cube surface onto the unit sphere.
//!
//! Both maps are written per component on the cube coordinates
//! `t ∈ [−1, 1]³` (one component is ±1), never per face. A point on a face
//! edge therefore maps the same way whichever face asks, and the maps are
//! continuous across edges by construction.
//!
//! Distortion on one face split into 256 × 256 cells (area ratio from
//! [`area_distortion`]; `cargo test -p nebula_math area_distortion --
//! --nocapture` prints it; edge and aspect figures from the same grid):
//!
//! | map | max/min cell area | max/min cell edge | worst cell aspect |
//! |---|---|---|---|
//! | [`SphereMap::Gnomonic`] (normalise the cube point) | 5.16 | 2.12 | 1.41 |
//! | Nowell's "spherified cube" `x·√(1 − y²/2 − z²/2 + y²z²/3)` (not offered) | 1.32 | 1.73 | 1.72 |
//! | [`SphereMap::EquiAngular`] (the default) | 1.41 | 1.41 | 1.41 |
//!
//! Equi-angular is the default although Nowell's map spreads area slightly
//! more evenly: its cells are closer to squares (aspect 1.41 vs 1.72) and its
//! longest cell edge is only 1.41× the shortest (vs 1.73×). Voxel columns
//! stand on these cells, so the longest edge sets the LOD error bound and the
//! aspect sets how far voxels are from cubes. It also has a closed-form
//! inverse (`atan`), which edits and cameras need.

use glam::DVec3;

/// A map from the cube surface to the unit sphere.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SphereMap {
    /// Normalise the cube point. Simple, but cells near face centres are
    /// about 5× larger than at the corners.
    Gnomonic,
    /// Equi-angular cubemap: `tan(t·π/4)` per component, then normalise.
    #[default]
    EquiAngular,
}

impl SphereMap {
    /// The unit-sphere direction of cube coordinates `t` (each component in
    /// `[−1, 1]`, at least one of them ±1).
    ///
    /// The arithmetic depends on `t` alone, in a fixed order, so equal `t`
    /// give bit-identical directions.
    #[must_use]
    pub fn direction(self, t: DVec3) -> DVec3 {
        DVec3::new(self.warp(t.x), self.warp(t.y), self.warp(t.z)).normalize()
    }

    /// One cube coordinate (in `[−1, 1]`) as this map warps it before
    /// normalising: itself for gnomonic, `tan(t·π/4)` for equi-angular.
    /// Odd, so `warp(−t)` is `−warp(t)` bit for bit.
    #[must_use]
    pub fn warp(self, t: f64) -> f64 {
        match self {
            SphereMap::Gnomonic => t,
            SphereMap::EquiAngular => equi_angular(t),
        }
    }
}

/// `tan(t·π/4)`, odd and exactly ±1 at t = ±1 (f64 `tan(π/4)` is 1 − 2⁻⁵³).
fn equi_angular(t: f64) -> f64 {
    let magnitude = t.abs();
    let warped = if magnitude >= 1.0 { 1.0 } else { (magnitude * std::f64::consts::FRAC_PI_4).tan() };
    warped.copysign(t)
}

/// Largest over smallest cell area of one cube face mapped by `map`, for a
/// face split into `cells_per_edge`² cells (each cell measured as the two
/// flat triangles between its four mapped corners).
#[must_use]
pub fn area_distortion(map: SphereMap, cells_per_edge: u32) -> f64 {
    area_distortion_of(|t| map.direction(t), cells_per_edge)
}

fn area_distortion_of(map: impl Fn(DVec3) -> DVec3, cells_per_edge: u32) -> f64 {
    let n = f64::from(cells_per_edge.max(1));
    let corner = |a: u32, b: u32| {
        // Face +Z: t = (2a/n − 1, 2b/n − 1, 1).
        map(DVec3::new(2.0 * f64::from(a) / n - 1.0, 2.0 * f64::from(b) / n - 1.0, 1.0))
    };
    let mut smallest = f64::INFINITY;
    let mut largest = 0.0_f64;
    for a in 0..cells_per_edge.max(1) {
        for b in 0..cells_per_edge.max(1) {
            let (p00, p10, p01, p11) = (corner(a, b), corner(a + 1, b), corner(a, b + 1), corner(a + 1, b + 1));
            let area = 0.5 * (p10 - p00).cross(p11 - p00).length() + 0.5 * (p11 - p00).cross(p01 - p00).length();
            smallest = smallest.min(area);
            largest = largest.max(area);
        }
    }
    largest / smallest
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Nowell's map, measured for comparison only.
    fn spherified(t: DVec3) -> DVec3 {
        let sq = t * t;
        DVec3::new(
            t.x * (1.0 - sq.y / 2.0 - sq.z / 2.0 + sq.y * sq.z / 3.0).sqrt(),
            t.y * (1.0 - sq.z / 2.0 - sq.x / 2.0 + sq.z * sq.x / 3.0).sqrt(),
            t.z * (1.0 - sq.x / 2.0 - sq.y / 2.0 + sq.x * sq.y / 3.0).sqrt(),
        )
    }

    #[test]
    fn area_distortion_of_the_three_maps() {
        let gnomonic = area_distortion(SphereMap::Gnomonic, 256);
        let spherified = area_distortion_of(spherified, 256);
        let equi = area_distortion(SphereMap::EquiAngular, 256);
        println!("max/min cell area: gnomonic {gnomonic:.3}, spherified {spherified:.3}, equi-angular {equi:.3}");
        // Gnomonic: 3√3 in the limit (cell at the centre vs at a corner).
        assert!((gnomonic - 3.0 * 3.0_f64.sqrt()).abs() < 0.05, "{gnomonic}");
        // Equi-angular: √2 in the limit (equal angles, corner cells sheared).
        assert!((equi - 2.0_f64.sqrt()).abs() < 0.01, "{equi}");
        assert!((spherified - 1.32).abs() < 0.01, "{spherified}");
    }

    #[test]
    fn maps_land_on_the_unit_sphere_and_are_odd() {
        for map in [SphereMap::Gnomonic, SphereMap::EquiAngular] {
            for t in [DVec3::new(1.0, 0.3, -0.7), DVec3::new(-0.2, -1.0, 1.0), DVec3::new(0.0, 0.0, 1.0)] {
                let d = map.direction(t);
                assert!((d.length() - 1.0).abs() < 1e-15, "{map:?} {t} -> {d}");
                assert_eq!(map.direction(-t), -d, "{map:?} must be odd");
            }
        }
    }

    #[test]
    fn equi_angular_is_exact_at_the_face_boundary() {
        assert_eq!(equi_angular(1.0), 1.0);
        assert_eq!(equi_angular(-1.0), -1.0);
        assert_eq!(equi_angular(0.0), 0.0);
        // Equal angles: t = 1/3 is 15° from the face centre.
        assert!((equi_angular(1.0 / 3.0) - 15f64.to_radians().tan()).abs() < 1e-15);
    }
}
