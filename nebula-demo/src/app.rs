//! The planet as a bevy_ecs world: resources for the LOD tree, the mesh
//! cache and the job queue, and systems that update the LOD selection,
//! collect finished meshes, choose what to draw and hand out meshing jobs.
//! Rendering reads the world; windowing lives in `main.rs`.
//!
//! # What is drawn: every frame complete, never waiting for meshing
//!
//! Meshes are made with [`MeshOptions::STREAMING`]: they do not depend on
//! their neighbours' LODs (skirts hang on every side, and their depth is
//! chosen per side at draw time from the LODs actually drawn next to the
//! chunk). So any chunk may be shown the moment its column is meshed, and a
//! LOD change never waits for neighbours to be re-meshed. Each frame:
//!
//! ```text
//!   for each visible leaf L of the LOD tree:
//!     L's column meshed            → draw L
//!     else its 4 children meshed   → draw them (a merge not ready yet)
//!     else nearest meshed ancestor → draw it instead (a split not ready yet);
//!                                    leaves under a drawn ancestor are not drawn
//!   skirt depth per side = skirt_depth(L, LOD drawn across that side)
//! ```
//!
//! The six face roots are meshed before the first frame, so an ancestor
//! always exists and no frame has a hole. Stand-ins are asked for every
//! [`STAND_IN_LEVEL_STEP`] LODs above a leaf. Jobs go to a priority queue
//! (largest projected voxel first, which is coarse-first and nearest-first),
//! rebuilt every frame from what is wanted, so a chunk that left the view is
//! never meshed (cancellation); workers on meshing's own thread pool take
//! the top job.

use std::collections::{BinaryHeap, HashMap, HashSet};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use bevy_ecs::prelude::*;
use nebula_lod::{Camera, LodSettings, LodTree, children, parent};
use nebula_math::{DVec3, FaceDirection};
use nebula_meshing::{
    ChunkDraw, ChunkLodContext, ChunkMeshBuffer, FrameDraw, MeshOptions, RenderVertex, mesh_chunk, skirt_depth,
};
use nebula_voxel::{ChunkColumn, ChunkKey, EditedSource, ProceduralPlanet, VoxelSource};

use crate::gpu::{DebugView, FrameParams, Gpu, GpuMesh};

/// The voxels the demo draws: the procedural planet with the player's
/// edits (none without `--world`).
pub type PlanetVoxels = EditedSource<ProceduralPlanet>;

/// The planet's voxels, shared with meshing jobs.
#[derive(Resource, Clone)]
pub struct Planet(pub Arc<PlanetVoxels>);

/// How many times the voxels were replaced by edited ones
/// ([`PlanetApp::set_voxels`]): a mesh made from an older generation of an
/// edited chunk is shown only until the new one is ready.
#[derive(Resource, Clone, Copy, Default)]
pub struct VoxelsGeneration(pub u64);

/// The LOD selection.
#[derive(Resource)]
pub struct Lod {
    /// The quadtrees.
    pub tree: LodTree,
}

/// The camera this frame.
#[derive(Resource, Clone, Copy)]
pub struct View {
    /// Position, direction, aspect.
    pub camera: Camera,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f64,
}

/// The GPU, for uploads.
#[derive(Resource)]
pub struct GpuRes(pub Gpu);

/// A chunk mesh in GPU form, kept on the CPU for the crack oracle.
pub struct CpuMesh {
    /// Vertices as uploaded.
    pub vertices: Vec<RenderVertex>,
    /// Triangle list: the surface, then each side's skirt.
    pub indices: Vec<u32>,
    /// `indices[..surface_indices]` is the surface.
    pub surface_indices: usize,
    /// Index range of each side's skirt (as in `FaceDirection::HORIZONTAL`).
    pub skirt_ranges: [std::ops::Range<usize>; 4],
}

impl CpuMesh {
    /// Bytes of its vertices and indices.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        (size_of_val(self.vertices.as_slice()) + size_of_val(self.indices.as_slice())) as u64
    }

    /// The index ranges drawn with `draw`: the surface and the skirts of
    /// the sides lowered.
    #[must_use]
    pub fn drawn_ranges(&self, draw: &ChunkDraw) -> Vec<std::ops::Range<usize>> {
        drawn_ranges(self.surface_indices, &self.skirt_ranges, draw)
    }
}

/// The surface range and the skirt ranges of the sides `draw` lowers,
/// adjacent ranges merged.
#[must_use]
pub fn drawn_ranges(
    surface: usize,
    skirts: &[std::ops::Range<usize>; 4],
    draw: &ChunkDraw,
) -> Vec<std::ops::Range<usize>> {
    let mut ranges = Vec::with_capacity(5);
    ranges.push(0..surface);
    for (range, depth) in skirts.iter().zip(draw.skirt_depths) {
        if depth <= 0.0 || range.is_empty() {
            continue;
        }
        match ranges.last_mut() {
            Some(last) if last.end == range.start => last.end = range.end,
            _ => ranges.push(range.clone()),
        }
    }
    ranges
}

