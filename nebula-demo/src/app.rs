//! The planet as a bevy_ecs world: chunks are entities, and systems update
//! the LOD selection, hand meshing jobs to rayon, collect finished meshes and
//! upload them. Rendering reads the world; windowing lives in `main.rs`.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::Instant;

use bevy_ecs::prelude::*;
use nebula_lod::{Camera, ChunkLodContext, LodSettings, LodTree};
use nebula_math::DVec3;
use nebula_meshing::{ChunkMesh, ChunkMeshBuffer, MeshError, MeshOptions, mesh_chunk};
use nebula_voxel::{ChunkKey, ProceduralPlanet, VoxelSource};

use crate::gpu::{DebugView, FrameParams, Gpu, GpuMesh};

/// The planet's voxels, shared with meshing jobs.
#[derive(Resource, Clone)]
pub struct Planet(pub Arc<ProceduralPlanet>);

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

/// Meshing jobs in flight on rayon and the channel their results come back
/// on.
#[derive(Resource)]
pub struct Meshing {
    sender: Sender<MeshResult>,
    receiver: std::sync::Mutex<Receiver<MeshResult>>,
    /// Jobs handed out and not yet collected.
    pub in_flight: usize,
    /// Which seam passes run.
    pub options: MeshOptions,
}

/// Entities by chunk key.
#[derive(Resource, Default)]
pub struct ChunkIndex(pub HashMap<ChunkKey, Entity>);

/// CPU time per stage, milliseconds, for the last frame (meshing: summed
/// over the jobs collected this frame).
#[derive(Resource, Default, Clone, Copy, Debug)]
pub struct StageTimes {
    /// LOD update and culling.
    pub lod_ms: f64,
    /// Meshing jobs collected this frame (CPU time of the jobs, on worker
    /// threads).
    pub meshing_ms: f64,
    /// Meshing CPU time since the start, all jobs.
    pub meshing_total_ms: f64,
    /// Chunks meshed since the start.
    pub chunks_meshed: usize,
    /// Buffer uploads.
    pub upload_ms: f64,
    /// Recording and submitting the draw.
    pub render_ms: f64,
}

struct MeshResult {
    entity: Entity,
    version: u32,
    result: Result<ChunkMesh, MeshError>,
    millis: f64,
}

/// A chunk the LOD selection wants.
#[derive(Component)]
pub struct Chunk {
    /// Which chunk.
    pub key: ChunkKey,
    /// Its neighbours' LODs.
    pub context: ChunkLodContext,
    /// Bumped when the chunk must be meshed again.
    pub version: u32,
    /// Whether a job for `version` is out.
    pub queued: bool,
    /// Frame it was last seen in view.
    pub last_seen: u64,
}

/// A chunk's mesh on the GPU, with its figures.
#[derive(Component)]
pub struct Uploaded {
    /// GPU buffers.
    pub mesh: GpuMesh,
    /// Triangles, all.
    pub triangles: usize,
    /// Of which skirts.
    pub skirt_triangles: usize,
}

/// Marks chunks whose leaf left the tree: drawn until their successors are
/// ready, then freed.
#[derive(Component)]
pub struct Retiring;

/// Marks chunks shown on screen (new chunks wait until the batch that
/// replaces old ones is complete, so the surface never has holes).
#[derive(Component)]
pub struct Shown;

/// Frame counter.
#[derive(Resource, Default)]
pub struct FrameCount(pub u64);

/// The demo's world and schedule.
pub struct PlanetApp {
    /// The ECS world.
    pub world: World,
    schedule: Schedule,
}

