//! bevy_ecs integration (feature `bevy`, on by default): a planet is three
//! resources and one system.
//!
//! ```text
//!   PlanetStream<S, H>   the Streamer (what to mesh, draw, free)
//!   StreamCamera         the camera this frame (the game moves it)
//!   MeshUploader<H>      the game's renderer: RenderMesh → handle
//!   stream_system        one frame of streaming; run it once per frame
//!   StreamView           optional: τ, screen height and field of view, for
//!                        a zoom or a resized window (applied when changed)
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

/// The view the LOD tree refines and culls for; insert it and change it
/// when the window is resized or the camera zooms ([`Streamer::set_view`]
/// runs when it changed). Without it the settings given to the streamer
/// stay.
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct StreamView {
    /// τ: the largest projected error allowed, pixels.
    pub threshold_px: f64,
    /// The picture's height, pixels.
    pub screen_height_px: f64,
    /// The vertical field of view, degrees.
    pub fov_y_degrees: f64,
}

/// A renderer's upload function: a finished chunk mesh in, the handle to
/// it out.
pub type UploadFn<H> = dyn FnMut(ChunkKey, &RenderMesh) -> H + Send + Sync;

/// The game's upload function: makes a renderer handle of a finished chunk
/// mesh (dropping the handle must free it).
#[derive(Resource)]
pub struct MeshUploader<H: Send + Sync + 'static>(pub Box<UploadFn<H>>);

/// One frame of streaming for the current [`StreamCamera`] (and
/// [`StreamView`], when there is one and it changed), uploading finished
/// meshes through the [`MeshUploader`].
pub fn stream_system<S: VoxelSource + 'static, H: MeshHandle>(
    mut stream: ResMut<PlanetStream<S, H>>,
    camera: Res<StreamCamera>,
    view: Option<Res<StreamView>>,
    mut uploader: ResMut<MeshUploader<H>>,
) {
    if let Some(view) = view.filter(|view| view.is_changed())
        && let Err(error) = stream.0.set_view(view.threshold_px, view.screen_height_px, view.fov_y_degrees)
    {
        log::warn!("keeping the last view, this one is refused: {error}");
    }
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