/// One chunk's mesh on the GPU.
pub struct LoadedChunk {
    /// GPU buffers.
    pub gpu: GpuMesh,
    /// Surface triangles.
    pub surface_triangles: usize,
    /// Skirt triangles per side (as in `FaceDirection::HORIZONTAL`).
    pub skirt_triangles: [usize; 4],
    /// The mesh on the CPU, when the app keeps them (crack checks).
    pub cpu: Option<CpuMesh>,
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
/// every third level costs about 1/64 (7,563 meshed, 7.4 s), but once
/// showed a one-pixel crack in a flight with stand-ins three LODs coarse
/// next to leaves, not explained yet, so it stays 1.
pub const STAND_IN_LEVEL_STEP: u8 = 1;

/// The meshes of one chunk column (all its radial layers).
struct CachedColumn {
    /// The radial layers that hold surface (a failed bounds query: none).
    layers: Vec<i32>,
    chunks: HashMap<i32, LoadedChunk>,
    /// Frame it was last drawn or wanted in.
    last_used: u64,
}

impl CachedColumn {
    fn new(planet: &PlanetVoxels, column: ChunkColumn, frame: u64) -> Self {
        let layers = planet.surface_chunk_layers(column).map(Iterator::collect).unwrap_or_default();
        Self { layers, chunks: HashMap::new(), last_used: frame }
    }

    fn ready(&self) -> bool {
        self.chunks.len() == self.layers.len()
    }

    /// Bytes of mesh data its chunks hold (GPU and CPU copies).
    fn bytes(&self) -> u64 {
        self.chunks.values().map(|c| c.gpu.bytes + c.cpu.as_ref().map_or(0, CpuMesh::bytes)).sum()
    }
}

/// Every chunk mesh on the GPU, by column.
#[derive(Resource, Default)]
pub struct MeshCache {
    columns: HashMap<ChunkColumn, CachedColumn>,
    /// Keep a CPU copy of each mesh (for the crack oracle).
    pub keep_cpu: bool,
    /// Columns out of use this many frames are freed (face roots never).
    pub free_after_frames: u64,
    /// At most this many chunk meshes are kept: past it, the columns used
    /// longest ago (not drawn or wanted this frame) are freed first. What
    /// the frame draws is always kept.
    pub max_chunks: usize,
    /// The same for bytes of mesh data held (GPU, plus the CPU copies when
    /// kept). Chunks differ a lot in size, so a chunk count alone does not
    /// bound memory (measured: flying 15–150 m over Earth at 600–3,000 m/s
    /// with the crack oracle's CPU copies, the cache stays at ≤ 537 MB).
    pub max_bytes: u64,
    /// Drawn chunks an edit changed: the old mesh stays on screen until one
    /// of at least this voxel generation replaces it.
    stale: HashMap<ChunkKey, u64>,
}

impl MeshCache {
    fn ready(&self, column: ChunkColumn) -> bool {
        self.columns.get(&column).is_some_and(CachedColumn::ready)
    }

    /// Bytes of GPU buffers held.
    #[must_use]
    pub fn gpu_bytes(&self) -> u64 {
        self.columns.values().flat_map(|c| c.chunks.values()).map(|c| c.gpu.bytes).sum()
    }

    /// Chunk meshes held.
    #[must_use]
    pub fn chunks(&self) -> usize {
        self.columns.values().map(|c| c.chunks.len()).sum()
    }

    /// The default [`MeshCache::max_bytes`]: 512 MiB.
    #[must_use]
    pub const fn default_max_bytes() -> u64 {
        512 << 20
    }

    /// Bytes of mesh data held (GPU and CPU copies).
    #[must_use]
    pub fn held_bytes(&self) -> u64 {
        self.columns.values().map(CachedColumn::bytes).sum()
    }
}

/// A meshing job: one chunk, with the priority of its column.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Job {
    priority: f64,
    key: ChunkKey,
}

impl Eq for Job {}

impl Ord for Job {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.priority.total_cmp(&other.priority).then_with(|| other.key.cmp(&self.key))
    }
}

impl PartialOrd for Job {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// The queue workers take jobs from, and the chunks they hold.
#[derive(Default)]
struct JobState {
    queue: BinaryHeap<Job>,
    /// Taken by a worker and not collected yet (running, or finished and
    /// waiting in the channel).
    running: HashSet<ChunkKey>,
    /// The voxels jobs read and their generation: a worker takes them with
    /// each job, so an edit reaches the next job, not the next worker.
    voxels: Option<(Arc<PlanetVoxels>, u64)>,
}

struct MeshResult {
    key: ChunkKey,
    /// The voxel generation the mesh was made from.
    generation: u64,
    result: Result<CpuMesh, nebula_meshing::MeshError>,
    millis: f64,
}

/// Meshing jobs: the shared priority queue, the workers on a thread pool of
/// their own and the channel finished meshes come back on.
#[derive(Resource)]
pub struct Meshing {
    /// Meshing's own threads: work the frame thread hands to rayon's global
    /// pool (the crack oracle) must never queue behind a worker that runs
    /// until the job queue is empty.
    pool: Arc<rayon::ThreadPool>,
    state: Arc<Mutex<JobState>>,
    workers: Arc<AtomicUsize>,
    max_workers: usize,
    /// Bounded: a worker waits once [`MAX_UPLOADS_PER_FRAME`] results are
    /// waiting, so slow frames never pile meshes up in memory.
    sender: SyncSender<MeshResult>,
    receiver: Mutex<Receiver<MeshResult>>,
    /// Which seam passes run (the draw-time skirts must stay on).
    pub options: MeshOptions,
}

impl Meshing {
    /// Jobs queued, running, or finished and not collected yet.
    #[must_use]
    pub fn pending(&self) -> usize {
        self.state.lock().map_or(0, |s| s.queue.len() + s.running.len())
    }

