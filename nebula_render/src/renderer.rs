//! [`PlanetRenderer`]: the planet's pipelines, per-frame constants, the
//! indirect draw list and the targets the terrain and sky passes share.
//! It draws the meshes it is given; what to draw is the streamer's.

use std::num::NonZeroU64;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{DVec3, Mat4, Vec3};
use nebula_meshing::{ChunkDraw, FrameDraw, RenderMesh, SURFACE_PARTS, drawn_ranges, lowered_skirts, split_high_low};
use nebula_voxel::{ChunkKey, ProceduralPlanet, VoxelSource};
use wgpu::util::{DrawIndexedIndirectArgs, DrawIndirectArgs};

use crate::arena::{MeshArena, Slot};
use crate::cull::{Bindings, ChunkBox, CullFigures, CullFrame, Culling, MeshBox, mesh_key};

/// The colour format of offscreen targets: plain UNORM, so the clear
/// colour is stored exactly (the shader encodes sRGB itself).
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// The depth format of the terrain pass. Depth is **reversed-Z** with an
/// infinite far plane ([`view_projection`]): cleared to 0, nearer is
/// greater (`CompareFunction::Greater`). A game drawing into the same
/// depth afterwards uses the same convention.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Where the terrain pass drew sea bed (1) or not (0), for the sky pass: the
/// sea is drawn over sea bed only (and, at LODs whose voxels are taller
/// than the relief, over the sides under sea level), never over land that
/// a coarse LOD drew below sea level.
pub const SEA_MASK_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
/// Samples per pixel of the shaded view with its sky: voxels a pixel wide
/// and less (everything past the first few hundred metres) alias into
/// streaks without them. Crack checks draw with one sample, so every pixel
/// is either the terrain or the clear colour.
pub const SMOOTH_SAMPLES: u32 = 4;
/// Bytes of one chunk's entry in the per-frame chunk table.
const CHUNK_UNIFORM_BYTES: u64 = size_of::<ChunkUniform>() as u64;
/// Bytes of one indexed indirect draw (a surface range).
const DRAW_ARGS_BYTES: u64 = size_of::<DrawIndexedIndirectArgs>() as u64;
/// Bytes of one indirect draw without indices (a skirt).
const SKIRT_ARGS_BYTES: u64 = size_of::<DrawIndirectArgs>() as u64;
/// A skirt draw's first vertex holds its side in the bits from here up
/// (the skirt shader's `SIDE_SHIFT`), 6 × its first edge below.
const SKIRT_SIDE_SHIFT: u32 = 28;

/// Device features the renderer uses where the device has them: indirect
/// draws that start at a chunk's entry in the chunk table
/// (`INDIRECT_FIRST_INSTANCE`; without it every chunk range is its own
/// draw call), GPU timings (`TIMESTAMP_QUERY`) and the wireframe view
/// (`POLYGON_MODE_LINE`). Ask for `adapter.features() & WANTED_FEATURES`
/// when opening the device.
pub const WANTED_FEATURES: wgpu::Features = wgpu::Features::INDIRECT_FIRST_INSTANCE
    .union(wgpu::Features::TIMESTAMP_QUERY)
    .union(wgpu::Features::POLYGON_MODE_LINE);

/// Errors of the GPU side.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// No adapter at all (no GPU and no software driver).
    #[error("no GPU adapter found (install Mesa's software Vulkan driver: apt-get install mesa-vulkan-drivers): {0}")]
    NoAdapter(String),
    /// The adapter refused a device.
    #[error("could not open a GPU device: {0}")]
    Device(String),
    /// Reading the image back failed.
    #[error("reading the frame back failed: {0}")]
    Readback(String),
    /// An image size the device cannot draw or read back.
    #[error("a {width}×{height} image is more than this GPU can draw: {limit}")]
    TooLarge {
        /// Requested width, pixels.
        width: u32,
        /// Requested height, pixels.
        height: u32,
        /// The device limit it passes.
        limit: String,
    },
    /// A colour format the renderer cannot draw to.
    #[error("the renderer cannot draw to {0:?}: it needs a renderable, blendable colour format")]
    ColorFormat(wgpu::TextureFormat),
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    sun: [f32; 4],
    params: [f32; 4],
    eye_high: [f32; 4],
    eye_low: [f32; 4],
    /// Camera-relative clip → world, for the sky pass's view rays.
    inv_view_proj: [[f32; 4]; 4],
    /// x: planet (sea level) radius, y: eye radius, z: eye altitude (both
    /// from f64), w: the water's extinction length ([`water_extinction`]).
    planet: [f32; 4],
    /// x: 1 where the eye is in the sea (under its surface, over sea
    /// bed), else 0; y: [`sea_hiding_depth`].
    sea: [f32; 4],
    /// xyz: the eye's world position modulo `TINT_PERIOD` (from f64), w:
    /// that period: camera-relative positions plus this are world
    /// positions, exact to f32 near the eye, for the terrain's tint noise.
    tint_origin: [f32; 4],
    /// x: the LOD-0 voxel edge, y: the relief, metres
    /// ([`FrameParams::voxel_size_and_relief`]).
    terrain: [f32; 4],
}

/// Metres after which the terrain's tint noise repeats: a multiple of its
/// cells (`shader.wgsl`, `tint`), so that moving the origin by a period
/// changes nothing.
const TINT_PERIOD: f64 = 4096.0;

/// Metres of water that dim the sea bed seen through them by a factor e:
/// 3 m, or a thousandth of a small planet's radius (so that its shallow
/// seas still read as sea).
#[must_use]
pub fn water_extinction(radius: f64) -> f64 {
    (0.001 * radius).min(3.0)
}

/// The depth of water under which the sky pass hides the sea bed: light
/// from it is dimmed by e⁻¹², 6·10⁻⁶ of itself, far below an 8-bit step
/// even where the sRGB curve is steepest, so nothing under it changes a
/// pixel. (`nebula_world::stream::OpaqueSea` takes it, so that the
/// streamer leaves that sea bed coarse.)
#[must_use]
pub fn sea_hiding_depth(radius: f64) -> f64 {
    12.0 * water_extinction(radius)
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ChunkUniform {
    info: [f32; 4],
    skirt_depths: [f32; 4],
    /// Where the skirt shader reads the chunk's mesh in its page: its first
    /// vertex, its first edge word, and 1 where its edges are two words.
    pulls: [u32; 4],
}

/// Debug views.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum DebugView {
    /// Materials and sun light.
    #[default]
    Shaded,
    /// One colour per LOD.
    Lod,
    /// Skirts in magenta.
    Skirts,
    /// The geomorph factor (blue = coarse, red = fine).
    Morph,
    /// Triangle edges (where the adapter can draw lines).
    Wireframe,
    /// One colour per chunk, so chunk bounds show.
    Chunks,
    /// Each chunk's own number, unlit, for counting what shows
    /// ([`seen_chunks`](crate::seen::seen_chunks)): the 24-bit hash of its key in
    /// red, green and blue, its LOD in alpha (0–24; the background's alpha
    /// stays 255).
    Ids,
}

impl DebugView {
    /// Every view with its name, in key order (1–7 in the demo's window).
    pub const ALL: [(&'static str, DebugView); 7] = [
        ("shaded", DebugView::Shaded),
        ("lod", DebugView::Lod),
        ("skirts", DebugView::Skirts),
        ("morph", DebugView::Morph),
        ("wireframe", DebugView::Wireframe),
        ("chunks", DebugView::Chunks),
        ("ids", DebugView::Ids),
    ];
}

impl std::str::FromStr for DebugView {
    type Err = String;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Self::ALL.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|(_, v)| *v).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|(n, _)| *n).collect();
            format!("unknown view '{name}': one of {}", names.join(", "))
        })
    }
}

/// One chunk's mesh on the GPU: what [`PlanetRenderer::upload`] makes for
/// the streamer (`nebula_world::stream::MeshHandle`). Dropping it frees its
/// space in the renderer's buffers.
pub struct GpuMesh {
    /// Where its vertices, indices and skirt edges live (`None`: empty,
    /// never drawn).
    slot: Option<Slot>,
    /// Each surface part's range of indices
    /// (`nebula_meshing::ChunkMesh::surface_parts`), `[start, end)` (u32
    /// pairs, not `Range<usize>`: a cache holds tens of thousands of
    /// meshes).
    surface_parts: [[u32; 2]; SURFACE_PARTS],
    /// Each side's range of skirt edges, `[start, end)`.
    skirt_ranges: [[u32; 2]; 4],
    /// The box of its surface, occlusion culling's test.
    bounds: MeshBox,
    /// The chunk's LOD.
    pub lod: u8,
    /// A 24-bit number from the chunk key, for the chunk-colour and id
    /// views.
    pub id: u32,
    /// Bytes it takes in the renderer's buffers (its vertices, indices and
    /// skirt edges, rounded up to whole vertices and then to the arena's
    /// size class, `arena::Slot::bytes`).
    pub bytes: u64,
}

impl nebula_world::stream::MeshHandle for GpuMesh {
    fn bytes(&self) -> u64 {
        self.bytes
    }
}

