//! The frame's selection (see the [`stream`](crate::stream) module docs):
//! what to draw, how deep each drawn side's skirt hangs and what to mesh
//! next, worked out as a [`Plan`] from a frozen view of the streamer (its
//! tree, its cached columns, the edits it awaits), so that the LOD thread
//! can make it while the game draws the frame before, and the frame thread
//! only applies it ([`Streamer::update`](crate::stream::Streamer::update)).
//!
//! A plan made ahead is made for a predicted eye: whatever depends on
//! where the eye is holds for every eye within a margin of it (the horizon
//! hides only what it hides from all of them, the sea only when all of them
//! are above it), and the walls that look away from the eye are told by
//! the frame thread, for the eye that came.

use std::cell::{Cell, RefCell};
use std::time::Instant;

use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use nebula_lod::{Camera, CullMargin, Frustum, Horizon, LodTree, NodeBounds, TerrainHorizon, children, parent};
use nebula_math::{DVec3, FaceEdge};
use nebula_voxel::{ChunkColumn, ChunkKey, LayerView, VoxelSource};

use crate::seams::{SAME_ALL_ROUND, SeamStrategy, side_relations};
use crate::stream::{
    Across, CachedColumn, ColumnStore, DrawList, DrawOptions, Failure, Job, MAX_QUEUED_JOBS, MAX_SEA_BED_MEMO,
    MeshHandle, OpaqueSea, PREFETCH_MAX_AGE_FRAMES, PREFETCH_REFRESH_FRAMES, STAND_IN_LEVEL_STEP, Tier, chunk_draw,
    column_layers, drawn_across, group_plug_choice, plug_choice, relations_across,
};

/// How much wider than the camera's own a plan made ahead for a predicted
/// camera draws its view at least, degrees (and a tenth of the eye's
/// margin, metres): the camera that came was up to about half a degree and
/// a few metres off the prediction in a 1 km/s flight at 10 frames a
/// second. The plan cannot serve a camera that sees past it (the frame
/// thread plans again), and the wider, the more is drawn out of sight. A
/// turning camera whose plans take frames to make gets the turn of those
/// frames more ([`SelectSettings::view_angle`]), so that the plan serves
/// them while the next is made.
pub(crate) const PLANNED_VIEW_ANGLE_DEGREES: f64 = 1.0;

/// What the selection keeps from frame to frame: moved to the LOD thread
/// with each request for a plan and back with the plan.
#[cfg_attr(test, derive(Clone))]
pub(crate) struct Selection {
    /// Sets filled each frame, kept for their allocations.
    scratch: SelectScratch,
    /// Columns known to lie under the streamer's sea, or not.
    pub(crate) under_sea: HashMap<ChunkColumn, bool>,
    /// Prefetch jobs not done yet, from the last prefetch refresh.
    pub(crate) prefetch_jobs: Vec<Job>,
    /// Frame of the last prefetch refresh (0: none yet, or asked again),
    /// and whether the tree changed since.
    pub(crate) prefetched_at: u64,
    pub(crate) tree_changed: bool,
    /// What the last prefetch refresh keeps: freed last, never for age.
    pub(crate) keep: HashSet<ChunkColumn>,
    /// Whether the last selection asked for meshes of the view:
    /// prefetching waits until it does not.
    pub(crate) view_busy: bool,
    /// Columns' tight tops ([`VoxelSource::surface_top_radius`]), asked
    /// for those the ground in front might hide.
    pub(crate) tops: HashMap<ChunkColumn, f64>,
    /// Prefetch-only plans ([`plan_prefetch`]) queue no job: a test breaks
    /// them so to see the full plan made beside each catch it.
    #[cfg(test)]
    pub(crate) prefetch_plans_queue_nothing: bool,
    /// Milliseconds the LOD thread sleeps before each update it is asked
    /// for: a test makes its plans slow so to see frames drawn meanwhile.
    #[cfg(test)]
    pub(crate) plan_delay_ms: u64,
    /// Meshes plugged far away are never made again whole: a test breaks
    /// the streamer so to see its check fail ([`plugs_far`]).
    #[cfg(test)]
    pub(crate) plugs_kept: bool,
}

impl Selection {
    /// Whether this state asks nothing of the next plan by itself: no
    /// view work to wait for, and with prefetching, no tree change to make
    /// the prefetch set for again.
    pub(crate) fn is_still(&self, settings: &SelectSettings) -> bool {
        !(self.view_busy || settings.prefetch && self.tree_changed)
    }

    /// Before the first frame: the prefetch set is made once the view is
    /// meshed.
    pub(crate) fn new() -> Self {
        Self {
            scratch: SelectScratch::default(),
            under_sea: HashMap::default(),
            tops: HashMap::default(),
            prefetch_jobs: Vec::new(),
            prefetched_at: 0,
            tree_changed: true,
            keep: HashSet::default(),
            view_busy: true,
            #[cfg(test)]
            prefetch_plans_queue_nothing: false,
            #[cfg(test)]
            plan_delay_ms: 0,
            #[cfg(test)]
            plugs_kept: false,
        }
    }
}

/// The sets [`plan`] fills each frame.
#[derive(Default)]
#[cfg_attr(test, derive(Clone))]
struct SelectScratch {
    /// Stand-ins drawn for leaves not ready.
    ancestors: HashSet<ChunkColumn>,
    /// Columns drawn for hidden leaves.
    hidden_tops: HashSet<ChunkColumn>,
    /// The columns drawn.
    drawn_set: HashSet<ChunkColumn>,
    /// Columns whose jobs are listed.
    seen: HashSet<ChunkColumn>,
    /// The column a hidden leaf under each of these parents is drawn as
    /// (`None`: the parent is not hidden, the leaf is drawn itself).
    climbs: HashMap<ChunkColumn, Option<ChunkColumn>>,
    /// The nearest ready ancestor of the leaves under each of these
    /// parents that are not ready (`None`: a hole).
    stand_in_climbs: HashMap<ChunkColumn, Option<ChunkColumn>>,
}