    /// Jobs taken by a worker and not collected yet.
    #[must_use]
    pub fn running(&self) -> usize {
        self.state.lock().map_or(0, |s| s.running.len())
    }
}

/// What the next frame draws.
#[derive(Resource, Default, Clone)]
pub struct DrawList {
    /// Columns drawn, with their per-chunk draw constants.
    pub columns: Vec<(ChunkColumn, ChunkDraw)>,
    /// Visible leaves with nothing to draw for them (no meshed ancestor).
    pub holes: usize,
    /// Visible leaves drawn through a coarser ancestor or finer children.
    pub stand_ins: usize,
    /// Largest LOD gap between a visible leaf and the ancestor drawn for it.
    pub max_stand_in_levels: u8,
    /// Lowest surface radius under the drawn columns.
    pub min_surface_radius: f64,
}

/// CPU time per stage, milliseconds, for the last frame (meshing: summed
/// over the jobs collected this frame).
#[derive(Resource, Default, Clone, Copy, Debug)]
pub struct StageTimes {
    /// LOD update and culling.
    pub lod_ms: f64,
    /// Choosing what to draw and what to mesh.
    pub select_ms: f64,
    /// Meshing jobs collected this frame (CPU time of the jobs, on worker
    /// threads).
    pub meshing_ms: f64,
    /// Meshing CPU time since the start, all jobs.
    pub meshing_total_ms: f64,
    /// Chunks meshed since the start.
    pub chunks_meshed: usize,
    /// Meshing errors since the start (each logged).
    pub mesh_errors: usize,
    /// Buffer uploads.
    pub upload_ms: f64,
    /// Recording and submitting the draw.
    pub render_ms: f64,
}

/// Frame counter.
#[derive(Resource, Default)]
pub struct FrameCount(pub u64);

/// What drives the geomorph factor μ of a chunk.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
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
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct DrawOptions {
    /// Lower skirts where a chunk meets another LOD (off: every skirt has
    /// depth 0, seams between LODs open).
    pub skirts: bool,
    /// What drives μ.
    pub morph: MorphRule,
}

impl Default for DrawOptions {
    fn default() -> Self {
        Self { skirts: true, morph: MorphRule::Parent }
    }
}

/// The demo's world and schedule.
pub struct PlanetApp {
    /// The ECS world.
    pub world: World,
    schedule: Schedule,
}

impl PlanetApp {
    /// A world for `planet` with LOD `settings`, drawing through `gpu`. The
    /// six face roots are meshed before it returns, so every frame has
    /// something to draw everywhere.
    ///
    /// # Errors
    /// If the LOD settings are bad or a root cannot be meshed.
    pub fn new(planet: impl Into<PlanetVoxels>, settings: LodSettings, gpu: Gpu, view: View) -> anyhow::Result<Self> {
        Self::with_voxels(Arc::new(planet.into()), settings, gpu, view)
    }

    /// [`PlanetApp::new`] for voxels shared with their owner (a
    /// `nebula_world::World::voxels` snapshot).
    ///
    /// # Errors
    /// As [`PlanetApp::new`].
    pub fn with_voxels(planet: Arc<PlanetVoxels>, settings: LodSettings, gpu: Gpu, view: View) -> anyhow::Result<Self> {
        let tree = LodTree::new(&*planet, settings)?;
        let mut world = World::new();
        let (sender, receiver) = sync_channel(MAX_UPLOADS_PER_FRAME);
        world.insert_resource(Planet(planet));
        world.insert_resource(VoxelsGeneration::default());
        world.insert_resource(Lod { tree });
        world.insert_resource(view);
        world.insert_resource(GpuRes(gpu));
        let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
        let pool =
            rayon::ThreadPoolBuilder::new().num_threads(threads).thread_name(|n| format!("nebula-mesh-{n}")).build()?;
        world.insert_resource(Meshing {
            pool: Arc::new(pool),
            state: Arc::default(),
            workers: Arc::default(),
            max_workers: threads,
            sender,
            receiver: Mutex::new(receiver),
            options: MeshOptions::STREAMING,
        });
        world.insert_resource(MeshCache {
            keep_cpu: false,
            free_after_frames: 300,
            max_chunks: 12_000,
            max_bytes: MeshCache::default_max_bytes(),
            ..MeshCache::default()
        });
        world.insert_resource(DrawList::default());
        world.insert_resource(DrawOptions::default());
        world.insert_resource(StageTimes::default());
        world.insert_resource(FrameCount::default());
        let mut schedule = Schedule::default();
        schedule.add_systems((lod_system, collect_meshes_system, select_system, free_system).chain());
        let mut app = Self { world, schedule };
        app.mesh_roots()?;
        Ok(app)
    }

