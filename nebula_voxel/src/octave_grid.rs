//! Noise octaves read from grids on a face's lattice instead of evaluated
//! at every voxel column.
//!
//! # Why
//!
//! A LOD-0 column of an Earth evaluates about 28 Perlin octaves of the
//! three noise sums, most of them with wavelengths of hundreds of voxels
//! to thousands of kilometres: between neighbouring columns such an octave
//! is nearly linear, yet each column paid for it in full (generation was
//! 70 % of the streaming workers' time, its noise 70 % of that).
//!
//! # The definition
//!
//! Octave `k` of a sum, of wavelength `λ_k` lattice cells, belongs to the
//! grid of spacing `S_k`: the largest power of two at most `λ_k / ratio`
//! (the planet's `octave_grid`), at most [`RATIO_SPACING_CAP`]; octaves
//! with `S_k = 1` are evaluated at the column itself. An octave the ratio
//! puts on the capped grid goes on to coarser ones (still at most
//! `λ_k / ratio`) while the bound of how far interpolating it moves H,
//! `(π²/2)·(S/λ_k)²·A_k` (**How far from exact noise**; `A_k` the most
//! the octave can move H, [`CoarseGrids`]), stays within the planet's
//! `octave_grid_error` metres: the continents' long octaves, which a
//! coarse voxel column otherwise sums in full. (An error budget, not a
//! ratio: at a ratio of 16 a grid of 64 moved the terrain by up to 3.9
//! voxels, the ridges' octaves being tall for their wavelengths, while the
//! continents' first takes a grid of 2,048 for 1 cm.) Spacings never grow
//! from one octave to the next. A grid of spacing `S` has
//! its nodes at the LOD-0 columns whose indices are `−1 mod S` on both
//! axes (column `u` has its centre at lattice coordinate `u + ½`).
//!
//! A sum's state ([`OctaveState`]) at a point is built coarse to fine:
//! at the nodes of its coarsest grid, its octaves from the start; at the
//! nodes of each finer grid, the coarser grid's state interpolated
//! bilinearly at the node, then that grid's octaves; at the point, the
//! finest grid's state interpolated there, then the octaves of spacing 1.
//!
//! - **The same at every LOD.** A voxel column of LOD `L` samples the
//!   LOD-0 column `(c + 1)·2^L − 1` (the far-corner rule), a node of every
//!   grid of spacing `2^L` or less, where interpolation returns the node's
//!   own state bit for bit: its octaves of those grids are evaluated there
//!   directly, as a LOD-0 chunk's grids evaluate them at that node, and
//!   the coarser grids' nodes are the same whichever chunk asks. So a LOD
//!   `L` chunk reads grids only where their spacing exceeds `2^L`: without
//!   coarse grids none from LOD 4 (spacing 16) on, every octave evaluated
//!   directly; with them, the continents' long octaves to LOD 10 or so
//!   (a grid of spacing `2^(L+1)` has 18 × 18 nodes over such a chunk).
//! - **One owner per column.** A column is a function of its own face's
//!   column indices; a chunk's padding beyond a face edge is computed on
//!   the face that owns it, as the direction rule already had it.
//! - **How far from exact noise.** Bilinear interpolation of a wave of
//!   wavelength `λ` from nodes `S` apart errs by at most `(π²/2)·(S/λ)²`
//!   of its amplitude: 1.9 % at ratio 16, for the finest octave of each
//!   grid, a quarter of that for the next. (A bound for a sine; Perlin
//!   octaves bend less, the ridges' creases more: the planet's tests
//!   measure how far the terrain moves.)
//! - **Bounds.** A state interpolated at a point blends node states from
//!   the point's own cell of each grid (the cells are nested: the nodes of
//!   a finer grid's cell lie in the coarser grid's cell), so octave `k`
//!   only ever reads noise within `√2·S_k` cells of the point; the noise
//!   ranges behind the surface bounds widen each octave's radius by that
//!   ([`OctaveLevels::reach`]). Blends stay within ranges (they are
//!   intervals), so the ranges still hold.

use nebula_math::{CubeFace, Cubesphere};

use crate::perlin::{Fractal, OctaveState};

