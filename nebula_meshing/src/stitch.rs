//! Stitched seams: closing the seam between chunks of different LOD with
//! geometry lying in their shared boundary plane instead of skirts (seed
//! `004`'s skirt-free idea, on blocky voxels; the issue of caves: a skirt
//! hung from a cave roof is seen from inside the cave, a face in the
//! boundary plane is not a wall anywhere).
//!
//! ```text
//!   boundary plane P, seen face-on (fine chunk A in front, coarse B behind)
//!
//!     ┌───┬───┐ coarse cells of B (2^d × 2^d fine cells each)
//!     │▓▓▓│   │     ▓ B solid       ░ A solid (fine cells)
//!     │▓░▓│ ░ │     faces in P where A and B differ:
//!     ├───┼───┤       A solid, B air → A's own face looking at B
//!     │▓▓▓│░░░│       B solid, A air → a "mirror" face looking at A
//!     └───┴───┘
//! ```
//!
//! The solid both chunks draw is, per chunk, its own voxels; the surface of
//! their union is each chunk's faces inside it plus, in P, the fine cells
//! where A's voxel and B's coarse voxel across P differ. The finer chunk
//! makes all of those: its padding on P is B's coarse voxels (so its
//! mesher makes the first kind itself), and it adds the second kind. The
//! coarser chunk makes no face in P on that side (its padding there
//! mirrors its own boundary voxels). Every lattice point on P is a vertex
//! on both sides ("dense"), and A's vertices on P are moved onto B's
//! coarse lattice lines (`constrain_edge_vertices`), so every fine vertex
//! on one of B's coarse edges lies on it exactly in f64. The f32 the GPU
//! gets still rounds them a hair off it (a T-junction): each such coarse
//! edge is zipped to the fine vertices on it with a fan of zero-area
//! triangles, both windings, which the rasteriser fills wherever rounding
//! opened a sliver.
//!
//! Closed for every pair of LODs and any voxels, caves included; the
//! meshes of both chunks depend on the LOD relation across the seam, so a
//! renderer re-meshes both when it changes. Geomorphing is left off: A's
//! and B's vertices on P would morph towards different LODs.

use nebula_lod::NeighborLodRelation;
use nebula_math::FaceDirection;
use nebula_voxel::{CHUNK_SIZE, ChunkVoxels, PADDED_CHUNK_SIZE, Voxel, VoxelCoord, VoxelSource};

use crate::MeshError;

/// A side of a chunk stitched to a neighbour of another LOD.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct StitchedSide {
    /// The side (horizontal).
    pub side: FaceDirection,
    /// `Some(d)`: the neighbour is `d` LODs coarser and this chunk makes
    /// the faces in the boundary plane and the zips; `None`: the neighbour
    /// is finer and makes them (this chunk makes none there).
    pub coarser_by: Option<u8>,
}

impl StitchedSide {
    /// Whether this side adds faces (a coarse neighbour's solid voxel
    /// across the plane from this chunk's air), so a chunk whose own voxels
    /// hold no surface is meshed all the same.
    pub fn has_faces(&self, voxels: &ChunkVoxels) -> bool {
        self.coarser_by.is_some()
            && plane_cells().any(|(height, along)| {
                let (pad, inside) = (padded(self.side, true, height, along), padded(self.side, false, height, along));
                solid(voxels, pad) && !solid(voxels, inside)
            })
    }
}

/// The fine cells of a side's plane: `(height, along)` padded coordinates,
/// each in `1..=32` (the chunk's own span, no corner columns).
pub(crate) fn plane_cells() -> impl Iterator<Item = (u32, u32)> {
    (1..=CHUNK_SIZE).flat_map(|height| (1..=CHUNK_SIZE).map(move |along| (height, along)))
}

