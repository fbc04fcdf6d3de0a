//! Ray picking on the LOD-0 voxel lattice.
//!
//! A voxel is bounded by two spheres (its layers) and four planes through
//! the planet centre (lattice lines are great circles, see
//! `Cubesphere::lattice_plane_normal`), so a ray can be walked from voxel to
//! voxel exactly, like a 3-D DDA on a grid: in each voxel, the nearest of
//! the six walls the ray leaves through says which neighbour comes next
//! (across a cube-face edge through `CubeFace::wrap_cell`). No sampling
//! step, so thin walls and corners are never skipped.
//!
//! Empty space is skipped a chunk column at a time, first LOD-3 columns
//! (256 cells across), then LOD-0 ones: where the ray's lowest point inside
//! a column stays above the column's [`SurfaceBounds::max_radius`] (which
//! [`EditedSource`](crate::EditedSource) raises for every edit under it),
//! no voxel of it is read.

use std::collections::HashMap;

use nebula_math::{CubeFace, DVec3, FaceDirection, ray_sphere};

use crate::{CHUNK_SIZE, ChunkColumn, SurfaceBounds, VoxelCoord, VoxelError, VoxelSource};

/// The first solid voxel along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelHit {
    /// The solid LOD-0 voxel hit.
    pub voxel: VoxelCoord,
    /// The side of `voxel` the ray entered through, in chunk axes; `None`
    /// when the ray starts inside it.
    pub face: Option<FaceDirection>,
    /// Unit normal of that side, pointing out of the voxel (towards the
    /// ray's origin when the ray starts inside: the reversed direction).
    pub normal: DVec3,
    /// Where the ray enters the voxel, world metres.
    pub point: DVec3,
    /// Distance from the ray's origin to `point`, metres.
    pub distance: f64,
    /// The voxel the ray was in just before (where a placed block goes);
    /// `None` when the ray starts inside `voxel`.
    pub before: Option<VoxelCoord>,
}

/// The first solid LOD-0 voxel of `source` (edits included when `source`
/// is an [`EditedSource`](crate::EditedSource)) along the ray from `origin`
/// towards `direction`, within `max_distance` metres.
///
/// # Errors
/// [`VoxelError::NonFinite`] for NaN or infinite input,
/// [`VoxelError::OutOfRange`] for a zero direction or a negative distance,
/// and the source's errors.
pub fn pick<S: VoxelSource + ?Sized>(
    source: &S,
    origin: DVec3,
    direction: DVec3,
    max_distance: f64,
) -> Result<Option<VoxelHit>, VoxelError> {
    for (name, value) in [("ray origin", origin), ("ray direction", direction)] {
        if let Some(&bad) = value.to_array().iter().find(|v| !v.is_finite()) {
            return Err(VoxelError::NonFinite { name, value: bad });
        }
    }
    if max_distance.is_nan() || max_distance < 0.0 {
        return Err(VoxelError::OutOfRange { name: "max distance", requirement: "at least 0", value: max_distance });
    }
    let dir = direction.normalize_or_zero();
    if dir == DVec3::ZERO {
        return Err(VoxelError::OutOfRange { name: "ray direction", requirement: "non-zero", value: 0.0 });
    }
    Walker::new(source, origin, dir, max_distance).run()
}

/// Which wall of the current voxel the ray leaves through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Wall {
    Side(FaceDirection),
    Top,
    Bottom,
}

struct Walker<'a, S: ?Sized> {
    source: &'a S,
    origin: DVec3,
    dir: DVec3,
    max_distance: f64,
    per_edge: i64,
    bounds: HashMap<ChunkColumn, SurfaceBounds>,
}

impl<'a, S: VoxelSource + ?Sized> Walker<'a, S> {
    fn new(source: &'a S, origin: DVec3, dir: DVec3, max_distance: f64) -> Self {
        let per_edge = i64::from(source.layout().voxels_per_edge(0));
        Self { source, origin, dir, max_distance, per_edge, bounds: HashMap::new() }
    }