/// The coarsest grid the ratio alone gives, LOD-0 columns (it takes every
/// octave of 256 cells and more at ratio 16): a coarser one moves an
/// octave by more than the ratio promises, so only the error budget
/// ([`CoarseGrids`]) sends octaves there.
pub(crate) const RATIO_SPACING_CAP: i64 = 16;

/// How much coarser each grid past [`RATIO_SPACING_CAP`] is than the one
/// before: a grid costs a pass of its own at every chunk that reads it
/// (its nodes' directions, its octaves there, its states interpolated),
/// so fewer, coarser steps.
const COARSE_STEP: i64 = 4;

/// How far octaves may go past [`RATIO_SPACING_CAP`]: the error budget
/// and what each octave can move H by.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CoarseGrids {
    /// The most H changes per unit of the sum, metres (its steepest rate
    /// anywhere: an octave's amplitude in the sum times this is its `A_k`).
    pub(crate) metres_per_unit: f64,
    /// The most interpolating one octave may move H, metres, by the bound
    /// (`(π²/2)·(S/λ)²·A_k`); 0: no grid coarser than the cap.
    pub(crate) error: f64,
}

/// Which octaves of one noise sum come from which grid.
#[derive(Clone, Debug)]
pub(crate) struct OctaveLevels {
    /// `(spacing, end)`: the grid's spacing in LOD-0 columns (> 1) and the
    /// octave after its last; coarsest first, each grid one or more
    /// octaves, the first from octave 0.
    levels: Vec<(i64, usize)>,
    /// Per octave, how far (in lattice cells) from a point its noise is
    /// read: `√2·S_k`, 0 where evaluated at the point.
    reach: Vec<f64>,
}

impl OctaveLevels {
    /// The grids of `fractal`'s octaves, whose first octave spans
    /// `cells_per_unit` lattice cells per unit of noise space, at `ratio`
    /// wavelengths per spacing (no grids at all for a ratio of 0: the
    /// terrain of planets from before grids), coarser than
    /// [`RATIO_SPACING_CAP`] as far as `coarse` allows (module docs).
    pub(crate) fn new(fractal: &Fractal, cells_per_unit: f64, ratio: f64, coarse: CoarseGrids) -> Self {
        let mut levels: Vec<(i64, usize)> = Vec::new();
        let mut reach = Vec::with_capacity(fractal.octaves());
        let mut coarsest = i64::MAX;
        for k in 0..fractal.octaves() {
            let wavelength = cells_per_unit / fractal.lacunarity().powi(k as i32);
            let by_ratio = if ratio > 0.0 { power_of_two_at_most(wavelength / ratio) } else { 1 };
            let mut spacing = by_ratio.min(RATIO_SPACING_CAP);
            let amplitude = coarse.metres_per_unit * fractal.octave_amplitude(k);
            let moves = |spacing: i64| {
                let relative = spacing as f64 / wavelength;
                std::f64::consts::PI * std::f64::consts::PI / 2.0 * relative * relative * amplitude
            };
            while spacing >= RATIO_SPACING_CAP
                && COARSE_STEP * spacing <= by_ratio
                && moves(COARSE_STEP * spacing) <= coarse.error
            {
                spacing *= COARSE_STEP;
            }
            spacing = spacing.min(coarsest);
            coarsest = spacing;
            reach.push(if spacing > 1 { std::f64::consts::SQRT_2 * spacing as f64 } else { 0.0 });
            if spacing == 1 {
                continue;
            }
            match levels.last_mut() {
                Some((last, end)) if *last == spacing => *end = k + 1,
                _ => levels.push((spacing, k + 1)),
            }
        }
        Self { levels, reach }
    }

    /// The same grids for the sum's first `octaves` octaves alone (the
    /// sum without the rest, `Fractal::with_octaves`): no grid holds an
    /// octave past them.
    pub(crate) fn with_octaves(&self, octaves: usize) -> Self {
        let mut levels = Vec::new();
        for &(spacing, end) in &self.levels {
            let from = levels.last().map_or(0, |&(_, end)| end);
            let end = end.min(octaves);
            if end > from {
                levels.push((spacing, end));
            }
        }
        Self { levels, reach: self.reach.iter().copied().take(octaves).collect() }
    }

    /// Per octave, the farthest its noise is read from a point, lattice
    /// cells (module docs, **Bounds**).
    pub(crate) fn reach(&self) -> &[f64] {
        &self.reach
    }

