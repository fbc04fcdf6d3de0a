//! `nebula-demo`: fly around a seamless voxel planet (a window), or render it
//! headless to PNG with a JSON report.
//!
//! Keys: W/A/S/D move, Q/E down/up, mouse (hold the middle button) looks,
//! Shift ×10 speed, O jumps between orbit and the surface, 1–7 debug views
//! (shaded, LOD colours, skirts, morph factor, wireframe, chunk colours,
//! chunk numbers),
//! Esc quits. Speed scales with altitude. Left click digs out the voxel at
//! the centre of the window, right click places one against it (M cycles
//! the material); with `--world` every edit is saved at once. G switches
//! between flying and walking (gravity, Space jumps, one-block ledges are
//! climbed). H hides or shows the HUD.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use nebula_demo::app::{DrawOptions, MorphRule, PlanetApp, PlanetVoxels, View, camera};
use nebula_demo::commands;
use nebula_demo::headless::{
    Shot, every_octave_reference, reference_node_budget, render_app, report_json, shot_view, write_png,
};
use nebula_demo::hud::Hud;
use nebula_lod::LodSettings;
use nebula_render::context::GpuContext;
use nebula_render::{DebugView, PlanetRenderer};

use nebula_math::DVec3;
use nebula_voxel::{PlanetSettings, Voxel, VoxelHit, VoxelSource};
use nebula_world::seams::SeamStrategy;
use nebula_world::walk::{Body, Orientation, Walker, is_solid, move_body};
use nebula_world::{Edit, World};
use winit::application::ApplicationHandler;
use winit::event::{DeviceEvent, ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

/// Render a Nebula planet.
#[derive(Parser, Debug)]
#[command(name = "nebula-demo", version, about)]
struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    /// Render offscreen instead of opening a window.
    #[arg(long)]
    headless: bool,
    /// Write the final frame to this PNG (headless).
    #[arg(long, value_name = "PATH")]
    screenshot: Option<PathBuf>,
    /// Frames to run before the screenshot (then it waits for meshing).
    #[arg(long, value_name = "N", default_value_t = 8)]
    frames: u32,
    /// Camera position in metres, planet centre at the origin.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    camera_pos: Option<DVec3>,
    /// Point to look at.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    look_at: Option<DVec3>,
    /// Up direction (default: radial up at the camera).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3)]
    up: Option<DVec3>,
    /// Vertical field of view in degrees.
    #[arg(long, value_name = "DEG", default_value_t = 60.0)]
    fov: f64,
    /// Image or window size.
    #[arg(long, value_name = "WxH", value_parser = parse_size, default_value = "1280x720")]
    size: (u32, u32),
    /// The sun, degrees: elevation over the horizon at the camera, then
    /// azimuth clockwise from the view direction (0 ahead, 90 right); in the
    /// window [ and ] lower and raise it [default: a sun fixed in the world].
    #[arg(long, value_name = "ELEVATION,AZIMUTH", value_parser = parse_sun, allow_hyphen_values = true)]
    sun: Option<(f64, f64)>,
    /// Clear colour (0–255 each); when given, nothing is drawn over it and
    /// crack pixels are counted.
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb)]
    background: Option<[u8; 3]>,
    /// A named planet; --seed, --radius and --voxel-size change it.
    #[arg(long, value_enum, default_value_t = Preset::Small)]
    planet: Preset,
    /// Planet seed [default: the preset's].
    #[arg(long = "seed", value_name = "N")]
    seed_arg: Option<u32>,
    /// Planet radius in metres [default: the preset's].
    #[arg(long = "radius", value_name = "M")]
    radius_arg: Option<f64>,
    /// Voxel size in metres [default: the preset's].
    #[arg(long = "voxel-size", value_name = "M")]
    voxel_size_arg: Option<f64>,
    /// Cave tunnel height in metres, 0 for no caves [default: five voxels,
    /// at most 1/30 of the relief].
    #[arg(long = "cave-size", value_name = "M")]
    cave_size: Option<f64>,
    /// Wavelengths per grid spacing at which noise octaves are read from
    /// grids, 0 for every octave at every column: the terrain of worlds
    /// saved before octave grids [default: 16].
    #[arg(long = "octave-grid", value_name = "RATIO")]
    octave_grid: Option<f64>,
    /// How far, metres, reading one octave from a grid coarser than 16
    /// columns may move the terrain, 0 for none coarser: the terrain of
    /// worlds saved before coarse grids [default: 0.01 voxels].
    #[arg(long = "octave-grid-error", value_name = "M")]
    octave_grid_error: Option<f64>,
    /// Voxels per wavelength under which coarse LODs (1 and up) leave a
    /// noise octave out, 0 for every octave at every LOD (more triangles,
    /// LOD switches nested exactly: `PlanetSettings::band_limit`). A saved
    /// world (--world) keeps its own unless this is given [default: 6].
    #[arg(long = "band-limit", value_name = "VOXELS")]
    band_limit: Option<f64>,
    /// The planet seed used: --seed or the preset's.
    #[arg(skip)]
    seed: u32,
    /// The radius used.
    #[arg(skip)]
    radius: f64,
    /// The voxel size used.
    #[arg(skip)]
    voxel_size: f64,
    /// Screen-space error threshold in pixels.
    #[arg(long, value_name = "PX", default_value_t = 1.0)]
    sse: f64,
    /// Also render the shot at this finer screen-space error (e.g. 0.25),
    /// save it beside the screenshot as NAME-reference.png, and report the
    /// share of pixels whose surface is off by more than a pixel's worth
    /// against it (`picture_error`; NAME-error.png shows them red). The
    /// reference has every noise octave at every LOD (band limit 0), the
    /// terrain itself. Both are drawn with one sample per pixel
    #[arg(long, value_name = "PX")]
    reference_sse: Option<f64>,
    /// Debug view: shaded, lod, skirts, morph, wireframe, chunks or ids (each chunk's number and LOD as bytes).
    #[arg(long, value_name = "VIEW", default_value = "shaded")]
    view: DebugView,
    /// Write the frame's figures as JSON here (with --flight: every frame's
    /// and the worst frame).
    #[arg(long, value_name = "PATH")]
    report: Option<PathBuf>,
    /// Fly a keyframed camera path headless: a JSON array of
    /// {"t": s, "pos": [x,y,z], "look_at": [x,y,z], "up": [x,y,z]} (up
    /// optional), rendered in real time at --fps, meshing never waited for.
    #[arg(long, value_name = "PATH")]
    flight: Option<PathBuf>,
    /// Frames per second of a flight: frame k shows time k/fps, drawn no
    /// earlier than k/fps seconds after the first.
    #[arg(long, value_name = "N", default_value_t = 30.0)]
    fps: f64,
    /// Write every frame of a flight here as 00000.png, 00001.png, …
    #[arg(long, value_name = "DIR")]
    frames_dir: Option<PathBuf>,
    /// What drives the geomorph (for debugging; `own` is the first
    /// version's rule, which draws LOD 0 fully morphed).
    #[arg(long, value_enum, default_value_t = MorphArg::Parent)]
    morph: MorphArg,
    /// Draw LOD seams without skirts (for debugging: they open).
    #[arg(long)]
    no_skirts: bool,
    /// Draw in detail what the ground in front hides (for comparing: the
    /// picture is the same, from more triangles).
    #[arg(long)]
    no_terrain_occlusion: bool,
    /// How seams between LODs are closed: skirts, constrained or stitched
    /// (`nebula_world::seams`).
    #[arg(long, value_name = "STRATEGY", default_value = "skirts")]
    seams: SeamStrategy,
    /// Antialiasing of the shaded view (four samples per pixel): `auto` is
    /// on with a GPU and off on a CPU adapter such as lavapipe, where it
    /// makes a frame about three times slower.
    #[arg(long, value_enum, default_value_t = Switch::Auto)]
    msaa: Switch,
    /// Leave out on the GPU the chunks nearer ones hide (the same picture
    /// from fewer triangles rasterised): `auto` is on with a GPU and off on
    /// a CPU adapter such as lavapipe, where it draws no faster and holds
    /// more memory; `on` is on wherever the device can (indirect draws,
    /// compute); `off` draws the whole list (for comparing).
    #[arg(long, value_enum, default_value_t = Switch::Auto)]
    occlusion_culling: Switch,
    /// Make the LOD tree's update and cull ahead on a thread of their own
    /// (`false`: on the frame thread, as before; for comparing).
    #[arg(long, value_name = "BOOL", default_value_t = true, action = clap::ArgAction::Set)]
    lod_thread: bool,
    /// Upload each mesh on the meshing thread that made it (`false`: on the
    /// frame thread, as before; for comparing).
    #[arg(long, value_name = "BOOL", default_value_t = true, action = clap::ArgAction::Set)]
    mesh_thread_uploads: bool,
    /// Mesh memory the streamer keeps at most, MiB (renderer buffers and
    /// CPU copies): past it the meshes used longest ago are freed.
    #[arg(long, value_name = "MIB", default_value_t = nebula_world::stream::MeshCache::<nebula_render::GpuMesh>::default_max_bytes() >> 20)]
    mesh_budget_mb: u64,
    /// A saved world (created if missing): its edits are drawn, picked and
    /// edited; `edit` saves into it.
    #[arg(long, value_name = "PATH")]
    world: Option<PathBuf>,
}