/// A mesh's index or edge range as two u32s (an upload's counts already fit
/// in its u32 indices).
fn narrow_range(range: std::ops::Range<usize>) -> [u32; 2] {
    [range.start, range.end].map(|n| u32::try_from(n).unwrap_or(u32::MAX))
}

/// [`narrow_range`] back.
fn widen_range([start, end]: [u32; 2]) -> std::ops::Range<usize> {
    start as usize..end as usize
}

/// What a frame draws: the view and the per-frame constants.
#[derive(Clone, Debug)]
pub struct FrameParams {
    /// Camera position (f64, world).
    pub eye: DVec3,
    /// View direction.
    pub forward: DVec3,
    /// Up direction.
    pub up: DVec3,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f32,
    /// K of the SSE math (pixels per radian; `nebula_meshing::FrameDraw`).
    pub k: f32,
    /// τ, pixels (`nebula_meshing::FrameDraw`).
    pub threshold_px: f32,
    /// Clear colour, 0–255 per channel.
    pub background: [u8; 3],
    /// Which debug view.
    pub view: DebugView,
    /// Geomorphing on.
    pub morph: bool,
    /// The planet's coarsest LOD (for colours).
    pub max_lod: u8,
    /// Draw the sky, sea and haze of a planet of this radius (metres) over
    /// the terrain; `None` leaves the background alone (crack checks).
    pub atmosphere: Option<f64>,
    /// The eye is under the sea's surface over sea bed (not in a pit dug
    /// below sea level under land): the sky pass draws it in water.
    pub eye_in_sea: bool,
    /// Unit direction towards the sun (world).
    pub sun: Vec3,
    /// The planet's LOD-0 voxel edge and the height of its relief
    /// (lowest to highest ground), metres: where voxels are taller than
    /// the relief, their sides are no landform and are lit as the ground.
    pub voxel_size_and_relief: (f64, f64),
}

/// The clear colour behind the sky: space.
pub const SPACE: [u8; 3] = [3, 4, 9];

impl FrameParams {
    /// The shaded view of `planet` from `camera` with its sky, sea and haze
    /// and the default sun ([`crate::sun::default_sun`]): `frame` is the
    /// streamer's `frame_draw(camera.position)` and `max_lod` its tree's.
    /// Change the public fields for a debug view, a background or a sun.
    #[must_use]
    pub fn new(
        planet: &ProceduralPlanet,
        camera: &nebula_lod::Camera,
        fov_y_degrees: f64,
        frame: &FrameDraw,
        max_lod: u8,
    ) -> Self {
        Self {
            max_lod,
            eye_in_sea: eye_in_sea(planet, camera.position),
            ..Self::for_source(planet, camera, fov_y_degrees, frame, planet.relief())
        }
    }

    /// The shaded view of any voxel source (a game's own world) from
    /// `camera`, with the sky, a sea at its base radius and haze, and the
    /// default sun: `frame` is the streamer's `frame_draw(camera.position)`
    /// and `relief` how far its ground ranges in height, metres (what
    /// voxel sides are lit by). The eye is never taken to be in the sea
    /// (set [`FrameParams::eye_in_sea`] where the source can tell).
    #[must_use]
    pub fn for_source<S: VoxelSource + ?Sized>(
        source: &S,
        camera: &nebula_lod::Camera,
        fov_y_degrees: f64,
        frame: &FrameDraw,
        relief: f64,
    ) -> Self {
        let layout = source.layout();
        Self {
            eye: camera.position,
            forward: camera.forward,
            up: camera.up,
            fov_y_degrees: fov_y_degrees as f32,
            k: frame.k as f32,
            threshold_px: frame.threshold_px as f32,
            background: SPACE,
            view: DebugView::Shaded,
            morph: frame.morph,
            max_lod: layout.max_lod(),
            atmosphere: Some(layout.sphere().radius()),
            eye_in_sea: false,
            sun: crate::sun::default_sun().as_vec3(),
            voxel_size_and_relief: (layout.sphere().layer_height(), relief),
        }
    }
}

/// Whether `eye` is in `planet`'s sea: under sea level over a column
/// whose (unedited) ground lies under the sea too, not in a pit dug below
/// sea level under land.
#[must_use]
pub fn eye_in_sea(planet: &ProceduralPlanet, eye: DVec3) -> bool {
    let sea_level = planet.layout().sphere().radius();
    eye.length() < sea_level && eye.length() > 0.0 && planet.height_at(eye.normalize()) < 0.0
}

/// How the renderer draws.
#[derive(Clone, Copy, Debug)]
pub struct RendererOptions {
    /// The format of the colour target the game draws the planet into
    /// (a surface's, or [`COLOR_FORMAT`] offscreen). The shader encodes
    /// sRGB itself: give a non-sRGB format.
    pub color_format: wgpu::TextureFormat,
}

/// Figures of the last frame recorded ([`PlanetRenderer::render`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Milliseconds of CPU time to write the frame's constants and draw
    /// list, record the passes and submit them (not waiting for the GPU).
    pub encode_ms: f64,
    /// Draw commands recorded: per mesh buffer page one multi-draw for the
    /// surfaces of each index format held and one for the skirts, twice
    /// where occlusion culling draws in two passes (or a draw per chunk
    /// range where the device cannot start an indirect draw at an
    /// instance), plus the sky pass's one.
    pub draw_calls: u32,
    /// Chunk ranges drawn, surface ranges and skirts (indirect draws, or
    /// direct draws without them).
    pub chunk_draws: u32,
    /// Milliseconds the GPU spent on the terrain and sky passes of an
    /// earlier frame (timestamp queries: the newest finished measurement),
    /// `None` where the device has no timestamps or none has finished yet.
    pub gpu_ms: Option<f64>,
}

/// The index formats of the meshes in a page ([`Slot::index_format`]), in
/// the order a page's draws are grouped.
const INDEX_FORMATS: [wgpu::IndexFormat; 2] = [wgpu::IndexFormat::Uint32, wgpu::IndexFormat::Uint16];

/// The draws of one kind of the meshes of one mesh buffer page: a range
/// of the indirect draws of that kind.
#[derive(Clone, Copy, Debug)]
struct PageDraws {
    page: usize,
    /// `Some`: surface ranges of meshes with this index format; `None`:
    /// skirts.
    surface: Option<wgpu::IndexFormat>,
    first: u32,
    count: u32,
}

/// One page's draws of a frame as they are made.
#[derive(Default)]
struct PageBatch {
    /// Surface ranges by index format (as in [`INDEX_FORMATS`]).
    surface: [Vec<DrawIndexedIndirectArgs>; 2],
    skirts: Vec<DrawIndirectArgs>,
}

/// The terrain's two pipelines for one way of drawing: surfaces (indexed,
/// from a page's vertices) and skirts (no indices: the quad under each
/// outline edge, from the page's edges and vertices).
struct TerrainPipelines {
    surface: wgpu::RenderPipeline,
    skirts: wgpu::RenderPipeline,
}

/// Draws a streamed planet with a game's own wgpu device and queue: owns
/// the pipelines, the chunk meshes' buffers (uploads go through
/// [`PlanetRenderer::upload`]), the per-frame constants and draw list, and
/// the depth and sea mask the terrain and sky passes share. No global
/// state: two renderers on one device are independent.
pub struct PlanetRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// The colour format the pipelines draw to.
    color_format: wgpu::TextureFormat,
    pipeline: TerrainPipelines,
    /// The same pipelines drawing triangle edges, if the device can.
    wire_pipeline: Option<TerrainPipelines>,
    frame_buffer: wgpu::Buffer,
    frame_group: wgpu::BindGroup,
    chunk_layout: wgpu::BindGroupLayout,
    chunk_buffer: wgpu::Buffer,
    chunk_group: wgpu::BindGroup,
    chunk_capacity: u64,
    /// How the vertex shaders read a page (vertices and skirt edges), and
    /// each page's binding, made when the page first appears.
    page_layout: wgpu::BindGroupLayout,
    page_groups: Vec<wgpu::BindGroup>,
    /// This frame's draws, grouped by page, and the buffer they live in
    /// (the surface draws, then the skirt draws).
    indirect: wgpu::Buffer,
    /// Its size in bytes.
    indirect_capacity: u64,
    /// How many times the indirect buffer, and the depth targets, were
    /// made (what occlusion culling's bind groups were made for).
    generations: (u64, u64),
    page_draws: Vec<PageDraws>,
    /// The same draws on the CPU (the direct-draw fallback reads them).
    draw_args: Vec<DrawIndexedIndirectArgs>,
    skirt_args: Vec<DrawIndirectArgs>,
    /// The frame's chunk constants and draws by page as they are made,
    /// kept for their allocations (made anew each frame, their growth and
    /// page faults were a good part of the frame's encoding).
    chunk_uniforms: Vec<ChunkUniform>,
    /// The frame's draws by page.
    by_page: Vec<PageBatch>,
    /// Whether draws go through the indirect buffer (the device can start
    /// an indirect draw at an instance).
    indirect_draws: bool,
    /// Two-phase occlusion culling of the indirect draws (`crate::cull`),
    /// made where the device draws indirectly.
    culling: Option<Culling>,
    /// Whether [`Self::render`] culls ([`Self::set_occlusion_culling`]).
    occlusion_culling: bool,
    /// The frame's chunk boxes by instance, as they are made.
    chunk_boxes: Vec<ChunkBox>,
    /// Whether the last frame rendered was culled.
    culled: bool,
    /// The chunk boxes' half axes are scaled by this (1; tests shrink
    /// them to show that their checks catch a wrong cull).
    cull_box_scale: f32,
    /// The depth target and sea mask, and the sky pass's bind group that
    /// reads them.
    depth: Option<DepthTarget>,
    /// The sky pass: sky, sea and haze from the terrain's depth.
    sky_pipeline: wgpu::RenderPipeline,
    sky_layout: wgpu::BindGroupLayout,
    /// The pipelines of the multisampled shaded view, where the adapter
    /// can draw [`SMOOTH_SAMPLES`] samples in every format it needs.
    smooth: Option<SmoothPipelines>,
    /// Its multisampled targets, made the first time they are drawn to.
    smooth_targets: Option<SmoothTargets>,
    /// Whether the shaded view with its sky is multisampled
    /// ([`Self::set_multisampling`]).
    multisampling: bool,
    /// What the prepared frame draws with: the pipeline's samples and
    /// debug view, and whether the sky pass follows.
    prepared: Option<Prepared>,
    /// GPU timings, where the device has timestamps.
    timer: Option<GpuTimer>,
    stats: FrameStats,
    /// The chunk meshes' buffers and the uploads into them, shared with
    /// the threads that upload ([`PlanetRenderer::uploader`]).
    uploader: Arc<MeshUploader>,
}

