//! The `noise` crate's 3-D Perlin noise, value for value, without its
//! branches.
//!
//! Why our own kernel: noise is most of a chunk's cost (one height per
//! voxel column, about 40 Perlin octaves each), and `noise::Perlin` picks
//! each corner's gradient with a 16-way `match` on a hash. Where samples
//! are a voxel apart (LOD 0) neighbouring calls take the same branches;
//! at coarse LODs they are hundreds of metres apart, the branches are
//! random, and the same call costs about twice as much (measured: a LOD-8
//! chunk 3.10 ms against 1.38 ms at LOD 0). Here the gradient comes from
//! three small tables instead, and the corner hashes share their prefixes.
//!
//! It is a drop-in source for `noise::Fbm` and `noise::RidgedMulti`, with
//! the same permutation table per seed (read out of
//! `noise::permutationtable::PermutationTable`), the same corner rule, the
//! same quintic fade and the same interpolation order, so the planet's
//! terrain is unchanged: `matches_the_noise_crate` compares the two on a
//! million points.

use std::ops::{Add, Mul, Sub};

use noise::permutationtable::{NoiseHasher, PermutationTable};
use noise::{NoiseFn, Seedable};
use wide::f64x2;

/// Gradient components by hash & 15, as `noise::core::perlin::perlin_3d`
/// lists them (12–15 repeat 0, 1, 9 and 11).
const GRAD_X: [f64; 16] = [1., -1., 1., -1., 1., -1., 1., -1., 0., 0., 0., 0., 1., -1., 0., 0.];
const GRAD_Y: [f64; 16] = [1., 1., -1., -1., 0., 0., 0., 0., 1., -1., 1., -1., 1., 1., -1., -1.];
const GRAD_Z: [f64; 16] = [0., 0., 0., 0., 1., 1., -1., -1., 1., 1., -1., -1., 0., 0., 1., -1.];

/// 2/√3: scales the kernel's range to (−1, 1), as `noise` does.
const SCALE_FACTOR: f64 = 1.154_700_538_379_251_5;

/// 3-D Perlin noise equal to `noise::Perlin` with the same seed.
#[derive(Clone, Copy, Debug)]
pub struct BranchlessPerlin {
    seed: u32,
    table: [u8; 256],
}

impl BranchlessPerlin {
    /// The noise of `seed`.
    #[must_use]
    pub fn new(seed: u32) -> Self {
        let permutation = PermutationTable::new(seed);
        // A one-coordinate hash is the table entry itself.
        let table = std::array::from_fn(|i| permutation.hash(&[i as isize]) as u8);
        Self { seed, table }
    }

    #[inline(always)]
    fn entry(&self, index: isize) -> usize {
        usize::from(self.table[(index & 0xff) as usize])
    }
}

impl Default for BranchlessPerlin {
    fn default() -> Self {
        Self::new(0)
    }
}

impl Seedable for BranchlessPerlin {
    fn set_seed(self, seed: u32) -> Self {
        if seed == self.seed { self } else { Self::new(seed) }
    }

    fn seed(&self) -> u32 {
        self.seed
    }
}

/// `noise`'s lattice corner: the integer part, one lower for values ≤ 0
/// (so exact non-positive integers go one cell further down than `floor`).
#[inline(always)]
fn corner(v: f64) -> isize {
    let truncated = v as isize;
    if v <= 0.0 { truncated - 1 } else { truncated }
}

/// [`corner`] of each coordinate (spelled out: `array::map` is left
/// uninlined in the AVX2 step).
#[inline(always)]
fn corners([x, y, z]: [f64; 3]) -> [isize; 3] {
    [corner(x), corner(y), corner(z)]
}

/// Whether two cell corners are the same, compared as one scalar: an
/// array compare loads the corner the last sample stored as a vector, and
/// that load waits for the stores (measured: a fifth of the noise time).
#[inline(always)]
fn same_cell([ax, ay, az]: [isize; 3], [bx, by, bz]: [isize; 3]) -> bool {
    (ax ^ bx) | (ay ^ by) | (az ^ bz) == 0
}

/// One value or two (SIMD lanes) through the same arithmetic: the kernel
/// is written once for both, and a lane's IEEE operations are the scalar
/// ones in the same order, so two at once equal one at a time bit for bit.
trait Lanes: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> {
    fn splat(value: f64) -> Self;
    /// `f64::clamp` for the values the kernel meets (no NaN, and no −0
    /// below `low`).
    fn clamp_to(self, low: f64, high: f64) -> Self;
}

impl Lanes for f64 {
    #[inline(always)]
    fn splat(value: f64) -> Self {
        value
    }

    #[inline(always)]
    fn clamp_to(self, low: f64, high: f64) -> Self {
        self.clamp(low, high)
    }
}

/// Four values through the same arithmetic, lane by lane: inlined into
/// [`Fractal::step`]'s AVX2 build, the four lanes are one 256-bit
/// register, and each lane's IEEE operations are the scalar ones in the
/// same order (Rust never fuses a multiply and an add of its own accord),
/// so four at once equal one at a time bit for bit. Spelled out lane by
/// lane: `array::map` and `from_fn` were left uninlined there.
#[derive(Clone, Copy)]
struct Quad([f64; 4]);

impl Add for Quad {
    type Output = Self;
    #[inline(always)]
    fn add(self, other: Self) -> Self {
        let (a, b) = (self.0, other.0);
        Self([a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]])
    }
}

impl Sub for Quad {
    type Output = Self;
    #[inline(always)]
    fn sub(self, other: Self) -> Self {
        let (a, b) = (self.0, other.0);
        Self([a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3]])
    }
}

impl Mul for Quad {
    type Output = Self;
    #[inline(always)]
    fn mul(self, other: Self) -> Self {
        let (a, b) = (self.0, other.0);
        Self([a[0] * b[0], a[1] * b[1], a[2] * b[2], a[3] * b[3]])
    }
}

