//! Where voxels come from.

use std::ops::RangeInclusive;

use crate::{CHUNK_SIZE, ChunkColumn, ChunkKey, ChunkLayout, ChunkVoxels, DVec3, Voxel, VoxelCoord, VoxelError};

/// Conservative bounds of the voxel surface over a chunk column.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceBounds {
    /// Lowest LOD-0 radial layer that may hold a solid voxel with air
    /// above or beside it, at the column's LOD.
    pub min_layer: i64,
    /// Highest such layer.
    pub max_layer: i64,
    /// Radius of the bottom of `min_layer`, metres.
    pub min_radius: f64,
    /// Radius of the top of `max_layer`, metres.
    pub max_radius: f64,
    /// Whether every solid voxel of the column, and of every finer column
    /// under it, is [`Voxel::SEABED`]: the whole column lies under the
    /// sea, so a renderer that covers the sea bed with water covers all of
    /// it. `false` where the source cannot tell.
    pub sea_bed_only: bool,
}

/// What of a source's surface an eye can see ([`VoxelSource::layer_view`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerView {
    /// Everything that holds surface.
    All,
    /// An eye over the ground or in a cave open to it: not the surface of
    /// caves sealed off from both.
    FromAbove,
    /// An eye down in sealed caves: only their surface (rock seals them
    /// from the ground and every other cave).
    FromSealedCaves,
}

impl LayerView {
    /// Every view, in the order of [`LayerView::index`].
    pub const ALL: [LayerView; 3] = [LayerView::All, LayerView::FromAbove, LayerView::FromSealedCaves];

    /// This view's place in [`LayerView::ALL`].
    #[must_use]
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// A column's surface bounds and the radial chunk layers an eye with each
/// [`LayerView`] sees of it ([`VoxelSource::surface_survey`]): what the LOD
/// tree keeps of every node, asked once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSurvey {
    /// [`VoxelSource::surface_bounds`].
    pub bounds: SurfaceBounds,
    /// First and last layer seen, by [`LayerView::index`].
    seen: [(i32, i32); 3],
}

impl SurfaceSurvey {
    /// A survey whose layers seen from each view are `seen(view)`.
    pub fn new(bounds: SurfaceBounds, mut seen: impl FnMut(LayerView) -> RangeInclusive<i32>) -> Self {
        Self { bounds, seen: LayerView::ALL.map(|view| seen(view).into_inner()) }
    }

    /// The radial chunk layers an eye with `view` sees
    /// ([`VoxelSource::surface_chunk_layers_seen`]).
    #[must_use]
    pub fn layers(&self, view: LayerView) -> RangeInclusive<i32> {
        let (first, last) = self.seen[view.index()];
        first..=last
    }
}

impl SurfaceBounds {
    /// The radial chunk layers of a column at `lod` these bounds reach.
    #[must_use]
    pub fn chunk_layers(&self, layout: &ChunkLayout, lod: u8) -> RangeInclusive<i32> {
        let chunk_layers = i64::from(CHUNK_SIZE) * layout.voxel_span(lod);
        let low = self.min_layer.div_euclid(chunk_layers);
        let high = self.max_layer.div_euclid(chunk_layers);
        clamp_i32(low)..=clamp_i32(high)
    }
}

/// A planet's voxels at any LOD, for any chunk: what a game implements to
/// bring its own world (the procedural planet is one; `nebula_tests`'
/// floating islands another).
///
/// What an implementation promises, and what breaks if it does not:
///
/// - **Determinism**: the same key always gives the same voxels, and
///   [`VoxelSource::voxel`] agrees with [`VoxelSource::fill_chunk`], so two
///   chunks that read each other's border as padding agree (else: cracks
///   between same-LOD chunks).
/// - **One voxel per coordinate at every LOD**, whatever rule makes coarse
///   voxels from fine ones (the procedural planet samples the far-corner
///   LOD-0 voxel; its caves keep a tunnel's core only).
/// - **Surface** means any solid voxel with air above or beside it: the
///   ground, and the walls, floors and ceilings of caves, overhangs and
///   floating rock alike. [`VoxelSource::surface_bounds`] must hold all of
///   it, at the column's LOD and every finer LOD under it (else: chunks
///   never meshed, holes).
/// - **δ(L)** ([`VoxelSource::geometric_error`]) bounds how far, radially,
///   LOD `L`'s surface can lie from LOD 0's across a seam between chunks of
///   different LODs: the skirts hang that deep. With caves that is as deep
///   as the deepest cave (a coarse chunk solid across a seam from a finer
///   chunk's tunnel leaves the tunnel's cross-section to cover).
/// - **Sky** (optional): a source that knows what lies above a chunk
///   records it in [`ChunkVoxels::set_covered_above`] when it fills one, so
///   that caves are dark although the chunk holds no roof of its own.
pub trait VoxelSource: Send + Sync {
    /// The planet's chunk layout.
    fn layout(&self) -> &ChunkLayout;

    /// One voxel at any LOD.
    ///
    /// # Errors
    /// [`VoxelError`] for coordinates off the planet.
    fn voxel(&self, at: VoxelCoord) -> Result<Voxel, VoxelError>;

    /// The voxels of one column, `out.len()` of them upwards from `bottom`
    /// (`bottom.h` is the first; its face, LOD, `i` and `j` name the
    /// column): what a stitched seam reads of a coarser neighbour. The
    /// default asks [`VoxelSource::voxel`] for each; a source with work per
    /// column (noise) does it once.
    ///
    /// # Errors
    /// [`VoxelError`] for coordinates off the planet.
    fn column_voxels(&self, bottom: VoxelCoord, out: &mut [Voxel]) -> Result<(), VoxelError> {
        for (h, voxel) in (bottom.h..).zip(out.iter_mut()) {
            *voxel = self.voxel(VoxelCoord { h, ..bottom })?;
        }
        Ok(())
    }

