//! How far a picture is from a reference picture of the same view: the
//! share of pixels whose surface differs by more than a pixel's worth.
//!
//! Fewer chunks and triangles must not come from drawing less than the
//! screen-space error τ promises. The measure: render a view at τ = 1 and
//! at a finer reference (τ = 0.25, say), read both depths back
//! ([`PlanetRenderer::read_view_depth`](crate::PlanetRenderer::read_view_depth)),
//! and count the pixels where they disagree. A pixel is *wrong* when its
//! distance is not within the range of the other picture's distances
//! around it (its 3×3 neighbourhood, widened by [`DEPTH_TOLERANCE`]), or
//! it shows sky and none of them does, either way round: so a surface
//! moved by up to a pixel on screen (what τ = 1 allows) is right, however
//! fast the distance changes from pixel to pixel (ground at a grazing
//! angle); a missing hill, a silhouette moved by two pixels or a hole is
//! wrong.
//!
//! The sea is drawn by the sky pass over the terrain's depth, not into it:
//! over the sea the depths compared are the sea bed's, which the streamer
//! draws coarse where the water hides it (`OpaqueSea`), so views over deep
//! water count sea-bed differences nobody sees. Measure over land, or with
//! a background (no sea drawn).
//!
//! It measures geometry, what τ bounds, not shading: a step a voxel tall
//! far away is thinner than a pixel, yet drawn or not it can colour a whole
//! row of pixels. Measured by colour (every channel within 6 %, same
//! neighbourhood) the 640×400 Earth land view came out *less* wrong at
//! τ = 4 (2.1 % of pixels) than at τ = 1 (3.0 %) against τ = 0.25: the
//! reference's one-voxel terraces are dark lines a pixel wide, missing at
//! τ = 4 and in other places at τ = 1. A measure that rewards drawing less
//! cannot guard against it.
//!
//! ```
//! use nebula_render::picture_error::depth_error;
//!
//! let size = (4, 3);
//! let reference = vec![100.0f32; 12];
//! let mut test = reference.clone();
//! test[5] = 150.0; // one pixel's surface half as far again
//! let error = depth_error(&test, &reference, size)?;
//! // The edge is left out: 2 of the 4 × 3 pixels are compared.
//! assert_eq!((error.wrong_pixels(), error.pixels), (1, 2));
//! assert_eq!(depth_error(&reference, &reference, size)?.wrong_pixels(), 0);
//! # Ok::<(), nebula_render::picture_error::PictureErrorError>(())
//! ```

/// How far, as a share of the distance, a surface may lie outside the
/// distances around it in the other picture and still count as the same:
/// 1 % (20 m two kilometres away, a metre at 100 m).
///
/// At a grazing angle that is more than it seems: 3° down through a 12°
/// lens at 640×400, ground's distance grows by about 1 % a row, so the
/// tolerance lets a surface move by a second pixel. [`depth_error_within`]
/// with 0 counts only what moved by more than the one pixel τ = 1 allows:
/// through that lens τ = 1 leaves 501 pixels wrong that way (378 with the
/// tolerance), τ = 1.5 leaves 12,141 (631 with it), nearly all of them
/// inside the ground (README, "Where τ = 1 stands").
pub const DEPTH_TOLERANCE: f32 = 0.01;

/// The pixels of a picture that differ from a reference by more than a
/// pixel's worth (see the module docs).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PictureError {
    /// Pixels compared: all but those on the picture's edge.
    pub pixels: u64,
    /// Whether each pixel is wrong in either picture, row by row from the
    /// top (edge pixels never are).
    pub wrong: Vec<bool>,
}

impl PictureError {
    /// How many pixels are wrong.
    #[must_use]
    pub fn wrong_pixels(&self) -> u64 {
        self.wrong.iter().filter(|wrong| **wrong).count() as u64
    }

    /// The share of the picture that is wrong, 0–1.
    #[must_use]
    pub fn share(&self) -> f64 {
        self.wrong_pixels() as f64 / self.pixels.max(1) as f64
    }