    /// Meshes the face roots on the calling thread (all of the planet, at
    /// its coarsest LOD: the stand-in of last resort).
    fn mesh_roots(&mut self) -> anyhow::Result<()> {
        let planet = self.world.resource::<Planet>().0.clone();
        let max_lod = planet.layout().max_lod();
        let mut buffer = ChunkMeshBuffer::new();
        let mut results = Vec::new();
        for face in nebula_voxel::CubeFace::ALL {
            let column = ChunkColumn { face, lod: max_lod, x: 0, y: 0 };
            for layer in planet.surface_chunk_layers(column)? {
                let key = column.chunk(layer);
                let mesh =
                    mesh_chunk(&*planet, key, &ChunkLodContext::uniform(max_lod), MeshOptions::STREAMING, &mut buffer)?;
                results.push(MeshResult { key, generation: 0, result: Ok(cpu_mesh(&mesh)), millis: 0.0 });
            }
        }
        self.world.resource_scope(|world, mut cache: Mut<MeshCache>| {
            let gpu = &world.resource::<GpuRes>().0;
            for done in results {
                store(&mut cache, &planet, gpu, done, 0);
            }
        });
        Ok(())
    }

    /// Keep CPU copies of meshes (needed by the crack oracle).
    pub fn keep_cpu_meshes(&mut self, keep: bool) {
        self.world.resource_mut::<MeshCache>().keep_cpu = keep;
    }

    /// Changes what is drawn (see [`DrawOptions`]); applies from the next
    /// [`PlanetApp::step`].
    pub fn set_draw_options(&mut self, options: DrawOptions) {
        self.world.insert_resource(options);
    }

    /// Moves the camera.
    pub fn set_view(&mut self, view: View) {
        self.world.insert_resource(view);
    }

    /// Draws `voxels` from now on: the same planet after edits whose dirty
    /// chunks (every LOD, as `nebula_world::World::apply` returns them) are
    /// `dirty`. Chunks on screen keep their old mesh until the new one is
    /// uploaded, so an edit never opens a hole; others are dropped and
    /// meshed again when needed. The LOD tree re-reads the bounds of the
    /// columns touched (an edit can raise or sink the surface).
    ///
    /// # Errors
    /// If the voxel source refuses a touched column.
    pub fn set_voxels(&mut self, voxels: Arc<PlanetVoxels>, dirty: &[ChunkKey]) -> anyhow::Result<()> {
        let generation = self.world.resource::<VoxelsGeneration>().0 + 1;
        self.world.insert_resource(VoxelsGeneration(generation));
        self.world.insert_resource(Planet(voxels.clone()));
        let columns: HashSet<ChunkColumn> = dirty.iter().map(|key| key.column()).collect();
        self.world.resource_mut::<Lod>().tree.refresh_bounds(&*voxels, columns.iter().copied())?;
        let drawn: HashSet<ChunkColumn> = self.world.resource::<DrawList>().columns.iter().map(|(c, _)| *c).collect();
        let mut cache = self.world.resource_mut::<MeshCache>();
        for &column in &columns {
            let Some(cached) = cache.columns.get_mut(&column) else { continue };
            cached.layers = voxels.surface_chunk_layers(column).map(Iterator::collect).unwrap_or_default();
            let layers = cached.layers.clone();
            cached.chunks.retain(|layer, _| layers.contains(layer));
            if !drawn.contains(&column) {
                for key in dirty.iter().filter(|key| key.column() == column) {
                    cached.chunks.remove(&key.layer);
                }
            }
        }
        for key in dirty {
            let column = key.column();
            if drawn.contains(&column) && cache.columns.get(&column).is_some_and(|c| c.chunks.contains_key(&key.layer))
            {
                cache.stale.insert(*key, generation);
            }
        }
        Ok(())
    }

    /// Chunks on screen still drawn from before an edit.
    #[must_use]
    pub fn stale_chunks(&self) -> usize {
        self.world.resource::<MeshCache>().stale.len()
    }

    /// Runs one frame of the systems (no drawing): LOD update, collecting
    /// finished meshes, choosing what to draw and what to mesh.
    pub fn step(&mut self) {
        self.world.resource_mut::<FrameCount>().0 += 1;
        self.schedule.run(&mut self.world);
    }

    /// Whether the view is final: nothing drawn in place of a visible leaf
    /// and no job queued or running.
    #[must_use]
    pub fn settled(&self) -> bool {
        let draw = self.world.resource::<DrawList>();
        draw.stand_ins == 0
            && draw.holes == 0
            && self.world.resource::<Meshing>().pending() == 0
            && self.world.resource::<MeshCache>().stale.is_empty()
    }

    /// Chunk meshes held (drawn, stand-ins, or kept a while out of view):
    /// what stays flat on a long flight.
    #[must_use]
    pub fn chunk_entities(&self) -> usize {
        self.world.resource::<MeshCache>().chunks()
    }

    /// Meshing jobs queued or running.
    #[must_use]
    pub fn jobs_in_flight(&self) -> usize {
        self.world.resource::<Meshing>().pending()
    }