    fn run(mut self) -> Result<Option<VoxelHit>, VoxelError> {
        let layout = *self.source.layout();
        // Start where the ray enters the highest terrain (every face root's
        // bounds), or at the origin when it is below that already.
        let mut top = f64::NEG_INFINITY;
        for face in CubeFace::ALL {
            let root = ChunkColumn { face, lod: layout.max_lod(), x: 0, y: 0 };
            top = top.max(self.source.surface_bounds(root)?.max_radius);
        }
        let mut t = 0.0;
        if self.origin.length() > top {
            match ray_sphere(self.origin, self.dir, top) {
                Some(entry) => t = entry,
                None => return Ok(None),
            }
        }
        let start = layout.voxel_at(self.at(t))?;
        let mut cell = (start.face, i64::from(start.i), i64::from(start.j), i64::from(start.h));
        let mut entered: Option<Wall> = None;
        let mut before = None;
        while t <= self.max_distance {
            let (face, i, j, h) = cell;
            // First a coarse column (256 LOD-0 cells across): its bounds
            // hold every LOD-0 voxel in it, edits included.
            let coarse_lod = COARSE_SKIP_LOD.min(layout.max_lod());
            let shift = u32::from(coarse_lod) + CHUNK_SIZE.trailing_zeros();
            let coarse = ChunkColumn { face, lod: coarse_lod, x: (i >> shift) as u32, y: (j >> shift) as u32 };
            let coarse_bounds = self.bounds_of(coarse)?;
            if coarse_lod > 0 && h > coarse_bounds.max_layer {
                match self.skip_column(coarse, coarse_bounds.max_radius, t, top)? {
                    Skip::Miss => return Ok(None),
                    Skip::Across { t: exit, wall, last, next } => {
                        (cell, t, entered, before) = (next, exit, Some(wall), Some(voxel_at(last)));
                        continue;
                    }
                    Skip::Into { .. } => {}
                }
            }
            let column = ChunkColumn {
                face,
                lod: 0,
                x: (i / i64::from(CHUNK_SIZE)) as u32,
                y: (j / i64::from(CHUNK_SIZE)) as u32,
            };
            let bounds = self.bounds_of(column)?;
            if h > bounds.max_layer {
                // Above every solid voxel of the column: skip the column if
                // the ray does not come down into its surface range in it.
                let exit = match self.skip_column(column, bounds.max_radius, t, top)? {
                    Skip::Miss => return Ok(None),
                    Skip::Across { t: exit, wall, last, next } => {
                        (cell, t, entered, before) = (next, exit, Some(wall), Some(voxel_at(last)));
                        continue;
                    }
                    Skip::Into { exit } => exit,
                };
                // It does: go straight down to where it reaches the top of
                // the column's surface range, if that is in this column.
                let down = ray_sphere(self.at(t), self.dir, bounds.max_radius).map(|dt| t + dt);
                if let Some(down) = down.filter(|&down| down < exit && h > bounds.max_layer + 1) {
                    let point = self.at(down);
                    let size = i64::from(CHUNK_SIZE);
                    let (i0, j0) = (i64::from(column.x) * size, i64::from(column.y) * size);
                    let (fi, fj) = self.coords_on(face, point)?;
                    let inside = |x: f64, low: i64| (x.floor() as i64).clamp(low, low + size - 1);
                    (cell, t, entered) = ((face, inside(fi, i0), inside(fj, j0), bounds.max_layer + 1), down, None);
                    continue;
                }
            } else {
                let voxel = voxel_at(cell);
                if self.source.voxel(voxel)?.is_solid() {
                    return Ok(Some(self.hit(voxel, entered, before, t)));
                }
            }
            let (exit, wall) = self.voxel_exit(cell, t);
            if wall == Wall::Top && self.at(exit).length() > top && h >= bounds.max_layer {
                // Leaving upwards above all terrain: nothing more to hit
                // unless the ray comes back down, which a straight ray
                // above the highest terrain going up cannot.
                if self.dir.dot(self.at(exit)) > 0.0 {
                    return Ok(None);
                }
            }
            before = Some(voxel_at(cell));
            cell = self.step(cell, wall);
            (t, entered) = (exit, Some(wall));
        }
        Ok(None)
    }

    /// Whether the ray, at `t` inside `column` and above `max_radius` (the
    /// column's surface bounds), skips the column: it stays above them all
    /// the way through it.
    fn skip_column(&self, column: ChunkColumn, max_radius: f64, t: f64, top: f64) -> Result<Skip, VoxelError> {
        let (exit, wall) = self.column_exit(column, t);
        if !exit.is_finite() {
            // Up inside the column's wedge for ever, above its ground:
            // nothing to hit.
            return Ok(Skip::Miss);
        }
        if self.lowest_radius(t, exit) <= max_radius {
            return Ok(Skip::Into { exit });
        }
        if self.at(exit).length() > top && self.dir.dot(self.at(exit)) > 0.0 {
            // Leaving above all terrain, going up.
            return Ok(Skip::Miss);
        }
        let (last, next) = self.across_column_wall(column, wall, exit)?;
        Ok(Skip::Across { t: exit, wall, last, next })
    }

