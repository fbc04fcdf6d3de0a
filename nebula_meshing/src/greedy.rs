//! Bitmask greedy quads of a padded chunk, read from its solid rows.
//!
//! The same quads, in the same order, as block-mesh-bgm's
//! `binary_greedy_quads` over the chunk with block-mesh's
//! `RIGHT_HANDED_Y_UP_CONFIG` (a test holds the two equal): per face
//! direction, slice by slice along the normal, a row's visible faces are a
//! bitmask; runs of a bit carry on to the next row while that row shows the
//! same material there, and where they end, neighbouring ended bits of one
//! material and one run length merge into a quad.
//!
//! Why not that crate: it reads the 34³ voxels one by one through
//! block-mesh's visibility trait to build its masks, half of its time on a
//! terrain chunk. Here the masks come from [`ChunkVoxels::solid_rows`]
//! (sixteen voxels a compare) and every face mask from those rows with a
//! few bit operations; only the faces across x are scattered bit by bit,
//! and they are few. Under the mountain flight a chunk's quads take a
//! third of the crate's time, and the rows give the sky floors for free.

use block_mesh::{QuadBuffer, UnorientedQuad};
use nebula_voxel::{ChunkVoxels, PADDED_CHUNK_SIZE, PADDED_ROWS, Voxel};

/// Padded voxels an axis.
const P: usize = PADDED_CHUNK_SIZE as usize;
/// The chunk's own voxels an axis (padding excluded).
const N: usize = P - 2;
/// Bits of a face row that are the chunk's own voxels, after the row is
/// shifted down past the padding voxel at bit 0.
const INTERIOR: u64 = (1 << N) - 1;

/// Strides of the padded layout (x fastest, then y, then z).
const STRIDE: [usize; 3] = [1, P, P * P];

/// Greedy quads of a padded chunk (the module docs above): the quads
/// block-mesh-bgm's `binary_greedy_quads` gives for the chunk with
/// block-mesh's `RIGHT_HANDED_Y_UP_CONFIG`, from the chunk's solid rows.
/// What [`ChunkMesher`](crate::ChunkMesher) starts from; for a game that
/// wants the quads alone. Keeps its scratch memory (about 40 KB) from one
/// chunk to the next.
///
/// ```
/// use nebula_meshing::GreedyQuads;
/// use nebula_voxel::{ChunkKey, ChunkVoxels, CubeFace, Voxel};
///
/// let mut voxels = ChunkVoxels::new(ChunkKey { face: CubeFace::PosX, lod: 0, x: 0, y: 0, layer: 0 });
/// // A 2 × 1 × 1 bar of stone: six quads, the long sides merged.
/// voxels.set([5, 6, 7], Voxel::STONE);
/// voxels.set([6, 6, 7], Voxel::STONE);
/// let mut greedy = GreedyQuads::new();
/// greedy.mesh(&voxels);
/// assert_eq!(greedy.quads().num_quads(), 6);
/// ```
pub struct GreedyQuads {
    /// The quads, grouped as block-mesh's `RIGHT_HANDED_Y_UP_CONFIG`
    /// orders its faces: −x, −y, −z, +x, +y, +z.
    pub(crate) quads: QuadBuffer,
    /// The chunk's [`ChunkVoxels::solid_rows`].
    pub(crate) rows: Box<[u64; PADDED_ROWS]>,
    /// The visible faces of one direction: per slice along the normal and
    /// row along the outer axis (`slice · 32 + row`), a bit per face along
    /// the bit axis (see [`Plan`]).
    faces: Box<[[u64; N]; N]>,
    /// The same for the direction opposite (x faces are found both ways
    /// in one pass).
    faces_opposite: Box<[[u64; N]; N]>,
    /// Per bit of the row being merged: rows its run has carried on for.
    carry: [u8; N],
}

impl Default for GreedyQuads {
    fn default() -> Self {
        Self::new()
    }
}

impl GreedyQuads {
    /// The last chunk's quads, grouped by face as block-mesh's
    /// `RIGHT_HANDED_Y_UP_CONFIG` orders its faces (−x, −y, −z, +x, +y,
    /// +z), in padded coordinates.
    #[must_use]
    pub fn quads(&self) -> &QuadBuffer {
        &self.quads
    }
}

/// How one normal axis is scanned (block-mesh-bgm's plan, so that the
/// quads are its quads): slices along the normal, rows along `outer`, bits
/// along `bit`.
#[derive(Clone, Copy)]
struct Plan {
    normal: usize,
    outer: usize,
    bit: usize,
}

impl Plan {
    const OF_NORMAL: [Plan; 3] = [
        Plan { normal: 0, outer: 2, bit: 1 },
        Plan { normal: 1, outer: 2, bit: 0 },
        Plan { normal: 2, outer: 1, bit: 0 },
    ];

