//! The demo's planet: a bevy_ecs world holding a [`nebula_world::stream::Streamer`]
//! whose meshes live in a [`PlanetRenderer`], one system that updates it
//! with the camera each frame, and drawing. What to mesh, draw and free is
//! the streamer's, how to draw the renderer's; this module connects them.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use nebula_lod::{Camera, LodSettings};
use nebula_math::DVec3;
use nebula_meshing::FrameDraw;
use nebula_render::context::GpuContext;
use nebula_render::{DebugView, FrameParams, FrameStats, GpuMesh, PlanetRenderer, RendererOptions};
use nebula_voxel::{ChunkKey, EditedSource, ProceduralPlanet};
pub use nebula_world::ecs::PlanetStream;
pub use nebula_world::stream::{
    DrawList, DrawOptions, MeshCache, MorphRule, OpaqueSea, STAND_IN_LEVEL_STEP, StageTimes,
    StreamFigures as FrameFigures, Streamer, Uploader,
};

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

/// The device and the planet's renderer, for uploads and drawing.
#[derive(Resource)]
pub struct Gpu {
    /// The adapter, device and queue.
    pub context: GpuContext,
    /// The planet's renderer.
    pub renderer: PlanetRenderer,
}

pub use nebula_render::SPACE;

/// The demo's world and schedule.
pub struct PlanetApp {
    /// The ECS world.
    pub world: World,
    schedule: Schedule,
    /// Unit world direction towards the sun.
    sun: DVec3,
}

impl PlanetApp {
    /// A world for `planet` with LOD `settings`, drawing with a
    /// [`PlanetRenderer`] on `gpu`. The six face roots are meshed before it
    /// returns, so every frame has something to draw everywhere.
    ///
    /// # Errors
    /// If the LOD settings are bad or a root cannot be meshed.
    pub fn new(
        planet: impl Into<PlanetVoxels>,
        settings: LodSettings,
        gpu: GpuContext,
        view: View,
    ) -> anyhow::Result<Self> {
        Self::with_voxels(Arc::new(planet.into()), settings, gpu, view)
    }

    /// [`PlanetApp::new`] for voxels shared with their owner (a
    /// `nebula_world::World::voxels` snapshot).
    ///
    /// # Errors
    /// As [`PlanetApp::new`].
    pub fn with_voxels(
        planet: Arc<PlanetVoxels>,
        settings: LodSettings,
        context: GpuContext,
        view: View,
    ) -> anyhow::Result<Self> {
        let renderer = PlanetRenderer::new(
            &context.adapter,
            &context.device,
            &context.queue,
            &RendererOptions { color_format: context.color_format },
        )?;
        let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
        let mut streamer =
            Streamer::new(planet, settings, view.camera, threads, &mut |key, mesh| renderer.upload(key, mesh))?;
        // The meshing threads upload what they make (the frame copies no
        // mesh bytes); `--mesh-thread-uploads false` turns it off.
        streamer.set_uploader(Some(mesh_uploader(&renderer)));
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
        world.insert_resource(Gpu { context, renderer });
        let mut schedule = Schedule::default();
        schedule.add_systems(stream_system);
        Ok(Self { world, schedule, sun: nebula_render::sun::default_sun() })
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
        let sea = drawn.then(|| OpaqueSea { radius, hiding_depth: nebula_render::sea_hiding_depth(radius) });
        self.streamer_mut().0.set_opaque_sea(sea);
    }

