//! The per-face quadtrees and their incremental update.
//!
//! # Conventions
//!
//! A node is a [`ChunkColumn`]: face, LOD and chunk coordinates at that LOD.
//! Depth = `max_lod − lod`; each face's root is the single column at the
//! planet's coarsest LOD. Children of `(lod, x, y)` are
//!
//! ```text
//!   (lod−1, 2x,   2y+1) │ (lod−1, 2x+1, 2y+1)        v (j)
//!   ────────────────────┼────────────────────        ↑
//!   (lod−1, 2x,   2y)   │ (lod−1, 2x+1, 2y)          └→ u (i)
//! ```
//!
//! Neighbours across an edge are found at the node's own LOD with
//! `CubeFace::wrap_cell`, which folds coordinates over cube-face edges
//! exactly; then the tree is walked up (a coarser leaf covers the cell) or
//! the cell is found split (finer leaves meet the edge).
//!
//! # Incremental updates
//!
//! A node's split/merge decision depends only on its distance D to the
//! camera, and D changes no faster than the camera moves. So each evaluated
//! node stores how far the camera may travel before the decision could flip
//! (`D − D_split` for a leaf, `D_merge − D` for a split node), and is queued
//! by "camera odometer + that margin". A frame pops only the nodes that are
//! due, top-down; neighbour relations are recomputed only for leaves that
//! changed and their neighbours (seed `002`'s dirty markers).

use std::cmp::Reverse;
use std::collections::{BTreeSet, BinaryHeap};

// Fx hashing for the maps keyed by chunk column: SipHash was a fifth of
// the main thread's time in a streaming view (keys are not attacker
// controlled).
use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use nebula_math::{DVec3, FaceEdge, ScreenSpace};
use nebula_voxel::{ChunkColumn, ChunkKey, ChunkLayout, CubeFace, LayerView, MAX_LOD, VoxelSource};

use crate::settings::{FOCUS_KEPT_ANGLE, FOCUS_MARGIN_ANGLE, FOCUS_MARGIN_VOXELS};
use crate::{
    BalanceMode, Camera, ChunkLodContext, CullMargin, FaceDirection, Frustum, Horizon, LodError, LodSettings,
    NeighborLodRelation, NodeBounds,
};

/// What changed in one update, so a renderer re-meshes only that.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LodChanges {
    /// Chunks of new leaves.
    pub added: Vec<ChunkKey>,
    /// Chunks of leaves that are gone.
    pub removed: Vec<ChunkKey>,
    /// Chunks of leaves that stayed but whose neighbour relations changed
    /// (re-mesh their seams).
    pub neighbours_changed: Vec<ChunkKey>,
}

/// Figures of the last update.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LodStats {
    /// Nodes whose decision was evaluated.
    pub nodes_evaluated: usize,
    /// Leaves in the tree.
    pub leaves: usize,
    /// Nodes in the tree (leaves and split nodes).
    pub nodes: usize,
    /// Leaves in view at the last [`LodTree::cull`].
    pub visible_leaves: usize,
    /// Leaves per LOD (index = LOD).
    pub lod_histogram: Vec<usize>,
    /// Largest LOD difference between neighbouring leaves.
    pub max_neighbor_lod_diff: u8,
    /// Passes of the balance filter ([`BalanceMode::Restricted`]).
    pub balance_passes: usize,
    /// Times a narrow view's focus was made (at the first update and each
    /// time the view left the last one, [`LodSettings::surround_fov_y_degrees`]).
    pub refocused: usize,
}

#[derive(Clone, Debug)]
struct Node {
    bounds: NodeBounds,
    /// First and last radial chunk layer that can hold surface.
    layers: (i32, i32),
    /// The same as seen from each [`LayerView`] (by its index).
    seen: [(i32, i32); 3],
    /// Bumped on every evaluation: stale queue entries carry an old one.
    generation: u32,
}

/// What a cull found ([`LodTree::cull_result`]): the leaves in view, with
/// their bounds, and the camera and margin they were culled for.
#[derive(Clone, Debug)]
pub struct Cull {
    visible: Vec<ChunkColumn>,
    visible_bounds: Vec<NodeBounds>,
    culled: Option<(Camera, CullMargin)>,
}

/// The LOD selection of a whole planet: one quadtree per cube face.
#[derive(Clone)]
pub struct LodTree {
    settings: LodSettings,
    screen: ScreenSpace,
    /// The constants outside a narrow view's focus (`screen` where the
    /// view is not narrow: [`LodSettings::surround_screen_space`]).
    surround: ScreenSpace,
    /// Where a narrow view refines with `screen`'s K: the frustum of the
    /// camera it was made for, opened by [`FOCUS_MARGIN_ANGLE`] and set
    /// back by [`FOCUS_MARGIN_VOXELS`]; `None` until the first update and
    /// for a view that is not narrow.
    focus: Option<Frustum>,
    layout: ChunkLayout,
    /// Lowest surface radius anywhere (occluder for horizon culling).
    min_surface_radius: f64,
    /// δ(L) per LOD, metres.
    errors: Vec<f64>,
    /// Every node of the SSE tree (leaves and split nodes).
    nodes: HashMap<ChunkColumn, Node>,
    /// Split nodes of the SSE tree.
    split: HashSet<ChunkColumn>,
    /// Split nodes of the tree that is drawn: `split`, plus the splits the
    /// balance filter forces in restricted mode.
    drawn_split: HashSet<ChunkColumn>,
    /// Leaves of the drawn tree, with their neighbour relations (by
    /// [`FaceEdge`]) and radial chunk layers.
    leaves: HashMap<ChunkColumn, ([NeighborLodRelation; 4], (i32, i32))>,
    visible: Vec<ChunkColumn>,
    /// The bounds of each of `visible`, alongside: the frame thread reads
    /// them for every leaf (narrowing a cull, the horizon, priorities)
    /// without a lookup in `nodes` each.
    visible_bounds: Vec<NodeBounds>,
    /// The camera and margin `visible` was culled for, while the tree has
    /// not changed since.
    culled: Option<(Camera, CullMargin)>,
    queue: BinaryHeap<Reverse<(u64, u8, ChunkColumn, u32)>>,
    odometer: f64,
    last_camera: Option<DVec3>,
    stats: LodStats,
}

