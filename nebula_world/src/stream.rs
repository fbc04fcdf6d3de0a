//! Streaming: what to mesh, in what order, what to draw while it is not
//! ready, and what to free — for any renderer.
//!
//! A game drives a [`Streamer`] once a frame with its camera and a function
//! that uploads a finished mesh and returns the renderer's handle to it
//! (a [`MeshHandle`]: dropping it frees the mesh). The streamer hands back
//! what to draw ([`Streamer::drawn`]): each chunk's handle with its
//! per-frame draw constants ([`ChunkDraw`]: the error it morphs towards,
//! how deep to lower each side's skirt, and which sides' walls all look
//! away from the eye and are left out).
//!
//! # What is drawn: every frame complete, never waiting for meshing
//!
//! By default ([`SeamStrategy::Skirts`]) meshes are made with
//! [`MeshOptions::STREAMING`]: they do not depend on their neighbours' LODs
//! (skirts hang on every side, and their depth is chosen per side at draw
//! time from the LODs actually drawn next to the chunk). So any chunk may be
//! shown the moment its column is meshed, and a LOD change never waits for
//! neighbours to be re-meshed. The other strategies make meshes for the
//! LODs around them and still never wait: see [`crate::seams`]. Each frame:
//!
//! ```text
//!   for each visible leaf L of the LOD tree:
//!     L behind the terrain's horizon → nothing drawn for it (the sphere
//!                                    under the ground near the eye,
//!                                    LodTree::horizon_occluder, or the
//!                                    ground in front bearing by bearing,
//!                                    TerrainHorizon); its coarsest hidden
//!                                    ancestor is meshed, and drawn while
//!                                    a stand-in covers ground that
//!                                    horizon was made of
//!     L under an opaque sea          → L := its coarsest ancestor under it
//!                                    with sea bed on every side (OpaqueSea)
//!     L's column meshed            → draw L
//!     else its 4 children meshed   → draw them (a merge not ready yet)
//!     else nearest meshed ancestor → draw it instead (a split not ready yet);
//!                                    leaves under a drawn ancestor are not drawn
//!   skirt depth per side = skirt_depth(L, LOD drawn across that side)
//!   walls looking towards +i (−i, +j, −j) left out when the eye is behind
//!     both outermost lattice planes of L on that axis
//! ```
//!
//! The six face roots are meshed before the first frame, so an ancestor
//! always exists and no frame has a hole. Stand-ins are asked for every
//! [`STAND_IN_LEVEL_STEP`] LODs above a leaf. Jobs go to a priority queue
//! (largest projected voxel first, which is coarse-first and nearest-first),
//! rebuilt every frame from what is wanted, so a chunk that left the view is
//! never meshed (cancellation); workers on the streamer's own thread pool
//! take the top job. Meshes are held within a chunk and a byte budget,
//! least recently used freed first. Edits ([`Streamer::set_voxels`]) keep
//! the old mesh of a chunk on screen until its new one is uploaded, and a
//! column on screen that an edit gave a new layer stays drawn with its
//! other layers until that one is.
//!
//! A column's layers are those that hold surface the eye can see
//! ([`VoxelSource::layer_view`]): caves sealed off from the open air are
//! meshed only while the eye is down in them, and then the ground over them
//! is not. When the eye crosses into or out of them, every held column's
//! layers are read again: gained layers are awaited as an edit's are.
//!
//! # Out of view: what a turn of the camera will need
//!
//! The LOD tree holds the whole planet by distance, not only the frustum.
//! Once the view's jobs are done, the streamer meshes every leaf of the
//! tree out of view (as it would be drawn: hidden ones as their hidden
//! ancestor) and each one's stand-in [`STAND_IN_LEVEL_STEP`] LODs up,
//! largest projected voxel first, while the cache is under three quarters
//! of its budget ([`MeshCache::prefetch`]), and keeps them: they are freed
//! last, and never for being out of view a while. Standing still and then
//! turning finds the new view meshed; without it, the meshes of what was
//! out of view aged out and the turn drew whole cube faces through their
//! roots (an Earth view 1 km up: 5,498 triangles for 868,554, a stand-in
//! 17 LODs above its leaves).

use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::Instant;

// Fx hashing for the maps keyed by chunk: SipHash was a fifth of the main
// thread's time in a streaming view (keys are not attacker controlled).
use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use nebula_lod::{Camera, CullMargin, LodError, LodSettings, LodTree, NodeBounds, cull_reaches, parent};
use nebula_math::{FaceDirection, FaceEdge};
use nebula_meshing::{
    ChunkDraw, ChunkLodContext, ChunkMeshBuffer, FrameDraw, MeshError, MeshOptions, RenderMesh, mesh_chunk, skirt_depth,
};
use nebula_voxel::{ChunkColumn, ChunkKey, CubeFace, LayerView, VoxelSource};

use crate::lod_thread::{LodThread, MadeTree, Outcome, SelectRequest};
use crate::panic_text;
use crate::seams::{SAME_ALL_ROUND, SeamStrategy, SideRelations, coarsest_made_for, mesh_context};
use crate::select::{
    PLANNED_VIEW_ANGLE_DEGREES, Plan, SelectInput, SelectSettings, Selection, group_unplug_due, job_priority,
    keep_most_urgent, least_recently_used, plugs_far,
};

/// A renderer's handle to an uploaded chunk mesh. Dropping it frees the
/// mesh (the streamer drops the handles of the meshes it frees).
pub trait MeshHandle: Send + Sync + 'static {
    /// Bytes the mesh takes in the renderer (for the memory budget).
    fn bytes(&self) -> u64;
}

/// Meshes uploaded per frame at most: a long frame (or a burst of finished
/// jobs) must not turn into one huge upload. Also the most results that
/// wait for collection: workers block past it, so finished meshes cannot
/// pile up in memory when frames are slow.
pub const MAX_UPLOADS_PER_FRAME: usize = 512;

/// Stand-ins for a leaf not meshed yet are meshed at every this many LODs
/// above it (nearer ones are drawn if they happen to be meshed).
///
/// Every level costs about a third of the leaves' meshing again (the Earth
/// view 1 km up: 10,194 chunks meshed for 7,296 drawn, settled in 10.0 s);
/// every third level costs about 1/64 (7,563 meshed, 7.4 s). A one-pixel
/// crack once seen with 3 (lavapipe only, never on an NVIDIA H100) is gone
/// since the canonical boundary vertex set: the render suite's flights
/// passed 7 runs of 7 on lavapipe, 2 of them pinned to one core.
pub const STAND_IN_LEVEL_STEP: u8 = 3;

/// What drives the geomorph factor μ of a chunk.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MorphRule {
    /// The projected error of the LOD the chunk merges into (its parent's
    /// voxel edge): LOD 0 near the camera is drawn exactly.
    #[default]
    Parent,
    /// The chunk's own error bound, as the first version did (0 at LOD 0,
    /// so LOD 0 is always drawn fully morphed): kept to show what the
    /// morph checks catch.
    Own,
    /// No geomorphing: every chunk drawn as meshed.
    Off,
}

/// Switches for what is drawn: for debugging and for showing that the
/// crack and morph checks catch real defects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DrawOptions {
    /// Lower skirts where a chunk meets another LOD (off: every skirt has
    /// depth 0, seams between LODs open).
    pub skirts: bool,
    /// What drives μ.
    pub morph: MorphRule,
    /// Leave out a chunk's side walls when they all look away from the eye
    /// by enough to be at least [`SLIVER_PX`] wide on screen
    /// (`ChunkDraw::hidden_sides`): back faces, never seen, about a tenth
    /// of the triangles. Off: every side drawn (the rasteriser culls the
    /// back faces).
    pub cull_back_sides: bool,
    /// Leave out the leaves that the ground in front hides, bearing by
    /// bearing ([`TerrainHorizon`](nebula_lod::TerrainHorizon)): their
    /// coarsest hidden ancestor is drawn only as a backstop
    /// ([`DrawList::backstops`]); off: only those behind the horizon
    /// sphere are
    /// ([`LodTree::horizon_occluder`](nebula_lod::LodTree::horizon_occluder)).
    pub terrain_occlusion: bool,
}

impl Default for DrawOptions {
    fn default() -> Self {
        Self { skirts: true, morph: MorphRule::Parent, cull_back_sides: true, terrain_occlusion: true }
    }
}

/// One chunk's mesh as the renderer holds it.
pub struct LoadedChunk<H> {
    /// The renderer's handle.
    pub handle: H,
    /// Surface triangles of each part (as in
    /// `nebula_meshing::ChunkMesh::surface_parts`).
    pub surface_triangles: [u32; nebula_meshing::SURFACE_PARTS],
    /// Skirt triangles per side (as in `FaceDirection::HORIZONTAL`).
    pub skirt_triangles: [u32; 4],
    /// The mesh on the CPU, when the streamer keeps them
    /// ([`Streamer::keep_cpu_meshes`], for checks that ray-cast what is
    /// drawn). Boxed, and the counts above are `u32`s: a cache holds tens
    /// of thousands of these, and in a game none has a CPU copy (8 bytes
    /// instead of a `RenderMesh`'s 232).
    pub cpu: Option<Box<RenderMesh>>,
    /// The LOD relations across its sides it was made for
    /// ([`SeamStrategy`]; the same all round for skirts).
    pub made_for: SideRelations,
    /// No point of its surface is drawn nearer the planet's centre
    /// ([`RenderMesh::lowest_radius`]).
    pub lowest_radius: f64,
    /// Some of its dark cave air was meshed as rock
    /// ([`RenderMesh::dark_air_plugged`]).
    pub dark_air_plugged: bool,
    /// Meshed plugged inside ([`RenderMesh::plugged_inside`]).
    pub plugged_inside: bool,
    /// A stub of it is seen through its own air
    /// ([`RenderMesh::stubs_exposed`]).
    pub stubs_exposed: bool,
    /// A pocket that is no stub reaches the chunk above or below
    /// ([`RenderMesh::pockets_beyond`]).
    pub pockets_beyond: [bool; 2],
}

impl<H: MeshHandle> LoadedChunk<H> {
    /// `mesh` of chunk `key` uploaded with `upload`, keeping the CPU copy
    /// if `keep_cpu`.
    fn uploaded(
        key: ChunkKey,
        mesh: RenderMesh,
        upload: impl FnOnce(ChunkKey, &RenderMesh) -> H,
        keep_cpu: bool,
    ) -> Self {
        let handle = upload(key, &mesh);
        let (surface, skirts) = mesh.triangle_counts();
        // A chunk mesh holds at most a few hundred thousand triangles.
        let count = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
        Self {
            handle,
            surface_triangles: surface.map(count),
            skirt_triangles: skirts.map(count),
            lowest_radius: mesh.lowest_radius,
            dark_air_plugged: mesh.dark_air_plugged,
            plugged_inside: mesh.plugged_inside,
            stubs_exposed: mesh.stubs_exposed,
            pockets_beyond: mesh.pockets_beyond,
            cpu: keep_cpu.then(|| Box::new(mesh)),
            made_for: SAME_ALL_ROUND,
        }
    }

    fn held(&self) -> Held {
        let renderer_bytes = self.handle.bytes();
        Held { chunks: 1, bytes: renderer_bytes + self.cpu.as_deref().map_or(0, RenderMesh::bytes), renderer_bytes }
    }
}

/// Which plug choice a mesh holds its plug group to: `Some(true)` for one
/// plugged inside that filled dark air
/// ([`MeshOptions::plug_dark_air_inside`]: it plugs the layers it shares
/// with the chunks above and below and those of its group beside it,
/// which must then be plugged so too),
/// `Some(false)` for one not plugged inside (those layers as the source
/// has them), `None` for one plugged inside that filled nothing (the same
/// mesh either way). A plug group ([`nebula_meshing::plug_group`]: the
/// chunks plugged inside plug the layers they share with each other) is
/// never drawn with both: a tunnel crossing from one chunk into the other
/// would show no wall at their boundary.
pub(crate) fn plug_choice<H>(chunk: &LoadedChunk<H>) -> Option<bool> {
    match (chunk.plugged_inside, chunk.dark_air_plugged) {
        (true, true) => Some(true),
        (true, false) => None,
        (false, _) => Some(false),
    }
}

/// The plug choice the meshes held for `column`'s plug group
/// ([`nebula_meshing::plug_group`]) were made with ([`plug_choice`]):
/// `Some(false)` where one was not plugged inside, else `Some(true)` where
/// one was, `None` where none says.
pub(crate) fn group_plug_choice<H: MeshHandle>(columns: &ColumnStore<H>, column: ChunkColumn) -> Option<bool> {
    match group_choices(columns, column, None, false) {
        (_, true) => Some(false),
        (true, false) => Some(true),
        (false, false) => None,
    }
}

/// What a column or the whole cache holds, kept up to date as chunks come
/// and go: counting it over the cache each frame cost milliseconds once
/// prefetching filled the cache with tens of thousands of chunks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Held {
    chunks: usize,
    /// Renderer and CPU copies.
    bytes: u64,
    renderer_bytes: u64,
}

impl Held {
    fn add(&mut self, other: Held) {
        self.chunks += other.chunks;
        self.bytes += other.bytes;
        self.renderer_bytes += other.renderer_bytes;
    }

    fn sub(&mut self, other: Held) {
        self.chunks -= other.chunks;
        self.bytes -= other.bytes;
        self.renderer_bytes -= other.renderer_bytes;
    }
}

/// The radial layers of `column` to mesh and draw: those an eye with
/// `view` can see ([`VoxelSource::surface_chunk_layers_seen`]), from the
/// tree's node when the tree holds one (asked of the source when the node
/// was made, on the LOD thread: no noise on the frame thread), else from
/// the source.
pub(crate) fn column_layers<S: VoxelSource + ?Sized>(
    voxels: &S,
    tree: &LodTree,
    column: ChunkColumn,
    view: LayerView,
) -> Vec<i32> {
    // A failed bounds query: no layers.
    tree.node_layers_seen(column, view)
        .or_else(|| voxels.surface_chunk_layers_seen(column, view).ok())
        .map_or_else(Vec::new, Iterator::collect)
}

/// The meshes of one chunk column (all its radial layers).
pub(crate) struct CachedColumn<H> {
    pub(crate) column: ChunkColumn,
    /// The radial layers that hold surface (a failed bounds query: none).
    pub(crate) layers: Vec<i32>,
    /// Its meshes: changed only through the cache ([`MeshCache::insert`],
    /// [`MeshCache::remove`], ...), which keeps `held` and the cache's
    /// total with them.
    pub(crate) chunks: LayerMeshes<H>,
    /// Layers without a mesh, kept with `layers` and `chunks` (the
    /// readiness check of every drawn column, every frame, reads this
    /// alone).
    missing: usize,
    held: Held,
    /// Frame it was last drawn or wanted in.
    pub(crate) last_used: u64,
    /// Its wall planes and neighbours ([`ColumnSides`]).
    pub(crate) sides: ColumnSides,
    /// Meshes made with the other plug choice than meshes held for its
    /// plug group ([`plug_choice`], [`nebula_meshing::plug_group`]), by
    /// layer, with the voxels' generation they were made from: held back
    /// until the group holds one choice with them, then drawn all at once
    /// ([`MeshCache::insert`], [`release_pending`]). Counted in `held`.
    pub(crate) pending: Vec<(i32, u64, LoadedChunk<H>)>,
}

impl<H: MeshHandle> CachedColumn<H> {
    /// A column with no meshes yet, its layers [`column_layers`].
    pub(crate) fn new<S: VoxelSource + ?Sized>(
        voxels: &S,
        tree: &LodTree,
        column: ChunkColumn,
        frame: u64,
        view: LayerView,
    ) -> Self {
        let layers = column_layers(voxels, tree, column, view);
        Self {
            column,
            missing: layers.len(),
            layers,
            chunks: LayerMeshes::default(),
            held: Held::default(),
            last_used: frame,
            sides: ColumnSides::of(voxels.layout(), column, tree.node_bounds(column)),
            pending: Vec::new(),
        }
    }

    /// Whether a mesh of `layer` waits in `pending`.
    pub(crate) fn pends(&self, layer: i32) -> bool {
        self.pending.iter().any(|(l, _, _)| *l == layer)
    }

    /// The radius of the top of its highest layer held: every face of the
    /// column's meshes (morphed too: a vertex morphs towards a lattice
    /// point of its own chunk) lies under it. `None` without meshes.
    fn top_radius(&self, layout: &nebula_voxel::ChunkLayout) -> Option<f64> {
        let top = self.chunks.top()?;
        let layers = (i64::from(top) + 1) * i64::from(nebula_voxel::CHUNK_SIZE) * layout.voxel_span(self.column.lod);
        Some(layout.sphere().layer_radius(layers as f64))
    }

    /// A radius under which none of its meshes draws a point: under it,
    /// within the column's patch, is rock as drawn (nothing drawn there,
    /// and the ground's inside below). `None` without meshes.
    pub(crate) fn drawn_floor(&self) -> Option<f64> {
        self.chunks.iter().map(|(_, chunk)| chunk.lowest_radius).reduce(f64::min)
    }

    /// Every layer meshed, or awaited after an edit that added it to a
    /// column on screen (`stale`): the column's other meshes stand for it
    /// until it comes, as an edited chunk's old mesh does.
    pub(crate) fn ready(&self, column: ChunkColumn, stale: &HashMap<ChunkKey, u64>) -> bool {
        self.missing == 0
            || (!stale.is_empty()
                && self
                    .layers
                    .iter()
                    .all(|&layer| self.chunks.contains(layer) || stale.contains_key(&column.chunk(layer))))
    }

    /// Counts [`CachedColumn::missing`] again after `layers` or `chunks`
    /// changed.
    fn recount_missing(&mut self) {
        self.missing = self.layers.iter().filter(|&&layer| !self.chunks.contains(layer)).count();
    }
}

/// A column's meshes by radial layer: a handful at most, so a short list
/// sorted by layer (a hash map per column cost a pointer chase and a hash
/// on every readiness check of every drawn column, every frame), and the
/// outermost layer held, kept beside it (read for every drawn column every
/// frame, [`ColumnSides::facing`]: the list is behind a pointer).
pub(crate) struct LayerMeshes<H>(Vec<(i32, LoadedChunk<H>)>, Option<i32>);

impl<H> Default for LayerMeshes<H> {
    fn default() -> Self {
        Self(Vec::new(), None)
    }
}

impl<H> LayerMeshes<H> {
    pub(crate) fn contains(&self, layer: i32) -> bool {
        self.0.iter().any(|(l, _)| *l == layer)
    }

    /// Holds `chunk` as `layer`, returning the mesh it replaces.
    fn insert(&mut self, layer: i32, chunk: LoadedChunk<H>) -> Option<LoadedChunk<H>> {
        match self.0.binary_search_by_key(&layer, |(l, _)| *l) {
            Ok(at) => Some(std::mem::replace(&mut self.0[at].1, chunk)),
            Err(at) => {
                // Most columns hold one or two layers: room for exactly
                // those, not the four a growing vector starts with (a
                // cache holds tens of thousands of columns).
                self.0.reserve_exact(1);
                self.0.insert(at, (layer, chunk));
                self.1 = self.0.last().map(|(l, _)| *l);
                None
            }
        }
    }

