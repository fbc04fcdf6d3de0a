//! How a chunk's LOD relates to its neighbours' (seam spec `003`).

use nebula_math::FaceDirection;

/// Describes the LOD relationship between a chunk and its neighbour on one
/// edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NeighborLodRelation {
    /// Same LOD level: no constraining needed.
    Same,
    /// This chunk has higher resolution than the neighbour. The edge
    /// vertices of this chunk must be constrained to the neighbour's edge.
    HigherThanNeighbor {
        /// The LOD difference (always positive). Typically 1.
        lod_diff: u8,
    },
    /// This chunk has lower resolution than the neighbour. The neighbour
    /// constrains its vertices; this chunk only hangs a skirt.
    LowerThanNeighbor,
}

/// The LOD context for meshing a chunk: its LOD and the relation to the
/// neighbour on each side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ChunkLodContext {
    /// LOD level of this chunk.
    pub lod: u8,
    /// Relation to the neighbour on each side, indexed by [`FaceDirection`]
    /// (+X, −X, +Z, −Z, then the radial +Y, −Y, which are always
    /// [`NeighborLodRelation::Same`] on a Nebula planet).
    pub neighbors: [NeighborLodRelation; 6],
}

impl ChunkLodContext {
    /// A chunk at `lod` whose neighbours all share its LOD.
    #[must_use]
    pub fn uniform(lod: u8) -> Self {
        Self { lod, neighbors: [NeighborLodRelation::Same; 6] }
    }

    /// The relation on side `side`.
    #[must_use]
    pub fn relation(&self, side: FaceDirection) -> NeighborLodRelation {
        self.neighbors[side as usize]
    }

    /// Sets the relation on side `side`.
    pub fn set(&mut self, side: FaceDirection, relation: NeighborLodRelation) {
        self.neighbors[side as usize] = relation;
    }

    /// The LOD difference to a coarser neighbour on `side`, if it is coarser.
    #[must_use]
    pub fn coarser_neighbor_diff(&self, side: FaceDirection) -> Option<u8> {
        match self.relation(side) {
            NeighborLodRelation::HigherThanNeighbor { lod_diff } => Some(lod_diff),
            _ => None,
        }
    }

    /// Whether `side` meets a neighbour of another LOD (and so gets a skirt).
    #[must_use]
    pub fn needs_skirt(&self, side: FaceDirection) -> bool {
        self.relation(side) != NeighborLodRelation::Same
    }
}
