//! The padded voxel array of one chunk.

use ndshape::{ConstShape, ConstShape3u32};

use crate::{CHUNK_SIZE, ChunkKey, Voxel, VoxelError};

/// Voxels along each edge of a padded chunk: 32 plus one layer of padding on
/// each side, read from the neighbours so the mesher can see across.
pub const PADDED_CHUNK_SIZE: u32 = CHUNK_SIZE + 2;

/// The shape of a padded chunk as block-mesh expects it: index
/// `x + 34·y + 34²·z` (x fastest), with x = u, y = radial, z = v.
pub type PaddedChunkShape = ConstShape3u32<PADDED_CHUNK_SIZE, PADDED_CHUNK_SIZE, PADDED_CHUNK_SIZE>;

/// Voxels in a padded chunk: 34³ = 39,304.
pub const PADDED_CHUNK_VOLUME: usize = PaddedChunkShape::USIZE;

/// The voxels of one chunk plus a one-voxel padding layer, in
/// [`PaddedChunkShape`] order. Padded coordinates run `0..34`; the chunk's own
/// voxel `(x, y, z)` sits at padded `(x + 1, y + 1, z + 1)`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChunkVoxels {
    key: ChunkKey,
    voxels: Box<[Voxel]>,
    /// Per padded voxel column (`x + 34·z`), whether something solid lies
    /// above the padded chunk, between it and the sky, as the source set it
    /// ([`ChunkVoxels::set_covered_above`]); `None` until a source does.
    covered_above: Option<Box<[u64; COLUMN_WORDS]>>,
}

/// Voxel columns of a padded chunk: 34².
pub const PADDED_COLUMNS: usize = (PADDED_CHUNK_SIZE * PADDED_CHUNK_SIZE) as usize;

/// Voxel rows (along x) of a padded chunk, one per `(y, z)`: 34².
pub const PADDED_ROWS: usize = (PADDED_CHUNK_SIZE * PADDED_CHUNK_SIZE) as usize;

/// 64-bit words of a bit per padded column.
const COLUMN_WORDS: usize = PADDED_COLUMNS.div_ceil(64);

impl ChunkVoxels {
    /// An all-air chunk for `key` (fill it with
    /// [`VoxelSource::fill_chunk`](crate::VoxelSource::fill_chunk)).
    #[must_use]
    pub fn new(key: ChunkKey) -> Self {
        Self { key, voxels: vec![Voxel::AIR; PADDED_CHUNK_VOLUME].into_boxed_slice(), covered_above: None }
    }

    /// Wraps a caller-made voxel array.
    ///
    /// # Errors
    /// [`VoxelError::WrongVoxelCount`] unless `voxels.len()` is 34³.
    pub fn from_voxels(key: ChunkKey, voxels: Vec<Voxel>) -> Result<Self, VoxelError> {
        if voxels.len() != PADDED_CHUNK_VOLUME {
            return Err(VoxelError::WrongVoxelCount { expected: PADDED_CHUNK_VOLUME, got: voxels.len() });
        }
        Ok(Self { key, voxels: voxels.into_boxed_slice(), covered_above: None })
    }

    /// The chunk these voxels belong to.
    #[must_use]
    pub fn key(&self) -> ChunkKey {
        self.key
    }

    /// Re-labels the buffer for another chunk (voxels unchanged, what lies
    /// above forgotten), so one allocation can be reused across chunks.
    pub fn set_key(&mut self, key: ChunkKey) {
        self.key = key;
        self.covered_above = None;
    }

    /// Records whether padded voxel column `(x, z)` (each `0..34`) is
    /// covered above the padded chunk: some solid voxel lies between its
    /// top and the sky. Sources that know it (the procedural planet) set it
    /// for every column when they fill a chunk; without it the sky is taken
    /// to begin over any column whose top padded voxel is air (right above
    /// ground, wrong in a buried chunk whose top is cave).
    pub fn set_covered_above(&mut self, (x, z): (u32, u32), covered: bool) {
        if x >= PADDED_CHUNK_SIZE || z >= PADDED_CHUNK_SIZE {
            return;
        }
        let words = self.covered_above.get_or_insert_with(|| Box::new([0; COLUMN_WORDS]));
        let n = (x + PADDED_CHUNK_SIZE * z) as usize;
        if covered {
            words[n / 64] |= 1 << (n % 64);
        } else {
            words[n / 64] &= !(1 << (n % 64));
        }
    }

