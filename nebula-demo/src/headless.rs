//! Offscreen rendering: settle the LOD and meshing, draw, read back, count
//! crack pixels, report.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use nebula_lod::LodSettings;
use nebula_math::DVec3;
use nebula_voxel::{PlanetSettings, ProceduralPlanet};

use crate::app::{FrameFigures, PlanetApp, PlanetVoxels, View, camera};
use nebula_render::DebugView;
use nebula_render::context::GpuContext;
use nebula_render::readback::Offscreen;

use nebula_render::crack::CrackCount;

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
    /// Frames to run before the picture (then it waits until settled).
    pub frames: u32,
    /// Debug view.
    pub view: DebugView,
    /// Sun elevation and azimuth in degrees over the horizon at
    /// `position`, azimuth from the view direction (see
    /// [`nebula_render::sun::sun_direction`]); `None` keeps the app's sun.
    pub sun: Option<(f64, f64)>,
}

impl Shot {
    /// The LOD settings this shot is drawn with: its τ, image height and
    /// field of view.
    #[must_use]
    pub fn lod_settings(&self) -> LodSettings {
        LodSettings {
            threshold_px: self.sse_px,
            screen_height_px: f64::from(self.size.1),
            fov_y_degrees: self.fov_y_degrees,
            ..LodSettings::default()
        }
    }

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
            sun: None,
        }
    }
}

/// The node bound ([`LodSettings::max_nodes`]) for a picture-error
/// reference drawn at `reference_px` beside a shot at `shot_px`: `budget`
/// scaled by `(shot_px / reference_px)²`, as a tree holds about 1/τ² as
/// many nodes (a finer τ refines the same area, twice as far per halving,
/// in two directions), at most 16 times `budget`. Without it a narrow
/// lens's reference is raised by the bound towards the shot's own τ (a
/// 12° lens at 640×400 asked for 0.5 px was drawn at 0.93 px) and
/// measures next to nothing. A reference no finer than the shot keeps
/// `budget`.
#[must_use]
pub fn reference_node_budget(budget: usize, shot_px: f64, reference_px: f64) -> usize {
    let ratio = shot_px / reference_px;
    if ratio.is_nan() || ratio <= 1.0 || ratio.is_infinite() {
        return budget;
    }
    let scale = (ratio * ratio).min(16.0);
    (budget as f64 * scale).round() as usize
}

/// The voxels a picture-error reference is drawn from: `voxels`' planet
/// with every noise octave at every LOD (`PlanetSettings::band_limit` 0)
/// and the same edits. The reference stands for the terrain itself, so a
/// shot whose coarse LODs leave octaves out is measured against the ground
/// with them, not against a finer view that leaves out octaves too.
///
/// # Errors
/// The planet's settings errors; an edit that is not on the planet (it was
/// on the same planet, so none).
pub fn every_octave_reference(voxels: &PlanetVoxels) -> anyhow::Result<PlanetVoxels> {
    let settings = PlanetSettings { band_limit: 0.0, ..voxels.base().settings().clone() };
    let mut reference = PlanetVoxels::new(ProceduralPlanet::new(settings)?);
    for (at, voxel) in voxels.edits() {
        reference.set_voxel(at, voxel)?;
    }
    Ok(reference)
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
    /// Crack pixels by both rules (when a background was given; see
    /// [`crate::crack`]).
    pub crack_pixels: Option<usize>,
    /// The oracle's breakdown.
    pub cracks: CrackCount,
    /// Pixels whose ray meets the sentinel sphere.
    pub planet_pixels: usize,
    /// Frames run before the picture.
    pub frames: u32,
    /// Milliseconds from the start to the first complete frame (no stand-in
    /// more than [`MAX_FIRST_FRAME_LEVELS`] LODs coarser than its leaf).
    pub first_frame_ms: f64,
    /// Milliseconds from the start to the settled view.
    pub settled_ms: f64,
    /// Milliseconds the draw and read-back took.
    pub draw_ms: f64,
    /// What the renderer recorded: CPU time to encode and submit, draw
    /// commands, GPU time where the device has timestamps.
    pub render: nebula_render::FrameStats,
    /// Milliseconds the crack oracle took.
    pub check_ms: f64,
    /// Bytes of the GPU buffers holding the meshes (arena pages, used or
    /// not).
    pub gpu_buffer_bytes: u64,
    /// Pixels in the picture (for triangles per pixel).
    pub pixels: u64,
    /// What occlusion culling let through to the rasteriser, when the
    /// frame was culled.
    pub culling: Option<nebula_render::CullFigures>,
}

