//! The crack oracle: which background pixels of a frame are holes.
//!
//! A frame is rendered over a sentinel background colour. A background pixel
//! is a crack when
//!
//! 1. **sphere rule**: the ray through its centre meets the sphere of the
//!    lowest surface under the chunks drawn — the ground must cover it; or
//! 2. **geometry rule**: the ray hits a triangle that frame drew, at least
//!    [`ROBUST_MARGIN_PX`] inside its edges. The triangles are the drawn
//!    meshes exactly as the vertex shaders place them (morph and draw-time
//!    skirts included; [`RenderMesh::drawn_triangles`](nebula_meshing::RenderMesh::drawn_triangles) is the
//!    shaders' CPU twin), intersected in f64. A front face the rasteriser
//!    should have covered is a pinhole; a back face means the ray got
//!    inside the ground without crossing its surface.
//!
//! The margin keeps rays that graze a silhouette edge (where rasteriser
//! and f64 may legitimately disagree by rounding) from counting. Candidate
//! chunks and triangles come from `obvhs` BVHs (f32, padded), the exact
//! test is f64.

use std::time::Duration;

use glam::Vec3A;
use nebula_lod::Camera;
use nebula_math::{DVec3, ray_sphere};
use nebula_meshing::{ChunkDraw, FrameDraw};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::{build_bvh2, build_bvh2_from_tris};
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use rayon::prelude::*;

use nebula_meshing::RenderMesh;

/// How far inside a triangle, in pixels, a ray must pass for its hit to
/// count: well above the rasteriser's f32 rounding, far below a pixel.
pub const ROBUST_MARGIN_PX: f64 = 0.05;

/// What the oracle found in one frame.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CrackCount {
    /// Background pixels that are cracks (either rule).
    pub cracks: usize,
    /// Of which by the sphere rule.
    pub sphere_cracks: usize,
    /// Of which by the geometry rule only.
    pub geometry_cracks: usize,
    /// Pixels whose ray meets the sentinel sphere.
    pub planet_pixels: usize,
    /// Background pixels cast against the drawn triangles.
    pub rays_cast: usize,
    /// Triangles the geometry rule tested against (degenerate ones left out).
    pub triangles: usize,
    /// Up to 8 crack pixels, (x, y).
    pub samples: Vec<(u32, u32)>,
}

/// What a frame drew, as the oracle needs it.
pub struct DrawnGeometry<'a> {
    /// The meshes drawn with their per-chunk draw constants.
    pub drawn: Vec<(&'a RenderMesh, ChunkDraw)>,
    /// The shader's frame constants.
    pub frame: FrameDraw,
    /// The lowest surface radius under the drawn chunks.
    pub sentinel_radius: f64,
}

/// Counts the cracks of `rgba` (RGBA8, row 0 at the top) drawn over
/// `background` from `camera` with `fov_y_degrees`, given what the frame
/// drew.
#[must_use]
pub fn count_cracks(
    rgba: &[u8],
    size: (u32, u32),
    background: [u8; 3],
    camera: &Camera,
    fov_y_degrees: f64,
    geometry: &DrawnGeometry<'_>,
) -> CrackCount {
    let (drawn, frame, sentinel_radius) = (&geometry.drawn, &geometry.frame, geometry.sentinel_radius);
    let (width, height) = size;
    let eye = camera.position;
    let ray = |pixel: u32| camera.pixel_ray(fov_y_degrees, size, (pixel % width, pixel / width));
    let is_background = |pixel: u32| {
        let i = pixel as usize * 4;
        rgba.get(i..i + 3).is_some_and(|p| p == background)
    };
    let mut count = CrackCount::default();
    let mut candidates = Vec::new();
    for pixel in 0..width * height {
        let dir = ray(pixel);
        let meets_sphere = ray_sphere(eye, dir, sentinel_radius).is_some();
        count.planet_pixels += usize::from(meets_sphere);
        if !is_background(pixel) {
            continue;
        }
        if meets_sphere {
            count.sphere_cracks += 1;
            if count.samples.len() < 8 {
                count.samples.push((pixel % width, pixel / width));
            }
        } else {
            candidates.push(pixel);
        }
    }
    if !candidates.is_empty() && !drawn.is_empty() {
        let hits = geometry_hits(drawn, frame, &candidates, &ray, &mut count);
        count.geometry_cracks = hits.len();
        for pixel in hits {
            if count.samples.len() < 8 {
                count.samples.push((pixel % width, pixel / width));
            }
        }
    }
    count.cracks = count.sphere_cracks + count.geometry_cracks;
    count
}

