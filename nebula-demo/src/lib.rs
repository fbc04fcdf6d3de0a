//! `nebula-demo` as a library: the headless renderer the integration tests
//! drive, and the pieces the windowed binary shares.
//!
//! A thin client of the libraries: [`app`] is the bevy_ecs world holding
//! `nebula_world`'s streamer, drawing through `nebula_render`'s
//! `PlanetRenderer`; [`headless`] renders a camera to an RGBA image and
//! writes the report, crack pixels counted by `nebula_render::crack`; [`flight`] flies a
//! keyframed path in real time and checks every frame; `main.rs` adds the
//! window, input and the command line. No LOD, meshing or drawing logic
//! lives here.
//!
//! ```no_run
//! use nebula_demo::headless::{Shot, render_shot};
//! use nebula_math::DVec3;
//! let shot = Shot::looking_at(DVec3::new(0.0, 0.0, 6_000.0), DVec3::ZERO, (256, 256));
//! let image = render_shot(&nebula_voxel::PlanetSettings::scaled(7, 2_000.0, 1.5), &shot)?;
//! assert_eq!(image.figures.crack_pixels, Some(0));
//! # Ok::<(), anyhow::Error>(())
//! ```

// The ECS resource holding the streamer proves `Sync` through wgpu-core's
// deeply nested types, past the default trait-solver depth of 128.
#![recursion_limit = "256"]

pub mod app;
pub mod commands;
pub mod flight;
pub mod headless;
pub mod hud;