    /// The per-frame constants of the shader for the current view.
    #[must_use]
    pub fn frame_draw(&self) -> FrameDraw {
        let view = self.world.resource::<View>();
        let settings = self.world.resource::<Lod>().tree.settings();
        let k = settings.screen_space().map_or(1.0, |s| s.k());
        let morph = self.world.resource::<DrawOptions>().morph != MorphRule::Off;
        FrameDraw::new(view.camera.position, k, settings.threshold_px, morph)
    }

    /// Draws this frame's [`DrawList`] into `target`.
    pub fn draw(&mut self, target: &wgpu::TextureView, size: (u32, u32), background: [u8; 3], debug: DebugView) {
        let start = Instant::now();
        let view = *self.world.resource::<View>();
        let frame_draw = self.frame_draw();
        let max_lod = self.world.resource::<Lod>().tree.max_lod();
        let frame = FrameParams {
            eye: view.camera.position,
            forward: view.camera.forward,
            up: view.camera.up,
            fov_y_degrees: view.fov_y_degrees as f32,
            k: frame_draw.k as f32,
            threshold_px: frame_draw.threshold_px as f32,
            background,
            view: debug,
            morph: frame_draw.morph,
            max_lod,
        };
        self.world.resource_scope(|world, mut gpu: Mut<GpuRes>| {
            let cache = world.resource::<MeshCache>();
            let list = world.resource::<DrawList>();
            let meshes: Vec<(&GpuMesh, ChunkDraw)> = list
                .columns
                .iter()
                .filter_map(|(column, draw)| cache.columns.get(column).map(|c| (c, *draw)))
                .flat_map(|(c, draw)| c.chunks.values().map(move |chunk| (&chunk.gpu, draw)))
                .collect();
            gpu.0.draw(target, size, &frame, &meshes);
        });
        self.world.resource_mut::<StageTimes>().render_ms = start.elapsed().as_secs_f64() * 1e3;
    }

    /// What the draw list draws, for the crack oracle: the meshes on the
    /// CPU with their draw constants (none unless
    /// [`PlanetApp::keep_cpu_meshes`]), the frame constants and the lowest
    /// ground under them.
    #[must_use]
    pub fn drawn_geometry(&self) -> crate::crack::DrawnGeometry<'_> {
        let cache = self.world.resource::<MeshCache>();
        let list = self.world.resource::<DrawList>();
        let drawn = list
            .columns
            .iter()
            .filter_map(|(column, draw)| cache.columns.get(column).map(|c| (c, *draw)))
            .flat_map(|(c, draw)| c.chunks.values().filter_map(move |chunk| chunk.cpu.as_ref().map(|m| (m, draw))))
            .collect();
        crate::crack::DrawnGeometry { drawn, frame: self.frame_draw(), sentinel_radius: self.view_min_surface_radius() }
    }

    /// Figures of what the draw list shows.
    #[must_use]
    pub fn frame_figures(&self) -> FrameFigures {
        let max_lod = self.world.resource::<Lod>().tree.max_lod();
        let mut figures = FrameFigures { lod_histogram: vec![0; usize::from(max_lod) + 1], ..FrameFigures::default() };
        let cache = self.world.resource::<MeshCache>();
        let list = self.world.resource::<DrawList>();
        for (column, draw) in &list.columns {
            let Some(cached) = cache.columns.get(column) else { continue };
            for chunk in cached.chunks.values() {
                figures.chunks += 1;
                let skirts: usize =
                    chunk.skirt_triangles.iter().zip(draw.skirt_depths).filter(|(_, d)| *d > 0.0).map(|(n, _)| n).sum();
                figures.triangles += chunk.surface_triangles + skirts;
                figures.skirt_triangles += skirts;
                figures.skirt_triangles_held += chunk.skirt_triangles.iter().sum::<usize>();
                figures.lod_histogram[usize::from(column.lod)] += 1;
            }
        }
        figures.stand_ins = list.stand_ins;
        figures.holes = list.holes;
        figures.max_neighbor_lod_diff = self.world.resource::<Lod>().tree.stats().max_neighbor_lod_diff;
        figures.times = *self.world.resource::<StageTimes>();
        figures.jobs_in_flight = self.jobs_in_flight();
        figures.gpu_bytes = cache.gpu_bytes();
        figures.held_bytes = cache.held_bytes();
        figures.gpu_buffer_bytes = self.gpu().mesh_buffer_bytes();
        figures.chunks_held = cache.chunks();
        figures
    }

    /// The lowest surface radius anywhere: the camera must stay above it.
    #[must_use]
    pub fn min_surface_radius(&self) -> f64 {
        self.world.resource::<Lod>().tree.min_surface_radius()
    }

    /// The lowest surface radius under the columns drawn: the crack
    /// sentinel sphere. Everything on screen lies above it.
    #[must_use]
    pub fn view_min_surface_radius(&self) -> f64 {
        let list = self.world.resource::<DrawList>();
        if list.min_surface_radius.is_finite() { list.min_surface_radius } else { self.min_surface_radius() }
    }

    /// The GPU.
    #[must_use]
    pub fn gpu(&self) -> &Gpu {
        &self.world.resource::<GpuRes>().0
    }
}

