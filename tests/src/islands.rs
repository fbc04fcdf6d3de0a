//! A world a game brings: rock islands floating over an ocean floor, a
//! [`VoxelSource`] shaped nothing like the procedural planet, streamed and
//! drawn by the same `Streamer` and renderer (render test
//! `floating_islands_stream_and_draw_crack_free`, example `islands`).
//!
//! The world is a signed shape in world space, sampled the way every
//! Nebula source samples: a voxel at LOD `L` is its far-corner LOD-0
//! voxel, whose centre decides it.
//!
//! - **Floor**: everything below radial layer [`FloatingIslands::FLOOR`]
//!   (30 m under the base radius) is sea bed, so a renderer's sea covers it.
//! - **Islands**: 80 of them, on a jittered Fibonacci spiral of directions,
//!   their flat grassy tops 80–220 m up, each an inverted cone (rim
//!   25–70 m out, wobbling in three lobes; bottom 20–50 m under the top):
//!   solid where `bottom(r) ≤ h ≤ top`, `h` along the island's up and `r`
//!   out from its axis, `bottom(r) = −depth · (1 − r / rim(θ))`.
//!
//! Its surface bounds are exact bands (the floor's, and each island's top
//! to bottom where one is near the column), and its error bound δ(L) comes
//! from the steepest cone: a coarse voxel's sample is at most `s − 1` cells
//! aside and `s` layers above the fine surface it stands for.

use nebula_math::{Cubesphere, DVec3, SphereMap};
use nebula_voxel::{
    CHUNK_SIZE, ChunkColumn, ChunkKey, ChunkLayout, ChunkVoxels, PADDED_CHUNK_SIZE, SurfaceBounds, Voxel, VoxelCoord,
    VoxelError, VoxelSource,
};

/// One island (world metres).
#[derive(Clone, Debug)]
struct Island {
    /// Unit direction of its axis.
    up: DVec3,
    /// Two unit tangents, for the lobes' angle.
    east: DVec3,
    north: DVec3,
    /// Radius of its flat top, metres from the planet centre.
    top: f64,
    /// The rim's mean distance from the axis.
    rim: f64,
    /// How far the cone's tip hangs under the top.
    depth: f64,
    /// The lobes' phase.
    phase: f64,
}

impl Island {
    /// The rim's distance from the axis at angle `theta` around it.
    fn rim_at(&self, theta: f64) -> f64 {
        self.rim * (1.0 + LOBES * (3.0 * theta + self.phase).sin())
    }

    /// Whether world point `p` is rock, and its depth under the top.
    fn holds(&self, p: DVec3) -> Option<f64> {
        let h = p.dot(self.up) - self.top;
        if h > 0.0 || h < -self.depth {
            return None;
        }
        let aside = p - self.up * p.dot(self.up);
        let (x, y) = (aside.dot(self.east), aside.dot(self.north));
        let r = x.hypot(y);
        let rim = self.rim_at(y.atan2(x));
        (r < rim && h >= -self.depth * (1.0 - r / rim)).then_some(-h)
    }

    /// The largest angle (radians, from the planet centre) of its rock
    /// from its axis.
    fn angle(&self) -> f64 {
        (self.rim * (1.0 + LOBES) / (self.top - self.depth)).atan()
    }
}

/// How far the rim wobbles, a share of its mean distance.
const LOBES: f64 = 0.25;

/// Rock islands over an ocean floor (module docs).
#[derive(Clone, Debug)]
pub struct FloatingIslands {
    layout: ChunkLayout,
    islands: Vec<Island>,
    /// The steepest a cone's underside gets, metres per metre out.
    steepest: f64,
}

impl FloatingIslands {
    /// Radial layers under the base radius that are sea bed: the floor.
    pub const FLOOR: i64 = -20;

    /// A world of `radius` metres with `2^max_lod` LOD-0 chunks along a
    /// cube face's edge, its islands placed from `seed`.
    ///
    /// # Errors
    /// [`VoxelError`] for a radius or LOD count the lattice refuses.
    pub fn new(radius: f64, max_lod: u8, seed: u64) -> Result<Self, VoxelError> {
        let resolution = CHUNK_SIZE << max_lod;
        let layer_height = radius * std::f64::consts::FRAC_PI_2 / f64::from(resolution);
        let sphere = Cubesphere::new(radius, resolution, layer_height, SphereMap::EquiAngular)?;
        let layout = ChunkLayout::new(sphere, max_lod)?;
        let mut state = seed;
        let mut next = || nebula_math::unit_random(&mut state);
        let count = 80;
        let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
        let islands: Vec<Island> = (0..count)
            .map(|k| {
                let z = 1.0 - 2.0 * (f64::from(k) + 0.5 + 0.4 * (next() - 0.5)) / f64::from(count);
                let a = golden * f64::from(k) + 0.3 * next();
                let ring = (1.0 - z * z).sqrt();
                let up = DVec3::new(ring * a.cos(), ring * a.sin(), z).normalize();
                let east = up.any_orthonormal_vector();
                Island {
                    up,
                    east,
                    north: up.cross(east),
                    top: radius + 80.0 + 140.0 * next(),
                    rim: 25.0 + 45.0 * next(),
                    depth: 20.0 + 30.0 * next(),
                    phase: std::f64::consts::TAU * next(),
                }
            })
            .collect();
        // The underside's slope, steepest where the rim is nearest the axis.
        let steepest = islands.iter().map(|i| i.depth / (i.rim * (1.0 - LOBES))).fold(0.0, f64::max);
        Ok(Self { layout, islands, steepest })
    }

