//! `nebula-demo` as a library: the headless renderer the integration tests
//! drive, and the pieces the windowed binary shares.
//!
//! Structure (after wgpu's examples): [`gpu`] owns device, pipeline and
//! buffers and draws what it is given; [`app`] is the bevy_ecs world with
//! systems for the LOD update, prioritised meshing jobs on rayon that never
//! block a frame, upload, and the choice of what to draw so that every
//! frame is complete; [`headless`] renders a camera to an RGBA image and
//! writes the report; [`crack`] is the crack oracle; [`flight`] flies a
//! keyframed path in real time and checks every frame; `main.rs` adds the
//! window, input and the command line. No LOD or meshing logic lives here:
//! that is `nebula_lod` and `nebula_meshing`.
//!
//! ```no_run
//! use nebula_demo::headless::{Shot, render_shot};
//! use nebula_math::DVec3;
//! let shot = Shot::looking_at(DVec3::new(0.0, 0.0, 6_000.0), DVec3::ZERO, (256, 256));
//! let image = render_shot(&nebula_demo::planet_settings(7, 2_000.0, 1.5), &shot)?;
//! assert_eq!(image.figures.crack_pixels, Some(0));
//! # Ok::<(), anyhow::Error>(())
//! ```

// The ECS resource holding the streamer proves `Sync` through wgpu-core's
// deeply nested types, past the default trait-solver depth of 128.
#![recursion_limit = "256"]

pub mod app;
pub mod arena;
pub mod commands;
pub mod crack;
pub mod flight;
pub mod gpu;
pub mod headless;
pub mod hud;
pub mod sun;

use nebula_voxel::PlanetSettings;

/// Planet parameters from the command line's radius and voxel size: relief
/// scaled to the radius (6 % mountains, hills 0.6 %), capped at Earth's
/// 4 km mountains and 40 m hills.
#[must_use]
pub fn planet_settings(seed: u32, radius: f64, voxel_size: f64) -> PlanetSettings {
    PlanetSettings {
        radius,
        voxel_size,
        amplitude: (radius * 0.06).min(4_000.0),
        feature_size: (radius * 0.75).min(400_000.0),
        detail_amplitude: (radius * 0.006).min(40.0),
        detail_size: (radius * 0.075).min(600.0),
        seed,
    }
}