/// Uploads chunk meshes into a [`PlanetRenderer`]'s buffers from any
/// thread ([`PlanetRenderer::uploader`]): the streamer's meshing threads
/// upload what they make (`nebula_world::stream::Streamer::set_uploader`),
/// so the frame thread copies no mesh bytes. The copies are recorded as
/// they come and submitted ahead of the renderer's next frame.
pub struct MeshUploader {
    device: wgpu::Device,
    /// The chunk meshes' buffers.
    arena: MeshArena,
    /// Uploads not yet submitted.
    uploads: std::sync::Mutex<Uploads>,
}

impl MeshUploader {
    /// Copies a chunk's mesh into the renderer's buffers (what the
    /// streamer's mesh maker does, [`PlanetRenderer::upload`]).
    #[must_use]
    pub fn upload(&self, key: ChunkKey, mesh: &RenderMesh) -> GpuMesh {
        // A number from the key, for the chunk-colour and id views (24
        // bits: exact as the shader's f32).
        let id = key.x.wrapping_mul(73_856_093)
            ^ key.y.wrapping_mul(19_349_663)
            ^ (key.layer as u32).wrapping_mul(83_492_791)
            ^ ((key.face as u32) << 3);
        let mut uploads = self.uploads();
        let Uploads { belt, encoder, meshes, .. } = &mut *uploads;
        let recording = encoder.get_or_insert_with(|| {
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("chunk uploads") })
        });
        let mut write = |target: &wgpu::Buffer, offset: u64, bytes: &[u8]| {
            if let Some(size) = wgpu::BufferSize::new(bytes.len() as u64) {
                belt.write_buffer(recording, target, offset, size).copy_from_slice(bytes);
            }
        };
        let slot = self.arena.upload(&self.device, &mut write, &mesh.vertices, &mesh.indices, &mesh.skirt_edges);
        *meshes += 1;
        // A full batch is closed here, on the uploading thread: closing
        // validates and records every copy (wgpu's barrier per copy), 0.7
        // of the frame thread's 1.95 ms encode in a 1 km/s flight when it
        // closed them all. Under the lock: the frame thread must not
        // finish the belt and recall its buffers while a batch that
        // writes from them is neither submitted nor in `closed`.
        if *meshes >= UPLOAD_BATCH_MESHES
            && let Some(full) = encoder.take()
        {
            *meshes = 0;
            uploads.closed.push(full.finish());
        }
        GpuMesh {
            bytes: slot.as_ref().map_or(0, Slot::bytes),
            slot,
            bounds: MeshBox::of(mesh),
            surface_parts: mesh.surface_parts.clone().map(narrow_range),
            skirt_ranges: mesh.skirt_ranges.clone().map(narrow_range),
            lod: key.lod,
            id: id % (1 << 24),
        }
    }

    /// The pending uploads. A panic while they were locked cannot have
    /// left a copy half recorded (each is recorded whole), so a poisoned
    /// lock's state is taken as it is. (A panic closing a batch, wgpu's
    /// default answer to a validation error, loses that batch's copies:
    /// the device is in error then anyway.)
    fn uploads(&self) -> std::sync::MutexGuard<'_, Uploads> {
        self.uploads.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The copies of the uploads made since the last submission, closed,
    /// in the order they were made (a slot freed and uploaded into again
    /// must get its new mesh last).
    fn take(&self) -> Vec<wgpu::CommandBuffer> {
        let (mut closed, encoder) = {
            let mut uploads = self.uploads();
            let uploads = &mut *uploads;
            uploads.meshes = 0;
            // Every staging buffer written so far is unmapped before any of
            // these copies is submitted.
            uploads.belt.finish();
            (std::mem::take(&mut uploads.closed), uploads.encoder.take())
        };
        // Closed outside the lock: an uploading thread need not wait.
        closed.extend(encoder.map(wgpu::CommandEncoder::finish));
        closed
    }

    /// Lets the staging buffers of submitted uploads be reused once the
    /// GPU is done with them.
    fn recall(&self) {
        self.uploads().belt.recall();
    }
}

/// Mesh uploads staged in reused mapped buffers and recorded as copies,
/// submitted before the next frame's draws. `queue.write_buffer` made a
/// fresh staging buffer for every mesh and freed it after the frame: on
/// the 2-core machine its page faults and frees were a fifth of the frame
/// thread's time in a flight.
struct Uploads {
    belt: wgpu::util::StagingBelt,
    /// The copies being recorded.
    encoder: Option<wgpu::CommandEncoder>,
    /// Meshes recorded into `encoder`.
    meshes: usize,
    /// Batches of copies closed by the uploading threads since the last
    /// submission, oldest first.
    closed: Vec<wgpu::CommandBuffer>,
}

/// Meshes whose copies an uploading thread records before it closes them
/// as one command buffer: a few buffers a frame for the frame thread to
/// submit, and little left for it to close.
const UPLOAD_BATCH_MESHES: usize = 16;

/// The staging belt's unit of allocation (a larger mesh gets a buffer of
/// its own size).
const STAGING_CHUNK_BYTES: u64 = 8 << 20;

/// What [`PlanetRenderer::prepare`] chose for the frame.
#[derive(Clone, Copy, Debug)]
struct Prepared {
    smooth: bool,
    view: DebugView,
    sky: bool,
    background: [u8; 3],
}