/// The streamer's settings a plan is made with, and the eye it is made
/// for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SelectSettings {
    /// The frame the plan is for.
    pub(crate) frame: u64,
    pub(crate) view: LayerView,
    pub(crate) seams: SeamStrategy,
    pub(crate) sea: Option<OpaqueSea>,
    pub(crate) options: DrawOptions,
    /// [`MeshCache::prefetch`](crate::stream::MeshCache::prefetch).
    pub(crate) prefetch: bool,
    /// Whether the cache had room to prefetch after the last frame's
    /// frees.
    pub(crate) room_to_prefetch: bool,
    /// [`MeshCache::free_after_frames`](crate::stream::MeshCache::free_after_frames).
    pub(crate) free_after_frames: u64,
    /// Whether the cache was near its budget after the last frame's frees
    /// (the plan then lists what to free first, should this frame's
    /// meshes take it past).
    pub(crate) near_budget: bool,
    /// The camera the plan is made for, and how far from its eye the eye
    /// it is drawn from may be, metres (0: made for the camera that came).
    pub(crate) camera: Camera,
    pub(crate) eye_margin: f64,
    /// How much wider than the camera's own the view planned is, radians,
    /// where `eye_margin` is not 0 ([`PLANNED_VIEW_ANGLE_DEGREES`] or more).
    pub(crate) view_angle: f64,
    /// Whether far columns' tops may be sampled
    /// ([`VoxelSource::surface_top_radius`], tens of microseconds each, up
    /// to [`NEW_TOPS_PER_PLAN`]): on the LOD thread, not on the frame
    /// thread (whose plan also starts without the thread's memo of them),
    /// unless there is no LOD thread.
    pub(crate) sample_tops: bool,
}

/// What a plan is made from: the streamer as it was after the last frame.
pub(crate) struct SelectInput<'a, S: ?Sized, H> {
    pub(crate) voxels: &'a S,
    pub(crate) tree: &'a LodTree,
    pub(crate) columns: &'a ColumnStore<H>,
    /// Drawn chunks an edit changed, and the voxel generation awaited.
    pub(crate) stale: &'a HashMap<ChunkKey, u64>,
    /// Of those, the layers a change of view added.
    pub(crate) gained: &'a HashSet<ChunkKey>,
    /// Chunks whose meshing failed.
    pub(crate) failed: &'a HashMap<ChunkKey, Failure>,
    pub(crate) settings: SelectSettings,
}

impl<S: ?Sized, H> SelectInput<'_, S, H> {
    /// Whether nothing here or in `selection` asks the next plan for
    /// work by itself: no edit's meshes awaited, no failure to retry, and
    /// the selection still ([`Selection::is_still`]).
    pub(crate) fn asks_nothing(&self, selection: &Selection) -> bool {
        self.stale.is_empty() && self.gained.is_empty() && self.failed.is_empty() && selection.is_still(&self.settings)
    }
}

/// A frame's selection, to apply to the streamer it was made from.
pub(crate) struct Plan<H> {
    /// What to draw: skirts for the LODs drawn around each column, no
    /// back sides told yet.
    pub(crate) draw: DrawList,
    /// The cache slot of each drawn column, in the draw list's order.
    pub(crate) slots: Vec<Option<usize>>,
    /// What is drawn across each side of each drawn column (only with a
    /// seam strategy that meshes for the neighbours).
    pub(crate) arounds: Vec<[Across; 4]>,
    /// Cached columns drawn or wanted this frame, by slot.
    pub(crate) used: Vec<(usize, ChunkColumn)>,
    /// Columns wanted and not in the cache yet, with their layers read.
    pub(crate) new_columns: Vec<CachedColumn<H>>,
    /// Chunks awaited after an edit in columns no longer drawn: dropped,
    /// meshed again when needed.
    pub(crate) dropped_stale: Vec<ChunkKey>,
    /// Meshing jobs, the most urgent [`MAX_QUEUED_JOBS`] (those of failed
    /// chunks waiting for their retry left out).
    pub(crate) jobs: Vec<Job>,
    /// Failed chunks no longer asked for: forgotten.
    pub(crate) forget_failed: Vec<ChunkKey>,
    /// The bounds of leaves in view that the plan draws nothing for: those
    /// the planned view does not hold, and those at its edge not meshed
    /// with no stand-in near. It cannot serve a camera that sees one.
    pub(crate) unseen: Vec<NodeBounds>,
    /// Columns out of use for a while (listed every 10 frames): freed.
    pub(crate) aged: Vec<(usize, ChunkColumn)>,
    /// Near the budget, every column not used this frame, in the order to
    /// free them should the cache be past its budget
    /// ([`least_recently_used`]).
    pub(crate) least_recent: Option<Vec<(usize, ChunkColumn)>>,
    /// Milliseconds the plan took to make.
    pub(crate) millis: f64,
}

/// Why a visible leaf is drawn as a coarser ancestor of its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Hidden {
    /// It is not: drawn as itself.
    No,
    /// Behind the terrain's horizon.
    BehindHorizon,
    /// Under the opaque sea.
    UnderSea,
}

/// A drawn column's slot in the cache and lowest surface radius (`None`:
/// behind the horizon), as the leaf loop finds them. Small on purpose: the
/// drawn list is sorted and filtered every frame, and moving the column's
/// sides with it was a fifth of the selection's time.
type KnownDraw = (usize, Option<f64>);

/// A job's priority: its column's projected voxel edge (largest first:
/// coarse-first and nearest-first), from its bounds where known.
pub(crate) fn job_priority<S: VoxelSource + ?Sized>(
    voxels: &S,
    tree: &LodTree,
    eye: DVec3,
    column: ChunkColumn,
    bounds: Option<&NodeBounds>,
) -> f64 {
    let distance = bounds.or_else(|| tree.node_bounds(column)).map_or(f64::INFINITY, |b| b.distance(eye)).max(1e-3);
    voxels.layout().voxel_edge(column.lod) * tree.screen_space().k() / distance
}

/// Whether a new mesh of `column` plugs its dark cave air inside it
/// ([`MeshOptions::plug_dark_air_inside`](nebula_meshing::MeshOptions::plug_dark_air_inside))
/// with the eye at `eye`: at a LOD `seams` does not plug by itself (LOD 0
/// for streaming), where the planet around a narrow lens's focus is drawn
/// coarser ([`LodTree::surround_split_ratio`] past the merge, 1 / (1 −
/// hysteresis)). A 12° lens draws LOD 0 kilometres away; there its caves
/// show as a 60° view shows them from LOD 1 at that distance, through
/// their mouths. A view at least as wide as the surround never draws LOD 0
/// that far: its meshes are never plugged so.
pub(crate) fn plugs_far(tree: &LodTree, seams: SeamStrategy, column: ChunkColumn, eye: DVec3) -> bool {
    let plugged_from = seams.mesh_options().plug_dark_air_from_lod;
    plugged_from.is_some_and(|lod| column.lod < lod)
        && tree.surround_split_ratio(column, eye).is_some_and(|ratio| ratio * (1.0 - tree.settings().hysteresis) > 1.0)
}

/// Whether the meshes of `column`'s plug group
/// ([`nebula_meshing::plug_group`]) that [`plugs_far`] plugged are made
/// again whole with the eye at `eye`: [`unplug_due`] for one of its
/// columns in the tree (the group's chunks plug the layers they share).
pub(crate) fn group_unplug_due(tree: &LodTree, column: ChunkColumn, eye: DVec3) -> bool {
    nebula_meshing::plug_group(column).any(|c| tree.node_bounds(c).is_some() && unplug_due(tree, c, eye))
}

