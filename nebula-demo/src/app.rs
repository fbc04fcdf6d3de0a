//! The demo's planet: a bevy_ecs world holding a [`nebula_world::stream::Streamer`]
//! whose meshes live in the demo's GPU arena, one system that updates it
//! with the camera each frame, and drawing. What to mesh, draw and free is
//! the streamer's (see its docs); this module only uploads and draws.

use std::sync::Arc;
use std::time::Instant;

use bevy_ecs::prelude::*;
use nebula_lod::{Camera, LodSettings};
use nebula_math::DVec3;
use nebula_meshing::{ChunkDraw, FrameDraw, RenderMesh};
use nebula_voxel::{ChunkKey, EditedSource, ProceduralPlanet};
pub use nebula_world::ecs::PlanetStream;
pub use nebula_world::stream::{
    DrawList, DrawOptions, MeshCache, MorphRule, OpaqueSea, STAND_IN_LEVEL_STEP, StageTimes,
    StreamFigures as FrameFigures, Streamer,
};

use crate::gpu::{DebugView, FrameParams, Gpu, GpuMesh};

/// The voxels the demo draws: the procedural planet with the player's
/// edits (none without `--world`).
pub type PlanetVoxels = EditedSource<ProceduralPlanet>;

/// The planet streamed onto the GPU (`nebula_world`'s ECS resource).
pub type Stream = PlanetStream<PlanetVoxels, GpuMesh>;

/// The camera this frame.
#[derive(Resource, Clone, Copy)]
pub struct View {
    /// Position, direction, aspect.
    pub camera: Camera,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f64,
    /// Height of the picture, pixels (the LOD tree's screen).
    pub screen_height_px: f64,
}

/// The GPU, for uploads and drawing.
#[derive(Resource)]
pub struct GpuRes(pub Gpu);

/// The clear colour behind the sky: space.
pub const SPACE: [u8; 3] = [3, 4, 9];

/// The demo's world and schedule.
pub struct PlanetApp {
    /// The ECS world.
    pub world: World,
    schedule: Schedule,
    /// Unit world direction towards the sun.
    sun: DVec3,
}

/// Uploads a finished chunk mesh into the GPU arena.
fn upload(gpu: &Gpu, key: ChunkKey, mesh: &RenderMesh) -> GpuMesh {
    // A small number from the key, for the chunk-colour view.
    let id = key.x.wrapping_mul(73_856_093)
        ^ key.y.wrapping_mul(19_349_663)
        ^ (key.layer as u32).wrapping_mul(83_492_791)
        ^ ((key.face as u32) << 3);
    gpu.upload(mesh, key.lod, id)
}