    /// Whether padded voxel column `(x, z)` is covered above the padded
    /// chunk, as its source recorded ([`ChunkVoxels::set_covered_above`]);
    /// `None` where the source recorded nothing or `(x, z)` is outside.
    #[must_use]
    pub fn covered_above(&self, (x, z): (u32, u32)) -> Option<bool> {
        if x >= PADDED_CHUNK_SIZE || z >= PADDED_CHUNK_SIZE {
            return None;
        }
        let n = (x + PADDED_CHUNK_SIZE * z) as usize;
        self.covered_above.as_ref().map(|words| words[n / 64] & (1 << (n % 64)) != 0)
    }

    /// For each padded voxel column (`x + 34·z`), the lowest padded layer
    /// `y` from which it is open to the sky: every voxel from `y` up, and
    /// everything above the padded chunk, is air. 34 where the column is
    /// covered at its top. What lights caves and overhangs darker than open
    /// ground.
    #[must_use]
    pub fn sky_floors(&self) -> [u8; PADDED_COLUMNS] {
        let mut rows = [0; PADDED_ROWS];
        self.solid_rows(&mut rows);
        self.sky_floors_from(&rows)
    }

    /// [`ChunkVoxels::sky_floors`] from the chunk's
    /// [`ChunkVoxels::solid_rows`], for a caller that has them: each
    /// column's floor is one over its highest solid voxel (0 where it has
    /// none), found slab by slab from the top row down while a column is
    /// still unfound.
    #[must_use]
    pub fn sky_floors_from(&self, rows: &[u64; PADDED_ROWS]) -> [u8; PADDED_COLUMNS] {
        let size = PADDED_CHUNK_SIZE as usize;
        let every_column = (1u64 << size) - 1;
        let mut floors = [0; PADDED_COLUMNS];
        for (z, slab) in rows.chunks_exact(size).enumerate() {
            let floors = &mut floors[z * size..][..size];
            // A column covered above the chunk is dark to its top; without
            // a record, one whose top voxel is solid (which the scan below
            // gives the top floor too).
            let mut covered = self.covered_in_slab(z);
            let mut unfound = every_column & !covered;
            while covered != 0 {
                floors[covered.trailing_zeros() as usize] = size as u8;
                covered &= covered - 1;
            }
            for (y, &row) in slab.iter().enumerate().rev() {
                if unfound == 0 {
                    break;
                }
                let mut found = row & unfound;
                unfound &= !found;
                while found != 0 {
                    floors[found.trailing_zeros() as usize] = y as u8 + 1;
                    found &= found - 1;
                }
            }
        }
        floors
    }

    /// Per slab `z`, the padded columns (bit `x`) with an air voxel under
    /// the column's sky floor ([`ChunkVoxels::sky_floors`]): a cave's, an
    /// overhang's or a covered column's. In the other columns every air
    /// voxel is open to the sky. From the chunk's
    /// [`ChunkVoxels::solid_rows`].
    #[must_use]
    pub fn dark_air_columns_from(&self, rows: &[u64; PADDED_ROWS]) -> [u64; PADDED_CHUNK_SIZE as usize] {
        let size = PADDED_CHUNK_SIZE as usize;
        let every_column = (1u64 << size) - 1;
        let mut dark = [0; PADDED_CHUNK_SIZE as usize];
        for (z, slab) in rows.chunks_exact(size).enumerate() {
            // Columns with something solid above the row (or covered over
            // the chunk): their air in the row is under the floor.
            let mut above = self.covered_in_slab(z);
            for &row in slab.iter().rev() {
                dark[z] |= !row & above & every_column;
                above |= row;
            }
        }
        dark
    }

    /// The columns of slab `z` (bit `x`) recorded as covered above the
    /// chunk ([`ChunkVoxels::set_covered_above`]; none without a record).
    fn covered_in_slab(&self, z: usize) -> u64 {
        let Some(words) = &self.covered_above else { return 0 };
        // The slab's 34 bits of the record, which may straddle two words.
        let size = PADDED_CHUNK_SIZE as usize;
        let first = size * z;
        let (word, shift) = (first / 64, first % 64);
        let low = words[word] >> shift;
        let high = if shift + size > 64 { words[word + 1] << (64 - shift) } else { 0 };
        (low | high) & ((1 << size) - 1)
    }