    fn remove(&mut self, layer: i32) -> Option<LoadedChunk<H>> {
        let at = self.0.iter().position(|(l, _)| *l == layer)?;
        let (_, chunk) = self.0.remove(at);
        self.1 = self.0.last().map(|(l, _)| *l);
        Some(chunk)
    }

    fn retain(&mut self, mut keep: impl FnMut(i32, &LoadedChunk<H>) -> bool) {
        self.0.retain(|(layer, chunk)| keep(*layer, chunk));
        self.1 = self.0.last().map(|(l, _)| *l);
    }

    /// The outermost layer held.
    fn top(&self) -> Option<i32> {
        self.1
    }

    /// The meshes, innermost layer first.
    pub(crate) fn iter(&self) -> impl Iterator<Item = (i32, &LoadedChunk<H>)> {
        self.0.iter().map(|(layer, chunk)| (*layer, chunk))
    }
}

/// The cached columns: a dense slab, and a small map from column to slot
/// (a hash map holding the columns themselves was tens of megabytes of
/// buckets, a miss in memory for every lookup of every drawn column; the
/// draw list keeps each drawn column's slot and walks them without one).
pub(crate) struct ColumnStore<H> {
    slots: HashMap<ChunkColumn, usize>,
    columns: slab::Slab<CachedColumn<H>>,
    /// Times the columns were taken to change ([`unshared`]): the same
    /// count, the same columns (a column's last use aside,
    /// [`MeshCache::mark_used`]).
    changes: u64,
    /// The columns changed (added, removed, their meshes or layers), in
    /// order, after the first `touched_before` ([`ColumnStore::touched_since`]):
    /// what a plan that read some columns only asks of later changes.
    touched: Vec<ChunkColumn>,
    touched_before: usize,
}

/// Changes [`ColumnStore`] logs before it forgets them (a plan older than
/// that is made again in full).
const MAX_TOUCHED: usize = 1 << 16;

impl<H> Default for ColumnStore<H> {
    fn default() -> Self {
        Self {
            slots: HashMap::default(),
            columns: slab::Slab::new(),
            changes: 0,
            touched: Vec::new(),
            touched_before: 0,
        }
    }
}

impl<H> ColumnStore<H> {
    /// Times the columns were taken to change: while it stays, so do they
    /// (but for their last uses).
    pub(crate) fn changes(&self) -> u64 {
        self.changes
    }

    /// How many column changes were logged so far: where
    /// [`ColumnStore::touched_since`] starts for changes after now.
    pub(crate) fn touch_count(&self) -> usize {
        self.touched_before + self.touched.len()
    }

    /// The columns changed since [`ColumnStore::touch_count`] was `count`
    /// (one may come more than once), or `None` where the log no longer
    /// reaches back that far.
    pub(crate) fn touched_since(&self, count: usize) -> Option<&[ChunkColumn]> {
        self.touched.get(count.checked_sub(self.touched_before)?..)
    }

    /// Logs a change of `column`.
    fn touch(&mut self, column: ChunkColumn) {
        if self.touched.len() >= MAX_TOUCHED {
            self.touched_before += self.touched.len();
            self.touched.clear();
        }
        self.touched.push(column);
    }

    pub(crate) fn get(&self, column: &ChunkColumn) -> Option<&CachedColumn<H>> {
        self.slots.get(column).map(|&slot| &self.columns[slot])
    }

    /// Whether the mesh of chunk `key` is held.
    pub(crate) fn holds(&self, key: ChunkKey) -> bool {
        self.get(&key.column()).is_some_and(|c| c.chunks.contains(key.layer))
    }

    /// The column's meshes, to change (the change is logged).
    fn get_mut(&mut self, column: &ChunkColumn) -> Option<&mut CachedColumn<H>> {
        self.touch(*column);
        self.slot_mut(column).map(|(_, cached)| cached)
    }

    /// The column's slot and meshes.
    pub(crate) fn slot(&self, column: &ChunkColumn) -> Option<(usize, &CachedColumn<H>)> {
        let slot = *self.slots.get(column)?;
        Some((slot, &self.columns[slot]))
    }

    /// The column's slot and meshes, to change.
    fn slot_mut(&mut self, column: &ChunkColumn) -> Option<(usize, &mut CachedColumn<H>)> {
        let slot = *self.slots.get(column)?;
        Some((slot, &mut self.columns[slot]))
    }

    /// The column in `slot`, if it is still `column`.
    pub(crate) fn in_slot(&self, slot: usize, column: ChunkColumn) -> Option<&CachedColumn<H>> {
        self.columns.get(slot).filter(|cached| cached.column == column)
    }

    /// The same, to change.
    fn in_slot_mut(&mut self, slot: usize, column: ChunkColumn) -> Option<&mut CachedColumn<H>> {
        self.columns.get_mut(slot).filter(|cached| cached.column == column)
    }

    /// The column's slot and meshes, made by `new` if it has none.
    fn get_or_insert_with(
        &mut self,
        column: ChunkColumn,
        new: impl FnOnce() -> CachedColumn<H>,
    ) -> (usize, &mut CachedColumn<H>) {
        self.touch(column);
        let slot = *self.slots.entry(column).or_insert_with(|| self.columns.insert(new()));
        (slot, &mut self.columns[slot])
    }

    fn remove(&mut self, column: &ChunkColumn) -> Option<CachedColumn<H>> {
        self.touch(*column);
        self.slots.remove(column).map(|slot| self.columns.remove(slot))
    }

    fn iter(&self) -> impl Iterator<Item = (&ChunkColumn, &CachedColumn<H>)> {
        self.columns.iter().map(|(_, cached)| (&cached.column, cached))
    }

    /// Every column with its slot.
    pub(crate) fn iter_slots(&self) -> impl Iterator<Item = (usize, &CachedColumn<H>)> {
        self.columns.iter()
    }

    /// A bound on the slots: every slot is under it.
    pub(crate) fn slot_bound(&self) -> usize {
        self.columns.capacity()
    }
}

/// Every chunk mesh held, by column, and the budget it is held to.
pub struct MeshCache<H> {
    /// Shared with the LOD thread, read only, while it plans the next
    /// frame (between updates, while the game draws): the streamer takes
    /// the plan back before it changes them ([`MeshCache::columns_mut`]).
    columns: Arc<ColumnStore<H>>,
    /// The sum of the columns' `held`.
    held: Held,
    /// Keep a CPU copy of each mesh.
    keep_cpu: bool,
    /// Also mesh and keep what the LOD tree holds out of view (every leaf,
    /// and its stand-in [`STAND_IN_LEVEL_STEP`] LODs up), after the view's
    /// own work and while the cache is under three quarters of its budget,
    /// so that turning the camera finds the new view meshed (default on;
    /// off: only what was seen is meshed, and a view turned to after a
    /// while is drawn through stand-ins as coarse as the face roots).
    pub prefetch: bool,
    /// Columns out of use this many frames are freed (face roots never).
    pub free_after_frames: u64,
    /// At most this many chunk meshes are kept (default 100,000): past it,
    /// the columns used longest ago (not drawn or wanted this frame) are
    /// freed first. What the frame draws is always kept. Memory is bounded
    /// by [`MeshCache::max_bytes`]; this bounds the bookkeeping (an Earth
    /// view 1 km up at 640×400 holds about 30,000 chunks, about 220 MB,
    /// with what is out of view).
    pub max_chunks: usize,
    /// The same for bytes of mesh data held (renderer, plus the CPU copies
    /// when kept). Chunks differ a lot in size, so a chunk count alone does
    /// not bound memory (measured: flying 15–150 m over Earth at 600–3,000
    /// m/s with CPU copies, the cache stays at ≤ 537 MB).
    pub max_bytes: u64,
    /// Mesh bytes uploaded per frame at most (default 16 MiB; at least one
    /// mesh a frame): a burst of finished jobs is spread over frames
    /// instead of one long upload.
    pub max_upload_bytes: u64,
    /// Drawn chunks an edit changed: the old mesh stays on screen until one
    /// of at least this voxel generation replaces it.
    stale: HashMap<ChunkKey, u64>,
    /// Of `stale`, the layers a change of view added to columns on screen
    /// ([`VoxelSource::layer_view`]): meshed at their column's priority,
    /// not ahead of everything as an edit's chunks are (the player looks
    /// at those).
    gained: HashSet<ChunkKey>,
    /// Chunks an edit changed while a job for them was running, with the
    /// voxel generation their mesh must be made from: that job read older
    /// voxels and is thrown away when collected, never cached as current
    /// (held only until then: a job taken after the edit reads its voxels).
    required: HashMap<ChunkKey, u64>,
    /// Meshes held back were drawn outside collecting (a chunk, layer or
    /// column dropped let them): the draw list's stubs are closed again
    /// ([`close_stubs`]) before the next frame.
    released: bool,
    /// Whether a plug group's meshes of the other plug choice wait until
    /// every chunk has one ([`MeshCache::insert`]); a test turns it off to
    /// see its check fail.
    #[cfg(test)]
    pub(crate) one_choice_per_group: bool,
}

impl<H: MeshHandle> MeshCache<H> {
    /// The default [`MeshCache::max_bytes`]: 256 MiB. It holds about what
    /// 360 MiB held before skirts were kept as outline edges (2026-11-27:
    /// the still Earth view 1 km up, 38.1 → 27.1 MB of meshes) and 512 MiB
    /// before meshes shrank by a third that morning, which a 640×400 view
    /// held still and then turned needs to keep its detail (the streaming
    /// test that does it keeps 84–94 % of the settled triangles at this
    /// budget). A game drawing more pixels wants more (the meshes a view
    /// draws grow with its pixels at a given τ).
    #[must_use]
    pub const fn default_max_bytes() -> u64 {
        256 << 20
    }

    /// The cached columns, to change ([`unshared`]).
    fn columns_mut(&mut self) -> &mut ColumnStore<H> {
        unshared(&mut self.columns)
    }

    /// Marks the columns in `used` (by slot) as used in `frame`, without
    /// counting a change ([`ColumnStore::changes`]): a plan reads a
    /// column's last use only to free it (for age, or near the budget),
    /// and a plan that frees is not repeated
    /// ([`repeatable_until`](crate::select::repeatable_until)).
    fn mark_used(&mut self, used: &[(usize, ChunkColumn)], frame: u64) {
        let columns = unshared_uncounted(&mut self.columns);
        for &(slot, column) in used {
            if let Some(cached) = columns.in_slot_mut(slot, column) {
                cached.last_used = frame;
            }
        }
    }

    /// Whether the mesh of `key` is held.
    /// Whether the mesh of chunk `key` is held.
    #[must_use]
    pub fn holds(&self, key: ChunkKey) -> bool {
        self.columns.holds(key)
    }

    /// Near the budget, given what is held (chunks, bytes): past 15/16 of
    /// either (a plan then lists what to free first).
    fn near_budget(&self, (chunks, bytes): (usize, u64)) -> bool {
        chunks > self.max_chunks / 16 * 15 || bytes > self.max_bytes / 16 * 15
    }

    /// Room for prefetching, given what is held (chunks, bytes): under
    /// three quarters of both budgets.
    fn room_to_prefetch(&self, (chunks, bytes): (usize, u64)) -> bool {
        chunks < self.max_chunks / 4 * 3 && bytes < self.max_bytes / 4 * 3
    }

    /// Bytes the renderer holds for the meshes.
    #[must_use]
    pub fn renderer_bytes(&self) -> u64 {
        self.held.renderer_bytes
    }

    /// Chunk meshes held.
    #[must_use]
    pub fn chunks(&self) -> usize {
        self.held.chunks
    }

    /// Bytes of mesh data held (renderer and CPU copies).
    #[must_use]
    pub fn held_bytes(&self) -> u64 {
        self.held.bytes
    }

    /// Holds `chunk`, made from the voxels of `generation`, as layer
    /// `layer` of `column` (a column already in the cache), in place of
    /// any mesh it had, and returns the chunks (with their generations)
    /// that are drawn now. A mesh whose plug choice ([`plug_choice`])
    /// differs from a mesh held for another chunk of its plug group
    /// ([`nebula_meshing::plug_group`]: the layers of 4 × 4 columns) waits
    /// in [`CachedColumn::pending`] instead, and the group's pending meshes
    /// are drawn all at once when, with them in place, the group holds one
    /// choice: a group plugged inside is meshed open chunk by chunk, but
    /// drawn so only when every chunk is.
    fn insert(
        &mut self,
        column: ChunkColumn,
        layer: i32,
        generation: u64,
        chunk: LoadedChunk<H>,
    ) -> Vec<(ChunkKey, u64)> {
        let key = column.chunk(layer);
        let columns = unshared(&mut self.columns);
        let Some(cached) = columns.get_mut(&column) else { return Vec::new() };
        let held = chunk.held();
        cached.held.add(held);
        self.held.add(held);
        // A pending mesh of the chunk is superseded either way.
        if let Some(at) = cached.pending.iter().position(|(l, _, _)| *l == layer) {
            let (_, _, old) = cached.pending.swap_remove(at);
            cached.held.sub(old.held());
            self.held.sub(old.held());
        }
        let (inside, open) = group_choices(columns, column, Some(key), false);
        let clashes = plug_choice(&chunk).is_some_and(|choice| if choice { open } else { inside });
        #[cfg(test)]
        let clashes = clashes && self.one_choice_per_group;
        let Some(cached) = columns.get_mut(&column) else { return Vec::new() };
        let mut drawn = Vec::new();
        if clashes {
            cached.pending.push((layer, generation, chunk));
        } else {
            if let Some(old) = cached.chunks.insert(layer, chunk) {
                cached.held.sub(old.held());
                self.held.sub(old.held());
            }
            cached.recount_missing();
            drawn.push((key, generation));
        }
        drawn.extend(release_pending(columns, &mut self.held, column));
        drawn
    }

    /// Drops the mesh of `key`, if held (and one pending for it).
    fn remove(&mut self, key: ChunkKey) {
        let Some(cached) = unshared(&mut self.columns).get_mut(&key.column()) else { return };
        if let Some(at) = cached.pending.iter().position(|(l, _, _)| *l == key.layer) {
            let (_, _, old) = cached.pending.swap_remove(at);
            cached.held.sub(old.held());
            self.held.sub(old.held());
        }
        if let Some(old) = cached.chunks.remove(key.layer) {
            cached.held.sub(old.held());
            self.held.sub(old.held());
            cached.recount_missing();
        }
        self.released |= !release_pending(unshared(&mut self.columns), &mut self.held, key.column()).is_empty();
    }

    /// Awaits the layers of `column` (on screen) that have no mesh like an
    /// edit's chunks (`stale`): the column stays drawn with its other
    /// layers meanwhile, not replaced by a coarse stand-in. `gained`
    /// (added by a change of view): meshed at the column's priority.
    fn await_missing_layers(&mut self, column: ChunkColumn, generation: u64, gained: bool) {
        let Some(cached) = self.columns.get(&column) else { return };
        for &layer in cached.layers.iter().filter(|&&layer| !cached.chunks.contains(layer)) {
            self.stale.insert(column.chunk(layer), generation);
            if gained {
                self.gained.insert(column.chunk(layer));
            }
        }
    }

    /// Keeps only the meshes of `column` whose layer `keep` accepts.
    fn retain_layers(&mut self, column: ChunkColumn, mut keep: impl FnMut(i32) -> bool) {
        let Some(cached) = unshared(&mut self.columns).get_mut(&column) else { return };
        let mut dropped = Held::default();
        cached.chunks.retain(|layer, chunk| {
            let kept = keep(layer);
            if !kept {
                dropped.add(chunk.held());
            }
            kept
        });
        cached.pending.retain(|(layer, _, chunk)| {
            let kept = keep(*layer);
            if !kept {
                dropped.add(chunk.held());
            }
            kept
        });
        cached.recount_missing();
        cached.held.sub(dropped);
        self.held.sub(dropped);
        self.released |= !release_pending(unshared(&mut self.columns), &mut self.held, column).is_empty();
    }

    /// Drops `column` and its meshes (the meshes its plug group's others
    /// held back for it drawn, where they now can be).
    fn remove_column(&mut self, column: ChunkColumn) {
        let columns = unshared(&mut self.columns);
        if let Some(cached) = columns.remove(&column) {
            self.held.sub(cached.held);
            self.released |= !release_pending(columns, &mut self.held, column).is_empty();
        }
    }

    /// The totals counted afresh (for checking the running ones).
    #[cfg(test)]
    fn recount(&self) -> Held {
        let mut held = Held::default();
        for (_, cached) in self.columns.iter() {
            for (_, chunk) in cached.chunks.iter() {
                held.add(chunk.held());
            }
            for (_, _, chunk) in &cached.pending {
                held.add(chunk.held());
            }
        }
        held
    }
}

/// Whether the meshes of `column`'s plug group ([`nebula_meshing::plug_group`])
/// hold a chunk plugged inside and one open ([`plug_choice`]): those drawn
/// but `except`'s, and with `with_pending` each pending mesh in place of
/// its chunk's.
fn group_choices<H: MeshHandle>(
    columns: &ColumnStore<H>,
    column: ChunkColumn,
    except: Option<ChunkKey>,
    with_pending: bool,
) -> (bool, bool) {
    let (mut inside, mut open) = (false, false);
    for cached in nebula_meshing::plug_group(column).filter_map(|c| columns.get(&c)) {
        let drawn = cached
            .chunks
            .iter()
            .filter(|&(l, _)| Some(cached.column.chunk(l)) != except && !(with_pending && cached.pends(l)));
        let pending = cached.pending.iter().filter(|_| with_pending).map(|(l, _, chunk)| (*l, chunk));
        for choice in drawn.chain(pending).filter_map(|(_, chunk)| plug_choice(chunk)) {
            inside |= choice;
            open |= !choice;
        }
    }
    (inside, open)
}

/// Draws the pending meshes of `column`'s plug group all at once
/// ([`CachedColumn::pending`]) where, with them in place of their chunks',
/// the group holds one plug choice; returns the chunks drawn (with their
/// voxels' generations). `held`: the cache's total, kept with the columns'.
fn release_pending<H: MeshHandle>(
    columns: &mut ColumnStore<H>,
    held: &mut Held,
    column: ChunkColumn,
) -> Vec<(ChunkKey, u64)> {
    let group: Vec<ChunkColumn> = nebula_meshing::plug_group(column).collect();
    let waiting = group.iter().filter_map(|c| columns.get(c)).any(|cached| !cached.pending.is_empty());
    if !waiting || group_choices(columns, column, None, true) == (true, true) {
        return Vec::new();
    }
    let mut drawn = Vec::new();
    for column in &group {
        let Some(cached) = columns.get_mut(column) else { continue };
        for (layer, generation, chunk) in std::mem::take(&mut cached.pending) {
            if let Some(old) = cached.chunks.insert(layer, chunk) {
                cached.held.sub(old.held());
                held.sub(old.held());
            }
            drawn.push((column.chunk(layer), generation));
        }
        cached.recount_missing();
    }
    drawn
}