impl LodTree {
    /// A tree of the six face roots for the planet of `source`.
    ///
    /// # Errors
    /// [`LodError`] for bad settings or a source that refuses the roots.
    pub fn new<S: VoxelSource + ?Sized>(source: &S, settings: LodSettings) -> Result<Self, LodError> {
        let layout = *source.layout();
        let (screen, surround) = Self::budgeted_screen(&settings, layout.max_lod())?;
        if settings.finest_lod > layout.max_lod() {
            return Err(LodError::BadFinestLod { finest_lod: settings.finest_lod, max_lod: layout.max_lod() });
        }
        // The error a node projects is its voxel edge: a leaf is split once
        // its voxels would subtend more than τ pixels (see `nebula_voxel`'s
        // `ChunkLayout::voxel_edge`; the geomorph shader uses the same).
        let errors = (0..=layout.max_lod()).map(|lod| layout.voxel_edge(lod)).collect();
        let mut tree = Self {
            settings,
            screen,
            surround,
            focus: None,
            layout,
            min_surface_radius: f64::INFINITY,
            errors,
            nodes: HashMap::default(),
            split: HashSet::default(),
            drawn_split: HashSet::default(),
            leaves: HashMap::default(),
            visible: Vec::new(),
            visible_bounds: Vec::new(),
            culled: None,
            queue: BinaryHeap::new(),
            odometer: 0.0,
            last_camera: None,
            stats: LodStats::default(),
        };
        for face in CubeFace::ALL {
            let root = ChunkColumn { face, lod: layout.max_lod(), x: 0, y: 0 };
            tree.insert_node(source, root)?;
            tree.min_surface_radius = tree.min_surface_radius.min(tree.nodes[&root].bounds.min_radius);
            // Due at once: the first update evaluates every root.
            tree.schedule(root, 0.0);
        }
        Ok(tree)
    }

    /// The screen-space constants the tree refines with, in the view's
    /// focus and around it: the settings' τ raised where the node budget
    /// needs it.
    fn budgeted_screen(settings: &LodSettings, max_lod: u8) -> Result<(ScreenSpace, ScreenSpace), LodError> {
        let threshold_px = settings.effective_threshold_px(max_lod)?;
        let budgeted = LodSettings { threshold_px, ..*settings };
        Ok((budgeted.screen_space()?, budgeted.surround_screen_space()?))
    }

    /// The settings in use.
    #[must_use]
    pub fn settings(&self) -> &LodSettings {
        &self.settings
    }

    /// The screen-space constants the tree refines with: K of the settings'
    /// screen and field of view, and the τ it refines to (the settings' τ,
    /// or a larger one where [`LodSettings::max_nodes`] needs it).
    #[must_use]
    pub fn screen_space(&self) -> &ScreenSpace {
        &self.screen
    }

    /// The screen-space constants the tree refines with outside a narrow
    /// view's focus ([`LodSettings::surround_screen_space`], τ as in
    /// [`LodTree::screen_space`]): the same as that where the view is not
    /// narrow.
    #[must_use]
    pub fn surround_space(&self) -> &ScreenSpace {
        &self.surround
    }

    /// Where a narrow view refines with its own K
    /// ([`LodSettings::surround_fov_y_degrees`]): the frustum of the camera
    /// it was made for, each side opened by 6° and its apex set back so
    /// that eyes within 32 voxels are inside. It is made again at the
    /// update whose camera's view, opened by 3° (what a cull ahead takes),
    /// no longer fits in it. `None` for a view that is not narrow and
    /// before the first update.
    #[must_use]
    pub fn focus(&self) -> Option<&Frustum> {
        self.focus.as_ref()
    }

    /// Changes the view the tree refines for (a zoom, a resized window, a
    /// quality setting): τ, the screen height and the vertical field of
    /// view. Every node is decided again at the next update; nothing
    /// happens when they are unchanged.
    ///
    /// # Errors
    /// As [`LodSettings::effective_threshold_px`]; the tree is unchanged
    /// then.
    pub fn set_view(&mut self, threshold_px: f64, screen_height_px: f64, fov_y_degrees: f64) -> Result<(), LodError> {
        let settings = LodSettings { threshold_px, screen_height_px, fov_y_degrees, ..self.settings };
        if settings == self.settings {
            return Ok(());
        }
        (self.screen, self.surround) = Self::budgeted_screen(&settings, self.layout.max_lod())?;
        self.settings = settings;
        self.focus = None;
        self.culled = None;
        let columns: Vec<ChunkColumn> = self.nodes.keys().copied().collect();
        self.queue.clear();
        for column in columns {
            self.schedule(column, 0.0);
        }
        Ok(())
    }

    /// The planet's coarsest LOD (the face roots).
    #[must_use]
    pub fn max_lod(&self) -> u8 {
        self.layout.max_lod()
    }

    /// Radius below which the planet is solid everywhere.
    #[must_use]
    pub fn min_surface_radius(&self) -> f64 {
        self.min_surface_radius
    }

    /// Figures of the last update (and cull). The largest neighbour LOD
    /// difference is counted on the call, over all leaves.
    #[must_use]
    pub fn stats(&self) -> LodStats {
        let mut stats = self.stats.clone();
        stats.nodes = self.nodes.len();
        stats.max_neighbor_lod_diff = self
            .leaves
            .values()
            .flat_map(|(relations, _)| relations)
            .filter_map(|r| match r {
                NeighborLodRelation::HigherThanNeighbor { lod_diff } => Some(*lod_diff),
                _ => None,
            })
            .max()
            .unwrap_or(0);
        stats
    }

    /// Bounds of a node of the tree, if it exists.
    #[must_use]
    pub fn node_bounds(&self, column: ChunkColumn) -> Option<&NodeBounds> {
        self.nodes.get(&column).map(|n| &n.bounds)
    }

    /// How far the parent of `column` lies from `eye`, over the distance
    /// at which the planet around a narrow view's focus splits it (with
    /// the surround's constants, [`LodSettings::surround_fov_y_degrees`];
    /// a view at least that wide refines everything with them): under 1,
    /// the surround is drawn at `column`'s LOD or finer there; past
    /// 1 / (1 − hysteresis), coarser (its parent merges). What a streamer
    /// asks to treat chunks that only a narrow lens draws in detail as a
    /// wider view would treat them at their distance. `None` for a face
    /// root, or a column whose parent the tree does not hold.
    #[must_use]
    pub fn surround_split_ratio(&self, column: ChunkColumn, eye: DVec3) -> Option<f64> {
        let parent = parent(column)?;
        let bounds = &self.nodes.get(&parent)?.bounds;
        Some(bounds.distance(eye) / self.transition_distance(&self.surround, parent.lod))
    }