/// Whether `eye` is in `planet`'s sea: under sea level over a column
/// whose (unedited) ground lies under the sea too, not in a pit dug below
/// sea level under land.
#[must_use]
pub fn eye_in_sea(planet: &ProceduralPlanet, eye: DVec3) -> bool {
    let sea_level = nebula_voxel::VoxelSource::layout(planet).sphere().radius();
    eye.length() < sea_level && eye.length() > 0.0 && planet.height_at(eye.normalize()) < 0.0
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
        let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
        let streamer = Streamer::new(planet, settings, view.camera, threads, &mut |key, mesh| upload(&gpu, key, mesh))?;
        let refined = streamer.tree().screen_space().threshold_px();
        if refined > settings.threshold_px {
            eprintln!(
                "nebula-demo: --sse {} px at this field of view and size would need more than the LOD tree's budget of \
                 {} nodes; refining to {refined:.3} px instead",
                settings.threshold_px, settings.max_nodes
            );
        }
        let mut world = World::new();
        world.insert_resource(PlanetStream(streamer));
        world.insert_resource(view);
        world.insert_resource(GpuRes(gpu));
        let mut schedule = Schedule::default();
        schedule.add_systems(stream_system);
        Ok(Self { world, schedule, sun: crate::sun::default_sun() })
    }

    /// The streamer.
    #[must_use]
    pub fn streamer(&self) -> &Streamer<PlanetVoxels, GpuMesh> {
        &self.world.resource::<Stream>().0
    }

    /// The streamer, to change its budget or options.
    pub fn streamer_mut(&mut self) -> Mut<'_, Stream> {
        self.world.resource_mut::<Stream>()
    }

    /// Whether the frames drawn show the sea (the shaded view with no
    /// background): then the streamer draws the sea bed the sea hides as
    /// coarse stand-ins ([`OpaqueSea`]) instead of refining it. Call it
    /// before the first [`PlanetApp::step`] (so that the first frames do
    /// not ask for detail under the sea) and whenever what
    /// [`PlanetApp::draw`] is given changes.
    pub fn set_sea_drawn(&mut self, drawn: bool) {
        let radius = nebula_voxel::VoxelSource::layout(&**self.streamer().voxels()).sphere().radius();
        let sea = drawn.then(|| OpaqueSea { radius, hiding_depth: crate::gpu::sea_hiding_depth(radius) });
        self.streamer_mut().0.set_opaque_sea(sea);
    }

    /// Keep CPU copies of meshes (needed by the crack oracle).
    pub fn keep_cpu_meshes(&mut self, keep: bool) {
        self.streamer_mut().0.keep_cpu_meshes(keep);
    }

    /// Changes what is drawn (see [`DrawOptions`]); applies from the next
    /// [`PlanetApp::step`].
    pub fn set_draw_options(&mut self, options: DrawOptions) {
        self.streamer_mut().0.set_draw_options(options);
    }

    /// Moves the camera.
    pub fn set_view(&mut self, view: View) {
        self.world.insert_resource(view);
    }

    /// Draws `voxels` from now on, an edit of the planet whose dirty chunks
    /// are `dirty` (see [`Streamer::set_voxels`]).
    ///
    /// # Errors
    /// If the voxel source refuses a touched column.
    pub fn set_voxels(&mut self, voxels: Arc<PlanetVoxels>, dirty: &[ChunkKey]) -> anyhow::Result<()> {
        Ok(self.streamer_mut().0.set_voxels(voxels, dirty)?)
    }

    /// Chunks on screen still drawn from before an edit.
    #[must_use]
    pub fn stale_chunks(&self) -> usize {
        self.streamer().stale_chunks()
    }

    /// Runs one frame of the streamer (no drawing): LOD update, uploading
    /// finished meshes, choosing what to draw and what to mesh.
    pub fn step(&mut self) {
        self.schedule.run(&mut self.world);
    }

    /// Whether the view is final: nothing drawn in place of a visible leaf,
    /// no job queued or running, nothing drawn from before an edit.
    #[must_use]
    pub fn settled(&self) -> bool {
        self.streamer().settled()
    }

    /// What the last step chose to draw.
    #[must_use]
    pub fn draw_list(&self) -> &DrawList {
        self.streamer().draw_list()
    }

    /// Chunk meshes held (drawn, stand-ins, or kept a while out of view):
    /// what stays flat on a long flight.
    #[must_use]
    pub fn chunk_entities(&self) -> usize {
        self.streamer().cache.chunks()
    }

    /// Meshing jobs queued or running.
    #[must_use]
    pub fn jobs_in_flight(&self) -> usize {
        self.streamer().jobs_in_flight()
    }

    /// The unit world direction towards the sun.
    #[must_use]
    pub fn sun(&self) -> DVec3 {
        self.sun
    }

    /// Moves the sun to unit world direction `towards` (see
    /// [`crate::sun::sun_direction`] to place it over a view).
    ///
    /// # Errors
    /// [`crate::sun::SunError::NonFinite`] for NaN or infinite input or a
    /// zero vector; the sun stays where it was.
    pub fn set_sun(&mut self, towards: DVec3) -> Result<(), crate::sun::SunError> {
        let length = towards.length();
        if !length.is_finite() || length == 0.0 {
            return Err(crate::sun::SunError::NonFinite { name: "direction", value: length });
        }
        self.sun = towards / length;
        Ok(())
    }

    /// The per-frame constants of the shader for the current view.
    #[must_use]
    pub fn frame_draw(&self) -> FrameDraw {
        self.streamer().frame_draw(self.world.resource::<View>().camera.position)
    }

    /// Draws this frame's [`DrawList`] into `target`: over `background`
    /// alone when one is given (nothing else is drawn over it, so crack
    /// checks can count it), else under a sky, with sea and haze.
    pub fn draw(
        &mut self,
        target: &wgpu::TextureView,
        size: (u32, u32),
        background: Option<[u8; 3]>,
        debug: DebugView,
    ) {
        let start = Instant::now();
        let view = *self.world.resource::<View>();
        let frame_draw = self.frame_draw();
        let max_lod = self.streamer().tree().max_lod();
        let frame = FrameParams {
            eye: view.camera.position,
            forward: view.camera.forward,
            up: view.camera.up,
            fov_y_degrees: view.fov_y_degrees as f32,
            k: frame_draw.k as f32,
            threshold_px: frame_draw.threshold_px as f32,
            background: background.unwrap_or(SPACE),
            view: debug,
            morph: frame_draw.morph,
            max_lod,
            sun: self.sun.as_vec3(),
            atmosphere: background
                .is_none()
                .then(|| nebula_voxel::VoxelSource::layout(&**self.streamer().voxels()).sphere().radius()),
            eye_in_sea: eye_in_sea(self.streamer().voxels().base(), view.camera.position),
            voxel_size_and_relief: {
                let planet = self.streamer().voxels().base();
                (planet.voxel_size(), planet.relief())
            },
        };
        self.world.resource_scope(|world, mut gpu: Mut<GpuRes>| {
            let stream = world.resource::<Stream>();
            let meshes: Vec<(&GpuMesh, ChunkDraw)> =
                stream.0.drawn().map(|(_, chunk, draw)| (&chunk.handle, draw)).collect();
            gpu.0.draw(target, size, &frame, &meshes);
        });
        let ms = start.elapsed().as_secs_f64() * 1e3;
        self.streamer_mut().0.set_render_ms(ms);
    }

    /// What the draw list draws, for the crack oracle: the meshes on the
    /// CPU with their draw constants (none unless
    /// [`PlanetApp::keep_cpu_meshes`]), the frame constants and the lowest
    /// ground under them.
    #[must_use]
    pub fn drawn_geometry(&self) -> crate::crack::DrawnGeometry<'_> {
        let drawn = self
            .streamer()
            .drawn()
            .filter_map(|(_, chunk, draw)| chunk.cpu.as_ref().map(|mesh| (mesh, draw)))
            .collect();
        crate::crack::DrawnGeometry { drawn, frame: self.frame_draw(), sentinel_radius: self.view_min_surface_radius() }
    }

    /// Figures of what the draw list shows.
    #[must_use]
    pub fn frame_figures(&self) -> FrameFigures {
        self.streamer().figures()
    }

    /// The lowest surface radius anywhere: the camera must stay above it.
    #[must_use]
    pub fn min_surface_radius(&self) -> f64 {
        self.streamer().min_surface_radius()
    }

    /// The lowest surface radius under the columns drawn: the crack
    /// sentinel sphere. Everything on screen lies above it.
    #[must_use]
    pub fn view_min_surface_radius(&self) -> f64 {
        self.streamer().view_min_surface_radius()
    }

    /// The GPU.
    #[must_use]
    pub fn gpu(&self) -> &Gpu {
        &self.world.resource::<GpuRes>().0
    }

    /// The GPU, to change how it draws ([`Gpu::set_multisampling`]).
    pub fn gpu_mut(&mut self) -> &mut Gpu {
        &mut self.world.resource_mut::<GpuRes>().into_inner().0
    }
}

