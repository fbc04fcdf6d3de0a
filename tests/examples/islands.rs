//! A world a game brings, drawn by Nebula: floating rock islands over an
//! ocean floor (`nebula_tests::islands::FloatingIslands`, a `VoxelSource`
//! of its own) streamed by `nebula_world`'s `Streamer` and drawn by
//! `nebula_render`'s `PlanetRenderer` headless, exactly as the procedural
//! planet is. Writes `islands.png` (sky and sea on) and prints what it drew.
//!
//! Run: `cargo run --release -p nebula_tests --example islands`

use std::sync::Arc;

use nebula_lod::{Camera, LodSettings};
use nebula_render::context::GpuContext;
use nebula_render::readback::Offscreen;
use nebula_render::{FrameParams, PlanetRenderer, RendererOptions};
use nebula_tests::islands::FloatingIslands;
use nebula_world::stream::Streamer;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let world = Arc::new(FloatingIslands::new(2_000.0, 6, 7)?);
    // 90 m from the first island's rim, 30 m over its top, looking at it.
    let (up, top) = world.island_tops()[20];
    let aside = up.any_orthonormal_vector();
    let eye = (up * 0.97 + aside * 0.03).normalize() * (top + 30.0);
    let camera = Camera { position: eye, forward: up * top - eye, up: eye.normalize(), aspect: 16.0 / 9.0 };
    let (size, fov) = ((960, 540), 60.0);
    let settings = LodSettings { screen_height_px: f64::from(size.1), fov_y_degrees: fov, ..LodSettings::default() };
    let gpu = GpuContext::headless()?;
    let mut renderer = PlanetRenderer::new(
        &gpu.adapter,
        &gpu.device,
        &gpu.queue,
        &RendererOptions { color_format: gpu.color_format },
    )?;
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let mut streamer =
        Streamer::new(world.clone(), settings, camera, threads, &mut |key, mesh| renderer.upload(key, mesh))?;
    let started = std::time::Instant::now();
    while !streamer.settled() {
        streamer.update(camera, &mut |key, mesh| renderer.upload(key, mesh));
        renderer.finish_uploads();
        std::thread::sleep(std::time::Duration::from_millis(16));
    }
    let mut frame = FrameParams::for_source(&*world, &camera, fov, &streamer.frame_draw(eye), 250.0);
    // Afternoon at the camera: high, from behind it and to the side.
    frame.sun = (eye.normalize() * 0.8 - camera.forward.normalize() * 0.4 + aside * 0.3).normalize().as_vec3();
    let target = Offscreen::new(&gpu, size)?;
    renderer.render(&target.view, size, &frame, streamer.drawn().map(|(_, chunk, draw)| (&chunk.handle, draw)));
    let rgba = target.read(&gpu)?;
    nebula_demo::headless::write_png(std::path::Path::new("islands.png"), &rgba, size)?;
    let figures = streamer.figures();
    println!(
        "islands.png: settled in {:.2} s, {} chunks drawn, {} triangles",
        started.elapsed().as_secs_f64(),
        figures.chunks,
        figures.triangles
    );
    Ok(())
}
