//! How a [`Streamer`](crate::stream::Streamer) closes the seams between chunks of
//! different LOD: the seed documents' strategies, one switch.
//!
//! ```text
//!   Skirts       meshes know nothing of their neighbours; every side has a
//!                skirt, lowered at draw time where the LODs drawn differ;
//!                geomorphing on (MeshOptions::STREAMING)
//!   Constrained  the seam spec's pipeline: a mesh is made for the LODs
//!                around it, its edges towards a coarser neighbour
//!                constrained onto that neighbour's lattice; skirts where
//!                the LODs drawn differ
//!   Stitched     a mesh is made for the LODs around it and its seams are
//!                closed in the boundary planes (nebula_meshing::stitch);
//!                no skirt, no geomorphing
//! ```
//!
//! With the last two a chunk's mesh depends on its neighbours' LODs, which
//! change as the camera moves (seed 000's dependency problem). The streamer
//! never waits for it: each mesh remembers the LOD relation it was made
//! for ([`SideRelations`]); a drawn column whose meshes were made for other
//! relations than those drawn around it is *unsettled*, and is meshed
//! again for the drawn ones. Meanwhile every seam with an unsettled column
//! on either side lowers its skirts on both sides (every streamed mesh
//! carries draw-time skirts of depth 0), as deep as the LODs drawn and
//! meshed for there need: the fallback is today's skirt seam, so no frame
//! shows a crack while a seam waits.

use nebula_lod::NeighborLodRelation;
use nebula_math::FaceDirection;
use nebula_meshing::{ChunkLodContext, MeshOptions};

/// The seam strategy of a streamer (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SeamStrategy {
    /// Draw-time skirts with geomorphing; meshes independent of their
    /// neighbours.
    #[default]
    Skirts,
    /// Meshes made for their neighbours' LODs with constrained edges;
    /// skirts where LODs differ.
    Constrained,
    /// Meshes made for their neighbours' LODs, seams stitched in the
    /// boundary planes; no geomorphing, and no skirt once settled.
    Stitched,
}

impl SeamStrategy {
    /// Every strategy, in the order of the module docs.
    pub const ALL: [Self; 3] = [Self::Skirts, Self::Constrained, Self::Stitched];

    /// Its name on the command line and in reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Skirts => "skirts",
            Self::Constrained => "constrained",
            Self::Stitched => "stitched",
        }
    }

    /// Whether a mesh depends on the LODs next to it.
    #[must_use]
    pub fn meshes_for_neighbours(self) -> bool {
        self != Self::Skirts
    }

    /// Whether chunks are drawn geomorphing: not where seams are stitched
    /// (a seam's two sides would morph towards different LODs).
    #[must_use]
    pub fn morphs(self) -> bool {
        self != Self::Stitched
    }

    /// How a streamed chunk is meshed: always with draw-time skirts (of
    /// depth 0 unless lowered: the fallback of an unsettled seam).
    #[must_use]
    pub fn mesh_options(self) -> MeshOptions {
        match self {
            Self::Skirts => MeshOptions::STREAMING,
            Self::Constrained => MeshOptions { constrain_edges: true, ..MeshOptions::STREAMING },
            Self::Stitched => MeshOptions { constrain_edges: true, stitch: true, ..MeshOptions::STREAMING },
        }
    }
}

impl std::fmt::Display for SeamStrategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SeamStrategy {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|strategy| strategy.name() == text)
            .ok_or_else(|| format!("unknown seam strategy {text:?} (skirts, constrained or stitched)"))
    }
}

/// The LOD relation across each horizontal side of a chunk (as in
/// [`FaceDirection::HORIZONTAL`]): what a mesh was made for, or what is
/// drawn around it.
pub type SideRelations = [NeighborLodRelation; 4];

/// The same LOD all round: what a mesh independent of its neighbours is
/// made for.
pub const SAME_ALL_ROUND: SideRelations = [NeighborLodRelation::Same; 4];

/// The meshing context of a chunk at `lod` made for `relations`.
#[must_use]
pub fn mesh_context(lod: u8, relations: &SideRelations) -> ChunkLodContext {
    let mut context = ChunkLodContext::uniform(lod);
    for (side, &relation) in FaceDirection::HORIZONTAL.into_iter().zip(relations) {
        context.set(side, relation);
    }
    context
}

/// The side relations of a LOD tree's context.
#[must_use]
pub fn side_relations(context: &ChunkLodContext) -> SideRelations {
    FaceDirection::HORIZONTAL.map(|side| context.relation(side))
}

/// The coarsest LOD a mesh of a chunk at `lod` made for `relations` was
/// made against (its own where every side is the same or finer).
#[must_use]
pub fn coarsest_made_for(lod: u8, relations: &SideRelations) -> u8 {
    relations
        .iter()
        .map(|relation| match relation {
            NeighborLodRelation::HigherThanNeighbor { lod_diff } => lod.saturating_add(*lod_diff),
            _ => lod,
        })
        .max()
        .unwrap_or(lod)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strategies_parse_from_their_names_and_nothing_else() {
        for strategy in SeamStrategy::ALL {
            assert_eq!(strategy.name().parse::<SeamStrategy>(), Ok(strategy));
        }
        assert!("skirt".parse::<SeamStrategy>().is_err());
        assert!("".parse::<SeamStrategy>().is_err());
    }

    #[test]
    fn a_mesh_for_the_same_lod_all_round_is_the_same_in_every_strategy() {
        // The face roots and every mesh made before a switch rely on it.
        for strategy in SeamStrategy::ALL {
            let options = strategy.mesh_options();
            assert!(options.draw_time_skirts, "{strategy}: the fallback skirts");
            let context = mesh_context(3, &SAME_ALL_ROUND);
            assert_eq!(context, ChunkLodContext::uniform(3));
        }
        assert_eq!(SeamStrategy::Skirts.mesh_options(), MeshOptions::STREAMING);
    }

    #[test]
    fn the_coarsest_lod_made_for_is_the_coarsest_neighbour() {
        let mut relations = SAME_ALL_ROUND;
        assert_eq!(coarsest_made_for(2, &relations), 2);
        relations[1] = NeighborLodRelation::HigherThanNeighbor { lod_diff: 3 };
        relations[2] = NeighborLodRelation::HigherThanNeighbor { lod_diff: 1 };
        relations[3] = NeighborLodRelation::LowerThanNeighbor;
        assert_eq!(coarsest_made_for(2, &relations), 5);
        assert_eq!(side_relations(&mesh_context(2, &relations)), relations);
    }
}
