//! Two-phase occlusion culling of a frame's indirect draws on the GPU.
//!
//! Why: a view of the ground draws many chunks no pixel shows, behind the
//! hills in front or past the horizon they make, that no test the streamer
//! can make proves hidden (their bounds are as tall as the relief). Through
//! a 12° lens 500 m over the Earth's plains, a third of the triangles
//! drawn fed the rasteriser for nothing.
//!
//! How (the scheme of Unreal's and Bevy's GPU occlusion culling): the
//! frame's draws are written twice into the indirect buffer, one block per
//! phase. A compute pass keeps in block 1 the chunks that were visible the
//! last time they were tested (one bit per mesh, kept on the GPU) and lie
//! in the frustum, and the first render pass draws them. Their depth is
//! reduced into a depth pyramid (each texel the farthest depth under it);
//! a second compute pass tests every chunk's box against the pyramid,
//! keeps in block 2 those the first phase did not draw and that a pixel
//! may show, and remembers each chunk's answer for the next frame; the
//! second render pass draws them. A chunk is left out only where every
//! pixel its box covers already holds something nearer than the box's
//! nearest point, so the picture is the one drawing everything makes; the
//! bits only choose which phase draws a chunk. Nothing is read back:
//! [`Culling::read_figures`] reads the frame's counts when asked (reports,
//! tests), waiting for the GPU.
//!
//! Two things lavapipe (Mesa 22.3) made us do: the cull pass reads its
//! parameters from a storage buffer, not a uniform one (a compute pass
//! binding a uniform buffer kept about 0.9 MB of the process's memory a
//! pass, inside the driver: 1.8 MB a frame); and the shader computes the
//! pyramid's level sizes (`textureDimensions` with a level that varies by
//! invocation gave level 0's size there).

use bytemuck::{Pod, Zeroable};
use glam::{DVec3, Mat4, Vec3};
use nebula_meshing::{ChunkDraw, RenderMesh};

use crate::RenderError;
use crate::arena::PAGE_UNITS;

/// A chunk's box for the cull pass (`cull.wgsl`'s `ChunkBox`): camera
/// relative, its centre and three half axes, and the key of its mesh's
/// visibility bit.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct ChunkBox {
    centre: [f32; 3],
    key: u32,
    half_axes: [[f32; 4]; 3],
}

/// The box around a mesh's surface, oriented along the planet's vertical
/// at the mesh: every vertex's morph target and finest position lies in
/// it (a morphed vertex lies between the two). Oriented, not along the
/// world's axes: a patch of ground tilted to them fills its world box
/// only along a diagonal, and the box's top then rises a tilt times its
/// width over the ground, over the horizon a far chunk hides behind.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MeshBox {
    /// Where the box's axes start, world metres.
    origin: DVec3,
    /// The planet's vertical there (the box's third axis).
    up: Vec3,
    /// Its extent along each axis from `origin`, metres, rounded outwards.
    low: Vec3,
    high: Vec3,
}

impl MeshBox {
    /// The box of `mesh`'s vertices (empty meshes get a point).
    pub(crate) fn of(mesh: &RenderMesh) -> Self {
        let decoded = mesh.targets_and_offsets();
        let count = decoded.len().max(1) as f64;
        let origin = decoded.iter().fold(DVec3::ZERO, |sum, &(target, _)| sum + target) / count;
        // The axes `relative` makes from the stored (f32) vertical.
        let up = origin.normalize_or(DVec3::Z).as_vec3();
        let axes = box_axes(up.as_dvec3());
        let (mut low, mut high) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for &(target, offset) in &decoded {
            for p in [target, target + offset.as_dvec3()] {
                let local = DVec3::from_array(axes.map(|axis| axis.dot(p - origin)));
                low = low.min(local);
                high = high.max(local);
            }
        }
        if mesh.vertices.is_empty() {
            (low, high) = (DVec3::ZERO, DVec3::ZERO);
        }
        // A centimetre spare for the f32 rounding of the extents.
        Self { origin, up, low: (low - 0.01).as_vec3(), high: (high + 0.01).as_vec3() }
    }