/// A named planet (`--planet`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Preset {
    /// 2 km radius, 1.5 m voxels, seed 7: streams fast anywhere.
    Small,
    /// Earth-sized: 6,371 km radius, 1 m voxels, seed 11.
    Earth,
}

impl Preset {
    /// Seed, radius and voxel size.
    fn parameters(self) -> (u32, f64, f64) {
        match self {
            Preset::Small => (7, 2_000.0, 1.5),
            Preset::Earth => (11, 6_371_000.0, 1.0),
        }
    }
}

/// `--msaa` and `--occlusion-culling`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Switch {
    /// The renderer's default (see each flag).
    Auto,
    /// On wherever the adapter can.
    On,
    /// Off.
    Off,
}

/// The renderer's switches the command line sets: `--msaa` and
/// `--occlusion-culling`.
#[derive(Clone, Copy, Debug)]
struct RendererSwitches {
    msaa: Switch,
    occlusion_culling: Switch,
}

impl RendererSwitches {
    fn of(args: &Args) -> Self {
        Self { msaa: args.msaa, occlusion_culling: args.occlusion_culling }
    }

    /// Applies them to `app`'s renderer.
    fn apply(self, app: &mut PlanetApp) {
        let renderer = app.renderer_mut();
        let cannot_msaa = "draw 4 samples per pixel in every target";
        self.msaa.apply(renderer, PlanetRenderer::set_multisampling, "--msaa", cannot_msaa);
        let cannot_cull = "draw indirectly (occlusion culling needs it)";
        self.occlusion_culling.apply(
            renderer,
            PlanetRenderer::set_occlusion_culling,
            "--occlusion-culling",
            cannot_cull,
        );
    }
}

