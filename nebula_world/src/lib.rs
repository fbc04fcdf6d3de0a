//! A Nebula planet a game can build on: point at a voxel, dig and place,
//! and keep what the player changed.
//!
//! [`World`] owns a planet's voxels with the player's edits on top
//! ([`nebula_voxel::EditedSource`]) and, when opened with a path, the file
//! they are saved in ([`WorldStore`], a [redb](https://docs.rs/redb)
//! database). Every [`World::apply`] is saved as one durable transaction
//! before it returns, so a crash or a killed process loses nothing that was
//! applied, and reopening the file gives the same voxels.
//!
//! Choices:
//! - **redb** as the store: an embedded, pure-Rust, crash-safe key-value
//!   database (copy-on-write B-trees, checksummed two-phase commits), so no
//!   C toolchain and no write-ahead log to manage. Minecraft keeps region
//!   files, Distant Horizons SQLite, Voxy RocksDB; per-chunk rows in an ACID
//!   store give the same "only what changed is written" with atomic batches.
//! - **Per-chunk diffs**: one value per LOD-0 chunk holding that chunk's
//!   edited voxels (3 bytes each), keyed by the chunk; coarse LODs are
//!   derived from LOD 0 by the planet's far-corner rule, never stored.
//! - **Streaming** ([`stream`]): a [`stream::Streamer`] decides what to
//!   mesh, draw and free for a moving camera, for any renderer (it uploads
//!   through a function the game gives it); [`ecs`] wraps it as bevy_ecs
//!   resources and a system. The LOD tree's update and cull, and the
//!   selection of what to draw and mesh, are made ahead on a thread of
//!   their own while the game draws the frame before, for the camera the
//!   last frames' motion predicts with a margin around it; the frame thread
//!   takes them when the margin covers the camera that came, and makes its
//!   own when not (a jump, a sharp turn).
//! - **Walking** ([`walk`]): bodies are upright boxes in the local
//!   east/north/up frame, moved axis by axis against the solid voxels'
//!   boxes in that frame, as block games do.
//! - **Refuse, never repair, what is not ours**: a corrupted file, another
//!   format version or another planet's world is reported as a
//!   [`WorldError`] and left untouched.
//!
//! ```
//! use nebula_voxel::{PlanetSettings, ProceduralPlanet, Voxel, VoxelSource};
//! use nebula_world::{Edit, World};
//!
//! let dir = std::env::temp_dir().join(format!("nebula-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let path = dir.join("world.redb");
//! let settings = PlanetSettings::small(7);
//! let up = nebula_voxel::DVec3::Y;
//!
//! let mut world = World::open(settings.clone(), Some(&path))?;
//! // Look straight down from 100 m over the ground and dig where we look.
//! let eye = world.source().base().surface_point(up) + up * 100.0;
//! let hit = world.pick(eye, -up, 1_000.0)?.expect("the ground is below");
//! world.apply(&[Edit::Voxel { at: hit.voxel, voxel: Voxel::AIR }])?;
//! drop(world);
//!
//! let again = World::open(settings, Some(&path))?;
//! assert_eq!(again.source().voxel(hit.voxel)?, Voxel::AIR);
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#[cfg(feature = "bevy")]
pub mod ecs;
mod error;
mod lod_thread;
pub mod seams;
mod select;
mod store;
pub mod stream;
pub mod walk;

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;

use nebula_math::DVec3;
use nebula_voxel::{
    ChunkKey, EditedSource, PlanetSettings, ProceduralPlanet, Voxel, VoxelCoord, VoxelHit, VoxelSource, pick,
};

pub use error::WorldError;
pub use store::{FORMAT_VERSION, Terrain, WorldStore};

/// One change to the planet's LOD-0 voxels. `Voxel::AIR` digs, a material
/// places.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Edit {
    /// One voxel.
    Voxel {
        /// The LOD-0 voxel.
        at: VoxelCoord,
        /// What it becomes.
        voxel: Voxel,
    },
    /// Every voxel whose centre is within `radius` metres of `center`.
    Sphere {
        /// Centre, world metres.
        center: DVec3,
        /// Radius, metres (at most 64 voxels).
        radius: f64,
        /// What the voxels become.
        voxel: Voxel,
    },
    /// Every voxel whose centre is in the world-axis-aligned box.
    Box {
        /// Lowest corner, world metres.
        min: DVec3,
        /// Highest corner, world metres.
        max: DVec3,
        /// What the voxels become.
        voxel: Voxel,
    },
}