    /// The box camera relative to `eye` as the cull pass reads it,
    /// stretched down by the chunk's deepest skirt this frame (a skirt
    /// hangs from the outline towards the planet's centre; that direction
    /// turns over the chunk by its angle seen from the centre, hence the
    /// spare sideways) and grown for the f32 rounding of the vertex
    /// shader's positions and the box's.
    pub(crate) fn relative(&self, eye: DVec3, draw: &ChunkDraw, key: u32) -> ChunkBox {
        let axes = box_axes(self.up.as_dvec3());
        let (low, high) = (self.low.as_dvec3(), self.high.as_dvec3());
        let depth = f64::from(draw.skirt_depths.iter().fold(0.0_f32, |a, &b| a.max(b)));
        let sideways = depth * (high - low).length() / self.origin.length().max(1.0);
        let relative = self.origin - eye;
        let spare = 0.05 + 1e-6 * relative.length();
        let low = low - DVec3::new(sideways, sideways, depth) - spare;
        let high = high + DVec3::new(sideways, sideways, 0.0) + spare;
        let (middle, half) = (0.5 * (low + high), 0.5 * (high - low));
        let centre = relative + axes[0] * middle.x + axes[1] * middle.y + axes[2] * middle.z;
        ChunkBox {
            centre: centre.as_vec3().to_array(),
            key,
            half_axes: [0, 1, 2].map(|k| {
                let axis = (axes[k] * half[k]).as_vec3();
                [axis.x, axis.y, axis.z, 0.0]
            }),
        }
    }
}

impl ChunkBox {
    /// The box with its half axes times `scale` (a test's deliberately
    /// wrong box, [`crate::PlanetRenderer::scale_cull_boxes_for_tests`]).
    pub(crate) fn scaled(mut self, scale: f32) -> Self {
        for axis in &mut self.half_axes {
            *axis = axis.map(|c| c * scale);
        }
        self
    }
}

/// Two horizontal axes and `up`, orthonormal.
fn box_axes(up: DVec3) -> [DVec3; 3] {
    let across = if up.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let east = (across - up * across.dot(up)).normalize();
    [east, up.cross(east), up]
}

/// `cull.wgsl`'s `CullParams`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CullParams {
    view_proj: [[f32; 4]; 4],
    screen: [f32; 2],
    near: f32,
    mips: u32,
    surface_draws: u32,
    skirt_draws: u32,
    pad: [u32; 2],
}

/// Bytes of the parameters ahead of the boxes in the boxes buffer.
const PARAMS_BYTES: u64 = size_of::<CullParams>() as u64;

/// The key of a mesh's visibility bit: its page and first vertex. Unique
/// among the meshes of ordinary pages; a mesh too large for one (a page
/// of its own, longer) may share a bit with the next page's, and a freed
/// slot's bit passes to the next mesh there: a bit only decides which
/// phase draws a chunk, never whether it is drawn where it may show.
#[must_use]
pub(crate) fn mesh_key(page: usize, first_vertex: u32) -> u32 {
    (page as u32) * PAGE_UNITS + first_vertex
}

/// What a culled frame drew, by phase ([`crate::PlanetRenderer::read_culling_figures`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CullFigures {
    /// Triangles the first phase drew (chunks visible when last tested).
    pub first_phase_triangles: u64,
    /// Triangles the second phase drew (chunks the depth pyramid did not
    /// hide and the first phase left).
    pub second_phase_triangles: u64,
    /// Indirect draws (chunk ranges) each phase kept.
    pub draws: [u32; 2],
    /// Indirect draws the frame's list held (the most either could keep).
    pub listed_draws: u32,
    /// Triangles the frame's list held.
    pub listed_triangles: u64,
}

impl CullFigures {
    /// Triangles sent to the rasteriser.
    #[must_use]
    pub fn triangles(&self) -> u64 {
        self.first_phase_triangles + self.second_phase_triangles
    }
}

/// The depth pyramid at one size: its levels' views and the bind groups
/// that reduce each level into the next.
struct Pyramid {
    size: (u32, u32),
    mips: u32,
    /// All levels, sampled by the cull pass.
    view: wgpu::TextureView,
    /// Level 0 as the first reduction's output.
    first_level: wgpu::TextureView,
    /// Per level from 1: the group reading the level below.
    down_groups: Vec<wgpu::BindGroup>,
    _texture: wgpu::Texture,
}

