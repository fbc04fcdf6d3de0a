//! The wgpu side: device, pipeline, per-chunk buffers, drawing and read-back.
//! Knows nothing about LOD or meshing: it draws the meshes it is given.

use std::num::NonZeroU64;

use bytemuck::{Pod, Zeroable};
use glam::{DVec3, Mat4, Vec3};
use nebula_meshing::{ChunkDraw, RenderVertex, split_high_low};

use crate::arena::{MeshArena, Slot};
use nebula_meshing::{RenderMesh, drawn_ranges};

/// The colour format of the offscreen target: plain UNORM, so the clear
/// colour is stored exactly (the shader encodes sRGB itself).
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Where the terrain pass drew sea bed (1) or not (0), for the sky pass: the
/// sea is drawn over sea bed only (and, at LODs whose voxels are taller
/// than the relief, over the sides under sea level), never over land that a coarse LOD drew
/// below sea level.
const SEA_MASK_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
/// Samples per pixel of the shaded view with its sky: voxels a pixel wide
/// and less (everything past the first few hundred metres) alias into
/// streaks without them. Crack checks draw with one sample, so every pixel
/// is either the terrain or the clear colour.
const SMOOTH_SAMPLES: u32 = 4;
/// Bytes of one chunk's entry in the per-frame chunk table.
const CHUNK_UNIFORM_BYTES: u64 = size_of::<ChunkUniform>() as u64;

/// Errors of the GPU side.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
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
/// pixel.
#[must_use]
pub fn sea_hiding_depth(radius: f64) -> f64 {
    12.0 * water_extinction(radius)
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ChunkUniform {
    info: [f32; 4],
    skirt_depths: [f32; 4],
}

/// Debug views, chosen by key or flag.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
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
}

/// One chunk's mesh on the GPU.
pub struct GpuMesh {
    /// Where its vertices and indices live (`None`: empty, never drawn).
    slot: Option<Slot>,
    surface_side_ranges: [std::ops::Range<usize>; 6],
    skirt_ranges: [std::ops::Range<usize>; 4],
    /// The chunk's LOD.
    pub lod: u8,
    /// A small number from the chunk key, for the chunk-colour view.
    pub id: u32,
    /// Bytes of its vertices and indices in the arena.
    pub bytes: u64,
}

impl nebula_world::stream::MeshHandle for GpuMesh {
    fn bytes(&self) -> u64 {
        self.bytes
    }
}