/// What [`World::apply`] changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Applied {
    /// Chunks at every LOD whose voxels changed (padding included): the
    /// ones a renderer must re-mesh. Sorted.
    pub dirty: Vec<ChunkKey>,
    /// LOD-0 chunks whose saved diffs were rewritten.
    pub saved_chunks: usize,
}

/// A planet with edits, saved to a file when opened with one.
#[derive(Debug)]
pub struct World<S = ProceduralPlanet> {
    /// Shared with renderers and meshing jobs ([`World::voxels`]); an edit
    /// while such a snapshot is alive clones it, which shares the edits'
    /// persistent maps: the edit costs what it changes, not every edit so
    /// far.
    source: Arc<EditedSource<S>>,
    store: Option<WorldStore>,
    /// LOD-0 chunks edited but not yet saved (after a failed save).
    unsaved: BTreeSet<ChunkKey>,
    /// Chunks edits changed that no [`Applied`] has reported yet (an apply
    /// that failed part way kept its earlier edits).
    unreported: BTreeSet<ChunkKey>,
}

impl World<ProceduralPlanet> {
    /// `settings` with the settings added since worlds were first saved
    /// ([`PlanetSettings::ADDED_SETTINGS`]: the band limit, caves, octave
    /// grids) taken over from the world file at `path`, but for those
    /// `given` names (a player's explicit choice, checked against the file
    /// when it opens): a world saved before a new default opens as the
    /// planet it was saved on. A file without one of them was saved before
    /// it existed, and gets the value that gives its planet; no file yet,
    /// or a file that cannot be read here (opening it says why), leaves
    /// `settings` as they are.
    ///
    /// # Errors
    /// [`WorldError::Corrupted`] for a saved value that is not a number.
    pub fn saved_settings_over(
        mut settings: PlanetSettings,
        path: &Path,
        given: &[&str],
    ) -> Result<PlanetSettings, WorldError> {
        let Ok(Some(saved)) = WorldStore::saved_settings(path) else { return Ok(settings) };
        for &(name, old) in PlanetSettings::ADDED_SETTINGS.iter().filter(|(name, _)| !given.contains(name)) {
            let text = saved.iter().find(|(n, _)| n == name).map_or(old, |(_, value)| value.as_str());
            let value = text.parse().map_err(|_| WorldError::Corrupted {
                path: path.into(),
                reason: format!("saved setting {name}={text} is not a number"),
            })?;
            if let Some(field) = settings.added_setting_mut(name) {
                *field = value;
            }
        }
        Ok(settings)
    }

    /// The procedural planet of `settings` with the edits saved at `path`
    /// (created if missing), or with no file at all (`None`: edits live in
    /// memory only).
    ///
    /// # Errors
    /// The planet's settings errors, and [`WorldStore::open`]'s.
    pub fn open(settings: PlanetSettings, path: Option<&Path>) -> Result<Self, WorldError> {
        let terrain = Terrain::of_planet(&settings);
        Self::with_source(ProceduralPlanet::new(settings)?, &terrain, path)
    }
}

impl<S: VoxelSource + Clone> World<S> {
    /// Any voxel source with the edits saved at `path`; `terrain` names the
    /// source's generator, code version and settings (the version must
    /// change whenever the same settings would give other voxels), so a
    /// file is never replayed onto other ground.
    ///
    /// # Errors
    /// [`WorldStore::open`]'s, and [`WorldError::Corrupted`] for a saved
    /// voxel that is not on this planet.
    pub fn with_source(base: S, terrain: &Terrain, path: Option<&Path>) -> Result<Self, WorldError> {
        let mut source = EditedSource::new(base);
        let store = match path {
            None => None,
            Some(path) => {
                let (store, edits) = WorldStore::open(path, terrain)?;
                for (at, voxel) in edits {
                    source.set_voxel(at, voxel).map_err(|e| WorldError::Corrupted {
                        path: path.into(),
                        reason: format!("saved voxel {at:?} is not on this planet: {e}"),
                    })?;
                }
                Some(store)
            }
        };
        Ok(Self { source: Arc::new(source), store, unsaved: BTreeSet::new(), unreported: BTreeSet::new() })
    }