impl Switch {
    /// Turns a renderer setting on or off with `set` (which answers
    /// whether it is now on), or leaves its default; says so when the
    /// adapter `cannot` have it on.
    fn apply(
        self,
        renderer: &mut PlanetRenderer,
        set: fn(&mut PlanetRenderer, bool) -> bool,
        flag: &str,
        cannot: &str,
    ) {
        match self {
            Switch::Auto => {}
            Switch::On => {
                if !set(renderer, true) {
                    eprintln!("nebula-demo: this adapter cannot {cannot}; {flag} ignored");
                }
            }
            Switch::Off => {
                set(renderer, false);
            }
        }
    }
}

/// What drives the geomorph (`nebula_world::stream::MorphRule`).
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum MorphArg {
    /// The projected error of the LOD a chunk merges into.
    Parent,
    /// The chunk's own error bound (the first version's rule).
    Own,
    /// No geomorphing.
    Off,
}

impl From<MorphArg> for MorphRule {
    fn from(arg: MorphArg) -> Self {
        match arg {
            MorphArg::Parent => MorphRule::Parent,
            MorphArg::Own => MorphRule::Own,
            MorphArg::Off => MorphRule::Off,
        }
    }
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print the planet's parameters.
    Info {
        /// As JSON.
        #[arg(long)]
        json: bool,
    },
    /// Print the first solid voxel on the ray from --camera-pos towards
    /// --look-at, as JSON (`"hit": false` when there is none).
    Pick,
    /// Apply an edit to the --world and save it; prints what changed as
    /// JSON.
    Edit {
        /// A ball: centre and radius in metres.
        #[arg(long, value_name = "X,Y,Z,R", conflicts_with_all = ["cuboid", "script"])]
        sphere: Option<String>,
        /// A world-axis-aligned box: two corners in metres.
        #[arg(long = "box", value_name = "X0,Y0,Z0,X1,Y1,Z1", conflicts_with = "script")]
        cuboid: Option<String>,
        /// What the voxels become: air, stone, dirt, grass, sand, snow.
        #[arg(long, value_name = "MATERIAL", default_value = "air")]
        set: String,
        /// Read edits from this file (`-` for stdin), one per line:
        /// `sphere X,Y,Z,R MATERIAL` or `box X0,Y0,Z0,X1,Y1,Z1 MATERIAL`;
        /// each is saved before its JSON line is printed.
        #[arg(long, value_name = "PATH")]
        script: Option<PathBuf>,
    },
}

fn parse_vec3(text: &str) -> Result<DVec3, String> {
    let parts: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("'{p}' is not a number: {e}")))
        .collect::<Result<_, _>>()?;
    match parts.as_slice() {
        [x, y, z] if parts.iter().all(|v| v.is_finite()) => Ok(DVec3::new(*x, *y, *z)),
        [_, _, _] => Err(format!("'{text}' has a NaN or infinite component")),
        _ => Err(format!("expected X,Y,Z, got '{text}'")),
    }
}

fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(|| format!("expected WxH, got '{text}'"))?;
    let w: u32 = w.trim().parse().map_err(|e| format!("bad width '{w}': {e}"))?;
    let h: u32 = h.trim().parse().map_err(|e| format!("bad height '{h}': {e}"))?;
    if w == 0 || h == 0 || w > 16_384 || h > 16_384 {
        return Err(format!("size must be between 1x1 and 16384x16384, got {w}x{h}"));
    }
    Ok((w, h))
}

fn parse_sun(text: &str) -> Result<(f64, f64), String> {
    let parts: Vec<&str> = text.split(',').collect();
    let [elevation, azimuth] = parts.as_slice() else {
        return Err(format!("expected ELEVATION,AZIMUTH in degrees, got {text:?}"));
    };
    let number = |s: &str| s.trim().parse::<f64>().map_err(|e| format!("{s:?}: {e}"));
    let (elevation, azimuth) = (number(elevation)?, number(azimuth)?);
    // The same checks as placing it, with a harmless view.
    nebula_render::sun::sun_direction(DVec3::X, DVec3::Y, elevation, azimuth).map_err(|e| e.to_string())?;
    Ok((elevation, azimuth))
}

fn parse_rgb(text: &str) -> Result<[u8; 3], String> {
    let parts: Vec<u8> = text
        .split(',')
        .map(|p| p.trim().parse::<u8>().map_err(|e| format!("'{p}' is not 0–255: {e}")))
        .collect::<Result<_, _>>()?;
    <[u8; 3]>::try_from(parts).map_err(|_| format!("expected R,G,B, got '{text}'"))
}

/// The window's keys for the debug views, in [`DebugView::ALL`]'s order
/// (one per view: the length is the list's).
const VIEW_KEYS: [KeyCode; DebugView::ALL.len()] = [
    KeyCode::Digit1,
    KeyCode::Digit2,
    KeyCode::Digit3,
    KeyCode::Digit4,
    KeyCode::Digit5,
    KeyCode::Digit6,
    KeyCode::Digit7,
];