    fn at(&self, t: f64) -> DVec3 {
        self.origin + self.dir * t
    }

    fn bounds_of(&mut self, column: ChunkColumn) -> Result<SurfaceBounds, VoxelError> {
        if let Some(&bounds) = self.bounds.get(&column) {
            return Ok(bounds);
        }
        let bounds = self.source.surface_bounds(column)?;
        self.bounds.insert(column, bounds);
        Ok(bounds)
    }

    /// The smallest radius of the ray over `[t0, t1]`.
    fn lowest_radius(&self, t0: f64, t1: f64) -> f64 {
        let closest = (-self.origin.dot(self.dir)).clamp(t0, t1);
        self.at(closest).length()
    }

    /// Where the ray, inside the wedge between planes `low` and `high` of
    /// both axes of `face`, leaves it: (t, wall).
    fn wedge_exit(&self, face: CubeFace, (i0, i1): (i64, i64), (j0, j1): (i64, i64), t: f64) -> (f64, FaceDirection) {
        let sphere = self.source.layout().sphere();
        let mut best = (f64::INFINITY, FaceDirection::PosX);
        for (along_u, coord, side, leaving_when_positive) in [
            (true, i1, FaceDirection::PosX, true),
            (true, i0, FaceDirection::NegX, false),
            (false, j1, FaceDirection::PosZ, true),
            (false, j0, FaceDirection::NegZ, false),
        ] {
            let normal = sphere.lattice_plane_normal(face, along_u, coord);
            let speed = normal.dot(self.dir);
            if (leaving_when_positive && speed > 0.0) || (!leaving_when_positive && speed < 0.0) {
                let exit = (-normal.dot(self.origin) / speed).max(t);
                if exit < best.0 {
                    best = (exit, side);
                }
            }
        }
        best
    }

    fn column_exit(&self, column: ChunkColumn, t: f64) -> (f64, Wall) {
        let size = column_cells(column);
        let (i0, j0) = (i64::from(column.x) * size, i64::from(column.y) * size);
        let (exit, side) = self.wedge_exit(column.face, (i0, i0 + size), (j0, j0 + size), t);
        (exit, Wall::Side(side))
    }

    fn voxel_exit(&self, (face, i, j, h): Cell, t: f64) -> (f64, Wall) {
        let sphere = self.source.layout().sphere();
        let (mut exit, side) = self.wedge_exit(face, (i, i + 1), (j, j + 1), t);
        let mut wall = Wall::Side(side);
        let b = self.origin.dot(self.dir);
        let c0 = self.origin.length_squared();
        // Outer sphere: the far root (the ray is inside it).
        let outer = sphere.layer_radius((h + 1) as f64);
        let disc = b * b - c0 + outer * outer;
        if disc >= 0.0 {
            let far = (-b + disc.sqrt()).max(t);
            if far < exit {
                (exit, wall) = (far, Wall::Top);
            }
        }
        // Inner sphere: the near root, if the ray reaches it.
        let inner = sphere.layer_radius(h as f64);
        let disc = b * b - c0 + inner * inner;
        if inner > 0.0 && disc >= 0.0 {
            let near = -b - disc.sqrt();
            if near >= t - 1e-9 * near.abs().max(1.0) && near.max(t) < exit {
                (exit, wall) = (near.max(t), Wall::Bottom);
            }
        }
        (exit, wall)
    }

    /// The voxel across `wall` of `cell`.
    fn step(&self, (face, i, j, h): Cell, wall: Wall) -> Cell {
        let (di, dj) = match wall {
            Wall::Top => return (face, i, j, h + 1),
            Wall::Bottom => return (face, i, j, h - 1),
            Wall::Side(FaceDirection::PosX) => (1, 0),
            Wall::Side(FaceDirection::NegX) => (-1, 0),
            Wall::Side(FaceDirection::PosZ) => (0, 1),
            Wall::Side(_) => (0, -1),
        };
        let (face, i, j) = face.wrap_cell(i + di, j + dj, self.per_edge).unwrap_or((face, i, j));
        (face, i, j, h)
    }

