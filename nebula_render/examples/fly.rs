//! The smallest complete program drawing a Nebula planet: a winit window,
//! a wgpu device, a streamer that meshes chunks on worker threads, and a
//! `PlanetRenderer` drawing what the streamer chose, once a frame. The
//! camera flies a circle around the small planet (2 km radius), coming
//! down from 3 km to 40 m over the ground; `earth` as the first argument
//! flies over an Earth-sized planet instead. Once every 60 frames it
//! prints what it drew. Close the window to quit.
//!
//! Run: `cargo run --release -p nebula_render --example fly [earth]`

use std::sync::Arc;
use std::time::Instant;

use nebula_lod::{Camera, LodSettings};
use nebula_math::DVec3;
use nebula_render::context::GpuContext;
use nebula_render::{FrameParams, GpuMesh, PlanetRenderer, RendererOptions};
use nebula_voxel::{EditedSource, PlanetSettings, ProceduralPlanet, VoxelSource};
use nebula_world::stream::Streamer;
use winit::application::ApplicationHandler;
use winit::event::WindowEvent;
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::window::{Window, WindowId};

const FOV_Y_DEGREES: f64 = 60.0;

/// Everything that exists once the window does.
struct Flying {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    gpu: GpuContext,
    renderer: PlanetRenderer,
    planet: ProceduralPlanet,
    streamer: Streamer<EditedSource<ProceduralPlanet>, GpuMesh>,
}

struct App {
    settings: PlanetSettings,
    started: Instant,
    frames: u64,
    flying: Option<Flying>,
}

impl App {
    /// The camera `t` seconds into the flight: once round the planet in
    /// two minutes, from 3 km up down to 40 m over the ground in the first
    /// 30 s, looking ahead over the horizon.
    fn camera(&self, planet: &ProceduralPlanet, aspect: f64) -> Camera {
        let t = self.started.elapsed().as_secs_f64();
        let angle = t * std::f64::consts::TAU / 120.0;
        let up = DVec3::new(angle.cos(), 0.3, angle.sin()).normalize();
        let ahead = DVec3::new(-angle.sin(), 0.0, angle.cos());
        let altitude = 40.0 + 2960.0 * (1.0 - (t / 30.0).min(1.0)).powi(2);
        let ground = planet.surface_point(up).length().max(planet.layout().sphere().radius());
        // Down past the horizon: the horizon dips more the higher the eye.
        let pitch = (ground / (ground + altitude)).acos() + 0.15;
        let forward = (ahead - up * ahead.dot(up)).normalize() * pitch.cos() - up * pitch.sin();
        Camera { position: up * (ground + altitude), forward, up, aspect }
    }

    fn open(&self, event_loop: &ActiveEventLoop) -> Result<Flying, Box<dyn std::error::Error>> {
        let window = Arc::new(event_loop.create_window(Window::default_attributes().with_title("Nebula: fly"))?);
        let instance = wgpu::Instance::new(nebula_render::context::instance_descriptor());
        let surface = instance.create_surface(window.clone())?;
        let gpu = GpuContext::new(&instance, Some(&surface))?;
        let size = window.inner_size();
        let config = gpu.surface_config(&surface, (size.width, size.height)).ok_or("the surface cannot be drawn to")?;
        surface.configure(&gpu.device, &config);
        let options = RendererOptions { color_format: config.format };
        let renderer = PlanetRenderer::new(&gpu.adapter, &gpu.device, &gpu.queue, &options)?;
        let planet = ProceduralPlanet::new(self.settings.clone())?;
        let camera = self.camera(&planet, f64::from(config.width) / f64::from(config.height));
        let lod = LodSettings {
            screen_height_px: f64::from(config.height),
            fov_y_degrees: FOV_Y_DEGREES,
            ..LodSettings::default()
        };
        let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
        let voxels = Arc::new(EditedSource::from(planet.clone()));
        let mut streamer = Streamer::new(voxels, lod, camera, threads, &mut |key, mesh| renderer.upload(key, mesh))?;
        // The meshing threads upload what they make: the frame copies none.
        let uploader = renderer.uploader();
        streamer.set_uploader(Some(Arc::new(move |key, mesh| uploader.upload(key, mesh))));
        Ok(Flying { window, surface, config, gpu, renderer, planet, streamer })
    }

    fn frame(&mut self) {
        let Some(f) = self.flying.as_ref() else { return };
        let (width, height) = (f.config.width, f.config.height);
        let camera = self.camera(&f.planet, f64::from(width) / f64::from(height));
        let Some(f) = self.flying.as_mut() else { return };
        // The screen the LOD tree refines for follows the window.
        let tau = f.streamer.tree().settings().threshold_px;
        if let Err(error) = f.streamer.set_view(tau, f64::from(height), FOV_Y_DEGREES) {
            eprintln!("fly: {error}");
        }
        // LOD update, finished meshes uploaded, what to draw chosen: never
        // waits for meshing.
        let renderer = &f.renderer;
        f.streamer.update(camera, &mut |key, mesh| renderer.upload(key, mesh));
        renderer.finish_uploads();
        let texture = match f.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                f.surface.configure(&f.gpu.device, &f.config);
                return;
            }
            _ => return,
        };
        let view = texture.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let frame_draw = f.streamer.frame_draw(camera.position);
        let frame = FrameParams::new(&f.planet, &camera, FOV_Y_DEGREES, &frame_draw, f.streamer.tree().max_lod());
        let drawn = f.streamer.drawn().map(|(_, chunk, draw)| (&chunk.handle, draw));
        let stats = f.renderer.render(&view, (width, height), &frame, drawn);
        f.gpu.queue.present(texture);
        // Once a second, what was drawn: in the title and on stdout.
        self.frames += 1;
        if self.frames.is_multiple_of(60) {
            let figures = f.streamer.figures();
            let line = format!(
                "{:.0} s: {} chunks, {} triangles, {} draw calls, {:.2} ms to encode",
                self.started.elapsed().as_secs_f64(),
                figures.chunks,
                figures.triangles,
                stats.draw_calls,
                stats.encode_ms
            );
            println!("{line}");
            f.window.set_title(&format!("Nebula: fly | {line}"));
        }
        f.window.request_redraw();
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.flying.is_some() {
            return;
        }
        match self.open(event_loop) {
            Ok(flying) => {
                flying.window.request_redraw();
                self.flying = Some(flying);
            }
            Err(error) => {
                eprintln!("fly: could not open the window: {error}");
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(f) = self.flying.as_mut() {
                    (f.config.width, f.config.height) = f.gpu.window_size((size.width, size.height));
                    f.surface.configure(&f.gpu.device, &f.config);
                }
            }
            WindowEvent::RedrawRequested => self.frame(),
            _ => {}
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let settings = match std::env::args().nth(1).as_deref() {
        Some("earth") => PlanetSettings::earth(11),
        _ => PlanetSettings::small(7),
    };
    let mut app = App { settings, started: Instant::now(), frames: 0, flying: None };
    EventLoop::new()?.run_app(&mut app)?;
    Ok(())
}