/// Whether a held mesh of `column` that [`plugs_far`] plugged is made
/// again whole with the eye at `eye`: the surround is drawn at its LOD
/// there (the eye came within the split distance; between it and the
/// merge, meshes stay as they were made, while a narrow lens looks), or
/// the view is no longer narrow (no focus): a wide view draws LOD 0 no
/// farther than the merge, so nowhere plugged.
pub(crate) fn unplug_due(tree: &LodTree, column: ChunkColumn, eye: DVec3) -> bool {
    let merge = 1.0 / (1.0 - tree.settings().hysteresis);
    let due = if tree.focus().is_some() { 1.0 } else { merge };
    tree.surround_split_ratio(column, eye).is_none_or(|ratio| ratio < due)
}

/// Columns whose tight tops a [`Selection`] remembers before it forgets
/// them all (about 5 MB).
const MAX_TOPS_MEMO: usize = 200_000;

/// Tight tops a plan asks the voxel source for at most.
const NEW_TOPS_PER_PLAN: usize = 256;

/// Every this many frames a plan lists the columns out of use for longer
/// than [`SelectSettings::free_after_frames`] (listing them takes a walk
/// over every column held).
const AGING_PERIOD: u64 = 10;

/// Chooses what to draw (see the module docs of [`crate::stream`]), the
/// skirt depth of every drawn side, and the meshing jobs, by priority.
#[allow(clippy::too_many_lines)]
pub(crate) fn plan<S: VoxelSource + ?Sized, H: MeshHandle>(
    input: &SelectInput<'_, S, H>,
    selection: &mut Selection,
) -> Plan<H> {
    let start = Instant::now();
    let SelectInput { voxels, tree, columns, stale, gained, failed, settings } = *input;
    let SelectSettings {
        frame,
        view,
        seams,
        sea,
        options,
        prefetch,
        room_to_prefetch,
        free_after_frames: _,
        near_budget: _,
        camera,
        eye_margin,
        view_angle,
        sample_tops,
    } = settings;
    let eye = camera.position;
    // The view planned for, where it is planned with a margin around the
    // camera: a little wider than the camera's own, so that the camera
    // that comes, a little off the prediction, seldom sees past it.
    let views = (eye_margin > 0.0).then(|| {
        let fov = tree.settings().fov_y_degrees;
        let margin = CullMargin { angle: view_angle, distance: 0.1 * eye_margin };
        (Frustum::new(&camera, fov), Frustum::with_margin(&camera, fov, margin))
    });
    let mut unseen = Vec::new();
    // Stand-ins for leaves at the planned view's edge, and those leaves.
    let mut edge_stand_ins: HashMap<ChunkColumn, Vec<(ChunkColumn, NodeBounds)>> = HashMap::default();
    let layout = voxels.layout();
    let max_lod = layout.max_lod();
    let Selection {
        scratch, under_sea: memo, prefetch_jobs, prefetched_at, tree_changed, keep, view_busy, tops, ..
    } = selection;
    let SelectScratch { ancestors, hidden_tops, drawn_set, seen, climbs, stand_in_climbs } = scratch;
    climbs.clear();
    stand_in_climbs.clear();
    ancestors.clear();
    hidden_tops.clear();
    drawn_set.clear();
    seen.clear();
    let ready = |column: ChunkColumn| columns.get(&column).is_some_and(|c| c.ready(column, stale));
    let holds = |key: ChunkKey| columns.holds(key);
    let mut used = Vec::new();
    // The drawn columns, with their slot and lowest surface radius
    // (`None` behind the horizon) where the leaf loop has them at hand
    // (`None`: looked up when the draw list is made).
    let mut drawn: Vec<(ChunkColumn, Option<KnownDraw>)> = Vec::new();
    // Columns to mesh, with their bounds where the leaf loop has them.
    let mut wanted: Vec<(ChunkColumn, Option<&NodeBounds>)> = Vec::new();
    let priority_within =
        |column: ChunkColumn, bounds: Option<&NodeBounds>| job_priority(voxels, tree, eye, column, bounds);
    let priority = |column: ChunkColumn| priority_within(column, None);
    // The LODs a new mesh is made for: the tree's around a leaf (what
    // will be drawn once the view settles), the same all round for a
    // stand-in; a drawn column's are checked against what is drawn.
    let predicted = |column: ChunkColumn| match seams.meshes_for_neighbours() {
        true => tree.context(column).map_or(SAME_ALL_ROUND, |context| side_relations(&context)),
        false => SAME_ALL_ROUND,
    };
    let (mut holes, mut stand_ins, mut max_levels) = (0, 0, 0u8);
    // Leaves (drawn or wanted) of plug groups holding meshes plugged far
    // away that the eye came near
    // ([`plugs_far`]), with their bounds: meshed again whole, the plugged
    // ones drawn meanwhile. (LODs the strategy plugs by itself stay so.)
    let plugged_from = seams.mesh_options().plug_dark_air_from_lod.unwrap_or(0);
    let mut unplug: Vec<(ChunkColumn, &NodeBounds)> = Vec::new();
    // By plug group: whether it holds a mesh plugged inside and is due to
    // be meshed open.
    let mut unplug_groups: HashMap<ChunkColumn, bool> = HashMap::default();
    let mut group_due = |leaf: ChunkColumn| {
        leaf.lod < plugged_from
            && *unplug_groups
                .entry(nebula_meshing::plug_group_key(leaf))
                .or_insert_with(|| group_plug_choice(columns, leaf) == Some(true) && group_unplug_due(tree, leaf, eye))
    };
    // Leaves behind the terrain's horizon stand for their coarsest ancestor
    // that is hidden too (a few columns where the selection has thousands
    // the eye cannot see), and nothing is drawn for it while what is
    // drawn in front is what the horizon was made of. Where a stand-in
    // covers a leaf whose floor went into it, its coarse surface may dip
    // under that floor and bare what lies behind: those hidden columns
    // meshed are drawn then (`backstops`, below), so what shows through
    // is coarse, never a hole. Hidden from every eye within the margin:
    // the occluder for all of them, its horizon widened.
    let distance = eye.length();
    let occluder = tree.horizon_occluder(voxels, eye, eye_margin);
    let horizon = occluder.map(|r| Horizon::around(eye, eye_margin, r));
    let sphere_hides = |bounds: &NodeBounds| horizon.is_some_and(|h| h.hides(bounds));
    // The same for leaves under an opaque sea, seen from above it.
    let sea = sea.filter(|sea| distance - eye_margin > sea.radius);
    if memo.len() > MAX_SEA_BED_MEMO {
        memo.clear();
    }
    // Whether the sea hides `column`; when `climbing` to it as a stand-in,
    // it must have the sea bed all round too: a coarse stand-in next to a
    // leaf drawn in detail would lower the ground beside that leaf and
    // bare its skirt, which takes the leaf's material (never sea bed at a
    // coast, so no water over it).
    let mut sea_hides = |column: ChunkColumn, climbing: bool| {
        sea.is_some_and(|sea| {
            under_sea(voxels, sea, memo, column, max_lod)
                && (!climbing
                    || FaceEdge::ALL.iter().all(|&edge| {
                        let across = layout.neighbor(column.chunk(0), edge).column();
                        under_sea(voxels, sea, memo, across, max_lod)
                    }))
        })
    };
    // Whether the sea may hide a leaf with `bounds`: the sea hides a column
    // only where its sea bed, or an ancestor's, lies wholly under the
    // hiding radius, so a leaf whose lowest surface lies over it is not
    // hidden; it is not asked (a memo lookup for it and its ancestors each
    // was 7 % of the LOD thread's plan over land).
    let may_be_under_sea = |bounds: &NodeBounds| sea.is_some_and(|sea| bounds.min_radius <= sea.hiding_radius());
    // The visible leaves' cache slots (a lookup is a miss in memory) and
    // whether the planned view holds them, found once for the ground's
    // horizon and the leaf loop below.
    let in_plan = |bounds: &NodeBounds| views.as_ref().is_none_or(|(_, planned)| !planned.excludes(bounds));
    let leaf_slots: Vec<(Option<usize>, bool)> = tree
        .visible_leaves_with_bounds()
        .map(|(leaf, bounds)| (columns.slot(&leaf).map(|(slot, _)| slot), in_plan(bounds)))
        .collect();
    // Leaves behind the ground in front are hidden too: its horizon,
    // bearing by bearing ([`TerrainHorizon`]), is made of the leaves of the
    // planned view (no line of sight in it crosses another's patch), over
    // what is drawn for them: under the opaque sea, the sea (drawn over
    // them whatever is meshed); where a leaf's meshes are all held, the
    // lowest point they draw. A leaf still waiting for its meshes is drawn
    // through a stand-in whose surface is not its own: it hides nothing
    // yet. One meshed before the ground in front hid it (not drawn now)
    // adds nothing either: its floor is under its top, which that ground
    // rises over. So a settled view (every leaf seen meshed, every top
    // sampled: [`DrawList::tops_awaited`]) is meant to hide the same
    // whatever came before; every leaf sizes the horizon's bearing bins
    // for that too. (One case still differs now and then: README, "The
    // ground's own horizon".)
    // The leaves whose meshes' floors the horizon is made of.
    let mut floored = Vec::new();
    let occluders: Vec<(NodeBounds, Option<f64>)> = tree
        .visible_leaves_with_bounds()
        .zip(&leaf_slots)
        .filter(|&((_, b), &(_, planned))| options.terrain_occlusion && planned && !sphere_hides(b))
        .map(|((leaf, b), &(slot, _))| {
            if let Some(sea) = sea.filter(|_| may_be_under_sea(b) && sea_hides(leaf, false)) {
                return (*b, Some(sea.radius));
            }
            let cached = slot.and_then(|slot| columns.in_slot(slot, leaf)).filter(|c| c.ready(leaf, stale));
            let floor = cached.and_then(CachedColumn::drawn_floor);
            if floor.is_some() {
                floored.push(leaf);
            }
            (*b, floor)
        })
        .collect();
    let terrain = TerrainHorizon::new(eye, eye_margin, occluders);
    // A column's bounds are loose far away (they allow for slope over the
    // whole patch): where its lowest surface would be hidden, its top is
    // sampled closer before it is judged seen.
    if tops.len() > MAX_TOPS_MEMO {
        tops.clear();
    }
    // A few hundred new ones a plan at most (each samples 81 heights): the
    // rest wait for the next, drawn in detail meanwhile.
    let (tops, new_tops, tops_awaited) = (RefCell::new(tops), Cell::new(0), Cell::new(0));
    let bounds_behind = |column: ChunkColumn, bounds: &NodeBounds| {
        if sphere_hides(bounds) {
            return true;
        }
        let Some(clearance) = terrain.clearance(bounds) else { return false };
        if clearance.hides(bounds.max_radius) {
            return true;
        }
        let mut tops = tops.borrow_mut();
        let top = match tops.get(&column) {
            Some(&top) => top,
            None if sample_tops && new_tops.get() < NEW_TOPS_PER_PLAN => {
                new_tops.set(new_tops.get() + 1);
                let top = voxels.surface_top_radius(column).unwrap_or(f64::INFINITY);
                tops.insert(column, top);
                top
            }
            None => {
                tops_awaited.set(tops_awaited.get() + 1);
                return false;
            }
        };
        clearance.hides(top)
    };
    let behind = |column: ChunkColumn| tree.node_bounds(column).is_some_and(|b| bounds_behind(column, b));
    // What is drawn for a leaf (with its bounds when known): itself, or
    // its coarsest ancestor hidden too (behind the horizon or under the
    // sea), and why.
    let mut drawn_for = |leaf: ChunkColumn, bounds: Option<&NodeBounds>| -> (ChunkColumn, Hidden) {
        let hidden = if bounds.map_or_else(|| behind(leaf), |b| bounds_behind(leaf, b)) {
            Hidden::BehindHorizon
        } else if bounds.is_none_or(&may_be_under_sea) && sea_hides(leaf, false) {
            Hidden::UnderSea
        } else {
            return (leaf, Hidden::No);
        };
        // Siblings, hidden alike, climb from the same parent: once a frame
        // for all of them.
        let Some(first) = parent(leaf).filter(|_| leaf.lod < max_lod) else { return (leaf, hidden) };
        let mut hides = |column: ChunkColumn| behind(column) || sea_hides(column, true);
        let top = *climbs.entry(first).or_insert_with(|| {
            if !hides(first) {
                return None;
            }
            let mut top = first;
            while let Some(up) = parent(top).filter(|&up| top.lod < max_lod && hides(up)) {
                top = up;
            }
            Some(top)
        });
        (top.unwrap_or(leaf), hidden)
    };
    let (mut behind_horizon, mut under_the_sea) = (0, 0);
    // Meshed columns hidden behind the horizon, drawn only where a
    // stand-in covers a leaf the horizon took a floor from (see above).
    let mut backstops = Vec::new();
    #[cfg(test)]
    let mut behind_horizon_leaves = Vec::new();
    for ((leaf, bounds), &(leaf_slot, planned)) in tree.visible_leaves_with_bounds().zip(&leaf_slots) {
        let (drawn_leaf, hidden) = drawn_for(leaf, Some(bounds));
        // The slot of what is drawn for it: the leaf's, looked up above.
        let own_slot = (drawn_leaf == leaf).then_some(leaf_slot);
        #[cfg(test)]
        if hidden == Hidden::BehindHorizon {
            behind_horizon_leaves.push(leaf);
        }
        let leaf = drawn_leaf;
        match hidden {
            Hidden::No => {}
            Hidden::BehindHorizon => behind_horizon += 1,
            Hidden::UnderSea => under_the_sea += 1,
        }
        // The planned view's edge (what it adds to the camera's own), and
        // what it does not hold (the cull's margin holds it for a camera
        // that comes off the prediction): nothing is drawn or meshed for
        // that, and the plan serves no camera that sees it (hidden from
        // every eye within the margin, none sees it).
        let edge = match &views {
            Some(_) if !planned => {
                if hidden == Hidden::No {
                    unseen.push(*bounds);
                }
                continue;
            }
            Some((own, _)) => own.excludes(bounds),
            None => false,
        };
        if hidden != Hidden::No && !hidden_tops.insert(leaf) {
            continue;
        }
        let slot = match own_slot {
            Some(slot) => slot.and_then(|slot| columns.in_slot(slot, leaf).map(|cached| (slot, cached))),
            None => columns.slot(&leaf),
        };
        if let Some((slot, cached)) = slot
            && cached.ready(leaf, stale)
        {
            // In use even when a stand-in covering it is drawn instead (a
            // sibling is not ready), or not drawn at all (hidden, a
            // backstop): never freed while it is a leaf.
            used.push((slot, leaf));
            if hidden == Hidden::BehindHorizon {
                backstops.push(leaf);
                continue;
            }
            let known = (hidden == Hidden::No).then_some((slot, Some(bounds.min_radius)));
            drawn.push((leaf, known));
            if group_due(leaf) {
                unplug.push((leaf, bounds));
            }
            continue;
        }
        // Hidden and not meshed: meshed for the view all the same, so that
        // a settled view holds every backstop it may need once a stand-in
        // comes. (Not drawn through a meshed ancestor meanwhile: that
        // ancestor would cover ground in view, drawn finer.)
        if hidden == Hidden::BehindHorizon {
            wanted.push((leaf, None));
            continue;
        }
        // A column of a group due, waiting for a layer (meshed open, held
        // back while the group is drawn plugged): the group is meshed
        // open whole all the same.
        if group_due(leaf) {
            unplug.push((leaf, bounds));
        }
        wanted.push((leaf, (hidden == Hidden::No).then_some(bounds)));
        if let Some(finer) = children(leaf)
            && finer.iter().all(|&c| ready(c))
        {
            stand_ins += 1;
            drawn.extend(finer.map(|c| (c, None)));
            continue;
        }
        // The nearest ready ancestor, and the stand-ins on the way up
        // wanted: the same for every sibling, so climbed once a frame from
        // their parent (thousands of leaves wait for meshes at once in a
        // fast flight).
        let climb = |wanted: &mut Vec<_>| {
            let mut ancestor = leaf;
            while ancestor.lod < max_lod {
                let Some(up) = parent(ancestor) else { break };
                ancestor = up;
                if ready(ancestor) {
                    return Some(ancestor);
                }
                if (ancestor.lod - leaf.lod).is_multiple_of(STAND_IN_LEVEL_STEP) {
                    wanted.push((ancestor, None));
                }
            }
            None
        };
        let found = match parent(leaf).filter(|_| leaf.lod < max_lod) {
            Some(first) => *stand_in_climbs.entry(first).or_insert_with(|| climb(&mut wanted)),
            None => climb(&mut wanted),
        };
        // At the planned view's edge, a stand-in is drawn only where it
        // stands for nothing else drawn (below): no detail in view is drawn
        // coarse for a leaf the camera most likely does not see.
        if edge {
            match found.filter(|ancestor| !ancestors.contains(ancestor)) {
                Some(ancestor) => edge_stand_ins.entry(ancestor).or_default().push((leaf, *bounds)),
                None if found.is_none() => unseen.push(*bounds),
                None => stand_ins += 1,
            }
            continue;
        }
        stand_ins += 1;
        if let Some(ancestor) = found {
            max_levels = max_levels.max(ancestor.lod - leaf.lod);
            ancestors.insert(ancestor);
        } else {
            holes += 1;
        }
    }
    // Tops awaited for the view (prefetching asks for more below).
    let tops_awaited = tops_awaited.get();
    // Out of view: every leaf the tree holds (as it would be drawn) and its
    // stand-in STAND_IN_LEVEL_STEP LODs up, meshed after the view's work
    // and kept, so a turn of the camera finds them meshed.
    let refresh = prefetch && refresh_due(*view_busy, *prefetched_at, *tree_changed, frame);
    if refresh {
        *prefetched_at = frame;
        *tree_changed = false;
        let mut kept: HashSet<ChunkColumn> = HashSet::default();
        for leaf in tree.leaf_columns() {
            let (column, _) = drawn_for(leaf, None);
            if kept.insert(column) {
                let mut up = column;
                for _ in 0..STAND_IN_LEVEL_STEP {
                    match parent(up).filter(|_| up.lod < max_lod) {
                        Some(coarser) => up = coarser,
                        None => break,
                    }
                }
                kept.insert(up);
            }
        }
        prefetch_jobs.clear();
        for &column in &kept {
            let layers = match columns.get(&column) {
                Some(cached) => cached.layers.clone(),
                None => column_layers(voxels, tree, column, view),
            };
            let priority = priority(column);
            prefetch_jobs.extend(layers.into_iter().map(|layer| column.chunk(layer)).filter(|&key| !holds(key)).map(
                |key| Job {
                    tier: Tier::Prefetch,
                    priority,
                    key,
                    seams,
                    relations: predicted(column),
                    plug_inside: false,
                },
            ));
        }
        // The most urgent last: meshed jobs come off its end.
        prefetch_jobs.sort_unstable();
        *keep = kept;
    } else if !prefetch {
        prefetch_jobs.clear();
        keep.clear();
    }
    // A drawn ancestor covers everything under it.
    for (ancestor, leaves) in edge_stand_ins.drain() {
        let holds = |column: ChunkColumn| {
            let up = ancestor.lod.checked_sub(column.lod).filter(|&up| up > 0 && up < 32);
            up.is_some_and(|up| {
                column.face == ancestor.face && column.x >> up == ancestor.x && column.y >> up == ancestor.y
            })
        };
        if drawn.iter().any(|&(column, _)| holds(column)) || ancestors.iter().any(|&column| holds(column)) {
            unseen.extend(leaves.iter().map(|&(_, bounds)| bounds));
        } else {
            stand_ins += leaves.len();
            for (leaf, _) in leaves {
                max_levels = max_levels.max(ancestor.lod - leaf.lod);
            }
            ancestors.insert(ancestor);
        }
    }
    // The hidden columns are drawn where a stand-in covers a leaf whose
    // floor the horizon took: it is not what the horizon was made of.
    let backstops_drawn = !ancestors.is_empty() && floored.iter().any(|&leaf| under_any(ancestors, leaf, max_lod));
    if backstops_drawn {
        drawn.extend(backstops.iter().map(|&column| (column, None)));
    }
    let covered = |column: ChunkColumn| under_any(ancestors, column, max_lod);
    if !ancestors.is_empty() {
        drawn.retain(|&(c, _)| !covered(c));
        drawn.extend(ancestors.iter().copied().filter(|&c| !covered(c)).map(|c| (c, None)));
    }
    drawn.sort_unstable_by_key(|&(c, _)| c);
    drawn.dedup_by_key(|&mut (c, _)| c);
    let mut draw = DrawList {
        behind_horizon,
        tops_awaited,
        under_sea: under_the_sea,
        occluder_radius: occluder.unwrap_or(f64::NAN),
        holes,
        stand_ins,
        backstops: if backstops_drawn { backstops.len() } else { 0 },
        max_stand_in_levels: max_levels,
        #[cfg(test)]
        behind_horizon_leaves,
        ..DrawList::default()
    };
    drawn_set.extend(drawn.iter().map(|&(c, _)| c));
    let set = &*drawn_set;
    // With meshes made for their neighbours: every ancestor of a drawn
    // column (a side whose same-LOD neighbour is one meets finer ones).
    let mut above = HashSet::default();
    if seams.meshes_for_neighbours() {
        for &(column, _) in &drawn {
            let mut c = column;
            while let Some(up) = parent(c).filter(|_| c.lod < max_lod) {
                if !above.insert(up) {
                    break;
                }
                c = up;
            }
        }
    }
    let mut arounds = Vec::new();
    let mut slots = Vec::with_capacity(drawn.len());
    let mut min_radius = f64::INFINITY;
    let mut max_lod_diff = 0;
    draw.columns = drawn
        .iter()
        .map(|&(column, known)| {
            let known = known.and_then(|(slot, low)| {
                columns.in_slot(slot, column).map(|cached| (Some(slot), cached.sides.across, low))
            });
            let (slot, across, low) = known.unwrap_or_else(|| {
                let (slot, across) = match columns.slot(&column) {
                    Some((slot, cached)) => {
                        used.push((slot, column));
                        (Some(slot), cached.sides.across)
                    }
                    None => (None, crate::stream::columns_across(layout, column)),
                };
                // The tree's cached bounds; a stand-in the tree merged away
                // asks the source (noise) once here. A coarse chunk drawn
                // behind the horizon is left out: its voxels round the
                // surface far down, and the terrain in front hides it.
                let bounds = tree.node_bounds(column);
                let low = bounds
                    .map(|b| b.min_radius)
                    .or_else(|| voxels.surface_bounds(column).ok().map(|b| b.min_radius))
                    .filter(|_| !bounds.is_some_and(|b| sphere_hides(b) || terrain.hides(b)));
                (slot, across, low)
            });
            if let Some(low) = low {
                min_radius = min_radius.min(low);
            }
            slots.push(slot);
            let around = drawn_across(&across, set, &above, max_lod);
            if seams.meshes_for_neighbours() {
                arounds.push(around);
            }
            for across in around {
                if let Across::Drawn(other) = across {
                    max_lod_diff = max_lod_diff.max(other.lod - column.lod);
                }
            }
            (column, chunk_draw(voxels, column, &around, options))
        })
        .collect();
    draw.min_surface_radius = min_radius;
    draw.max_lod_diff = max_lod_diff;
    // The LODs a drawn column is meshed for: those drawn around it.
    let drawn_relations = |column: ChunkColumn| {
        let index = draw.columns.binary_search_by_key(&column, |&(c, _)| c).ok()?;
        arounds.get(index).map(|around| relations_across(column, around))
    };

    // Jobs: every chunk of a wanted column not meshed and not running, the
    // largest projected voxel first.
    let mut jobs = Vec::new();
    let mut new_columns = Vec::new();
    for (column, bounds) in wanted {
        if !seen.insert(column) {
            continue;
        }
        let priority = priority_within(column, bounds);
        let relations = predicted(column);
        let job =
            |layer| Job { tier: Tier::View, priority, key: column.chunk(layer), seams, relations, plug_inside: false };
        match columns.slot(&column) {
            Some((slot, cached)) => {
                used.push((slot, column));
                jobs.extend(cached.layers.iter().filter(|&&layer| !cached.chunks.contains(layer)).map(|&l| job(l)));
            }
            None => {
                let cached = CachedColumn::new(voxels, tree, column, frame, view);
                jobs.extend(cached.layers.iter().map(|&l| job(l)));
                new_columns.push(cached);
            }
        }
    }
    // Drawn chunks an edit changed go first: the player is looking at
    // them. One no longer drawn is dropped, to be meshed when needed.
    let mut dropped_stale = Vec::new();
    for &key in stale.keys() {
        if !set.contains(&key.column()) {
            dropped_stale.push(key);
            continue;
        }
        let priority = if gained.contains(&key) { priority(key.column()) } else { f64::MAX };
        let relations = drawn_relations(key.column()).unwrap_or_else(|| predicted(key.column()));
        jobs.push(Job { tier: Tier::View, priority, key, seams, relations, plug_inside: false });
    }
    #[cfg(test)]
    if selection.plugs_kept {
        unplug.clear();
    }
    // Every chunk plugged inside of a group due (those of its columns
    // not drawn too: the group is drawn open only once all are), once.
    let mut unplugged_groups = HashSet::default();
    for (leaf, bounds) in unplug {
        if !unplugged_groups.insert(nebula_meshing::plug_group_key(leaf)) {
            continue;
        }
        let priority = priority_within(leaf, Some(bounds));
        for column in nebula_meshing::plug_group(leaf) {
            let Some(cached) = columns.get(&column) else { continue };
            let relations = drawn_relations(column).unwrap_or_else(|| predicted(column));
            // An edited chunk is meshed again by its edit's job (above),
            // with the plug the eye then asks for: one job per chunk.
            let unplugged = cached.chunks.iter().filter(|(layer, chunk)| {
                plug_choice(chunk) == Some(true) && !stale.contains_key(&column.chunk(*layer)) && !cached.pends(*layer)
            });
            jobs.extend(unplugged.map(|(layer, _)| Job {
                tier: Tier::View,
                priority,
                key: column.chunk(layer),
                seams,
                relations,
                plug_inside: false,
            }));
        }
    }
    // Prefetching only while there is room for it: what the view needs is
    // never evicted for it. (A chunk waiting to retry a failure does not
    // hold prefetching up.)
    *view_busy = jobs.iter().any(|job| failed.get(&job.key).is_none_or(|f| f.retry_at <= frame));
    if !*view_busy {
        queue_prefetch(&mut jobs, prefetch_jobs, holds, room_to_prefetch);
    }
    // A chunk that failed waits for its retry; one no longer asked for is
    // forgotten.
    let mut forget_failed = Vec::new();
    if !failed.is_empty() {
        let asked: HashSet<ChunkKey> = jobs.iter().map(|job| job.key).collect();
        forget_failed.extend(failed.keys().filter(|key| !asked.contains(key)));
        jobs.retain(|job| failed.get(&job.key).is_none_or(|f| f.retry_at <= frame));
    }
    keep_most_urgent(&mut jobs);
    let (aged, least_recent) = freeing(input, keep, &used);
    Plan {
        draw,
        slots,
        arounds,
        used,
        new_columns,
        dropped_stale,
        jobs,
        forget_failed,
        unseen,
        aged,
        least_recent,
        millis: start.elapsed().as_secs_f64() * 1e3,
    }
}

