//! The LOD tree's update and cull and the frame's selection, made ahead on
//! a thread of their own for where the camera is going, so that the frame
//! thread only takes the result.
//!
//! At the end of each update the streamer asks for the tree of the camera
//! it predicts for the next frame, culled with a margin ([`CullMargin`])
//! around it, and for the selection planned on it ([`crate::select`]). The
//! thread keeps a tree of its own, updates it, culls it, plans the
//! selection from the cached columns (shared read only meanwhile: the game
//! draws the frame from them) and sends back a copy of the tree with the
//! plan; the next update takes both when the margin covers the camera that
//! came ([`LodTree::cull_covers`]), and else updates and culls its own tree
//! and plans itself, as it always did. An update whose outcome has not
//! come yet (or came for a camera the view has since left) draws the plan
//! before again while that plan's cull still covers the camera, instead of
//! waiting, and the next request asks for the camera as many frames ahead
//! as the last plan took ([`LodThread::ready`],
//! `Streamer::set_draw_while_planning`). What changes a tree besides the
//! camera (an edit's bounds, a new view, a tree started again) is done to
//! both, in the same order: a copy made before the thread saw all of them
//! is not taken.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use nebula_lod::{Camera, Cull, CullMargin, LodTree};
use nebula_voxel::{ChunkColumn, ChunkKey, VoxelSource};

use crate::select::{
    Plan, SelectInput, SelectSettings, Selection, asks_prefetching_only, plan, plan_prefetch, repeatable_until,
    settled_view,
};
use crate::stream::{ColumnStore, Failure, MeshHandle};

/// The LOD thread's priority, on `thread-priority`'s cross-platform scale
/// (as [`MESHING_THREAD_PRIORITY`](crate::stream::MESHING_THREAD_PRIORITY)):
/// niceness 4 on Linux, under the frame thread and meshing. Measured on the
/// 2-core machine (lavapipe drawing on the same cores), the 1 km/s land
/// flight at 640x400, three runs each: the step's 95th percentile 5.8-7.0
/// ms at niceness 1 (a woken plan took the frame thread's core: the step's
/// wall time 4-10 ms over its CPU time in a fifth of the frames), 4.9-5.9
/// ms here (the plan 12-21 ms median, made while the frame draws); at
/// niceness 7 the plan (64 ms) was not ready when the next update came
/// (95th percentile 55 ms).
pub(crate) const LOD_THREAD_PRIORITY: u8 = 33;

/// Puts the calling thread (the LOD thread) below the frame thread, which
/// wakes it with each request, and below meshing (see
/// [`LOD_THREAD_PRIORITY`]); on Linux with batch scheduling too (a woken
/// batch thread does not preempt the running one), elsewhere the lower
/// priority alone.
fn lower_priority() {
    let Ok(value) = thread_priority::ThreadPriorityValue::try_from(LOD_THREAD_PRIORITY) else { return };
    let priority = thread_priority::ThreadPriority::Crossplatform(value);
    #[cfg(target_os = "linux")]
    {
        use thread_priority::{NormalThreadSchedulePolicy, ThreadSchedulePolicy};
        let batch = ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Batch);
        if thread_priority::set_thread_priority_and_policy(thread_priority::thread_native_id(), priority, batch).is_ok()
        {
            return;
        }
    }
    let _ = priority.set_for_current();
}

/// What the LOD thread needs to plan a frame's selection on its tree: the
/// selection's state (moved there and back), the cached columns (shared
/// read only until the plan is sent) and a copy of what else it reads.
pub(crate) struct SelectRequest<H> {
    pub(crate) selection: Box<Selection>,
    pub(crate) columns: Arc<ColumnStore<H>>,
    pub(crate) stale: HashMap<ChunkKey, u64>,
    pub(crate) gained: HashSet<ChunkKey>,
    pub(crate) failed: HashMap<ChunkKey, Failure>,
    pub(crate) settings: SelectSettings,
}