    /// Fills `out` with chunk `key` and its one-voxel padding (read across
    /// chunk and cube-face edges), and sets `out`'s key.
    ///
    /// # Errors
    /// [`VoxelError`] for a key that is not a chunk of this planet.
    fn fill_chunk(&self, key: ChunkKey, out: &mut ChunkVoxels) -> Result<(), VoxelError>;

    /// Conservative surface bounds over `column` at its LOD.
    ///
    /// # Errors
    /// [`VoxelError`] for a column that is not on this planet.
    fn surface_bounds(&self, column: ChunkColumn) -> Result<SurfaceBounds, VoxelError>;

    /// A radius, metres, that no surface of `column` rises above, at its
    /// LOD or any finer one: [`VoxelSource::surface_bounds`]' top, or a
    /// tighter one where finding it costs more than the bounds the LOD tree
    /// asks of every node (the procedural planet samples a 9 × 9 grid of
    /// heights). What an occlusion test reads of a far column it might hide.
    ///
    /// # Errors
    /// As [`VoxelSource::surface_bounds`].
    fn surface_top_radius(&self, column: ChunkColumn) -> Result<f64, VoxelError> {
        Ok(self.surface_bounds(column)?.max_radius)
    }

    /// δ(L): a bound, in metres, on how far the voxel surface at `lod` lies
    /// from the LOD-0 voxel surface, measured radially. 0 at LOD 0.
    fn geometric_error(&self, lod: u8) -> f64;

    /// A lower bound on the radius of the LOD-0 surface anywhere on the
    /// planet (its deepest valley, edits included), metres, or `None` where
    /// the source cannot tell. Renderers use it for the horizon that hides
    /// the far side of the planet.
    fn lowest_surface_radius(&self) -> Option<f64> {
        None
    }

    /// Whether every solid voxel of `column` is [`Voxel::SEABED`] and its
    /// whole surface lies below `radius` (metres), at every LOD under the
    /// column: a renderer whose sea hides the sea bed under a given depth
    /// of water need not refine, mesh or draw such a column in detail.
    /// Conservative: `false` where the source cannot tell. By default, from
    /// [`VoxelSource::surface_bounds`], whose radii and `sea_bed_only` must
    /// then hold for the finer columns too (the procedural planet's bound
    /// H over the whole patch).
    ///
    /// # Errors
    /// As [`VoxelSource::surface_bounds`].
    fn sea_bed_below(&self, column: ChunkColumn, radius: f64) -> Result<bool, VoxelError> {
        let bounds = self.surface_bounds(column)?;
        Ok(bounds.sea_bed_only && bounds.max_radius <= radius)
    }

    /// The radial chunk layers of `column` that can contain surface.
    ///
    /// # Errors
    /// As [`VoxelSource::surface_bounds`].
    fn surface_chunk_layers(&self, column: ChunkColumn) -> Result<RangeInclusive<i32>, VoxelError> {
        Ok(self.surface_bounds(column)?.chunk_layers(self.layout(), column.lod))
    }

    /// What an eye at `eye` can see of the surface
    /// ([`VoxelSource::surface_chunk_layers_seen`]). By default
    /// [`LayerView::All`]: every layer that holds surface is meshed and
    /// drawn. A source with caves sealed off from the open air (the
    /// procedural planet's deep network) says [`LayerView::FromAbove`] over
    /// the ground and [`LayerView::FromSealedCaves`] down in them, so that
    /// a streamer pays only for what the eye can see.
    fn layer_view(&self, eye: DVec3) -> LayerView {
        let _ = eye;
        LayerView::All
    }

    /// The radial chunk layers of `column` whose surface an eye with
    /// `view` can see: by default all of
    /// [`VoxelSource::surface_chunk_layers`]. A source that leaves layers
    /// out promises that no ray from such an eye reaches their surface
    /// without passing through rock first, and says the same in
    /// [`VoxelSource::surface_survey`] (what the streamer reads).
    ///
    /// # Errors
    /// As [`VoxelSource::surface_bounds`].
    fn surface_chunk_layers_seen(
        &self,
        column: ChunkColumn,
        view: LayerView,
    ) -> Result<RangeInclusive<i32>, VoxelError> {
        let _ = view;
        self.surface_chunk_layers(column)
    }

    /// [`VoxelSource::surface_bounds`] and the layers each view sees
    /// ([`VoxelSource::surface_chunk_layers_seen`]) at once: what the LOD
    /// tree asks of every node it makes, so that the streamer finds a
    /// column's layers there instead of asking the source on the frame
    /// thread. By default every view sees every layer of the bounds (one
    /// call to `surface_bounds`): a source that leaves layers out of a view
    /// overrides this too (the procedural planet answers every view from
    /// one evaluation); one that does not has every layer drawn, which is
    /// never wrong, only more to mesh.
    ///
    /// # Errors
    /// As [`VoxelSource::surface_bounds`].
    fn surface_survey(&self, column: ChunkColumn) -> Result<SurfaceSurvey, VoxelError> {
        let bounds = self.surface_bounds(column)?;
        let all = bounds.chunk_layers(self.layout(), column.lod);
        Ok(SurfaceSurvey::new(bounds, |_| all.clone()))
    }
}

fn clamp_i32(value: i64) -> i32 {
    value.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}