/// Whether a column in `ancestors` (a drawn stand-in) lies above
/// `column`, up to `max_lod`.
fn under_any(ancestors: &HashSet<ChunkColumn>, column: ChunkColumn, max_lod: u8) -> bool {
    let mut c = column;
    while c.lod < max_lod {
        let Some(up) = parent(c) else { break };
        c = up;
        if ancestors.contains(&c) {
            return true;
        }
    }
    false
}

/// Cached columns with their slots.
type SlotColumns = Vec<(usize, ChunkColumn)>;

/// Whether a plan made in `frame` makes the prefetch set again, for a
/// selection whose last plan left `view_busy`, `prefetched_at` and
/// `tree_changed` (with prefetching on).
fn refresh_due(view_busy: bool, prefetched_at: u64, tree_changed: bool, frame: u64) -> bool {
    let age = frame.saturating_sub(prefetched_at);
    // Not while the view has work of its own: a cold start or a fast
    // flight spends the frame thread and the workers on what is seen.
    !view_busy
        && (prefetched_at == 0 || (tree_changed && age >= PREFETCH_REFRESH_FRAMES) || age >= PREFETCH_MAX_AGE_FRAMES)
}

/// Adds to `jobs` the next prefetch jobs of `prefetch_jobs` (the most
/// urgent last) not held yet, dropping those at its end already held.
fn queue_prefetch(
    jobs: &mut Vec<Job>,
    prefetch_jobs: &mut Vec<Job>,
    holds: impl Fn(ChunkKey) -> bool,
    room_to_prefetch: bool,
) {
    while prefetch_jobs.last().is_some_and(|job| holds(job.key)) {
        prefetch_jobs.pop();
    }
    if room_to_prefetch {
        // Never more than the queue keeps: making 20,000 jobs to keep
        // 1,024 is the cost its cap removes.
        let next = prefetch_jobs.iter().rev().filter(|job| !holds(job.key));
        jobs.extend(next.take(MAX_QUEUED_JOBS).copied());
    }
}

