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

use noise::permutationtable::{NoiseHasher, PermutationTable};
use noise::{NoiseFn, Seedable};

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

#[inline(always)]
fn quintic(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * x * (x * (x * 6.0 - 15.0) + 10.0)
}

#[inline(always)]
fn linear(a: f64, b: f64, alpha: f64) -> f64 {
    b * alpha + a * (1.0 - alpha)
}

impl NoiseFn<f64, 3> for BranchlessPerlin {
    #[inline]
    fn get(&self, point: [f64; 3]) -> f64 {
        let [cx, cy, cz] = point.map(corner);
        let (x, y, z) = (point[0] - cx as f64, point[1] - cy as f64, point[2] - cz as f64);
        // hash(a, b, c) = P[P[P[a] ^ b] ^ c] with every coordinate & 0xff.
        let (x0, x1) = (self.entry(cx), self.entry(cx + 1));
        let mask = |v: isize| (v & 0xff) as usize;
        let (y0, y1, z0, z1) = (mask(cy), mask(cy + 1), mask(cz), mask(cz + 1));
        let grad = |xy: usize, z_index: usize, dx: f64, dy: f64, dz: f64| {
            let h = usize::from(self.table[usize::from(self.table[xy]) ^ z_index]) & 15;
            GRAD_X[h] * dx + GRAD_Y[h] * dy + GRAD_Z[h] * dz
        };
        let (a00, a10, a01, a11) = (x0 ^ y0, x1 ^ y0, x0 ^ y1, x1 ^ y1);
        let g000 = grad(a00, z0, x, y, z);
        let g100 = grad(a10, z0, x - 1.0, y, z);
        let g010 = grad(a01, z0, x, y - 1.0, z);
        let g110 = grad(a11, z0, x - 1.0, y - 1.0, z);
        let g001 = grad(a00, z1, x, y, z - 1.0);
        let g101 = grad(a10, z1, x - 1.0, y, z - 1.0);
        let g011 = grad(a01, z1, x, y - 1.0, z - 1.0);
        let g111 = grad(a11, z1, x - 1.0, y - 1.0, z - 1.0);
        let (u, v, w) = (quintic(x), quintic(y), quintic(z));
        let result = linear(
            linear(linear(g000, g001, w), linear(g010, g011, w), v),
            linear(linear(g100, g101, w), linear(g110, g111, w), v),
            u,
        ) * SCALE_FACTOR;
        result.clamp(-1.0, 1.0)
    }
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
        let fbm_ours = Fbm::<BranchlessPerlin>::new(5).set_octaves(16).set_persistence(0.45);
        let fbm_theirs = Fbm::<Perlin>::new(5).set_octaves(16).set_persistence(0.45);
        let ridged_ours = RidgedMulti::<BranchlessPerlin>::new(6).set_octaves(15);
        let ridged_theirs = RidgedMulti::<Perlin>::new(6).set_octaves(15);
        for _ in 0..20_000 {
            let p = [0.0; 3].map(|_| (next() * 2.0 - 1.0) * 16.0);
            assert_eq!(fbm_ours.get(p), fbm_theirs.get(p));
            assert_eq!(ridged_ours.get(p), ridged_theirs.get(p));
        }
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