impl Quad {
    /// [`corner`] lane by lane, as a float: the truncation, one lower at
    /// or below 0 (exact at noise coordinates' magnitudes, far below
    /// 2⁵³), so `v − corner` is [`BranchlessPerlin::enter`]'s offset to
    /// the bit. In floating point, four lanes at once (`roundpd`), where
    /// the integer conversions were most of a point's cost.
    #[inline(always)]
    fn corner(self) -> Self {
        let c = |v: f64| {
            let t = v.trunc();
            if v <= 0.0 { t - 1.0 } else { t }
        };
        let a = self.0;
        Self([c(a[0]), c(a[1]), c(a[2]), c(a[3])])
    }
}

impl Lanes for Quad {
    #[inline(always)]
    fn splat(value: f64) -> Self {
        Self([value; 4])
    }

    /// `f64::clamp` lane by lane (its steps, without its assertion on the
    /// limits, which kept the lanes apart).
    #[inline(always)]
    fn clamp_to(self, low: f64, high: f64) -> Self {
        let clamp = |v: f64| {
            let v = if v < low { low } else { v };
            if v > high { high } else { v }
        };
        let a = self.0;
        Self([clamp(a[0]), clamp(a[1]), clamp(a[2]), clamp(a[3])])
    }
}

impl Lanes for f64x2 {
    #[inline(always)]
    fn splat(value: f64) -> Self {
        f64x2::splat(value)
    }

    #[inline(always)]
    fn clamp_to(self, low: f64, high: f64) -> Self {
        self.fast_max(f64x2::splat(low)).fast_min(f64x2::splat(high))
    }
}

#[inline(always)]
fn quintic<T: Lanes>(x: T) -> T {
    let x = x.clamp_to(0.0, 1.0);
    x * x * x * (x * (x * T::splat(6.0) - T::splat(15.0)) + T::splat(10.0))
}

#[inline(always)]
fn linear<T: Lanes>(a: T, b: T, alpha: T) -> T {
    b * alpha + a * (T::splat(1.0) - alpha)
}

impl NoiseFn<f64, 3> for BranchlessPerlin {
    #[inline]
    fn get(&self, point: [f64; 3]) -> f64 {
        self.get_in(point, &mut Cell::default())
    }
}

/// The gradients at the eight corners of the lattice cell last sampled.
///
/// Why: neighbouring voxel columns are a voxel apart, and every octave
/// with a wavelength of many voxels puts long runs of them in one cell.
/// Their corner hashes (14 dependent table reads) are then the same, and
/// only the arithmetic is left per sample.
#[derive(Clone, Copy, Debug)]
pub struct Cell {
    /// The cell's lowest corner; `isize::MIN` (no cell `corner` gives for
    /// finite points) before the first sample.
    corner: [isize; 3],
    /// `corner` as floats, for the four-lane path's compares.
    corner_as_floats: [f64; 3],
    /// Gradient components by corner, `x + 2y + 4z` order.
    gradients: [[f64; 3]; 8],
}

impl Default for Cell {
    fn default() -> Self {
        Self { corner: [isize::MIN; 3], corner_as_floats: [f64::NAN; 3], gradients: [[0.0; 3]; 8] }
    }
}

impl BranchlessPerlin {
    /// The noise at `point`, reusing `cell`'s gradients when the point
    /// lies in the same lattice cell as the last one sampled with it. Equal
    /// to [`NoiseFn::get`] whatever `cell` held before.
    #[inline(always)]
    pub fn get_in(&self, point: [f64; 3], cell: &mut Cell) -> f64 {
        let offset = self.enter(point, cell);
        kernel(offset, &cell.gradients)
    }

    /// [`Self::get_in`] of two points: where the second lies in the
    /// first's cell (neighbouring columns, most octaves) both are blended
    /// at once in the two lanes of an SSE2 register.
    #[inline(always)]
    fn get2_in(&self, [first, second]: [[f64; 3]; 2], cell: &mut Cell) -> [f64; 2] {
        let a = self.enter(first, cell);
        if !same_cell(corners(second), cell.corner) {
            let a = kernel(a, &cell.gradients);
            return [a, self.get_in(second, cell)];
        }
        let b = self.enter(second, cell);
        let lanes = |axis: usize| f64x2::new([a[axis], b[axis]]);
        kernel([lanes(0), lanes(1), lanes(2)], &cell.gradients).to_array()
    }

    /// [`Self::get_in`] of four points: where all lie in one cell
    /// (neighbouring columns, the octaves many columns long) blended at
    /// once in the four lanes of an AVX2 register, otherwise as two
    /// pairs. Called from [`Fractal::step`]'s AVX2 build only.
    #[inline(always)]
    fn get4_in(&self, points: [[f64; 3]; 4], cell: &mut Cell) -> [f64; 4] {
        let axis = |a: usize| Quad([points[0][a], points[1][a], points[2][a], points[3][a]]);
        let (x, y, z) = (axis(0), axis(1), axis(2));
        let (cx, cy, cz) = (x.corner(), y.corner(), z.corner());
        let offsets = [x - cx, y - cy, z - cz];
        let lane_corner = |k: usize| [cx.0[k], cy.0[k], cz.0[k]];
        let same = |a: usize, b: usize| {
            let ([ax, ay, az], [bx, by, bz]) = (lane_corner(a), lane_corner(b));
            (ax == bx) & (ay == by) & (az == bz)
        };
        if same(0, 1) & same(0, 2) & same(0, 3) {
            self.move_to(lane_corner(0), cell);
            return kernel(offsets, &cell.gradients).0;
        }
        let [a, b] = self.get2_in([points[0], points[1]], cell);
        let [c, d] = self.get2_in([points[2], points[3]], cell);
        [a, b, c, d]
    }