    /// Whether no octave is read from a grid coarser than `spacing`: a
    /// column of that spacing is the exact noise's.
    pub(crate) fn exact_at(&self, spacing: i64) -> bool {
        self.levels.first().is_none_or(|&(coarsest, _)| coarsest <= spacing)
    }

    /// The first octave not read from a grid coarser than `spacing`.
    fn start_below(&self, spacing: i64) -> usize {
        self.levels.iter().take_while(|&&(s, _)| s > spacing).last().map_or(0, |&(_, end)| end)
    }
}

/// The largest power of two at most `x` (1 below 2).
fn power_of_two_at_most(x: f64) -> i64 {
    if x < 2.0 { 1 } else { 1_i64 << (x.log2().floor() as u32).min(62) }
}

/// `x.floor()` for |x| < 2⁶³ without the libm call baseline x86-64 makes
/// of it: once per point and grid.
fn floor(x: f64) -> f64 {
    let truncated = x as i64 as f64;
    if truncated > x { truncated - 1.0 } else { truncated }
}

/// One sum's states at the nodes of one grid.
struct Grid {
    /// 1 / spacing (a power of two: exact).
    inverse_spacing: f64,
    /// The node index (`m`, the node at column `m·S − 1`) of the first
    /// node along each axis.
    first: [f64; 2],
    /// The last node's offset from the first along each axis.
    last: [usize; 2],
    /// Nodes along `u` (a row).
    width: usize,
    states: Vec<OctaveState>,
}

impl Grid {
    /// The offset of the node below `u` on this grid (along `axis`), the
    /// next one's (itself at the grid's far edge) and how far on to it, in
    /// `[0, 1)`: 0 exactly on a node (whole `u`: exact arithmetic).
    #[inline]
    fn cell(&self, u: f64, axis: usize) -> (usize, usize, f64) {
        let x = (u + 1.0) * self.inverse_spacing - self.first[axis];
        let m = floor(x);
        let below = m as usize;
        (below, (below + 1).min(self.last[axis]), x - m)
    }

    /// The states at `points` (column coordinates), bilinearly from the
    /// four nodes around each. On a node it is the node's state bit for
    /// bit: `a + 0·(b − a)` is `a` (states are never −0). Points in rows
    /// (the same `v` one after another, as a chunk's columns and a grid's
    /// nodes come) share the blend along `v`.
    fn interpolate(&self, points: &[[f64; 2]]) -> Vec<OctaveState> {
        let mut along_v: Vec<OctaveState> = Vec::with_capacity(self.width);
        let mut row_v = f64::NAN;
        // The cells along `u` of the last row's points by their place in
        // the row: the rows of a chunk (and of a grid's nodes) repeat the
        // same `u`s, whose cells are then read, not found again.
        let mut u_cells: Vec<(f64, usize, usize, f64)> = Vec::new();
        let mut place = 0;
        points
            .iter()
            .map(|&[u, v]| {
                if v != row_v {
                    let (v0, v1, tv) = self.cell(v, 1);
                    let (below, above) =
                        (&self.states[v0 * self.width..][..self.width], &self.states[v1 * self.width..][..self.width]);
                    along_v.clear();
                    along_v.extend(below.iter().zip(above).map(|(a, b)| a.lerp(*b, tv)));
                    row_v = v;
                    place = 0;
                }
                let (u0, u1, tu) = match u_cells.get(place) {
                    Some(&(known, u0, u1, tu)) if known == u => (u0, u1, tu),
                    _ => {
                        let (u0, u1, tu) = self.cell(u, 0);
                        u_cells.truncate(place);
                        u_cells.push((u, u0, u1, tu));
                        (u0, u1, tu)
                    }
                };
                place += 1;
                along_v[u0].lerp(along_v[u1], tu)
            })
            .collect()
    }
}

/// One noise sum as the planet evaluates it: the octaves, the scale from
/// a unit direction to noise space, and their grids.
#[derive(Clone, Copy)]
pub(crate) struct GriddedSum<'a> {
    pub(crate) fractal: &'a Fractal,
    pub(crate) scale: f64,
    pub(crate) levels: &'a OctaveLevels,
}