    /// The islands' axes and the radius of their tops: where a camera can
    /// look at one.
    #[must_use]
    pub fn island_tops(&self) -> Vec<(DVec3, f64)> {
        self.islands.iter().map(|i| (i.up, i.top)).collect()
    }

    /// The voxel whose sample (the centre of its far-corner LOD-0 voxel)
    /// lies at `p`, for voxels `span` layers tall.
    fn classify(&self, p: DVec3, layer: f64, span: f64, near: &[&Island]) -> Voxel {
        if layer < Self::FLOOR as f64 {
            return Voxel::SEABED;
        }
        let top_voxel = span * self.layout.sphere().layer_height();
        match near.iter().find_map(|island| island.holds(p)) {
            Some(depth) if depth < top_voxel => Voxel::GRASS,
            Some(_) => Voxel::STONE,
            None => Voxel::AIR,
        }
    }

    /// The islands within `reach` radians (plus their own size) of unit
    /// direction `d`.
    fn islands_near(&self, d: DVec3, reach: f64) -> Vec<&Island> {
        self.islands.iter().filter(|i| d.dot(i.up).clamp(-1.0, 1.0).acos() <= reach + i.angle()).collect()
    }

    /// The ball (unit centre, radius in radians) holding chunk column
    /// `column`'s patch and a voxel around it.
    fn patch(&self, column: ChunkColumn) -> (DVec3, f64) {
        let sphere = self.layout.sphere();
        let size = f64::from(CHUNK_SIZE) * self.layout.voxel_span(column.lod) as f64;
        let (i0, j0) = (f64::from(column.x) * size, f64::from(column.y) * size);
        let centre = sphere.direction(column.face, i0 + 0.5 * size, j0 + 0.5 * size);
        let margin = size / 16.0;
        let reach = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
            .into_iter()
            .map(|(a, b)| {
                let corner = sphere.direction(column.face, i0 + a * size, j0 + b * size);
                centre.dot(corner).clamp(-1.0, 1.0).acos()
            })
            .fold(0.0, f64::max);
        // A chord is shorter than its arc; and the padding's voxel beyond.
        (centre, reach * 1.01 + margin * sphere.cell_width() / sphere.radius() * 2.0)
    }
}

impl VoxelSource for FloatingIslands {
    fn layout(&self) -> &ChunkLayout {
        &self.layout
    }

    fn voxel(&self, at: VoxelCoord) -> Result<Voxel, VoxelError> {
        self.layout.check_voxel(at)?;
        let d = self.layout.sample_direction(at.face, at.lod, i64::from(at.i), i64::from(at.j));
        let span = self.layout.voxel_span(at.lod) as f64;
        let layer = self.layout.sample_layer(i64::from(at.h), at.lod);
        let p = d * self.layout.sphere().layer_radius(layer);
        Ok(self.classify(p, layer, span, &self.islands_near(d, 0.0)))
    }

    fn fill_chunk(&self, key: ChunkKey, out: &mut ChunkVoxels) -> Result<(), VoxelError> {
        self.layout.check_key(key)?;
        out.set_key(key);
        let column = key.column();
        let (centre, reach) = self.patch(column);
        let near = self.islands_near(centre, reach);
        let span = self.layout.voxel_span(key.lod) as f64;
        let size = i64::from(CHUNK_SIZE);
        let (base_i, base_j) = (i64::from(key.x) * size - 1, i64::from(key.y) * size - 1);
        let base_h = i64::from(key.layer) * size - 1;
        let sphere = self.layout.sphere();
        for z in 0..PADDED_CHUNK_SIZE {
            for x in 0..PADDED_CHUNK_SIZE {
                let d = self.layout.sample_direction(key.face, key.lod, base_i + i64::from(x), base_j + i64::from(z));
                for y in 0..PADDED_CHUNK_SIZE {
                    let layer = self.layout.sample_layer(base_h + i64::from(y), key.lod);
                    let voxel = self.classify(d * sphere.layer_radius(layer), layer, span, &near);
                    out.set([x, y, z], voxel);
                }
            }
        }
        Ok(())
    }

    fn surface_bounds(&self, column: ChunkColumn) -> Result<SurfaceBounds, VoxelError> {
        self.layout.check_key(column.chunk(0))?;
        let sphere = self.layout.sphere();
        let span = self.layout.voxel_span(column.lod);
        let (centre, reach) = self.patch(column);
        let near = self.islands_near(centre, reach);
        // The floor's top voxel at this LOD, a voxel either way.
        let mut min_layer = Self::FLOOR - 2 * span - 1;
        let mut max_layer = Self::FLOOR + span;
        let layer_of = |radius: f64| sphere.radius_to_layer(radius);
        for island in &near {
            min_layer = min_layer.min(layer_of(island.top - island.depth).floor() as i64 - 2 * span);
            max_layer = max_layer.max(layer_of(island.top).ceil() as i64 + 2 * span);
        }
        Ok(SurfaceBounds {
            min_layer,
            max_layer,
            min_radius: sphere.layer_radius(min_layer as f64),
            max_radius: sphere.layer_radius(max_layer as f64 + 1.0),
            sea_bed_only: near.is_empty(),
        })
    }

    fn geometric_error(&self, lod: u8) -> f64 {
        if lod == 0 {
            return 0.0;
        }
        // A coarse voxel's sample lies up to s − 1 cells aside and s layers
        // above the fine voxels it stands for; aside, the cones' undersides
        // move by the slope.
        let s = self.layout.voxel_span(lod) as f64;
        (s + (s - 1.0) * self.steepest) * self.layout.sphere().layer_height()
    }

    fn lowest_surface_radius(&self) -> Option<f64> {
        Some(self.layout.sphere().layer_radius((Self::FLOOR - 1) as f64))
    }
}