/// One frame of the streamer for the current view, uploading into the GPU
/// arena.
fn stream_system(mut stream: ResMut<Stream>, view: Res<View>, gpu: Res<GpuRes>) {
    // A zoom or a resized window refines for the new view at once.
    let tau = stream.0.tree().settings().threshold_px;
    if let Err(error) = stream.0.set_view(tau, view.screen_height_px, view.fov_y_degrees) {
        eprintln!("nebula-demo: keeping the last view for the LOD tree: {error}");
    }
    let mut uploaded = false;
    stream.0.update(view.camera, &mut |key, mesh| {
        uploaded = true;
        upload(&gpu.0, key, mesh)
    });
    if uploaded {
        // Let wgpu release the staging memory of the uploads now.
        gpu.0.queue.submit([]);
        let _ = gpu.0.device.poll(wgpu::PollType::Poll);
    }
}

/// A camera for the LOD selection.
#[must_use]
pub fn camera(position: DVec3, forward: DVec3, up: DVec3, aspect: f64) -> Camera {
    Camera { position, forward, up, aspect }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nebula_voxel::PlanetSettings;

    /// Under sea level over the sea is in the sea; the same depth under land
    /// (a pit dug below sea level) is not, nor is anywhere above sea level.
    #[test]
    fn the_eye_is_in_the_sea_only_over_sea_bed() {
        let planet = ProceduralPlanet::new(PlanetSettings::small(7)).expect("valid planet");
        let radius = planet.settings().radius;
        let mut state = 3_u64;
        let (mut sea, mut land) = (0, 0);
        for _ in 0..400 {
            let d = DVec3::new(
                nebula_math::unit_random(&mut state) - 0.5,
                nebula_math::unit_random(&mut state) - 0.5,
                nebula_math::unit_random(&mut state) - 0.5,
            )
            .normalize();
            let under = eye_in_sea(&planet, d * (radius - 2.0));
            if planet.height_at(d) < 0.0 {
                sea += 1;
                assert!(under, "{d}: under the sea but not in it");
            } else {
                land += 1;
                assert!(!under, "{d}: in a pit under land but in the sea");
            }
            assert!(!eye_in_sea(&planet, d * (radius + 2.0)), "above sea level");
        }
        assert!(sea > 20 && land > 20, "{sea} over sea, {land} over land");
    }
}