    /// Moves `cell` to the cell whose lowest corner is `corner` (whole
    /// numbers, as floats), hashing its corners only if it is another.
    #[inline(always)]
    fn move_to(&self, corner: [f64; 3], cell: &mut Cell) {
        let [x, y, z] = cell.corner_as_floats;
        if (corner[0] != x) | (corner[1] != y) | (corner[2] != z) {
            self.hash_corners(corner.map(|c| c as isize), cell);
        }
    }

    /// Moves `cell` to `point`'s lattice cell (hashing its corners only if
    /// it is another cell) and returns the point's offset in the cell.
    #[inline(always)]
    fn enter(&self, point: [f64; 3], cell: &mut Cell) -> [f64; 3] {
        let corner = corners(point);
        if !same_cell(corner, cell.corner) {
            self.hash_corners(corner, cell);
        }
        let [cx, cy, cz] = corner;
        [point[0] - cx as f64, point[1] - cy as f64, point[2] - cz as f64]
    }

    /// Moves `cell` to the cell whose lowest corner is `corner`: its
    /// corners' gradients from the permutation table.
    #[inline(always)]
    fn hash_corners(&self, corner: [isize; 3], cell: &mut Cell) {
        let [cx, cy, cz] = corner;
        cell.corner = corner;
        cell.corner_as_floats = corner.map(|c| c as f64);
        // hash(a, b, c) = P[P[P[a] ^ b] ^ c] with every coordinate & 0xff.
        let (x0, x1) = (self.entry(cx), self.entry(cx + 1));
        let mask = |v: isize| (v & 0xff) as usize;
        let (y0, y1, z0, z1) = (mask(cy), mask(cy + 1), mask(cz), mask(cz + 1));
        let (a00, a10, a01, a11) = (x0 ^ y0, x1 ^ y0, x0 ^ y1, x1 ^ y1);
        let gradient = |xy: usize, z_index: usize| {
            let h = usize::from(self.table[usize::from(self.table[xy]) ^ z_index]) & 15;
            [GRAD_X[h], GRAD_Y[h], GRAD_Z[h]]
        };
        cell.gradients = [
            gradient(a00, z0),
            gradient(a10, z0),
            gradient(a01, z0),
            gradient(a11, z0),
            gradient(a00, z1),
            gradient(a10, z1),
            gradient(a01, z1),
            gradient(a11, z1),
        ];
    }
}

/// Perlin's blend of the corner gradients at `offset` in the cell, as
/// `noise::core::perlin::perlin_3d` orders the arithmetic.
#[inline(always)]
fn kernel<T: Lanes>([x, y, z]: [T; 3], gradients: &[[f64; 3]; 8]) -> T {
    let g = |k: usize, axis: usize| T::splat(gradients[k][axis]);
    let dot = |k: usize, dx: T, dy: T, dz: T| g(k, 0) * dx + g(k, 1) * dy + g(k, 2) * dz;
    let one = T::splat(1.0);
    let g000 = dot(0, x, y, z);
    let g100 = dot(1, x - one, y, z);
    let g010 = dot(2, x, y - one, z);
    let g110 = dot(3, x - one, y - one, z);
    let g001 = dot(4, x, y, z - one);
    let g101 = dot(5, x - one, y, z - one);
    let g011 = dot(6, x, y - one, z - one);
    let g111 = dot(7, x - one, y - one, z - one);
    let (u, v, w) = (quintic(x), quintic(y), quintic(z));
    let result = linear(
        linear(linear(g000, g001, w), linear(g010, g011, w), v),
        linear(linear(g100, g101, w), linear(g110, g111, w), v),
        u,
    ) * T::splat(SCALE_FACTOR);
    result.clamp_to(-1.0, 1.0)
}

/// How a [`Fractal`] sums its octaves.
#[derive(Clone, Copy, Debug, PartialEq)]
enum FractalKind {
    /// `noise::Fbm`: octave `k` weighted by persistence^(k+1).
    Fbm,
    /// `noise::RidgedMulti`: `(1 − |n|)²`, each octave weighted by the
    /// previous one's signal.
    Ridged,
}

/// A fractal sum of [`BranchlessPerlin`] octaves, equal value for value to
/// `noise::Fbm` or `noise::RidgedMulti` (frequency 1) over the same
/// octaves, evaluated for many points at once.
///
/// Why batches: the points of a chunk's voxel columns are evaluated octave
/// by octave, each octave through one [`Cell`], so a run of columns in one
/// lattice cell pays its corner hashes once (see [`Cell`]). The arithmetic
/// per point is the same as `noise`'s, in the same order, so the sums are
/// bit-identical to the one-point path (`matches_the_noise_crate`).
#[derive(Clone, Debug)]
pub struct Fractal {
    kind: FractalKind,
    sources: Vec<BranchlessPerlin>,
    persistence: f64,
    lacunarity: f64,
    scale_factor: f64,
}

/// `noise::RidgedMulti`'s attenuation (its default).
const RIDGED_ATTENUATION: f64 = 2.0;

/// The steepest [`BranchlessPerlin`] gets: its largest gradient, per unit
/// of noise space, is 2.5·√3 (4.3301…), rounded up.
///
/// Where it comes from: local search over the kernel's corner gradients
/// and offsets, from 20,000 random starts (400 in
/// `no_gradient_steeper_than_the_bound`), converges on 2.5·√3 and never
/// beyond: at a cell's centre, along an axis, the fade's steepest slope
/// (15/8) times a difference of 2 across the cell, scaled by 2/√3. Found,
/// not proven, like the planet's slope bound.
pub const PERLIN_MAX_GRADIENT: f64 = 4.3302;

impl Fractal {
    /// `noise::Fbm::<Perlin>::new(seed)` with these octaves, persistence and
    /// lacunarity.
    #[must_use]
    pub fn fbm(seed: u32, octaves: usize, persistence: f64, lacunarity: f64) -> Self {
        // As `noise::Fbm::calc_scale_factor`.
        let denominator = (1..=octaves).fold(0.0, |acc, x| acc + persistence.powi(x as i32));
        Self {
            kind: FractalKind::Fbm,
            sources: Self::sources(seed, octaves),
            persistence,
            lacunarity,
            scale_factor: 1.0 / denominator,
        }
    }