    /// The voxels with every edit applied: what meshing, picking and
    /// collision read.
    pub fn source(&self) -> &EditedSource<S> {
        &self.source
    }

    /// A snapshot of the voxels with every edit so far, to hand to meshing
    /// threads: it stays as it is while the world goes on changing (the
    /// next edit clones the voxels while a snapshot is alive, sharing all
    /// but what it changes).
    pub fn voxels(&self) -> Arc<EditedSource<S>> {
        self.source.clone()
    }

    /// The world file, if any.
    pub fn store(&self) -> Option<&WorldStore> {
        self.store.as_ref()
    }

    /// LOD-0 chunks whose edits are not saved yet: 0 after every save that
    /// went through; more after a failed one (a full disk), until a later
    /// [`World::apply`] or [`World::save`] writes them. A game shows it
    /// and calls [`World::save`] now and then while it is not 0.
    pub fn unsaved_chunks(&self) -> usize {
        self.unsaved.len()
    }

    /// How many LOD-0 voxels differ from the generated planet.
    pub fn edit_count(&self) -> usize {
        self.source.edit_count()
    }

    /// The first solid LOD-0 voxel (edits included) along a ray: see
    /// [`nebula_voxel::pick`].
    ///
    /// # Errors
    /// [`WorldError::Voxel`] for a NaN, infinite or zero ray.
    pub fn pick(&self, origin: DVec3, direction: DVec3, max_distance: f64) -> Result<Option<VoxelHit>, WorldError> {
        Ok(pick(&*self.source, origin, direction, max_distance)?)
    }

    /// Applies `edits` in order and saves them as one transaction. Returns
    /// the chunks to re-mesh (with those of earlier applies that failed part
    /// way).
    ///
    /// # Errors
    /// [`WorldError::Voxel`] for a bad edit: the edits before it stay
    /// applied and are saved. [`WorldError::Storage`] if the save fails:
    /// the edits stay applied in memory and are saved with the next
    /// successful [`World::apply`] or [`World::save`]. Either way the
    /// chunks the applied edits changed are kept for
    /// [`World::take_unreported`] or the next successful apply.
    pub fn apply(&mut self, edits: &[Edit]) -> Result<Applied, WorldError> {
        let mut dirty = std::mem::take(&mut self.unreported);
        let mut failure = None;
        let source = Arc::make_mut(&mut self.source);
        for edit in edits {
            let result = match *edit {
                Edit::Voxel { at, voxel } => source.set_voxel(at, voxel),
                Edit::Sphere { center, radius, voxel } => source.fill_sphere(center, radius, voxel),
                Edit::Box { min, max, voxel } => source.fill_box(min, max, voxel),
            };
            match result {
                Ok(keys) => dirty.extend(keys),
                Err(e) => {
                    failure = Some(WorldError::from(e));
                    break;
                }
            }
        }
        self.unsaved.extend(dirty.iter().filter(|key| key.lod == 0).copied());
        let saved = self.save();
        match (saved, failure) {
            (Ok(saved_chunks), None) => Ok(Applied { dirty: dirty.into_iter().collect(), saved_chunks }),
            (Err(error), _) | (Ok(_), Some(error)) => {
                self.unreported = dirty;
                Err(error)
            }
        }
    }

    /// The chunks that edits of failed applies changed (they stay applied),
    /// for a renderer to re-mesh; empties the list.
    pub fn take_unreported(&mut self) -> Vec<ChunkKey> {
        std::mem::take(&mut self.unreported).into_iter().collect()
    }

    /// Saves every edited chunk not saved yet. Returns how many chunks
    /// were written (0 without a file). After a failed save the file is
    /// opened again on a new handle and the save retried
    /// ([`WorldStore::save_chunks`]).
    ///
    /// # Errors
    /// [`WorldError::Storage`]; the chunks stay pending
    /// ([`World::unsaved_chunks`]).
    pub fn save(&mut self) -> Result<usize, WorldError> {
        let Some(store) = &mut self.store else {
            self.unsaved.clear();
            return Ok(0);
        };
        let chunks: Vec<_> = self.unsaved.iter().map(|&key| (key, self.source.chunk_edits(key))).collect();
        store.save_chunks(&chunks)?;
        self.unsaved.clear();
        Ok(chunks.len())
    }
}

/// The message of a caught panic.
pub(crate) fn panic_text(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}

#[cfg(test)]
mod tests;
