//! A voxel planet in a bevy_ecs app: three resources and one system.
//!
//! The "renderer" here keeps counts instead of GPU buffers, so the example
//! runs anywhere; a real one uploads `RenderMesh::vertices` / `indices` in
//! its `upload` function and draws `Streamer::drawn()` each frame with the
//! `nebula_meshing::RenderVertex` shader rules (`nebula_render` does all this). The
//! camera flies from orbit down to 30 m over the ground; every second the
//! example prints what would be drawn.
//!
//! Run: `cargo run --release -p nebula_world --example bevy_planet`

use std::error::Error;
use std::time::Duration;

use bevy_ecs::prelude::*;
use nebula_lod::{Camera, LodSettings};
use nebula_math::DVec3;
use nebula_meshing::RenderMesh;
use nebula_voxel::{EditedSource, PlanetSettings, ProceduralPlanet};
use nebula_world::ecs::{PlanetStream, StreamCamera, insert_planet, stream_system};
use nebula_world::stream::{MeshHandle, Streamer};

/// What the game's renderer would hold for a chunk: here, its size.
struct CountedMesh {
    bytes: u64,
}

impl MeshHandle for CountedMesh {
    fn bytes(&self) -> u64 {
        self.bytes
    }
}

fn upload(_key: nebula_voxel::ChunkKey, mesh: &RenderMesh) -> CountedMesh {
    CountedMesh { bytes: mesh.bytes() }
}

type Voxels = EditedSource<ProceduralPlanet>;

fn main() -> Result<(), Box<dyn Error>> {
    // The planet and its edits (no file here: `Some(path)` saves them).
    let planet = nebula_world::World::open(PlanetSettings::small(7), None)?;
    let up = DVec3::new(0.35, 0.55, 0.76).normalize();
    let ground = planet.source().base().surface_point(up);
    let orbit = up * ground.length() * 3.0;
    let camera = Camera { position: orbit, forward: -up, up: DVec3::Z, aspect: 16.0 / 9.0 };
    let lod = LodSettings { screen_height_px: 720.0, fov_y_degrees: 60.0, ..LodSettings::default() };

    // The three resources and the system.
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let streamer = Streamer::new(planet.voxels(), lod, camera, threads, &mut upload)?;
    let mut world = World::new();
    insert_planet(&mut world, streamer, camera, upload);
    let mut schedule = Schedule::default();
    schedule.add_systems((fly, stream_system::<Voxels, CountedMesh>, report).chain());

    for _ in 0..600 {
        schedule.run(&mut world);
        std::thread::sleep(Duration::from_millis(16));
    }
    Ok(())
}

/// Ten seconds from three radii out down to 30 m over the ground.
fn fly(mut camera: ResMut<StreamCamera>, stream: Res<PlanetStream<Voxels, CountedMesh>>, mut frame: Local<u32>) {
    *frame += 1;
    let up = camera.0.position.normalize();
    let ground = stream.0.voxels().base().surface_point(up).length();
    let t = (f64::from(*frame) / 600.0).min(1.0);
    let altitude = 30.0 + (ground * 2.0 - 30.0) * (1.0 - t).powi(3);
    camera.0.position = up * (ground + altitude);
}

/// Once a second: what a renderer would draw.
fn report(stream: Res<PlanetStream<Voxels, CountedMesh>>, camera: Res<StreamCamera>, mut frame: Local<u32>) {
    *frame += 1;
    if !frame.is_multiple_of(60) {
        return;
    }
    let f = stream.0.figures();
    let ground = stream.0.voxels().base().surface_point(camera.0.position).length();
    println!(
        "{:>5.0} m up: {:>5} chunks drawn, {:>8} triangles, {:>4} stand-ins, {:>4} jobs, {:>5.1} MB of meshes",
        camera.0.position.length() - ground,
        f.chunks,
        f.triangles,
        f.stand_ins,
        f.jobs_in_flight,
        f.held_bytes as f64 / 1e6
    );
}