/// What the frame thread frees after applying a plan that uses `used`
/// (listing and sorting every column held was the step's slowest part in a
/// frame past the budget): every [`AGING_PERIOD`] frames the columns out of
/// use too long and not in `keep`; near the budget, every column not used,
/// in the order to free them.
fn freeing<S: VoxelSource + ?Sized, H>(
    input: &SelectInput<'_, S, H>,
    keep: &HashSet<ChunkColumn>,
    used: &[(usize, ChunkColumn)],
) -> (Vec<(usize, ChunkColumn)>, Option<SlotColumns>) {
    let SelectSettings { frame, free_after_frames, near_budget, .. } = input.settings;
    let columns = input.columns;
    let (mut aged, mut least_recent) = (Vec::new(), None);
    let aging = frame.is_multiple_of(AGING_PERIOD);
    if aging || near_budget {
        let in_use = slots_in_use(columns, used);
        let max_lod = input.voxels.layout().max_lod();
        let candidates = least_recently_used(columns, keep, max_lod, |slot, _| in_use[slot]);
        if aging {
            aged.extend(
                candidates
                    .iter()
                    .filter(|&&(kept, last_used, _, _)| !kept && frame.saturating_sub(last_used) > free_after_frames)
                    .map(|&(_, _, column, slot)| (slot, column)),
            );
        }
        if near_budget {
            least_recent = Some(candidates.into_iter().map(|(_, _, column, slot)| (slot, column)).collect());
        }
    }
    (aged, least_recent)
}

