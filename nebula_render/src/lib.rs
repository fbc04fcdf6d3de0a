//! `nebula_render`: draws a streamed Nebula planet with wgpu, into a
//! game's own device, queue and colour target.
//!
//! - [`PlanetRenderer::upload`] is the mesh maker `Streamer::update`
//!   asks for: chunk meshes go into a few large buffers
//!   ([`arena::MeshArena`], pages of 34 MB sub-allocated with
//!   `offset-allocator`), never a buffer per chunk.
//! - [`PlanetRenderer::prepare`] once a frame writes the frame's constants,
//!   a table of per-chunk constants (read by the instance index) and the
//!   frame's draws as indirect commands; [`PlanetRenderer::draw_terrain`]
//!   issues per page one `multi_draw_indexed_indirect` for the surfaces
//!   and one `multi_draw_indirect` for the skirts: a frame of 20,000
//!   chunks is a handful of draw calls. Where the device lacks
//!   `INDIRECT_FIRST_INSTANCE` every chunk range is its own draw (counted
//!   in [`FrameStats::draw_calls`]).
//! - The vertex shaders place every vertex camera-relative from f64 split
//!   into two f32s and geomorph it towards its parent LOD by screen-space
//!   error; the skirt shader builds each skirt quad from an outline edge of
//!   the surface, lowered as deep as the frame needs. The fragment shader
//!   lights materials, or shows a [`DebugView`].
//! - [`PlanetRenderer::render`] culls on the GPU what nearer chunks hide
//!   (two-phase occlusion culling against a depth pyramid, `cull`; on by
//!   default where a GPU draws, [`PlanetRenderer::set_occlusion_culling`]
//!   sets it): the chunks visible the frame before are drawn, their depth
//!   reduced, and the rest drawn where their boxes may show. The same
//!   picture from fewer triangles ([`PlanetRenderer::read_culling_figures`] says how
//!   many); [`PlanetRenderer::terrain_pass`] with
//!   [`PlanetRenderer::draw_terrain`] draws the whole list in one pass.
//! - [`PlanetRenderer::draw_atmosphere`] draws sky, sea and haze over the
//!   terrain from its depth and sea mask; a game with its own sky skips it.
//! - Depth is reversed-Z with an infinite far plane ([`DEPTH_FORMAT`],
//!   cleared to 0, `Greater` passes): a game's own pass after the
//!   planet's draws against the same convention.
//! - [`context::GpuContext`] opens a device with the features the renderer
//!   uses, for programs that have none yet; [`readback::Offscreen`] reads a
//!   picture back.
//!
//! A whole frame ([`PlanetRenderer::render`] records both passes and
//! submits them):
//!
//! ```no_run
//! use std::sync::Arc;
//! use nebula_lod::{Camera, LodSettings};
//! use nebula_math::DVec3;
//! use nebula_render::{FrameParams, PlanetRenderer, RendererOptions, context::GpuContext, readback::Offscreen};
//! use nebula_voxel::{EditedSource, PlanetSettings, ProceduralPlanet};
//! use nebula_world::stream::Streamer;
//!
//! let gpu = GpuContext::headless()?;
//! let renderer = PlanetRenderer::new(&gpu.adapter, &gpu.device, &gpu.queue,
//!     &RendererOptions { color_format: gpu.color_format })?;
//! let mut renderer = renderer;
//! let planet = ProceduralPlanet::new(PlanetSettings::small(7))?;
//! let eye = DVec3::new(0.0, 0.0, 6_000.0);
//! let camera = Camera { position: eye, forward: -eye, up: DVec3::Y, aspect: 1.0 };
//! let lod = LodSettings { screen_height_px: 512.0, ..LodSettings::default() };
//! let voxels = Arc::new(EditedSource::from(planet.clone()));
//! let mut streamer = Streamer::new(voxels, lod, camera, 2, &mut |key, mesh| renderer.upload(key, mesh))?;
//! let target = Offscreen::new(&gpu, (512, 512))?;
//! for _ in 0..100 {
//!     streamer.update(camera, &mut |key, mesh| renderer.upload(key, mesh));
//!     let frame = FrameParams::new(&planet, &camera, 60.0, &streamer.frame_draw(eye), streamer.tree().max_lod());
//!     let drawn = streamer.drawn().map(|(_, chunk, draw)| (&chunk.handle, draw));
//!     let stats = renderer.render(&target.view, (512, 512), &frame, drawn);
//!     assert!(stats.draw_calls < 64);
//! }
//! let rgba = target.read(&gpu)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! `examples/fly.rs` is a window that flies over a planet (winit), in under
//! 200 lines.

pub mod arena;
pub mod context;
pub mod crack;
mod cull;
pub mod picture_error;
pub mod readback;
mod renderer;
pub mod seen;
pub mod sun;

pub use cull::CullFigures;
pub use renderer::{
    COLOR_FORMAT, DEPTH_FORMAT, DebugView, FrameParams, FrameStats, GpuMesh, MeshUploader, NEAR_PLANE, PlanetRenderer,
    RenderError, RendererOptions, SEA_MASK_FORMAT, SMOOTH_SAMPLES, SPACE, WANTED_FEATURES, eye_in_sea, overlay_pass,
    sea_hiding_depth, view_projection, water_extinction,
};