/// The process's peak resident memory so far (Linux `VmHWM`), bytes;
/// `None` where the system does not say.
#[must_use]
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|line| line.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The first frame is drawn once no visible leaf is stood in for by an
/// ancestor more than this many LODs coarser: close enough that the stand-in
/// lies within a few pixels of the truth, never over the camera.
pub const MAX_FIRST_FRAME_LEVELS: u8 = 3;

/// Puts `app`'s sun where `shot` asks ([`Shot::sun`], over the horizon at
/// its camera); nothing when it asks for none.
///
/// # Errors
/// [`nebula_render::sun::SunError`] for a bad elevation, azimuth or camera.
pub fn place_sun(app: &mut PlanetApp, shot: &Shot) -> Result<(), nebula_render::sun::SunError> {
    if let Some((elevation, azimuth)) = shot.sun {
        app.set_sun(nebula_render::sun::sun_direction(
            shot.position,
            shot.look_at - shot.position,
            elevation,
            azimuth,
        )?)?;
    }
    Ok(())
}

/// Renders one shot of the planet.
///
/// # Errors
/// No adapter, a bad camera (inside the planet, NaN) or bad settings.
pub fn render_shot(planet: &PlanetSettings, shot: &Shot) -> anyhow::Result<Picture> {
    let gpu = GpuContext::headless()?;
    let planet = ProceduralPlanet::new(planet.clone())?;
    let view = shot_view(shot)?;
    let mut app = PlanetApp::new(planet, shot.lod_settings(), gpu, view)?;
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
        screen_height_px: f64::from(shot.size.1),
    };
    view.camera.check()?;
    anyhow::ensure!(
        shot.fov_y_degrees.is_finite() && shot.fov_y_degrees > 0.0 && shot.fov_y_degrees < 180.0,
        "field of view must be in (0, 180) degrees, got {}",
        shot.fov_y_degrees
    );
    Ok(view)
}

/// Steps `app` until it can draw a complete first frame (stand-ins at
/// most [`MAX_FIRST_FRAME_LEVELS`] LODs coarse), meshing at full speed.
/// Returns the milliseconds it took.
///
/// # Errors
/// If that takes more than 10 minutes.
pub fn prime(app: &mut PlanetApp) -> anyhow::Result<f64> {
    let started = Instant::now();
    loop {
        let step_started = Instant::now();
        app.step();
        app.submit_uploads();
        let list = app.draw_list();
        if list.holes == 0 && list.max_stand_in_levels <= MAX_FIRST_FRAME_LEVELS {
            return Ok(started.elapsed().as_secs_f64() * 1e3);
        }
        anyhow::ensure!(started.elapsed().as_secs() < 600, "no complete frame in 10 minutes");
        pace(step_started);
    }
}

/// Frames are stepped at most [`FRAME_RATE`] a second, as a game would:
/// stepping as fast as possible re-runs the selection hundreds of times a
/// second and takes CPU from the meshing workers.
pub const FRAME_RATE: f64 = 60.0;

/// Sleeps out the rest of a frame that started at `started`.
fn pace(started: Instant) {
    let frame = std::time::Duration::from_secs_f64(1.0 / FRAME_RATE);
    if let Some(rest) = frame.checked_sub(started.elapsed()) {
        std::thread::sleep(rest);
    }
}

/// Runs at least `shot.frames` frames and until the view has settled (no
/// stand-ins, no jobs), then draws, reads back and counts cracks:
/// [`prepare_shot`] then [`settle_and_draw`].
///
/// # Errors
/// As those two.
pub fn render_app(app: &mut PlanetApp, shot: &Shot) -> anyhow::Result<Picture> {
    let view = prepare_shot(app, shot)?;
    settle_and_draw(app, shot, &view)
}