/// The states of `sums` at `points` (LOD-0 column coordinates on `face`,
/// whole or not) after their octaves on grids coarser than `spacing`
/// columns, with the octave each sum goes on from at the points (module
/// docs). A chunk of LOD `L` asks with spacing `2^L`, its columns being
/// nodes of the finer grids; a point anywhere asks with spacing 1.
pub(crate) fn grid_states<const N: usize>(
    sphere: &Cubesphere,
    face: CubeFace,
    sums: [GriddedSum<'_>; N],
    points: &[[f64; 2]],
    spacing: i64,
) -> [(usize, Vec<OctaveState>); N] {
    let starts = sums.map(|sum| sum.levels.start_below(spacing));
    let mut spacings: Vec<i64> =
        sums.iter().flat_map(|sum| sum.levels.levels.iter().map(|&(s, _)| s)).filter(|&s| s > spacing).collect();
    spacings.sort_unstable_by(|a, b| b.cmp(a));
    spacings.dedup();
    if spacings.is_empty() || points.is_empty() {
        return starts.map(|start| (start, vec![OctaveState::START; points.len()]));
    }
    // The nodes each grid needs, finest first: those around the points,
    // then those around the finer grid's nodes.
    let (mut low, mut high) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for point in points {
        for axis in 0..2 {
            low[axis] = low[axis].min(point[axis]);
            high[axis] = high[axis].max(point[axis]);
        }
    }
    let mut ranges = vec![([0_i64; 2], [0_i64; 2]); spacings.len()];
    for (range, &s) in ranges.iter_mut().zip(&spacings).rev() {
        let first = low.map(|c| floor((c + 1.0) / s as f64) as i64);
        let last = high.map(|c| -floor(-(c + 1.0) / s as f64) as i64);
        *range = (first, last);
        low = first.map(|m| (m * s - 1) as f64);
        high = last.map(|m| (m * s - 1) as f64);
    }
    let mut grids: [Option<Grid>; N] = std::array::from_fn(|_| None);
    for (&s, &(first, last)) in spacings.iter().zip(&ranges) {
        let width = (last[0] - first[0] + 1) as usize;
        let height = (last[1] - first[1] + 1) as usize;
        // The nodes' columns and directions: one warp per row and per
        // column of nodes (bit for bit `Cubesphere::direction`).
        let column = |m: i64| (m * s - 1) as f64;
        let warped = |axis: usize, count: usize| -> Vec<f64> {
            (0..count as i64).map(|n| sphere.warp(column(first[axis] + n) + 0.5)).collect()
        };
        let (warped_u, warped_v) = (warped(0, width), warped(1, height));
        let nodes: Vec<[f64; 2]> = (0..width * height)
            .map(|n| [column(first[0] + (n % width) as i64), column(first[1] + (n / width) as i64)])
            .collect();
        let directions: Vec<nebula_math::DVec3> = (0..width * height)
            .map(|n| sphere.direction_warped(face, warped_u[n % width], warped_v[n / width]))
            .collect();
        for (sum, grid) in sums.iter().zip(&mut grids) {
            let Some(index) = sum.levels.levels.iter().position(|&(level, _)| level == s) else { continue };
            let from = if index == 0 { 0 } else { sum.levels.levels[index - 1].1 };
            let end = sum.levels.levels[index].1;
            let states: Vec<OctaveState> = match grid {
                Some(coarser) => coarser.interpolate(&nodes),
                None => vec![OctaveState::START; nodes.len()],
            };
            let noise_points: Vec<[f64; 3]> = directions.iter().map(|d| (*d * sum.scale).to_array()).collect();
            let mut batch = sum.fractal.resume(&noise_points, &states, from);
            let all: Vec<usize> = (0..nodes.len()).collect();
            while batch.octave() < end {
                sum.fractal.step(&mut batch, &all);
            }
            *grid = Some(Grid {
                inverse_spacing: 1.0 / s as f64,
                first: first.map(|m| m as f64),
                last: [width - 1, height - 1],
                width,
                states: (0..nodes.len()).map(|k| batch.state(k)).collect(),
            });
        }
    }
    let mut out = starts.map(|start| (start, Vec::new()));
    for ((_, states), grid) in out.iter_mut().zip(&grids) {
        *states = match grid {
            Some(grid) => grid.interpolate(points),
            None => vec![OctaveState::START; points.len()],
        };
    }
    out
}