/// What a frame draws: the view and the per-frame constants.
pub struct FrameParams {
    /// Camera position (f64, world).
    pub eye: DVec3,
    /// View direction.
    pub forward: DVec3,
    /// Up direction.
    pub up: DVec3,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f32,
    /// K of the SSE math (pixels per radian).
    pub k: f32,
    /// τ, pixels.
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

/// Device, queue, pipeline and the per-chunk uniform ring.
pub struct Gpu {
    /// The device.
    pub device: wgpu::Device,
    /// The queue.
    pub queue: wgpu::Queue,
    /// What the adapter says it is.
    pub adapter_name: String,
    /// The colour format the pipeline draws to.
    pub color_format: wgpu::TextureFormat,
    adapter: wgpu::Adapter,
    pipeline: wgpu::RenderPipeline,
    /// The same pipeline drawing triangle edges, if the adapter can.
    wire_pipeline: Option<wgpu::RenderPipeline>,
    frame_buffer: wgpu::Buffer,
    frame_group: wgpu::BindGroup,
    chunk_layout: wgpu::BindGroupLayout,
    chunk_buffer: wgpu::Buffer,
    chunk_group: wgpu::BindGroup,
    chunk_capacity: u64,
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
    /// The chunk meshes' buffers.
    arena: MeshArena,
}

impl Gpu {
    /// Opens the first adapter wgpu offers (lavapipe on a machine with no
    /// GPU), optionally one that can present to `surface`. Draws to
    /// [`COLOR_FORMAT`] offscreen, or to the surface's first non-sRGB format.
    ///
    /// # Errors
    /// [`GpuError::NoAdapter`] or [`GpuError::Device`].
    pub fn new(instance: &wgpu::Instance, surface: Option<&wgpu::Surface<'_>>) -> Result<Self, GpuError> {
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: surface,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let adapter_name = adapter.get_info().name;
        let on_a_gpu = adapter.get_info().device_type != wgpu::DeviceType::Cpu;
        let color_format = match surface {
            None => COLOR_FORMAT,
            Some(surface) => {
                let formats = surface.get_capabilities(&adapter).formats;
                formats.iter().copied().find(|f| !f.is_srgb()).or(formats.first().copied()).unwrap_or(COLOR_FORMAT)
            }
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("nebula device"),
            required_features: adapter.features() & wgpu::Features::POLYGON_MODE_LINE,
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
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
        let chunk_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("chunk layout"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: NonZeroU64::new(CHUNK_UNIFORM_BYTES),
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("nebula pipeline layout"),
            bind_group_layouts: &[Some(&frame_layout), Some(&chunk_layout)],
            immediate_size: 0,
        });
        // The layout of `nebula_meshing::RenderVertex`.
        let attributes =
            wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x3, 3 => Snorm16x2, 4 => Uint32];
        let make_pipeline = |polygon_mode: wgpu::PolygonMode, samples: u32, label: &str| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &shader,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: size_of::<RenderVertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &attributes,
                    })],
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
        let pipeline = make_pipeline(wgpu::PolygonMode::Fill, 1, "nebula terrain pipeline");
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
                terrain: make_pipeline(
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
            .then(|| make_pipeline(wgpu::PolygonMode::Line, 1, "nebula wireframe pipeline"));
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
        let (chunk_buffer, chunk_group) = chunk_ring(&device, &chunk_layout, 256);
        Ok(Self {
            device,
            queue,
            adapter_name,
            color_format,
            adapter,
            pipeline,
            wire_pipeline,
            frame_buffer,
            frame_group,
            chunk_layout,
            chunk_buffer,
            chunk_group,
            chunk_capacity: 256,
            depth: None,
            sky_pipeline,
            sky_layout,
            // On by default where a GPU draws: on a CPU (lavapipe) the four
            // samples cost more than the whole frame did (Earth over the
            // mountains at 640×400: 707 ms a frame against 231 ms).
            multisampling: smooth.is_some() && on_a_gpu,
            smooth,
            smooth_targets: None,
            arena: MeshArena::default(),
        })
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

    /// A configuration for presenting to `surface` at `size`.
    #[must_use]
    pub fn surface_config(&self, surface: &wgpu::Surface<'_>, size: (u32, u32)) -> Option<wgpu::SurfaceConfiguration> {
        let (width, height) = self.window_size(size);
        let mut config = surface.get_default_config(&self.adapter, width, height)?;
        config.format = self.color_format;
        config.present_mode = wgpu::PresentMode::AutoVsync;
        Some(config)
    }

    /// Uploads a chunk mesh into the mesh arena; `key_id` colours the chunk
    /// view.
    #[must_use]
    pub fn upload(&self, mesh: &RenderMesh, lod: u8, key_id: u32) -> GpuMesh {
        let slot = self.arena.upload(&self.device, &self.queue, &mesh.vertices, &mesh.indices);
        GpuMesh {
            slot,
            surface_side_ranges: mesh.surface_side_ranges.clone(),
            skirt_ranges: mesh.skirt_ranges.clone(),
            lod,
            id: key_id % 4096,
            bytes: mesh.bytes(),
        }
    }

    /// Draws `meshes`, each with its per-chunk draw constants, into
    /// `target` (of `size`), clearing to the background.
    pub fn draw(
        &mut self,
        target: &wgpu::TextureView,
        size: (u32, u32),
        frame: &FrameParams,
        meshes: &[(&GpuMesh, ChunkDraw)],
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
        if meshes.len() as u64 > self.chunk_capacity {
            let capacity = (meshes.len() as u64).next_power_of_two();
            let (buffer, group) = chunk_ring(&self.device, &self.chunk_layout, capacity);
            self.chunk_buffer = buffer;
            self.chunk_group = group;
            self.chunk_capacity = capacity;
        }
        let chunk_uniforms: Vec<ChunkUniform> = meshes
            .iter()
            .map(|(m, draw)| ChunkUniform {
                info: [f32::from(m.lod), f32::from(frame.max_lod), m.id as f32, draw.parent_error.min(1e30) as f32],
                skirt_depths: draw.skirt_depths,
            })
            .collect();
        if !chunk_uniforms.is_empty() {
            self.queue.write_buffer(&self.chunk_buffer, 0, bytemuck::cast_slice(&chunk_uniforms));
        }
        let bg = frame.background.map(|c| f64::from(c) / 255.0);
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        // The shaded view with its sky is multisampled (resolved into
        // `target` and the sea mask); anything else, crack checks and
        // debug views, one sample per pixel.
        let smooth = sky.is_some() && self.multisampling;
        if smooth {
            self.ensure_smooth_targets(size);
        }
        let smooth_targets = self.smooth_targets.as_ref().filter(|_| smooth);
        let pages = self.arena.lock();
        {
            let resolved_mask = self.depth.as_ref().map(|d| &d.sea_mask);
            let (colour, colour_resolve) = match smooth_targets {
                Some(t) => (&t.colour_view, Some(target)),
                None => (target, None),
            };
            let (depth_view, sea_mask, mask_resolve) = match smooth_targets {
                Some(t) => (Some(&t.depth_view), Some(&t.mask_view), resolved_mask),
                None => (self.depth.as_ref().map(|d| &d.view), resolved_mask, None),
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("terrain pass"),
                color_attachments: &[
                    Some(wgpu::RenderPassColorAttachment {
                        view: colour,
                        depth_slice: None,
                        resolve_target: colour_resolve,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color { r: bg[0], g: bg[1], b: bg[2], a: 1.0 }),
                            store: wgpu::StoreOp::Store,
                        },
                    }),
                    sea_mask.map(|view| wgpu::RenderPassColorAttachment {
                        view,
                        depth_slice: None,
                        resolve_target: mask_resolve,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                    }),
                ],
                depth_stencil_attachment: depth_view.map(|view| wgpu::RenderPassDepthStencilAttachment {
                    view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            let pipeline = match (&self.wire_pipeline, frame.view, &self.smooth) {
                (_, _, Some(smooth)) if smooth_targets.is_some() => &smooth.terrain,
                (Some(wire), DebugView::Wireframe, _) => wire,
                _ => &self.pipeline,
            };
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &self.frame_group, &[]);
            // One table of per-chunk constants for the whole frame, read by
            // the instance index, instead of a bind group change per chunk:
            // on lavapipe every draw after a dynamic-offset rebind kept its
            // own copy of the descriptor state, about 800 MB per frame of
            // 8,000 chunks that was never given back.
            pass.set_bind_group(1, &self.chunk_group, &[]);
            let mut bound = None;
            for (n, (mesh, draw)) in meshes.iter().enumerate() {
                let Some(slot) = &mesh.slot else { continue };
                // The surface but the sides looking away, and only the
                // skirts lowered this frame.
                let ranges = drawn_ranges(&mesh.surface_side_ranges, &mesh.skirt_ranges, draw);
                if ranges.iter().all(std::ops::Range::is_empty) {
                    continue;
                }
                let instance = n as u32;
                if bound != Some(slot.page) {
                    let page = pages.page(slot.page);
                    pass.set_vertex_buffer(0, page.vertices.slice(..));
                    pass.set_index_buffer(page.indices.slice(..), wgpu::IndexFormat::Uint32);
                    bound = Some(slot.page);
                }
                let (first, base) = (slot.first_index(), slot.first_vertex() as i32);
                for range in ranges.into_iter().filter(|r| !r.is_empty()) {
                    pass.draw_indexed(
                        first + range.start as u32..first + range.end as u32,
                        base,
                        instance..instance + 1,
                    );
                }
            }
        }
        let sky_pass = match (smooth_targets, &self.smooth) {
            (Some(targets), Some(pipelines)) => Some((&pipelines.sky, &targets.sky_group)),
            _ => self.depth.as_ref().map(|d| (&self.sky_pipeline, &d.sky_group)),
        };
        if let (Some(_), Some((sky_pipeline, sky_group))) = (sky, sky_pass) {
            // Sky, sea and haze over the terrain, from its depth: one
            // full-screen triangle.
            let mut pass = overlay_pass(&mut encoder, target, "sky pass");
            pass.set_pipeline(sky_pipeline);
            pass.set_bind_group(0, &self.frame_group, &[]);
            pass.set_bind_group(1, sky_group, &[]);
            pass.draw(0..3, 0..1);
        }
        drop(pages);
        self.queue.submit([encoder.finish()]);
    }

    /// A window size this device can draw: each side clamped to 1 ..= its
    /// largest texture side (a window larger than that is drawn at the
    /// limit and stretched by the compositor, with a message).
    #[must_use]
    pub fn window_size(&self, (width, height): (u32, u32)) -> (u32, u32) {
        let side = self.device.limits().max_texture_dimension_2d;
        let clamped = (width.clamp(1, side), height.clamp(1, side));
        if clamped.0 < width || clamped.1 < height {
            eprintln!(
                "nebula-demo: a {width}×{height} window is drawn at {}×{} (this GPU's limit)",
                clamped.0, clamped.1
            );
        }
        clamped
    }

    /// Checks that this device can draw a `size` image and read it back
    /// (its largest texture side and buffer), so a request past the
    /// limits is refused before any work, not as a panic inside wgpu.
    ///
    /// # Errors
    /// [`GpuError::TooLarge`] naming the limit.
    pub fn check_image_size(&self, (width, height): (u32, u32)) -> Result<(), GpuError> {
        let limits = self.device.limits();
        let too_large = |limit: String| Err(GpuError::TooLarge { width, height, limit });
        let side = limits.max_texture_dimension_2d;
        if width == 0 || height == 0 || width > side || height > side {
            return too_large(format!("each side must be 1 to {side} pixels"));
        }
        let row = u64::from(width * 4).div_ceil(u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT))
            * u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let bytes = row * u64::from(height);
        if bytes > limits.max_buffer_size {
            return too_large(format!(
                "its read-back buffer of {bytes} bytes passes the {} byte limit",
                limits.max_buffer_size
            ));
        }
        Ok(())
    }

    /// Bytes of GPU buffers held for chunk meshes (pages, used or not).
    #[must_use]
    pub fn mesh_buffer_bytes(&self) -> u64 {
        self.arena.lock().capacity_bytes()
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
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
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
        self.depth = Some(DepthTarget { _texture: texture, view, _mask: mask, sea_mask, size, sky_group });
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
    terrain: wgpu::RenderPipeline,
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

/// The shader with the terrain's depth declared multisampled, for the sky
/// pass over a multisampled terrain (`textureLoad`'s last argument is then
/// the sample, 0, where it was the mip level, 0).
fn multisampled_depth_shader() -> String {
    const DECLARATION: &str = "var terrain_depth: texture_depth_2d;";
    let source = include_str!("shader.wgsl");
    debug_assert!(source.contains(DECLARATION), "shader.wgsl no longer declares {DECLARATION}");
    source.replace(DECLARATION, "var terrain_depth: texture_depth_multisampled_2d;")
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

/// A render pass over `target` that keeps what is drawn there (no depth):
/// the sky pass and the HUD draw over the terrain this way.
pub fn overlay_pass<'a>(
    encoder: &'a mut wgpu::CommandEncoder,
    target: &'a wgpu::TextureView,
    label: &str,
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
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// The terrain pass's depth and sea mask at one size, and the sky pass's
/// bind group reading both.
struct DepthTarget {
    _texture: wgpu::Texture,
    view: wgpu::TextureView,
    _mask: wgpu::Texture,
    sea_mask: wgpu::TextureView,
    size: (u32, u32),
    sky_group: wgpu::BindGroup,
}

/// An offscreen colour target and the buffer it is read back through.
pub struct Offscreen {
    texture: wgpu::Texture,
    /// View to draw into.
    pub view: wgpu::TextureView,
    size: (u32, u32),
}

impl Offscreen {
    /// A `width` × `height` target.
    ///
    /// # Errors
    /// [`GpuError::TooLarge`] past the device's limits
    /// ([`Gpu::check_image_size`]).
    pub fn new(gpu: &Gpu, size: (u32, u32)) -> Result<Self, GpuError> {
        gpu.check_image_size(size)?;
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen colour"),
            size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: COLOR_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        Ok(Self { texture, view, size })
    }

    /// The image size.
    #[must_use]
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// Copies the image back: RGBA8, row 0 at the top, no row padding.
    ///
    /// # Errors
    /// [`GpuError::Readback`] if mapping fails.
    pub fn read(&self, gpu: &Gpu) -> Result<Vec<u8>, GpuError> {
        let (width, height) = self.size;
        let unpadded = width * 4;
        let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let padded = unpadded.div_ceil(align) * align;
        let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read-back"),
            size: u64::from(padded) * u64::from(height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("read-back") });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        gpu.queue.submit([encoder.finish()]);
        let (sender, receiver) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |result| {
            let _ = sender.send(result);
        });
        gpu.device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        receiver
            .recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let mut pixels = Vec::with_capacity((unpadded * height) as usize);
        {
            let mapped = buffer.get_mapped_range(..).map_err(|e| GpuError::Readback(e.to_string()))?;
            for row in mapped.chunks_exact(padded as usize) {
                pixels.extend_from_slice(&row[..unpadded as usize]);
            }
        }
        buffer.unmap();
        Ok(pixels)
    }
}

/// The camera-relative view-projection (eye at the origin): right-handed
/// look-to with an orthonormalised basis, reverse-Z infinite perspective
/// (near plane 0.1 m), Y up in NDC.
#[must_use]
pub fn view_projection(forward: DVec3, up: DVec3, fov_y_degrees: f32, aspect: f32) -> Mat4 {
    let (forward, _, up) = nebula_math::view_basis(forward, up);
    let view = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, forward.as_vec3(), up.as_vec3());
    glam::camera::rh::proj::directx::perspective_infinite_reverse(fov_y_degrees.to_radians(), aspect, 0.1) * view
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The multisampled sky pass's shader is the shader with its depth
    /// declaration replaced: if the declaration changes, so must this.
    #[test]
    fn the_sky_pass_has_a_multisampled_depth_variant() {
        let source = multisampled_depth_shader();
        assert!(source.contains("var terrain_depth: texture_depth_multisampled_2d;"));
        assert!(!source.contains("texture_depth_2d;"));
    }
}