/// What the frame thread asks of the LOD thread, in order.
enum Request<S, H> {
    /// Update and cull the tree for `camera` with `margin`, plan the
    /// selection on it, and send a copy (or the cull alone, when the frame
    /// thread holds copy `holding` and the tree has not changed since it
    /// was sent) and the plan.
    Update { voxels: Arc<S>, camera: Camera, margin: CullMargin, holding: Option<u64>, select: Box<SelectRequest<H>> },
    /// Re-read the bounds of edited columns.
    Refresh { voxels: Arc<S>, columns: Vec<ChunkColumn> },
    /// A new threshold, screen height or field of view.
    SetView { threshold_px: f64, screen_height_px: f64, fov_y_degrees: f64 },
    /// Go on from this tree (the frame thread started its own again).
    Replace(Box<LodTree>),
}

/// The tree an update made, as the LOD thread sends it.
pub(crate) enum MadeTree {
    /// A copy of the whole tree, numbered.
    Whole(Box<LodTree>, u64),
    /// The cull alone, for the numbered copy the frame thread said it
    /// holds: the tree has not changed since that copy was sent. (Copying
    /// a narrow lens's tree of 276,000 nodes for every update of a still
    /// view was a tenth of the CPU of settling it.)
    Cull(Cull, u64),
}

/// What the LOD thread sends back for an update.
pub(crate) struct Outcome<H> {
    /// The tree updated and culled for the asked camera (whether its
    /// leaves changed went into the selection's state); `None`: the update
    /// failed (a refused camera, a failing voxel source), and the frame
    /// thread updates its own tree and reports what it finds.
    pub(crate) tree: Option<MadeTree>,
    /// Tree-changing requests applied before the update.
    commands: u64,
    /// The selection's state sent with the request (`None` once the
    /// streamer took it back).
    pub(crate) selection: Option<Box<Selection>>,
    /// The selection planned on the tree (if the update and the plan went
    /// through).
    pub(crate) plan: Option<Plan<H>>,
    /// The plan's number: each plan made gets the next, a repeated one
    /// keeps its own.
    pub(crate) plan_number: u64,
    /// The plan is the one before again ([`Repeatable`]), and so is the
    /// tree's cull.
    pub(crate) repeated: bool,
    /// The plan is a settled view's with new prefetch jobs
    /// ([`SettledView`]), not planned in full.
    pub(crate) prefetch_only: bool,
    /// Where a prefetch-only plan differed from the full plan made beside
    /// it to check it (tests only): what differed.
    #[cfg(test)]
    pub(crate) prefetch_mismatch: Option<&'static str>,
}

impl<H> Outcome<H> {
    /// The camera and margin the outcome's tree was culled for (before
    /// the frame thread narrows it to its camera).
    pub(crate) fn culled_for(&self) -> Option<(Camera, CullMargin)> {
        match self.tree.as_ref()? {
            MadeTree::Whole(tree, _) => tree.culled_for(),
            MadeTree::Cull(cull, _) => cull.culled_for(),
        }
    }
}

/// The frame thread's end of the LOD thread.
pub(crate) struct LodThread<S, H> {
    requests: Sender<(Request<S, H>, u64)>,
    /// Behind a lock only so that the streamer is `Sync` (an ECS resource).
    outcomes: Mutex<Receiver<Outcome<H>>>,
    /// Tree-changing requests sent so far.
    commands: u64,
    /// An update asked for whose outcome has not been taken.
    in_flight: bool,
    /// The outcome of the update in flight, come before it was taken
    /// ([`LodThread::ready`]).
    arrived: Option<Outcome<H>>,
    /// The frame the update in flight was asked in.
    asked_in: u64,
    /// The numbered copy the frame thread's tree is, while it is one
    /// ([`LodThread::hold`]; a tree-changing request ends it).
    holding: Option<u64>,
    /// Whole trees received so far.
    copies: u64,
    /// Plans received that were the one before again.
    repeats: u64,
    /// Plans received that were prefetch-only ([`SettledView`]).
    prefetch_plans: u64,
}