/// The pipelines, buffers and depth pyramid of occlusion culling.
pub(crate) struct Culling {
    cull: wgpu::ComputePipeline,
    cull_layout: wgpu::BindGroupLayout,
    /// The pyramid's first level from single-sample and multisampled depth.
    first: [(wgpu::ComputePipeline, wgpu::BindGroupLayout); 2],
    down: wgpu::ComputePipeline,
    down_layout: wgpu::BindGroupLayout,
    /// The frame's parameters, then its chunk boxes by instance.
    boxes: wgpu::Buffer,
    box_capacity: u64,
    /// A bit per mesh key: visible when last tested (1 when never).
    visible: wgpu::Buffer,
    visible_words: u64,
    counts: wgpu::Buffer,
    pyramid: Option<Pyramid>,
    /// The frame's surface and skirt draws.
    draws: (u32, u32),
    /// The triangles the frame's list holds, for the figures.
    listed_triangles: u64,
    /// The bind groups of both cull passes and of the pyramid's first
    /// level, made again only when what they bind changes, and what they
    /// were made for: the renderer's indirect buffer and depth targets
    /// (its counts of how often it made them) and whether the depth is
    /// multisampled.
    groups: Option<Groups>,
}

/// [`Culling`]'s bind groups and what they bind.
struct Groups {
    cull: wgpu::BindGroup,
    first_level: wgpu::BindGroup,
    made_for: Bindings,
}

/// A frame as [`Culling::prepare`] takes it.
#[derive(Clone, Copy)]
pub(crate) struct CullFrame<'a> {
    /// The terrain's camera-relative view-projection.
    pub view_proj: Mat4,
    /// Surface and skirt draws in each block of the indirect buffer.
    pub draws: (u32, u32),
    /// Triangles the list holds (surfaces and skirts).
    pub listed_triangles: u64,
    /// The chunks' boxes by instance (as the chunk table).
    pub boxes: &'a [ChunkBox],
    /// Mesh pages held (each has `PAGE_UNITS` visibility bits).
    pub pages: usize,
    /// The target's size, pixels.
    pub size: (u32, u32),
    /// The indirect buffer (both blocks) and the depth the first phase
    /// draws into, with what says whether they changed.
    pub indirect: &'a wgpu::Buffer,
    pub depth: &'a wgpu::TextureView,
    pub bindings: Bindings,
}

/// What the renderer binds into [`Culling`]'s groups: its generations of
/// the indirect buffer and the depth targets, and which depth is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Bindings {
    pub indirect: u64,
    pub targets: u64,
    pub multisampled: bool,
}

/// Workgroup size of the cull pass (`cull.wgsl`).
const CULL_GROUP: u32 = 64;
/// Workgroup edge of the pyramid's passes (`pyramid.wgsl`).
const PYRAMID_GROUP: u32 = 8;

impl Culling {
    /// Whether the device can cull: compute shaders, four storage buffers
    /// and a storage texture in one compute stage (a downlevel device that
    /// cannot draws the whole list instead).
    pub(crate) fn fits(adapter: &wgpu::Adapter, device: &wgpu::Device) -> bool {
        let limits = device.limits();
        adapter.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
            && limits.max_storage_buffers_per_shader_stage >= 4
            && limits.max_storage_textures_per_shader_stage >= 1
            && limits.max_compute_workgroups_per_dimension >= 2
    }

