//! Where the sun is: a world direction, placed by elevation and azimuth at
//! the camera's place on the planet (so any view can be lit by day or at
//! dusk), and moved by the window's `[` and `]` keys.

use nebula_math::DVec3;

/// The sun of the first version, fixed in the world: by day over much of
/// the planet, at dusk or night elsewhere.
#[must_use]
pub fn default_sun() -> DVec3 {
    DVec3::new(0.4, 0.8, 0.45).normalize()
}

/// Bad sun input.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SunError {
    /// A NaN or infinite value.
    #[error("the sun's {name} is not finite ({value})")]
    NonFinite {
        /// Which value.
        name: &'static str,
        /// It.
        value: f64,
    },
    /// Elevation outside −90°..=90°.
    #[error("sun elevation {0}° is outside -90..=90")]
    Elevation(f64),
    /// The eye at the planet centre has no up.
    #[error("the eye is at the planet centre: no horizon to place the sun over")]
    NoHorizon,
}

/// The unit direction towards a sun `elevation_deg` above the horizon at
/// `eye` (radial up), `azimuth_deg` clockwise seen from above from the
/// view direction `forward` (0: ahead, 90: to the right, 180: behind).
/// Looking straight up or down, "ahead" is any horizontal direction.
///
/// # Errors
/// [`SunError`] for NaN or infinite input, an elevation beyond ±90° or an
/// eye at the planet centre.
pub fn sun_direction(eye: DVec3, forward: DVec3, elevation_deg: f64, azimuth_deg: f64) -> Result<DVec3, SunError> {
    for (name, value) in [("elevation", elevation_deg), ("azimuth", azimuth_deg)]
        .into_iter()
        .chain(eye.to_array().map(|v| ("eye", v)))
        .chain(forward.to_array().map(|v| ("view direction", v)))
    {
        if !value.is_finite() {
            return Err(SunError::NonFinite { name, value });
        }
    }
    if !(-90.0..=90.0).contains(&elevation_deg) {
        return Err(SunError::Elevation(elevation_deg));
    }
    let up = eye.try_normalize().ok_or(SunError::NoHorizon)?;
    // Looking (nearly) straight up or down the horizontal part is rounding.
    let level = forward - up * forward.dot(up);
    let ahead = if level.length() > 1e-9 * forward.length() { level.normalize() } else { up.any_orthonormal_vector() };
    let right = ahead.cross(up);
    let (azimuth, elevation) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let horizontal = ahead * azimuth.cos() + right * azimuth.sin();
    Ok((horizontal * elevation.cos() + up * elevation.sin()).normalize())
}

/// `sun` raised by `degrees` (lowered when negative) at `eye`: turned about
/// the horizontal axis across it, through the zenith if need be.
#[must_use]
pub fn raise_sun(sun: DVec3, eye: DVec3, degrees: f64) -> DVec3 {
    let up = eye.normalize_or_zero();
    let axis = sun.cross(up).try_normalize().unwrap_or_else(|| sun.any_orthonormal_vector());
    // Rodrigues' rotation about `axis`.
    let (sin, cos) = degrees.to_radians().sin_cos();
    (sun * cos + axis.cross(sun) * sin + axis * axis.dot(sun) * (1.0 - cos)).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sun_is_placed_over_the_local_horizon() {
        // An eye over the +X side of a planet, looking along +Y.
        let (eye, forward) = (DVec3::new(7e6, 0.0, 0.0), DVec3::new(0.1, 1.0, 0.0));
        let zenith = sun_direction(eye, forward, 90.0, 0.0).unwrap();
        assert!(zenith.distance(DVec3::X) < 1e-12);
        let ahead = sun_direction(eye, forward, 0.0, 0.0).unwrap();
        assert!(ahead.distance(DVec3::Y) < 1e-12);
        let right = sun_direction(eye, forward, 0.0, 90.0).unwrap();
        assert!(right.distance(DVec3::Y.cross(DVec3::X)) < 1e-12, "{right}");
        let low = sun_direction(eye, forward, 30.0, 180.0).unwrap();
        assert!((low.dot(DVec3::X) - 0.5).abs() < 1e-12 && low.y < 0.0);
        // Straight down: still a sun at the asked height.
        let down = sun_direction(eye, -DVec3::X, 10.0, 0.0).unwrap();
        assert!((down.dot(DVec3::X) - 10f64.to_radians().sin()).abs() < 1e-12, "{down}");
        // Raising by 20° from 10° gives 30°, lowering crosses the horizon.
        let raised = raise_sun(sun_direction(eye, forward, 10.0, 40.0).unwrap(), eye, 20.0);
        assert!((raised.dot(DVec3::X) - 0.5).abs() < 1e-12);
        assert!(raise_sun(raised, eye, -40.0).dot(DVec3::X) < 0.0);
    }

    #[test]
    fn bad_sun_input_is_an_error() {
        let (eye, forward) = (DVec3::new(7e6, 0.0, 0.0), DVec3::Y);
        assert_eq!(sun_direction(eye, forward, 91.0, 0.0), Err(SunError::Elevation(91.0)));
        assert!(matches!(
            sun_direction(eye, forward, f64::NAN, 0.0),
            Err(SunError::NonFinite { name: "elevation", .. })
        ));
        assert!(matches!(sun_direction(eye, forward, 10.0, f64::INFINITY), Err(SunError::NonFinite { .. })));
        assert!(matches!(sun_direction(DVec3::ZERO, forward, 10.0, 0.0), Err(SunError::NoHorizon)));
        assert!(matches!(sun_direction(eye, DVec3::NAN, 10.0, 0.0), Err(SunError::NonFinite { .. })));
    }
}