    /// Writes, for each padded row (`y + 34·z`), which of its voxels are
    /// solid: bit `x`. Sixteen voxels are compared at a time, so a chunk's
    /// 1,156 rows take about a microsecond: what bitmask meshing and the
    /// sky floors start from.
    pub fn solid_rows(&self, rows: &mut [u64; PADDED_ROWS]) {
        use wide::u8x16;
        let (voxel_rows, _) = self.voxels.as_chunks::<{ PADDED_CHUNK_SIZE as usize }>();
        for (bits, row) in rows.iter_mut().zip(voxel_rows) {
            let air = |at: usize| {
                let lanes = u8x16::new(std::array::from_fn(|i| row[at + i].material()));
                u64::from(lanes.simd_eq(u8x16::ZERO).to_bitmask())
            };
            let solid = !(air(0) | air(16) << 16) & 0xFFFF_FFFF;
            *bits = solid | u64::from(row[32].is_solid()) << 32 | u64::from(row[33].is_solid()) << 33;
        }
    }

    /// All voxels in [`PaddedChunkShape`] order (what block-mesh takes).
    #[must_use]
    pub fn as_slice(&self) -> &[Voxel] {
        &self.voxels
    }

    /// All voxels, mutable, in [`PaddedChunkShape`] order.
    #[must_use]
    pub fn as_mut_slice(&mut self) -> &mut [Voxel] {
        &mut self.voxels
    }

    /// The voxel at padded coordinates `[x, y, z]` (each `0..34`), or `None`
    /// outside the padded chunk.
    #[must_use]
    #[inline]
    pub fn get(&self, padded: [u32; 3]) -> Option<Voxel> {
        padded.iter().all(|&c| c < PADDED_CHUNK_SIZE).then(|| self.voxels[PaddedChunkShape::linearize(padded) as usize])
    }

    /// Sets the voxel at padded coordinates `[x, y, z]` (each `0..34`).
    /// Returns `false`, changing nothing, outside the padded chunk.
    pub fn set(&mut self, padded: [u32; 3], voxel: Voxel) -> bool {
        if padded.iter().all(|&c| c < PADDED_CHUNK_SIZE) {
            self.voxels[PaddedChunkShape::linearize(padded) as usize] = voxel;
            true
        } else {
            false
        }
    }

    /// Solid voxels inside the chunk proper (padding excluded).
    #[must_use]
    pub fn solid_count(&self) -> usize {
        let mut count = 0;
        for z in 1..=CHUNK_SIZE {
            for y in 1..=CHUNK_SIZE {
                let row = PaddedChunkShape::linearize([1, y, z]) as usize;
                count += self.voxels[row..row + CHUNK_SIZE as usize].iter().filter(|v| v.is_solid()).count();
            }
        }
        count
    }

    /// Whether meshing can be skipped: the chunk proper is all air, or all
    /// solid with solid padding on all six sides (no visible face).
    #[must_use]
    pub fn has_no_surface(&self) -> bool {
        let first = self.voxels[PaddedChunkShape::linearize([1, 1, 1]) as usize].is_solid();
        if !first {
            return self.solid_count() == 0;
        }
        // All solid, including every face-adjacent padding voxel (edge and
        // corner padding is never a face neighbour of the chunk proper):
        // row by row as stored (x fastest), a row's run of voxels tested in
        // one pass. A test a voxel of how many of its coordinates lie in
        // the padding was 7 % of the workers' time over a hillside view
        // (most chunks under the ground are all rock).
        let last = PADDED_CHUNK_SIZE - 1;
        (0..PADDED_CHUNK_SIZE).all(|z| {
            (0..PADDED_CHUNK_SIZE).all(|y| {
                let in_padding = u8::from(y == 0 || y == last) + u8::from(z == 0 || z == last);
                // A row in the chunk proper takes its padding at both ends
                // too; a row of the padding, its part beside the chunk; a
                // row of the edge padding, nothing.
                let xs = match in_padding {
                    0 => 0..PADDED_CHUNK_SIZE,
                    1 => 1..last,
                    _ => return true,
                };
                let row = PaddedChunkShape::linearize([0, y, z]) as usize;
                // A fold, not `all`: no branch a voxel, so it runs 16 at a time.
                let run = &self.voxels[row + xs.start as usize..row + xs.end as usize];
                run.iter().fold(true, |solid, voxel| solid & voxel.is_solid())
            })
        })
    }
}