impl<S: VoxelSource + Send + Sync + 'static, H: MeshHandle> LodThread<S, H> {
    /// Starts the thread with a copy of `tree`.
    pub(crate) fn start(tree: &LodTree) -> std::io::Result<Self> {
        let (requests, inbox) = channel::<(Request<S, H>, u64)>();
        let (outbox, outcomes) = channel();
        let tree = tree.clone();
        std::thread::Builder::new().name("nebula-lod".into()).spawn(move || {
            lower_priority();
            serve(tree, &inbox, &outbox);
        })?;
        Ok(Self {
            requests,
            outcomes: Mutex::new(outcomes),
            commands: 0,
            in_flight: false,
            arrived: None,
            asked_in: 0,
            holding: None,
            copies: 0,
            repeats: 0,
            prefetch_plans: 0,
        })
    }

    /// Asks for the tree of `camera`, culled with `margin`, and for the
    /// selection planned on it (a still camera's too: the plan follows the
    /// meshes that come).
    pub(crate) fn ask(&mut self, voxels: &Arc<S>, camera: Camera, margin: CullMargin, select: SelectRequest<H>) {
        let frame = select.settings.frame;
        let request =
            Request::Update { voxels: voxels.clone(), camera, margin, holding: self.holding, select: Box::new(select) };
        if self.requests.send((request, self.commands)).is_ok() {
            self.in_flight = true;
            // Asked for `frame`, in the update before it.
            self.asked_in = frame.saturating_sub(1);
        }
    }

    /// Whether an update is asked for and its outcome not taken yet.
    pub(crate) fn in_flight(&self) -> bool {
        self.in_flight
    }

    /// Whether the outcome of the update in flight has come (without
    /// waiting for it): [`LodThread::take`] then returns at once.
    pub(crate) fn ready(&mut self) -> bool {
        if self.arrived.is_none() && self.in_flight {
            self.arrived = self.outcomes.get_mut().ok().and_then(|outcomes| outcomes.try_recv().ok());
        }
        self.arrived.is_some()
    }

    /// The frame the update in flight (or taken last) was asked in.
    pub(crate) fn asked_in(&self) -> u64 {
        self.asked_in
    }

    /// Tree-changing requests sent so far.
    pub(crate) fn commands(&self) -> u64 {
        self.commands
    }

    /// The outcome of the update asked for, waiting for it if it has not
    /// come; `None` when none was asked for (or the thread is gone: it
    /// cannot panic, updates and plans are caught).
    pub(crate) fn take(&mut self) -> Option<Outcome<H>> {
        if !self.in_flight {
            return None;
        }
        self.in_flight = false;
        let outcome = match self.arrived.take() {
            Some(outcome) => outcome,
            None => self.outcomes.get_mut().ok()?.recv().ok()?,
        };
        self.copies += u64::from(matches!(outcome.tree, Some(MadeTree::Whole(..))));
        self.repeats += u64::from(outcome.repeated);
        self.prefetch_plans += u64::from(outcome.prefetch_only);
        Some(outcome)
    }

    /// The frame thread's tree is now copy `copy` (a whole tree it took),
    /// or no copy the thread sent (`None`).
    pub(crate) fn hold(&mut self, copy: Option<u64>) {
        self.holding = copy;
    }

    /// The numbered copy the frame thread's tree is, if it is one.
    pub(crate) fn holding(&self) -> Option<u64> {
        self.holding
    }

    /// Whole trees received so far (the rest of the updates sent their
    /// cull alone).
    pub(crate) fn copies(&self) -> u64 {
        self.copies
    }

    /// Prefetch-only plans received so far ([`SettledView`]).
    pub(crate) fn prefetch_plans(&self) -> u64 {
        self.prefetch_plans
    }

    /// Plans received that were the one before again (a still camera over
    /// a settled view).
    pub(crate) fn repeats(&self) -> u64 {
        self.repeats
    }

    /// Whether `outcome` was made after every tree-changing request sent
    /// so far: its tree (and plan) may be taken.
    pub(crate) fn is_current(&self, outcome: &Outcome<H>) -> bool {
        outcome.commands == self.commands
    }

    /// Re-reads the bounds of `columns` in the thread's tree too.
    pub(crate) fn refresh(&mut self, voxels: &Arc<S>, columns: Vec<ChunkColumn>) {
        self.command(Request::Refresh { voxels: voxels.clone(), columns });
    }

    /// Sets the view of the thread's tree too.
    pub(crate) fn set_view(&mut self, threshold_px: f64, screen_height_px: f64, fov_y_degrees: f64) {
        self.command(Request::SetView { threshold_px, screen_height_px, fov_y_degrees });
    }

    /// The thread goes on from a copy of `tree`.
    pub(crate) fn replace(&mut self, tree: &LodTree) {
        self.command(Request::Replace(Box::new(tree.clone())));
    }

    fn command(&mut self, request: Request<S, H>) {
        self.commands += 1;
        // Both trees change: neither is a copy sent before.
        self.holding = None;
        // A closed channel (the thread gone) leaves the frame thread to
        // update its own tree, as without one.
        let _ = self.requests.send((request, self.commands));
    }
}