    /// The leaves of the drawn tree, sorted.
    #[must_use]
    pub fn leaves(&self) -> Vec<ChunkColumn> {
        let mut leaves: Vec<_> = self.leaves.keys().copied().collect();
        leaves.sort_unstable();
        leaves
    }

    /// The leaves of the drawn tree, in no particular order (no sort, no
    /// copy: for per-frame walks over the whole tree).
    pub fn leaf_columns(&self) -> impl Iterator<Item = ChunkColumn> + '_ {
        self.leaves.keys().copied()
    }

    /// The radial chunk layers that can hold surface of any node of the
    /// tree (leaf or split), from the bounds it already holds.
    #[must_use]
    pub fn node_layers(&self, column: ChunkColumn) -> Option<std::ops::RangeInclusive<i32>> {
        self.nodes.get(&column).map(|node| node.layers.0..=node.layers.1)
    }

    /// Of [`LodTree::node_layers`], those an eye with `view` sees
    /// ([`VoxelSource::surface_chunk_layers_seen`]), asked of the source
    /// when the node was made.
    #[must_use]
    pub fn node_layers_seen(&self, column: ChunkColumn, view: LayerView) -> Option<std::ops::RangeInclusive<i32>> {
        self.nodes.get(&column).map(|node| {
            let (first, last) = node.seen[view.index()];
            first..=last
        })
    }

    /// The neighbour relations of a leaf, by [`FaceDirection`], as the
    /// mesher takes them.
    #[must_use]
    pub fn context(&self, column: ChunkColumn) -> Option<ChunkLodContext> {
        let (relations, _) = self.leaves.get(&column)?;
        let mut context = ChunkLodContext::uniform(column.lod);
        for (edge, relation) in FaceEdge::ALL.iter().zip(relations) {
            context.set(FaceDirection::from_face_edge(*edge), *relation);
        }
        Some(context)
    }

    /// The radial chunk layers of a leaf that can hold surface.
    #[must_use]
    pub fn layers(&self, column: ChunkColumn) -> Option<std::ops::RangeInclusive<i32>> {
        self.leaves.get(&column).map(|(_, layers)| layers.0..=layers.1)
    }

    /// For a leaf that meets a coarser neighbour on `edge`: which segment of
    /// the coarse edge it covers, as `(index, count)`: the coarse edge is
    /// cut into `count = 2^lod_diff` pieces of this leaf's size and the leaf
    /// meets piece `index` (counted along the leaf's own edge direction).
    #[must_use]
    pub fn coarse_edge_segment(&self, column: ChunkColumn, edge: FaceEdge) -> Option<(u32, u32)> {
        let NeighborLodRelation::HigherThanNeighbor { lod_diff } = self.leaves.get(&column)?.0[edge as usize] else {
            return None;
        };
        let along = match edge {
            FaceEdge::NegU | FaceEdge::PosU => column.y,
            FaceEdge::NegV | FaceEdge::PosV => column.x,
        };
        let count = 1u32 << lod_diff;
        Some((along % count, count))
    }

    /// The sphere whose horizon hides what lies behind it from every eye
    /// within `margin` metres of `eye`: the highest of two.
    ///
    /// - The planet's: the deepest LOD-0 surface
    ///   ([`VoxelSource::lowest_surface_radius`]) lowered by δ of the
    ///   coarsest LOD this tree draws out to that sphere's horizon (coarse
    ///   voxels round the drawn surface down by up to δ).
    /// - The eye's own ground ([`LodTree::local_occluder`]): the lowest
    ///   surface bound of the tree's leaves around the eye, as far round
    ///   as that sphere's horizon reaches. Near the ground over land it is
    ///   kilometres higher than the planet's, whose deepest sea floor puts
    ///   the horizon hundreds of kilometres away, where a narrow lens still
    ///   refines.
    ///
    /// Why not the planet-wide lowest bound of the tree
    /// ([`LodTree::min_surface_radius`]): it is hundreds of kilometres deep
    /// on an Earth (a coarse node's bound allows for its voxel and slope),
    /// so its horizon hides next to nothing near the ground. The occluder
    /// is not a proof that the drawn surface hides everything behind it (a
    /// coarse stand-in can dip lower), so what it hides should be drawn
    /// coarse, not left out. `None` where the source knows no such depth or
    /// the eye is below it.
    #[must_use]
    pub fn horizon_occluder<S: VoxelSource + ?Sized>(&self, source: &S, eye: DVec3, margin: f64) -> Option<f64> {
        let lowest = source.lowest_surface_radius()?;
        let d = eye.length() + margin;
        if d <= lowest {
            return None;
        }
        // How far the horizon is: the tangent from the eye to the sphere,
        // then as far again for terrain up to the eye's height beyond it.
        let reach = 2.0 * (d * d - lowest * lowest).sqrt();
        // The coarsest LOD drawn within reach: nodes closer than their
        // split distance are split.
        // (Outside a narrow view's focus nodes split nearer: its constants.)
        let lod = (0..=self.layout.max_lod())
            .find(|&l| self.transition_distance(&self.surround, l) > reach)
            .unwrap_or(self.layout.max_lod());
        let planet = (lowest - source.geometric_error(lod)).max(self.min_surface_radius);
        Some(self.local_occluder(eye, margin).map_or(planet, |local| local.max(planet)))
    }

    /// The highest sphere under every surface the tree's leaves bound
    /// within its own horizon seen from every eye within `margin` of
    /// `eye`; `None` where none is found in a few passes (or the eye is
    /// under the ground).
    ///
    /// Why it hides: a line of sight from such an eye that passes under the
    /// sphere (radius r) enters it within acos(r / d) of the eye's
    /// direction (d: the eye's farthest distance from the centre), where
    /// every leaf's surface, at its own LOD and every finer one, cave air
    /// included, lies above r ([`VoxelSource::surface_bounds`]): the point
    /// where it enters is inside the drawn rock, so the line crossed the
    /// drawn surface before. The sphere is the fixed point r = lowest bound
    /// within acos(r / d), found by lowering r until the leaves out to its
    /// own horizon bear it.
    #[must_use]
    pub fn local_occluder(&self, eye: DVec3, margin: f64) -> Option<f64> {
        let d = eye.length();
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        let far = d + margin;
        let direction = eye / d;
        // How far the eye's direction moves within the margin.
        let drift = (margin / d).min(1.0).asin();
        let mut r = far;
        for _ in 0..24 {
            let reach = drift + if r < far { (r / far).acos() } else { 0.0 };
            let lowest = self.lowest_bound_within(direction, reach, r);
            if lowest >= r {
                return (r < d).then_some(r);
            }
            // A little lower than the lowest found: the next, wider cap
            // seldom holds lower ground by less than that.
            r = lowest - 0.02 * (far - lowest);
        }
        None
    }

    /// The lowest surface bound of the leaves at most `reach` radians from
    /// `direction`, where it is below `below` (`below` otherwise). A node
    /// all above `below` is not walked: every surface of its patch, at its
    /// LOD and every finer one, lies within its bounds.
    fn lowest_bound_within(&self, direction: DVec3, reach: f64, below: f64) -> f64 {
        let cos_near = reach.min(std::f64::consts::PI).cos();
        let mut lowest = below;
        let mut stack: Vec<ChunkColumn> =
            CubeFace::ALL.iter().map(|&face| ChunkColumn { face, lod: self.layout.max_lod(), x: 0, y: 0 }).collect();
        while let Some(column) = stack.pop() {
            let Some(node) = self.nodes.get(&column) else { continue };
            let bounds = &node.bounds;
            if bounds.min_radius >= lowest {
                continue;
            }
            // Within reach: its nearest point is (centre's angle minus its
            // angular radius); the cosine test first, the angle only near
            // the cap's rim.
            let cos_centre = direction.dot(bounds.center_direction);
            if cos_centre < cos_near && cos_centre.clamp(-1.0, 1.0).acos() - bounds.angular_radius > reach {
                continue;
            }
            if self.drawn_is_split(&column) {
                stack.extend(children_of(column));
            } else {
                lowest = bounds.min_radius;
            }
        }
        lowest
    }

    /// The leaf chunks in view at the last [`LodTree::cull`].
    #[must_use]
    pub fn visible_chunks(&self) -> Vec<ChunkKey> {
        self.visible.iter().flat_map(|&c| self.layers(c).into_iter().flatten().map(move |l| c.chunk(l))).collect()
    }

    /// The leaf columns in view at the last [`LodTree::cull`].
    #[must_use]
    pub fn visible_leaves(&self) -> &[ChunkColumn] {
        &self.visible
    }

    /// [`LodTree::visible_leaves`] with the bounds of each.
    pub fn visible_leaves_with_bounds(&self) -> impl Iterator<Item = (ChunkColumn, &NodeBounds)> {
        self.visible.iter().copied().zip(&self.visible_bounds)
    }

    /// Updates the tree for `camera`, evaluating only the nodes whose
    /// decision may have changed since they were last evaluated.
    ///
    /// # Errors
    /// [`LodError`] for a bad camera (NaN, inside the planet, degenerate
    /// view), checked before anything changes, so the tree is as it was; or
    /// a node the voxel source refuses, after which the tree may be part
    /// way through the update and should be rebuilt.
    pub fn update<S: VoxelSource + ?Sized>(&mut self, source: &S, camera: &Camera) -> Result<LodChanges, LodError> {
        self.update_with(source, camera, false)
    }

    /// Like [`LodTree::update`], but evaluates every node of the tree (the
    /// full traversal the incremental update is measured against). Gives
    /// the same tree.
    ///
    /// # Errors
    /// As [`LodTree::update`].
    pub fn update_full<S: VoxelSource + ?Sized>(
        &mut self,
        source: &S,
        camera: &Camera,
    ) -> Result<LodChanges, LodError> {
        self.update_with(source, camera, true)
    }

    fn update_with<S: VoxelSource + ?Sized>(
        &mut self,
        source: &S,
        camera: &Camera,
        full: bool,
    ) -> Result<LodChanges, LodError> {
        camera.check()?;
        let distance = camera.position.length();
        if distance < self.min_surface_radius {
            return Err(LodError::CameraInsidePlanet { distance, min_surface_radius: self.min_surface_radius });
        }
        // A narrow view refines its focus with its own K: once the camera's
        // view (opened by the margin a cull ahead takes) leaves the focus,
        // a new one is made around it, and the nodes in one focus and not
        // the other are decided again.
        let fov = self.settings.fov_y_degrees;
        let refocus = self.surround.k() < self.screen.k()
            && !self.focus.is_some_and(|focus| focus.covers_opened(camera, fov, FOCUS_KEPT_ANGLE));
        let old_focus = self.focus;
        if refocus {
            let margin =
                CullMargin { angle: FOCUS_MARGIN_ANGLE, distance: FOCUS_MARGIN_VOXELS * self.layout.voxel_edge(0) };
            self.focus = Some(Frustum::with_margin(camera, fov, margin));
            self.stats.refocused += 1;
        }
        let eye = camera.position;
        if let Some(last) = self.last_camera {
            self.odometer += last.distance(eye);
        }
        self.last_camera = Some(eye);
        let mut changed = BTreeSet::new();
        let mut evaluated = 0;
        if full {
            self.queue.clear();
            for face in CubeFace::ALL {
                let root = ChunkColumn { face, lod: self.layout.max_lod(), x: 0, y: 0 };
                self.evaluate(source, root, eye, &mut changed, &mut evaluated, true)?;
            }
        } else {
            if refocus {
                self.refocus(source, old_focus, eye, &mut changed, &mut evaluated)?;
            }
            let mut due = Vec::new();
            while let Some(Reverse((at, _, _, _))) = self.queue.peek() {
                if f64::from_bits(*at) > self.odometer {
                    break;
                }
                let Some(Reverse((_, _, column, generation))) = self.queue.pop() else { break };
                due.push((column, generation));
            }
            // Top-down: coarse LODs (small depth) first.
            due.sort_by_key(|(c, _)| Reverse(c.lod));
            for (column, generation) in due {
                if self.nodes.get(&column).is_some_and(|n| n.generation == generation) {
                    self.evaluate(source, column, eye, &mut changed, &mut evaluated, false)?;
                }
            }
        }
        self.stats.nodes_evaluated = evaluated;
        if !changed.is_empty() {
            self.culled = None;
        }
        let restricted = self.settings.balance == BalanceMode::Restricted;
        if restricted || full || self.leaves.is_empty() {
            // Whole-tree path: the balance filter may move any leaf.
            let old_leaves = self.leaves.clone();
            if !changed.is_empty() || self.leaves.is_empty() || full {
                self.rebuild_drawn_tree(source, &changed, full)?;
            }
            let changes = self.diff(&old_leaves);
            self.recount();
            Ok(changes)
        } else {
            Ok(self.apply_changes(&changed))
        }
    }

    /// Incremental bookkeeping after an unrestricted update: only the
    /// columns that split or merged and the leaves around them are touched.
    fn apply_changes(&mut self, changed: &BTreeSet<ChunkColumn>) -> LodChanges {
        let keys = |column: ChunkColumn, layers: (i32, i32)| (layers.0..=layers.1).map(move |l| column.chunk(l));
        let mut changes = LodChanges::default();
        let mut added = Vec::new();
        for &column in changed {
            let is_leaf =
                self.nodes.contains_key(&column) && !self.split.contains(&column) && self.drawn_exists(column);
            match (is_leaf, self.leaves.get(&column)) {
                (true, None) => added.push(column),
                (false, Some(&(_, layers))) => {
                    self.leaves.remove(&column);
                    self.stats.lod_histogram[usize::from(column.lod)] -= 1;
                    changes.removed.extend(keys(column, layers));
                }
                _ => {}
            }
        }
        for &column in &added {
            let layers = self.nodes[&column].layers;
            self.leaves.insert(column, ([NeighborLodRelation::Same; 4], layers));
            self.stats.lod_histogram[usize::from(column.lod)] += 1;
            changes.added.extend(keys(column, layers));
        }
        let mut dirty = BTreeSet::new();
        for &column in changed {
            dirty.extend(self.leaves_touching(column));
        }
        let added: HashSet<ChunkColumn> = added.into_iter().collect();
        for column in dirty {
            let relations = FaceEdge::ALL.map(|edge| self.relation(column, edge));
            if let Some(entry) = self.leaves.get_mut(&column) {
                if entry.0 != relations && !added.contains(&column) {
                    changes.neighbours_changed.extend(keys(column, entry.1));
                }
                entry.0 = relations;
            }
        }
        self.stats.leaves = self.leaves.len();
        changes.added.sort_unstable();
        changes.removed.sort_unstable();
        changes.neighbours_changed.sort_unstable();
        changes
    }

    /// Leaf count and LOD histogram from scratch.
    fn recount(&mut self) {
        let mut histogram = vec![0; usize::from(self.layout.max_lod()) + 1];
        for c in self.leaves.keys() {
            histogram[usize::from(c.lod)] += 1;
        }
        self.stats.lod_histogram = histogram;
        self.stats.leaves = self.leaves.len();
    }

    /// Whether `column` is split in the drawn tree.
    fn drawn_is_split(&self, column: &ChunkColumn) -> bool {
        if self.settings.balance == BalanceMode::Restricted {
            self.drawn_split.contains(column)
        } else {
            self.split.contains(column)
        }
    }

    /// Decides again, after the focus moved from `old`, every node whose K
    /// changed with it (in one focus and not the other; where there was
    /// none, every node had the view's K, so those outside the new one),
    /// walking the tree
    /// from the roots through its split nodes. The others keep their
    /// decisions and their checks: their split distance is the same.
    fn refocus<S: VoxelSource + ?Sized>(
        &mut self,
        source: &S,
        old: Option<Frustum>,
        eye: DVec3,
        changed: &mut BTreeSet<ChunkColumn>,
        evaluated: &mut usize,
    ) -> Result<(), LodError> {
        let Some(new) = self.focus else { return Ok(()) };
        let mut stack: Vec<ChunkColumn> =
            CubeFace::ALL.iter().map(|&face| ChunkColumn { face, lod: self.layout.max_lod(), x: 0, y: 0 }).collect();
        while let Some(column) = stack.pop() {
            let Some(node) = self.nodes.get(&column) else { continue };
            // With no focus before, every node had the view's K (`split_distance`).
            let was_in = old.is_none_or(|old| !old.excludes(&node.bounds));
            // (Nodes this walk made or split were decided with the new one.)
            if was_in == new.excludes(&node.bounds) && !changed.contains(&column) {
                self.evaluate(source, column, eye, changed, evaluated, false)?;
            }
            if self.split.contains(&column) {
                stack.extend(children_of(column));
            }
        }
        Ok(())
    }

    /// Applies the split/merge rule to `column` and schedules its next
    /// check. Newly split children are evaluated at once; with `recurse`,
    /// children of a node that stays split are too.
    fn evaluate<S: VoxelSource + ?Sized>(
        &mut self,
        source: &S,
        column: ChunkColumn,
        eye: DVec3,
        changed: &mut BTreeSet<ChunkColumn>,
        evaluated: &mut usize,
        recurse: bool,
    ) -> Result<(), LodError> {
        *evaluated += 1;
        let bounds = &self.nodes[&column].bounds;
        let distance = bounds.distance(eye);
        let split_distance = self.split_distance(column.lod, bounds);
        let merge_distance = split_distance / (1.0 - self.settings.hysteresis);
        let is_split = self.split.contains(&column);
        let (now_split, margin) = if column.lod <= self.settings.finest_lod {
            (false, f64::INFINITY)
        } else if is_split {
            if distance > merge_distance {
                (false, distance - split_distance)
            } else {
                (true, merge_distance - distance)
            }
        } else if distance < split_distance {
            (true, merge_distance - distance)
        } else {
            (false, distance - split_distance)
        };
        if now_split && !is_split {
            // Children first, so an error leaves the tree as it was.
            let children = children_of(column);
            for child in children {
                self.insert_node(source, child)?;
            }
            self.split.insert(column);
            changed.insert(column);
            changed.extend(children);
            self.schedule(column, margin);
            for child in children {
                self.evaluate(source, child, eye, changed, evaluated, recurse)?;
            }
        } else if !now_split && is_split {
            self.remove_subtree(column, changed);
            self.split.remove(&column);
            changed.insert(column);
            self.schedule(column, margin);
        } else {
            self.schedule(column, margin);
            if recurse && is_split {
                for child in children_of(column) {
                    self.evaluate(source, child, eye, changed, evaluated, recurse)?;
                }
            }
        }
        Ok(())
    }

    /// D_split for a node at `lod` with `bounds`: closer than this, its
    /// error exceeds τ (with the view's K in a narrow view's focus, the
    /// surround's outside it).
    fn split_distance(&self, lod: u8, bounds: &NodeBounds) -> f64 {
        let screen = match &self.focus {
            Some(focus) if focus.excludes(bounds) => &self.surround,
            _ => &self.screen,
        };
        self.transition_distance(screen, lod)
    }

    /// D_split at `lod` with `screen`'s constants.
    fn transition_distance(&self, screen: &ScreenSpace, lod: u8) -> f64 {
        screen.transition_distance(self.errors[usize::from(lod)])
    }

    fn schedule(&mut self, column: ChunkColumn, margin: f64) {
        let Some(node) = self.nodes.get_mut(&column) else { return };
        node.generation = node.generation.wrapping_add(1);
        if margin.is_finite() {
            // Shave a hair off so rounding never delays a due check.
            let at = self.odometer + (margin * (1.0 - 1e-9) - 1e-9).max(0.0);
            self.queue.push(Reverse((at.to_bits(), column.lod, column, node.generation)));
        }
    }

    /// Re-reads the surface bounds of every node that covers one of
    /// `columns` (any LOD; typically the dirty chunks an edit returned), so
    /// that terrain an edit moved outside the old bounds is selected, culled
    /// and meshed correctly. Returns the chunks that leaves gained (new
    /// radial layers to mesh); their next decisions use the new bounds.
    ///
    /// # Errors
    /// [`LodError::Voxel`] if the source refuses a node.
    pub fn refresh_bounds<S: VoxelSource + ?Sized>(
        &mut self,
        source: &S,
        columns: impl IntoIterator<Item = ChunkColumn>,
    ) -> Result<Vec<ChunkKey>, LodError> {
        self.culled = None;
        let mut covering = BTreeSet::new();
        for column in columns {
            let mut node = column;
            loop {
                if self.nodes.contains_key(&node) {
                    covering.insert(node);
                }
                if node.lod >= self.layout.max_lod() {
                    break;
                }
                node = parent_of(node);
            }
        }
        let mut gained = Vec::new();
        for column in covering {
            let survey = source.surface_survey(column)?;
            let layers = survey.layers(LayerView::All).into_inner();
            let bounds = NodeBounds::new(&self.layout, column, &survey.bounds);
            self.min_surface_radius = self.min_surface_radius.min(bounds.min_radius);
            if let Some(node) = self.nodes.get_mut(&column) {
                node.bounds = bounds;
                node.layers = layers;
                node.seen = LayerView::ALL.map(|view| survey.layers(view).into_inner());
            }
            if let Some(leaf) = self.leaves.get_mut(&column) {
                let old = leaf.1;
                gained.extend((layers.0..=layers.1).filter(|l| *l < old.0 || *l > old.1).map(|l| column.chunk(l)));
                leaf.1 = layers;
            }
            // Decide again with the new bounds at the next update.
            self.schedule(column, 0.0);
        }
        Ok(gained)
    }

    fn insert_node<S: VoxelSource + ?Sized>(&mut self, source: &S, column: ChunkColumn) -> Result<(), LodError> {
        if self.nodes.contains_key(&column) {
            return Ok(());
        }
        // One question to the source for the bounds and every view's layers.
        let survey = source.surface_survey(column)?;
        let bounds = NodeBounds::new(&self.layout, column, &survey.bounds);
        let seen = LayerView::ALL.map(|view| survey.layers(view).into_inner());
        self.nodes.insert(column, Node { bounds, layers: seen[LayerView::All.index()], seen, generation: 0 });
        Ok(())
    }

    fn remove_subtree(&mut self, column: ChunkColumn, changed: &mut BTreeSet<ChunkColumn>) {
        for child in children_of(column) {
            if self.split.remove(&child) {
                self.remove_subtree(child, changed);
            }
            self.nodes.remove(&child);
            changed.insert(child);
        }
    }

    /// Derives the drawn tree from the SSE tree: the same in unrestricted
    /// mode; in restricted mode its least refinement with neighbours at
    /// most one LOD apart (a monotone filter: only splits, so it ends).
    fn rebuild_drawn_tree<S: VoxelSource + ?Sized>(
        &mut self,
        source: &S,
        changed: &BTreeSet<ChunkColumn>,
        full: bool,
    ) -> Result<(), LodError> {
        self.stats.balance_passes = 0;
        let restricted = self.settings.balance == BalanceMode::Restricted;
        if restricted {
            self.drawn_split.clone_from(&self.split);
            loop {
                let leaves = self.drawn_leaves();
                let to_split: Vec<ChunkColumn> =
                    leaves.into_iter().filter(|&leaf| self.violates_balance(leaf)).collect();
                self.stats.balance_passes += 1;
                if to_split.is_empty() {
                    break;
                }
                for &column in &to_split {
                    for child in children_of(column) {
                        self.insert_node(source, child)?;
                    }
                }
                self.drawn_split.extend(to_split);
            }
            // Forget nodes of forced splits that are no longer drawn.
            let drawn = self.drawn_leaves();
            let split = &self.split;
            let drawn_split = &self.drawn_split;
            self.nodes.retain(|c, _| {
                drawn.contains(c)
                    || drawn_split.contains(c)
                    || c.lod == self.layout.max_lod()
                    || split.contains(&parent_of(*c))
            });
        }
        // Relations: all leaves after a full traversal or in restricted mode
        // (the filter may have moved any leaf), else only leaves near change.
        let leaves = self.drawn_leaves();
        let dirty: Vec<ChunkColumn> = if full || restricted || self.leaves.is_empty() {
            leaves.iter().copied().collect()
        } else {
            let mut dirty = BTreeSet::new();
            for &column in changed {
                dirty.extend(self.leaves_touching(column));
            }
            dirty.into_iter().filter(|c| leaves.contains(c)).collect()
        };
        self.leaves.retain(|c, _| leaves.contains(c));
        for column in
            dirty.into_iter().chain(leaves.iter().copied().filter(|c| !self.leaves.contains_key(c))).collect::<Vec<_>>()
        {
            let relations = FaceEdge::ALL.map(|edge| self.relation(column, edge));
            let layers = self.nodes[&column].layers;
            self.leaves.insert(column, (relations, layers));
        }
        Ok(())
    }

    /// Leaves of the drawn tree.
    fn drawn_leaves(&self) -> HashSet<ChunkColumn> {
        let mut leaves = HashSet::default();
        let mut stack: Vec<ChunkColumn> =
            CubeFace::ALL.iter().map(|&face| ChunkColumn { face, lod: self.layout.max_lod(), x: 0, y: 0 }).collect();
        while let Some(column) = stack.pop() {
            if self.drawn_is_split(&column) {
                stack.extend(children_of(column));
            } else {
                leaves.insert(column);
            }
        }
        leaves
    }

    /// Whether a drawn leaf has a neighbour more than one LOD finer.
    fn violates_balance(&self, leaf: ChunkColumn) -> bool {
        FaceEdge::ALL.iter().any(|&edge| {
            let Some(across) = self.same_lod_neighbor(leaf, edge) else { return false };
            if !self.drawn_split.contains(&across) {
                return false;
            }
            let back = self.back_edge(leaf, edge, across);
            edge_children(across, back).iter().any(|c| self.drawn_split.contains(c))
        })
    }

    /// The cell at `column`'s LOD across `edge` (on this or the next face).
    fn same_lod_neighbor(&self, column: ChunkColumn, edge: FaceEdge) -> Option<ChunkColumn> {
        let (di, dj) = edge.step();
        let per_edge = i64::from(self.layout.chunks_per_edge(column.lod));
        let (face, x, y) = column.face.wrap_cell(i64::from(column.x) + di, i64::from(column.y) + dj, per_edge)?;
        Some(ChunkColumn { face, lod: column.lod, x: x as u32, y: y as u32 })
    }

    /// The edge of `across` that faces back to `column`.
    fn back_edge(&self, column: ChunkColumn, edge: FaceEdge, across: ChunkColumn) -> FaceEdge {
        if across.face == column.face { edge.opposite() } else { column.face.neighbor(edge).edge }
    }

    /// Whether `column` exists in the drawn tree (all its ancestors split).
    fn drawn_exists(&self, column: ChunkColumn) -> bool {
        let mut node = column;
        while node.lod < self.layout.max_lod() {
            node = parent_of(node);
            if !self.drawn_is_split(&node) {
                return false;
            }
        }
        true
    }

    /// The relation of drawn leaf `column` to what lies across `edge`.
    fn relation(&self, column: ChunkColumn, edge: FaceEdge) -> NeighborLodRelation {
        let Some(across) = self.same_lod_neighbor(column, edge) else { return NeighborLodRelation::Same };
        if self.drawn_is_split(&across) {
            return NeighborLodRelation::LowerThanNeighbor;
        }
        // Walk up to the leaf that covers the cell.
        let mut cell = across;
        let mut diff = 0u8;
        while !self.drawn_exists(cell) {
            cell = parent_of(cell);
            diff += 1;
        }
        if diff == 0 { NeighborLodRelation::Same } else { NeighborLodRelation::HigherThanNeighbor { lod_diff: diff } }
    }

    /// Drawn leaves that meet `column`'s region: inside it, or across any
    /// of its edges (coarser, same or finer).
    fn leaves_touching(&self, column: ChunkColumn) -> Vec<ChunkColumn> {
        let mut found = Vec::new();
        // The leaf covering the region itself, or the leaves inside it.
        self.leaves_in(column, &mut found);
        for edge in FaceEdge::ALL {
            let Some(across) = self.same_lod_neighbor(column, edge) else { continue };
            let back = self.back_edge(column, edge, across);
            let mut cell = across;
            while !self.drawn_exists(cell) {
                cell = parent_of(cell);
            }
            if cell == across {
                self.leaves_along(across, back, &mut found);
            } else {
                found.push(cell);
            }
        }
        found
    }

    /// Drawn leaves inside `column` (or the leaf covering it).
    fn leaves_in(&self, column: ChunkColumn, found: &mut Vec<ChunkColumn>) {
        let mut cell = column;
        while !self.drawn_exists(cell) {
            cell = parent_of(cell);
        }
        if cell != column {
            found.push(cell);
            return;
        }
        let mut stack = vec![column];
        while let Some(c) = stack.pop() {
            if self.drawn_is_split(&c) {
                stack.extend(children_of(c));
            } else {
                found.push(c);
            }
        }
    }

    /// Drawn leaves inside existing node `column` that touch its `edge`.
    fn leaves_along(&self, column: ChunkColumn, edge: FaceEdge, found: &mut Vec<ChunkColumn>) {
        if self.drawn_is_split(&column) {
            for child in edge_children(column, edge) {
                self.leaves_along(child, edge, found);
            }
        } else {
            found.push(column);
        }
    }

    fn diff(&self, old_leaves: &HashMap<ChunkColumn, ([NeighborLodRelation; 4], (i32, i32))>) -> LodChanges {
        let keys = |column: ChunkColumn, layers: (i32, i32)| (layers.0..=layers.1).map(move |l| column.chunk(l));
        let mut changes = LodChanges::default();
        for (&column, &(relations, layers)) in &self.leaves {
            match old_leaves.get(&column) {
                None => changes.added.extend(keys(column, layers)),
                Some(&(old, _)) if old != relations => changes.neighbours_changed.extend(keys(column, layers)),
                Some(_) => {}
            }
        }
        for (&column, &(_, layers)) in old_leaves {
            if !self.leaves.contains_key(&column) {
                changes.removed.extend(keys(column, layers));
            }
        }
        changes.added.sort_unstable();
        changes.removed.sort_unstable();
        changes.neighbours_changed.sort_unstable();
        changes
    }

    /// Picks the leaves in view of `camera` (not behind the horizon of the
    /// lowest surface, not outside the frustum), walking the tree from the
    /// roots so that hidden subtrees are skipped whole. Read the result
    /// with [`LodTree::visible_leaves`] and [`LodTree::visible_chunks`].
    ///
    /// # Errors
    /// [`LodError::BadCamera`] for NaN, infinite or degenerate camera data.
    pub fn cull(&mut self, camera: &Camera) -> Result<(), LodError> {
        self.cull_with_margin(camera, CullMargin::default())
    }

    /// [`LodTree::cull`] for every camera within `margin` of `camera`: the
    /// leaves any of them could see (a cull made ahead, on another thread,
    /// for where the camera is going; [`LodTree::cull_covers`] says
    /// whether it holds for the camera that came).
    ///
    /// # Errors
    /// [`LodError::BadCamera`].
    pub fn cull_with_margin(&mut self, camera: &Camera, margin: CullMargin) -> Result<(), LodError> {
        camera.check()?;
        self.culled = None;
        let frustum = Frustum::with_margin(camera, self.settings.fov_y_degrees, margin);
        let horizon = Horizon::around(camera.position, margin.distance, self.min_surface_radius);
        let mut visible = Vec::new();
        let mut stack: Vec<ChunkColumn> =
            CubeFace::ALL.iter().map(|&face| ChunkColumn { face, lod: self.layout.max_lod(), x: 0, y: 0 }).collect();
        while let Some(column) = stack.pop() {
            let Some(node) = self.nodes.get(&column) else { continue };
            if horizon.hides(&node.bounds) || frustum.excludes(&node.bounds) {
                continue;
            }
            if self.drawn_is_split(&column) {
                stack.extend(children_of(column));
            } else {
                visible.push((column, node.bounds));
            }
        }
        visible.sort_unstable_by_key(|(column, _)| *column);
        self.stats.visible_leaves = visible.len();
        (self.visible, self.visible_bounds) = visible.into_iter().unzip();
        self.culled = Some((*camera, margin));
        Ok(())
    }

    /// Narrows the visible leaves of a cull that covers `camera`
    /// ([`LodTree::cull_covers`]) to those `camera` itself may see: each
    /// leaf's own frustum and horizon tests, no walk of the tree.
    ///
    /// # Errors
    /// [`LodError::BadCamera`]; [`LodError::NotCovered`] when the last cull
    /// does not cover `camera` (the visible leaves are unchanged then).
    pub fn narrow_cull(&mut self, camera: &Camera) -> Result<(), LodError> {
        camera.check()?;
        if !self.cull_covers(camera) {
            return Err(LodError::NotCovered);
        }
        let frustum = Frustum::new(camera, self.settings.fov_y_degrees);
        let horizon = Horizon::new(camera.position, self.min_surface_radius);
        let mut kept = 0;
        for n in 0..self.visible.len() {
            let bounds = &self.visible_bounds[n];
            if !horizon.hides(bounds) && !frustum.excludes(bounds) {
                self.visible.swap(kept, n);
                self.visible_bounds.swap(kept, n);
                kept += 1;
            }
        }
        self.visible.truncate(kept);
        self.visible_bounds.truncate(kept);
        self.stats.visible_leaves = kept;
        self.culled = Some((*camera, CullMargin::default()));
        Ok(())
    }

    /// The last cull's result ([`LodTree::cull_with_margin`] or
    /// [`LodTree::narrow_cull`]): the visible leaves, their bounds and the
    /// camera they were culled for, to put onto another copy of this tree
    /// ([`LodTree::set_cull`]) instead of copying the whole tree (an
    /// Earth's tree through a narrow lens has some 276,000 nodes).
    #[must_use]
    pub fn cull_result(&self) -> Cull {
        Cull { visible: self.visible.clone(), visible_bounds: self.visible_bounds.clone(), culled: self.culled }
    }

    /// Takes `cull` as this tree's last cull. Only for a cull made on a
    /// copy of this very tree, its nodes unchanged since it was copied
    /// (the caller keeps track; nothing here can check it cheaply): the
    /// leaves and bounds are taken as they are.
    pub fn set_cull(&mut self, cull: Cull) {
        self.stats.visible_leaves = cull.visible.len();
        (self.visible, self.visible_bounds, self.culled) = (cull.visible, cull.visible_bounds, cull.culled);
    }

    /// Whether the visible leaves hold every leaf `camera` sees: the last
    /// cull's camera and margin cover it (its eye within the margin's
    /// distance, its frustum inside the opened one) and the tree has not
    /// changed since.
    #[must_use]
    pub fn cull_covers(&self, camera: &Camera) -> bool {
        self.culled.is_some_and(|culled| cull_reaches(culled, self.settings.fov_y_degrees, camera))
    }

    /// The camera and margin the last cull was made for (`None` before
    /// the first): what [`cull_reaches`] takes.
    #[must_use]
    pub fn culled_for(&self) -> Option<(Camera, CullMargin)> {
        self.culled
    }
}

