//! Offscreen rendering: settle the LOD and meshing, draw, read back, count
//! crack pixels, report.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use nebula_lod::LodSettings;
use nebula_math::{DVec3, ray_sphere};
use nebula_voxel::{PlanetSettings, ProceduralPlanet};

use crate::app::{FrameFigures, PlanetApp, View, camera};
use crate::gpu::{DebugView, Gpu, GpuError, Offscreen};

/// One picture to take.
#[derive(Clone, Debug)]
pub struct Shot {
    /// Eye, metres, planet centre at the origin.
    pub position: DVec3,
    /// Point looked at.
    pub look_at: DVec3,
    /// Up (default: radial at the eye).
    pub up: Option<DVec3>,
    /// Vertical field of view, degrees.
    pub fov_y_degrees: f64,
    /// Image size.
    pub size: (u32, u32),
    /// Clear colour; when set, nothing else is drawn over it and crack
    /// pixels are counted.
    pub background: Option<[u8; 3]>,
    /// SSE threshold τ, pixels.
    pub sse_px: f64,
    /// Frames to run before the picture (then it waits for meshing).
    pub frames: u32,
    /// Debug view.
    pub view: DebugView,
}

impl Shot {
    /// A 60° shot from `position` at `look_at`.
    #[must_use]
    pub fn looking_at(position: DVec3, look_at: DVec3, size: (u32, u32)) -> Self {
        Self {
            position,
            look_at,
            up: None,
            fov_y_degrees: 60.0,
            size,
            background: Some([255, 0, 255]),
            sse_px: 1.0,
            frames: 4,
            view: DebugView::Shaded,
        }
    }
}

/// A rendered picture and what it showed.
pub struct Picture {
    /// RGBA8, row 0 at the top.
    pub rgba: Vec<u8>,
    /// Size.
    pub size: (u32, u32),
    /// Figures of the frame.
    pub figures: Figures,
    /// The adapter that drew it.
    pub adapter: String,
}

/// The report's figures.
#[derive(Clone, Debug, Default)]
pub struct Figures {
    /// What the frame drew.
    pub frame: FrameFigures,
    /// Background pixels inside the silhouette of the sphere of minimum
    /// surface radius under the leaves in view (when a background was
    /// given).
    pub crack_pixels: Option<usize>,
    /// Pixels inside that silhouette.
    pub planet_pixels: usize,
    /// Frames run before the picture.
    pub frames: u32,
}

/// Opens a GPU for offscreen work.
///
/// # Errors
/// [`GpuError::NoAdapter`] when there is no adapter at all.
pub fn headless_gpu() -> Result<Gpu, GpuError> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    Gpu::new(&instance, None)
}

/// Renders one shot of the planet.
///
/// # Errors
/// No adapter, a bad camera (inside the planet, NaN) or bad settings.
pub fn render_shot(planet: &PlanetSettings, shot: &Shot) -> anyhow::Result<Picture> {
    let gpu = headless_gpu()?;
    let planet = ProceduralPlanet::new(planet.clone())?;
    let view = shot_view(shot)?;
    let settings = LodSettings {
        threshold_px: shot.sse_px,
        screen_height_px: f64::from(shot.size.1),
        fov_y_degrees: shot.fov_y_degrees,
        ..LodSettings::default()
    };
    let mut app = PlanetApp::new(planet, settings, gpu, view)?;
    render_app(&mut app, shot)
}

/// The LOD camera of a shot, checked.
///
/// # Errors
/// A degenerate view or a zero-sized image.
pub fn shot_view(shot: &Shot) -> anyhow::Result<View> {
    anyhow::ensure!(shot.size.0 > 0 && shot.size.1 > 0, "image size must be at least 1x1, got {:?}", shot.size);
    let forward = shot.look_at - shot.position;
    let up = shot.up.unwrap_or_else(|| {
        let radial = shot.position.normalize_or_zero();
        if forward.normalize_or_zero().cross(radial).length() > 1e-6 {
            radial
        } else {
            forward.any_orthonormal_vector()
        }
    });
    let view = View {
        camera: camera(shot.position, forward, up, f64::from(shot.size.0) / f64::from(shot.size.1)),
        fov_y_degrees: shot.fov_y_degrees,
    };
    view.camera.check()?;
    anyhow::ensure!(
        shot.fov_y_degrees.is_finite() && shot.fov_y_degrees > 0.0 && shot.fov_y_degrees < 180.0,
        "field of view must be in (0, 180) degrees, got {}",
        shot.fov_y_degrees
    );
    Ok(view)
}