impl PlanetApp {
    /// A world for `planet` with LOD `settings`, drawing through `gpu`.
    ///
    /// # Errors
    /// If the LOD settings are bad.
    pub fn new(planet: ProceduralPlanet, settings: LodSettings, gpu: Gpu, view: View) -> anyhow::Result<Self> {
        let tree = LodTree::new(&planet, settings)?;
        let mut world = World::new();
        let (sender, receiver) = channel();
        world.insert_resource(Planet(Arc::new(planet)));
        world.insert_resource(Lod { tree });
        world.insert_resource(view);
        world.insert_resource(GpuRes(gpu));
        world.insert_resource(Meshing {
            sender,
            receiver: std::sync::Mutex::new(receiver),
            in_flight: 0,
            options: MeshOptions::default(),
        });
        world.insert_resource(ChunkIndex::default());
        world.insert_resource(StageTimes::default());
        world.insert_resource(FrameCount::default());
        let mut schedule = Schedule::default();
        schedule.add_systems((lod_system, dispatch_meshing_system, collect_meshes_system, swap_system).chain());
        Ok(Self { world, schedule })
    }

    /// Moves the camera.
    pub fn set_view(&mut self, view: View) {
        self.world.insert_resource(view);
    }

    /// Runs one frame of the systems (no drawing).
    pub fn step(&mut self) {
        self.world.resource_mut::<FrameCount>().0 += 1;
        self.schedule.run(&mut self.world);
    }

    /// Chunk entities alive (drawn, waiting, or kept a while out of view):
    /// what stays flat on a long flight.
    #[must_use]
    pub fn chunk_entities(&self) -> usize {
        self.world.resource::<ChunkIndex>().0.len()
    }

    /// Meshing jobs still out.
    #[must_use]
    pub fn jobs_in_flight(&self) -> usize {
        self.world.resource::<Meshing>().in_flight
    }

    /// Draws the shown chunks in view into `target`.
    pub fn draw(&mut self, target: &wgpu::TextureView, size: (u32, u32), background: [u8; 3], debug: DebugView) {
        let start = Instant::now();
        let view = *self.world.resource::<View>();
        let (k, threshold, max_lod) = {
            let lod = self.world.resource::<Lod>();
            let settings = lod.tree.settings();
            let k = settings.screen_space().map_or(1.0, |s| s.k());
            (k, settings.threshold_px, lod.tree.max_lod())
        };
        let visible: std::collections::HashSet<_> =
            self.world.resource::<Lod>().tree.visible_leaves().iter().copied().collect();
        let frame = FrameParams {
            eye: view.camera.position,
            forward: view.camera.forward,
            up: view.camera.up,
            fov_y_degrees: view.fov_y_degrees as f32,
            k: k as f32,
            threshold_px: threshold as f32,
            background,
            view: debug,
            morph: true,
            max_lod,
        };
        // Retiring chunks stay on screen until their successors are all
        // ready (their columns are no longer leaves, so no cull test).
        let mut query = self.world.query_filtered::<(Entity, &Chunk, Has<Retiring>), (With<Shown>, With<Uploaded>)>();
        let chosen: Vec<Entity> = query
            .iter(&self.world)
            .filter(|(_, chunk, retiring)| *retiring || visible.contains(&chunk.key.column()))
            .map(|(entity, _, _)| entity)
            .collect();
        self.world.resource_scope(|world, mut gpu: Mut<GpuRes>| {
            let meshes: Vec<&GpuMesh> =
                chosen.iter().filter_map(|&e| world.get::<Uploaded>(e)).map(|u| &u.mesh).collect();
            gpu.0.draw(target, size, &frame, &meshes);
        });
        self.world.resource_mut::<StageTimes>().render_ms = start.elapsed().as_secs_f64() * 1e3;
    }

    /// Figures of what the last draw showed.
    #[must_use]
    pub fn frame_figures(&mut self) -> FrameFigures {
        let visible: std::collections::HashSet<_> =
            self.world.resource::<Lod>().tree.visible_leaves().iter().copied().collect();
        let max_lod = self.world.resource::<Lod>().tree.max_lod();
        let mut figures = FrameFigures { lod_histogram: vec![0; usize::from(max_lod) + 1], ..FrameFigures::default() };
        let mut query = self.world.query_filtered::<(&Chunk, &Uploaded), With<Shown>>();
        for (chunk, uploaded) in query.iter(&self.world) {
            if visible.contains(&chunk.key.column()) {
                figures.chunks += 1;
                figures.triangles += uploaded.triangles;
                figures.skirt_triangles += uploaded.skirt_triangles;
                figures.lod_histogram[usize::from(chunk.key.lod)] += 1;
            }
        }
        let stats = self.world.resource::<Lod>().tree.stats();
        figures.max_neighbor_lod_diff = stats.max_neighbor_lod_diff;
        figures.times = *self.world.resource::<StageTimes>();
        figures.jobs_in_flight = self.jobs_in_flight();
        figures
    }