impl<S, H> Drop for LodThread<S, H> {
    /// Waits for an update in flight: the thread holds the cached columns
    /// while it plans, and nothing the streamer uploaded may outlive it (a
    /// game drops its renderer after it).
    fn drop(&mut self) {
        if self.in_flight
            && self.arrived.is_none()
            && let Ok(outcomes) = self.outcomes.get_mut()
        {
            drop(outcomes.recv());
        }
    }
}

/// A plan the next ones would make again while nothing it was made from
/// changes but the frame (a still, settled view:
/// [`repeatable_until`]): a still camera's frames take it again instead of
/// planning (every frame's plan, 10–20 ms on an Earth view, kept a core of
/// the 2-core machine a third to half busy while nothing moved), and the
/// tree's cull with it (the frame thread keeps what it draws:
/// [`Outcome::repeated`]).
struct Repeatable<H> {
    /// What it was made from: the eye and margin, the cached columns'
    /// change count ([`ColumnStore::changes`]) and the settings, frame
    /// aside.
    made_from: (Camera, CullMargin, u64, SelectSettings),
    /// The first frame it may differ for.
    until: u64,
    plan: Plan<H>,
    /// Its number ([`Outcome::plan_number`]).
    number: u64,
}

impl<H> Repeatable<H> {
    /// The plan again, if it serves a request made from these (the tree
    /// unchanged since, the selection settled).
    fn serve(&self, made_from: (Camera, CullMargin, u64, SelectSettings), frame: u64) -> Option<Plan<H>> {
        (self.made_from == made_from && frame < self.until).then(|| self.plan.repeat())
    }
}

/// The view's part of a plan of a settled view ([`settled_view`]), for
/// the plans after it that only prefetching changes: while the camera, its
/// margin, the tree and the settings (the frame aside) stay, and none of
/// the cached columns that plan read changes (each mesh that comes for
/// prefetching changes another), the next plans are this one's view with
/// new prefetch jobs ([`plan_prefetch`]).
struct SettledView<H> {
    /// The eye, margin and settings (frame aside) it was made from.
    made_from: (Camera, CullMargin, SelectSettings),
    /// The cached columns' change log position ([`ColumnStore::touch_count`])
    /// up to which the changes are known to leave it as it is.
    checked_to: usize,
    /// The cached columns the view's part read: every visible leaf's and
    /// every drawn column's.
    read: HashSet<ChunkColumn>,
    plan: Plan<H>,
}