    /// The quad starting at interior voxel `(slice, row, bit)` (0-based),
    /// `width` bits wide and `length` rows long, in padded coordinates with
    /// block-mesh's `u` and `v` (`u` is the bit axis only for z faces).
    fn quad(self, slice: usize, row: usize, bit: usize, width: usize, length: usize) -> UnorientedQuad {
        let mut minimum = [0; 3];
        minimum[self.normal] = slice as u32 + 1;
        minimum[self.outer] = row as u32 + 1;
        minimum[self.bit] = bit as u32 + 1;
        let (width, length) = (width as u32, length as u32);
        let (width, height) = if self.normal == 2 { (width, length) } else { (length, width) };
        UnorientedQuad { minimum, width, height }
    }
}

impl GreedyQuads {
    /// Empty scratch memory.
    #[must_use]
    pub fn new() -> Self {
        Self {
            quads: QuadBuffer::new(),
            rows: Box::new([0; PADDED_ROWS]),
            faces: Box::new([[0; N]; N]),
            faces_opposite: Box::new([[0; N]; N]),
            carry: [0; N],
        }
    }

    /// Meshes `voxels` (their padding read, not meshed) into
    /// [`GreedyQuads::quads`], replacing the last chunk's.
    pub fn mesh(&mut self, voxels: &ChunkVoxels) {
        self.quads.reset();
        voxels.solid_rows(&mut self.rows);
        let slice = voxels.as_slice();
        let rows = &*self.rows;
        let row = |y: usize, z: usize| rows[y + P * z];

        // x faces: within each row, a solid voxel whose neighbour along x
        // is not; scattered into slices of x, rows of z, bits of y.
        for faces in [&mut self.faces, &mut self.faces_opposite] {
            faces.iter_mut().for_each(|slice| slice.fill(0));
        }
        let (mut active, mut active_opposite) = (0u64, 0u64);
        for z in 1..=N {
            for y in 1..=N {
                let solid = row(y, z);
                let scatter = |mut bits: u64, faces: &mut [[u64; N]; N], active: &mut u64| {
                    bits = (bits >> 1) & INTERIOR;
                    *active |= bits;
                    while bits != 0 {
                        faces[bits.trailing_zeros() as usize][z - 1] |= 1 << (y - 1);
                        bits &= bits - 1;
                    }
                };
                scatter(solid & !(solid << 1), &mut self.faces, &mut active);
                scatter(solid & !(solid >> 1), &mut self.faces_opposite, &mut active_opposite);
            }
        }
        let plan = Plan::OF_NORMAL[0];
        merge(plan, &self.faces, active, slice, &mut self.carry, &mut self.quads.groups[0]);
        merge(plan, &self.faces_opposite, active_opposite, slice, &mut self.carry, &mut self.quads.groups[3]);

        // y and z faces: a whole row against the row beside it along the
        // normal.
        for normal in [1, 2] {
            let plan = Plan::OF_NORMAL[normal];
            for (toward, group) in [(-1isize, normal), (1, normal + 3)] {
                let mut active = 0u64;
                for (s, faces) in self.faces.iter_mut().enumerate() {
                    let mut any = 0;
                    for (r, face) in faces.iter_mut().enumerate() {
                        let (n, o) = (s + 1, r + 1);
                        let beside = n.wrapping_add_signed(toward);
                        let (here, there) =
                            if normal == 1 { (row(n, o), row(beside, o)) } else { (row(o, n), row(o, beside)) };
                        *face = ((here & !there) >> 1) & INTERIOR;
                        any |= *face;
                    }
                    active |= u64::from(any != 0) << s;
                }
                merge(plan, &self.faces, active, slice, &mut self.carry, &mut self.quads.groups[group]);
            }
        }
    }
}