/// The cached columns, to change: never while the LOD thread plans with
/// them (the streamer takes its plan back first, and the thread lets go of
/// them before it sends the plan).
fn unshared<H>(columns: &mut Arc<ColumnStore<H>>) -> &mut ColumnStore<H> {
    let columns = unshared_uncounted(columns);
    columns.changes += 1;
    columns
}

/// [`unshared`] without counting a change: for marking last uses alone
/// ([`MeshCache::mark_used`]).
fn unshared_uncounted<H>(columns: &mut Arc<ColumnStore<H>>) -> &mut ColumnStore<H> {
    Arc::get_mut(columns).expect("the cached columns are shared only while the LOD thread plans")
}

/// Which work a job is: the view's first, then seams, then prefetching.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Tier {
    /// Out of view, for a later turn ([`MeshCache::prefetch`]).
    Prefetch,
    /// A chunk drawn with a mesh made for other LODs around it than those
    /// drawn ([`SeamStrategy`]): its fallback skirts close the seam
    /// meanwhile.
    Reseam,
    /// In view (leaves, their stand-ins, edited chunks on screen).
    View,
}

/// A meshing job: one chunk, with the priority of its column, and the
/// seams to make it for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Job {
    pub(crate) tier: Tier,
    pub(crate) priority: f64,
    pub(crate) key: ChunkKey,
    pub(crate) seams: SeamStrategy,
    pub(crate) relations: SideRelations,
    /// Whether its dark cave air is plugged where its LOD is not plugged
    /// by itself ([`MeshOptions::plug_dark_air_inside`]): chosen as it is
    /// queued, by the eye of that update and its plug group's meshes held
    /// (see `Streamer::apply`).
    pub(crate) plug_inside: bool,
}

impl Eq for Job {}

impl Ord for Job {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.tier
            .cmp(&other.tier)
            .then_with(|| self.priority.total_cmp(&other.priority))
            .then_with(|| other.key.cmp(&self.key))
    }
}

impl PartialOrd for Job {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// The queue workers take jobs from, and the chunks they hold.
struct JobState<S, H> {
    queue: BinaryHeap<Job>,
    /// Taken by a worker and not collected yet (running, or finished and
    /// waiting in the channel), with the tier they were taken at.
    running: HashMap<ChunkKey, Tier>,
    /// The columns workers are meshing a chunk of now.
    in_hand: ColumnsInHand,
    /// The voxels jobs read and their generation: a worker takes them with
    /// each job, so an edit reaches the next job, not the next worker.
    voxels: Option<(Arc<S>, u64)>,
    /// Meshes uploaded and not kept, for the next worker to free: freeing
    /// megabytes of meshes made on other threads blocked the frame thread
    /// on the allocator's locks for milliseconds (a flight showed it asleep
    /// in their drop), and handing them to a thread of normal priority
    /// woke it in the middle of the frame.
    spent: Vec<RenderMesh>,
    /// Uploads each mesh on the worker that made it, if set
    /// ([`Streamer::set_uploader`]), keeping a CPU copy when `keep_cpu`.
    uploader: Option<Uploader<H>>,
    keep_cpu: bool,
    /// No job is started while set ([`Streamer::set_meshing_paused`]).
    paused: bool,
}

/// Jobs [`ColumnsInHand::take`] looks past for one whose column no
/// worker has in hand.
const JOBS_LOOKED_PAST: usize = 8;

/// The columns workers are meshing a chunk of now, with how many.
#[derive(Debug, Default)]
struct ColumnsInHand(HashMap<ChunkColumn, usize>);

impl ColumnsInHand {
    /// The top job of `queue`, passing over (up to [`JOBS_LOOKED_PAST`])
    /// those whose column a worker is meshing a chunk of now, which stay
    /// queued (for a job of the same tier only); its column is in hand
    /// until [`Self::put_down`]. Where every job looked at is of a column
    /// in hand, the top one.
    ///
    /// Why: a column's chunks share a priority and come out of the queue
    /// together, and a voxel source computes what they share once (the
    /// procedural planet's column heights, most of a chunk's cost). Taken
    /// side by side, the second waits for the first's heights (before the
    /// planet waited, it computed them again: 27 % of the columns computed
    /// for a hillside view); taken after it, it finds them made.
    fn take(&mut self, queue: &mut BinaryHeap<Job>) -> Option<Job> {
        let mut passed: Vec<Job> = Vec::new();
        let mut free = None;
        while passed.len() <= JOBS_LOOKED_PAST {
            let Some(job) = queue.pop() else { break };
            // Never a lower tier's instead: prefetching must not hold up
            // the view (the view's last chunks are often a column's
            // layers, one in hand).
            if passed.first().is_some_and(|top| job.tier < top.tier) {
                queue.push(job);
                break;
            }
            if self.0.contains_key(&job.key.column()) {
                passed.push(job);
            } else {
                free = Some(job);
                break;
            }
        }
        let job = match free {
            Some(job) => job,
            None if passed.is_empty() => return None,
            None => passed.remove(0),
        };
        queue.extend(passed);
        *self.0.entry(job.key.column()).or_default() += 1;
        Some(job)
    }

    /// A worker is done with a chunk of `column`.
    fn put_down(&mut self, column: ChunkColumn) {
        if let Some(count) = self.0.get_mut(&column) {
            *count -= 1;
            if *count == 0 {
                self.0.remove(&column);
            }
        }
    }
}

pub(crate) struct MeshResult<H> {
    pub(crate) key: ChunkKey,
    /// The seams it was made for.
    pub(crate) seams: SeamStrategy,
    pub(crate) relations: SideRelations,
    /// The voxel generation the mesh was made from.
    pub(crate) generation: u64,
    /// The mesh, or why there is none (an error, or a panic in the voxel
    /// source or the mesher, as text).
    pub(crate) result: Result<Made<H>, String>,
    pub(crate) millis: f64,
}

/// A finished mesh: to be uploaded by the frame thread, or uploaded
/// already by the worker that made it ([`Streamer::set_uploader`]).
pub(crate) enum Made<H> {
    /// Boxed: a render mesh's head (its part and skirt ranges) is a few
    /// hundred bytes, a job's result is moved through channels.
    Mesh(Box<RenderMesh>),
    Uploaded(LoadedChunk<H>),
}

impl<H: MeshHandle> Made<H> {
    /// Bytes the frame thread has to upload.
    fn upload_bytes(&self) -> u64 {
        match self {
            Made::Mesh(mesh) => mesh.bytes(),
            Made::Uploaded(_) => 0,
        }
    }
}

/// Makes a renderer's handle for a finished mesh on the meshing thread
/// that made it ([`Streamer::set_uploader`]).
pub type Uploader<H> = Arc<dyn Fn(ChunkKey, &RenderMesh) -> H + Send + Sync>;

/// A chunk whose meshing failed: it is asked for again after a wait that
/// doubles with each failure, and its stand-in is drawn meanwhile.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Failure {
    attempts: u32,
    /// The first frame it may be tried again.
    pub(crate) retry_at: u64,
}

/// Frames before the first retry of a failed chunk; each further failure
/// doubles it, up to 64 times (about 8 s at 60 fps).
pub const RETRY_AFTER_FRAMES: u64 = 8;

/// A meshing job that failed (an error, or a panic in the voxel source or
/// the mesher), reported once per chunk ([`Streamer::take_mesh_failures`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MeshFailure {
    /// The chunk.
    pub key: ChunkKey,
    /// What went wrong.
    pub message: String,
}

/// Meshing jobs: the shared priority queue, the workers on a thread pool of
/// their own and the channel finished meshes come back on.
struct Meshing<S, H> {
    /// Meshing's own threads: work the frame thread hands to rayon's global
    /// pool must never queue behind a worker that runs until the job queue
    /// is empty.
    pool: Arc<rayon::ThreadPool>,
    state: Arc<Mutex<JobState<S, H>>>,
    workers: Arc<AtomicUsize>,
    max_workers: usize,
    /// Bounded: a worker waits once [`MAX_UPLOADS_PER_FRAME`] results are
    /// waiting, so slow frames never pile meshes up in memory.
    sender: SyncSender<MeshResult<H>>,
    /// In a mutex only so that a streamer can be shared (`Sync`), as ECS
    /// resources must be; only `update` takes it.
    receiver: Mutex<Receiver<MeshResult<H>>>,
}

impl<S, H> Meshing<S, H> {
    /// Jobs queued or running, of the view and prefetching.
    fn pending(&self) -> usize {
        self.state.lock().map_or(0, |s| s.queue.len() + s.running.len())
    }

    /// Jobs of the view (its seams included) queued or running.
    fn view_pending(&self) -> usize {
        self.state.lock().map_or(0, |s| {
            s.queue.iter().filter(|job| job.tier != Tier::Prefetch).count()
                + s.running.values().filter(|&&tier| tier != Tier::Prefetch).count()
        })
    }
}

/// A sea the renderer draws over the sea bed
/// ([`Voxel::SEABED`](nebula_voxel::Voxel::SEABED)), opaque under
/// `hiding_depth` of water. Seen from above its surface, a column of sea
/// bed wholly deeper than that is hidden, so the streamer draws it as its
/// coarsest ancestor that is hidden too ([`VoxelSource::sea_bed_below`])
/// and has hidden sea bed across all four sides (so no leaf drawn in
/// detail borders it), instead of meshing it in detail.
///
/// Why coarse and not left out (as behind the horizon, where the ground in
/// front covers the place): the sea is drawn over the place itself, and
/// whatever the renderer shows where nothing is drawn, a coarse chunk in
/// its place keeps it from showing what lies behind the sea bed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpaqueSea {
    /// Radius of the sea's surface, metres.
    pub radius: f64,
    /// Depth of water, metres, under which the sea bed no longer shows
    /// (nothing under it changes a pixel).
    pub hiding_depth: f64,
}

impl OpaqueSea {
    /// The radius under which sea bed no longer shows through the water.
    #[must_use]
    pub fn hiding_radius(&self) -> f64 {
        self.radius - self.hiding_depth
    }
}

/// Columns [`Streamer`] remembers as under the sea or not before it
/// forgets them all (about 10 MB).
pub(crate) const MAX_SEA_BED_MEMO: usize = 200_000;

/// The prefetch set ([`MeshCache::prefetch`]) is worked out again (a walk
/// over every leaf of the tree, 10–20 ms on an Earth view) at most every
/// this many frames when the tree has changed, and every
/// [`PREFETCH_MAX_AGE_FRAMES`] otherwise: a still camera pays nothing.
pub const PREFETCH_REFRESH_FRAMES: u64 = 8;

/// The most jobs queued at once, the most urgent: the queue is made anew
/// every frame from every job wanted, and handing it all of them cost the
/// frame thread for each one (a fresh prefetch set of 20,470 jobs cost a
/// still camera's step 0.76 ms, `cargo bench -p nebula_world --bench
/// step`; the 1 km/s mountain flight, over 9,000 view jobs waiting, spent
/// a quarter of its selection handing them over). Two meshing threads
/// take about half a second to run this many, several frames at any rate.
pub const MAX_QUEUED_JOBS: usize = 1024;

/// The longest the prefetch set goes unrefreshed (what the horizon and
/// the sea hide moves with the eye even where the tree does not change).
pub const PREFETCH_MAX_AGE_FRAMES: u64 = 240;

/// What the next frame draws.
#[derive(Default, Clone)]
pub struct DrawList {
    /// Columns drawn, with their per-chunk draw constants.
    pub columns: Vec<(ChunkColumn, ChunkDraw)>,
    /// Visible leaves with nothing to draw for them (no meshed ancestor).
    pub holes: usize,
    /// Visible leaves drawn through a coarser ancestor or finer children.
    pub stand_ins: usize,
    /// Largest LOD gap between a visible leaf and the ancestor drawn for it.
    pub max_stand_in_levels: u8,
    /// Lowest surface radius under the drawn columns (those behind the
    /// horizon left out).
    pub min_surface_radius: f64,
    /// The sphere whose horizon hid leaves this frame
    /// ([`LodTree::horizon_occluder`](nebula_lod::LodTree::horizon_occluder)),
    /// metres; NaN where the source knows no lowest surface.
    pub occluder_radius: f64,
    /// Leaves in the frustum behind that horizon or the ground's in front:
    /// not drawn (their coarsest hidden ancestor is meshed all the same,
    /// and drawn as a backstop while a stand-in covers ground the horizon
    /// was made of: [`DrawList::backstops`]).
    pub behind_horizon: usize,
    /// Those leaves (tests only: what a draw list may leave uncovered).
    #[cfg(test)]
    pub(crate) behind_horizon_leaves: Vec<ChunkColumn>,
    /// Columns hidden behind the horizon drawn as backstops this frame: a
    /// stand-in drawn in front covers a leaf whose floor the ground's
    /// horizon took, so that horizon is not quite what is drawn (0 once a
    /// view has settled).
    pub backstops: usize,
    /// Columns whose tight tops the ground's horizon waits for
    /// ([`VoxelSource::surface_top_radius`], a few hundred sampled a
    /// plan): drawn in detail meanwhile, so the view is not final until
    /// none is.
    pub tops_awaited: usize,
    /// Leaves in the frustum under the opaque sea ([`OpaqueSea`]), drawn
    /// as their coarsest ancestor under it too.
    pub under_sea: usize,
    /// Drawn columns whose meshes were made for other LODs around them
    /// than those drawn ([`SeamStrategy`]; always 0 with skirts): their
    /// seams are closed by fallback skirts until they are meshed again.
    pub unsettled: usize,
    /// Largest LOD difference between drawn columns across a side.
    pub max_lod_diff: u8,
}

/// CPU time per stage, milliseconds, for the last frame (meshing: summed
/// over the jobs collected this frame).
#[derive(Default, Clone, Copy, Debug)]
pub struct StageTimes {
    /// LOD update and culling.
    pub lod_ms: f64,
    /// Choosing what to draw and what to mesh, on the frame thread: applying
    /// the plan made ahead on the LOD thread, or making it too when none
    /// could serve.
    pub select_ms: f64,
    /// Making the plan of the selection (on the LOD thread, ahead of the
    /// frame, when made there).
    pub plan_ms: f64,
    /// Whether the selection was planned ahead on the LOD thread (else on
    /// the frame thread: no plan made ahead could serve this camera).
    pub planned_ahead: bool,
    /// Wall time the update waited for the LOD thread to finish what it
    /// was asked for the frame before.
    pub lod_wait_ms: f64,
    /// Meshing jobs collected this frame (CPU time of the jobs, on worker
    /// threads).
    pub meshing_ms: f64,
    /// Meshing CPU time since the start, all jobs.
    pub meshing_total_ms: f64,
    /// Chunks meshed since the start.
    pub chunks_meshed: usize,
    /// Of which meshed again for the LODs drawn around them
    /// ([`SeamStrategy`]; none with skirts).
    pub chunks_remeshed: usize,
    /// Meshing errors since the start (each logged).
    pub mesh_errors: usize,
    /// Uploads of finished meshes this frame.
    pub upload_ms: f64,
    /// Bytes of the meshes uploaded this frame (at most
    /// [`MeshCache::max_upload_bytes`], or one mesh).
    pub upload_bytes: u64,
}

/// What the draw list shows, for reports and HUDs.
#[derive(Clone, Debug, Default)]
pub struct StreamFigures {
    /// The τ the LOD tree refines to, pixels: the one asked, or larger
    /// where the tree's node bound (`LodSettings::max_nodes`) needs it.
    pub threshold_px: f64,
    /// Chunks drawn.
    pub chunks: usize,
    /// Triangles drawn.
    pub triangles: usize,
    /// Of which skirts (the sides drawn lowered).
    pub skirt_triangles: usize,
    /// Skirt triangles of all sides in the drawn meshes (drawn or not).
    pub skirt_triangles_held: usize,
    /// Chunks drawn per LOD.
    pub lod_histogram: Vec<usize>,
    /// Triangles drawn per LOD (skirts included): where a view's triangles
    /// per pixel come from.
    pub lod_triangles: Vec<usize>,
    /// Visible leaves drawn through an ancestor or their children.
    pub stand_ins: usize,
    /// Visible leaves with nothing drawn for them.
    pub holes: usize,
    /// Leaves behind the terrain's horizon, not drawn
    /// ([`DrawList::behind_horizon`]).
    pub behind_horizon: usize,
    /// Hidden columns drawn as backstops ([`DrawList::backstops`]).
    pub backstops: usize,
    /// Leaves under the opaque sea, drawn coarse ([`DrawList::under_sea`]).
    pub under_sea: usize,
    /// Largest LOD difference between neighbouring leaves.
    pub max_neighbor_lod_diff: u8,
    /// Largest LOD difference between drawn columns across a side.
    pub max_drawn_lod_diff: u8,
    /// Drawn columns whose seams wait to be meshed for the LODs drawn
    /// around them ([`DrawList::unsettled`]).
    pub unsettled: usize,
    /// CPU time per stage.
    pub times: StageTimes,
    /// Meshing jobs queued or running (view and prefetch).
    pub jobs_in_flight: usize,
    /// Of which prefetching out of view ([`MeshCache::prefetch`]).
    pub prefetch_jobs: usize,
    /// Largest LOD gap between a visible leaf and the ancestor drawn for
    /// it ([`DrawList::max_stand_in_levels`]).
    pub max_stand_in_levels: u8,
    /// Bytes of the chunk meshes held by the renderer.
    pub renderer_bytes: u64,
    /// Bytes of mesh data held, renderer and CPU copies (what
    /// [`MeshCache::max_bytes`] bounds).
    pub held_bytes: u64,
    /// Chunk meshes held.
    pub chunks_held: usize,
}

/// The meshing threads' priority, on `thread-priority`'s cross-platform
/// scale (0–99, where the normal priority is about 48): niceness 2 on
/// Linux, so that the frame thread gets a core first without starving
/// meshing. Measured on the 2-core machine (lavapipe rasterising on the
/// same cores), 1 km/s flights 300 m over Earth at 640×400: over land the
/// frame thread's step median / 95th percentile 5.4 / 11.2 ms at the normal
/// priority, 2.5 / 7.4 ms at this one; niceness 5 gave the same over land
/// but over the mountains meshing fell behind (median 1,675 chunks drawn
/// through stand-ins 3 LODs coarse, against 8,644 and 1 LOD here).
pub const MESHING_THREAD_PRIORITY: u8 = 41;

thread_local! {
    static BUFFER: std::cell::RefCell<ChunkMeshBuffer> = std::cell::RefCell::new(ChunkMeshBuffer::new());
}