/// Whether `plan`, made from `input` and leaving `selection` as it is now,
/// planned a settled view: nothing of the view to mesh, stand in for,
/// sample or forget, and nothing asked of the next plan but prefetching.
/// Until the camera, the tree, the settings (the frame aside) or one of
/// the cached columns it read change, the view's part of every later plan
/// is the same (the columns it read: every visible leaf's and every drawn
/// one's), and only the prefetch jobs and what to free are made anew
/// ([`plan_prefetch`]).
pub(crate) fn settled_view<S: VoxelSource + ?Sized, H>(
    input: &SelectInput<'_, S, H>,
    selection: &Selection,
    plan: &Plan<H>,
) -> bool {
    input.asks_nothing(selection)
        && plan.new_columns.is_empty()
        && plan.dropped_stale.is_empty()
        && plan.forget_failed.is_empty()
        && plan.draw.tops_awaited == 0
        && plan.draw.stand_ins == 0
        && plan.draw.holes == 0
        && plan.jobs.iter().all(|job| job.tier == Tier::Prefetch)
}

/// Whether a plan from `input` and `selection` may be [`plan_prefetch`]'s:
/// nothing asked of it but prefetching, and no prefetch set to make again.
pub(crate) fn asks_prefetching_only<S: ?Sized, H>(input: &SelectInput<'_, S, H>, selection: &Selection) -> bool {
    // (Asking nothing, the view is not busy.)
    input.asks_nothing(selection)
        && !(input.settings.prefetch
            && refresh_due(selection.view_busy, selection.prefetched_at, selection.tree_changed, input.settings.frame))
}