    pub(crate) fn new(device: &wgpu::Device, samples: u32) -> Self {
        let cull_shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("occlusion culling"),
            source: wgpu::ShaderSource::Wgsl(include_str!("cull.wgsl").into()),
        });
        let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let texture =
            |binding: u32, sample_type: wgpu::TextureSampleType, multisampled: bool| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Texture {
                    sample_type,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled,
                },
                count: None,
            };
        let unfiltered = wgpu::TextureSampleType::Float { filterable: false };
        let cull_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("occlusion culling layout"),
            entries: &[
                storage(1, true),
                storage(2, false),
                storage(3, false),
                storage(4, false),
                texture(5, unfiltered, false),
            ],
        });
        let pipeline = |module: &wgpu::ShaderModule, layout: &wgpu::BindGroupLayout, entry: &str| {
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(entry),
                bind_group_layouts: &[Some(layout)],
                immediate_size: 0,
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let cull = pipeline(&cull_shader, &cull_layout, "cull");
        let level_out = wgpu::BindGroupLayoutEntry {
            binding: 1,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: wgpu::TextureFormat::R32Float,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        };
        // The first level's pipeline from single-sample depth, and from
        // multisampled depth where the renderer draws it (the same
        // pipeline otherwise: index 1 is what `multisampled` picks).
        let first_level = |samples: u32| {
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("depth pyramid, first level"),
                entries: &[texture(0, wgpu::TextureSampleType::Depth, samples > 1), level_out],
            });
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("depth pyramid"),
                source: wgpu::ShaderSource::Wgsl(pyramid_shader(samples).into()),
            });
            (pipeline(&module, &layout, "hzb_first"), layout, module)
        };
        let (single, single_layout, pyramid_module) = first_level(1);
        let multisampled = if samples > 1 {
            let (pipeline, layout, _) = first_level(samples);
            (pipeline, layout)
        } else {
            (single.clone(), single_layout.clone())
        };
        let first = [(single, single_layout), multisampled];
        let down_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("depth pyramid, coarser levels"),
            entries: &[level_out, texture(2, unfiltered, false)],
        });
        let down = pipeline(&pyramid_module, &down_layout, "hzb_down");
        let buffer = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false })
        };
        let box_capacity = 256;
        Self {
            cull,
            cull_layout,
            first,
            down,
            down_layout,
            boxes: box_buffer(device, box_capacity),
            box_capacity,
            visible: visible_buffer(device, 1),
            visible_words: 1,
            counts: buffer(
                "culling counts",
                16,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            ),
            pyramid: None,
            draws: (0, 0),
            listed_triangles: 0,
            groups: None,
        }
    }

    /// Writes `frame`'s parameters and chunk boxes, sizes the visibility
    /// bits for its mesh pages and the pyramid for its target, makes the
    /// bind groups again if what they bind changed, and remembers the
    /// list's size for the figures.
    pub(crate) fn prepare(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, frame: &CullFrame<'_>) {
        let CullFrame { view_proj, draws, listed_triangles, boxes, pages, size, indirect, depth, bindings } = *frame;
        if boxes.len() as u64 > self.box_capacity {
            self.box_capacity = (boxes.len() as u64).next_power_of_two();
            self.boxes = box_buffer(device, self.box_capacity);
            self.groups = None;
        }
        if !boxes.is_empty() {
            queue.write_buffer(&self.boxes, PARAMS_BYTES, bytemuck::cast_slice(boxes));
        }
        let words = (pages.max(1) as u64) * u64::from(PAGE_UNITS / 32);
        if words > self.visible_words {
            // Every mesh visible: the first frame after draws them all in
            // the first phase, as a frame with no history does.
            self.visible = visible_buffer(device, words);
            self.visible_words = words;
            self.groups = None;
        }
        if self.pyramid.as_ref().is_none_or(|p| p.size != size) {
            self.pyramid = Some(self.make_pyramid(device, size));
            self.groups = None;
        }
        if self.groups.as_ref().is_none_or(|g| g.made_for != bindings) {
            self.groups = self.make_groups(device, indirect, depth, bindings);
        }
        if let Some(pyramid) = &self.pyramid {
            let params = CullParams {
                view_proj: view_proj.to_cols_array_2d(),
                screen: [pyramid.size.0.max(1) as f32, pyramid.size.1.max(1) as f32],
                near: crate::NEAR_PLANE,
                mips: pyramid.mips,
                surface_draws: draws.0,
                skirt_draws: draws.1,
                pad: [0; 2],
            };
            queue.write_buffer(&self.boxes, 0, bytemuck::bytes_of(&params));
        }
        self.draws = draws;
        self.listed_triangles = listed_triangles;
    }

    /// Whether [`Self::prepare`] made everything the passes bind.
    pub(crate) fn ready(&self) -> bool {
        self.pyramid.is_some() && self.groups.is_some()
    }

    fn make_groups(
        &self,
        device: &wgpu::Device,
        indirect: &wgpu::Buffer,
        depth: &wgpu::TextureView,
        bindings: Bindings,
    ) -> Option<Groups> {
        let pyramid = self.pyramid.as_ref()?;
        let cull = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("occlusion culling"),
            layout: &self.cull_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 1, resource: self.boxes.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: indirect.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: self.visible.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: self.counts.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&pyramid.view) },
            ],
        });
        let first_level = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth pyramid, first level"),
            layout: &self.first[usize::from(bindings.multisampled)].1,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(depth) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&pyramid.first_level) },
            ],
        });
        Some(Groups { cull, first_level, made_for: bindings })
    }

    fn make_pyramid(&self, device: &wgpu::Device, size: (u32, u32)) -> Pyramid {
        let (width, height) = (size.0.max(1), size.1.max(1));
        let mips = 32 - width.max(height).leading_zeros();
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("depth pyramid"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: mips,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Float,
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let level = |mip: u32| {
            texture.create_view(&wgpu::TextureViewDescriptor {
                base_mip_level: mip,
                mip_level_count: Some(1),
                ..Default::default()
            })
        };
        let down_groups = (1..mips)
            .map(|mip| {
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("depth pyramid level"),
                    layout: &self.down_layout,
                    entries: &[
                        wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&level(mip)) },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::TextureView(&level(mip - 1)),
                        },
                    ],
                })
            })
            .collect();
        Pyramid {
            size,
            mips,
            view: texture.create_view(&wgpu::TextureViewDescriptor::default()),
            first_level: level(0),
            down_groups,
            _texture: texture,
        }
    }

    /// Records the first phase's cull pass: block 1 of `indirect` keeps
    /// the chunks visible when last tested and in the frustum (block 2
    /// emptied), and the counts start again.
    pub(crate) fn record_first_phase(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.counts, 0, None);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("cull, first phase"),
            timestamp_writes: None,
        });
        self.dispatch(&mut pass, 0);
    }

    /// Records the depth pyramid's reduction of the depth (what the first
    /// phase drew) and the second phase's cull pass: block 2 keeps what
    /// the pyramid does not hide and the first phase did not draw; every
    /// chunk's bit is its answer.
    pub(crate) fn record_second_phase(&self, encoder: &mut wgpu::CommandEncoder) {
        let (Some(pyramid), Some(bound)) = (&self.pyramid, &self.groups) else { return };
        let first = &self.first[usize::from(bound.made_for.multisampled)].0;
        let groups = |mip: u32| {
            let (w, h) = ((pyramid.size.0 >> mip).max(1), (pyramid.size.1 >> mip).max(1));
            (w.div_ceil(PYRAMID_GROUP), h.div_ceil(PYRAMID_GROUP))
        };
        // One pass: each dispatch sees what the one before wrote.
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("depth pyramid, cull"),
            timestamp_writes: None,
        });
        let levels = std::iter::once((first, &bound.first_level))
            .chain(pyramid.down_groups.iter().map(|group| (&self.down, group)));
        for (mip, (pipeline, group)) in (0..).zip(levels) {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, group, &[]);
            let (x, y) = groups(mip);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.dispatch(&mut pass, 1);
    }

    /// Records the cull pass of `phase` (0 or 1) into `pass`: one row of
    /// workgroups for the first, two for the second (the shader tells them
    /// apart by that; the second row works).
    fn dispatch(&self, pass: &mut wgpu::ComputePass<'_>, phase: u32) {
        let Some(bound) = &self.groups else { return };
        pass.set_pipeline(&self.cull);
        pass.set_bind_group(0, &bound.cull, &[]);
        pass.dispatch_workgroups((self.draws.0 + self.draws.1).div_ceil(CULL_GROUP), 1 + phase, 1);
    }

    /// What the last culled frame drew, read back (waits for the GPU).
    pub(crate) fn read_figures(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<CullFigures, RenderError> {
        let bytes = crate::readback::read_buffer(device, queue, &self.counts, 16)?;
        let counts: [u32; 4] = bytemuck::pod_read_unaligned(&bytes[..16]);
        Ok(CullFigures {
            first_phase_triangles: u64::from(counts[0]),
            second_phase_triangles: u64::from(counts[1]),
            draws: [counts[2], counts[3]],
            listed_draws: self.draws.0 + self.draws.1,
            listed_triangles: self.listed_triangles,
        })
    }
}