impl PlanetRenderer {
    /// A renderer drawing into `options.color_format` with `device` (opened
    /// from `adapter`, ideally with `adapter.features() & WANTED_FEATURES`)
    /// and `queue`, which it keeps (wgpu handles are shared references).
    ///
    /// # Errors
    /// [`RenderError::ColorFormat`] for an sRGB or non-renderable format.
    pub fn new(
        adapter: &wgpu::Adapter,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        options: &RendererOptions,
    ) -> Result<Self, RenderError> {
        let color_format = options.color_format;
        let renderable = adapter
            .get_texture_format_features(color_format)
            .allowed_usages
            .contains(wgpu::TextureUsages::RENDER_ATTACHMENT);
        if color_format.is_srgb() || !renderable || color_format.has_depth_aspect() {
            return Err(RenderError::ColorFormat(color_format));
        }
        let on_a_gpu = !crate::context::is_cpu(adapter);
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("nebula shader"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame layout"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: NonZeroU64::new(size_of::<FrameUniform>() as u64),
                },
                count: None,
            }],
        });
        let chunk_layout = read_only_storage_layout(device, "chunk layout", CHUNK_UNIFORM_BYTES);
        let page_layout =
            read_only_storage_layout(device, "mesh page layout", size_of::<nebula_meshing::RenderVertex>() as u64);
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("nebula pipeline layout"),
            bind_group_layouts: &[Some(&frame_layout), Some(&chunk_layout), Some(&page_layout)],
            immediate_size: 0,
        });
        // The surface reads `nebula_meshing::RenderVertex` from the page as
        // its vertex buffer; the skirts read the page as storage (their
        // edges and the vertices those name). Both convert the same bytes
        // to the same values and place them with the same code, so a
        // skirt's top corners land on the bit-identical positions of the
        // surface vertices they hang from.
        let attributes =
            wgpu::vertex_attr_array![0 => Float32x3, 1 => Float16x4, 2 => Float16x2, 3 => Snorm16x2, 4 => Uint32];
        let vertex_buffer = [Some(wgpu::VertexBufferLayout {
            array_stride: size_of::<nebula_meshing::RenderVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &attributes,
        })];
        let make_pipeline = |entry_point: &str,
                             buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
                             polygon_mode: wgpu::PolygonMode,
                             samples: u32,
                             label: &str| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &shader,
                    entry_point: Some(entry_point),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    front_face: wgpu::FrontFace::Ccw,
                    cull_mode: Some(wgpu::Face::Back),
                    polygon_mode,
                    ..Default::default()
                },
                // Reverse Z with an infinite far plane: holds from 0.1 m to
                // a planet's diameter.
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Greater),
                    stencil: wgpu::StencilState::default(),
                    bias: wgpu::DepthBiasState::default(),
                }),
                multisample: wgpu::MultisampleState { count: samples, ..Default::default() },
                fragment: Some(wgpu::FragmentState {
                    module: &shader,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[
                        Some(wgpu::ColorTargetState {
                            format: color_format,
                            blend: None,
                            write_mask: wgpu::ColorWrites::ALL,
                        }),
                        Some(wgpu::ColorTargetState {
                            format: SEA_MASK_FORMAT,
                            blend: None,
                            write_mask: wgpu::ColorWrites::ALL,
                        }),
                    ],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let make_pipelines = |polygon_mode: wgpu::PolygonMode, samples: u32, label: &str| TerrainPipelines {
            surface: make_pipeline("vs_main", &vertex_buffer, polygon_mode, samples, label),
            skirts: make_pipeline("vs_skirt", &[], polygon_mode, samples, &format!("{label}, skirts")),
        };
        let pipeline = make_pipelines(wgpu::PolygonMode::Fill, 1, "nebula terrain pipeline");
        let make_sky_layout = |multisampled: bool| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("sky layout"),
                entries: &[
                    wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Texture {
                            sample_type: wgpu::TextureSampleType::Depth,
                            view_dimension: wgpu::TextureViewDimension::D2,
                            multisampled,
                        },
                        count: None,
                    },
                    wgpu::BindGroupLayoutEntry {
                        binding: 1,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Texture {
                            sample_type: wgpu::TextureSampleType::Float { filterable: false },
                            view_dimension: wgpu::TextureViewDimension::D2,
                            multisampled: false,
                        },
                        count: None,
                    },
                ],
            })
        };
        let sky_layout = make_sky_layout(false);
        // Premultiplied: the pass writes the light scattered towards the eye
        // and, as alpha, how much of what lies behind it hides.
        let premultiplied = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::One,
            dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
            operation: wgpu::BlendOperation::Add,
        };
        // The sky pass reads the terrain's depth: one sample of it where
        // the terrain is multisampled (the same WGSL, the depth declared
        // multisampled; `textureLoad`'s last argument is then the sample).
        let smooth_shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("nebula shader, multisampled depth"),
            source: wgpu::ShaderSource::Wgsl(multisampled_depth_shader().into()),
        });
        let make_sky_pipeline = |shader: &wgpu::ShaderModule, sky_layout: &wgpu::BindGroupLayout| {
            let sky_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("sky pipeline layout"),
                bind_group_layouts: &[Some(&frame_layout), Some(sky_layout)],
                immediate_size: 0,
            });
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("nebula sky pipeline"),
                layout: Some(&sky_pipeline_layout),
                vertex: wgpu::VertexState {
                    module: shader,
                    entry_point: Some("vs_sky"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: shader,
                    entry_point: Some("fs_sky"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: color_format,
                        blend: Some(wgpu::BlendState { color: premultiplied, alpha: premultiplied }),
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let sky_pipeline = make_sky_pipeline(&shader, &sky_layout);
        let multisamples = |format: wgpu::TextureFormat, resolved: bool| {
            let flags = adapter.get_texture_format_features(format).flags;
            flags.sample_count_supported(SMOOTH_SAMPLES)
                && (!resolved || flags.contains(wgpu::TextureFormatFeatureFlags::MULTISAMPLE_RESOLVE))
        };
        let formats = [(color_format, true), (SEA_MASK_FORMAT, true), (DEPTH_FORMAT, false)];
        let smooth = formats.into_iter().all(|(format, resolved)| multisamples(format, resolved)).then(|| {
            let sky_layout = make_sky_layout(true);
            SmoothPipelines {
                terrain: make_pipelines(
                    wgpu::PolygonMode::Fill,
                    SMOOTH_SAMPLES,
                    "nebula terrain pipeline, multisampled",
                ),
                sky: make_sky_pipeline(&smooth_shader, &sky_layout),
                sky_layout,
            }
        });
        let wire_pipeline = device
            .features()
            .contains(wgpu::Features::POLYGON_MODE_LINE)
            .then(|| make_pipelines(wgpu::PolygonMode::Line, 1, "nebula wireframe pipeline"));
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame uniform"),
            size: size_of::<FrameUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let frame_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame bind group"),
            layout: &frame_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: frame_buffer.as_entire_binding() }],
        });
        let (chunk_buffer, chunk_group) = chunk_ring(device, &chunk_layout, 256);
        let indirect_draws = device.features().contains(wgpu::Features::INDIRECT_FIRST_INSTANCE);
        let culling = (indirect_draws && Culling::fits(adapter, device))
            .then(|| Culling::new(device, if smooth.is_some() { SMOOTH_SAMPLES } else { 1 }));
        let indirect = indirect_buffer(device, 1024 * DRAW_ARGS_BYTES, culling.is_some());
        let timer = device.features().contains(wgpu::Features::TIMESTAMP_QUERY).then(|| GpuTimer::new(device, queue));
        Ok(Self {
            device: device.clone(),
            queue: queue.clone(),
            color_format,
            pipeline,
            wire_pipeline,
            frame_buffer,
            frame_group,
            chunk_layout,
            chunk_buffer,
            chunk_group,
            chunk_capacity: 256,
            page_layout,
            page_groups: Vec::new(),
            indirect,
            indirect_capacity: 1024 * DRAW_ARGS_BYTES,
            generations: (0, 0),
            page_draws: Vec::new(),
            draw_args: Vec::new(),
            skirt_args: Vec::new(),
            chunk_uniforms: Vec::new(),
            by_page: Vec::new(),
            indirect_draws,
            // On by default where a GPU draws. On a CPU (lavapipe) it
            // draws no faster (the rasteriser's cost is not mostly in
            // triangles) and holds more memory: Earth 1 km over land at
            // 1280×720 settled in the same 1.67–1.76 s and peaked at
            // 479–518 MB without it against 544–610 MB with it (Mesa 22.3
            // keeps memory per compute pass, see the README).
            occlusion_culling: culling.is_some() && on_a_gpu,
            culling,
            chunk_boxes: Vec::new(),
            culled: false,
            cull_box_scale: 1.0,
            depth: None,
            sky_pipeline,
            sky_layout,
            // On by default where a GPU draws: on a CPU (lavapipe) the four
            // samples cost more than the whole frame did (Earth over the
            // mountains at 640×400: 707 ms a frame against 231 ms).
            multisampling: smooth.is_some() && on_a_gpu,
            smooth,
            smooth_targets: None,
            prepared: None,
            timer,
            stats: FrameStats::default(),
            uploader: Arc::new(MeshUploader {
                device: device.clone(),
                arena: MeshArena::default(),
                uploads: std::sync::Mutex::new(Uploads {
                    belt: wgpu::util::StagingBelt::new(device.clone(), STAGING_CHUNK_BYTES),
                    encoder: None,
                    meshes: 0,
                    closed: Vec::new(),
                }),
            }),
        })
    }

    /// The colour format the renderer draws to.
    #[must_use]
    pub fn color_format(&self) -> wgpu::TextureFormat {
        self.color_format
    }

    /// Draws the shaded view with its sky at [`SMOOTH_SAMPLES`] samples per
    /// pixel (`true`) or one; returns whether it now does (never where the
    /// adapter cannot). On by default on a GPU, off on a CPU adapter.
    /// Views over a background (crack checks) and debug views always draw
    /// one sample.
    pub fn set_multisampling(&mut self, on: bool) -> bool {
        self.multisampling = on && self.smooth.is_some();
        self.multisampling
    }

    /// Whether the shaded view with its sky is multisampled.
    #[must_use]
    pub fn multisampling(&self) -> bool {
        self.multisampling
    }

    /// Whether the frame's draws go through one indirect buffer (the
    /// device has `INDIRECT_FIRST_INSTANCE`), else a draw per chunk range.
    #[must_use]
    pub fn indirect_draws(&self) -> bool {
        self.indirect_draws
    }

    /// Draws each chunk range with its own draw call even where indirect
    /// draws are possible (for comparing the two; off by default).
    pub fn set_direct_draws(&mut self, direct: bool) {
        self.indirect_draws = !direct && self.device.features().contains(wgpu::Features::INDIRECT_FIRST_INSTANCE);
    }

    /// Culls hidden chunks on the GPU in [`Self::render`] (two-phase
    /// occlusion culling, `crate::cull`: the same picture, fewer triangles
    /// rasterised), or draws every chunk of the list; returns whether it
    /// now culls (never where draws are not indirect). On by default where
    /// it can be and a GPU draws (off on a CPU adapter such as lavapipe,
    /// where it is no faster and holds more memory).
    pub fn set_occlusion_culling(&mut self, on: bool) -> bool {
        self.occlusion_culling = on && self.culling.is_some();
        self.occlusion_culling()
    }

    /// Whether [`Self::render`] culls hidden chunks.
    #[must_use]
    pub fn occlusion_culling(&self) -> bool {
        self.occlusion_culling && self.indirect_draws
    }

    /// Scales the boxes occlusion culling tests (1 is right; smaller boxes
    /// leave out chunks that show). For tests that must show they catch a
    /// wrong cull.
    #[doc(hidden)]
    pub fn scale_cull_boxes_for_tests(&mut self, scale: f32) {
        self.cull_box_scale = scale;
    }

    /// What the last frame [`Self::render`] drew through occlusion
    /// culling: triangles and draws by phase, and what the list held;
    /// `None` when that frame was not culled. Reads the GPU's counts back
    /// and waits for it (reports and tests, not every frame).
    ///
    /// # Errors
    /// [`RenderError::Readback`] if the read-back fails.
    pub fn read_culling_figures(&self) -> Result<Option<CullFigures>, RenderError> {
        match &self.culling {
            Some(culling) if self.culled => culling.read_figures(&self.device, &self.queue).map(Some),
            _ => Ok(None),
        }
    }

    /// Copies a chunk's mesh into the renderer's buffers: the mesh maker
    /// `nebula_world::stream::Streamer::update` asks for.
    #[must_use]
    pub fn upload(&self, key: ChunkKey, mesh: &RenderMesh) -> GpuMesh {
        self.uploader.upload(key, mesh)
    }

    /// A handle that uploads into this renderer's buffers from other
    /// threads ([`MeshUploader`]): give it to the streamer's meshing
    /// threads (`Streamer::set_uploader`) and the frame thread copies no
    /// mesh.
    #[must_use]
    pub fn uploader(&self) -> Arc<MeshUploader> {
        self.uploader.clone()
    }

    /// Submits the uploads made since the last call (`prepare` and
    /// `render` do it first thing), so that their meshes can be drawn by
    /// what is submitted next, and lets the staging memory of finished
    /// ones be reused.
    pub fn finish_uploads(&self) {
        let copies = self.take_uploads();
        if !copies.is_empty() {
            self.queue.submit(copies);
            self.recall_staging();
        }
        let _ = self.device.poll(wgpu::PollType::Poll);
    }

    /// The copies of the uploads made since the last submission, closed.
    fn take_uploads(&self) -> Vec<wgpu::CommandBuffer> {
        self.uploader.take()
    }

    /// Lets the staging buffers of submitted uploads be reused once the
    /// GPU is done with them.
    fn recall_staging(&self) {
        self.uploader.recall();
    }

    /// Writes the frame's constants and its draw list for a `size` target:
    /// `meshes` with their per-chunk constants (what
    /// `Streamer::drawn` gives). Then [`Self::terrain_pass`] /
    /// [`Self::draw_terrain`] and [`Self::draw_atmosphere`], or all at once
    /// with [`Self::render`].
    pub fn prepare<'a>(
        &mut self,
        frame: &FrameParams,
        size: (u32, u32),
        meshes: impl IntoIterator<Item = (&'a GpuMesh, ChunkDraw)>,
    ) {
        self.finish_uploads();
        self.prepare_draws(frame, size, meshes);
        // Drawn whole by `draw_terrain`, never culled.
        self.culled = false;
    }

    /// [`Self::prepare`] but for the uploads, which the caller submits
    /// ahead of the draws. (Taking them twice in a frame would let the
    /// staging belt recall buffers that copies not yet submitted still
    /// read, once meshing threads upload between the two.)
    fn prepare_draws<'a>(
        &mut self,
        frame: &FrameParams,
        size: (u32, u32),
        meshes: impl IntoIterator<Item = (&'a GpuMesh, ChunkDraw)>,
    ) {
        self.ensure_depth(size);
        let aspect = size.0 as f32 / size.1.max(1) as f32;
        // Camera-relative: the eye is the origin of the render space; the
        // shader forms vertex − eye from high and low f32 parts of both
        // (`nebula_meshing::RenderVertex`), the same in every chunk.
        let view_proj = view_projection(frame.forward, frame.up, frame.fov_y_degrees, aspect);
        let sun = frame.sun;
        let (eye_high, eye_low) = split_high_low(frame.eye);
        // The sky pass only in the shaded view: debug colours stay plain.
        let sky = frame.atmosphere.filter(|_| frame.view == DebugView::Shaded);
        let radius = sky.unwrap_or(1.0);
        let uniform = FrameUniform {
            view_proj: view_proj.to_cols_array_2d(),
            sun: [sun.x, sun.y, sun.z, 0.25],
            params: [frame.k, frame.threshold_px, frame.view as u32 as f32, if frame.morph { 1.0 } else { 0.0 }],
            eye_high: [eye_high[0], eye_high[1], eye_high[2], 0.0],
            eye_low: [eye_low[0], eye_low[1], eye_low[2], 0.0],
            inv_view_proj: view_proj.inverse().to_cols_array_2d(),
            planet: [
                radius as f32,
                frame.eye.length() as f32,
                (frame.eye.length() - radius) as f32,
                water_extinction(radius) as f32,
            ],
            sea: [if frame.eye_in_sea { 1.0 } else { 0.0 }, sea_hiding_depth(radius) as f32, 0.0, 0.0],
            tint_origin: {
                let origin = frame.eye.to_array().map(|c| c.rem_euclid(TINT_PERIOD) as f32);
                [origin[0], origin[1], origin[2], TINT_PERIOD as f32]
            },
            terrain: [frame.voxel_size_and_relief.0 as f32, frame.voxel_size_and_relief.1 as f32, 0.0, 0.0],
        };
        self.queue.write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&uniform));
        // One entry per chunk in the chunk table, read by the instance
        // index; one indirect draw per drawn surface range (the surface
        // but the sides looking away) and one per skirt lowered this frame,
        // grouped by the page holding the mesh and by kind.
        let (chunk_uniforms, by_page, boxes) = (&mut self.chunk_uniforms, &mut self.by_page, &mut self.chunk_boxes);
        chunk_uniforms.clear();
        boxes.clear();
        for batch in by_page.iter_mut() {
            batch.surface.iter_mut().for_each(Vec::clear);
            batch.skirts.clear();
        }
        for (mesh, draw) in meshes {
            // An empty mesh draws nothing and needs no constants.
            let Some(slot) = &mesh.slot else { continue };
            let instance = chunk_uniforms.len() as u32;
            let wide = slot.index_format() == wgpu::IndexFormat::Uint32;
            chunk_uniforms.push(ChunkUniform {
                info: [
                    f32::from(mesh.lod),
                    f32::from(frame.max_lod),
                    mesh.id as f32,
                    draw.parent_error.min(1e30) as f32,
                ],
                skirt_depths: draw.skirt_depths,
                pulls: [slot.first_vertex(), slot.first_edge_word(), u32::from(wide), 0],
            });
            let key = mesh_key(slot.page, slot.first_vertex());
            boxes.push(mesh.bounds.relative(frame.eye, &draw, key).scaled(self.cull_box_scale));
            if by_page.len() <= slot.page {
                by_page.resize_with(slot.page + 1, Default::default);
            }
            let format = usize::from(slot.index_format() == INDEX_FORMATS[1]);
            let (first, base) = (slot.first_index(), slot.first_vertex() as i32);
            let batch = &mut by_page[slot.page];
            for range in drawn_ranges(&mesh.surface_parts.map(widen_range), &draw) {
                batch.surface[format].push(DrawIndexedIndirectArgs {
                    index_count: range.len() as u32,
                    instance_count: 1,
                    first_index: first + range.start as u32,
                    base_vertex: base,
                    first_instance: instance,
                });
            }
            // A skirt's vertex index is its side, then 6 per edge and the
            // corner (the skirt shader reads them back).
            for (side, edges) in lowered_skirts(&mesh.skirt_ranges.map(widen_range), &draw) {
                batch.skirts.push(DrawIndirectArgs {
                    vertex_count: 6 * edges.len() as u32,
                    instance_count: 1,
                    first_vertex: ((side as u32) << SKIRT_SIDE_SHIFT) | (6 * edges.start as u32),
                    first_instance: instance,
                });
            }
        }
        if chunk_uniforms.len() as u64 > self.chunk_capacity {
            let capacity = (chunk_uniforms.len() as u64).next_power_of_two();
            (self.chunk_buffer, self.chunk_group) = chunk_ring(&self.device, &self.chunk_layout, capacity);
            self.chunk_capacity = capacity;
        }
        if !chunk_uniforms.is_empty() {
            self.queue.write_buffer(&self.chunk_buffer, 0, bytemuck::cast_slice(chunk_uniforms));
        }
        self.draw_args.clear();
        self.skirt_args.clear();
        self.page_draws.clear();
        for (page, batch) in by_page.iter().enumerate() {
            for (&index_format, draws) in INDEX_FORMATS.iter().zip(&batch.surface).filter(|(_, d)| !d.is_empty()) {
                let first = self.draw_args.len() as u32;
                self.page_draws.push(PageDraws { page, surface: Some(index_format), first, count: draws.len() as u32 });
                self.draw_args.extend_from_slice(draws);
            }
        }
        for (page, batch) in by_page.iter().enumerate().filter(|(_, b)| !b.skirts.is_empty()) {
            let first = self.skirt_args.len() as u32;
            self.page_draws.push(PageDraws { page, surface: None, first, count: batch.skirts.len() as u32 });
            self.skirt_args.extend_from_slice(&batch.skirts);
        }
        // Each page the vertex shaders may read, bound once.
        {
            let pages = self.uploader.arena.lock();
            let limit = self.device.limits().max_storage_buffer_binding_size;
            for n in self.page_groups.len()..pages.len() {
                let buffer = &pages.page(n).buffer;
                self.page_groups.push(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("mesh page bind group"),
                    layout: &self.page_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer,
                            offset: 0,
                            size: NonZeroU64::new(buffer.size().min(limit)),
                        }),
                    }],
                }));
            }
        }
        let (surface_bytes, skirt_bytes) =
            (self.draw_args.len() as u64 * DRAW_ARGS_BYTES, self.skirt_args.len() as u64 * SKIRT_ARGS_BYTES);
        let block = surface_bytes + skirt_bytes;
        if self.indirect_draws && block > 0 {
            // Twice: the blocks of occlusion culling's two phases (the
            // first is the whole list where nothing culls).
            if 2 * block > self.indirect_capacity {
                self.indirect_capacity = (2 * block).next_power_of_two();
                self.indirect = indirect_buffer(&self.device, self.indirect_capacity, self.culling.is_some());
                self.generations.0 += 1;
            }
            for start in [0, block] {
                self.queue.write_buffer(&self.indirect, start, bytemuck::cast_slice(&self.draw_args));
                if skirt_bytes > 0 {
                    self.queue.write_buffer(
                        &self.indirect,
                        start + surface_bytes,
                        bytemuck::cast_slice(&self.skirt_args),
                    );
                }
            }
        }
        // The shaded view with its sky is multisampled (resolved into the
        // target and the sea mask); anything else, crack checks and debug
        // views, one sample per pixel.
        let smooth = sky.is_some() && self.multisampling;
        if smooth {
            self.ensure_smooth_targets(size);
        }
        let smooth = smooth && self.smooth_targets.is_some();
        let depth = match (&self.smooth_targets, &self.depth) {
            (Some(targets), _) if smooth => Some(&targets.depth_view),
            (_, depth) => depth.as_ref().map(|d| &d.view),
        };
        if let (Some(culling), Some(depth)) =
            (self.culling.as_mut().filter(|_| self.occlusion_culling && self.indirect_draws), depth)
        {
            let triangles = self.draw_args.iter().map(|a| u64::from(a.index_count / 3)).sum::<u64>()
                + self.skirt_args.iter().map(|a| u64::from(a.vertex_count / 3)).sum::<u64>();
            let frame = CullFrame {
                view_proj,
                draws: (self.draw_args.len() as u32, self.skirt_args.len() as u32),
                listed_triangles: triangles,
                boxes: &self.chunk_boxes,
                pages: self.page_groups.len(),
                size,
                indirect: &self.indirect,
                depth,
                bindings: Bindings { indirect: self.generations.0, targets: self.generations.1, multisampled: smooth },
            };
            culling.prepare(&self.device, &self.queue, &frame);
        }
        self.prepared = Some(Prepared { smooth, view: frame.view, sky: sky.is_some(), background: frame.background });
    }

    /// Begins the terrain pass over `target` (a view of
    /// [`Self::color_format`] at the prepared size), clearing it to the
    /// prepared background: colour, the renderer's sea mask and its
    /// reversed-Z depth ([`DEPTH_FORMAT`]), multisampled and resolved into
    /// `target` when the prepared frame is. Draw with
    /// [`Self::draw_terrain`]; a game may draw its own geometry in it too
    /// if its pipeline has the same two colour targets and depth.
    ///
    /// # Panics
    /// Before [`Self::prepare`].
    pub fn terrain_pass<'e>(
        &'e self,
        encoder: &'e mut wgpu::CommandEncoder,
        target: &'e wgpu::TextureView,
    ) -> wgpu::RenderPass<'e> {
        self.begin_terrain_pass(encoder, target, TerrainPass::Whole)
    }

    /// [`Self::terrain_pass`], or one of occlusion culling's two: the first
    /// clears and keeps its samples unresolved, the second loads them and
    /// resolves.
    fn begin_terrain_pass<'e>(
        &'e self,
        encoder: &'e mut wgpu::CommandEncoder,
        target: &'e wgpu::TextureView,
        which: TerrainPass,
    ) -> wgpu::RenderPass<'e> {
        let prepared = self.prepared.expect("PlanetRenderer::prepare before terrain_pass");
        let (clear, resolve) = (which != TerrainPass::SecondPhase, which != TerrainPass::FirstPhase);
        let bg = prepared.background.map(|c| f64::from(c) / 255.0);
        let smooth_targets = self.smooth_targets.as_ref().filter(|_| prepared.smooth);
        let resolved_mask = self.depth.as_ref().map(|d| &d.sea_mask);
        let (colour, colour_resolve) = match smooth_targets {
            Some(t) => (&t.colour_view, Some(target).filter(|_| resolve)),
            None => (target, None),
        };
        let (depth_view, sea_mask, mask_resolve) = match smooth_targets {
            Some(t) => (Some(&t.depth_view), Some(&t.mask_view), resolved_mask.filter(|_| resolve)),
            None => (self.depth.as_ref().map(|d| &d.view), resolved_mask, None),
        };
        let colour_load = if clear {
            wgpu::LoadOp::Clear(wgpu::Color { r: bg[0], g: bg[1], b: bg[2], a: 1.0 })
        } else {
            wgpu::LoadOp::Load
        };
        let (mask_load, depth_load) = if clear {
            (wgpu::LoadOp::Clear(wgpu::Color::BLACK), wgpu::LoadOp::Clear(0.0))
        } else {
            (wgpu::LoadOp::Load, wgpu::LoadOp::Load)
        };
        let timestamps =
            self.timer.as_ref().and_then(|t| t.writes(if which == TerrainPass::SecondPhase { 1 } else { 0 }));
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("terrain pass"),
            color_attachments: &[
                Some(wgpu::RenderPassColorAttachment {
                    view: colour,
                    depth_slice: None,
                    resolve_target: colour_resolve,
                    ops: wgpu::Operations { load: colour_load, store: wgpu::StoreOp::Store },
                }),
                sea_mask.map(|view| wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: mask_resolve,
                    ops: wgpu::Operations { load: mask_load, store: wgpu::StoreOp::Store },
                }),
            ],
            depth_stencil_attachment: depth_view.map(|view| wgpu::RenderPassDepthStencilAttachment {
                view,
                depth_ops: Some(wgpu::Operations { load: depth_load, store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: timestamps,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }

    /// Records the terrain [`Self::prepare`] prepared into `pass` (one
    /// begun by [`Self::terrain_pass`]), the whole list, not culled (a
    /// frame [`Self::render`] drew must be prepared again first); returns
    /// the draw commands recorded: per mesh buffer page a
    /// multi-draw-indirect for its surfaces (per index format) and one for
    /// its skirts, or one draw per chunk range where the device cannot
    /// start an indirect draw at an instance.
    pub fn draw_terrain(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        self.draw_block(pass, 0)
    }

    /// [`Self::draw_terrain`] from block `block` of the indirect buffer (0:
    /// the list, or occlusion culling's first phase; 1: its second).
    fn draw_block(&self, pass: &mut wgpu::RenderPass<'_>, block: u64) -> u32 {
        let Some(prepared) = self.prepared else { return 0 };
        let pipelines = match (&self.wire_pipeline, prepared.view, &self.smooth) {
            (_, _, Some(smooth)) if prepared.smooth => &smooth.terrain,
            (Some(wire), DebugView::Wireframe, _) => wire,
            _ => &self.pipeline,
        };
        pass.set_bind_group(0, &self.frame_group, &[]);
        // One table of per-chunk constants for the whole frame, read by
        // the instance index, instead of a bind group change per chunk:
        // on lavapipe every draw after a dynamic-offset rebind kept its
        // own copy of the descriptor state, about 800 MB per frame of
        // 8,000 chunks that was never given back.
        pass.set_bind_group(1, &self.chunk_group, &[]);
        let pages = self.uploader.arena.lock();
        let surface_bytes = self.draw_args.len() as u64 * DRAW_ARGS_BYTES;
        let block_start = block * (surface_bytes + self.skirt_args.len() as u64 * SKIRT_ARGS_BYTES);
        let skirts_from = block_start + surface_bytes;
        let mut calls = 0;
        // The surfaces (indexed), then the skirts (one pipeline change).
        let mut drawing_surfaces = None;
        for draws in &self.page_draws {
            if drawing_surfaces != Some(draws.surface.is_some()) {
                pass.set_pipeline(if draws.surface.is_some() { &pipelines.surface } else { &pipelines.skirts });
                drawing_surfaces = Some(draws.surface.is_some());
            }
            pass.set_bind_group(2, &self.page_groups[draws.page], &[]);
            let first = draws.first as usize;
            let count = draws.count as usize;
            match draws.surface {
                Some(index_format) => {
                    let buffer = &pages.page(draws.page).buffer;
                    pass.set_vertex_buffer(0, buffer.slice(..));
                    pass.set_index_buffer(buffer.slice(..), index_format);
                    if self.indirect_draws {
                        let offset = block_start + u64::from(draws.first) * DRAW_ARGS_BYTES;
                        pass.multi_draw_indexed_indirect(&self.indirect, offset, draws.count);
                        calls += 1;
                    } else {
                        for args in &self.draw_args[first..first + count] {
                            pass.draw_indexed(
                                args.first_index..args.first_index + args.index_count,
                                args.base_vertex,
                                args.first_instance..args.first_instance + 1,
                            );
                            calls += 1;
                        }
                    }
                }
                None => {
                    if self.indirect_draws {
                        let offset = skirts_from + u64::from(draws.first) * SKIRT_ARGS_BYTES;
                        pass.multi_draw_indirect(&self.indirect, offset, draws.count);
                        calls += 1;
                    } else {
                        for args in &self.skirt_args[first..first + count] {
                            pass.draw(
                                args.first_vertex..args.first_vertex + args.vertex_count,
                                args.first_instance..args.first_instance + 1,
                            );
                            calls += 1;
                        }
                    }
                }
            }
        }
        calls
    }

    /// Begins the sky pass over `target`, keeping what the terrain pass
    /// drew there, and draws sky, sea and haze from the terrain's depth
    /// and sea mask (one full-screen triangle). Nothing when the prepared
    /// frame has no atmosphere (a debug view, or over a background).
    /// Returns the draw commands recorded.
    pub fn draw_atmosphere(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView) -> u32 {
        let Some(prepared) = self.prepared.filter(|p| p.sky) else { return 0 };
        let sky_pass = match (self.smooth_targets.as_ref().filter(|_| prepared.smooth), &self.smooth) {
            (Some(targets), Some(pipelines)) => Some((&pipelines.sky, &targets.sky_group)),
            _ => self.depth.as_ref().map(|d| (&self.sky_pipeline, &d.sky_group)),
        };
        let Some((sky_pipeline, sky_group)) = sky_pass else { return 0 };
        let mut pass = keeping_pass(encoder, target, "sky pass", self.timer.as_ref().and_then(|t| t.writes(1)));
        pass.set_pipeline(sky_pipeline);
        pass.set_bind_group(0, &self.frame_group, &[]);
        pass.set_bind_group(1, sky_group, &[]);
        pass.draw(0..3, 0..1);
        1
    }

    /// The whole frame: [`Self::prepare`], the terrain pass, the sky pass,
    /// submitted. Returns (and keeps, [`Self::stats`]) its figures.
    pub fn render<'a>(
        &mut self,
        target: &wgpu::TextureView,
        size: (u32, u32),
        frame: &FrameParams,
        meshes: impl IntoIterator<Item = (&'a GpuMesh, ChunkDraw)>,
    ) -> FrameStats {
        let start = Instant::now();
        if let Some(timer) = self.timer.as_mut() {
            // A frame is timed only once the last measurement is read.
            timer.collect();
            timer.timing = !timer.pending;
        }
        // The uploads go in the frame's submission, ahead of its draws.
        let copies = self.take_uploads();
        self.prepare_draws(frame, size, meshes);
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        let draws = self.draw_args.len() + self.skirt_args.len();
        let culling =
            self.culling.as_ref().filter(|c| self.occlusion_culling && self.indirect_draws && draws > 0 && c.ready());
        self.culled = culling.is_some();
        let mut draw_calls = match culling {
            Some(culling) => {
                culling.record_first_phase(&mut encoder);
                let mut calls = {
                    let mut pass = self.begin_terrain_pass(&mut encoder, target, TerrainPass::FirstPhase);
                    self.draw_block(&mut pass, 0)
                };
                culling.record_second_phase(&mut encoder);
                let mut pass = self.begin_terrain_pass(&mut encoder, target, TerrainPass::SecondPhase);
                calls += self.draw_block(&mut pass, 1);
                calls
            }
            None => {
                let mut pass = self.terrain_pass(&mut encoder, target);
                self.draw_terrain(&mut pass)
            }
        };
        draw_calls += self.draw_atmosphere(&mut encoder, target);
        let timed = self.timer.as_mut().is_some_and(|t| t.resolve(&mut encoder));
        self.queue.submit(copies.into_iter().chain([encoder.finish()]));
        self.recall_staging();
        if timed && let Some(timer) = self.timer.as_mut() {
            timer.map();
        }
        self.stats = FrameStats {
            encode_ms: start.elapsed().as_secs_f64() * 1e3,
            draw_calls,
            chunk_draws: (self.draw_args.len() + self.skirt_args.len()) as u32,
            gpu_ms: self.timer.as_ref().and_then(|t| t.last_ms),
        };
        self.stats
    }

    /// How far the surface drawn at each pixel of the last frame lies
    /// along the view axis, metres (row 0 at the top); `f32::INFINITY`
    /// where nothing was drawn. Reads the frame's depth back and waits.
    ///
    /// # Errors
    /// [`RenderError::Readback`] before any frame, after a multisampled
    /// one (whose depth is not kept), or when the read-back fails.
    pub fn read_view_depth(&self) -> Result<Vec<f32>, RenderError> {
        let unavailable = |why: &str| RenderError::Readback(format!("no depth to read: {why}"));
        let prepared = self.prepared.ok_or_else(|| unavailable("no frame drawn yet"))?;
        if prepared.smooth {
            return Err(unavailable("the frame was multisampled (turn multisampling off)"));
        }
        let depth = self.depth.as_ref().ok_or_else(|| unavailable("no frame drawn yet"))?;
        let bytes = crate::readback::read_texture(
            &self.device,
            &self.queue,
            &depth.texture,
            depth.size,
            wgpu::TextureAspect::DepthOnly,
            4,
        )?;
        Ok(bytes
            .chunks_exact(4)
            .map(|d| {
                let d = f32::from_le_bytes([d[0], d[1], d[2], d[3]]);
                if d > 0.0 { NEAR_PLANE / d } else { f32::INFINITY }
            })
            .collect())
    }

    /// The figures of the last [`Self::render`], its GPU time included
    /// once the GPU has finished it and the device has been polled (a
    /// read-back waits for it; a window's next frame usually finds it).
    pub fn stats(&mut self) -> FrameStats {
        if let Some(timer) = self.timer.as_mut() {
            timer.collect();
            self.stats.gpu_ms = timer.last_ms;
        }
        self.stats
    }

    /// Bytes of GPU buffers held for chunk meshes (pages, used or not).
    #[must_use]
    pub fn mesh_buffer_bytes(&self) -> u64 {
        self.uploader.arena.lock().capacity_bytes()
    }

    fn ensure_depth(&mut self, size: (u32, u32)) {
        if self.depth.as_ref().is_some_and(|d| d.size == size) {
            return;
        }
        // Drawn into by the terrain pass, read by the sky pass.
        let target = |label: &str, format: wgpu::TextureFormat| {
            let texture = self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: size.0.max(1), height: size.1.max(1), depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                // Read back by `read_view_depth`.
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
            (texture, view)
        };
        let (texture, view) = target("depth", DEPTH_FORMAT);
        let (mask, sea_mask) = target("sea mask", SEA_MASK_FORMAT);
        let sky_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sky bind group"),
            layout: &self.sky_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&sea_mask) },
            ],
        });
        self.depth = Some(DepthTarget { texture, view, _mask: mask, sea_mask, size, sky_group });
        self.generations.1 += 1;
        // Their sky bind group reads the sea mask just replaced.
        self.smooth_targets = None;
    }

    /// The multisampled colour, sea mask and depth at `size`, and the sky
    /// pass's bind group reading that depth and the resolved sea mask
    /// ([`Self::ensure_depth`] first).
    fn ensure_smooth_targets(&mut self, size: (u32, u32)) {
        let Some(smooth) = &self.smooth else { return };
        if self.smooth_targets.as_ref().is_some_and(|t| t.size == size) {
            return;
        }
        let target = |label: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
            let texture = self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: size.0.max(1), height: size.1.max(1), depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: SMOOTH_SAMPLES,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | usage,
                view_formats: &[],
            });
            let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
            (texture, view)
        };
        let none = wgpu::TextureUsages::empty();
        let (colour, colour_view) = target("colour, multisampled", self.color_format, none);
        let (mask, mask_view) = target("sea mask, multisampled", SEA_MASK_FORMAT, none);
        let (depth, depth_view) = target("depth, multisampled", DEPTH_FORMAT, wgpu::TextureUsages::TEXTURE_BINDING);
        let Some(resolved) = &self.depth else { return };
        let sky_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sky bind group, multisampled"),
            layout: &smooth.sky_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&depth_view) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&resolved.sea_mask) },
            ],
        });
        self.generations.1 += 1;
        self.smooth_targets = Some(SmoothTargets {
            _textures: [colour, mask, depth],
            colour_view,
            mask_view,
            depth_view,
            sky_group,
            size,
        });
    }
}