    /// `rgba` (RGBA8, the compared picture's size) with the wrong pixels
    /// red, to show where they are.
    #[must_use]
    pub fn marked(&self, rgba: &[u8]) -> Vec<u8> {
        let mut marked = rgba.to_vec();
        for (pixel, _) in marked.chunks_exact_mut(4).zip(&self.wrong).filter(|(_, wrong)| **wrong) {
            pixel.copy_from_slice(&[255, 0, 0, 255]);
        }
        marked
    }
}

/// Pictures that cannot be compared.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PictureErrorError {
    /// A depth list is not one value a pixel of the size.
    #[error("a {width}x{height} picture has {expected} depths, got {got}")]
    WrongLength {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Depths expected.
        expected: u64,
        /// Depths given.
        got: u64,
    },
}

/// Compares the view depths `test` and `reference` (metres, infinite
/// where nothing was drawn), both `size` pixels: see the module docs.
///
/// # Errors
/// [`PictureErrorError::WrongLength`] when a depth list is not one value a
/// pixel.
pub fn depth_error(test: &[f32], reference: &[f32], size: (u32, u32)) -> Result<PictureError, PictureErrorError> {
    depth_error_within(test, reference, size, DEPTH_TOLERANCE)
}

/// [`depth_error`] with `tolerance` (a share of the distance, 0 or more)
/// in place of [`DEPTH_TOLERANCE`]: 0 counts every surface that moved by
/// more than a pixel, however fast its distance changes from pixel to
/// pixel.
///
/// # Errors
/// As [`depth_error`].
pub fn depth_error_within(
    test: &[f32],
    reference: &[f32],
    size: (u32, u32),
    tolerance: f32,
) -> Result<PictureError, PictureErrorError> {
    let (width, height) = size;
    let expected = u64::from(width) * u64::from(height);
    for picture in [test, reference] {
        if picture.len() as u64 != expected {
            return Err(PictureErrorError::WrongLength { width, height, expected, got: picture.len() as u64 });
        }
    }
    let (w, h) = (width as usize, height as usize);
    // Whether `from`'s pixel (x, y) has a match within a pixel in `other`:
    // sky for sky; else a distance the finite distances around it span
    // (give or take the tolerance): ground at a grazing angle changes
    // distance by far more than the tolerance from one pixel to the next,
    // and a surface moved by part of a pixel lies between them.
    let matched = |from: &[f32], other: &[f32], x: usize, y: usize| {
        let depth = from[y * w + x];
        let around = (y.saturating_sub(1)..(y + 2).min(h))
            .flat_map(|oy| (x.saturating_sub(1)..(x + 2).min(w)).map(move |ox| other[oy * w + ox]));
        if !depth.is_finite() {
            return around.clone().any(|d| !d.is_finite());
        }
        let (low, high) = around
            .filter(|d| d.is_finite())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(low, high), d| (low.min(d), high.max(d)));
        low <= depth * (1.0 + tolerance) && high >= depth * (1.0 - tolerance)
    };
    // The pixels on the picture's edge have no neighbours past it to
    // bracket a surface moved across the edge: they are left out.
    let interior =
        |n: usize| (1..w.saturating_sub(1)).contains(&(n % w)) && (1..h.saturating_sub(1)).contains(&(n / w));
    let wrong = (0..w * h)
        .map(|n| interior(n) && (!matched(test, reference, n % w, n / w) || !matched(reference, test, n % w, n / w)))
        .collect();
    let inner = |side: u32| u64::from(side.saturating_sub(2));
    Ok(PictureError { pixels: inner(width) * inner(height), wrong })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `size` depth picture of ground 100 m away with a `side`-pixel
    /// square at `depth` whose top left corner is at `at`.
    fn square(size: (u32, u32), at: (u32, u32), side: u32, depth: f32) -> Vec<f32> {
        let mut picture = Vec::new();
        for y in 0..size.1 {
            for x in 0..size.0 {
                let inside = (at.0..at.0 + side).contains(&x) && (at.1..at.1 + side).contains(&y);
                picture.push(if inside { depth } else { 100.0 });
            }
        }
        picture
    }

    /// Moved by a pixel or within the tolerance is right; moved by two
    /// pixels, missing, at another distance or sky is wrong, whichever
    /// picture has the feature.
    #[test]
    fn a_pixel_of_movement_is_right_and_more_is_wrong() {
        let size = (32, 24);
        let reference = square(size, (10, 8), 6, 50.0);
        let check = |test: &[f32]| depth_error(test, &reference, size).unwrap().wrong_pixels();
        assert_eq!(check(&reference), 0);
        assert_eq!(check(&square(size, (11, 9), 6, 50.0)), 0, "a pixel diagonally");
        assert_eq!(check(&square(size, (10, 8), 6, 50.4)), 0, "within 1 %");
        // Two pixels right: the reference's first column and the moved
        // square's last (nothing of the other's square within one pixel),
        // and the inner 4 of the columns beside them, whose neighbourhoods
        // in the other picture are all square or all ground: 6 + 6 + 4 + 4.
        assert_eq!(check(&square(size, (12, 8), 6, 50.0)), 20);
        // Missing: every pixel of the reference's square (nothing 50 m
        // away in the test).
        let missing = square(size, (10, 8), 6, 100.0);
        assert_eq!(check(&missing), 36);
        assert_eq!(check(&square(size, (10, 8), 6, 60.0)), 36, "10 m further");
        assert_eq!(check(&square(size, (10, 8), 6, f32::INFINITY)), 36, "a hole to the sky");
        // Either way round.
        assert_eq!(depth_error(&reference, &missing, size).unwrap().wrong_pixels(), 36);
        let error = depth_error(&missing, &reference, size).unwrap();
        assert!((error.share() - 36.0 / 660.0).abs() < 1e-12);
    }

    /// A `size` depth picture of ground at a grazing angle, `near` metres
    /// away in its first row and `growth` times further each row after,
    /// moved down by `shift` rows.
    fn ramp(size: (u32, u32), near: f32, growth: f32, shift: f32) -> Vec<f32> {
        (0..size.0 * size.1).map(|n| near * growth.powf((n / size.0) as f32 + shift)).collect()
    }

    /// Ground at a grazing angle, 10 % further each row: moved by half a
    /// row or one row it is right (its distance lies between those around
    /// it), by three rows wrong.
    #[test]
    fn grazing_ground_moved_by_part_of_a_pixel_is_right() {
        let size = (8, 40);
        let ramp = |shift: f32| ramp(size, 100.0, 1.1, shift);
        let reference = ramp(0.0);
        let wrong = |shift| depth_error(&ramp(shift), &reference, size).unwrap().wrong_pixels();
        assert_eq!(wrong(0.5), 0);
        assert_eq!(wrong(1.0), 0);
        // Every pixel compared: 6 × 38.
        assert_eq!(wrong(3.0), 6 * 38);
    }

    /// Ground 1 % further each row (3° down through a 12° lens): moved by
    /// a pixel it is right with or without the tolerance; by two rows the
    /// 1 % tolerance still calls it right, and only the measure without it
    /// counts the second row's movement.
    #[test]
    fn the_depth_tolerance_lets_grazing_ground_move_a_second_pixel() {
        let size = (8, 40);
        let ramp = |shift: f32| ramp(size, 2000.0, 1.009, shift);
        let reference = ramp(0.0);
        let wrong = |shift: f32, tolerance: f32| {
            depth_error_within(&ramp(shift), &reference, size, tolerance).unwrap().wrong_pixels()
        };
        assert_eq!((wrong(1.0, DEPTH_TOLERANCE), wrong(1.0, 0.0)), (0, 0));
        assert_eq!(wrong(2.0, DEPTH_TOLERANCE), 0);
        assert_eq!(wrong(2.0, 0.0), 6 * 38);
        assert_eq!(depth_error(&ramp(2.0), &reference, size).unwrap(), {
            depth_error_within(&ramp(2.0), &reference, size, DEPTH_TOLERANCE).unwrap()
        });
    }

    #[test]
    fn pictures_of_the_wrong_size_are_refused() {
        let picture = vec![1.0f32; 6];
        assert!(depth_error(&picture, &picture, (3, 2)).is_ok());
        assert_eq!(
            depth_error(&picture, &picture[..5], (3, 2)),
            Err(PictureErrorError::WrongLength { width: 3, height: 2, expected: 6, got: 5 })
        );
        assert!(depth_error(&picture, &picture, (4, 2)).is_err());
    }
}