/// A chunk's drawn triangles (placed as the vertex shader places them) and
/// their BVH.
struct ChunkTriangles {
    exact: Vec<[DVec3; 3]>,
    bvh: obvhs::bvh2::Bvh2,
}

/// The candidate pixels whose ray robustly hits a drawn triangle. Two
/// levels, so memory stays proportional to what the rays touch: a BVH over
/// the drawn chunks' boxes picks the chunks along each ray; a chunk's
/// triangles get a BVH of their own the first time a ray reaches it; every
/// triangle along the ray is tested exactly, and the ray stops at the
/// first robust hit.
fn geometry_hits(
    drawn: &[(&RenderMesh, ChunkDraw)],
    frame: &FrameDraw,
    candidates: &[u32],
    ray: &(impl Fn(u32) -> DVec3 + Sync),
    count: &mut CrackCount,
) -> Vec<u32> {
    // Each chunk's box, over the vertices it draws (chunks that draw
    // nothing left out).
    let boxes: Vec<(usize, Aabb, f64)> = drawn
        .par_iter()
        .enumerate()
        .filter_map(|(n, (mesh, chunk))| {
            let (mut min, mut max, mut top) = (DVec3::INFINITY, DVec3::NEG_INFINITY, 0.0_f64);
            let eye = frame.eye();
            for p in mesh.drawn_triangles(frame, chunk).into_iter().flatten() {
                min = min.min(p);
                max = max.max(p);
                top = top.max((p + eye).length());
            }
            if !(min.is_finite() && max.is_finite()) {
                return None;
            }
            // Padded so that f32 rounding never drops a box.
            let pad = DVec3::splat(1e-3) + (max - min) * 1e-6 + min.abs().max(max.abs()) * 1e-6;
            Some((n, Aabb::new((min - pad).as_vec3a(), (max + pad).as_vec3a()), top))
        })
        .collect();
    let Some(top) = boxes.iter().map(|b| b.2).reduce(f64::max) else { return Vec::new() };
    // Rays that pass above every drawn vertex hit nothing.
    let eye = frame.eye();
    let rays: Vec<u32> =
        candidates.iter().copied().filter(|&p| ray_sphere(eye, ray(p), top * (1.0 + 1e-9)).is_some()).collect();
    count.rays_cast = rays.len();
    if rays.is_empty() {
        return Vec::new();
    }
    let aabbs: Vec<Aabb> = boxes.iter().map(|b| b.1).collect();
    let chunk_bvh = build_bvh2(&aabbs, BvhBuildParams::fast_build(), &mut Duration::default());
    let built: Vec<std::sync::OnceLock<Option<ChunkTriangles>>> =
        (0..boxes.len()).map(|_| std::sync::OnceLock::new()).collect();
    let triangles_of = |slot: usize| {
        built[slot]
            .get_or_init(|| {
                let (mesh, chunk) = &drawn[boxes[slot].0];
                let exact: Vec<[DVec3; 3]> = mesh
                    .drawn_triangles(frame, chunk)
                    .into_iter()
                    .filter(|t| (t[1] - t[0]).cross(t[2] - t[0]).length_squared() > 0.0)
                    .collect();
                if exact.is_empty() {
                    return None;
                }
                let tris: Vec<Triangle> = exact
                    .iter()
                    .map(|t| Triangle { v0: t[0].as_vec3a(), v1: t[1].as_vec3a(), v2: t[2].as_vec3a() })
                    .collect();
                let bvh = build_bvh2_from_tris(&tris, BvhBuildParams::fast_build(), &mut Duration::default());
                Some(ChunkTriangles { exact, bvh })
            })
            .as_ref()
    };
    let k = frame.k;
    let hits: Vec<u32> = rays
        .par_iter()
        .copied()
        .filter(|&pixel| {
            let dir = ray(pixel);
            let query = Ray::new(Vec3A::ZERO, dir.as_vec3a(), 0.0, f32::INFINITY);
            let mut robust = false;
            let mut hit = RayHit::none();
            chunk_bvh.ray_traverse(query, &mut hit, |_, id| {
                if robust {
                    return 0.0;
                }
                let Some(chunk) = triangles_of(chunk_bvh.primitive_indices[id] as usize) else {
                    return f32::INFINITY;
                };
                let mut inner = RayHit::none();
                chunk.bvh.ray_traverse(query, &mut inner, |_, t| {
                    let triangle = &chunk.exact[chunk.bvh.primitive_indices[t] as usize];
                    if exact_hit(triangle, dir).is_some_and(|(_, margin)| margin * k > ROBUST_MARGIN_PX) {
                        robust = true;
                        return 0.0;
                    }
                    // Never shrink the ray: every triangle along it counts.
                    f32::INFINITY
                });
                // Stop at the first robust hit (a zero-length ray ends the walk).
                if robust { 0.0 } else { f32::INFINITY }
            });
            robust
        })
        .collect();
    count.triangles = built.iter().filter_map(|b| b.get().and_then(Option::as_ref)).map(|c| c.exact.len()).sum();
    hits
}