    /// `noise::RidgedMulti::<Perlin>::new(seed)` with these octaves and
    /// lacunarity (persistence 1, attenuation 2: its defaults).
    #[must_use]
    pub fn ridged(seed: u32, octaves: usize, lacunarity: f64) -> Self {
        let persistence = 1.0;
        // As `noise::RidgedMulti::calc_scale_factor`.
        let (mut amplitude, mut weight) = (1.0_f64, 1.0_f64);
        let mut signal = weight * amplitude;
        let mut denominator = signal;
        for x in 1..=octaves {
            amplitude *= persistence;
            weight = (signal / RIDGED_ATTENUATION.powi(x as i32)).clamp(0.0, 1.0);
            signal = weight * amplitude;
            denominator += signal;
        }
        Self {
            kind: FractalKind::Ridged,
            sources: Self::sources(seed, octaves),
            persistence,
            lacunarity,
            scale_factor: 2.0 / denominator,
        }
    }

    /// As `noise`'s `build_sources`: octave `k` is seeded `seed + k`.
    fn sources(seed: u32, octaves: usize) -> Vec<BranchlessPerlin> {
        (0..octaves).map(|k| BranchlessPerlin::new(seed.wrapping_add(k as u32))).collect()
    }

    /// The same sum without the octaves past the first `octaves` (all of
    /// them where it has no more), scaled as this one: its value at a point
    /// is this one's partial sum, bit for bit, and its bounds and rest
    /// those of the octaves it keeps.
    #[must_use]
    pub fn with_octaves(&self, octaves: usize) -> Self {
        Self { sources: self.sources[..octaves.min(self.sources.len())].to_vec(), ..self.clone() }
    }

    /// The sum at one point.
    #[must_use]
    pub fn get(&self, point: [f64; 3]) -> f64 {
        let mut point = point;
        let mut sum = 0.0;
        let mut weight = 1.0;
        let mut attenuation = self.first_attenuation();
        for source in &self.sources {
            sum += self.term(source.get(point), &mut weight) * attenuation;
            point = point.map(|c| c * self.lacunarity);
            attenuation *= self.persistence;
        }
        self.finish(sum)
    }

    /// Bounds `(low, high)` of the sum anywhere within `radius` (noise
    /// space) of `point`.
    ///
    /// Each octave's noise is its value at `point` give or take its
    /// steepest change over the radius ([`PERLIN_MAX_GRADIENT`] times the
    /// octave's frequency), within [−1, 1]; octaves too fine for that to
    /// say anything are not evaluated. The octaves' ranges are summed as
    /// [`Self::get`] sums their values (a ridged octave's signal
    /// `(1 − |n|)²` falls as `|n|` grows, and scales the next one's weight),
    /// so the bounds cost at most one evaluation and are tight where the
    /// radius is small against the coarse octaves' wavelengths.
    ///
    /// `widen[k]` (noise space, 0 where missing) adds to the radius for
    /// octave `k` alone: the planet reads some octaves from grid nodes up
    /// to that far from the point ([`crate::octave_grid`]). The ranges
    /// of the running sum and of the ridged weight bound every state a
    /// point within reach can carry, so a blend of such states (what a grid
    /// interpolates) stays within them.
    #[must_use]
    pub fn range_near(&self, point: [f64; 3], radius: f64, widen: &[f64]) -> (f64, f64) {
        let mut point = point;
        let (mut low, mut high) = (0.0, 0.0);
        let (mut weight_low, mut weight_high) = (1.0_f64, 1.0_f64);
        let mut attenuation = self.first_attenuation();
        let mut frequency = 1.0;
        for (k, source) in self.sources.iter().enumerate() {
            let reach = (radius + widen.get(k).copied().unwrap_or(0.0)) * PERLIN_MAX_GRADIENT * frequency;
            frequency *= self.lacunarity;
            let (noise_low, noise_high) = if reach >= 2.0 {
                (-1.0, 1.0)
            } else {
                let noise = source.get(point);
                ((noise - reach).max(-1.0), (noise + reach).min(1.0))
            };
            let (term_low, term_high) = match self.kind {
                FractalKind::Fbm => (noise_low, noise_high),
                FractalKind::Ridged => {
                    let farthest = noise_low.abs().max(noise_high.abs());
                    let nearest =
                        if noise_low <= 0.0 && noise_high >= 0.0 { 0.0 } else { noise_low.abs().min(noise_high.abs()) };
                    let signal_low = (1.0 - farthest) * (1.0 - farthest) * weight_low;
                    let signal_high = (1.0 - nearest) * (1.0 - nearest) * weight_high;
                    weight_low = (signal_low / RIDGED_ATTENUATION).clamp(0.0, 1.0);
                    weight_high = (signal_high / RIDGED_ATTENUATION).clamp(0.0, 1.0);
                    (signal_low, signal_high)
                }
            };
            low += term_low * attenuation;
            high += term_high * attenuation;
            point = point.map(|c| c * self.lacunarity);
            attenuation *= self.persistence;
        }
        (self.finish(low), self.finish(high))
    }

    /// The first octave's weight: persistence for `Fbm`, 1 for
    /// `RidgedMulti`.
    fn first_attenuation(&self) -> f64 {
        match self.kind {
            FractalKind::Fbm => self.persistence,
            FractalKind::Ridged => 1.0,
        }
    }

    /// An octave's contribution (before its weight) from its noise;
    /// `weight` carries the ridged octaves' weighting along.
    #[inline(always)]
    fn term(&self, noise: f64, weight: &mut f64) -> f64 {
        match self.kind {
            FractalKind::Fbm => noise,
            FractalKind::Ridged => ridge(noise, weight),
        }
    }

