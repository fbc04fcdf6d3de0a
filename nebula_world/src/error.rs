//! The error type of `nebula_world`.

use std::path::PathBuf;

use nebula_voxel::VoxelError;

/// Why a world could not be opened, edited or saved.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WorldError {
    /// Bad voxel coordinates, edit shapes or rays.
    #[error(transparent)]
    Voxel(#[from] VoxelError),
    /// The file is not a Nebula world, or its contents fail their checks.
    /// It was not modified.
    #[error("{path} is not a readable Nebula world: {reason}")]
    Corrupted {
        /// The world file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The world was written by a format this build does not read. It was
    /// not modified.
    #[error("{path} is world format {found}, this build reads format {supported}")]
    WrongVersion {
        /// The world file.
        path: PathBuf,
        /// The format version in the file.
        found: u8,
        /// The version this build reads and writes.
        supported: u8,
    },
    /// The world was saved on another version of the terrain code: the
    /// same settings give other ground now, so its edits would land in the
    /// wrong places. It was not modified.
    #[error(
        "{path} was saved with terrain version {stored} of {generator}, this build has {this_build}: \
         its edits would land on other ground"
    )]
    TerrainVersion {
        /// The world file.
        path: PathBuf,
        /// The terrain generator.
        generator: String,
        /// The terrain version the world was saved with.
        stored: u32,
        /// This build's terrain version.
        this_build: u32,
    },
    /// The world belongs to a planet with other settings or another
    /// generator (its edits would land on different terrain). It was not
    /// modified.
    #[error("{path} holds edits of another planet: saved for {stored}, opened with {given}")]
    OtherPlanet {
        /// The world file.
        path: PathBuf,
        /// The planet the file was saved for.
        stored: String,
        /// The planet it was opened with.
        given: String,
    },
    /// Another process has the world open.
    #[error("{path} is open in another process")]
    InUse {
        /// The world file.
        path: PathBuf,
    },
    /// The database or the file system failed (disk full, permissions, …).
    #[error("world storage at {path}: {message}")]
    Storage {
        /// The world file.
        path: PathBuf,
        /// The underlying error.
        message: String,
    },
}