/// Merges the visible faces of one direction into quads (see the module
/// docs), slices in `active` only (a bit per slice; x faces pass every bit
/// any of their rows holds, a superset).
fn merge(
    plan: Plan,
    faces: &[[u64; N]; N],
    active: u64,
    voxels: &[Voxel],
    carry: &mut [u8; N],
    quads: &mut Vec<UnorientedQuad>,
) {
    let (outer, bit_stride) = (STRIDE[plan.outer], STRIDE[plan.bit]);
    let mut slices = active;
    while slices != 0 {
        let s = slices.trailing_zeros() as usize;
        slices &= slices - 1;
        let rows = &faces[s];
        carry.fill(0);
        // Padded index of the slice's interior voxel (row 0, bit 0).
        let base = (s + 1) * STRIDE[plan.normal] + outer + bit_stride;
        for (r, &bits) in rows.iter().enumerate() {
            if bits == 0 {
                continue;
            }
            let at = base + r * outer;
            let voxel = |bit: usize| voxels[at + bit * bit_stride];
            // Runs carry on where the next row shows a face of the same
            // material right beside this one.
            let mut overlap = bits & rows.get(r + 1).copied().unwrap_or(0);
            let mut carried = 0u64;
            while overlap != 0 {
                let bit = overlap.trailing_zeros() as usize;
                overlap &= overlap - 1;
                if voxels[at + bit * bit_stride + outer] == voxel(bit) {
                    carried |= 1 << bit;
                    carry[bit] += 1;
                }
            }
            let mut ended = bits & !carried;
            while ended != 0 {
                let bit = ended.trailing_zeros() as usize;
                let (material, length) = (voxel(bit), carry[bit]);
                let mut width = 1;
                while bit + width < N
                    && ended & (1 << (bit + width)) != 0
                    && carry[bit + width] == length
                    && voxel(bit + width) == material
                {
                    carry[bit + width] = 0;
                    width += 1;
                }
                ended &= !(((1u64 << width) - 1) << bit);
                carry[bit] = 0;
                quads.push(plan.quad(s, r - usize::from(length), bit, width, usize::from(length) + 1));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use block_mesh::RIGHT_HANDED_Y_UP_CONFIG;
    use block_mesh::ndshape::ConstShape;
    use block_mesh_bgm::{BinaryGreedyQuadsBuffer, binary_greedy_quads};
    use nebula_voxel::{ChunkKey, CubeFace, PADDED_CHUNK_VOLUME, PaddedChunkShape};
    use proptest::prelude::*;

    /// Quads group by group, each as `(minimum, width, height)`.
    type Groups = Vec<Vec<([u32; 3], u32, u32)>>;

    /// block-mesh-bgm's quads of `voxels`.
    fn reference(voxels: &ChunkVoxels) -> Groups {
        let mut buffer = BinaryGreedyQuadsBuffer::new();
        let faces = &RIGHT_HANDED_Y_UP_CONFIG.faces;
        binary_greedy_quads(voxels.as_slice(), &PaddedChunkShape {}, [0; 3], [P as u32 - 1; 3], faces, &mut buffer);
        flatten(&buffer.quads)
    }

    fn flatten(quads: &QuadBuffer) -> Groups {
        quads.groups.iter().map(|group| group.iter().map(|q| (q.minimum, q.width, q.height)).collect()).collect()
    }

    /// Voxels of up to `materials` kinds with `density` solid, in layers
    /// whose ground rises and falls (`ground`), so that faces merge as on
    /// terrain, plus speckle.
    fn chunk(seed: u64, density: f64, materials: u8, ground: bool) -> ChunkVoxels {
        let mut state = seed | 1;
        let key = ChunkKey { face: CubeFace::PosX, lod: 0, x: 0, y: 0, layer: 0 };
        let mut voxels = ChunkVoxels::new(key);
        let (tilt_x, tilt_z) = (nebula_math::unit_random(&mut state), nebula_math::unit_random(&mut state));
        for index in 0..PADDED_CHUNK_VOLUME {
            let [x, y, z] = PaddedChunkShape::delinearize(index as u32);
            let roll = nebula_math::unit_random(&mut state);
            let solid = if ground {
                let height = 8.0 + 16.0 * (tilt_x * f64::from(x) / 34.0 + tilt_z * f64::from(z) / 34.0);
                (f64::from(y) < height) != (roll < 1.0 - density)
            } else {
                roll < density
            };
            let material = 1 + (u64::from(x / 5 + y / 7 + z / 3) % u64::from(materials)) as u8;
            voxels.set([x, y, z], if solid { Voxel::from_material(material) } else { Voxel::AIR });
        }
        voxels
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        /// The quads are block-mesh-bgm's, group by group and in order, on
        /// speckled voxels and on rolling ground of one to four materials.
        #[test]
        fn the_quads_are_block_mesh_bgms(
            seed in any::<u64>(), density in 0.0f64..1.0, materials in 1u8..=4, ground in any::<bool>(),
        ) {
            let voxels = chunk(seed, density, materials, ground);
            let mut greedy = GreedyQuads::new();
            greedy.mesh(&voxels);
            prop_assert_eq!(flatten(&greedy.quads), reference(&voxels));
        }
    }

    /// All air, all rock, and one voxel: no quads, none, and six.
    #[test]
    fn empty_full_and_single_chunks() {
        let key = ChunkKey { face: CubeFace::PosX, lod: 0, x: 0, y: 0, layer: 0 };
        let mut greedy = GreedyQuads::new();
        let mut voxels = ChunkVoxels::new(key);
        greedy.mesh(&voxels);
        assert_eq!(greedy.quads.num_quads(), 0);
        voxels.as_mut_slice().fill(Voxel::STONE);
        greedy.mesh(&voxels);
        assert_eq!(greedy.quads.num_quads(), 0);
        voxels.as_mut_slice().fill(Voxel::AIR);
        voxels.set([5, 6, 7], Voxel::STONE);
        greedy.mesh(&voxels);
        assert_eq!(greedy.quads.num_quads(), 6);
        assert_eq!(flatten(&greedy.quads), reference(&voxels));
    }
}