/// The plan [`plan`] makes from `input` and `selection` where the view's
/// part is that of `view`, a [`settled_view`]'s plan whose columns read
/// are unchanged since ([`asks_prefetching_only`] holds): `view` again,
/// with the next prefetch jobs and what to free. Through a 12° lens 500 m
/// over the Earth a full plan took about 15 ms of the LOD thread's CPU
/// (33–47 ms of wall time on the 2-core machine), every frame of the
/// prefetching after the view settled (each mesh that came changed the
/// cached columns).
pub(crate) fn plan_prefetch<S: VoxelSource + ?Sized, H>(
    input: &SelectInput<'_, S, H>,
    selection: &mut Selection,
    view: &Plan<H>,
) -> Plan<H> {
    let start = Instant::now();
    debug_assert!(asks_prefetching_only(input, selection));
    let holds = |key: ChunkKey| input.columns.holds(key);
    let mut plan = view.repeat();
    queue_prefetch(&mut plan.jobs, &mut selection.prefetch_jobs, holds, input.settings.room_to_prefetch);
    keep_most_urgent(&mut plan.jobs);
    (plan.aged, plan.least_recent) = freeing(input, &selection.keep, &plan.used);
    #[cfg(test)]
    if selection.prefetch_plans_queue_nothing {
        plan.jobs.clear();
    }
    plan.millis = start.elapsed().as_secs_f64() * 1e3;
    plan
}