/// A planet's chunks streamed for a moving camera (see the module docs).
pub struct Streamer<S, H> {
    voxels: Arc<S>,
    /// How many times the voxels were replaced by edited ones.
    pub(crate) generation: u64,
    tree: LodTree,
    meshing: Meshing<S, H>,
    /// The meshes held and their budget.
    pub cache: MeshCache<H>,
    draw: DrawList,
    times: StageTimes,
    frame: u64,
    options: DrawOptions,
    eye: Camera,
    /// The sea the renderer draws, if any.
    sea: Option<OpaqueSea>,
    /// The camera the tree's visible leaves were last picked for, while
    /// the tree has not changed since.
    culled_for: Option<Camera>,
    /// The LOD thread's plan applied last (its number), the eye it was
    /// applied for and the cached columns' change count after it: while
    /// those stand, the same plan again draws what is drawn.
    applied: Option<(u64, Camera, u64)>,
    /// What the selection keeps from frame to frame (`None` while the
    /// LOD thread plans with it: [`Streamer::selection_mut`] takes it
    /// back).
    selection: Option<Box<Selection>>,
    /// What the LOD thread made for the next update, taken back before it
    /// (the selection's state was needed, or the cache was to change: its
    /// plan is dropped).
    early: Option<Outcome<H>>,
    /// Whether prefetching was done after the last update, bar the jobs
    /// queued or running ([`Streamer::prefetched`]).
    prefetch_done: bool,
    /// The cache slot of each column of the draw list, in its order.
    drawn_slots: Vec<Option<usize>>,
    /// Chunks and bytes held at the end of the last update.
    held: (usize, u64),
    /// Chunks whose meshing failed and when to try them again.
    failed: HashMap<ChunkKey, Failure>,
    /// LOD updates that failed (the first is reported).
    lod_failures: usize,
    /// Whether the last LOD update went through.
    lod_ok: bool,
    /// Finished meshes collected from the workers, not uploaded yet.
    pub(crate) finished: std::collections::VecDeque<MeshResult<H>>,
    /// First failures not taken by the game yet.
    failures: Vec<MeshFailure>,
    /// Meshes uploaded this frame and not kept, freed by a meshing worker
    /// ([`JobState::spent`]).
    spent: Vec<RenderMesh>,
    /// Chunks collected this frame (meshed, failed or thrown away): a plan
    /// made before asks for them again.
    collected: HashSet<ChunkKey>,
    /// The LOD tree's update and cull and the selection made ahead for the
    /// next frame (`None`: on the frame thread only,
    /// [`Streamer::set_lod_thread`]).
    lod_thread: Option<LodThread<S, H>>,
    /// Frames whose tree came from the LOD thread, and frames that had to
    /// update and cull on the frame thread.
    lod_frames: (u64, u64),
    /// How far the camera moved in the frame before (for the prediction).
    last_step: f64,
    /// What the eye can see of the source's layers
    /// ([`VoxelSource::layer_view`]): only those are meshed and drawn.
    view: LayerView,
    /// How seams between LODs are closed.
    seams: SeamStrategy,
    /// What the draw list was planned for, while it was planned ahead
    /// with a margin: the cameras it serves without a new plan.
    drawn_for: Option<DrawnFor>,
    /// Whether an update whose plan is not ready draws the last one again
    /// while it serves the camera (see [`Streamer::set_draw_while_planning`]).
    draw_while_planning: bool,
    /// Frames drawn from the plan before while the LOD thread planned.
    frames_drawn_while_planning: u64,
    /// Frames from asking the LOD thread to taking its outcome, last time:
    /// how far ahead the next request predicts the camera.
    plan_latency: u64,
    /// The draw list before is taken to serve any camera while the LOD
    /// thread plans: a test breaks it so to see its check catch it.
    #[cfg(test)]
    pub(crate) serve_any_camera: bool,
}

/// The cull a plan made ahead was made on (its camera and margin), with
/// the leaves in view it draws nothing for: a camera that cull covers and
/// that sees none of those leaves is served by the plan's draw list.
struct DrawnFor {
    camera: Camera,
    margin: CullMargin,
    unseen: Vec<NodeBounds>,
    /// The LOD thread's tree-changing requests when it was taken: one sent
    /// since (an edit, a new view) ends it.
    commands: u64,
}