    /// The sum scaled to the noise crate's range.
    fn finish(&self, sum: f64) -> f64 {
        match self.kind {
            FractalKind::Fbm => sum * self.scale_factor,
            FractalKind::Ridged => sum * self.scale_factor - 1.0,
        }
    }

    /// The sums at `points` into `out` (the shorter length of the two;
    /// the rest of the longer is left alone), each bit for bit what
    /// [`Self::get`] gives: octave by octave over all points, each octave
    /// through one [`Cell`]. (The planet steps its heights' batches
    /// itself, [`Self::step`], to stop each column early; this is the
    /// whole sum.)
    pub fn get_many(&self, points: &[[f64; 3]], out: &mut [f64]) {
        let n = points.len().min(out.len());
        let mut batch = self.begin(&points[..n]);
        let all: Vec<usize> = (0..n).collect();
        while !batch.done(self) {
            self.step(&mut batch, &all);
        }
        for (k, sum) in out[..n].iter_mut().enumerate() {
            *sum = self.bounds(&batch, k).0;
        }
    }

    /// The octaves summed.
    #[must_use]
    pub fn octaves(&self) -> usize {
        self.sources.len()
    }

    /// Each octave's frequency over the one before.
    #[must_use]
    pub fn lacunarity(&self) -> f64 {
        self.lacunarity
    }

    /// The most octave `k` can add to the finished sum: an fBm octave's
    /// weight (its noise is within ±1), or a ridged one's signal, at most
    /// the weight the octaves before left (each at most half the last:
    /// [`Self::bounds`]), scaled as the sum is.
    #[must_use]
    pub fn octave_amplitude(&self, k: usize) -> f64 {
        let weight = match self.kind {
            FractalKind::Fbm => self.first_attenuation() * self.persistence.powi(k as i32),
            FractalKind::Ridged => RIDGED_ATTENUATION.powi(-(k as i32)),
        };
        weight * self.scale_factor
    }

    /// A sum over `points` with no octave in yet: [`Self::step`] adds them
    /// one at a time, for the points still wanted, and [`Self::bounds`]
    /// says how far each sum can still go.
    #[must_use]
    pub fn begin(&self, points: &[[f64; 3]]) -> FractalBatch {
        self.resume(points, &vec![OctaveState::START; points.len()], 0)
    }

    /// A sum over `points` (at the first octave's frequency) that goes on
    /// from `states` (one per point) at octave `octave`: [`Self::step`]
    /// adds the octaves from there. The point's scaling and the octave's
    /// weight are reached by the same multiplications [`Self::step`]
    /// makes, so a sum resumed from the states a batch had after `octave`
    /// octaves ends bit for bit where that batch does. Where `octave` is
    /// past the last, nothing is stepped and `points` may be empty.
    #[must_use]
    pub fn resume(&self, points: &[[f64; 3]], states: &[OctaveState], octave: usize) -> FractalBatch {
        let octave = octave.min(self.sources.len());
        // A power-of-two lacunarity scales exactly: its power at once is
        // the repeated product (away from overflow and subnormals).
        let exact = self.lacunarity.log2().fract() == 0.0;
        let power = (0..octave).fold(1.0, |p, _| p * self.lacunarity);
        let scaled = points
            .iter()
            .map(|&point| {
                if exact {
                    point.map(|c| c * power)
                } else {
                    (0..octave).fold(point, |p, _| p.map(|c| c * self.lacunarity))
                }
            })
            .collect();
        let attenuation = (0..octave).fold(self.first_attenuation(), |a, _| a * self.persistence);
        FractalBatch {
            points: scaled,
            sums: states.iter().map(|s| s.sum).collect(),
            weights: states.iter().map(|s| s.weight).collect(),
            octave,
            attenuation,
            rest: self.rest(octave),
        }
    }