/// Sets `app` up for `shot`: its view and sun, CPU meshes kept for the
/// crack check when a background is given, and the sea drawn (so the sea
/// bed it hides is left coarse) when not. Returns the view.
///
/// # Errors
/// A bad view or sun, an image too large for the adapter, or a camera
/// inside the planet.
pub fn prepare_shot(app: &mut PlanetApp, shot: &Shot) -> anyhow::Result<View> {
    let view = shot_view(shot)?;
    app.gpu().check_image_size(shot.size)?;
    app.set_view(view);
    place_sun(app, shot)?;
    let min_radius = app.min_surface_radius();
    anyhow::ensure!(
        shot.position.length() > min_radius,
        "camera is {:.1} m from the centre, inside the planet (solid below {:.1} m)",
        shot.position.length(),
        min_radius
    );
    app.keep_cpu_meshes(shot.background.is_some());
    app.set_sea_drawn(shot.background.is_none() && shot.view == DebugView::Shaded);
    Ok(view)
}

/// Steps `app` at [`FRAME_RATE`] for at least `shot.frames` frames and
/// until it has settled, then draws `view` ([`draw_frame`]), with the
/// times to the first complete frame and to settled.
///
/// # Errors
/// Read-back failures, or no settled view in 10 minutes.
pub fn settle_and_draw(app: &mut PlanetApp, shot: &Shot, view: &View) -> anyhow::Result<Picture> {
    let started = Instant::now();
    let first_frame_ms = prime(app)?;
    let mut frames = 0;
    loop {
        let step_started = Instant::now();
        app.step();
        app.submit_uploads();
        frames += 1;
        if frames >= shot.frames && app.settled() {
            break;
        }
        anyhow::ensure!(started.elapsed().as_secs() < 600, "meshing did not settle in 10 minutes");
        pace(step_started);
    }
    let settled_ms = started.elapsed().as_secs_f64() * 1e3;
    let mut picture = draw_frame(app, shot, view)?;
    picture.figures.frames = frames;
    picture.figures.first_frame_ms = first_frame_ms;
    picture.figures.settled_ms = settled_ms;
    Ok(picture)
}

/// Draws the app's current draw list from `view`, reads it back and counts
/// cracks (with a background).
///
/// # Errors
/// Read-back failures.
pub fn draw_frame(app: &mut PlanetApp, shot: &Shot, view: &View) -> anyhow::Result<Picture> {
    let target = Offscreen::new(app.gpu(), shot.size)?;
    if app.renderer().occlusion_culling() {
        // Occlusion culling draws first what was visible the frame before;
        // a game draws every frame, a settled shot only this one: draw it
        // once unread, as the frame before.
        app.draw(&target.view, shot.size, shot.background, shot.view);
        // Finished before the frame measured starts.
        app.gpu()
            .device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
            .context("waiting for the frame before")?;
    }
    draw_into(app, shot, view, &target, true)
}

/// [`draw_frame`] into `target` (`shot`'s size); without `read_back` the
/// picture's pixels are left empty and no cracks are counted, and it waits
/// for the GPU to finish the frame instead: what a game's frame costs, one
/// frame at a time.
///
/// # Errors
/// Read-back failures.
pub fn draw_into(
    app: &mut PlanetApp,
    shot: &Shot,
    view: &View,
    target: &Offscreen,
    read_back: bool,
) -> anyhow::Result<Picture> {
    let started = Instant::now();
    app.draw(&target.view, shot.size, shot.background, shot.view);
    let rgba = if read_back {
        target.read(app.gpu()).context("reading the image back")?
    } else {
        app.gpu()
            .device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
            .context("waiting for the frame")?;
        Vec::new()
    };
    // The read-back or the wait waited for the frame: its GPU time is in.
    let render = app.renderer_mut().stats();
    let culling = app.renderer().read_culling_figures().context("reading occlusion culling's counts back")?;
    let draw_ms = started.elapsed().as_secs_f64() * 1e3;
    let started = Instant::now();
    let cracks = match shot.background.filter(|_| read_back) {
        Some(background) => nebula_render::crack::count_cracks(
            &rgba,
            shot.size,
            background,
            &view.camera,
            shot.fov_y_degrees,
            &app.drawn_geometry(),
        ),
        None => CrackCount::default(),
    };
    Ok(Picture {
        adapter: app.gpu().adapter_name.clone(),
        figures: Figures {
            frame: app.frame_figures(),
            crack_pixels: shot.background.filter(|_| read_back).map(|_| cracks.cracks),
            planet_pixels: cracks.planet_pixels,
            cracks,
            draw_ms,
            render,
            check_ms: started.elapsed().as_secs_f64() * 1e3,
            gpu_buffer_bytes: app.renderer().mesh_buffer_bytes(),
            pixels: u64::from(shot.size.0) * u64::from(shot.size.1),
            culling,
            ..Figures::default()
        },
        rgba,
        size: shot.size,
    })
}