impl<S: VoxelSource + 'static, H: MeshHandle> Streamer<S, H> {
    /// A streamer for `voxels` with LOD `settings`, seen first from
    /// `camera`, meshing on `threads` threads of its own (at least 1). The
    /// six face roots are meshed and uploaded with `upload` before it
    /// returns, so every frame has something to draw everywhere.
    ///
    /// # Errors
    /// Bad LOD settings, a root that cannot be meshed, or no thread pool.
    pub fn new(
        voxels: Arc<S>,
        settings: LodSettings,
        camera: Camera,
        threads: usize,
        upload: &mut dyn FnMut(ChunkKey, &RenderMesh) -> H,
    ) -> Result<Self, StreamError> {
        let tree = LodTree::new(&*voxels, settings)?;
        let view = voxels.layer_view(camera.position);
        let (sender, receiver) = sync_channel(MAX_UPLOADS_PER_FRAME);
        let threads = threads.max(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|n| format!("nebula-mesh-{n}"))
            // Below the frame thread, which must not wait for a core while
            // meshing (a lower priority needs no privilege; where it is
            // refused the threads run at the normal one).
            .start_handler(|_| {
                if let Ok(value) = thread_priority::ThreadPriorityValue::try_from(MESHING_THREAD_PRIORITY) {
                    let _ = thread_priority::ThreadPriority::Crossplatform(value).set_for_current();
                }
            })
            // Jobs catch their own panics; without a handler rayon would
            // abort the game on any other.
            .panic_handler(|panic| log::error!("a meshing thread panicked: {}", panic_text(&*panic)))
            .build()
            .map_err(|e| StreamError::Threads(e.to_string()))?;
        let mut streamer = Self {
            voxels,
            generation: 0,
            tree,
            meshing: Meshing {
                pool: Arc::new(pool),
                state: Arc::new(Mutex::new(JobState {
                    queue: BinaryHeap::new(),
                    running: HashMap::default(),
                    in_hand: ColumnsInHand::default(),
                    voxels: None,
                    spent: Vec::new(),
                    uploader: None,
                    keep_cpu: false,
                    paused: false,
                })),
                workers: Arc::default(),
                max_workers: threads,
                sender,
                receiver: Mutex::new(receiver),
            },
            cache: MeshCache {
                columns: Arc::default(),
                held: Held::default(),
                keep_cpu: false,
                prefetch: true,
                free_after_frames: 300,
                max_chunks: 100_000,
                max_bytes: MeshCache::<H>::default_max_bytes(),
                max_upload_bytes: 16 << 20,
                stale: HashMap::default(),
                gained: HashSet::default(),
                required: HashMap::default(),
                released: false,
                #[cfg(test)]
                one_choice_per_group: true,
            },
            draw: DrawList::default(),
            times: StageTimes::default(),
            frame: 0,
            view,
            options: DrawOptions::default(),
            eye: camera,
            sea: None,
            culled_for: None,
            applied: None,
            selection: Some(Box::new(Selection::new())),
            early: None,
            prefetch_done: false,
            drawn_slots: Vec::new(),
            held: (0, 0),
            failed: HashMap::default(),
            lod_failures: 0,
            lod_ok: false,
            finished: std::collections::VecDeque::new(),
            failures: Vec::new(),
            spent: Vec::new(),
            collected: HashSet::default(),
            lod_thread: None,
            lod_frames: (0, 0),
            last_step: 0.0,
            seams: SeamStrategy::Skirts,
            drawn_for: None,
            draw_while_planning: true,
            frames_drawn_while_planning: 0,
            plan_latency: 1,
            #[cfg(test)]
            serve_any_camera: false,
        };
        streamer.set_lod_thread(true);
        streamer.mesh_roots(upload)?;
        Ok(streamer)
    }

    /// Meshes the face roots on the calling thread (all of the planet, at
    /// its coarsest LOD: the stand-in of last resort).
    fn mesh_roots(&mut self, upload: &mut dyn FnMut(ChunkKey, &RenderMesh) -> H) -> Result<(), StreamError> {
        let max_lod = self.voxels.layout().max_lod();
        let mut buffer = ChunkMeshBuffer::new();
        for face in CubeFace::ALL {
            let column = ChunkColumn { face, lod: max_lod, x: 0, y: 0 };
            for layer in self.voxels.surface_chunk_layers(column)? {
                let key = column.chunk(layer);
                let mesh = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    mesh_chunk(
                        &*self.voxels,
                        key,
                        &ChunkLodContext::uniform(max_lod),
                        MeshOptions::STREAMING,
                        &mut buffer,
                    )
                }))
                .map_err(|panic| StreamError::Panicked { key, message: panic_text(&*panic) })??;
                let done = MeshResult {
                    key,
                    seams: self.seams,
                    relations: SAME_ALL_ROUND,
                    generation: 0,
                    result: Ok(Made::Mesh(Box::new(mesh.render_mesh()))),
                    millis: 0.0,
                };
                self.store(done, upload);
            }
        }
        Ok(())
    }

    /// Uploads each finished mesh on the meshing thread that made it with
    /// `uploader` (`Some`), instead of on the frame thread in
    /// [`Streamer::update`] with its mesh maker (`None`, the default): the
    /// frame thread then copies no mesh bytes (the land flight spent about
    /// 0.9 ms of its 2.8 ms step doing so). The uploader must be callable
    /// from any thread (a wgpu renderer's is:
    /// `nebula_render::PlanetRenderer::uploader`) and its handles may be
    /// dropped on any thread. Jobs already finished keep the way they were
    /// made.
    pub fn set_uploader(&mut self, uploader: Option<Uploader<H>>) {
        if let Ok(mut state) = self.meshing.state.lock() {
            state.uploader = uploader;
        }
    }

    /// Pauses meshing (`true`): no new job starts, jobs already running
    /// finish and are collected, and the view is drawn from what is held
    /// (stand-ins where meshes are missing). For a game's loading screen or
    /// a frame that needs both cores, and for measuring the frame thread's
    /// work against a fixed state. `false` starts the workers again.
    pub fn set_meshing_paused(&mut self, paused: bool) {
        if let Ok(mut state) = self.meshing.state.lock() {
            state.paused = paused;
        }
        if !paused {
            self.spawn_workers();
        }
    }

    /// Keep a CPU copy of every mesh (for checks that ray-cast what is
    /// drawn); counted in the byte budget.
    pub fn keep_cpu_meshes(&mut self, keep: bool) {
        self.cache.keep_cpu = keep;
        if let Ok(mut state) = self.meshing.state.lock() {
            state.keep_cpu = keep;
        }
    }

    /// Closes the seams between LODs with `seams` from the next update (see
    /// [`SeamStrategy`]). Meshes made for other LODs around them than the
    /// same all round are dropped and made again; the rest serve every
    /// strategy.
    pub fn set_seam_strategy(&mut self, seams: SeamStrategy) {
        if seams == self.seams {
            return;
        }
        self.reclaim();
        self.seams = seams;
        let keys: Vec<ChunkKey> = self
            .cache
            .columns
            .iter()
            .flat_map(|(column, cached)| {
                cached
                    .chunks
                    .iter()
                    .filter(|(_, chunk)| chunk.made_for != SAME_ALL_ROUND)
                    .map(|(layer, _)| column.chunk(layer))
                    .collect::<Vec<_>>()
            })
            .collect();
        for key in keys {
            self.cache.remove(key);
        }
    }

    /// How seams between LODs are closed.
    #[must_use]
    pub fn seam_strategy(&self) -> SeamStrategy {
        self.seams
    }

    /// Changes what is drawn (see [`DrawOptions`]), from the next update.
    pub fn set_draw_options(&mut self, options: DrawOptions) {
        if options != self.options {
            // A plan made ahead has the old ones.
            self.reclaim();
        }
        self.options = options;
    }

    /// The draw options.
    #[must_use]
    pub fn draw_options(&self) -> DrawOptions {
        self.options
    }

    /// Tells the streamer the sea the renderer draws over the sea bed
    /// (`None`: no sea, every leaf is drawn in detail), from the next
    /// update. See [`OpaqueSea`].
    pub fn set_opaque_sea(&mut self, sea: Option<OpaqueSea>) {
        if self.sea != sea {
            self.sea = sea;
            self.selection_mut().under_sea.clear();
        }
    }

    /// The voxels streamed.
    #[must_use]
    pub fn voxels(&self) -> &Arc<S> {
        &self.voxels
    }

    /// The LOD tree.
    #[must_use]
    pub fn tree(&self) -> &LodTree {
        &self.tree
    }

    /// The camera of the last update.
    #[must_use]
    pub fn camera(&self) -> &Camera {
        &self.eye
    }

    /// One frame: updates the LOD selection for `camera`, uploads finished
    /// meshes with `upload` (at most [`MAX_UPLOADS_PER_FRAME`]), chooses
    /// what to draw and what to mesh next, and frees meshes past the
    /// budget. Never waits for meshing.
    ///
    /// With the LOD thread ([`Streamer::set_lod_thread`], the default) the
    /// tree and the selection of this frame were made ahead, while the
    /// game drew the frame before, for a predicted camera; this update
    /// takes them when they cover the camera that came, and makes its own
    /// when not. Where they are not made yet, the frame draws the
    /// selection before again if it serves the camera, rather than wait
    /// ([`Streamer::set_draw_while_planning`]).
    pub fn update(&mut self, camera: Camera, upload: &mut dyn FnMut(ChunkKey, &RenderMesh) -> H) {
        self.frame += 1;
        let start = Instant::now();
        // The LOD thread still planning (a narrow lens's turn can take it
        // several frames): the plan before, if it serves this camera, is
        // drawn again instead of waiting.
        let planning = self.early.is_none() && self.lod_thread.as_mut().is_some_and(|t| t.in_flight() && !t.ready());
        if planning && self.draw_while_planning && self.drawn_plan_serves(&camera) {
            self.draw_again_for(camera, start);
            return;
        }
        let mut made_ahead = self.take_outcome();
        if made_ahead.is_some()
            && let Some(thread) = self.lod_thread.as_ref()
        {
            self.plan_latency = self.frame.saturating_sub(thread.asked_in()).clamp(1, MAX_PLAN_LATENCY);
        }
        self.times.lod_wait_ms = start.elapsed().as_secs_f64() * 1e3;
        #[cfg(test)]
        if let Some(differs) = made_ahead.as_ref().and_then(|outcome| outcome.prefetch_mismatch) {
            panic!("a prefetch-only plan differs from the full plan in {differs}");
        }
        let view = self.voxels.layer_view(camera.position);
        if view != self.view {
            self.view = view;
            self.refresh_layers();
            // Planned for the layers seen before.
            if let Some(outcome) = made_ahead.as_mut() {
                outcome.plan = None;
            }
        }
        let (previous, last_step) = self.move_eye(camera);
        // The tree made ahead for this frame, when its cull covers the
        // camera that came; else the frame thread updates its own.
        let mut plan = None;
        let made = made_ahead.as_ref().map(|outcome| (outcome.plan_number, outcome.repeated));
        let made_for = made_ahead.as_ref().and_then(Outcome::culled_for);
        // An update that failed on the thread is made here, where its error
        // is found and reported.
        let failed_ahead = made_ahead.as_ref().is_some_and(|outcome| outcome.tree.is_none());
        match made_ahead.map(|outcome| self.take_made_ahead(outcome, &camera)) {
            Some(Some(planned)) => {
                self.lod_frames.0 += 1;
                self.lod_ok = true;
                plan = planned;
            }
            missed => {
                self.lod_frames.1 += u64::from(missed.is_some());
                // Made for a camera this one left (it turned past the
                // margin while the thread planned): the plan before, if it
                // serves, is drawn again and the thread asked anew, rather
                // than planning here.
                if missed.is_some() && !failed_ahead && self.draw_while_planning && self.drawn_plan_serves(&camera) {
                    self.draw_again_and_ask(start, &previous, last_step);
                    return;
                }
                self.update_tree(camera);
            }
        }
        self.times.lod_ms = start.elapsed().as_secs_f64() * 1e3;
        self.collect(upload);
        // A plan made ahead that cannot serve this camera (it sees leaves
        // the plan draws nothing for): the plan before, if it serves and
        // no mesh collected now could change a seam it was checked
        // against, is drawn again and the thread asked anew, rather than
        // planning here.
        if plan.as_ref().is_some_and(|plan| !self.serves(plan))
            && self.draw_while_planning
            && (self.collected.is_empty() || !self.seams.meshes_for_neighbours())
            && self.drawn_plan_serves(&camera)
        {
            self.draw_again_and_ask(start, &previous, last_step);
            return;
        }
        if self.lod_ok {
            let (plan, here) = match plan.filter(|plan| self.serves(plan)) {
                Some(plan) => (plan, false),
                None => (self.plan_here(), true),
            };
            // What the draw list will serve while the next plan is made.
            self.drawn_for = made_for.filter(|_| !here).map(|(camera, margin)| DrawnFor {
                camera,
                margin,
                unseen: plan.unseen.clone(),
                commands: self.lod_thread.as_ref().map_or(0, LodThread::commands),
            });
            self.times.planned_ahead = !here;
            let number = made.filter(|_| !here).map(|(number, _)| number);
            let drawn_again = made.is_some_and(|(_, repeated)| repeated)
                && self.collected.is_empty()
                && number.is_some_and(|number| self.applied == Some((number, camera, self.cache.columns.changes())));
            if drawn_again {
                // The plan drawn now, for the same eye over the same
                // columns: what it draws stands (its walls that look away
                // included), and nothing is to mesh.
                let applying = Instant::now();
                self.cache.mark_used(&plan.used, self.frame);
                self.free(Vec::new(), None);
                self.times.plan_ms = 0.0;
                self.times.select_ms = applying.elapsed().as_secs_f64() * 1e3;
            } else {
                self.apply(plan);
            }
            self.applied = number.map(|number| (number, camera, self.cache.columns.changes()));
            if here {
                self.times.select_ms += self.times.plan_ms;
            }
        } else if !self.collected.is_empty() || std::mem::take(&mut self.cache.released) {
            // The last frame's selection is drawn again, with the meshes
            // just collected (or drawn from those held back): its stubs
            // closed by them.
            close_stubs(self.voxels.layout(), &self.cache.columns, &mut self.draw, &self.drawn_slots);
        }
        // Else the last frame's selection is drawn again (nothing it draws
        // was freed), never an empty one.
        self.prefetch_done = self.selection.as_deref().is_some_and(|selection| {
            (!self.cache.prefetch || !selection.tree_changed)
                && (selection.prefetch_jobs.is_empty() || !self.cache.room_to_prefetch(self.held))
        });
        #[cfg(test)]
        {
            assert_eq!(self.cache.held, self.cache.recount(), "the cache's running totals");
            for (column, cached) in self.cache.columns.iter() {
                let missing = cached.layers.iter().filter(|&&layer| !cached.chunks.contains(layer)).count();
                assert_eq!(cached.missing, missing, "{column:?}: layers without a mesh");
            }
            assert_eq!(self.draw.columns.len(), self.drawn_slots.len());
            for (&(column, _), &slot) in self.draw.columns.iter().zip(&self.drawn_slots) {
                assert!(
                    slot.is_some_and(|slot| self.cache.columns.in_slot(slot, column).is_some()),
                    "{column:?} is drawn from slot {slot:?}, which does not hold it"
                );
            }
        }
        if self.lod_ok {
            self.ask_ahead(&previous, &camera, last_step);
        }
    }

    /// Whether the draw list serves `camera` as it is: it was planned
    /// ahead on a cull that covers `camera` ([`cull_reaches`]), for the
    /// layers `camera` sees, with no tree-changing request since, and
    /// `camera` sees none of the leaves in view it draws nothing for.
    fn drawn_plan_serves(&self, camera: &Camera) -> bool {
        let Some(drawn) = &self.drawn_for else { return false };
        #[cfg(test)]
        if self.serve_any_camera {
            return true;
        }
        camera.check().is_ok()
            && self.lod_thread.as_ref().is_some_and(|thread| thread.commands() == drawn.commands)
            && self.voxels.layer_view(camera.position) == self.view
            && cull_reaches((drawn.camera, drawn.margin), self.tree.settings().fov_y_degrees, camera)
            && self.sees_none_of(camera, &drawn.unseen)
    }

    /// This frame draws the draw list before for `camera`
    /// ([`Self::drawn_plan_serves`]) while the LOD thread plans: nothing is
    /// collected or planned.
    fn draw_again_for(&mut self, camera: Camera, start: Instant) {
        self.move_eye(camera);
        self.draw_again(start);
    }

    /// The eye is `camera` now: returns the one before and the step before
    /// it (what the prediction of the next goes by).
    fn move_eye(&mut self, camera: Camera) -> (Camera, f64) {
        let previous = std::mem::replace(&mut self.eye, camera);
        let step = previous.position.distance(camera.position);
        (previous, std::mem::replace(&mut self.last_step, step))
    }

    /// The draw list before, its walls turned for the eye that came (which
    /// of a column's sides look away moves with it), its stubs closed by
    /// the meshes collected (one meshed open draws them again); no mesh is
    /// collected for seams made for neighbours (a new one could change a
    /// seam the list was checked against).
    fn draw_again(&mut self, start: Instant) {
        if self.options.cull_back_sides {
            let cull = (*self.tree.screen_space(), self.morphs());
            let eye = self.eye.position;
            face_walls(&*self.voxels, &self.cache.columns, &mut self.draw, &self.drawn_slots, eye, cull);
        }
        if !self.collected.is_empty() || std::mem::take(&mut self.cache.released) {
            close_stubs(self.voxels.layout(), &self.cache.columns, &mut self.draw, &self.drawn_slots);
        }
        self.frames_drawn_while_planning += 1;
        let millis = start.elapsed().as_secs_f64() * 1e3;
        self.times = StageTimes {
            lod_ms: millis,
            select_ms: millis,
            planned_ahead: true,
            meshing_total_ms: self.times.meshing_total_ms,
            chunks_meshed: self.times.chunks_meshed,
            chunks_remeshed: self.times.chunks_remeshed,
            mesh_errors: self.times.mesh_errors,
            ..StageTimes::default()
        };
    }

    /// [`Self::draw_again`] for the eye that came (`self.eye`, moved from
    /// `previous`), the plan that came set aside, and the LOD thread asked
    /// anew.
    fn draw_again_and_ask(&mut self, start: Instant, previous: &Camera, last_step: f64) {
        self.draw_again(start);
        let eye = self.eye;
        self.ask_ahead(previous, &eye, last_step);
    }

    /// Whether an update whose plan the LOD thread has not finished draws
    /// the plan before again, while it serves the camera (a camera the
    /// margin it was planned with covers; `true`, the default), instead of
    /// waiting for the new one. Such frames collect no meshes; the thread
    /// is then asked for the camera as far ahead as its plans take.
    pub fn set_draw_while_planning(&mut self, on: bool) {
        self.draw_while_planning = on;
    }

    /// Frames drawn from the plan before while the LOD thread planned
    /// ([`Streamer::set_draw_while_planning`]).
    #[must_use]
    pub fn frames_drawn_while_planning(&self) -> u64 {
        self.frames_drawn_while_planning
    }

    /// Asks the LOD thread for the next frame's tree and selection, for the
    /// camera that the motion from `previous` to `current` predicts (as many
    /// frames ahead as the last plan took to come); the selection's state
    /// and the cached columns go with the request.
    fn ask_ahead(&mut self, previous: &Camera, current: &Camera, last_step: f64) {
        if self.lod_thread.is_none() {
            return;
        }
        let latency = self.plan_latency;
        let (next, margin, turn) = predict(previous, current, last_step, latency);
        // Wide enough for the turn of the frames the plan is to serve while
        // the next is made (within the cull's margin).
        let view_angle = (PLANNED_VIEW_ANGLE_DEGREES.to_radians() + turn * (latency - 1) as f64).min(margin.angle);
        let settings = self.select_settings(self.frame + 1, (next, margin.distance, view_angle), true);
        let select = SelectRequest {
            selection: self.selection.take().unwrap_or_else(|| Box::new(Selection::new())),
            columns: self.cache.columns.clone(),
            stale: self.cache.stale.clone(),
            gained: self.cache.gained.clone(),
            failed: self.failed.clone(),
            settings,
        };
        if let Some(thread) = self.lod_thread.as_mut() {
            thread.ask(&self.voxels, next, margin, select);
        }
    }

    /// Takes back what the LOD thread made for this update (waiting for
    /// it, or as taken back before): the selection's state comes home and
    /// the cached columns are the frame thread's alone again.
    fn take_outcome(&mut self) -> Option<Outcome<H>> {
        let mut outcome = match self.early.take() {
            Some(outcome) => outcome,
            None => self.lod_thread.as_mut()?.take()?,
        };
        if let Some(selection) = outcome.selection.take() {
            self.selection = Some(selection);
        }
        Some(outcome)
    }

    /// Takes back the selection's state and the cached columns if the LOD
    /// thread is planning with them, keeping its tree for the next update
    /// and dropping its plan (what it was made from is about to change).
    fn reclaim(&mut self) {
        if let Some(mut outcome) = self.take_outcome() {
            outcome.plan = None;
            self.early = Some(outcome);
        }
    }

    /// The selection's state, taken back from the LOD thread if it is
    /// there (a new one if the thread is gone with it).
    pub(crate) fn selection_mut(&mut self) -> &mut Selection {
        if self.selection.is_none() {
            self.reclaim();
        }
        self.selection.get_or_insert_with(|| Box::new(Selection::new()))
    }

    /// Takes the tree the LOD thread made for this frame, and its plan, if
    /// the tree was made after every change sent to the thread and its
    /// cull covers `camera`; `None` when it cannot serve (not covered,
    /// failed, or made before a change).
    fn take_made_ahead(&mut self, outcome: Outcome<H>, camera: &Camera) -> Option<Option<Plan<H>>> {
        let thread = self.lod_thread.as_mut()?;
        if !thread.is_current(&outcome) {
            return None;
        }
        // Its cull, made with a margin, narrowed to this camera's view.
        match outcome.tree? {
            MadeTree::Whole(mut tree, copy) => {
                tree.narrow_cull(camera).ok()?;
                self.tree = *tree;
                thread.hold(Some(copy));
            }
            MadeTree::Cull(cull, copy) => {
                // Made on the copy this tree is (the thread sends a cull
                // alone only for the copy the request said it holds).
                if thread.holding() != Some(copy) {
                    return None;
                }
                if outcome.repeated && self.culled_for == Some(*camera) {
                    // The cull this tree was narrowed from, for this eye.
                    return Some(outcome.plan);
                }
                let own = self.tree.cull_result();
                self.tree.set_cull(cull);
                if self.tree.narrow_cull(camera).is_err() {
                    self.tree.set_cull(own);
                    return None;
                }
            }
        }
        self.culled_for = Some(*camera);
        Some(outcome.plan)
    }

    /// The settings of a plan for `frame`, for `camera` (its eye, or one
    /// within `eye_margin` of it).
    fn select_settings(
        &self,
        frame: u64,
        (camera, eye_margin, view_angle): (Camera, f64, f64),
        sample_tops: bool,
    ) -> SelectSettings {
        SelectSettings {
            frame,
            view: self.view,
            seams: self.seams,
            sea: self.sea,
            options: self.options,
            prefetch: self.cache.prefetch,
            room_to_prefetch: self.cache.room_to_prefetch(self.held),
            free_after_frames: self.cache.free_after_frames,
            near_budget: self.cache.near_budget(self.held),
            camera,
            eye_margin,
            view_angle,
            sample_tops,
        }
    }

    /// Whether a plan made ahead serves the camera that came: it sees none
    /// of the leaves in view the plan draws nothing for (as the tree's
    /// narrowed cull tells what it sees).
    fn serves(&self, plan: &Plan<H>) -> bool {
        self.sees_none_of(&self.eye, &plan.unseen)
    }

    /// Whether `camera` sees none of `unseen` (a plan's leaves in view it
    /// draws nothing for): each outside its frustum or under its horizon.
    fn sees_none_of(&self, camera: &Camera, unseen: &[NodeBounds]) -> bool {
        if unseen.is_empty() {
            return true;
        }
        let frustum = nebula_lod::Frustum::new(camera, self.tree.settings().fov_y_degrees);
        let horizon = nebula_lod::Horizon::new(camera.position, self.tree.min_surface_radius());
        unseen.iter().all(|bounds| frustum.excludes(bounds) || horizon.hides(bounds))
    }

    /// Plans this frame's selection on the frame thread (no plan made
    /// ahead could serve).
    fn plan_here(&mut self) -> Plan<H> {
        // Far tops are sampled on the LOD thread, off the frame's time;
        // without one, here (the view would never settle on them).
        let settings = self.select_settings(self.frame, (self.eye, 0.0, 0.0), self.lod_thread.is_none());
        let mut selection = self.selection.take().unwrap_or_else(|| Box::new(Selection::new()));
        let input = SelectInput {
            voxels: &*self.voxels,
            tree: &self.tree,
            columns: &self.cache.columns,
            stale: &self.cache.stale,
            gained: &self.cache.gained,
            failed: &self.failed,
            settings,
        };
        let plan = crate::select::plan(&input, &mut selection);
        self.selection = Some(selection);
        plan
    }

    /// Applies a plan made from the streamer as the last update left it
    /// (here or on the LOD thread): marks what it draws and wants as used,
    /// adds the columns it wants, tells which walls look away from the eye
    /// that came, checks seams against the meshes held now (this update
    /// collected some), and queues its jobs.
    fn apply(&mut self, plan: Plan<H>) {
        let start = Instant::now();
        let Plan {
            mut draw,
            slots,
            arounds,
            used,
            new_columns,
            dropped_stale,
            mut jobs,
            forget_failed,
            aged,
            least_recent,
            millis,
            ..
        } = plan;
        let frame = self.frame;
        // The τ and morph the frame is drawn with: how wide its walls look.
        let (screen, morph) = (*self.tree.screen_space(), self.morphs());
        let cache = &mut self.cache;
        cache.mark_used(&used, frame);
        if !new_columns.is_empty() {
            let columns = cache.columns_mut();
            for cached in new_columns {
                // Collected meshes may have brought the column in already.
                columns.get_or_insert_with(cached.column, || cached).1.last_used = frame;
            }
        }
        for key in dropped_stale {
            // Unless its new mesh came meanwhile.
            if cache.stale.remove(&key).is_some() {
                cache.remove(key);
            }
        }
        let MeshCache { stale, gained, .. } = &mut *cache;
        gained.retain(|key| stale.contains_key(key));
        let (voxels, eye, seams, options) = (&*self.voxels, self.eye.position, self.seams, self.options);
        if options.cull_back_sides {
            face_walls(voxels, &cache.columns, &mut draw, &slots, eye, (screen, morph));
        }
        close_stubs(voxels.layout(), &cache.columns, &mut draw, &slots);
        cache.released = false;
        // A plan made ahead asks for what this update collected: asked
        // again if it still is (a failure waits for its retry below, an
        // edit's chunk is stale until a mesh of its voxels comes). Only the
        // plan's jobs: a seam found wrong below is found so against the
        // meshes held now, those just collected included (filtered too, a
        // mesh collected for LODs no longer drawn around it was never
        // meshed again, and the view counted as settled with its seam
        // waiting: `settled()` with `unsettled` > 0).
        if !self.collected.is_empty() {
            let (collected, cache) = (&self.collected, &*cache);
            jobs.retain(|job| {
                !collected.contains(&job.key) || (!cache.holds(job.key) || cache.stale.contains_key(&job.key))
            });
        }
        let mut reseamed = HashSet::default();
        if seams.meshes_for_neighbours() {
            let tree = &self.tree;
            let priority = |column: ChunkColumn| job_priority(voxels, tree, eye, column, None);
            let reseams = settle_seams(voxels, cache, &mut draw, &slots, &arounds, seams, options, &priority);
            if !reseams.is_empty() {
                // Seams of the view to mesh again: no prefetching yet.
                if let Some(selection) = self.selection.as_deref_mut() {
                    selection.view_busy = true;
                }
                jobs.retain(|job| job.tier != Tier::Prefetch);
            }
            reseamed.extend(reseams.iter().map(|job| job.key));
            // One job per chunk: an edited chunk among them is meshed for
            // them by its edit's job; one the plan meshes again whole
            // (unplugged) by its re-seam.
            jobs.retain(|job| !reseamed.contains(&job.key) || cache.stale.contains_key(&job.key));
            jobs.extend(reseams.into_iter().filter(|job| !cache.stale.contains_key(&job.key)));
        }
        // A chunk that failed waits for its retry (failures collected this
        // update too); one no longer asked for is forgotten.
        for key in forget_failed.iter().filter(|key| !reseamed.contains(*key)) {
            self.failed.remove(key);
        }
        if !self.failed.is_empty() {
            let failed = &self.failed;
            jobs.retain(|job| failed.get(&job.key).is_none_or(|f| f.retry_at <= frame));
        }
        keep_most_urgent(&mut jobs);
        // Chosen now, by the eye the jobs are queued for (a plan made ahead
        // was made for a predicted one), and by plug group: a group held
        // with one choice keeps it, but one plugged inside is meshed open
        // once due for one of its columns in the tree (`group_unplug_due`),
        // its chunks drawn so together (`MeshCache::insert`); a new group
        // is plugged only where all its columns in the tree are far
        // (`plugs_far`). A chunk whose mesh of that choice waits for its
        // group is not meshed again (an edit's, stale, is).
        let mut choices: HashMap<ChunkColumn, bool> = HashMap::default();
        for job in &mut jobs {
            let column = job.key.column();
            let group = nebula_meshing::plug_group_key(column);
            job.plug_inside = *choices.entry(group).or_insert_with(|| {
                let (tree, columns) = (&self.tree, &cache.columns);
                let in_tree = || nebula_meshing::plug_group(column).filter(|&c| tree.node_bounds(c).is_some());
                match group_plug_choice(columns, column) {
                    Some(true) => !group_unplug_due(tree, column, eye),
                    Some(false) => false,
                    None => in_tree().next().is_some() && in_tree().all(|c| plugs_far(tree, seams, c, eye)),
                }
            });
        }
        jobs.retain(|job| {
            let waits = cache.columns.get(&job.key.column()).is_some_and(|cached| {
                cached
                    .pending
                    .iter()
                    .any(|(layer, _, mesh)| *layer == job.key.layer && mesh.plugged_inside == job.plug_inside)
            });
            !waits || cache.stale.contains_key(&job.key)
        });
        if let Ok(mut state) = self.meshing.state.lock() {
            state.queue.clear();
            let JobState { queue, running, .. } = &mut *state;
            queue.extend(jobs.into_iter().filter(|job| !running.contains_key(&job.key)));
            state.voxels = Some((self.voxels.clone(), self.generation));
        }
        self.draw = draw;
        self.drawn_slots = slots;
        self.spawn_workers();
        self.times.plan_ms = millis;
        self.times.select_ms = start.elapsed().as_secs_f64() * 1e3;
        self.free(aged, least_recent);
        if std::mem::take(&mut self.cache.released) {
            // A column freed let its plug group's held-back meshes be drawn.
            close_stubs(self.voxels.layout(), &self.cache.columns, &mut self.draw, &self.drawn_slots);
        }
    }

    /// Updates and culls the frame thread's own tree for `camera`.
    fn update_tree(&mut self, camera: Camera) {
        // The leaves in view depend on the camera and the tree alone: a
        // still camera over a settled tree need not walk it again. A panic
        // in the voxel source's bounds (a game's own) fails the update, not
        // the game.
        let mut changed = false;
        let culled = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            self.tree.update(&*self.voxels, &camera).and_then(|changes| {
                let same_tree =
                    changes.added.is_empty() && changes.removed.is_empty() && changes.neighbours_changed.is_empty();
                changed = !same_tree;
                if !(same_tree && self.culled_for == Some(camera)) {
                    self.culled_for = None;
                    self.tree.cull(&camera)?;
                    self.culled_for = Some(camera);
                }
                Ok(())
            })
        }))
        .map(|result| {
            // A bad camera is refused before the tree changes; a source
            // that fails may have stopped the update part-way.
            result.map_err(|error| {
                let damaged = !matches!(error, LodError::BadCamera { .. } | LodError::CameraInsidePlanet { .. });
                (error.to_string(), damaged)
            })
        })
        .unwrap_or_else(|panic| Err((format!("the voxel source panicked: {}", panic_text(&*panic)), true)));
        self.lod_ok = culled.is_ok();
        if let Err((error, damaged)) = culled {
            self.culled_for = None;
            self.lod_failures += 1;
            if self.lod_failures == 1 {
                log::warn!("LOD update failed, keeping the last selection (reported once): {error}");
            }
            if damaged {
                // Start the tree again from its roots: the next updates
                // refine it anew; the meshes held stay.
                let settings = *self.tree.settings();
                let voxels = &*self.voxels;
                if let Ok(Ok(tree)) =
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| LodTree::new(voxels, settings)))
                {
                    self.tree = tree;
                    changed = true;
                }
            }
        }
        if changed {
            self.selection_mut().tree_changed = true;
        }
        // The LOD thread goes on from the tree this frame made, not its own
        // older one (on a cold start it would make the whole tree again
        // while the next frame waits for it).
        if changed && let Some(thread) = self.lod_thread.as_mut() {
            thread.replace(&self.tree);
        }
    }

    /// Makes the LOD tree's update and cull and the selection ahead, on a
    /// thread of their own, between updates (while the game draws), for
    /// the camera the last two frames' motion predicts, with a margin
    /// around it (`true`, the default); a frame whose camera the margin
    /// covers takes that tree and plan and only applies the plan, others
    /// update their own and plan as with `false`. Returns whether the
    /// thread runs (it may not start).
    pub fn set_lod_thread(&mut self, on: bool) -> bool {
        // What the old thread made is not for the new one (nor are its
        // plans' numbers).
        self.reclaim();
        self.early = None;
        self.applied = None;
        self.lod_thread = if on { LodThread::start(&self.tree).ok() } else { None };
        self.lod_thread.is_some()
    }

    /// Frames whose LOD tree came from the LOD thread, and frames whose
    /// tree it made could not serve (the camera jumped or turned past the
    /// margin, the update failed, or an edit came in between), updated on
    /// the frame thread. Every update asks the thread for the next (the
    /// selection is planned there too), a still camera's as well; one
    /// that follows no request (the first, or one after a failed update)
    /// counts in neither.
    #[must_use]
    pub fn lod_thread_frames(&self) -> (u64, u64) {
        self.lod_frames
    }

    /// Whole copies of the LOD tree the LOD thread has sent back; its
    /// other outcomes carried the cull alone (the tree had not changed
    /// since the copy the frame thread holds).
    #[must_use]
    pub fn lod_tree_copies(&self) -> u64 {
        self.lod_thread.as_ref().map_or(0, LodThread::copies)
    }

    /// Plans the LOD thread sent that were its plan before again, not made
    /// anew: a still camera over a settled view (nothing to mesh, free or
    /// wait for) is planned once, and again only where time alone may
    /// change the plan (a column out of use long enough to free, the
    /// prefetch set's greatest age). The frame thread then keeps what it
    /// draws as it is.
    #[must_use]
    pub fn lod_plans_repeated(&self) -> u64 {
        self.lod_thread.as_ref().map_or(0, LodThread::repeats)
    }

    /// Plans the LOD thread made for a settled view's frames that only
    /// prefetching changed (each mesh that comes for it changes the cached
    /// columns): the view's part of the plan before again, with the next
    /// prefetch jobs, instead of a plan made in full.
    #[must_use]
    pub fn lod_plans_for_prefetching(&self) -> u64 {
        self.lod_thread.as_ref().map_or(0, LodThread::prefetch_plans)
    }

    /// Draws `voxels` from now on: the same planet after edits whose dirty
    /// chunks (every LOD, as `World::apply` returns them) are `dirty`.
    /// Chunks on screen keep their old mesh until the new one is uploaded,
    /// so an edit never opens a hole; others are dropped and meshed again
    /// when needed. The LOD tree re-reads the bounds of the columns touched
    /// (an edit can raise or sink the surface).
    ///
    /// # Errors
    /// If the voxel source refuses a touched column.
    pub fn set_voxels(&mut self, voxels: Arc<S>, dirty: &[ChunkKey]) -> Result<(), StreamError> {
        self.reclaim();
        self.generation += 1;
        self.voxels = voxels;
        let stitched = self.stitched_across(dirty);
        let dirty = &[dirty, &stitched].concat();
        self.culled_for = None;
        let columns: HashSet<ChunkColumn> = dirty.iter().map(|key| key.column()).collect();
        // An edit can put anything on the sea bed, and moves tops: those
        // of the columns it touched and of every column above them are
        // asked again. Only those: the rest of a view's hidden ground
        // stays hidden (with every top forgotten, a plan samples a few
        // hundred again and draws the rest as if seen, through coarse
        // stand-ins where their own meshes were never made).
        let mut touched: HashSet<ChunkColumn> = HashSet::default();
        for &column in &columns {
            let mut up = Some(column);
            while let Some(c) = up.filter(|&c| touched.insert(c)) {
                up = parent(c);
            }
        }
        let selection = self.selection_mut();
        selection.under_sea.retain(|column, _| !touched.contains(column));
        selection.tops.retain(|column, _| !touched.contains(column));
        // The next job a worker takes reads the new voxels; only the jobs
        // running now read the old ones, so only their meshes need checking
        // (all under one lock: no job is taken in between).
        let running: HashSet<ChunkKey> = match self.meshing.state.lock() {
            Ok(mut state) => {
                state.voxels = Some((self.voxels.clone(), self.generation));
                state.running.keys().copied().collect()
            }
            Err(_) => HashSet::default(),
        };
        // A source that refuses a column leaves the tree's bounds old, never
        // the meshes: the error is returned once the rest is done.
        let refreshed = self.tree.refresh_bounds(&*self.voxels, columns.iter().copied());
        if let Some(thread) = self.lod_thread.as_mut() {
            thread.refresh(&self.voxels, columns.iter().copied().collect());
        }
        let drawn: HashSet<ChunkColumn> = self.draw.columns.iter().map(|(c, _)| *c).collect();
        for &column in &columns {
            self.reread_layers(column);
            if !drawn.contains(&column) {
                for &key in dirty.iter().filter(|key| key.column() == column) {
                    self.cache.remove(key);
                }
            }
        }
        for key in dirty {
            let column = key.column();
            // An edited chunk is awaited first, whatever awaited it before.
            self.cache.gained.remove(key);
            if running.contains(key) {
                self.cache.required.insert(*key, self.generation);
            }
            if drawn.contains(&column) && self.cache.holds(*key) {
                self.cache.stale.insert(*key, self.generation);
            }
        }
        // A layer an edit added to a column on screen (a tower, a shaft)
        // is awaited like a changed chunk: the column stays drawn with its
        // other layers meanwhile, not replaced by a coarse stand-in.
        for &column in columns.iter().filter(|column| drawn.contains(column)) {
            self.cache.await_missing_layers(column, self.generation, false);
        }
        refreshed?;
        Ok(())
    }

    /// The chunks held or being meshed whose stitches read voxels of `dirty`
    /// chunks: with
    /// [`SeamStrategy::Stitched`] a chunk next to a coarser column holds
    /// that column's voxels along the seam (`nebula_meshing::stitch`), up to
    /// a coarse voxel deep, which its own padding does not reach. Every held
    /// chunk stitched to some coarser neighbour, and every job running,
    /// under a same-LOD neighbour of a dirty column (more than needed:
    /// edits are rare).
    fn stitched_across(&self, dirty: &[ChunkKey]) -> Vec<ChunkKey> {
        if self.seams != SeamStrategy::Stitched || dirty.is_empty() {
            return Vec::new();
        }
        let layout = self.voxels.layout();
        let max_lod = layout.max_lod();
        let beside: HashSet<ChunkColumn> = dirty
            .iter()
            .flat_map(|key| FaceEdge::ALL.map(|edge| layout.neighbor(key.column().chunk(0), edge).column()))
            .collect();
        let under_beside = |column: ChunkColumn| {
            let mut c = column;
            while let Some(up) = parent(c).filter(|_| c.lod < max_lod) {
                if beside.contains(&up) {
                    return true;
                }
                c = up;
            }
            false
        };
        let stitched = |chunk: &LoadedChunk<H>| {
            chunk.made_for.iter().any(|r| matches!(r, nebula_lod::NeighborLodRelation::HigherThanNeighbor { .. }))
        };
        let mut keys: Vec<ChunkKey> = self
            .cache
            .columns
            .iter()
            .filter(|(column, _)| under_beside(**column))
            .flat_map(|(column, cached)| {
                cached.chunks.iter().filter(|(_, chunk)| stitched(chunk)).map(|(layer, _)| column.chunk(layer))
            })
            .collect();
        // Jobs running now read the old voxels: their meshes are asked for
        // again (`MeshCache::required`).
        if let Ok(state) = self.meshing.state.lock() {
            keys.extend(state.running.keys().filter(|key| under_beside(key.column())));
        }
        keys.sort_unstable();
        keys.dedup();
        keys
    }

    /// Re-reads every held column's layers once the eye went down into
    /// sealed caves or came back out ([`VoxelSource::layer_view`]): the
    /// meshes of layers no longer seen are freed, and a column on screen
    /// that gains layers stays drawn with the others until they are
    /// meshed (as for an edit that adds a layer).
    fn refresh_layers(&mut self) {
        // Prefetch jobs made for the old layers would be meshed and thrown
        // away: list them again on the next update.
        let selection = self.selection_mut();
        selection.prefetched_at = 0;
        selection.prefetch_jobs.clear();
        let drawn: HashSet<ChunkColumn> = self.draw.columns.iter().map(|(c, _)| *c).collect();
        let columns: Vec<ChunkColumn> = self.cache.columns.iter().map(|(column, _)| *column).collect();
        for column in columns {
            self.reread_layers(column);
            if drawn.contains(&column) {
                self.cache.await_missing_layers(column, self.generation, true);
            }
        }
    }

    /// Reads `column`'s layers again (its voxels or the view changed),
    /// freeing the meshes of layers it no longer has.
    fn reread_layers(&mut self, column: ChunkColumn) {
        let layers = column_layers(&*self.voxels, &self.tree, column, self.view);
        let Some(cached) = self.cache.columns_mut().get_mut(&column) else { return };
        cached.layers.clone_from(&layers);
        self.cache.retain_layers(column, |layer| layers.contains(&layer));
    }

    /// Chunks on screen still drawn from before an edit.
    #[must_use]
    pub fn stale_chunks(&self) -> usize {
        self.cache.stale.len()
    }

    /// Whether the view is final: nothing drawn in place of a visible leaf,
    /// no job of the view queued or running (meshing a seam again for the
    /// LODs drawn around it included, [`SeamStrategy`]) and nothing drawn
    /// from before an edit. (A seam whose meshing keeps failing waits with
    /// its fallback skirts: [`StreamFigures::unsettled`].)
    #[must_use]
    pub fn settled(&self) -> bool {
        self.lod_ok
            && self.draw.stand_ins == 0
            && self.draw.holes == 0
            && self.meshing.view_pending() == 0
            && self.cache.stale.is_empty()
            && self.draw.tops_awaited == 0
    }

    /// Whether prefetching out of view ([`MeshCache::prefetch`]) has
    /// nothing left to mesh (or no room to), its set made for the tree as
    /// it is (right after a view settles, the set is still the one made
    /// before the tree was refined, and is made anew within a few frames).
    #[must_use]
    pub fn prefetched(&self) -> bool {
        self.prefetch_done && self.meshing.pending() == self.meshing.view_pending()
    }

    /// Meshing jobs queued or running (the view's and prefetching); at
    /// most [`MAX_QUEUED_JOBS`] of those wanted are queued at a time.
    #[must_use]
    pub fn jobs_in_flight(&self) -> usize {
        self.meshing.pending()
    }

    /// What the last update chose to draw.
    #[must_use]
    pub fn draw_list(&self) -> &DrawList {
        &self.draw
    }

    /// The chunks to draw this frame, with their draw constants.
    pub fn drawn(&self) -> impl Iterator<Item = (ChunkKey, &LoadedChunk<H>, ChunkDraw)> + '_ {
        // Each column straight from its slot; the list is made with its
        // slots, and nothing frees a drawn column until the next one.
        self.draw
            .columns
            .iter()
            .zip(&self.drawn_slots)
            .filter_map(|(&(column, draw), &slot)| {
                let cached = slot
                    .and_then(|slot| self.cache.columns.in_slot(slot, column))
                    .or_else(|| self.cache.columns.get(&column));
                cached.map(|c| (column, c, draw))
            })
            .flat_map(|(column, cached, draw)| {
                cached.chunks.iter().map(move |(layer, chunk)| (column.chunk(layer), chunk, draw))
            })
    }

    /// The vertex shader's per-frame constants for an eye at `eye`.
    #[must_use]
    pub fn frame_draw(&self, eye: nebula_math::DVec3) -> FrameDraw {
        // The τ the tree refines to: the morph must follow the same one.
        let screen = self.tree.screen_space();
        FrameDraw::new(eye, screen.k(), screen.threshold_px(), self.morphs())
    }

    /// Whether the frame's vertices geomorph (the draw options and the
    /// seam strategy allow it).
    fn morphs(&self) -> bool {
        self.options.morph != MorphRule::Off && self.seams.morphs()
    }

    /// Changes the view the LOD tree refines and culls for: τ, the screen
    /// height and the vertical field of view (a zoom, a resized window, a
    /// quality setting). Call it before [`Streamer::update`] whenever one
    /// may have changed; nothing happens when none did.
    ///
    /// # Errors
    /// Bad values ([`LodError`]); the view is unchanged then.
    pub fn set_view(
        &mut self,
        threshold_px: f64,
        screen_height_px: f64,
        fov_y_degrees: f64,
    ) -> Result<(), StreamError> {
        let before = *self.tree.settings();
        self.tree.set_view(threshold_px, screen_height_px, fov_y_degrees)?;
        if *self.tree.settings() != before {
            self.culled_for = None;
            self.selection_mut().tree_changed = true;
            if let Some(thread) = self.lod_thread.as_mut() {
                thread.set_view(threshold_px, screen_height_px, fov_y_degrees);
            }
        }
        Ok(())
    }

    /// Figures of what the draw list shows.
    #[must_use]
    pub fn figures(&self) -> StreamFigures {
        let max_lod = self.tree.max_lod();
        let lods = usize::from(max_lod) + 1;
        let mut figures =
            StreamFigures { lod_histogram: vec![0; lods], lod_triangles: vec![0; lods], ..StreamFigures::default() };
        for (key, chunk, draw) in self.drawn() {
            figures.chunks += 1;
            let skirts: usize = chunk
                .skirt_triangles
                .iter()
                .zip(draw.skirt_depths)
                .filter(|(_, d)| *d > 0.0)
                .map(|(&n, _)| n as usize)
                .sum();
            let shown = |(part, &n): (usize, &u32)| if draw.drawn_parts() & (1 << part) != 0 { n as usize } else { 0 };
            let triangles = chunk.surface_triangles.iter().enumerate().map(shown).sum::<usize>() + skirts;
            figures.triangles += triangles;
            figures.lod_triangles[usize::from(key.lod)] += triangles;
            figures.skirt_triangles += skirts;
            figures.skirt_triangles_held += chunk.skirt_triangles.iter().map(|&n| n as usize).sum::<usize>();
            figures.lod_histogram[usize::from(key.lod)] += 1;
        }
        figures.threshold_px = self.tree.screen_space().threshold_px();
        figures.stand_ins = self.draw.stand_ins;
        figures.behind_horizon = self.draw.behind_horizon;
        figures.backstops = self.draw.backstops;
        figures.under_sea = self.draw.under_sea;
        figures.holes = self.draw.holes;
        figures.max_neighbor_lod_diff = self.tree.stats().max_neighbor_lod_diff;
        figures.max_drawn_lod_diff = self.draw.max_lod_diff;
        figures.unsettled = self.draw.unsettled;
        figures.times = self.times;
        figures.jobs_in_flight = self.jobs_in_flight();
        figures.prefetch_jobs = figures.jobs_in_flight - self.meshing.view_pending();
        figures.max_stand_in_levels = self.draw.max_stand_in_levels;
        figures.renderer_bytes = self.cache.renderer_bytes();
        figures.held_bytes = self.cache.held_bytes();
        figures.chunks_held = self.cache.chunks();
        figures
    }

    /// The lowest surface radius anywhere: a camera must stay above it.
    #[must_use]
    pub fn min_surface_radius(&self) -> f64 {
        self.tree.min_surface_radius()
    }

    /// The lowest surface radius under the columns drawn: everything on
    /// screen lies above it.
    #[must_use]
    pub fn view_min_surface_radius(&self) -> f64 {
        if self.draw.min_surface_radius.is_finite() { self.draw.min_surface_radius } else { self.min_surface_radius() }
    }

    /// Uploads a finished job into the cache. A failed one is not stored:
    /// it is reported once, asked for again after a wait that doubles each
    /// time, and what stands in for it stays drawn meanwhile. Returns
    /// whether it failed.
    fn store(&mut self, done: MeshResult<H>, upload: &mut dyn FnMut(ChunkKey, &RenderMesh) -> H) -> bool {
        let key = done.key;
        let column = key.column();
        if done.seams != self.seams {
            // Made before a switch of strategy: asked for again.
            return false;
        }
        if let Some(wanted) = self.cache.required.remove(&key)
            && done.generation < wanted
        {
            // Made from voxels before an edit: asked for again (the next
            // job reads the new ones).
            return false;
        }
        let mesh = match done.result {
            Ok(mesh) => mesh,
            Err(message) => {
                let failure = self.failed.entry(key).or_insert(Failure { attempts: 0, retry_at: 0 });
                failure.attempts += 1;
                failure.retry_at = self.frame + (RETRY_AFTER_FRAMES << (failure.attempts - 1).min(6));
                if failure.attempts == 1 {
                    log::warn!("meshing {key:?} failed, retrying with backoff: {message}");
                    self.failures.push(MeshFailure { key, message });
                }
                return true;
            }
        };
        self.failed.remove(&key);
        let loaded = match mesh {
            Made::Uploaded(loaded) => loaded,
            Made::Mesh(mesh) => {
                let mut loaded = LoadedChunk {
                    made_for: done.relations,
                    ..LoadedChunk::uploaded(key, *mesh, |key, mesh| upload(key, mesh), true)
                };
                if !self.cache.keep_cpu {
                    // Freed by a meshing worker (`JobState::spent`).
                    self.spent.extend(loaded.cpu.take().map(|mesh| *mesh));
                }
                loaded
            }
        };
        let (voxels, tree, frame, view) = (&*self.voxels, &self.tree, self.frame, self.view);
        let (_, entry) = self
            .cache
            .columns_mut()
            .get_or_insert_with(column, || CachedColumn::new(voxels, tree, column, frame, view));
        if entry.layers.contains(&key.layer) {
            // An edit's chunk is stale until a mesh of its voxels is drawn
            // (one held back is asked for again, with its group's choice).
            for (drawn, generation) in self.cache.insert(column, key.layer, done.generation, loaded) {
                if self.cache.stale.get(&drawn).is_some_and(|&wanted| generation >= wanted) {
                    self.cache.stale.remove(&drawn);
                }
                // Drawn now (a plan made ahead asks for it no more).
                self.collected.insert(drawn);
            }
        } else if self.cache.stale.get(&key).is_some_and(|&wanted| done.generation >= wanted) {
            self.cache.stale.remove(&key);
        }
        false
    }

    /// Meshing failures since the last call, one per chunk (its first):
    /// errors of the voxel source or the mesher, and panics in them, which
    /// are caught. Each chunk is retried with backoff; chunks failing now
    /// are [`Streamer::failing_chunks`].
    pub fn take_mesh_failures(&mut self) -> Vec<MeshFailure> {
        std::mem::take(&mut self.failures)
    }

    /// LOD updates that failed since the start (a bad camera, or the voxel
    /// source's bounds failing or panicking; the tree is then started
    /// again from its roots), the first reported on stderr.
    #[must_use]
    pub fn lod_failures(&self) -> usize {
        self.lod_failures
    }

    /// Chunks still asked for whose last meshing attempt failed (retried
    /// with backoff).
    #[must_use]
    pub fn failing_chunks(&self) -> usize {
        self.failed.len()
    }

    /// Picks up finished meshes and uploads them.
    fn collect(&mut self, upload: &mut dyn FnMut(ChunkKey, &RenderMesh) -> H) {
        let start = Instant::now();
        // Finished meshes wait here (at most MAX_UPLOADS_PER_FRAME, so the
        // workers block behind a full channel rather than pile meshes up)
        // and go up at most max_upload_bytes a frame, largest priority
        // first as they came.
        if let Ok(receiver) = self.meshing.receiver.lock() {
            let room = MAX_UPLOADS_PER_FRAME.saturating_sub(self.finished.len());
            self.finished.extend(receiver.try_iter().take(room));
        }
        let mut results = Vec::new();
        let mut bytes = 0u64;
        while let Some(done) = self.finished.front() {
            let size = done.result.as_ref().map_or(0, Made::upload_bytes);
            if !results.is_empty() && bytes + size > self.cache.max_upload_bytes {
                break;
            }
            bytes += size;
            results.extend(self.finished.pop_front());
        }
        self.times.upload_bytes = bytes;
        if let Ok(mut state) = self.meshing.state.lock() {
            for done in &results {
                if state.running.remove(&done.key) == Some(Tier::Reseam) {
                    self.times.chunks_remeshed += 1;
                }
            }
        }
        let mut meshing_ms = 0.0;
        self.collected.clear();
        for done in results {
            self.collected.insert(done.key);
            meshing_ms += done.millis;
            self.times.chunks_meshed += 1;
            if self.store(done, upload) {
                self.times.mesh_errors += 1;
            }
        }
        if !self.spent.is_empty()
            && let Ok(mut state) = self.meshing.state.lock()
        {
            state.spent.append(&mut self.spent);
        }
        self.times.meshing_ms = meshing_ms;
        self.times.meshing_total_ms += meshing_ms;
        self.times.upload_ms = start.elapsed().as_secs_f64() * 1e3;
    }

    /// Starts workers until every meshing thread has one or the queue is
    /// empty. A worker takes the top job ([`ColumnsInHand::take`]), meshes it
    /// and sends it back, until the queue is empty; nothing ever waits for
    /// it.
    fn spawn_workers(&self) {
        let meshing = &self.meshing;
        loop {
            let queued = meshing.state.lock().map_or(0, |s| if s.paused { 0 } else { s.queue.len() });
            let workers = meshing.workers.load(Ordering::Acquire);
            if queued == 0 || workers >= meshing.max_workers {
                return;
            }
            meshing.workers.fetch_add(1, Ordering::AcqRel);
            let (state, workers, sender) = (meshing.state.clone(), meshing.workers.clone(), meshing.sender.clone());
            meshing.pool.spawn(move || {
                // The column of the chunk this worker meshed last.
                let mut finished = None;
                loop {
                    let mut spent = Vec::new();
                    let job = state.lock().ok().and_then(|mut s| {
                        if let Some(column) = finished.take() {
                            s.in_hand.put_down(column);
                        }
                        spent = std::mem::take(&mut s.spent);
                        let voxels = s.voxels.clone().filter(|_| !s.paused)?;
                        let JobState { queue, in_hand, .. } = &mut *s;
                        let job = in_hand.take(queue)?;
                        s.running.insert(job.key, job.tier);
                        Some((job, voxels, s.uploader.clone(), s.keep_cpu))
                    });
                    // Freed here, outside the lock.
                    drop(spent);
                    let Some((job, (voxels, generation), uploader, keep_cpu)) = job else { break };
                    finished = Some(job.key.column());
                    let start = Instant::now();
                    // A panic in the voxel source (a game's own) or the
                    // mesher fails this chunk, not the game.
                    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        BUFFER.with(|buffer| {
                            mesh_chunk(
                                &*voxels,
                                job.key,
                                &mesh_context(job.key.lod, &job.relations),
                                MeshOptions { plug_dark_air_inside: job.plug_inside, ..job.seams.mesh_options() },
                                &mut buffer.borrow_mut(),
                            )
                            .map(|mesh| mesh.render_mesh())
                            .map_err(|error| error.to_string())
                        })
                    }))
                    .unwrap_or_else(|panic| {
                        // The buffer may be half written: start afresh.
                        BUFFER.with(|buffer| *buffer.borrow_mut() = ChunkMeshBuffer::new());
                        Err(format!("panicked: {}", panic_text(&*panic)))
                    });
                    // Uploaded here when the game gave an uploader: the
                    // frame thread then copies no mesh bytes.
                    let result = result.map(|mesh| match &uploader {
                        Some(upload) => Made::Uploaded(LoadedChunk {
                            made_for: job.relations,
                            ..LoadedChunk::uploaded(job.key, mesh, &**upload, keep_cpu)
                        }),
                        None => Made::Mesh(Box::new(mesh)),
                    });
                    let millis = start.elapsed().as_secs_f64() * 1e3;
                    // It stays in the running set until collected, so no
                    // queue refresh asks for it again while it waits in the
                    // channel.
                    let done = MeshResult {
                        key: job.key,
                        seams: job.seams,
                        relations: job.relations,
                        generation,
                        result,
                        millis,
                    };
                    if sender.send(done).is_err() {
                        // The streamer is gone: stop meshing its queue.
                        break;
                    }
                }
                workers.fetch_sub(1, Ordering::AcqRel);
            });
        }
    }

    /// Frees the columns the plan found out of use for a while (`aged`,
    /// every 10 frames), and in a frame that finds the cache past its chunk
    /// or byte budget the least recently used ones until it is under it
    /// (in the plan's order, `least_recent`, or one listed here where it
    /// made none), never the face roots, never what this frame draws or
    /// wants.
    fn free(&mut self, aged: Vec<(usize, ChunkColumn)>, least_recent: Option<Vec<(usize, ChunkColumn)>>) {
        let frame = self.frame;
        let cache = &mut self.cache;
        let limit = cache.free_after_frames;
        for (slot, column) in aged {
            // Unless used since the plan was made.
            if cache.columns.in_slot(slot, column).is_some_and(|cached| frame.saturating_sub(cached.last_used) > limit)
            {
                cache.remove_column(column);
            }
        }
        let (mut chunks, mut bytes) = (cache.chunks(), cache.held_bytes());
        self.held = (chunks, bytes);
        let over = |chunks: usize, bytes: u64| chunks > cache.max_chunks || bytes > cache.max_bytes;
        if !over(chunks, bytes) {
            return;
        }
        // Just under the budget: freeing is spread over the frames that
        // fill the cache, each dropping what its own meshes took (dropping
        // down to 7/8 of the budget at once took the step 20-30 ms in such
        // a frame). Once near the budget, the plan lists the order to free
        // in (listing and sorting every column here each frame cost the
        // step's CPU time 2.8 -> 4.5 ms median in a 1 km/s flight with a
        // 256 MiB budget); a frame that went past it unplanned lists here.
        let least_recent = least_recent.unwrap_or_else(|| {
            let nothing_kept = HashSet::default();
            let keep = self.selection.as_deref().map_or(&nothing_kept, |selection| &selection.keep);
            let max_lod = self.tree.max_lod();
            least_recently_used(&cache.columns, keep, max_lod, |_, cached| cached.last_used >= frame)
                .into_iter()
                .map(|(_, _, column, slot)| (slot, column))
                .collect()
        });
        let mut freed = Vec::new();
        for (slot, column) in least_recent {
            if !over(chunks, bytes) {
                break;
            }
            if let Some(cached) = cache.columns.in_slot(slot, column)
                && cached.last_used < frame
            {
                chunks -= cached.held.chunks;
                bytes -= cached.held.bytes;
                freed.push(column);
            }
        }
        for column in freed {
            cache.remove_column(column);
        }
        self.held = (chunks, bytes);
    }
}