    /// Adds the next octave to the sums of the points `active` (indices
    /// into the batch, ascending); the others are left as they are and
    /// must not be stepped again. Each point's arithmetic is
    /// [`Self::get`]'s, so a point stepped through every octave ends bit
    /// for bit where `get` does.
    ///
    /// Four points a blend where the CPU has AVX2 (checked once, then a
    /// cached flag), two otherwise: the same values either way.
    pub fn step(&self, batch: &mut FractalBatch, active: &[usize]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // The workspace's one unsafe call: a function built for a CPU
            // feature may run only where the CPU has it.
            #[allow(unsafe_code)]
            // SAFETY: this CPU has AVX2, just checked.
            unsafe {
                self.step_avx2(batch, active);
            }
            return;
        }
        self.step_with::<false>(batch, active);
    }

    /// [`Self::step`] built for AVX2, four points a blend (a LOD-0 chunk's
    /// cold generation 208 → 184 µs, the same voxels). Call only where
    /// the CPU has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn step_avx2(&self, batch: &mut FractalBatch, active: &[usize]) {
        self.step_with::<true>(batch, active);
    }

    /// [`Self::step`]'s body: the points four at a time (`QUADS`, in an
    /// AVX2 build) or two.
    #[inline(always)]
    fn step_with<const QUADS: bool>(&self, batch: &mut FractalBatch, active: &[usize]) {
        let Some(source) = self.sources.get(batch.octave) else { return };
        let mut cell = Cell::default();
        for points in active.chunks(if QUADS { 4 } else { 2 }) {
            let signals = match *points {
                [a, b, c, d] if QUADS => {
                    source.get4_in([batch.points[a], batch.points[b], batch.points[c], batch.points[d]], &mut cell)
                }
                [a, b, c] => {
                    let [x, y] = source.get2_in([batch.points[a], batch.points[b]], &mut cell);
                    [x, y, source.get_in(batch.points[c], &mut cell), 0.0]
                }
                [a, b] => {
                    let [x, y] = source.get2_in([batch.points[a], batch.points[b]], &mut cell);
                    [x, y, 0.0, 0.0]
                }
                [a] => [source.get_in(batch.points[a], &mut cell), 0.0, 0.0, 0.0],
                _ => unreachable!("chunks of one to four"),
            };
            for (&at, signal) in points.iter().zip(signals) {
                batch.sums[at] += self.term(signal, &mut batch.weights[at]) * batch.attenuation;
                let [x, y, z] = batch.points[at];
                batch.points[at] = [x * self.lacunarity, y * self.lacunarity, z * self.lacunarity];
            }
        }
        batch.attenuation *= self.persistence;
        batch.octave += 1;
        batch.rest = self.rest(batch.octave);
    }

    /// How far the octaves after the first `octaves` can move an fBm sum
    /// at most, either way (0 for ridged sums, which depend on the point):
    /// for deciding when bounds are worth a look.
    #[must_use]
    pub fn fbm_rest(&self, octaves: usize) -> f64 {
        self.rest(octaves) * self.scale_factor
    }

    /// The weights of the octaves after the first `octaves`, summed (0 for
    /// ridged sums): how far they can move an fBm sum before scaling.
    fn rest(&self, octaves: usize) -> f64 {
        match self.kind {
            FractalKind::Fbm => {
                let left = self.sources.len().saturating_sub(octaves) as i32;
                let attenuation = self.first_attenuation() * self.persistence.powi(octaves as i32);
                attenuation * (1.0 - self.persistence.powi(left)) / (1.0 - self.persistence)
            }
            FractalKind::Ridged => 0.0,
        }
    }

    /// Bounds `(low, high)` of point `k`'s finished sum, from the octaves
    /// in so far: the remaining fBm octaves add at most their weights
    /// either way; a ridged octave's signal is at most the weight the one
    /// before left, which halves it, so the rest add between 0 and twice
    /// the current weight. Equal bounds, [`Self::get`]'s value, once every
    /// octave is in.
    #[must_use]
    pub fn bounds(&self, batch: &FractalBatch, k: usize) -> (f64, f64) {
        let sum = batch.sums[k];
        if batch.done(self) {
            let value = self.finish(sum);
            return (value, value);
        }
        match self.kind {
            FractalKind::Fbm => (self.finish(sum - batch.rest), self.finish(sum + batch.rest)),
            FractalKind::Ridged => (self.finish(sum), self.finish(sum + 2.0 * batch.weights[k])),
        }
    }
}

/// A [`Fractal`] sum in progress over many points, octave by octave.
#[derive(Clone, Debug)]
pub struct FractalBatch {
    /// Each point, scaled to the next octave's frequency.
    points: Vec<[f64; 3]>,
    sums: Vec<f64>,
    /// The ridged octaves' weights carried to the next octave.
    weights: Vec<f64>,
    /// The next octave.
    octave: usize,
    /// The next octave's weight.
    attenuation: f64,
    /// The weights of the octaves still to come, summed (fBm).
    rest: f64,
}

impl FractalBatch {
    /// Whether every octave of `fractal` is in.
    #[must_use]
    pub fn done(&self, fractal: &Fractal) -> bool {
        self.octave >= fractal.sources.len()
    }

    /// The next octave to come.
    #[must_use]
    pub fn octave(&self) -> usize {
        self.octave
    }

    /// Point `k`'s sum so far, to go on from ([`Fractal::resume`]).
    #[must_use]
    pub fn state(&self, k: usize) -> OctaveState {
        OctaveState { sum: self.sums[k], weight: self.weights[k] }
    }
}

/// Where a [`Fractal`] sum stands at one point after some octaves: the
/// unscaled sum and the weight a ridged sum carries to the next octave
/// (1 for fBm, which has none). Blends of states are what
/// [`crate::octave_grid`] interpolates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OctaveState {
    /// The octaves' terms summed, before [`Fractal`]'s scaling.
    pub sum: f64,
    /// The ridged weight for the next octave.
    pub weight: f64,
}

impl OctaveState {
    /// No octave in yet.
    pub const START: Self = Self { sum: 0.0, weight: 1.0 };

    /// `self + t·(other − self)`, both parts: `self` itself, bit for bit,
    /// at `t = 0` (a grid node reads as its own state) unless a part is
    /// −0, which no sum or weight is (they start at +0 and 1, and
    /// `+0 + −0` is `+0`).
    #[must_use]
    #[inline]
    pub fn lerp(self, other: Self, t: f64) -> Self {
        Self { sum: self.sum + t * (other.sum - self.sum), weight: self.weight + t * (other.weight - self.weight) }
    }
}

/// One ridged octave's signal from its noise, weighted by the previous
/// octave's `weight`, which becomes this one's (as `noise::RidgedMulti`).
#[inline(always)]
fn ridge(noise: f64, weight: &mut f64) -> f64 {
    let mut signal = 1.0 - noise.abs();
    signal *= signal;
    signal *= *weight;
    *weight = (signal / RIDGED_ATTENUATION).clamp(0.0, 1.0);
    signal
}

#[cfg(test)]
mod tests {
    use noise::{Fbm, MultiFractal, Perlin, RidgedMulti};

    use super::*;