fn box_buffer(device: &wgpu::Device, capacity: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("chunk boxes"),
        size: PARAMS_BYTES + capacity * size_of::<ChunkBox>() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// `words` of visibility bits, all set.
fn visible_buffer(device: &wgpu::Device, words: u64) -> wgpu::Buffer {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("chunk visibility"),
        size: words * 4,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: true,
    });
    // (Were the mapping refused, the bits would be 0: every chunk then
    // waits for the second phase's test, which draws what shows.)
    if let Ok(mut bits) = buffer.slice(..).get_mapped_range_mut() {
        bits.copy_from_slice(&vec![0xff; bits.len()]);
    }
    buffer.unmap();
    buffer
}

/// `pyramid.wgsl` reading depth of `samples` samples a pixel.
fn pyramid_shader(samples: u32) -> String {
    const SAMPLES: &str = "const DEPTH_SAMPLES: i32 = 1;";
    const DEPTH: &str = "var terrain_depth: texture_depth_2d;";
    let source = include_str!("pyramid.wgsl");
    debug_assert!(source.contains(SAMPLES) && source.contains(DEPTH), "pyramid.wgsl's declarations changed");
    if samples == 1 {
        return source.to_owned();
    }
    source
        .replace(SAMPLES, &format!("const DEPTH_SAMPLES: i32 = {samples};"))
        .replace(DEPTH, "var terrain_depth: texture_depth_multisampled_2d;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use nebula_lod::ChunkLodContext;
    use nebula_meshing::{ChunkMeshBuffer, FrameDraw, MeshOptions, mesh_chunk};
    use nebula_voxel::{ChunkColumn, CubeFace, PlanetSettings, ProceduralPlanet, VoxelSource};
    use proptest::prelude::*;

    /// Surface chunks of a small planet at LODs 0–3 around one place, as
    /// the streamer meshes them (made once).
    fn meshes() -> &'static [RenderMesh] {
        static MESHES: std::sync::OnceLock<Vec<RenderMesh>> = std::sync::OnceLock::new();
        MESHES.get_or_init(make_meshes)
    }

    fn make_meshes() -> Vec<RenderMesh> {
        let planet = ProceduralPlanet::new(PlanetSettings::small(7)).expect("valid planet");
        let mut buffer = ChunkMeshBuffer::new();
        let mut meshes = Vec::new();
        for lod in 0..4u8 {
            for (x, y) in [(1, 2), (2, 2), (3, 1)] {
                let column = ChunkColumn { face: CubeFace::PosY, lod, x: x >> lod, y: y >> lod };
                let layers = planet.surface_chunk_layers(column).expect("on the planet");
                for layer in layers {
                    let key = column.chunk(layer);
                    let context = ChunkLodContext::uniform(lod);
                    let mesh = mesh_chunk(&planet, key, &context, MeshOptions::STREAMING, &mut buffer).expect("meshes");
                    if !mesh.is_empty() {
                        meshes.push(mesh.render_mesh());
                    }
                }
            }
        }
        meshes
    }

    /// How far `point` lies outside `b` (0 inside), metres.
    fn outside(b: &ChunkBox, point: DVec3) -> f64 {
        let offset = point - Vec3::from_array(b.centre).as_dvec3();
        b.half_axes
            .iter()
            .map(|a| {
                let axis = DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]));
                let half = axis.length();
                (offset.dot(axis / half).abs() - half).max(0.0)
            })
            .fold(0.0, f64::max)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// Every point the vertex shaders may place, morphed to any degree
        /// and with skirts lowered as deep as the frame asks, lies in the
        /// box the cull pass tests, camera relative, from any eye: near
        /// the ground and across the planet.
        #[test]
        fn a_chunks_box_holds_everything_it_draws(
            eye in prop::array::uniform3(-4_000.0..4_000.0_f64),
            depths in prop::array::uniform4(0.0..60.0_f32),
            k in 10.0..4_000.0_f64,
            morph in any::<bool>(),
        ) {
            let eye = DVec3::from_array(eye);
            let frame = FrameDraw::new(eye, k, 1.0, morph);
            let meshes = meshes();
            prop_assert!(meshes.len() > 6);
            for mesh in meshes {
                let draw = ChunkDraw::new(4.0, depths);
                let b = MeshBox::of(mesh).relative(frame.eye(), &draw, 0);
                for point in mesh.drawn_triangles(&frame, &draw).iter().flatten() {
                    let out = outside(&b, *point);
                    prop_assert!(out == 0.0, "{point} lies {out} m outside the box {b:?}");
                }
            }
        }
    }
}