/// The padded coordinates of the cell at padded `height` and `along` on
/// `side`: in the padding beyond the plane (`beyond`), else the chunk's
/// own boundary layer.
pub(crate) fn padded(side: FaceDirection, beyond: bool, height: u32, along: u32) -> [u32; 3] {
    let last = PADDED_CHUNK_SIZE - 1;
    let plane = match (side.is_positive(), beyond) {
        (true, true) => last,
        (true, false) => last - 1,
        (false, true) => 0,
        (false, false) => 1,
    };
    if side.axis() == 0 { [plane, height, along] } else { [along, height, plane] }
}

pub(crate) fn solid(voxels: &ChunkVoxels, padded: [u32; 3]) -> bool {
    voxels.get(padded).is_some_and(Voxel::is_solid)
}

/// Prepares the padding of `side` for a stitched seam with the neighbour
/// across it (`relation`): a coarser neighbour's voxels, each fine padding
/// cell taking the coarse voxel that holds it, read from `source`; for a
/// finer neighbour a copy of the chunk's own boundary layer (no face in the
/// plane). Rows above and below the chunk are padded alike; the corner
/// columns keep the source's voxels.
///
/// # Errors
/// [`MeshError::LodDiffOutOfRange`] for a coarser neighbour past the
/// planet's coarsest LOD; the source's errors.
pub(crate) fn stitch_padding<S: VoxelSource + ?Sized>(
    source: &S,
    voxels: &mut ChunkVoxels,
    side: FaceDirection,
    relation: NeighborLodRelation,
) -> Result<Option<StitchedSide>, MeshError> {
    let rows = 0..PADDED_CHUNK_SIZE;
    match relation {
        NeighborLodRelation::Same => Ok(None),
        NeighborLodRelation::LowerThanNeighbor => {
            for height in rows {
                for along in 1..=CHUNK_SIZE {
                    let own = voxels.get(padded(side, false, height, along)).unwrap_or(Voxel::AIR);
                    voxels.set(padded(side, true, height, along), own);
                }
            }
            Ok(Some(StitchedSide { side, coarser_by: None }))
        }
        NeighborLodRelation::HigherThanNeighbor { lod_diff } => {
            let key = voxels.key();
            let layout = *source.layout();
            let max = layout.max_lod() - key.lod;
            if lod_diff == 0 || lod_diff > max {
                return Err(MeshError::LodDiffOutOfRange { lod: key.lod, lod_diff, max });
            }
            let per_edge = i64::from(layout.voxels_per_edge(key.lod));
            let size = i64::from(CHUNK_SIZE);
            // The padding's radial voxels, fine, and the coarse ones
            // holding them: one column read per coarse column.
            let first_h = i64::from(key.layer) * size - 1;
            let coarse_h = |h: i64| h.div_euclid(1 << lod_diff);
            let bottom = coarse_h(first_h);
            let mut coarse =
                vec![Voxel::AIR; (coarse_h(first_h + i64::from(PADDED_CHUNK_SIZE) - 1) - bottom + 1) as usize];
            let mut read: Option<(nebula_voxel::CubeFace, i64, i64)> = None;
            for along in 1..=CHUNK_SIZE {
                let at = padded(side, true, 0, along);
                let (ci, cj) =
                    (i64::from(key.x) * size + i64::from(at[0]) - 1, i64::from(key.y) * size + i64::from(at[2]) - 1);
                let Some((face, i, j)) = key.face.wrap_cell(ci, cj, per_edge) else { continue };
                let column = (face, i >> lod_diff, j >> lod_diff);
                if read != Some(column) {
                    let bottom = VoxelCoord {
                        face,
                        lod: key.lod + lod_diff,
                        i: column.1 as u32,
                        j: column.2 as u32,
                        h: bottom as i32,
                    };
                    source.column_voxels(bottom, &mut coarse)?;
                    read = Some(column);
                }
                for height in rows.clone() {
                    let voxel = coarse[(coarse_h(first_h + i64::from(height)) - bottom) as usize];
                    voxels.set(padded(side, true, height, along), voxel);
                }
            }
            Ok(Some(StitchedSide { side, coarser_by: Some(lod_diff) }))
        }
    }
}