    /// An uploader into the renderer's buffers for the streamer's meshing
    /// threads (`Streamer::set_uploader`).
    pub fn mesh_uploader(&self) -> Uploader<GpuMesh> {
        mesh_uploader(self.renderer())
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

    /// Submits the meshes the steps since the last drawn frame uploaded:
    /// a drawn frame submits them with its own commands; a loop that steps
    /// without drawing calls this after each step.
    pub fn submit_uploads(&self) {
        self.world.resource::<Gpu>().renderer.finish_uploads();
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
    /// [`nebula_render::sun::sun_direction`] to place it over a view).
    ///
    /// # Errors
    /// [`nebula_render::sun::SunError::NonFinite`] for NaN or infinite input or a
    /// zero vector; the sun stays where it was.
    pub fn set_sun(&mut self, towards: DVec3) -> Result<(), nebula_render::sun::SunError> {
        let length = towards.length();
        if !length.is_finite() || length == 0.0 {
            return Err(nebula_render::sun::SunError::NonFinite { name: "direction", value: length });
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
    /// checks can count it), else under a sky, with sea and haze. Returns
    /// the renderer's figures of the frame.
    pub fn draw(
        &mut self,
        target: &wgpu::TextureView,
        size: (u32, u32),
        background: Option<[u8; 3]>,
        debug: DebugView,
    ) -> FrameStats {
        let view = *self.world.resource::<View>();
        let streamer = self.streamer();
        let mut frame = FrameParams::new(
            streamer.voxels().base(),
            &view.camera,
            view.fov_y_degrees,
            &self.frame_draw(),
            streamer.tree().max_lod(),
        );
        frame.view = debug;
        frame.sun = self.sun.as_vec3();
        if let Some(background) = background {
            frame.background = background;
            frame.atmosphere = None;
        }
        self.world.resource_scope(|world, mut gpu: Mut<Gpu>| {
            let drawn = world.resource::<Stream>().0.drawn().map(|(_, chunk, draw)| (&chunk.handle, draw));
            gpu.renderer.render(target, size, &frame, drawn)
        })
    }

    /// What the draw list draws, for the crack oracle: the meshes on the
    /// CPU with their draw constants (none unless
    /// [`PlanetApp::keep_cpu_meshes`]), the frame constants and the lowest
    /// ground under them.
    #[must_use]
    pub fn drawn_geometry(&self) -> nebula_render::crack::DrawnGeometry<'_> {
        let drawn = self
            .streamer()
            .drawn()
            .filter_map(|(_, chunk, draw)| chunk.cpu.as_deref().map(|mesh| (mesh, draw)))
            .collect();
        nebula_render::crack::DrawnGeometry {
            drawn,
            frame: self.frame_draw(),
            sentinel_radius: self.view_min_surface_radius(),
        }
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

    /// The adapter, device and queue.
    #[must_use]
    pub fn gpu(&self) -> &GpuContext {
        &self.world.resource::<Gpu>().context
    }

    /// The planet's renderer.
    #[must_use]
    pub fn renderer(&self) -> &PlanetRenderer {
        &self.world.resource::<Gpu>().renderer
    }

    /// The renderer, to change how it draws
    /// ([`PlanetRenderer::set_multisampling`]).
    pub fn renderer_mut(&mut self) -> &mut PlanetRenderer {
        &mut self.world.resource_mut::<Gpu>().into_inner().renderer
    }
}

/// One frame of the streamer for the current view, uploading into the
/// renderer.
fn stream_system(mut stream: ResMut<Stream>, view: Res<View>, gpu: Res<Gpu>) {
    // A zoom or a resized window refines for the new view at once.
    let tau = stream.0.tree().settings().threshold_px;
    if let Err(error) = stream.0.set_view(tau, view.screen_height_px, view.fov_y_degrees) {
        eprintln!("nebula-demo: keeping the last view for the LOD tree: {error}");
    }
    stream.0.update(view.camera, &mut |key, mesh| gpu.renderer.upload(key, mesh));
}

/// A camera for the LOD selection.
#[must_use]
pub fn camera(position: DVec3, forward: DVec3, up: DVec3, aspect: f64) -> Camera {
    Camera { position, forward, up, aspect }
}

/// Uploads into `renderer`'s buffers from the streamer's meshing threads.
fn mesh_uploader(renderer: &PlanetRenderer) -> Uploader<GpuMesh> {
    let uploader = renderer.uploader();
    Arc::new(move |key, mesh| uploader.upload(key, mesh))
}
