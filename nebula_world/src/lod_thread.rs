//! The LOD tree's update and cull, made ahead on a thread of their own for
//! where the camera is going, so that the frame thread only takes the
//! result.
//!
//! Each frame the streamer asks for the tree of the camera it predicts for
//! the next frame, culled with a margin ([`CullMargin`]) around it. The
//! thread keeps a tree of its own, updates it, culls it and sends back a
//! copy; the next frame takes that copy in place of its own tree when the
//! margin covers the camera that came ([`LodTree::cull_covers`]), and else
//! updates and culls its own tree itself, as it always did. What changes a
//! tree besides the camera (an edit's bounds, a new view, a tree started
//! again) is done to both, in the same order: a copy made before the
//! thread saw all of them is not taken.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

use nebula_lod::{Camera, CullMargin, LodTree};
use nebula_voxel::{ChunkColumn, VoxelSource};

/// What the frame thread asks of the LOD thread, in order.
enum Request<S> {
    /// Update and cull the tree for `camera` with `margin`, and send a copy.
    Update { voxels: Arc<S>, camera: Camera, margin: CullMargin },
    /// Re-read the bounds of edited columns.
    Refresh { voxels: Arc<S>, columns: Vec<ChunkColumn> },
    /// A new threshold, screen height or field of view.
    SetView { threshold_px: f64, screen_height_px: f64, fov_y_degrees: f64 },
    /// Go on from this tree (the frame thread started its own again).
    Replace(Box<LodTree>),
}

/// What the LOD thread sends back for an update.
pub(crate) enum Outcome {
    /// The tree updated and culled for the asked camera, after `commands`
    /// tree-changing requests; `changed`: its leaves changed.
    Tree { tree: Box<LodTree>, changed: bool, commands: u64 },
    /// The update failed (a refused camera, a failing voxel source); the
    /// frame thread updates its own tree and reports what it finds.
    Failed,
}

/// The frame thread's end of the LOD thread.
pub(crate) struct LodThread<S> {
    requests: Sender<(Request<S>, u64)>,
    /// Behind a lock only so that the streamer is `Sync` (an ECS resource).
    outcomes: Mutex<Receiver<Outcome>>,
    /// Tree-changing requests sent so far.
    commands: u64,
    /// An update asked for whose outcome has not come.
    in_flight: bool,
    /// The camera and commands of the last update asked for: a still camera
    /// over an unchanged tree asks for nothing more.
    asked: Option<(Camera, u64)>,
}

impl<S: VoxelSource + Send + Sync + 'static> LodThread<S> {
    /// Starts the thread with a copy of `tree`.
    pub(crate) fn start(tree: &LodTree) -> std::io::Result<Self> {
        let (requests, inbox) = channel::<(Request<S>, u64)>();
        let (outbox, outcomes) = channel();
        let tree = tree.clone();
        std::thread::Builder::new().name("nebula-lod".into()).spawn(move || serve(tree, &inbox, &outbox))?;
        Ok(Self { requests, outcomes: Mutex::new(outcomes), commands: 0, in_flight: false, asked: None })
    }

    /// Asks for the tree of `camera`, culled with `margin` (unless the
    /// last request was the same camera with nothing changed since).
    pub(crate) fn ask(&mut self, voxels: &Arc<S>, camera: Camera, margin: CullMargin) {
        if self.asked == Some((camera, self.commands)) && !self.in_flight {
            return;
        }
        let request = Request::Update { voxels: voxels.clone(), camera, margin };
        if self.requests.send((request, self.commands)).is_ok() {
            self.in_flight = true;
            self.asked = Some((camera, self.commands));
        }
    }

    /// Whether an update was asked for and its outcome not taken.
    pub(crate) fn in_flight(&self) -> bool {
        self.in_flight
    }

    /// The outcome of the update asked for, waiting for it if it has not
    /// come; `None` when none was asked for, or the copy predates a
    /// tree-changing request.
    pub(crate) fn take(&mut self) -> Option<Outcome> {
        if !self.in_flight {
            return None;
        }
        self.in_flight = false;
        let outcome = self.outcomes.get_mut().map(|outcomes| outcomes.recv());
        match outcome {
            Ok(Ok(Outcome::Tree { commands, .. })) if commands != self.commands => None,
            Ok(Ok(outcome)) => Some(outcome),
            // The thread is gone (it cannot panic: updates are caught).
            _ => None,
        }
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

    fn command(&mut self, request: Request<S>) {
        self.commands += 1;
        // A closed channel (the thread gone) leaves the frame thread to
        // update its own tree, as without one.
        let _ = self.requests.send((request, self.commands));
    }
}

/// The thread: takes every request waiting, applies the tree-changing ones
/// in order, then updates for the newest camera asked for.
fn serve<S: VoxelSource + Send + Sync + 'static>(
    mut tree: LodTree,
    inbox: &Receiver<(Request<S>, u64)>,
    outbox: &Sender<Outcome>,
) {
    let mut commands = 0;
    while let Ok(first) = inbox.recv() {
        // At most one update is in flight: the frame thread takes each
        // outcome before it asks again.
        let mut update = None;
        for (request, sequence) in std::iter::once(first).chain(inbox.try_iter()) {
            match request {
                Request::Update { voxels, camera, margin } => {
                    update = Some((voxels, camera, margin));
                }
                Request::Refresh { voxels, columns } => {
                    commands = sequence;
                    // A failing source leaves these bounds old here as on
                    // the frame thread, which reports it.
                    let _ = tree.refresh_bounds(&*voxels, columns);
                }
                Request::SetView { threshold_px, screen_height_px, fov_y_degrees } => {
                    commands = sequence;
                    let _ = tree.set_view(threshold_px, screen_height_px, fov_y_degrees);
                }
                Request::Replace(replacement) => {
                    commands = sequence;
                    tree = *replacement;
                }
            }
        }
        let Some((voxels, camera, margin)) = update else { continue };
        let updated = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let changes = tree.update(&*voxels, &camera)?;
            tree.cull_with_margin(&camera, margin)?;
            Ok::<bool, nebula_lod::LodError>(
                !(changes.added.is_empty() && changes.removed.is_empty() && changes.neighbours_changed.is_empty()),
            )
        }));
        let outcome = match updated {
            Ok(Ok(changed)) => Outcome::Tree { tree: Box::new(tree.clone()), changed, commands },
            Ok(Err(_)) => Outcome::Failed,
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
                Outcome::Failed
            }
        };
        if outbox.send(outcome).is_err() {
            return;
        }
    }
}