/// The pipelines of the multisampled shaded view.
struct SmoothPipelines {
    terrain: TerrainPipelines,
    sky: wgpu::RenderPipeline,
    /// The sky pass's bindings with the depth multisampled.
    sky_layout: wgpu::BindGroupLayout,
}

/// The multisampled shaded view's targets at one size.
struct SmoothTargets {
    _textures: [wgpu::Texture; 3],
    colour_view: wgpu::TextureView,
    mask_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    /// Reads `depth_view` and the resolved sea mask.
    sky_group: wgpu::BindGroup,
    size: (u32, u32),
}

/// The terrain pass's depth and sea mask at one size, and the sky pass's
/// bind group reading both.
struct DepthTarget {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    _mask: wgpu::Texture,
    sea_mask: wgpu::TextureView,
    size: (u32, u32),
    sky_group: wgpu::BindGroup,
}

/// Timestamps at the start of the terrain pass and the end of the last
/// pass, resolved into a buffer that is read back without waiting: a frame
/// is timed only when the previous measurement has been read.
struct GpuTimer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// Set by the map callback once `readback` can be read.
    mapped: Arc<AtomicBool>,
    /// A measurement is on its way (`readback` is being mapped).
    pending: bool,
    /// This frame writes timestamps.
    timing: bool,
    period_ns: f64,
    last_ms: Option<f64>,
}