impl Cull {
    /// The camera and margin this cull was made for (`None` if none was
    /// made): what [`cull_reaches`] takes.
    #[must_use]
    pub fn culled_for(&self) -> Option<(Camera, CullMargin)> {
        self.culled
    }
}

/// Whether a cull made for `(culled, margin)` holds every leaf `camera`
/// sees with a field of view of `fov_y_degrees` (the tree unchanged since):
/// its eye within the margin's distance, its frustum inside the opened one.
#[must_use]
pub fn cull_reaches((culled, margin): (Camera, CullMargin), fov_y_degrees: f64, camera: &Camera) -> bool {
    culled.position.distance(camera.position) <= margin.distance
        && Frustum::with_margin(&culled, fov_y_degrees, margin).covers(camera, fov_y_degrees)
}

/// The four children of `column` (one LOD finer, in the order (0,0),
/// (1,0), (0,1), (1,1)), or `None` at LOD 0, past [`MAX_LOD`] or where the
/// coordinates would overflow.
#[must_use]
pub fn children(column: ChunkColumn) -> Option<[ChunkColumn; 4]> {
    if column.lod == 0 || column.lod > MAX_LOD {
        return None;
    }
    // The last child's coordinates must fit.
    column.x.checked_mul(2)?.checked_add(1)?;
    column.y.checked_mul(2)?.checked_add(1)?;
    Some(children_of(column))
}