fn main() -> std::process::ExitCode {
    // The libraries report through `log`: warnings and errors by default,
    // more with RUST_LOG.
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let mut args = Args::parse();
    let (seed, radius, voxel_size) = args.planet.parameters();
    args.seed = args.seed_arg.unwrap_or(seed);
    args.radius = args.radius_arg.unwrap_or(radius);
    args.voxel_size = args.voxel_size_arg.unwrap_or(voxel_size);
    match run(args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("nebula-demo: {error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let reference_sse = ("--reference-sse", args.reference_sse.unwrap_or(1.0));
    for (name, value) in [
        ("--fov", args.fov),
        ("--radius", args.radius),
        ("--voxel-size", args.voxel_size),
        ("--sse", args.sse),
        reference_sse,
    ] {
        if !value.is_finite() || value <= 0.0 {
            bail!("{name} must be a positive number, got {value}");
        }
    }
    let mut settings = PlanetSettings::scaled(args.seed, args.radius, args.voxel_size);
    if let Some(cave_size) = args.cave_size {
        settings.cave_size = cave_size;
    }
    if let Some(octave_grid) = args.octave_grid {
        settings.octave_grid = octave_grid;
    }
    if let Some(octave_grid_error) = args.octave_grid_error {
        settings.octave_grid_error = octave_grid_error;
    }
    if let Some(band_limit) = args.band_limit {
        settings.band_limit = band_limit;
    }
    // A saved world keeps the band limit, caves and grids it was saved
    // with unless the command line gives them.
    if let Some(path) = &args.world {
        let given = [
            ("band_limit", args.band_limit.is_some()),
            ("cave_size", args.cave_size.is_some()),
            ("octave_grid", args.octave_grid.is_some()),
            ("octave_grid_error", args.octave_grid_error.is_some()),
        ];
        let given: Vec<&str> = given.iter().filter(|(_, given)| *given).map(|(name, _)| *name).collect();
        settings = World::saved_settings_over(settings, path, &given)
            .with_context(|| format!("reading the settings of {}", path.display()))?;
    }
    let mut world = World::open(settings, args.world.as_deref()).with_context(|| {
        args.world.as_ref().map_or("bad planet parameters".into(), |p| format!("opening {}", p.display()))
    })?;
    match &args.command {
        Some(Command::Info { json }) => return info(&world, *json),
        Some(Command::Pick) => {
            let (Some(eye), Some(look_at)) = (args.camera_pos, args.look_at) else {
                bail!("pick needs --camera-pos and --look-at");
            };
            println!("{}", serde_json::to_string_pretty(&commands::pick(&world, eye, look_at)?)?);
            return Ok(());
        }
        Some(Command::Edit { sphere, cuboid, set, script }) => {
            if args.world.is_none() {
                bail!("edit needs --world PATH to save into");
            }
            if let Some(script) = script {
                let stdout = std::io::stdout().lock();
                return if script.as_os_str() == "-" {
                    commands::edit_script(&mut world, std::io::stdin().lock(), stdout)
                } else {
                    let file = std::fs::File::open(script).with_context(|| format!("opening {}", script.display()))?;
                    commands::edit_script(&mut world, std::io::BufReader::new(file), stdout)
                };
            }
            let voxel = commands::material(set)?;
            let edit = match (sphere, cuboid) {
                (Some(sphere), _) => commands::shape_edit("sphere", sphere, voxel)?,
                (_, Some(cuboid)) => commands::shape_edit("box", cuboid, voxel)?,
                _ => bail!("edit needs --sphere, --box or --script"),
            };
            println!("{}", serde_json::to_string_pretty(&commands::edit(&mut world, &[edit])?)?);
            return Ok(());
        }
        None => {}
    }
    let default_eye = DVec3::new(0.35, 0.55, 0.76).normalize() * args.radius * 2.6;
    let shot = Shot {
        position: args.camera_pos.unwrap_or(default_eye),
        look_at: args.look_at.unwrap_or(DVec3::ZERO),
        up: args.up,
        fov_y_degrees: args.fov,
        size: args.size,
        background: args.background,
        sse_px: args.sse,
        frames: args.frames,
        view: args.view,
        sun: args.sun,
    };
    shot_view(&shot)?;
    if let Some(reference) = args.reference_sse {
        if args.flight.is_some() || !args.headless || args.camera_pos.is_none() {
            bail!("--reference-sse compares one headless shot: give it with --headless and --camera-pos, not --flight");
        }
        if reference >= args.sse {
            bail!(
                "--reference-sse ({reference}) must be finer than --sse ({}): a reference draws more detail",
                args.sse
            );
        }
    }
    if let Some(path) = &args.flight {
        return flight(world.voxels(), &shot, path, &args);
    }
    if !args.headless {
        match EventLoop::new() {
            Ok(event_loop) => {
                let switches = RendererSwitches::of(&args);
                return windowed(event_loop, world, shot, draw_options(&args), switches, args.mesh_budget_mb);
            }
            Err(error) => eprintln!("nebula-demo: no display ({error}); rendering headless instead"),
        }
    }
    headless(world.voxels(), &shot, &args)
}

fn info(world: &World, json: bool) -> anyhow::Result<()> {
    let planet = world.source().base();
    let layout = planet.layout();
    // The face roots' bounds cover the whole planet.
    let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
    for face in nebula_voxel::CubeFace::ALL {
        let bounds = planet.surface_bounds(nebula_voxel::ChunkColumn { face, lod: layout.max_lod(), x: 0, y: 0 })?;
        min = min.min(bounds.min_radius);
        max = max.max(bounds.max_radius);
    }
    let s = planet.settings();
    // The deepest LOD-0 surface (edits included); the root bounds' minimum
    // is far lower, as the coarsest voxels round the surface down.
    let lowest = world.source().lowest_surface_radius().unwrap_or(min);
    let value = serde_json::json!({
        "radius": s.radius,
        "voxel_size": planet.voxel_size(),
        "min_surface_radius": lowest,
        "max_surface_radius": max,
        "min_drawn_radius": min,
        "max_lod": layout.max_lod(),
        "seed": s.seed,
        "cave_size": s.cave_size,
        "octave_grid": s.octave_grid,
        "octave_grid_error": s.octave_grid_error,
        "band_limit": s.band_limit,
        "terrain_version": nebula_voxel::ProceduralPlanet::TERRAIN_VERSION,
        "world": world.store().map(|store| store.path().display().to_string()),
        "unsaved_chunks": world.unsaved_chunks(),
        "edited_voxels": world.edit_count(),
    });
    if json {
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        println!(
            "radius {} m, voxel {:.3} m, surface between {} and {} m, LODs 0..={}, seed {}, {} edited voxels",
            s.radius,
            planet.voxel_size(),
            lowest,
            max,
            layout.max_lod(),
            s.seed,
            world.edit_count()
        );
    }
    Ok(())
}

fn draw_options(args: &Args) -> DrawOptions {
    DrawOptions {
        skirts: !args.no_skirts,
        morph: args.morph.into(),
        terrain_occlusion: !args.no_terrain_occlusion,
        ..DrawOptions::default()
    }
}

/// The streamer and renderer options the command line sets.
fn configure(app: &mut PlanetApp, args: &Args) {
    app.set_draw_options(draw_options(args));
    RendererSwitches::of(args).apply(app);
    let uploader = args.mesh_thread_uploads.then(|| app.mesh_uploader());
    let mut stream = app.streamer_mut();
    stream.0.set_uploader(uploader);
    stream.0.set_lod_thread(args.lod_thread);
    stream.0.set_seam_strategy(args.seams);
    stream.0.cache.max_bytes = args.mesh_budget_mb.saturating_mul(1 << 20);
}

fn headless(planet: Arc<PlanetVoxels>, shot: &Shot, args: &Args) -> anyhow::Result<()> {
    let gpu = GpuContext::headless()?;
    let voxels = planet.clone();
    let mut app = PlanetApp::with_voxels(planet, shot.lod_settings(), gpu, shot_view(shot)?)?;
    configure(&mut app, args);
    if args.screenshot.is_none() && args.camera_pos.is_none() {
        // No camera given: an orbit-to-surface sequence.
        let dir = DVec3::new(0.35, 0.55, 0.76).normalize();
        let dir_ahead = DVec3::new(0.45, 0.5, 0.74).normalize();
        let radius = args.radius;
        let folder = PathBuf::from("nebula-frames");
        for (n, height) in [2.0, 0.6, 0.15, 0.03, 0.008].iter().enumerate() {
            let eye = dir * (app_ground_radius(&app, dir) + radius * height);
            let target = dir_ahead * app_ground_radius(&app, dir_ahead);
            let look = if *height > 0.5 { DVec3::ZERO } else { target };
            let frame_shot = Shot { position: eye, look_at: look, ..shot.clone() };
            let picture = render_app(&mut app, &frame_shot)?;
            let path = folder.join(format!("frame-{n}.png"));
            write_png(&path, &picture.rgba, picture.size)?;
            println!(
                "wrote {} ({} chunks drawn, {} triangles, {} chunk entities alive)",
                path.display(),
                picture.figures.frame.chunks,
                picture.figures.frame.triangles,
                app.chunk_entities()
            );
        }
        return Ok(());
    }
    // The picture error compares depths, which one sample per pixel keeps.
    let measured = args.reference_sse.is_some();
    if measured {
        app.renderer_mut().set_multisampling(false);
    }
    let picture = render_app(&mut app, shot)?;
    let depth = if measured { app.renderer().read_view_depth()? } else { Vec::new() };
    // What the drawn chunks show: those with a pixel, by LOD.
    let seen = nebula_demo::headless::seen_chunks(&mut app, shot)?;
    drop(app);
    let path = args.screenshot.clone().unwrap_or_else(|| PathBuf::from("nebula.png"));
    write_png(&path, &picture.rgba, picture.size)?;
    let mut report = report_json(&picture.figures, &picture.adapter);
    report["seen_chunks"] = serde_json::json!(seen.chunks);
    report["seen_lod_histogram"] = serde_json::json!(seen.by_lod);
    if let Some(sse_px) = args.reference_sse {
        // The same view at a finer error, on its own streamer.
        let reference_shot = Shot { sse_px, ..shot.clone() };
        // The tree's node bound would raise a narrow lens's reference
        // towards the shot's own τ: it is given the nodes it asks for.
        let lod = reference_shot.lod_settings();
        let lod = LodSettings { max_nodes: reference_node_budget(lod.max_nodes, shot.sse_px, sse_px), ..lod };
        let gpu = GpuContext::headless()?;
        let voxels = Arc::new(every_octave_reference(&voxels)?);
        let mut app = PlanetApp::with_voxels(voxels, lod, gpu, shot_view(&reference_shot)?)?;
        configure(&mut app, args);
        app.renderer_mut().set_multisampling(false);
        let reference = render_app(&mut app, &reference_shot)?;
        // A tree too large for its node bound refines to a larger τ: the
        // reference must still be finer than the shot.
        let drawn = (picture.figures.frame.threshold_px, reference.figures.frame.threshold_px);
        if drawn.1 >= drawn.0 {
            bail!(
                "the reference is drawn at τ = {:.2} px and the shot at {:.2} px: the LOD tree's node bound \
                 raises both (a narrow lens or a large picture); ask for a larger --sse",
                drawn.1,
                drawn.0
            );
        }
        let stem = path.file_stem().unwrap_or_default().display();
        write_png(&path.with_file_name(format!("{stem}-reference.png")), &reference.rgba, reference.size)?;
        let reference_depth = app.renderer().read_view_depth()?;
        let error = nebula_render::picture_error::depth_error(&depth, &reference_depth, picture.size)?;
        // And without the depth tolerance, which lets ground at a grazing
        // angle move by a second pixel.
        let strict = nebula_render::picture_error::depth_error_within(&depth, &reference_depth, picture.size, 0.0)?;
        write_png(&path.with_file_name(format!("{stem}-error.png")), &error.marked(&picture.rgba), picture.size)?;
        report["picture_error"] = serde_json::json!({
            "reference_sse": sse_px,
            "reference_sse_drawn": drawn.1,
            "reference_chunks": reference.figures.frame.chunks,
            "reference_triangles": reference.figures.frame.triangles,
            "wrong_pixels": error.wrong_pixels(),
            "share": error.share(),
            "wrong_pixels_without_tolerance": strict.wrong_pixels(),
            "share_without_tolerance": strict.share(),
        });
    }
    println!("wrote {} ({})", path.display(), report);
    if let Some(report_path) = &args.report {
        std::fs::write(report_path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", report_path.display()))?;
    }
    Ok(())
}

fn flight(planet: Arc<PlanetVoxels>, shot: &Shot, path: &std::path::Path, args: &Args) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let flight = nebula_demo::flight::Flight::from_json(&text).with_context(|| format!("in {}", path.display()))?;
    let gpu = GpuContext::headless()?;
    let mut app = PlanetApp::with_voxels(planet, shot.lod_settings(), gpu, shot_view(shot)?)?;
    configure(&mut app, args);
    let report = nebula_demo::flight::fly(&mut app, &flight, shot, args.fps, args.frames_dir.as_deref())?;
    let json = report.json();
    println!(
        "flew {} frames (first frame after {:.0} ms); worst frame: {}",
        report.frames.len(),
        report.first_frame_ms,
        json["worst_frame"]
    );
    if let Some(report_path) = &args.report {
        std::fs::write(report_path, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("writing {}", report_path.display()))?;
    }
    Ok(())
}

fn app_ground_radius(app: &PlanetApp, dir: DVec3) -> f64 {
    app.streamer().voxels().base().surface_point(dir).length()
}

/// How far a click reaches, metres.
const EDIT_REACH: f64 = 200.0;

/// Flying steps shorter than this (metres per frame) collide with blocks;
/// longer ones (high up, where speed scales with altitude) fly free.
const FLY_COLLIDE_BELOW_STEP: f64 = 2.0;

/// The windowed demo.
struct Windowed {
    /// The planet and its edits; clicks edit it and save to its file.
    world: World,
    /// What a right click places.
    material: Voxel,
    /// The voxel under the crosshair (the window's centre), if any.
    picked: Option<VoxelHit>,
    /// Walking instead of flying (G toggles).
    walker: Option<Walker>,
    options: DrawOptions,
    switches: RendererSwitches,
    /// `--mesh-budget-mb`.
    mesh_budget_mb: u64,
    shot: Shot,
    state: Option<WindowState>,
    eye: DVec3,
    /// Where the eye looks: a heading carried along as it moves (no north
    /// to get stuck at over a pole) and a pitch.
    orientation: Orientation,
    keys: std::collections::HashSet<KeyCode>,
    looking: bool,
    view: DebugView,
    last: Instant,
    frames: u32,
    frame_clock: Instant,
}

struct WindowState {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    app: PlanetApp,
    hud: Hud,
}

fn windowed(
    event_loop: EventLoop<()>,
    world: World,
    shot: Shot,
    options: DrawOptions,
    switches: RendererSwitches,
    mesh_budget_mb: u64,
) -> anyhow::Result<()> {
    let forward = (shot.look_at - shot.position).normalize();
    let mut demo = Windowed {
        world,
        material: Voxel::STONE,
        picked: None,
        walker: None,
        options,
        switches,
        mesh_budget_mb,
        eye: shot.position,
        // Straight down has no heading: tip it a hair off vertical.
        orientation: Orientation::looking(shot.position, forward)
            .or_else(|_| Orientation::looking(shot.position, forward + forward.any_orthonormal_vector() * 1e-3))?,
        shot,
        state: None,
        keys: Default::default(),
        looking: false,
        view: DebugView::Shaded,
        last: Instant::now(),
        frames: 0,
        frame_clock: Instant::now(),
    };
    event_loop.run_app(&mut demo)?;
    Ok(())
}

impl Windowed {
    /// The view basis at the eye: its forward and radial up, the heading
    /// carried to where the eye is now.
    fn basis(&mut self) -> (DVec3, DVec3) {
        self.orientation.move_to(self.eye);
        (self.orientation.forward(), self.orientation.up())
    }

    /// Digs out (`dig`) the voxel under the crosshair, or places the
    /// current material against the side looked at; saved at once.
    fn edit_at_crosshair(&mut self, dig: bool) {
        let Some(hit) = self.picked else { return };
        let edit = match (dig, hit.before) {
            (true, _) => Edit::Voxel { at: hit.voxel, voxel: Voxel::AIR },
            (false, Some(at)) => Edit::Voxel { at, voxel: self.material },
            (false, None) => return,
        };
        let dirty = match self.world.apply(&[edit]) {
            Ok(applied) => applied.dirty,
            Err(error) => {
                // What it did apply is shown all the same.
                eprintln!("nebula-demo: the edit failed: {error}");
                self.world.take_unreported()
            }
        };
        if let Some(state) = self.state.as_mut()
            && let Err(error) = state.app.set_voxels(self.world.voxels(), &dirty)
        {
            eprintln!("nebula-demo: showing the edit failed: {error:#}");
        }
    }

    fn frame(&mut self) -> anyhow::Result<()> {
        let dt = self.last.elapsed().as_secs_f64().min(0.1);
        self.last = Instant::now();
        let (forward, up) = self.basis();
        let Some(state) = self.state.as_mut() else { return Ok(()) };
        let min_radius = state.app.min_surface_radius();
        // Over the terrain under the eye (its smooth height), so flying
        // slows down near the ground wherever the ground is.
        let ground = self.world.source().base().surface_point(self.eye).length();
        let altitude = (self.eye.length() - ground).max(1.0);
        let fast = self.keys.contains(&KeyCode::ShiftLeft);
        let speed = altitude * 0.6 * if fast { 10.0 } else { 1.0 };
        let right = forward.cross(up).normalize();
        let mut motion = DVec3::ZERO;
        for (key, dir) in [
            (KeyCode::KeyW, forward),
            (KeyCode::KeyS, -forward),
            (KeyCode::KeyD, right),
            (KeyCode::KeyA, -right),
            (KeyCode::KeyE, up),
            (KeyCode::KeyQ, -up),
        ] {
            if self.keys.contains(&key) {
                motion += dir;
            }
        }
        if let Some(walker) = self.walker.as_mut() {
            // Walking: W/A/S/D along the ground at 5 m/s (Shift ×3), Space
            // jumps, gravity towards the centre; ledges of one block are
            // climbed.
            let horizontal = motion - up * motion.dot(up);
            let pace = if fast { 15.0 } else { 5.0 };
            let jump = self.keys.contains(&KeyCode::Space).then_some(5.0);
            match walker
                .step(self.world.source(), dt, horizontal.normalize_or_zero() * pace, jump)
                .and_then(|()| walker.eye())
            {
                Ok(eye) => self.eye = eye,
                Err(error) => {
                    eprintln!("nebula-demo: walking failed, flying instead: {error}");
                    self.walker = None;
                }
            }
        } else {
            let step = motion.normalize_or_zero() * speed * dt;
            if step.length() < FLY_COLLIDE_BELOW_STEP {
                // Slow enough to be near the ground: the eye is a small box
                // that slides along blocks instead of entering them.
                let body = Body { feet: self.eye - up * 0.25, half_width: 0.25, height: 0.5 };
                match move_body(self.world.source(), body, step) {
                    Ok(moved) => self.eye = moved.feet + up * 0.25,
                    Err(error) => eprintln!("nebula-demo: flying collision failed: {error}"),
                }
            } else if (self.eye + step).length() > min_radius + 0.5
                && !is_solid(self.world.source(), self.eye + step).unwrap_or(true)
            {
                self.eye += step;
            }
        }
        // What a click would edit: the first solid voxel at the crosshair,
        // within reach.
        self.picked = self.world.pick(self.eye, forward, EDIT_REACH).unwrap_or(None);
        let size = (state.config.width, state.config.height);
        state.app.set_view(View {
            camera: camera(self.eye, forward, up, f64::from(size.0) / f64::from(size.1.max(1))),
            fov_y_degrees: self.shot.fov_y_degrees,
            screen_height_px: f64::from(size.1.max(1)),
        });
        state.app.set_sea_drawn(self.shot.background.is_none() && self.view == DebugView::Shaded);
        state.app.step();
        let texture = match state.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            // No frame drawn (a minimised window): the uploads go now.
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                state.surface.configure(&state.app.gpu().device, &state.config);
                state.app.submit_uploads();
                return Ok(());
            }
            _ => {
                state.app.submit_uploads();
                return Ok(());
            }
        };
        let view = texture.texture.create_view(&wgpu::TextureViewDescriptor::default());
        state.app.draw(&view, size, self.shot.background, self.view);
        // Like the sky, nothing over a background given for crack checks.
        if self.shot.background.is_none()
            && let Err(error) = state.hud.draw(state.app.gpu(), &view)
        {
            eprintln!("nebula-demo: HUD hidden: {error}");
            state.hud.visible = false;
        }
        state.app.gpu().queue.present(texture);
        self.frames += 1;
        if self.frame_clock.elapsed().as_secs_f64() > 0.5 {
            let f = state.app.frame_figures();
            let ms = self.frame_clock.elapsed().as_secs_f64() * 1e3 / f64::from(self.frames.max(1));
            let lods: Vec<usize> =
                f.lod_histogram.iter().enumerate().filter(|(_, n)| **n > 0).map(|(l, _)| l).collect();
            let picked = self.picked.map_or_else(
                || "nothing in reach".to_owned(),
                |hit| {
                    format!(
                        "{:?} {} {} {} at {:.1} m",
                        hit.voxel.face, hit.voxel.i, hit.voxel.j, hit.voxel.h, hit.distance
                    )
                },
            );
            // A save that failed (a full disk) is retried here until it
            // goes through; the HUD says what is not saved meanwhile.
            let unsaved = self.world.unsaved_chunks();
            if unsaved > 0 && self.world.save().is_ok() {
                eprintln!("nebula-demo: saved {unsaved} edited chunks that an earlier save could not write");
            }
            let saving = match (self.world.store(), self.world.unsaved_chunks()) {
                (None, _) => "edits kept in memory (no --world)".to_owned(),
                (Some(_), 0) => "every edit saved".to_owned(),
                (Some(_), n) => format!("{n} edited chunks NOT SAVED, retrying"),
            };
            state.hud.set_text(format!(
                "{ms:.1} ms/frame\n{} chunks, {} triangles\n{} meshing jobs\nLOD {} to {}\naltitude {:.0} m, {:.0} m/s\n{picked}\nplaces {} (M), H hides this\n{saving}",
                f.chunks,
                f.triangles,
                f.jobs_in_flight,
                lods.first().copied().unwrap_or(0),
                lods.last().copied().unwrap_or(0),
                altitude,
                speed,
                self.material.name().unwrap_or("?"),
            ));
            state.window.set_title(&format!(
                "Nebula — {ms:.1} ms/frame, {} chunks, {} tris, queue {}, LOD {:?}..{:?}, alt {:.0} m, {:?} | {picked} | places {}",
                f.chunks,
                f.triangles,
                f.jobs_in_flight,
                lods.first(),
                lods.last(),
                altitude,
                self.view,
                self.material.name().unwrap_or("?"),
            ));
            self.frames = 0;
            self.frame_clock = Instant::now();
        }
        state.window.request_redraw();
        Ok(())
    }
}