    /// Equal to `noise::Perlin` (as numbers: ±0 may differ) on a million
    /// points: Earth-scale coordinates, exact integers (the corner rule's
    /// edge case), negative values, and through `Fbm` and `RidgedMulti`.
    #[test]
    fn matches_the_noise_crate() {
        let mut state = 0x2545_F491_4F6C_DD1D_u64;
        let mut next = || nebula_math::unit_random(&mut state);
        for seed in [0, 11, 12, 13, 0xdead_beef] {
            let (ours, theirs) = (BranchlessPerlin::new(seed), Perlin::new(seed));
            for n in 0..200_000 {
                let scale = [1.0, 40.0, 1.1e4, 1.4e6][n % 4];
                let mut p = [0.0; 3].map(|_| (next() * 2.0 - 1.0) * scale);
                if n % 7 == 0 {
                    p = p.map(f64::round); // lattice points, 0 and negatives included
                }
                assert_eq!(ours.get(p), theirs.get(p), "seed {seed} at {p:?}");
            }
        }
        let fbm_ours = Fractal::fbm(5, 16, 0.45, 2.0);
        let fbm_theirs = Fbm::<Perlin>::new(5).set_octaves(16).set_persistence(0.45).set_lacunarity(2.0);
        let hills_ours = Fractal::fbm(7, 8, 0.5, std::f64::consts::PI * 2.0 / 3.0);
        let hills_theirs = Fbm::<Perlin>::new(7).set_octaves(8).set_persistence(0.5);
        let ridged_ours = Fractal::ridged(6, 15, 2.0);
        let ridged_theirs = RidgedMulti::<Perlin>::new(6).set_octaves(15).set_lacunarity(2.0);
        for _ in 0..20_000 {
            let p = [0.0; 3].map(|_| (next() * 2.0 - 1.0) * 16.0);
            assert_eq!(fbm_ours.get(p), fbm_theirs.get(p));
            assert_eq!(hills_ours.get(p), hills_theirs.get(p));
            assert_eq!(ridged_ours.get(p), ridged_theirs.get(p));
        }
    }

    /// Local search from random starts over the kernel's corner
    /// gradients (each one of the 12) and offsets finds no gradient
    /// steeper than [`PERLIN_MAX_GRADIENT`], and comes within 1 % of it
    /// (so the bound is not slack either).
    #[test]
    fn no_gradient_steeper_than_the_bound() {
        fn steepness(gradients: &[[f64; 3]; 8], p: [f64; 3]) -> f64 {
            let h = 1e-6;
            let f = |q: [f64; 3]| kernel::<f64>(q, gradients);
            (0..3)
                .map(|axis| {
                    let (mut a, mut b) = (p, p);
                    a[axis] += h;
                    b[axis] -= h;
                    ((f(a) - f(b)) / (2.0 * h)).powi(2)
                })
                .sum::<f64>()
                .sqrt()
        }
        let mut state = 99_u64;
        let mut next = || nebula_math::unit_random(&mut state);
        let gradient = |k: usize| [GRAD_X[k], GRAD_Y[k], GRAD_Z[k]];
        let mut steepest = 0.0_f64;
        for _ in 0..400 {
            let mut gradients: [[f64; 3]; 8] = std::array::from_fn(|_| gradient((next() * 12.0) as usize));
            let mut p = [0.0; 3].map(|_: f64| next() * 0.98 + 0.01);
            let mut best = steepness(&gradients, p);
            let mut step = 0.1;
            for _ in 0..40 {
                for corner in 0..8 {
                    for k in 0..12 {
                        let old = gradients[corner];
                        gradients[corner] = gradient(k);
                        let s = steepness(&gradients, p);
                        if s > best { best = s } else { gradients[corner] = old }
                    }
                }
                for axis in 0..3 {
                    for sign in [-1.0, 1.0] {
                        let mut q = p;
                        q[axis] = (q[axis] + sign * step).clamp(1e-5, 1.0 - 1e-5);
                        let s = steepness(&gradients, q);
                        if s > best {
                            best = s;
                            p = q;
                        }
                    }
                }
                step *= 0.85;
            }
            steepest = steepest.max(best);
        }
        println!("steepest gradient found {steepest}");
        assert!(steepest <= PERLIN_MAX_GRADIENT, "{steepest}");
        assert!(steepest > 0.99 * PERLIN_MAX_GRADIENT, "{steepest}");
    }

    /// Every value within the radius lies in [`Fractal::range_near`]'s
    /// bounds, for both kinds, from balls far smaller than the coarsest
    /// octave to larger than it; and the bounds narrow as the ball does.
    #[test]
    fn ranges_hold_every_value_near() {
        let fractals = [Fractal::fbm(5, 16, 0.45, 2.0), Fractal::ridged(6, 15, 2.0), Fractal::fbm(7, 8, 0.5, 2.1)];
        let mut state = 5_u64;
        let mut next = || nebula_math::unit_random(&mut state);
        for fractal in &fractals {
            let mut widths = Vec::new();
            for radius in [1e-4, 1e-3, 1e-2, 0.1, 1.0] {
                let mut width = 0.0;
                for _ in 0..200 {
                    let centre = [0.0; 3].map(|_: f64| (next() - 0.5) * 200.0);
                    let (low, high) = fractal.range_near(centre, radius, &[]);
                    width += high - low;
                    for _ in 0..20 {
                        // A point in the ball, on its surface half the time.
                        let d = [0.0; 3].map(|_: f64| next() - 0.5);
                        let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt();
                        let r = if next() < 0.5 { radius } else { radius * next() };
                        let at = [0, 1, 2].map(|a| centre[a] + d[a] / norm * r);
                        let value = fractal.get(at);
                        assert!(low <= value && value <= high, "{value} outside [{low}, {high}] at radius {radius}");
                    }
                }
                widths.push(width / 200.0);
            }
            println!("mean widths {widths:?}");
            assert!(widths.windows(2).all(|w| w[0] < w[1]), "{widths:?}");
            assert!(widths[0] < 0.05, "{widths:?}");
        }
    }