/// The column one LOD coarser that contains `column`, or `None` past
/// [`MAX_LOD`] (a planet's roots have no parent on the planet: compare
/// with its `max_lod`).
#[must_use]
pub fn parent(column: ChunkColumn) -> Option<ChunkColumn> {
    (column.lod < MAX_LOD).then(|| parent_of(column))
}

/// [`children`] where the tree knows `column` is above LOD 0.
fn children_of(column: ChunkColumn) -> [ChunkColumn; 4] {
    debug_assert!(column.lod > 0, "{column:?} has no children");
    let (x, y, lod) = (column.x * 2, column.y * 2, column.lod - 1);
    [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| ChunkColumn { face: column.face, lod, x: x + dx, y: y + dy })
}

/// [`parent`] where the tree knows `column` is below its roots.
fn parent_of(column: ChunkColumn) -> ChunkColumn {
    ChunkColumn { face: column.face, lod: column.lod + 1, x: column.x / 2, y: column.y / 2 }
}

/// The two children of `column` along its `edge`.
fn edge_children(column: ChunkColumn, edge: FaceEdge) -> [ChunkColumn; 2] {
    let [c00, c10, c01, c11] = children_of(column);
    match edge {
        FaceEdge::NegU => [c00, c01],
        FaceEdge::PosU => [c10, c11],
        FaceEdge::NegV => [c00, c10],
        FaceEdge::PosV => [c01, c11],
    }
}