/// Runs `shot.frames` frames, then waits until no meshing job is out, then
/// draws and reads back.
///
/// # Errors
/// Read-back failures.
pub fn render_app(app: &mut PlanetApp, shot: &Shot) -> anyhow::Result<Picture> {
    let view = shot_view(shot)?;
    app.set_view(view);
    let min_radius = app.min_surface_radius();
    anyhow::ensure!(
        shot.position.length() > min_radius,
        "camera is {:.1} m from the centre, inside the planet (solid below {:.1} m)",
        shot.position.length(),
        min_radius
    );
    let target = Offscreen::new(app.gpu(), shot.size);
    let background = shot.background.unwrap_or([20, 26, 38]);
    let mut frames = 0;
    let started = Instant::now();
    loop {
        app.step();
        frames += 1;
        if frames >= shot.frames && app.jobs_in_flight() == 0 {
            // One more step lets the swap show the last batch.
            app.step();
            if app.jobs_in_flight() == 0 {
                break;
            }
        }
        if started.elapsed().as_secs() > 600 {
            anyhow::bail!("meshing did not settle in 10 minutes");
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    app.draw(&target.view, shot.size, background, shot.view);
    let rgba = target.read(app.gpu()).context("reading the image back")?;
    let sentinel_radius = app.view_min_surface_radius();
    let (crack_pixels, planet_pixels) = count_cracks(&rgba, shot, &view, sentinel_radius, background);
    Ok(Picture {
        adapter: app.gpu().adapter_name.clone(),
        figures: Figures {
            frame: app.frame_figures(),
            crack_pixels: shot.background.map(|_| crack_pixels),
            planet_pixels,
            frames,
        },
        rgba,
        size: shot.size,
    })
}

/// Background-coloured pixels whose ray meets the sphere of `min_radius`
/// (a crack: the surface must cover that sphere), and how many pixels meet
/// it at all.
fn count_cracks(rgba: &[u8], shot: &Shot, view: &View, min_radius: f64, background: [u8; 3]) -> (usize, usize) {
    let (width, height) = shot.size;
    let (mut cracks, mut planet) = (0, 0);
    for py in 0..height {
        for px in 0..width {
            let dir = view.camera.pixel_ray(shot.fov_y_degrees, shot.size, (px, py));
            if ray_sphere(view.camera.position, dir, min_radius).is_none() {
                continue;
            }
            planet += 1;
            let i = ((py * width + px) * 4) as usize;
            if rgba[i..i + 3] == background {
                cracks += 1;
            }
        }
    }
    (cracks, planet)
}

/// Writes RGBA8 pixels as a PNG.
///
/// # Errors
/// I/O or encoding errors.
pub fn write_png(path: &Path, rgba: &[u8], size: (u32, u32)) -> anyhow::Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)?;
    }
    let file =
        std::io::BufWriter::new(std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?);
    let mut encoder = png::Encoder::new(file, size.0, size.1);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgba)?;
    writer.finish()?;
    Ok(())
}

/// The report as JSON.
#[must_use]
pub fn report_json(figures: &Figures, adapter: &str) -> serde_json::Value {
    let f = &figures.frame;
    let histogram: serde_json::Map<String, serde_json::Value> = f
        .lod_histogram
        .iter()
        .enumerate()
        .filter(|(_, n)| **n > 0)
        .map(|(lod, n)| (lod.to_string(), serde_json::json!(n)))
        .collect();
    serde_json::json!({
        "adapter": adapter,
        "frames": figures.frames,
        "chunks": f.chunks,
        "triangles": f.triangles,
        "skirt_triangles": f.skirt_triangles,
        "lod_histogram": histogram,
        "max_neighbor_lod_diff": f.max_neighbor_lod_diff,
        "cpu_ms": {
            "lod": f.times.lod_ms,
            "meshing": f.times.meshing_ms,
            "meshing_total": f.times.meshing_total_ms,
            "upload": f.times.upload_ms,
            "render": f.times.render_ms,
        },
        "chunks_meshed": f.times.chunks_meshed,
        "crack_pixels": figures.crack_pixels,
        "planet_pixels": figures.planet_pixels,
    })
}