impl GpuTimer {
    fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Self {
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("frame timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        });
        let buffer = |label: &str, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Self {
            queries,
            resolve: buffer("timestamps", wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            readback: buffer("timestamps read back", wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ),
            mapped: Arc::new(AtomicBool::new(false)),
            pending: false,
            timing: false,
            period_ns: f64::from(queue.get_timestamp_period()),
            last_ms: None,
        }
    }

    /// Reads a finished measurement, if one is mapped.
    fn collect(&mut self) {
        if self.pending && self.mapped.load(Ordering::Acquire) {
            if let Ok(view) = self.readback.get_mapped_range(..) {
                let stamps: [u64; 2] = bytemuck::pod_read_unaligned(&view[..16]);
                self.last_ms = Some(stamps[1].saturating_sub(stamps[0]) as f64 * self.period_ns * 1e-6);
            }
            self.readback.unmap();
            self.pending = false;
            self.mapped.store(false, Ordering::Release);
        }
    }

    /// The timestamp writes of pass 0 (the terrain: start and end) or 1
    /// (the sky: its end), when this frame is timed.
    fn writes(&self, pass: u8) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        self.timing.then_some(wgpu::RenderPassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: (pass == 0).then_some(0),
            end_of_pass_write_index: Some(1),
        })
    }