/// The chunks the app's current draw list shows from `shot`'s view, by
/// LOD: drawn once more with [`DebugView::Ids`] and read back
/// ([`nebula_render::seen`]).
///
/// # Errors
/// Read-back failures.
pub fn seen_chunks(app: &mut PlanetApp, shot: &Shot) -> anyhow::Result<nebula_render::seen::SeenChunks> {
    let target = Offscreen::new(app.gpu(), shot.size)?;
    app.draw(&target.view, shot.size, shot.background, DebugView::Ids);
    let rgba = target.read(app.gpu()).context("reading the chunk numbers back")?;
    Ok(nebula_render::seen::seen_chunks(&rgba))
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
    // Per LOD, as {"lod": count} for the LODs with any.
    let by_lod = |counts: &[usize]| -> serde_json::Map<String, serde_json::Value> {
        counts
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .map(|(lod, n)| (lod.to_string(), serde_json::json!(n)))
            .collect()
    };
    let (histogram, lod_triangles) = (by_lod(&f.lod_histogram), by_lod(&f.lod_triangles));
    serde_json::json!({
        "adapter": adapter,
        "frames": figures.frames,
        "sse_px_drawn": f.threshold_px,
        "first_frame_ms": figures.first_frame_ms,
        "settled_ms": figures.settled_ms,
        "draw_and_read_back_ms": figures.draw_ms,
        "crack_check_ms": figures.check_ms,
        "chunks": f.chunks,
        "chunks_held": f.chunks_held,
        "gpu_mesh_bytes": f.renderer_bytes,
        "gpu_mesh_buffer_bytes": figures.gpu_buffer_bytes,
        "mesh_bytes_held": f.held_bytes,
        "triangles": f.triangles,
        "triangles_per_pixel": f.triangles as f64 / figures.pixels.max(1) as f64,
        // What reached the rasteriser after occlusion culling (surfaces
        // and skirts; `triangles` counts the list's surfaces).
        "occlusion_culling": figures.culling.map(|c| serde_json::json!({
            "rasterised_triangles": c.triangles(),
            "rasterised_triangles_per_pixel": c.triangles() as f64 / figures.pixels.max(1) as f64,
            "listed_triangles": c.listed_triangles,
            "first_phase_triangles": c.first_phase_triangles,
            "second_phase_triangles": c.second_phase_triangles,
            "draws": c.draws,
            "listed_draws": c.listed_draws,
        })),
        "peak_rss_bytes": peak_rss_bytes(),
        "skirt_triangles": f.skirt_triangles,
        "skirt_triangles_held": f.skirt_triangles_held,
        "stand_ins": f.stand_ins,
        "max_stand_in_levels": f.max_stand_in_levels,
        "prefetch_jobs": f.prefetch_jobs,
        "behind_horizon": f.behind_horizon,
        "backstops": f.backstops,
        "under_sea": f.under_sea,
        "lod_histogram": histogram,
        "lod_triangles": lod_triangles,
        "max_neighbor_lod_diff": f.max_neighbor_lod_diff,
        "max_drawn_lod_diff": f.max_drawn_lod_diff,
        "unsettled": f.unsettled,
        "cpu_ms": {
            "lod": f.times.lod_ms,
            "select": f.times.select_ms,
            "meshing": f.times.meshing_ms,
            "meshing_total": f.times.meshing_total_ms,
            "upload": f.times.upload_ms,
        },
        "encode_ms": figures.render.encode_ms,
        "draw_calls": figures.render.draw_calls,
        "chunk_draws": figures.render.chunk_draws,
        "gpu_ms": figures.render.gpu_ms,
        "chunks_meshed": f.times.chunks_meshed,
        "chunks_remeshed_for_seams": f.times.chunks_remeshed,
        "mesh_errors": f.times.mesh_errors,
        "crack_pixels": figures.crack_pixels,
        "crack_pixels_sphere_rule": figures.cracks.sphere_cracks,
        "crack_pixels_geometry_rule": figures.cracks.geometry_cracks,
        "crack_samples": figures.cracks.samples,
        "crack_rays_cast": figures.cracks.rays_cast,
        "planet_pixels": figures.planet_pixels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reference at half the shot's τ gets four times the nodes, one far
    /// finer at most 16 times; one no finer, or from NaN or infinite
    /// figures, the budget as it was.
    #[test]
    fn a_finer_reference_gets_the_nodes_it_asks_for() {
        assert_eq!(reference_node_budget(400_000, 1.0, 0.5), 1_600_000);
        assert_eq!(reference_node_budget(400_000, 1.0, 0.01), 6_400_000);
        for (shot, reference) in [(1.0, 1.0), (1.0, 2.0), (f64::NAN, 0.5), (1.0, 0.0), (1.0, f64::NAN)] {
            assert_eq!(reference_node_budget(400_000, shot, reference), 400_000, "{shot} / {reference}");
        }
    }

    /// The picture-error reference is the same planet and edits with every
    /// octave: its coarse chunks differ from the band-limited planet's,
    /// its LOD-0 chunks and edits do not.
    #[test]
    fn the_reference_has_every_octave_and_the_same_edits() {
        let planet = ProceduralPlanet::new(PlanetSettings::small(3)).unwrap();
        assert!(planet.settings().band_limit > 0.0, "the preset is band-limited");
        let ground = planet.surface_point(DVec3::new(0.3, 0.5, 0.8).normalize());
        let mut voxels = PlanetVoxels::new(planet);
        let dug = voxels.fill_sphere(ground, 4.0, nebula_voxel::Voxel::AIR).unwrap();
        let reference = every_octave_reference(&voxels).unwrap();
        let settings = reference.base().settings();
        assert_eq!(settings.band_limit, 0.0);
        assert_eq!(*settings, PlanetSettings { band_limit: 0.0, ..voxels.base().settings().clone() });
        assert!(voxels.edit_count() > 0);
        let sorted = |source: &PlanetVoxels| {
            let mut edits: Vec<_> = source.edits().map(|(at, voxel)| format!("{at:?} {voxel:?}")).collect();
            edits.sort_unstable();
            edits
        };
        assert_eq!(sorted(&reference), sorted(&voxels));
        let fill = |source: &PlanetVoxels, key: nebula_voxel::ChunkKey| {
            let mut chunk = nebula_voxel::ChunkVoxels::new(key);
            nebula_voxel::VoxelSource::fill_chunk(source, key, &mut chunk).unwrap();
            chunk
        };
        let dug: Vec<_> = dug.into_iter().filter(|key| key.lod == 0).collect();
        assert!(!dug.is_empty());
        for key in &dug {
            assert!(fill(&reference, *key) == fill(&voxels, *key), "LOD 0 {key:?} differs");
        }
        // Over the same ground a few LODs up the octaves left out show.
        let differ = dug.iter().filter(|key| {
            let column = nebula_voxel::ChunkColumn { lod: 4, x: key.x >> 4, y: key.y >> 4, ..key.column() };
            let layers = nebula_voxel::VoxelSource::surface_chunk_layers(&voxels, column).unwrap();
            layers.into_iter().any(|layer| fill(&reference, column.chunk(layer)) != fill(&voxels, column.chunk(layer)))
        });
        assert!(differ.count() > 0, "the reference's coarse chunks are the band-limited ones");
    }
}