/// What a frame showed.
#[derive(Clone, Debug, Default)]
pub struct FrameFigures {
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
    /// Visible leaves drawn through an ancestor or their children.
    pub stand_ins: usize,
    /// Visible leaves with nothing drawn for them.
    pub holes: usize,
    /// Largest LOD difference between neighbouring leaves.
    pub max_neighbor_lod_diff: u8,
    /// CPU time per stage.
    pub times: StageTimes,
    /// Meshing jobs queued or running.
    pub jobs_in_flight: usize,
    /// Bytes of the chunk meshes held on the GPU.
    pub gpu_bytes: u64,
    /// Bytes of the GPU buffers holding them (arena pages, used or not).
    pub gpu_buffer_bytes: u64,
    /// Bytes of mesh data held, GPU and CPU copies (what
    /// [`MeshCache::max_bytes`] bounds).
    pub held_bytes: u64,
    /// Chunk meshes held.
    pub chunks_held: usize,
}

/// Updates the LOD selection and culls it to the view.
fn lod_system(planet: Res<Planet>, view: Res<View>, mut lod: ResMut<Lod>, mut times: ResMut<StageTimes>) {
    let start = Instant::now();
    let planet = &*planet.0;
    if let Err(error) = lod.tree.update(planet, &view.camera).and_then(|_| lod.tree.cull(&view.camera)) {
        eprintln!("nebula-demo: LOD update failed, keeping the last selection: {error}");
    }
    times.lod_ms = start.elapsed().as_secs_f64() * 1e3;
}

/// The GPU form of a finished mesh and its skirt triangle count.
fn cpu_mesh(mesh: &nebula_meshing::ChunkMesh) -> CpuMesh {
    CpuMesh {
        vertices: mesh.render_vertices(),
        indices: mesh.indices().to_vec(),
        surface_indices: mesh.surface_triangle_count() * 3,
        skirt_ranges: mesh.skirt_index_ranges(),
    }
}

/// Uploads a finished job into the cache (a failed one is logged and
/// stored empty, so its column is not blocked for ever).
fn store(cache: &mut MeshCache, planet: &PlanetVoxels, gpu: &Gpu, done: MeshResult, frame: u64) -> bool {
    let column = done.key.column();
    let (mesh, failed) = match done.result {
        Ok(mesh) => (mesh, false),
        Err(error) => {
            eprintln!("nebula-demo: meshing {:?} failed, drawing it empty: {error}", done.key);
            let empty = [0..0, 0..0, 0..0, 0..0];
            (CpuMesh { vertices: Vec::new(), indices: Vec::new(), surface_indices: 0, skirt_ranges: empty }, true)
        }
    };
    let key = done.key;
    let id = key.x.wrapping_mul(73_856_093)
        ^ key.y.wrapping_mul(19_349_663)
        ^ (key.layer as u32).wrapping_mul(83_492_791)
        ^ ((key.face as u32) << 3);
    let gpu_mesh = gpu.upload(&mesh, key.lod, id);
    let loaded = LoadedChunk {
        gpu: gpu_mesh,
        surface_triangles: mesh.surface_indices / 3,
        skirt_triangles: mesh.skirt_ranges.clone().map(|r| r.len() / 3),
        cpu: cache.keep_cpu.then_some(mesh),
    };
    let entry = cache.columns.entry(column).or_insert_with(|| CachedColumn::new(planet, column, frame));
    if entry.layers.contains(&key.layer) {
        entry.chunks.insert(key.layer, loaded);
    }
    if cache.stale.get(&key).is_some_and(|&wanted| done.generation >= wanted) {
        cache.stale.remove(&key);
    }
    failed
}

/// Picks up finished meshes and uploads them.
fn collect_meshes_system(
    planet: Res<Planet>,
    gpu: Res<GpuRes>,
    meshing: Res<Meshing>,
    frame: Res<FrameCount>,
    mut cache: ResMut<MeshCache>,
    mut times: ResMut<StageTimes>,
) {
    let start = Instant::now();
    // At most this many uploads a frame: a long frame (or a burst of
    // finished jobs) must not turn into one huge upload; the rest waits in
    // the channel for the next frame.
    let results: Vec<MeshResult> =
        meshing.receiver.lock().map(|r| r.try_iter().take(MAX_UPLOADS_PER_FRAME).collect()).unwrap_or_default();
    if let Ok(mut state) = meshing.state.lock() {
        for done in &results {
            state.running.remove(&done.key);
        }
    }
    let mut meshing_ms = 0.0;
    let uploaded = !results.is_empty();
    for done in results {
        meshing_ms += done.millis;
        times.chunks_meshed += 1;
        if store(&mut cache, &planet.0, &gpu.0, done, frame.0) {
            times.mesh_errors += 1;
        }
    }
    if uploaded {
        // Let wgpu release the staging memory of the uploads now.
        gpu.0.queue.submit([]);
        let _ = gpu.0.device.poll(wgpu::PollType::Poll);
    }
    times.meshing_ms = meshing_ms;
    times.meshing_total_ms += meshing_ms;
    times.upload_ms = start.elapsed().as_secs_f64() * 1e3;
}