/// The draw constants of `column` when `around` is drawn across its
/// sides: the error it morphs towards and, per side, a skirt as deep as
/// the LOD drawn across that side needs (none next to the same LOD, whose
/// boundary vertices are shared exactly). No side is told to look away
/// from the eye yet ([`ColumnSides::facing`]).
pub(crate) fn chunk_draw<S: VoxelSource + ?Sized>(
    voxels: &S,
    column: ChunkColumn,
    around: &[Across; 4],
    options: DrawOptions,
) -> ChunkDraw {
    let layout = voxels.layout();
    let parent_error = match options.morph {
        MorphRule::Own => voxels.geometric_error(column.lod),
        _ => layout.merge_error(column.lod),
    };
    let mut skirt_depths = [0.0f32; 4];
    if options.skirts {
        for (depth, across) in skirt_depths.iter_mut().zip(around) {
            // A coarser column drawn across (an ancestor of the same-LOD
            // neighbour), else finer ones (or none): the deepest a finer
            // side can need is the depth for the same LOD.
            let other = match *across {
                Across::Drawn(other) if other.lod == column.lod => continue,
                Across::Drawn(other) => other.lod,
                Across::Finer(_) | Across::Nothing => column.lod,
            };
            *depth = skirt_depth(voxels, column.lod, other) as f32;
        }
    }
    ChunkDraw::new(parent_error, skirt_depths)
}