/// Whether two plans are the same (their timing aside): what a test asks
/// of [`plan_prefetch`] against [`plan`].
#[cfg(test)]
pub(crate) fn same_plan<H>(a: &Plan<H>, b: &Plan<H>) -> bool {
    let draws = |d: &DrawList| {
        (
            d.columns.clone(),
            (d.holes, d.stand_ins, d.max_stand_in_levels, d.behind_horizon, d.tops_awaited, d.under_sea),
            (d.min_surface_radius.to_bits(), d.occluder_radius.to_bits(), d.unsettled, d.max_lod_diff),
        )
    };
    draws(&a.draw) == draws(&b.draw)
        && a.slots == b.slots
        && a.arounds == b.arounds
        && a.used == b.used
        && a.new_columns.len() == b.new_columns.len()
        && a.dropped_stale == b.dropped_stale
        && a.jobs == b.jobs
        && a.forget_failed == b.forget_failed
        && a.unseen == b.unseen
        && a.aged == b.aged
        && a.least_recent == b.least_recent
}

impl<H> Plan<H> {
    /// This plan again, for a later frame of a still, settled view (see
    /// [`repeatable_until`]): what it draws and uses, nothing to mesh, add
    /// or free (a repeatable plan has none of those).
    pub(crate) fn repeat(&self) -> Self {
        Self {
            draw: self.draw.clone(),
            slots: self.slots.clone(),
            arounds: self.arounds.clone(),
            used: self.used.clone(),
            new_columns: Vec::new(),
            dropped_stale: Vec::new(),
            jobs: Vec::new(),
            forget_failed: Vec::new(),
            unseen: self.unseen.clone(),
            aged: Vec::new(),
            least_recent: None,
            millis: 0.0,
        }
    }
}

/// The frame before which `plan`, made from `input` and leaving
/// `selection` as it is now, would be made again as it is (what
/// [`Plan::repeat`] gives) by every later plan from the same tree, the same
/// cached columns (none added, changed or freed: a column's last use
/// aside, read only to free for age or near the budget), the same settings
/// but the frame, and this selection state; `None` where the next plan may
/// differ even so. Such a plan is a still view's, settled: nothing to mesh
/// (prefetching done), free, retry, or sample, no edit awaited. What time
/// alone changes bounds it: the first frame that lists a column out of
/// use for too long (those it uses are used again each frame it is
/// repeated), and the prefetch set's greatest age.
pub(crate) fn repeatable_until<S: VoxelSource + ?Sized, H>(
    input: &SelectInput<'_, S, H>,
    selection: &Selection,
    plan: &Plan<H>,
) -> Option<u64> {
    let settled = input.asks_nothing(selection)
        && plan.jobs.is_empty()
        && plan.new_columns.is_empty()
        && plan.dropped_stale.is_empty()
        && plan.forget_failed.is_empty()
        && plan.aged.is_empty()
        && plan.least_recent.is_none()
        && plan.draw.tops_awaited == 0;
    if !settled {
        return None;
    }
    let frame = input.settings.frame;
    let next_aging = (frame / AGING_PERIOD + 1) * AGING_PERIOD;
    // The column out of use the longest, not kept for prefetching.
    let in_use = slots_in_use(input.columns, &plan.used);
    let max_lod = input.voxels.layout().max_lod();
    let candidates = least_recently_used(input.columns, &selection.keep, max_lod, |slot, _| in_use[slot]);
    let aging = match candidates.first() {
        Some(&(false, last_used, _, _)) => {
            // Listed at the first aging frame past its limit.
            let limit = last_used.saturating_add(input.settings.free_after_frames);
            let listed = (limit / AGING_PERIOD).saturating_add(1).saturating_mul(AGING_PERIOD);
            listed.max(next_aging)
        }
        _ => u64::MAX,
    };
    match input.settings.prefetch {
        false => Some(aging),
        // A prefetch set is made first when the view has no work.
        true if selection.prefetched_at == 0 => None,
        true => Some(aging.min(selection.prefetched_at + PREFETCH_MAX_AGE_FRAMES)),
    }
}

/// Whether each slot of `columns` is one of `used`, by slot.
fn slots_in_use<H>(columns: &ColumnStore<H>, used: &[(usize, ChunkColumn)]) -> Vec<bool> {
    let mut in_use = vec![false; columns.slot_bound()];
    for &(slot, _) in used {
        if let Some(in_use) = in_use.get_mut(slot) {
            *in_use = true;
        }
    }
    in_use
}

/// The cached columns that may be freed (not a face root, not
/// `used_now`), in the order to free them: what the prefetch set does not
/// keep first, the least recently used first within each; with whether it
/// is kept, its last use and its slot.
pub(crate) fn least_recently_used<H>(
    columns: &ColumnStore<H>,
    keep: &HashSet<ChunkColumn>,
    max_lod: u8,
    used_now: impl Fn(usize, &CachedColumn<H>) -> bool,
) -> Vec<(bool, u64, ChunkColumn, usize)> {
    let mut candidates: Vec<_> = columns
        .iter_slots()
        .filter(|&(slot, cached)| cached.column.lod != max_lod && !used_now(slot, cached))
        .map(|(slot, cached)| (keep.contains(&cached.column), cached.last_used, cached.column, slot))
        .collect();
    candidates.sort_unstable();
    candidates
}

/// Keeps the [`MAX_QUEUED_JOBS`] most urgent of `jobs`.
pub(crate) fn keep_most_urgent(jobs: &mut Vec<Job>) {
    if jobs.len() > MAX_QUEUED_JOBS {
        jobs.select_nth_unstable_by(MAX_QUEUED_JOBS, |a, b| b.cmp(a));
        jobs.truncate(MAX_QUEUED_JOBS);
    }
}

/// Whether `sea` hides `column`: it or an ancestor is sea bed wholly under
/// the sea's hiding depth ([`VoxelSource::sea_bed_below`]). Remembered in
/// `memo`, ancestors first (a hidden parent hides its children for free).
fn under_sea<S: VoxelSource + ?Sized>(
    voxels: &S,
    sea: OpaqueSea,
    memo: &mut HashMap<ChunkColumn, bool>,
    column: ChunkColumn,
    max_lod: u8,
) -> bool {
    if let Some(&known) = memo.get(&column) {
        return known;
    }
    let hidden = (column.lod < max_lod && parent(column).is_some_and(|up| under_sea(voxels, sea, memo, up, max_lod)))
        || voxels.sea_bed_below(column, sea.hiding_radius()).unwrap_or(false);
    memo.insert(column, hidden);
    hidden
}