/// Chooses what to draw (see the module docs), the skirt depth of every
/// drawn side, and the meshing jobs, by priority.
#[expect(clippy::too_many_arguments, reason = "a bevy system names each resource it touches")]
fn select_system(
    planet: Res<Planet>,
    generation: Res<VoxelsGeneration>,
    view: Res<View>,
    lod: Res<Lod>,
    frame: Res<FrameCount>,
    meshing: Res<Meshing>,
    options: Res<DrawOptions>,
    mut cache: ResMut<MeshCache>,
    mut draw: ResMut<DrawList>,
    mut times: ResMut<StageTimes>,
) {
    let start = Instant::now();
    let planet_arc = planet.0.clone();
    let planet = &*planet.0;
    let tree = &lod.tree;
    let layout = planet.layout();
    let max_lod = layout.max_lod();
    let eye = view.camera.position;
    let mut drawn: Vec<ChunkColumn> = Vec::new();
    let mut ancestors: HashSet<ChunkColumn> = HashSet::new();
    let mut wanted: Vec<ChunkColumn> = Vec::new();
    let (mut holes, mut stand_ins, mut max_levels) = (0, 0, 0u8);
    for &leaf in tree.visible_leaves() {
        if let Some(cached) = cache.columns.get_mut(&leaf).filter(|c| c.ready()) {
            // In use even when a stand-in covering it is drawn instead
            // (a sibling is not ready): never freed while it is a leaf.
            cached.last_used = frame.0;
            drawn.push(leaf);
            continue;
        }
        wanted.push(leaf);
        stand_ins += 1;
        if let Some(finer) = children(leaf)
            && finer.iter().all(|&c| cache.ready(c))
        {
            drawn.extend(finer);
            continue;
        }
        let mut ancestor = leaf;
        let mut found = false;
        while ancestor.lod < max_lod {
            let Some(up) = parent(ancestor) else { break };
            ancestor = up;
            if cache.ready(ancestor) {
                found = true;
                break;
            }
            if (ancestor.lod - leaf.lod).is_multiple_of(STAND_IN_LEVEL_STEP) {
                wanted.push(ancestor);
            }
        }
        if found {
            max_levels = max_levels.max(ancestor.lod - leaf.lod);
            ancestors.insert(ancestor);
        } else {
            holes += 1;
        }
    }
    // A drawn ancestor covers everything under it.
    let covered = |column: ChunkColumn| {
        let mut c = column;
        while c.lod < max_lod {
            let Some(up) = parent(c) else { break };
            c = up;
            if ancestors.contains(&c) {
                return true;
            }
        }
        false
    };
    let mut columns: Vec<ChunkColumn> = drawn.into_iter().filter(|&c| !covered(c)).collect();
    columns.extend(ancestors.iter().copied().filter(|&c| !covered(c)));
    columns.sort_unstable();
    columns.dedup();
    let set: HashSet<ChunkColumn> = columns.iter().copied().collect();
    let mut min_radius = f64::INFINITY;
    draw.columns = columns
        .iter()
        .map(|&column| {
            if let Some(cached) = cache.columns.get_mut(&column) {
                cached.last_used = frame.0;
            }
            // The tree's cached bounds; a stand-in the tree merged away asks
            // the source (noise) once here.
            let low = tree
                .node_bounds(column)
                .map(|b| b.min_radius)
                .or_else(|| planet.surface_bounds(column).ok().map(|b| b.min_radius));
            if let Some(low) = low {
                min_radius = min_radius.min(low);
            }
            (column, chunk_draw(planet, column, &set, *options))
        })
        .collect();
    draw.holes = holes;
    draw.stand_ins = stand_ins;
    draw.max_stand_in_levels = max_levels;
    draw.min_surface_radius = min_radius;

    // Jobs: every chunk of a wanted column not meshed and not running, the
    // largest projected voxel first.
    let k = tree.settings().screen_space().map_or(1.0, |s| s.k());
    let mut jobs = Vec::new();
    let mut seen = HashSet::new();
    for column in wanted {
        if !seen.insert(column) {
            continue;
        }
        let distance = tree.node_bounds(column).map_or(f64::INFINITY, |b| b.distance(eye)).max(1e-3);
        let priority = layout.voxel_edge(column.lod) * k / distance;
        let entry = cache.columns.entry(column).or_insert_with(|| CachedColumn::new(planet, column, frame.0));
        entry.last_used = frame.0;
        for &layer in &entry.layers {
            if !entry.chunks.contains_key(&layer) {
                jobs.push(Job { priority, key: column.chunk(layer) });
            }
        }
    }
    // Drawn chunks an edit changed go first: the player is looking at them.
    for (&key, _) in cache.stale.iter().filter(|(key, _)| set.contains(&key.column())) {
        jobs.push(Job { priority: f64::MAX, key });
    }
    if let Ok(mut state) = meshing.state.lock() {
        state.queue.clear();
        let running = state.running.clone();
        state.queue.extend(jobs.into_iter().filter(|job| !running.contains(&job.key)));
        state.voxels = Some((planet_arc, generation.0));
    }
    spawn_workers(&meshing);
    times.select_ms = start.elapsed().as_secs_f64() * 1e3;
}