/// Möller–Trumbore in f64 from the origin along `dir`, either side: the
/// distance, and how far inside the triangle the ray passes as seen from
/// the origin — the angle (radians) between `dir` and the nearest of the
/// planes through the origin and an edge, which is what a rasteriser's edge
/// functions measure on the screen.
fn exact_hit(v: &[DVec3; 3], dir: DVec3) -> Option<(f64, f64)> {
    let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let s = -v[0];
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let w = dir.dot(q) / det;
    if u < 0.0 || w < 0.0 || u + w > 1.0 {
        return None;
    }
    let t = e2.dot(q) / det;
    if t <= 0.0 {
        return None;
    }
    let inside = (0..3)
        .map(|i| {
            let normal = v[i].cross(v[(i + 1) % 3]).normalize_or_zero();
            dir.dot(normal).abs().min(1.0).asin()
        })
        .fold(f64::INFINITY, f64::min);
    Some((t, inside))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_hit_measures_the_margin() {
        // A triangle 10 m ahead, the ray through its middle and near an edge.
        let tri = [DVec3::new(-1.0, -1.0, 10.0), DVec3::new(1.0, -1.0, 10.0), DVec3::new(0.0, 1.0, 10.0)];
        let (t, margin) = exact_hit(&tri, DVec3::Z).expect("hit");
        assert!((t - 10.0).abs() < 1e-12);
        // The nearest edges are the slanted ones, 1/√5 m off the centre at
        // 10 m.
        assert!((margin - (1.0 / 5f64.sqrt() / 10.0).atan()).abs() < 1e-6, "{margin}");
        let near_edge = DVec3::new(0.0, -0.999, 10.0).normalize();
        let (_, margin) = exact_hit(&tri, near_edge).expect("hit");
        assert!(margin < 1e-3 / 10.0 * 1.01, "{margin}");
        // Seen nearly edge-on, a hit deep inside the triangle's plane is
        // close to an edge on the screen: a long strip 1 m below the eye.
        let strip = [DVec3::new(-1.0, -1.0, 10.0), DVec3::new(1.0, -1.0, 10.0), DVec3::new(0.0, -1.0, 1000.0)];
        let dir = DVec3::new(0.0, -1.0, 500.0).normalize();
        let (_, margin) = exact_hit(&strip, dir).expect("hit");
        let in_plane = 0.5; // the strip is half a metre wide there
        assert!(margin < in_plane / 500.0, "grazing margin {margin}");
        assert!(exact_hit(&tri, DVec3::new(3.0, 0.0, 10.0).normalize()).is_none());
        assert!(exact_hit(&tri, -DVec3::Z).is_none(), "behind the eye");
    }
}