/// What is drawn across one side of a drawn column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Across {
    /// Nothing (out of view).
    Nothing,
    /// The column of the same LOD, or a coarser one holding it.
    Drawn(ChunkColumn),
    /// Columns finer than the same-LOD column there (which is given).
    Finer(ChunkColumn),
}

/// What is drawn across each side of a column, given the columns of its
/// LOD across its sides ([`ColumnSides::across`]), the drawn columns and
/// every ancestor of one (`above`; empty, finer columns and none are not
/// told apart).
pub(crate) fn drawn_across(
    across: &[Option<ChunkColumn>; 4],
    drawn: &HashSet<ChunkColumn>,
    above: &HashSet<ChunkColumn>,
    max_lod: u8,
) -> [Across; 4] {
    across.map(|across| {
        let Some(across) = across else { return Across::Nothing };
        if drawn.contains(&across) {
            return Across::Drawn(across);
        }
        if above.contains(&across) {
            return Across::Finer(across);
        }
        let mut up = across;
        while let Some(next) = parent(up).filter(|_| up.lod < max_lod) {
            up = next;
            if drawn.contains(&up) {
                return Across::Drawn(up);
            }
        }
        Across::Nothing
    })
}

/// Checks every drawn column's meshes against the LODs drawn around it
/// ([`SeamStrategy`]): lowers fallback skirts on both sides of every seam
/// with an unsettled column, as deep as the LODs drawn and meshed for
/// there need (with stitches, no skirt elsewhere), counts the unsettled
/// columns and returns the jobs that mesh the unsettled chunks again for
/// the LODs drawn around them ([`relations_across`]).
///
/// A side with nothing drawn across (out of view) wants a mesh made for
/// the same LOD there: its own faces in the boundary plane. (Taking any
/// mesh there left a chunk's wall open where it rose above a neighbour
/// culled just under the frustum: a crack pixel after a turn.)
#[allow(clippy::too_many_arguments)]
fn settle_seams<S: VoxelSource + ?Sized, H: MeshHandle>(
    voxels: &S,
    cache: &MeshCache<H>,
    draw: &mut DrawList,
    slots: &[Option<usize>],
    arounds: &[[Across; 4]],
    seams: SeamStrategy,
    options: DrawOptions,
    priority: &impl Fn(ChunkColumn) -> f64,
) -> Vec<Job> {
    let max_lod = voxels.layout().max_lod();
    let cached = |index: usize| {
        let column = draw.columns[index].0;
        slots[index].and_then(|slot| cache.columns.in_slot(slot, column)).or_else(|| cache.columns.get(&column))
    };
    let mut masks = Vec::with_capacity(draw.columns.len());
    // Unsettled columns, and every ancestor of one, with the coarsest LOD
    // their meshes were made for.
    let mut unsettled: HashMap<ChunkColumn, u8> = HashMap::default();
    let mut jobs = Vec::new();
    for (index, around) in arounds.iter().enumerate() {
        let column = draw.columns[index].0;
        let relations = relations_across(column, around);
        let mut mask = 0u8;
        let mut coarsest = column.lod;
        for (layer, chunk) in cached(index).into_iter().flat_map(|c| c.chunks.iter()) {
            coarsest = coarsest.max(coarsest_made_for(column.lod, &chunk.made_for));
            let wrong = (0..4).filter(|&s| chunk.made_for[s] != relations[s]).fold(0u8, |m, s| m | 1 << s);
            if wrong != 0 {
                mask |= wrong;
                let key = column.chunk(layer);
                jobs.push(Job {
                    tier: Tier::Reseam,
                    priority: priority(column),
                    key,
                    seams,
                    relations,
                    plug_inside: false,
                });
            }
        }
        if mask != 0 {
            unsettled.insert(column, coarsest);
        }
        masks.push(mask);
    }
    let mut unsettled_above: HashMap<ChunkColumn, u8> = HashMap::default();
    for (&column, &coarsest) in &unsettled {
        let mut c = column;
        while c.lod < max_lod {
            let Some(up) = parent(c) else { break };
            let entry = unsettled_above.entry(up).or_insert(0);
            *entry = (*entry).max(coarsest);
            c = up;
        }
    }
    draw.unsettled = unsettled.len();
    for (index, (column, chunk_draw)) in draw.columns.iter_mut().enumerate() {
        if seams == SeamStrategy::Stitched {
            chunk_draw.skirt_depths = [0.0; 4];
        }
        if !options.skirts {
            continue;
        }
        let own = unsettled.get(column).copied();
        for (side, across) in arounds[index].iter().enumerate() {
            let (other_lod, other) = match *across {
                Across::Nothing => (column.lod, None),
                Across::Drawn(other) => (other.lod, unsettled.get(&other).copied()),
                // The deepest a finer side can need is the same LOD's.
                Across::Finer(same) => (column.lod, unsettled_above.get(&same).copied()),
            };
            if masks[index] & (1 << side) == 0 && other.is_none() {
                continue;
            }
            let coarsest = column.lod.max(other_lod).max(own.unwrap_or(0)).max(other.unwrap_or(0));
            let depth = skirt_depth(voxels, column.lod.min(other_lod), coarsest) as f32;
            chunk_draw.skirt_depths[side] = chunk_draw.skirt_depths[side].max(depth);
        }
    }
    jobs
}

/// The LODs a drawn column's meshes are made for when `around` is drawn
/// across its sides.
pub(crate) fn relations_across(column: ChunkColumn, around: &[Across; 4]) -> SideRelations {
    around.map(|across| match across {
        Across::Drawn(other) if other.lod > column.lod => {
            nebula_lod::NeighborLodRelation::HigherThanNeighbor { lod_diff: other.lod - column.lod }
        }
        Across::Finer(_) => nebula_lod::NeighborLodRelation::LowerThanNeighbor,
        _ => nebula_lod::NeighborLodRelation::Same,
    })
}

/// The columns of `column`'s LOD across its sides (as in
/// `FaceDirection::HORIZONTAL`; none across the edge of the lattice).
pub(crate) fn columns_across(layout: &nebula_voxel::ChunkLayout, column: ChunkColumn) -> [Option<ChunkColumn>; 4] {
    FaceDirection::HORIZONTAL.map(|side| side.face_edge().map(|edge| layout.neighbor(column.chunk(0), edge).column()))
}

/// A column's sides, worked out once per column: the outermost lattice
/// planes of its side walls (the unit normals, towards growing `i`, resp.
/// `j`, of its first and last `i` line and of its first and last `j`
/// line), and the column of the same LOD across each side (as in
/// `FaceDirection::HORIZONTAL`; finding it across a cube edge was a tenth
/// of the selection's time, every drawn column every frame).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ColumnSides {
    i: [nebula_math::DVec3; 2],
    j: [nebula_math::DVec3; 2],
    /// The direction through the middle of its patch, and the cosine and
    /// sine of the largest angle from it to a point of the patch (its
    /// node's bounds, where it had them when cached: read once, not from
    /// the tree every frame).
    directions: Option<(nebula_math::DVec3, f64, f64)>,
    /// The box holding its surface (its node's bounds, as `directions`):
    /// how far from the eye its walls can be.
    extent: Option<(nebula_math::DVec3, nebula_math::DVec3)>,
    pub(crate) across: [Option<ChunkColumn>; 4],
}

/// The least width, in pixels, that a step's wall looking away from the
/// eye must have on screen before it is left out. Left out, the faces on
/// either side of it (the nearer one's silhouette edge, the farther one's
/// edge at the wall's foot) no longer share an edge: they overlap by the
/// wall's width on screen, and the rasteriser snaps each edge's corners
/// on its own (to 1/256 px with 8 sub-pixel bits: lavapipe and desktop
/// GPUs; this is four times that), which can pull them apart. A wall
/// narrower than this (a step that the morph has nearly flattened, or one
/// seen almost edge-on) is drawn: the strip nearer face, wall, farther
/// face shares every edge, and where rounding opens a gap between the two
/// faces it turns the wall's rounded corners to face the eye, so the
/// rasteriser fills exactly that gap with it instead of culling it.
pub const SLIVER_PX: f64 = 1.0 / 64.0;

/// What [`ColumnSides::facing`] needs of the frame and the column's
/// LOD to tell how wide a wall looks on screen.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WallScale {
    /// The eye.
    pub(crate) eye: nebula_math::DVec3,
    /// The frame's pixels per radian and τ.
    pub(crate) screen: nebula_math::ScreenSpace,
    /// Geomorphing on.
    pub(crate) morph: bool,
    /// The edge of a voxel of the column's LOD, metres: the lowest step
    /// a wall of it can have unmorphed.
    pub(crate) voxel_edge: f64,
    /// The error the column morphs towards (`ChunkDraw::parent_error`).
    pub(crate) parent_error: f64,
}

impl ColumnSides {
    pub(crate) fn of(layout: &nebula_voxel::ChunkLayout, column: ChunkColumn, bounds: Option<&NodeBounds>) -> Self {
        let sphere = layout.sphere();
        let size = i64::from(nebula_voxel::CHUNK_SIZE) * layout.voxel_span(column.lod);
        let planes = |along_u: bool, first: i64| {
            [first, first + size].map(|c| sphere.lattice_plane_normal(column.face, along_u, c))
        };
        let across = columns_across(layout, column);
        Self {
            i: planes(true, i64::from(column.x) * size),
            j: planes(false, i64::from(column.y) * size),
            directions: bounds.map(|b| (b.center_direction, b.angular_radius.cos(), b.angular_radius.sin())),
            extent: bounds.map(|b| (b.min, b.max)),
            across,
        }
    }

    /// How far (metres) the eye must be behind the plane of a wall of the
    /// column before the wall is left out, for the walls the morph keeps
    /// at least a voxel tall and for those it flattens (and the faces
    /// looking down): a wall at distance D whose plane is d from the eye
    /// is seen at an angle whose sine is d/D, and its step, at least a
    /// voxel δ of the LOD tall (times the morph factor μ where the morph
    /// flattens it), is at least (μ·)δ·K·d/D² pixels wide; D and μ taken
    /// at the farthest point of the column's box. `None` where the extent
    /// is unknown; +∞ for the flattening walls where μ may be 0 (nothing
    /// of them is left out).
    fn wall_margins(&self, scale: &WallScale) -> Option<(f64, f64)> {
        const MARGIN_M: f64 = 1e-3;
        let (low, high) = self.extent?;
        let eye = scale.eye;
        let farthest = (eye - low).abs().max((high - eye).abs()).length();
        let mu = if scale.morph && scale.parent_error.is_finite() {
            scale.screen.morph_factor(scale.parent_error, farthest)
        } else {
            1.0
        };
        let steady = (SLIVER_PX * farthest * farthest / (scale.voxel_edge * scale.screen.k())).max(MARGIN_M);
        Some((steady, if mu > 0.0 { steady / mu } else { f64::INFINITY }))
    }