/// The draw constants of `column` when the columns in `drawn` are drawn:
/// the error it morphs towards and, per side, a skirt as deep as the LOD
/// drawn across that side needs (none next to the same LOD, whose
/// boundary vertices are shared exactly).
fn chunk_draw(
    planet: &PlanetVoxels,
    column: ChunkColumn,
    drawn: &HashSet<ChunkColumn>,
    options: DrawOptions,
) -> ChunkDraw {
    let layout = planet.layout();
    let max_lod = layout.max_lod();
    let parent_error = match options.morph {
        MorphRule::Own => planet.geometric_error(column.lod),
        _ => layout.merge_error(column.lod),
    };
    let mut skirt_depths = [0.0f32; 4];
    if !options.skirts {
        return ChunkDraw { parent_error, skirt_depths };
    }
    for (depth, side) in skirt_depths.iter_mut().zip(FaceDirection::HORIZONTAL) {
        let Some(edge) = side.face_edge() else { continue };
        let mut across = layout.neighbor(column.chunk(0), edge).column();
        if drawn.contains(&across) {
            continue;
        }
        // A coarser column drawn across (an ancestor of the same-LOD
        // neighbour), else finer ones: the deepest a finer side can need is
        // the depth for the same LOD.
        let mut other = column.lod;
        while across.lod < max_lod {
            let Some(up) = parent(across) else { break };
            across = up;
            if drawn.contains(&across) {
                other = across.lod;
                break;
            }
        }
        *depth = skirt_depth(planet, column.lod, other) as f32;
    }
    ChunkDraw { parent_error, skirt_depths }
}

thread_local! {
    static BUFFER: std::cell::RefCell<ChunkMeshBuffer> = std::cell::RefCell::new(ChunkMeshBuffer::new());
}

/// Starts workers until every meshing thread has one or the queue is empty.
/// A worker takes the top job, meshes it and sends it back, until the queue
/// is empty; nothing ever waits for it.
fn spawn_workers(meshing: &Meshing) {
    loop {
        let queued = meshing.state.lock().map_or(0, |s| s.queue.len());
        let workers = meshing.workers.load(Ordering::Acquire);
        if queued == 0 || workers >= meshing.max_workers {
            return;
        }
        meshing.workers.fetch_add(1, Ordering::AcqRel);
        let (state, workers, sender, options) =
            (meshing.state.clone(), meshing.workers.clone(), meshing.sender.clone(), meshing.options);
        meshing.pool.spawn(move || {
            loop {
                let job = state.lock().ok().and_then(|mut s| {
                    let voxels = s.voxels.clone()?;
                    let job = s.queue.pop()?;
                    s.running.insert(job.key);
                    Some((job, voxels))
                });
                let Some((job, (planet, generation))) = job else { break };
                let start = Instant::now();
                let result = BUFFER.with(|buffer| {
                    mesh_chunk(
                        &*planet,
                        job.key,
                        &ChunkLodContext::uniform(job.key.lod),
                        options,
                        &mut buffer.borrow_mut(),
                    )
                    .map(|mesh| cpu_mesh(&mesh))
                });
                let millis = start.elapsed().as_secs_f64() * 1e3;
                // It stays in the running set until collected, so no queue
                // refresh asks for it again while it waits in the channel.
                let _ = sender.send(MeshResult { key: job.key, generation, result, millis });
            }
            workers.fetch_sub(1, Ordering::AcqRel);
        });
    }
}

/// Frees columns out of use for a while (every 10 frames), and every frame
/// the least recently used ones past the cache's chunk or byte budget
/// (never the face roots, never what this frame draws or wants).
fn free_system(lod: Res<Lod>, frame: Res<FrameCount>, mut cache: ResMut<MeshCache>) {
    let max_lod = lod.tree.max_lod();
    if frame.0.is_multiple_of(10) {
        let limit = cache.free_after_frames;
        cache
            .columns
            .retain(|column, cached| column.lod == max_lod || frame.0.saturating_sub(cached.last_used) <= limit);
    }
    let (mut chunks, mut bytes) = (cache.chunks(), cache.held_bytes());
    let over = |chunks: usize, bytes: u64| chunks > cache.max_chunks || bytes > cache.max_bytes;
    if !over(chunks, bytes) {
        return;
    }
    let mut old: Vec<(u64, ChunkColumn)> = cache
        .columns
        .iter()
        .filter(|(column, cached)| column.lod != max_lod && cached.last_used < frame.0)
        .map(|(column, cached)| (cached.last_used, *column))
        .collect();
    old.sort_unstable();
    let mut freed = Vec::new();
    for (_, column) in old {
        if !over(chunks, bytes) {
            break;
        }
        if let Some(cached) = cache.columns.get(&column) {
            chunks -= cached.chunks.len();
            bytes -= cached.bytes();
            freed.push(column);
        }
    }
    for column in freed {
        cache.columns.remove(&column);
    }
}

/// A camera for the LOD selection.
#[must_use]
pub fn camera(position: DVec3, forward: DVec3, up: DVec3, aspect: f64) -> Camera {
    Camera { position, forward, up, aspect }
}