    /// Resolves this frame's timestamps; whether it was timed.
    fn resolve(&mut self, encoder: &mut wgpu::CommandEncoder) -> bool {
        if self.timing {
            encoder.resolve_query_set(&self.queries, 0..2, &self.resolve, 0);
            encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.readback, 0, 16);
        }
        self.timing
    }

    /// Starts reading the resolved timestamps back (after the submit).
    fn map(&mut self) {
        let mapped = self.mapped.clone();
        self.readback.map_async(wgpu::MapMode::Read, .., move |result| {
            if result.is_ok() {
                mapped.store(true, Ordering::Release);
            }
        });
        self.pending = true;
        self.timing = false;
    }
}

/// The shader with the terrain's depth declared multisampled, for the sky
/// pass over a multisampled terrain (`textureLoad`'s last argument is then
/// the sample where it was the mip level, 0), with `DEPTH_SAMPLES` (the
/// samples its loops over a pixel read) [`SMOOTH_SAMPLES`].
fn multisampled_depth_shader() -> String {
    const DECLARATION: &str = "var terrain_depth: texture_depth_2d;";
    let source = include_str!("shader.wgsl");
    debug_assert!(source.contains(DECLARATION), "shader.wgsl no longer declares {DECLARATION}");
    const SAMPLES: &str = "const DEPTH_SAMPLES: i32 = 1;";
    debug_assert!(source.contains(SAMPLES), "shader.wgsl no longer declares {SAMPLES}");
    source
        .replace(DECLARATION, "var terrain_depth: texture_depth_multisampled_2d;")
        .replace(SAMPLES, &format!("const DEPTH_SAMPLES: i32 = {SMOOTH_SAMPLES};"))
}