impl<H> SettledView<H> {
    /// Whether it is still the view's part of a plan from `input`, the
    /// tree unchanged since (else the thread dropped it), made from
    /// `made_from`; notes the cached columns' changes as checked.
    fn serves<S: ?Sized>(
        &mut self,
        input: &SelectInput<'_, S, H>,
        selection: &Selection,
        made_from: (Camera, CullMargin, SelectSettings),
    ) -> bool {
        if self.made_from != made_from || !asks_prefetching_only(input, selection) {
            return false;
        }
        let Some(touched) = input.columns.touched_since(self.checked_to) else { return false };
        if touched.iter().any(|column| self.read.contains(column)) {
            return false;
        }
        self.checked_to = input.columns.touch_count();
        true
    }
}

/// The settings a plan is made with, the frame aside (see [`Repeatable`]).
fn frameless(settings: SelectSettings) -> SelectSettings {
    SelectSettings { frame: 0, ..settings }
}

/// The thread: takes every request waiting, applies the tree-changing ones
/// in order, then updates for the newest camera asked for and plans on it.
fn serve<S: VoxelSource + Send + Sync + 'static, H: MeshHandle>(
    mut tree: LodTree,
    inbox: &Receiver<(Request<S, H>, u64)>,
    outbox: &Sender<Outcome<H>>,
) {
    let mut commands = 0;
    // The number of the last whole copy sent, while the tree is unchanged
    // since; the next number.
    let (mut sent, mut next_copy): (Option<u64>, u64) = (None, 0);
    // The eye and margin the tree is culled for, while nothing changed it
    // since: a still camera over a settled tree is not culled again.
    let mut culled_for: Option<(Camera, CullMargin)> = None;
    let mut repeatable: Option<Repeatable<H>> = None;
    let mut settled: Option<SettledView<H>> = None;
    let mut plans_made = 0;
    while let Ok(first) = inbox.recv() {
        // At most one update is in flight: the frame thread takes each
        // outcome before it asks again.
        let mut update = None;
        for (request, sequence) in std::iter::once(first).chain(inbox.try_iter()) {
            match request {
                Request::Update { voxels, camera, margin, holding, select } => {
                    update = Some((voxels, camera, margin, holding, select));
                }
                Request::Refresh { voxels, columns } => {
                    commands = sequence;
                    (sent, culled_for, repeatable, settled) = (None, None, None, None);
                    // A failing source leaves these bounds old here as on
                    // the frame thread, which reports it.
                    let _ = tree.refresh_bounds(&*voxels, columns);
                }
                Request::SetView { threshold_px, screen_height_px, fov_y_degrees } => {
                    commands = sequence;
                    (sent, culled_for, repeatable, settled) = (None, None, None, None);
                    let _ = tree.set_view(threshold_px, screen_height_px, fov_y_degrees);
                }
                Request::Replace(replacement) => {
                    commands = sequence;
                    (sent, culled_for, repeatable, settled) = (None, None, None, None);
                    tree = *replacement;
                }
            }
        }
        let Some((voxels, camera, margin, holding, select)) = update else { continue };
        #[cfg(test)]
        std::thread::sleep(std::time::Duration::from_millis(select.selection.plan_delay_ms));
        let updated = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let changes = tree.update(&*voxels, &camera)?;
            let same_tree =
                changes.added.is_empty() && changes.removed.is_empty() && changes.neighbours_changed.is_empty();
            if !(same_tree && culled_for == Some((camera, margin))) {
                culled_for = None;
                tree.cull_with_margin(&camera, margin)?;
                culled_for = Some((camera, margin));
            }
            Ok::<bool, nebula_lod::LodError>(!same_tree)
        }));
        if !matches!(updated, Ok(Ok(false))) {
            // Changed, or maybe part-way through a change.
            (culled_for, repeatable, settled) = (None, None, None);
        }
        let changed = match updated {
            Ok(Ok(changed)) => Some(changed),
            Ok(Err(_)) => None,
            Err(_) => {
                // The tree may be part-way through a change: start again
                // from the roots, as the frame thread would (which reports
                // the failure: it updates its own tree when this one
                // fails).
                let settings = *tree.settings();
                if let Ok(Ok(fresh)) =
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| LodTree::new(&*voxels, settings)))
                {
                    tree = fresh;
                }
                None
            }
        };
        let SelectRequest { mut selection, columns, stale, gained, failed, settings } = *select;
        selection.tree_changed |= changed == Some(true);
        // A panic in the voxel source while planning leaves the plan to the
        // frame thread, which reports it.
        let mut repeated = false;
        let mut prefetch_only = false;
        #[cfg(test)]
        let mut prefetch_mismatch = None;
        let mut plan_number = plans_made;
        let plan = changed.and_then(|_| {
            let made_from = (camera, margin, columns.changes(), frameless(settings));
            let input = SelectInput {
                voxels: &*voxels,
                tree: &tree,
                columns: &columns,
                stale: &stale,
                gained: &gained,
                failed: &failed,
                settings,
            };
            if let Some(repeatable) = repeatable.as_ref().filter(|_| input.asks_nothing(&selection))
                && let Some(plan) = repeatable.serve(made_from, settings.frame)
            {
                (repeated, plan_number) = (true, repeatable.number);
                return Some(plan);
            }
            plans_made += 1;
            plan_number = plans_made;
            // Only prefetching changed since a settled view's plan: its
            // view again, with the next prefetch jobs.
            let view_made_from = (camera, margin, frameless(settings));
            if let Some(view) = settled.as_mut()
                && view.serves(&input, &selection, view_made_from)
            {
                #[cfg(test)]
                let mut check = (*selection).clone();
                let made = plan_prefetch(&input, &mut selection, &view.plan);
                #[cfg(test)]
                {
                    let full = plan(&input, &mut check);
                    prefetch_mismatch = if !crate::select::same_plan(&made, &full) {
                        Some("the plan")
                    } else if check.prefetch_jobs != selection.prefetch_jobs {
                        Some("the prefetch jobs left")
                    } else {
                        None
                    };
                }
                prefetch_only = true;
                repeatable = repeatable_until(&input, &selection, &made).map(|until| Repeatable {
                    made_from,
                    until,
                    plan: made.repeat(),
                    number: plan_number,
                });
                return Some(made);
            }
            let plan = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| plan(&input, &mut selection))).ok();
            repeatable = plan.as_ref().and_then(|plan| {
                let until = repeatable_until(&input, &selection, plan)?;
                Some(Repeatable { made_from, until, plan: plan.repeat(), number: plan_number })
            });
            settled = plan.as_ref().filter(|plan| settled_view(&input, &selection, plan)).map(|plan| {
                let mut read: HashSet<ChunkColumn> = tree.visible_leaves().iter().copied().collect();
                read.extend(plan.draw.columns.iter().map(|&(column, _)| column));
                SettledView { made_from: view_made_from, checked_to: columns.touch_count(), read, plan: plan.repeat() }
            });
            plan
        });
        // Let go of the columns before the frame thread can have the plan:
        // it changes them as soon as it does.
        drop(columns);
        if changed != Some(false) {
            sent = None;
        }
        let made = changed.map(|_| match sent {
            Some(copy) if holding == Some(copy) => MadeTree::Cull(tree.cull_result(), copy),
            _ => {
                next_copy += 1;
                sent = Some(next_copy);
                MadeTree::Whole(Box::new(tree.clone()), next_copy)
            }
        });
        let outcome = Outcome {
            tree: made,
            commands,
            selection: Some(selection),
            plan,
            plan_number,
            repeated,
            prefetch_only,
            #[cfg(test)]
            prefetch_mismatch,
        };
        if outbox.send(outcome).is_err() {
            return;
        }
    }
}