    /// Which sides to leave out (bit `FaceDirection as usize`), the radial
    /// faces looking down among them where the column's faces lie under
    /// `top` (metres from the centre) and its patch's directions are
    /// known.
    ///
    /// A wall looking towards +i lies in the plane through the planet
    /// centre of its lattice line `i = c` and faces the eye only when the
    /// eye is on that plane's +i side; the column's walls lie in the planes
    /// from its first to its last line, a pencil about one axis, so the eye
    /// is behind all of them when it is behind the two outermost. A side's
    /// walls are left out when the eye is behind them by
    /// [`Self::wall_margins`], so that every wall left out is at least
    /// [`SLIVER_PX`] wide on screen (a millimetre at least): those the
    /// morph keeps a voxel tall by the first margin, those it flattens by
    /// the second. A wall looking away by less is drawn, and the
    /// rasteriser culls it unless its rounded corners turn it to the eye,
    /// which they do exactly where the faces either side of it would open
    /// a gap (`ChunkDraw::hidden_sides`).
    ///
    /// A face looking down (a ceiling, an overhang's underside) at a
    /// point v with normal −n (n within the patch's directions: its
    /// corners are on one radial layer) faces the eye only when eye·n <
    /// v·n ≤ top: an eye above `top` by the flattening margin in every
    /// direction of the patch sees none. (Faces looking up are never left
    /// out: stitched seams' zero-area zips lie in their range.)
    pub(crate) fn facing(&self, scale: &WallScale, top: Option<f64>) -> SideFacing {
        let Some((steady, flattening)) = self.wall_margins(scale) else {
            return SideFacing::NOTHING_HIDDEN;
        };
        let eye = scale.eye;
        let mut facing = SideFacing::NOTHING_HIDDEN;
        for (planes, positive, negative) in
            [(self.i, FaceDirection::PosX, FaceDirection::NegX), (self.j, FaceDirection::PosZ, FaceDirection::NegZ)]
        {
            // How far the eye is behind the outermost planes of the walls
            // looking towards `positive` (in front, for `negative`): the
            // least of the two.
            let [a, b] = planes.map(|normal| -eye.dot(normal));
            for (bit, behind) in [(1 << positive as u8, a.min(b)), (1 << negative as u8, -a.max(b))] {
                if behind > steady {
                    facing.hidden |= bit;
                }
                if behind > flattening {
                    facing.hidden_flattening |= bit;
                }
            }
        }
        if let (Some((centre, cos_radius, sin_radius)), Some(top)) = (self.directions, top) {
            // |eye|·cos(θ + ρ), θ the eye's angle from the middle and ρ the
            // patch's angular radius: the least eye·n over the patch (no
            // trigonometry every frame for every column).
            let along = eye.dot(centre);
            let across = (eye.length_squared() - along * along).max(0.0).sqrt();
            if along * cos_radius - across * sin_radius > top + flattening {
                facing.hidden |= 1 << FaceDirection::NegY as u8;
            }
        }
        facing
    }
}

/// A column's sides as a frame draws them ([`ColumnSides::facing`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SideFacing {
    /// Left out (`ChunkDraw::hidden_sides`).
    pub(crate) hidden: u8,
    /// Of the walls, the faces the morph flattens left out too
    /// (`ChunkDraw::hidden_flattening`).
    pub(crate) hidden_flattening: u8,
}

impl SideFacing {
    /// Nothing left out: where nothing is known of the column or its
    /// extent.
    pub(crate) const NOTHING_HIDDEN: Self = Self { hidden: 0, hidden_flattening: 0 };
}

/// Why a [`Streamer`] could not start or take new voxels.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StreamError {
    /// Bad LOD settings or camera, or the source refused a node.
    #[error(transparent)]
    Lod(#[from] LodError),
    /// A face root could not be meshed.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The voxel source refused a column.
    #[error(transparent)]
    Voxel(#[from] nebula_voxel::VoxelError),
    /// The voxel source or the mesher panicked on a face root (meshed
    /// before the first frame, so nothing can stand in for it).
    #[error("meshing the face root {key:?} panicked: {message}")]
    Panicked {
        /// The root chunk.
        key: ChunkKey,
        /// The panic's message.
        message: String,
    },
    /// The meshing thread pool could not start.
    #[error("the meshing threads could not start: {0}")]
    Threads(String),
}

/// The most frames ahead the LOD thread is asked to plan for
/// ([`predict`]): a plan that takes longer is not waited for past what its
/// margin covers.
const MAX_PLAN_LATENCY: u64 = 8;

/// Sets each drawn column's [`ChunkDraw::hidden_stubs`] by the meshes held
/// now: a column whose chunks are all plugged inside with no stub exposed
/// ([`LoadedChunk::plugged_inside`], [`LoadedChunk::stubs_exposed`]) leaves
/// out its stubs towards each side whose same-LOD neighbour is drawn so
/// too. A stub may run through every layer of the two columns (they plug
/// the layers shared radially, so a pocket in a side's layers reaches up
/// and down; a layer a column does not hold is rock, sky or sealed caves),
/// so the rule goes by whole columns, and a pocket that is no stub to the
/// chunk holding it but reaches the layer above or below
/// ([`LoadedChunk::pockets_beyond`]) keeps the stubs of both columns drawn
/// where either holds that layer (a chunk there may see its part of the
/// pocket as a stub). Called whenever the meshes drawn may have changed (a
/// new draw list, meshes collected): a neighbour meshed open draws its
/// side's stubs again the frame its mesh is drawn.
fn close_stubs<H: MeshHandle>(
    layout: &nebula_voxel::ChunkLayout,
    columns: &ColumnStore<H>,
    draw: &mut DrawList,
    slots: &[Option<usize>],
) {
    let cached: Vec<Option<&CachedColumn<H>>> = draw
        .columns
        .iter()
        .zip(slots)
        .map(|((column, _), slot)| slot.and_then(|slot| columns.in_slot(slot, *column)))
        .collect();
    // Whether a pocket of one of `from`'s chunks reaches a layer `into`
    // holds.
    let reaches = |from: &CachedColumn<H>, into: &CachedColumn<H>| {
        from.chunks.iter().any(|(layer, chunk)| {
            let [up, down] = chunk.pockets_beyond;
            (up && into.chunks.contains(layer + 1)) || (down && into.chunks.contains(layer - 1))
        })
    };
    let closed: Vec<bool> = cached
        .iter()
        .map(|cached| {
            // Every layer it draws held (one awaited is surface the eye
            // may see), plugged inside, none exposed.
            cached.is_some_and(|cached| {
                cached.missing == 0
                    && cached.chunks.iter().next().is_some()
                    && cached.chunks.iter().all(|(_, chunk)| chunk.plugged_inside && !chunk.stubs_exposed)
                    && !reaches(cached, cached)
            })
        })
        .collect();
    let index_of = |column: ChunkColumn| draw.columns.binary_search_by_key(&column, |&(c, _)| c).ok();
    let hidden: Vec<u8> = draw
        .columns
        .iter()
        .enumerate()
        .map(|(n, &(column, _))| {
            let Some(own) = cached[n].filter(|_| closed[n]) else { return 0 };
            FaceDirection::HORIZONTAL.into_iter().fold(0, |hidden, side| {
                let across = side
                    .face_edge()
                    .and_then(|edge| index_of(layout.neighbor(column.chunk(0), edge).column()))
                    .filter(|&m| closed[m])
                    .and_then(|m| cached[m]);
                match across {
                    Some(other) if !reaches(own, other) && !reaches(other, own) => hidden | 1 << side as u8,
                    _ => hidden,
                }
            })
        })
        .collect();
    for ((_, chunk_draw), hidden) in draw.columns.iter_mut().zip(hidden) {
        chunk_draw.hidden_stubs = hidden;
    }
}

/// Which sides of each drawn column look away from `eye` (`scale`: the
/// frame's screen-space constants and whether it morphs), into the draw
/// list (`slots`: each column's cache slot, in its order).
fn face_walls<H: MeshHandle>(
    voxels: &dyn VoxelSource,
    columns: &ColumnStore<H>,
    draw: &mut DrawList,
    slots: &[Option<usize>],
    eye: nebula_math::DVec3,
    (screen, morph): (nebula_math::ScreenSpace, bool),
) {
    for ((column, chunk_draw), slot) in draw.columns.iter_mut().zip(slots) {
        let cached = slot.and_then(|slot| columns.in_slot(slot, *column));
        let scale = WallScale {
            eye,
            screen,
            morph,
            voxel_edge: voxels.layout().voxel_edge(column.lod),
            parent_error: chunk_draw.parent_error,
        };
        // A column not cached (none drawn) draws every side.
        let facing = match cached.or_else(|| columns.get(column)) {
            Some(cached) => cached.sides.facing(&scale, cached.top_radius(voxels.layout())),
            None => SideFacing::NOTHING_HIDDEN,
        };
        chunk_draw.hidden_sides = facing.hidden;
        chunk_draw.hidden_flattening = facing.hidden_flattening;
    }
}

/// The camera `frames` frames on (at least one) if it moves and turns
/// each frame as from `previous` to `current`, the margin a cull for it
/// needs to cover the camera that comes (3° of turn and half the steps,
/// at least a metre, of error) and the turn of one frame, radians. A step
/// more than four times the one before (`last_step`, plus 10 m) is a jump
/// (a teleport, a new view), not a motion to go on with: the camera is
/// expected to stay.
fn predict(previous: &Camera, current: &Camera, last_step: f64, frames: u64) -> (Camera, CullMargin, f64) {
    let step = current.position - previous.position;
    if step.length() > 4.0 * last_step + 10.0 {
        return (*current, CullMargin { angle: 3f64.to_radians(), distance: 1.0 }, 0.0);
    }
    let (before, now) = (previous.forward.normalize_or_zero(), current.forward.normalize_or_zero());
    let turn = if before == nebula_math::DVec3::ZERO || now == nebula_math::DVec3::ZERO {
        nebula_math::DQuat::IDENTITY
    } else {
        nebula_math::DQuat::from_rotation_arc(before, now)
    };
    let mut next = *current;
    for _ in 0..frames.max(1) {
        next = Camera {
            position: next.position + step,
            forward: turn * next.forward,
            up: turn * next.up,
            aspect: current.aspect,
        };
    }
    let distance = (0.5 * step.length() * frames.max(1) as f64).max(1.0);
    (next, CullMargin { angle: 3f64.to_radians(), distance }, turn.angle_between(nebula_math::DQuat::IDENTITY))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mesh handle of a fixed size.
    struct Bytes(u64);

    impl MeshHandle for Bytes {
        fn bytes(&self) -> u64 {
            self.0
        }
    }

    /// A cache holding `columns` (layers 0 to 2 each, no meshes yet).
    fn cache_of(columns: &[ChunkColumn], one_choice_per_group: bool) -> MeshCache<Bytes> {
        let planet = nebula_voxel::ProceduralPlanet::new(nebula_voxel::PlanetSettings::small(1)).unwrap();
        let mut cache = MeshCache {
            columns: Arc::default(),
            held: Held::default(),
            keep_cpu: false,
            prefetch: false,
            free_after_frames: 300,
            max_chunks: 100_000,
            max_bytes: u64::MAX,
            max_upload_bytes: 1,
            stale: HashMap::default(),
            gained: HashSet::default(),
            required: HashMap::default(),
            released: false,
            one_choice_per_group,
        };
        for &column in columns {
            cache.columns_mut().get_or_insert_with(column, || CachedColumn {
                column,
                layers: vec![0, 1, 2],
                chunks: LayerMeshes::default(),
                missing: 3,
                held: Held::default(),
                last_used: 0,
                sides: ColumnSides::of(planet.layout(), column, None),
                pending: Vec::new(),
            });
        }
        cache
    }

    /// A mesh plugged inside or not, that filled dark air or not.
    fn mesh(plugged_inside: bool, dark_air_plugged: bool) -> LoadedChunk<Bytes> {
        LoadedChunk {
            handle: Bytes(1_000),
            surface_triangles: [0; nebula_meshing::SURFACE_PARTS],
            skirt_triangles: [0; 4],
            cpu: None,
            made_for: SAME_ALL_ROUND,
            lowest_radius: 0.0,
            dark_air_plugged,
            plugged_inside,
            stubs_exposed: false,
            pockets_beyond: [false; 2],
        }
    }

    #[test]
    fn a_plug_group_plugged_inside_is_drawn_open_in_all_its_chunks_at_once() {
        // Column a's layers 0 and 1 plugged inside, their dark air filled
        // (each plugs the layers it shares with the other), layer 2
        // plugged inside with nothing to fill (the same mesh open); column
        // b, beside it in its plug group, layer 0 plugged inside (it plugs
        // the layers it shares with a); column c, of another group,
        // plugged inside too. Meshed open chunk by chunk: the open meshes
        // wait, the group drawn plugged; with the last, all are drawn.
        // Layer 2's mesh stands with either, c's stays.
        let a = ChunkColumn { face: CubeFace::PosZ, lod: 0, x: 5, y: 4 };
        let b = ChunkColumn { x: 6, ..a };
        let c = ChunkColumn { x: 8, ..a };
        let planet = nebula_voxel::ProceduralPlanet::new(nebula_voxel::PlanetSettings::small(1)).unwrap();
        assert!(nebula_meshing::plug_group_across(planet.layout(), a, FaceDirection::PosX));
        assert!(!nebula_meshing::plug_group_across(planet.layout(), ChunkColumn { x: 7, ..a }, FaceDirection::PosX));
        let drawn_choices = |cache: &MeshCache<Bytes>, column: ChunkColumn| -> Vec<Option<bool>> {
            cache.columns.get(&column).unwrap().chunks.iter().map(|(_, chunk)| plug_choice(chunk)).collect()
        };
        let group_choice = |cache: &MeshCache<Bytes>| group_plug_choice(&cache.columns, a);
        let mut cache = cache_of(&[a, b, c], true);
        for (column, layer, filled) in [(a, 0, true), (a, 1, true), (a, 2, false), (b, 0, true), (c, 0, true)] {
            assert_eq!(cache.insert(column, layer, 1, mesh(true, filled)), vec![(column.chunk(layer), 1)]);
        }
        assert_eq!(drawn_choices(&cache, a), [Some(true), Some(true), None]);
        assert_eq!(cache.insert(a, 0, 2, mesh(false, false)), vec![], "the first open mesh is drawn");
        assert_eq!(drawn_choices(&cache, a), [Some(true), Some(true), None]);
        assert_eq!(group_choice(&cache), Some(true));
        assert_eq!(cache.held, cache.recount(), "a mesh held back is counted");
        assert_eq!(cache.held.chunks, 6);
        // Made plugged again (the eye went back): drawn, the open one dropped.
        assert_eq!(cache.insert(a, 0, 3, mesh(true, true)), vec![(a.chunk(0), 3)]);
        assert!(cache.columns.get(&a).unwrap().pending.is_empty());
        assert_eq!((cache.held, cache.held.chunks), (cache.recount(), 5));
        // All three meshed open: drawn together, the other group's kept.
        assert_eq!(cache.insert(a, 1, 4, mesh(false, false)), vec![]);
        assert_eq!(cache.insert(b, 0, 5, mesh(false, false)), vec![]);
        let mut drawn = cache.insert(a, 0, 6, mesh(false, false));
        drawn.sort_unstable();
        assert_eq!(drawn, vec![(a.chunk(0), 6), (a.chunk(1), 4), (b.chunk(0), 5)]);
        assert_eq!(drawn_choices(&cache, a), [Some(false), Some(false), None]);
        assert_eq!((drawn_choices(&cache, b), drawn_choices(&cache, c)), (vec![Some(false)], vec![Some(true)]));
        assert_eq!(group_choice(&cache), Some(false));
        assert_eq!((cache.held, cache.held.chunks), (cache.recount(), 5));
        // A mesh held back goes with its chunk.
        assert_eq!(cache.insert(a, 1, 7, mesh(true, true)), vec![]);
        cache.remove(a.chunk(1));
        assert!(cache.columns.get(&a).unwrap().pending.is_empty());
        assert_eq!((cache.held, cache.held.chunks), (cache.recount(), 4));
        // Released when what it waits for goes: a's plugged layer 0 no
        // longer among its layers, layer 1's open mesh is drawn.
        let mut cache = cache_of(&[a], true);
        for layer in [0, 1] {
            cache.insert(a, layer, 1, mesh(true, true));
        }
        assert_eq!(cache.insert(a, 1, 2, mesh(false, false)), vec![]);
        cache.retain_layers(a, |layer| layer != 0);
        assert_eq!(drawn_choices(&cache, a), [Some(false)]);
        assert!(cache.columns.get(&a).unwrap().pending.is_empty());
        assert_eq!((cache.held, cache.held.chunks), (cache.recount(), 1));
        // And when the column it waits for is freed: b's plugged mesh
        // gone with b, a's open one is drawn.
        let mut cache = cache_of(&[a, b], true);
        for column in [a, b] {
            cache.insert(column, 0, 1, mesh(true, true));
        }
        assert_eq!(cache.insert(a, 0, 2, mesh(false, false)), vec![]);
        cache.remove_column(b);
        assert_eq!(drawn_choices(&cache, a), [Some(false)]);
        assert_eq!((cache.held, cache.held.chunks), (cache.recount(), 1));
        // The control: each mesh drawn as it comes draws the group with
        // both choices.
        let mut cache = cache_of(&[a, b], false);
        for column in [a, b] {
            cache.insert(column, 0, 1, mesh(true, true));
        }
        cache.insert(a, 0, 2, mesh(false, false));
        assert_eq!((drawn_choices(&cache, a), drawn_choices(&cache, b)), (vec![Some(false)], vec![Some(true)]));
    }

    fn job(priority: f64, x: u32, layer: i32) -> Job {
        Job {
            tier: Tier::View,
            priority,
            key: ChunkKey { face: CubeFace::PosZ, lod: 0, x, y: 0, layer },
            seams: SeamStrategy::default(),
            relations: SAME_ALL_ROUND,
            plug_inside: false,
        }
    }

    #[test]
    fn a_worker_passes_over_the_chunks_of_a_column_in_hand() {
        // Column 1's two layers first, then column 2's.
        let mut queue: BinaryHeap<Job> = [job(3.0, 1, 0), job(3.0, 1, 1), job(2.0, 2, 0)].into_iter().collect();
        let mut in_hand = ColumnsInHand::default();
        let first = in_hand.take(&mut queue).expect("a job");
        assert_eq!(first.key.column(), job(3.0, 1, 0).key.column());
        // The second worker leaves column 1's other layer for later.
        let second = in_hand.take(&mut queue).expect("a job");
        assert_eq!(second.key, job(2.0, 2, 0).key);
        assert_eq!(queue.len(), 1, "column 1's other layer stays queued");
        // Every job left is of a column in hand: the top one is taken.
        let third = in_hand.take(&mut queue).expect("a job");
        assert_eq!(third.key.column(), first.key.column());
        assert!(in_hand.take(&mut queue).is_none());
        // Put down, a column is free again.
        for taken in [first, second, third] {
            in_hand.put_down(taken.key.column());
        }
        assert!(in_hand.0.is_empty());
        queue.push(job(1.0, 1, 2));
        queue.push(job(0.5, 3, 0));
        assert_eq!(in_hand.take(&mut queue).map(|job| job.key.x), Some(1), "column 1 put down: by priority");
    }

    #[test]
    fn a_view_chunk_of_a_column_in_hand_goes_before_prefetching() {
        let prefetch = Job { tier: Tier::Prefetch, ..job(9.0, 4, 0) };
        let mut queue: BinaryHeap<Job> = [job(1.0, 1, 0), job(1.0, 1, 1), prefetch].into_iter().collect();
        let mut in_hand = ColumnsInHand::default();
        in_hand.take(&mut queue).expect("a job");
        let second = in_hand.take(&mut queue).expect("a job");
        assert_eq!(second.tier, Tier::View, "the view's last chunk, not prefetching");
        assert_eq!(queue.pop().map(|job| job.tier), Some(Tier::Prefetch));
    }
}