/// A bind group layout of one read-only storage buffer the vertex shaders
/// read (the chunk table, a mesh page).
fn read_only_storage_layout(device: &wgpu::Device, label: &str, min_bytes: u64) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: NonZeroU64::new(min_bytes),
            },
            count: None,
        }],
    })
}

fn chunk_ring(device: &wgpu::Device, layout: &wgpu::BindGroupLayout, capacity: u64) -> (wgpu::Buffer, wgpu::BindGroup) {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("chunk table"),
        size: capacity * CHUNK_UNIFORM_BYTES,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("chunk bind group"),
        layout,
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() }],
    });
    (buffer, group)
}

/// Which terrain pass [`PlanetRenderer::begin_terrain_pass`] begins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TerrainPass {
    /// The only one: clears, resolves.
    Whole,
    /// Occlusion culling's first: clears, keeps the samples.
    FirstPhase,
    /// Its second: loads, resolves.
    SecondPhase,
}

/// The indirect buffer, `bytes` long; bound as storage where occlusion
/// culling sets its instance counts (`culled`).
fn indirect_buffer(device: &wgpu::Device, bytes: u64, culled: bool) -> wgpu::Buffer {
    let storage = if culled { wgpu::BufferUsages::STORAGE } else { wgpu::BufferUsages::empty() };
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("indirect draws"),
        size: bytes,
        usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST | storage,
        mapped_at_creation: false,
    })
}

/// A render pass over `target` that keeps what is drawn there (no depth):
/// a HUD draws over the planet this way.
pub fn overlay_pass<'a>(
    encoder: &'a mut wgpu::CommandEncoder,
    target: &'a wgpu::TextureView,
    label: &str,
) -> wgpu::RenderPass<'a> {
    keeping_pass(encoder, target, label, None)
}

/// [`overlay_pass`], timed when `timestamp_writes` are given.
fn keeping_pass<'a>(
    encoder: &'a mut wgpu::CommandEncoder,
    target: &'a wgpu::TextureView,
    label: &str,
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'a>>,
) -> wgpu::RenderPass<'a> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: target,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
        })],
        depth_stencil_attachment: None,
        timestamp_writes,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// The near plane of [`view_projection`], metres.
pub const NEAR_PLANE: f32 = 0.1;

/// The camera-relative view-projection (eye at the origin): right-handed
/// look-to with an orthonormalised basis, reverse-Z infinite perspective
/// (near plane [`NEAR_PLANE`]; a depth `d` lies `NEAR_PLANE / d` metres
/// along the view axis), Y up in NDC.
#[must_use]
pub fn view_projection(forward: DVec3, up: DVec3, fov_y_degrees: f32, aspect: f32) -> Mat4 {
    let (forward, _, up) = nebula_math::view_basis(forward, up);
    let view = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, forward.as_vec3(), up.as_vec3());
    glam::camera::rh::proj::directx::perspective_infinite_reverse(fov_y_degrees.to_radians(), aspect, NEAR_PLANE) * view
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The multisampled sky pass's shader is the shader with its depth
    /// declaration and its samples a pixel replaced: if either changes, so
    /// must this.
    #[test]
    fn the_sky_pass_has_a_multisampled_depth_variant() {
        let source = multisampled_depth_shader();
        assert!(source.contains("var terrain_depth: texture_depth_multisampled_2d;"));
        assert!(!source.contains("texture_depth_2d;"));
        assert!(source.contains(&format!("const DEPTH_SAMPLES: i32 = {SMOOTH_SAMPLES};")));
    }

    /// Under sea level over the sea is in the sea; the same depth under land
    /// (a pit dug below sea level) is not, nor is anywhere above sea level.
    #[test]
    fn the_eye_is_in_the_sea_only_over_sea_bed() {
        let planet = ProceduralPlanet::new(nebula_voxel::PlanetSettings::small(7)).expect("valid planet");
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

    #[test]
    fn debug_views_parse_by_name() {
        for (name, view) in DebugView::ALL {
            assert_eq!(name.parse::<DebugView>(), Ok(view));
            assert_eq!(name.to_uppercase().parse::<DebugView>(), Ok(view));
        }
        let error = "shiny".parse::<DebugView>().expect_err("no such view");
        assert!(error.contains("wireframe"), "{error}");
    }
}