    /// The last voxel of `column` and the first of the column across its
    /// `wall`, where the ray crosses that wall at `t`.
    fn across_column_wall(&self, column: ChunkColumn, wall: Wall, t: f64) -> Result<(Cell, Cell), VoxelError> {
        let sphere = self.source.layout().sphere();
        let size = column_cells(column);
        let (i0, j0) = (i64::from(column.x) * size, i64::from(column.y) * size);
        let point = self.at(t);
        // The in-face coordinates along the wall come from the point, in
        // this face's frame and clamped into the column; across it, the
        // index is the neighbour's by construction.
        let (fi, fj) = self.coords_on(column.face, point)?;
        let inside = |x: f64, low: i64| (x.floor() as i64).clamp(low, low + size - 1);
        let (i, j) = match wall {
            Wall::Side(FaceDirection::PosX) => (i0 + size - 1, inside(fj, j0)),
            Wall::Side(FaceDirection::NegX) => (i0, inside(fj, j0)),
            Wall::Side(FaceDirection::PosZ) => (inside(fi, i0), j0 + size - 1),
            _ => (inside(fi, i0), j0),
        };
        let last = (column.face, i, j, sphere.radius_to_layer(point.length()).floor() as i64);
        Ok((last, self.step(last, wall)))
    }

    /// In-face coordinates of `point` in `face`'s frame.
    fn coords_on(&self, face: CubeFace, point: DVec3) -> Result<(f64, f64), VoxelError> {
        let sphere = self.source.layout().sphere();
        match sphere.face_coords_in(face, point) {
            Some(coords) => Ok(coords),
            None => {
                let (_, fi, fj) = sphere.face_coords_of(point)?;
                Ok((fi, fj))
            }
        }
    }

    fn hit(&self, voxel: VoxelCoord, entered: Option<Wall>, before: Option<VoxelCoord>, t: f64) -> VoxelHit {
        let sphere = self.source.layout().sphere();
        let point = self.at(t);
        let (face, normal) = match entered {
            None => (None, -self.dir),
            // Left the previous voxel through its top: came in from below.
            Some(Wall::Top) => (Some(FaceDirection::NegY), -point.normalize()),
            Some(Wall::Bottom) => (Some(FaceDirection::PosY), point.normalize()),
            Some(Wall::Side(_)) => {
                // The side wall of this voxel the entry point lies on (found
                // in this voxel's own frame, which differs from the previous
                // voxel's across a cube-face edge).
                let (i, j) = (i64::from(voxel.i), i64::from(voxel.j));
                let walls = [
                    (FaceDirection::PosX, true, i + 1, 1.0),
                    (FaceDirection::NegX, true, i, -1.0),
                    (FaceDirection::PosZ, false, j + 1, 1.0),
                    (FaceDirection::NegZ, false, j, -1.0),
                ]
                .map(|(side, along_u, coord, sign)| {
                    let normal = sphere.lattice_plane_normal(voxel.face, along_u, coord) * sign;
                    (normal.dot(point).abs(), side, normal)
                });
                let nearest = walls.into_iter().min_by(|a, b| a.0.total_cmp(&b.0)).unwrap_or(walls[0]);
                (Some(nearest.1), nearest.2)
            }
        };
        VoxelHit { voxel, face, normal, point, distance: t, before }
    }
}

/// The LOD of the columns tried first: 8 × 8 LOD-0 chunk columns.
const COARSE_SKIP_LOD: u8 = 3;

/// LOD-0 cells across a chunk column of `column`'s LOD.
fn column_cells(column: ChunkColumn) -> i64 {
    i64::from(CHUNK_SIZE) << column.lod
}

/// What [`Walker::skip_column`] found.
enum Skip {
    /// Nothing more to hit.
    Miss,
    /// The ray comes down into the column's surface range before `exit`.
    Into { exit: f64 },
    /// The ray stays above: go on at `t` in `next`, after `last`.
    Across { t: f64, wall: Wall, last: Cell, next: Cell },
}

/// A LOD-0 voxel while walking: face, i, j, layer (unchecked).
type Cell = (CubeFace, i64, i64, i64);

fn voxel_at((face, i, j, h): Cell) -> VoxelCoord {
    VoxelCoord { face, lod: 0, i: i as u32, j: j as u32, h: h.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32 }
}