    /// At every octave, the bounds of a sum in progress hold its finished
    /// value, and narrow to it; points left out of a step keep their sums.
    #[test]
    fn bounds_in_progress_hold_the_finished_sums() {
        let fractals = [Fractal::fbm(5, 16, 0.45, 2.0), Fractal::ridged(6, 15, 2.0), Fractal::fbm(7, 8, 0.5, 2.1)];
        let mut state = 9_u64;
        let points: Vec<[f64; 3]> =
            (0..300).map(|_| [0.0; 3].map(|_: f64| (nebula_math::unit_random(&mut state) - 0.5) * 50.0)).collect();
        for fractal in &fractals {
            let finished: Vec<f64> = points.iter().map(|&p| fractal.get(p)).collect();
            let mut batch = fractal.begin(&points);
            let mut active: Vec<usize> = (0..points.len()).collect();
            let mut widths = Vec::new();
            while !batch.done(fractal) {
                let mut width = 0.0;
                for &k in &active {
                    let (low, high) = fractal.bounds(&batch, k);
                    assert!(low <= finished[k] && finished[k] <= high, "{} outside [{low}, {high}]", finished[k]);
                    width += high - low;
                }
                widths.push(width / active.len() as f64);
                fractal.step(&mut batch, &active);
                // Drop every third point for a while: the rest go on alone.
                if batch.octave == 3 {
                    let (kept, left): (Vec<usize>, Vec<usize>) = active.iter().partition(|&&k| k % 3 != 0);
                    for k in left {
                        let (low, high) = fractal.bounds(&batch, k);
                        assert!(low <= finished[k] && finished[k] <= high);
                    }
                    active = kept;
                }
            }
            for &k in &active {
                assert_eq!(fractal.bounds(&batch, k), (finished[k], finished[k]), "not get's value");
            }
            assert!(widths.windows(2).all(|w| w[1] <= w[0] + 1e-12), "{widths:?}");
        }
    }

    /// Many points at once give what one at a time gives, bit for bit:
    /// rows of points a small step apart (as a chunk's voxel columns, so
    /// cells are shared by runs of points), at Earth-scale offsets and at
    /// steps from far below to far above the cell size (an odd count, so a
    /// point is left over after the pairs).
    #[test]
    fn batches_equal_single_points() {
        let mut state = 0x005E_ED0F_BA7C_u64;
        let mut next = || nebula_math::unit_random(&mut state);
        let fractals = [Fractal::fbm(11, 16, 0.45, 2.0), Fractal::ridged(12, 15, 2.0), Fractal::fbm(13, 8, 0.5, 2.1)];
        for round in 0..60 {
            let origin = [0.0; 3].map(|_| (next() * 2.0 - 1.0) * [1.0, 3e2, 1.6e6][round % 3]);
            let step = [0.0; 3].map(|_| (next() * 2.0 - 1.0) * [1e-4, 0.03, 0.6, 7.0][round % 4]);
            let points: Vec<[f64; 3]> = (0..301)
                .map(|k| [0, 1, 2].map(|a| origin[a] + step[a] * f64::from(k % 17) + 0.01 * f64::from(k / 17)))
                .collect();
            for fractal in &fractals {
                let mut batch = vec![0.0; points.len()];
                fractal.get_many(&points, &mut batch);
                for (point, value) in points.iter().zip(&batch) {
                    assert_eq!(value.to_bits(), fractal.get(*point).to_bits(), "{fractal:?} at {point:?}");
                }
            }
        }
    }

    /// Two points a blend (the build without AVX2) and four (this CPU's
    /// AVX2 build, where it has one) give the same sums to the bit, over
    /// rows of points as a chunk's columns come, in one cell and across
    /// many, with some points left out of some octaves.
    #[test]
    fn four_lanes_equal_two() {
        let mut state = 0x0F0F_1234_u64;
        let mut next = || nebula_math::unit_random(&mut state);
        let fractals = [Fractal::fbm(21, 12, 0.5, 2.1), Fractal::ridged(22, 9, 2.0)];
        for round in 0..40 {
            let origin = [0.0; 3].map(|_| (next() * 2.0 - 1.0) * [3.0, 7e2, 2e6][round % 3]);
            let step = [0.0; 3].map(|_| (next() * 2.0 - 1.0) * [1e-3, 0.05, 0.9][round % 3]);
            let points: Vec<[f64; 3]> =
                (0..203).map(|k| [0, 1, 2].map(|a| origin[a] + step[a] * f64::from(k))).collect();
            for fractal in &fractals {
                let (mut pairs, mut dispatched) = (fractal.begin(&points), fractal.begin(&points));
                let mut active: Vec<usize> = (0..points.len()).collect();
                while !pairs.done(fractal) {
                    fractal.step_with::<false>(&mut pairs, &active);
                    fractal.step(&mut dispatched, &active);
                    active.retain(|&k| (k + pairs.octave()) % 5 != 0);
                }
                for k in 0..points.len() {
                    assert_eq!(pairs.sums[k].to_bits(), dispatched.sums[k].to_bits(), "{fractal:?} point {k}");
                }
            }
        }
        #[cfg(target_arch = "x86_64")]
        println!("AVX2 here: {}", std::arch::is_x86_feature_detected!("avx2"));
    }

    /// The batch check can fail: a cell cache that keeps gradients after
    /// the point moved to another cell gives other values.
    #[test]
    fn a_stale_cell_is_seen() {
        let perlin = BranchlessPerlin::new(4);
        let mut cell = Cell::default();
        let first = perlin.get_in([0.5, 0.5, 0.5], &mut cell);
        assert_eq!(first, perlin.get([0.5, 0.5, 0.5]));
        // Pretend the next point is in the same cell: the stale gradients
        // give a value other than the true one somewhere.
        let differs = (1..100).any(|k| {
            let p = [0.5 + f64::from(k), 0.25, 0.75];
            let mut stale = cell;
            stale.corner = p.map(corner);
            perlin.get_in(p, &mut stale) != perlin.get(p)
        });
        assert!(differs);
    }

    /// The check can fail: a permutation table with two entries swapped is seen.
    #[test]
    fn a_wrong_table_is_seen() {
        let theirs = Perlin::new(3);
        let mut ours = BranchlessPerlin::new(3);
        // Swap two table entries: a different hash somewhere.
        ours.table.swap(0, 1);
        let differs = (0..10_000).any(|n| {
            let p = [n as f64 * 0.37, n as f64 * 0.11, 0.5];
            ours.get(p) != theirs.get(p)
        });
        assert!(differs);
    }
}