    /// The lowest surface radius anywhere: the camera must stay above it.
    #[must_use]
    pub fn min_surface_radius(&self) -> f64 {
        self.world.resource::<Lod>().tree.min_surface_radius()
    }

    /// The lowest surface radius under the leaves in view: the crack
    /// sentinel sphere. Everything on screen lies above it, and unlike the
    /// planet-wide minimum it is close enough under the ground that grazing
    /// views still see it.
    #[must_use]
    pub fn view_min_surface_radius(&self) -> f64 {
        let tree = &self.world.resource::<Lod>().tree;
        tree.visible_leaves()
            .iter()
            .filter_map(|&c| tree.node_bounds(c))
            .map(|b| b.min_radius)
            .reduce(f64::min)
            .unwrap_or_else(|| tree.min_surface_radius())
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
    /// Of which skirts.
    pub skirt_triangles: usize,
    /// Chunks drawn per LOD.
    pub lod_histogram: Vec<usize>,
    /// Largest LOD difference between neighbouring leaves.
    pub max_neighbor_lod_diff: u8,
    /// CPU time per stage.
    pub times: StageTimes,
    /// Meshing jobs still out.
    pub jobs_in_flight: usize,
}

/// Updates the LOD selection and the set of chunk entities it wants.
#[expect(clippy::too_many_arguments, reason = "a bevy system names each resource it touches")]
fn lod_system(
    mut commands: Commands,
    planet: Res<Planet>,
    view: Res<View>,
    frame: Res<FrameCount>,
    mut lod: ResMut<Lod>,
    mut index: ResMut<ChunkIndex>,
    mut times: ResMut<StageTimes>,
    mut chunks: Query<(&mut Chunk, Has<Retiring>)>,
) {
    let start = Instant::now();
    let planet = &*planet.0;
    let Ok(changes) = lod.tree.update(planet, &view.camera) else { return };
    if lod.tree.cull(&view.camera).is_err() {
        return;
    }
    // Chunks whose leaf is gone retire (drawn until their successors are
    // ready); the tree says which, so nothing is scanned.
    for key in &changes.removed {
        if let Some(&entity) = index.0.get(key) {
            commands.entity(entity).insert(Retiring);
        }
    }
    for key in lod.tree.visible_chunks() {
        let Some(context) = lod.tree.context(key.column()) else { continue };
        match index.0.get(&key) {
            Some(&entity) => {
                if let Ok((mut chunk, retiring)) = chunks.get_mut(entity) {
                    if retiring {
                        // Its leaf came back before the swap: keep it.
                        commands.entity(entity).remove::<Retiring>();
                        chunk.queued = chunk.queued && chunk.context == context;
                    }
                    chunk.last_seen = frame.0;
                    if chunk.context != context {
                        chunk.context = context;
                        chunk.version += 1;
                        chunk.queued = false;
                    }
                }
            }
            None => {
                let entity = commands.spawn(Chunk { key, context, version: 1, queued: false, last_seen: frame.0 }).id();
                index.0.insert(key, entity);
            }
        }
    }
    // Chunks out of view for 300 frames are freed, so memory stays flat on
    // a long flight (checked once a second at 60 fps, not every frame).
    if frame.0.is_multiple_of(60) {
        let mut freed = Vec::new();
        for (&key, &entity) in &index.0 {
            let Ok((chunk, retiring)) = chunks.get(entity) else { continue };
            if !retiring && frame.0.saturating_sub(chunk.last_seen) > 300 {
                freed.push(key);
                commands.entity(entity).despawn();
            }
        }
        for key in freed {
            index.0.remove(&key);
        }
    }
    times.lod_ms = start.elapsed().as_secs_f64() * 1e3;
}

thread_local! {
    static BUFFER: std::cell::RefCell<ChunkMeshBuffer> = std::cell::RefCell::new(ChunkMeshBuffer::new());
}

/// Hands chunks that need a mesh to rayon; never waits for one.
fn dispatch_meshing_system(
    planet: Res<Planet>,
    mut meshing: ResMut<Meshing>,
    mut chunks: Query<(Entity, &mut Chunk), Without<Retiring>>,
) {
    for (entity, mut chunk) in &mut chunks {
        if chunk.queued {
            continue;
        }
        chunk.queued = true;
        meshing.in_flight += 1;
        let (planet, sender, options) = (planet.0.clone(), meshing.sender.clone(), meshing.options);
        let (key, context, version) = (chunk.key, chunk.context, chunk.version);
        rayon::spawn(move || {
            let start = Instant::now();
            let result = BUFFER.with(|buffer| mesh_chunk(&*planet, key, &context, options, &mut buffer.borrow_mut()));
            let _ = sender.send(MeshResult { entity, version, result, millis: start.elapsed().as_secs_f64() * 1e3 });
        });
    }
}

/// Picks up finished meshes and uploads them.
fn collect_meshes_system(
    mut commands: Commands,
    planet: Res<Planet>,
    gpu: Res<GpuRes>,
    mut meshing: ResMut<Meshing>,
    mut times: ResMut<StageTimes>,
    chunks: Query<&Chunk>,
) {
    let start = Instant::now();
    let mut meshing_ms = 0.0;
    let results: Vec<MeshResult> = meshing.receiver.lock().map(|r| r.try_iter().collect()).unwrap_or_default();
    for done in results {
        meshing.in_flight -= 1;
        meshing_ms += done.millis;
        times.chunks_meshed += 1;
        let Ok(chunk) = chunks.get(done.entity) else { continue };
        if chunk.version != done.version {
            continue;
        }
        let Ok(mesh) = done.result else { continue };
        // μ follows the error of the LOD the chunk merges into; the
        // coarsest LOD has none and never morphs.
        let layout = planet.0.layout();
        let error =
            if chunk.key.lod >= layout.max_lod() { f64::from(f32::MAX) } else { layout.voxel_edge(chunk.key.lod + 1) };
        let uploaded = Uploaded {
            mesh: gpu.0.upload(&mesh, error),
            triangles: mesh.triangle_count(),
            skirt_triangles: mesh.skirt_triangle_count(),
        };
        commands.entity(done.entity).insert(uploaded);
    }
    times.meshing_ms = meshing_ms;
    times.meshing_total_ms += meshing_ms;
    times.upload_ms = start.elapsed().as_secs_f64() * 1e3;
}

/// Chunks with a mesh that are not on screen yet and not retiring.
type ReadyNotShown = (With<Uploaded>, Without<Shown>, Without<Retiring>);

/// Once every job is back, frees retired chunks and shows the new ones in
/// one step: the old surface stays until the new one is complete.
fn swap_system(
    mut commands: Commands,
    meshing: Res<Meshing>,
    mut index: ResMut<ChunkIndex>,
    retiring: Query<(Entity, &Chunk), With<Retiring>>,
    fresh: Query<Entity, ReadyNotShown>,
    shown_count: Query<(), With<Shown>>,
) {
    // Nothing on screen yet: show what is ready at once.
    if meshing.in_flight > 0 && !shown_count.is_empty() {
        return;
    }
    for (entity, chunk) in &retiring {
        index.0.remove(&chunk.key);
        commands.entity(entity).despawn();
    }
    for entity in &fresh {
        commands.entity(entity).insert(Shown);
    }
}

/// A camera for the LOD selection.
#[must_use]
pub fn camera(position: DVec3, forward: DVec3, up: DVec3, aspect: f64) -> Camera {
    Camera { position, forward, up, aspect }
}