impl ApplicationHandler for Windowed {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        let planet = self.world.voxels();
        let result = (|| -> anyhow::Result<WindowState> {
            let attributes = Window::default_attributes()
                .with_title("Nebula")
                .with_inner_size(winit::dpi::PhysicalSize::new(self.shot.size.0, self.shot.size.1));
            let window = Arc::new(event_loop.create_window(attributes)?);
            let instance = wgpu::Instance::new(nebula_render::context::instance_descriptor());
            let surface = instance.create_surface(window.clone())?;
            let gpu = GpuContext::new(&instance, Some(&surface))?;
            let size = window.inner_size();
            let config = gpu.surface_config(&surface, (size.width, size.height)).context("surface not supported")?;
            surface.configure(&gpu.device, &config);
            let mut app = PlanetApp::with_voxels(planet, self.shot.lod_settings(), gpu, shot_view(&self.shot)?)?;
            nebula_demo::headless::place_sun(&mut app, &self.shot)?;
            app.set_draw_options(self.options);
            self.switches.apply(&mut app);
            app.streamer_mut().0.cache.max_bytes = self.mesh_budget_mb.saturating_mul(1 << 20);
            let hud = Hud::new(app.gpu(), (config.width, config.height), config.format)?;
            Ok(WindowState { window, surface, config, app, hud })
        })();
        match result {
            Ok(state) => {
                state.window.request_redraw();
                self.state = Some(state);
            }
            Err(error) => {
                eprintln!("nebula-demo: could not open the window: {error:#}");
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(state) = self.state.as_mut() {
                    let (width, height) = state.app.gpu().window_size((size.width, size.height));
                    if (width, height) != (size.width, size.height) {
                        eprintln!(
                            "nebula-demo: a {}×{} window is drawn at {width}×{height} (this GPU's limit)",
                            size.width, size.height
                        );
                    }
                    (state.config.width, state.config.height) = (width, height);
                    state.surface.configure(&state.app.gpu().device, &state.config);
                    state.hud.resize(state.app.gpu(), (state.config.width, state.config.height));
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                let PhysicalKey::Code(code) = event.physical_key else { return };
                if event.state == ElementState::Pressed {
                    self.keys.insert(code);
                    match code {
                        KeyCode::Escape => event_loop.exit(),
                        code if let Some(n) = VIEW_KEYS.iter().position(|&key| key == code) => {
                            self.view = DebugView::ALL[n].1;
                        }
                        KeyCode::KeyG => {
                            self.walker = match self.walker {
                                Some(_) => None,
                                None => {
                                    let up = self.eye.normalize();
                                    let voxel = self.world.source().base().voxel_size();
                                    Some(Walker { step_up: voxel * 1.02, ..Walker::new(self.eye - up * 1.6) })
                                }
                            };
                        }
                        KeyCode::BracketLeft | KeyCode::BracketRight => {
                            // Lower or raise the sun 5° over the camera's horizon.
                            let degrees = if code == KeyCode::BracketRight { 5.0 } else { -5.0 };
                            if let Some(state) = self.state.as_mut() {
                                let sun = nebula_render::sun::raise_sun(state.app.sun(), self.eye, degrees);
                                // A unit vector from a unit vector: never refused.
                                let _ = state.app.set_sun(sun);
                            }
                        }
                        KeyCode::KeyH => {
                            if let Some(state) = self.state.as_mut() {
                                state.hud.visible = !state.hud.visible;
                            }
                        }
                        KeyCode::KeyM => {
                            let solid: Vec<Voxel> = Voxel::NAMED
                                .iter()
                                .map(|&(_, v)| v)
                                .filter(|v| v.is_solid() && *v != Voxel::SEABED)
                                .collect();
                            let next = solid.iter().position(|&v| v == self.material).map_or(0, |n| n + 1);
                            self.material = solid[next % solid.len()];
                        }
                        KeyCode::KeyO => {
                            self.walker = None;
                            let r = self.eye.length();
                            let radius = self.shot.position.length().max(r);
                            let up = self.eye.normalize();
                            let ground = self.state.as_ref().map_or(r, |s| app_ground_radius(&s.app, up));
                            self.eye =
                                if r > ground * 1.5 { up * (ground + 30.0) } else { up * radius.max(ground * 2.5) };
                        }
                        _ => {}
                    }
                } else {
                    self.keys.remove(&code);
                }
            }
            WindowEvent::MouseInput { state, button: MouseButton::Middle, .. } => {
                self.looking = state == ElementState::Pressed;
            }
            WindowEvent::MouseInput { state: ElementState::Pressed, button: MouseButton::Left, .. } => {
                self.edit_at_crosshair(true);
            }
            WindowEvent::MouseInput { state: ElementState::Pressed, button: MouseButton::Right, .. } => {
                self.edit_at_crosshair(false);
            }
            WindowEvent::RedrawRequested => {
                if let Err(error) = self.frame() {
                    eprintln!("nebula-demo: {error:#}");
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }

    fn device_event(&mut self, _event_loop: &ActiveEventLoop, _id: winit::event::DeviceId, event: DeviceEvent) {
        if let DeviceEvent::MouseMotion { delta } = event
            && self.looking
        {
            self.orientation.turn(delta.0 * 0.003, -delta.1 * 0.003);
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// clap checks argument names and conflicts only when a command is
    /// parsed: check them all here rather than in front of a user.
    #[test]
    fn the_command_line_is_consistent() {
        super::Args::command().debug_assert();
    }
}
