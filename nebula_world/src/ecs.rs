//! bevy_ecs integration (feature `bevy`, on by default): a planet is three
//! resources and one system.
//!
//! ```text
//!   PlanetStream<S, H>   the Streamer (what to mesh, draw, free)
//!   StreamCamera         the camera this frame (the game moves it)
//!   MeshUploader<H>      the game's renderer: RenderMesh → handle
//!   stream_system        one frame of streaming; run it once per frame
//! ```
//!
//! A game's render system then reads [`PlanetStream`] and draws
//! [`Streamer::drawn`]. See `examples/bevy_planet.rs`.

use bevy_ecs::prelude::*;
use nebula_lod::Camera;
use nebula_meshing::RenderMesh;
use nebula_voxel::{ChunkKey, VoxelSource};

use crate::stream::{MeshHandle, Streamer};

/// The planet's streamer as a resource.
#[derive(Resource)]
pub struct PlanetStream<S: Send + Sync + 'static, H: Send + Sync + 'static>(pub Streamer<S, H>);

/// The camera the planet is streamed for; the game updates it each frame.
#[derive(Resource, Clone, Copy, Debug)]
pub struct StreamCamera(pub Camera);

/// A renderer's upload function: a finished chunk mesh in, the handle to
/// it out.
pub type UploadFn<H> = dyn FnMut(ChunkKey, &RenderMesh) -> H + Send + Sync;

/// The game's upload function: makes a renderer handle of a finished chunk
/// mesh (dropping the handle must free it).
#[derive(Resource)]
pub struct MeshUploader<H: Send + Sync + 'static>(pub Box<UploadFn<H>>);

/// One frame of streaming for the current [`StreamCamera`], uploading
/// finished meshes through the [`MeshUploader`].
pub fn stream_system<S: VoxelSource + 'static, H: MeshHandle>(
    mut stream: ResMut<PlanetStream<S, H>>,
    camera: Res<StreamCamera>,
    mut uploader: ResMut<MeshUploader<H>>,
) {
    stream.0.update(camera.0, &mut *uploader.0);
}

/// Adds a planet to `world`: the resources above, with `streamer` started
/// for `camera` and `upload` as the renderer; add [`stream_system`] (for
/// the same `S`, `H`) to the schedule that runs every frame.
pub fn insert_planet<S: VoxelSource + 'static, H: MeshHandle>(
    world: &mut World,
    streamer: Streamer<S, H>,
    camera: Camera,
    upload: impl FnMut(ChunkKey, &RenderMesh) -> H + Send + Sync + 'static,
) {
    world.insert_resource(PlanetStream(streamer));
    world.insert_resource(StreamCamera(camera));
    world.insert_resource(MeshUploader(Box::new(upload)));
}
