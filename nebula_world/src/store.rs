//! Saved worlds: per-chunk edit diffs in a redb database.
//!
//! ```text
//!   table "meta"         "format"          → [FORMAT_VERSION]
//!                        "generator"       → the terrain generator's name (UTF-8)
//!                        "terrain_version" → its code version, u32 LE
//!                        "settings"        → its canonical settings, "name=value\n" sorted by name
//!   table "chunk_edits"  (face, x, y, layer) of a LOD-0 chunk
//!                        → [VALUE_FORMAT u8][count u32 LE][count × (local u16 LE, material u8)]
//! ```
//!
//! `local` is `i + 32·(j + 32·h)` inside the chunk. A value holds every
//! edited voxel of its chunk, so a save rewrites only the chunks an edit
//! touched, and a batch of edits is one write transaction: redb commits it
//! durably (fsync, copy-on-write pages, a checksummed two-phase commit) or
//! not at all, so a process killed mid-save loses at most the batch it was
//! writing and the file still opens.
//!
//! **What the edits lie on** ([`Terrain`]): the generator, the version of
//! its code and its settings are stored apart, so a world is refused with
//! the reason: another terrain version ("saved with terrain version N,
//! this build has M"), or other settings (naming them). A setting added
//! after a world was saved is matched by the value that gives the planets
//! saved before it ([`Terrain::added_settings`]), so old saves still open.
//! Format 1 (before versioned terrain) kept the settings' `Debug` text; such
//! a file opens when that text is this planet's ([`Terrain::legacy`]) and is
//! then rewritten as format 2.
//!
//! Opening checks the file read-only first (redb's integrity check, the
//! format version, the terrain, every value's encoding) and refuses a
//! corrupted, foreign or wrong-version file before anything could write to
//! it. Only a file left by a killed writer is opened for writing straight
//! away: redb must roll it back to its last commit first.
//!
//! **A failed save is retried on a new handle.** After one I/O error (a
//! full disk, a pulled drive) redb refuses every later transaction of that
//! handle; [`WorldStore::save_chunks`] then closes it, opens the file again
//! (redb rolls back to the last commit) and retries once, and every later
//! save does the same until the disk takes the data again.

use std::path::{Path, PathBuf};

use nebula_voxel::{CHUNK_SIZE, ChunkKey, CubeFace, PlanetSettings, ProceduralPlanet, Voxel, VoxelCoord};
use redb::{
    Builder, Database, DatabaseError, ReadableDatabase, ReadableTable, ReadableTableMetadata, StorageError,
    TableDefinition,
};

use crate::WorldError;

/// The file format this build reads and writes, stored in the meta table
/// (it reads format 1 too, and rewrites it as this one).
pub const FORMAT_VERSION: u8 = 2;

/// The encoding of a chunk's value, its first byte.
const VALUE_FORMAT: u8 = 1;

pub(crate) const META: TableDefinition<&str, &[u8]> = TableDefinition::new("meta");
const CHUNK_EDITS: TableDefinition<(u8, u32, u32, i32), &[u8]> = TableDefinition::new("chunk_edits");

/// The terrain a world's edits were made on: they are replayed only onto
/// the same terrain.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Terrain {
    /// The generator's name (for the procedural planet,
    /// `"nebula_voxel::ProceduralPlanet"`).
    pub generator: String,
    /// The version of the generator's code: within a version, the same
    /// settings give the same voxels.
    pub version: u32,
    /// The settings, canonical: `(name, value)` pairs sorted by name.
    pub settings: Vec<(String, String)>,
    /// Settings newer than some saved worlds, with the value that gives
    /// the terrain those worlds were saved on (a world that lacks the
    /// setting matches when this build has that value).
    pub added_settings: Vec<(String, String)>,
    /// The identity text format-1 worlds stored for this terrain (before
    /// versioned terrain), if any: such a world opens when it matches.
    pub legacy: Option<String>,
}

impl Terrain {
    /// The terrain of [`ProceduralPlanet`] with `settings`.
    #[must_use]
    pub fn of_planet(settings: &PlanetSettings) -> Self {
        let owned = |pairs: Vec<(&str, String)>| pairs.into_iter().map(|(n, v)| (n.to_owned(), v)).collect();
        let canonical = settings.canonical();
        let value = |name: &str| canonical.iter().find(|(n, _)| *n == name).map_or("", |(_, v)| v.as_str());
        let before_added_settings = PlanetSettings::ADDED_SETTINGS.iter().all(|&(name, old)| value(name) == old);
        Self {
            generator: "nebula_voxel::ProceduralPlanet".into(),
            version: ProceduralPlanet::TERRAIN_VERSION,
            settings: owned(canonical.clone()),
            added_settings: owned(PlanetSettings::ADDED_SETTINGS.iter().map(|&(n, v)| (n, v.to_owned())).collect()),
            // Format 1 keyed worlds by the settings' Debug text (of the
            // fields it had: every setting added since at the value that
            // gives the planets from before it); the terrain code did not
            // change between the last format-1 build and terrain version 1.
            legacy: (ProceduralPlanet::TERRAIN_VERSION == 1 && before_added_settings).then(|| {
                // The derived Debug text of the fields format 1 knew, in
                // their order (canonical values are Debug's: `{:?}` of each
                // f64, the seed's digits).
                const FORMAT_1_FIELDS: [&str; 8] = [
                    "radius",
                    "voxel_size",
                    "amplitude",
                    "feature_size",
                    "mountain_size",
                    "detail_amplitude",
                    "detail_size",
                    "seed",
                ];
                let fields: Vec<String> = FORMAT_1_FIELDS.iter().map(|n| format!("{n}: {}", value(n))).collect();
                format!("PlanetSettings {{ {} }}", fields.join(", "))
            }),
        }
    }

    /// The settings as stored: `name=value` lines, sorted by name.
    fn settings_bytes(&self) -> Vec<u8> {
        let mut settings = self.settings.clone();
        settings.sort();
        settings.iter().map(|(name, value)| format!("{name}={value}\n")).collect::<String>().into_bytes()
    }

    /// Whether stored settings are this terrain's: the same values, a
    /// setting missing from the store only where this build has the value
    /// that gives the older planets. Returns the differences otherwise, as
    /// (stored, this build) texts.
    fn compare_settings(&self, stored: &[(String, String)]) -> Result<(), (String, String)> {
        let mut differ: (Vec<String>, Vec<String>) = (Vec::new(), Vec::new());
        for (name, value) in &self.settings {
            let theirs =
                stored.iter().find(|(n, _)| n == name).map(|(_, v)| v.clone()).or_else(|| {
                    self.added_settings.iter().find(|(n, _)| n == name).map(|(_, implied)| implied.clone())
                });
            if theirs.as_ref() != Some(value) {
                differ.0.push(format!("{name}={}", theirs.as_deref().unwrap_or("(none)")));
                differ.1.push(format!("{name}={value}"));
            }
        }
        for (name, value) in stored.iter().filter(|(n, _)| !self.settings.iter().any(|(m, _)| m == n)) {
            differ.0.push(format!("{name}={value}"));
            differ.1.push(format!("{name}=(unknown to this build)"));
        }
        if differ.0.is_empty() { Ok(()) } else { Err((differ.0.join(", "), differ.1.join(", "))) }
    }
}

/// Parses stored `name=value` lines.
fn parse_settings(bytes: &[u8]) -> Option<Vec<(String, String)>> {
    let text = std::str::from_utf8(bytes).ok()?;
    text.lines().map(|line| line.split_once('=').map(|(n, v)| (n.to_owned(), v.to_owned()))).collect()
}

/// An open world file.
pub struct WorldStore {
    /// `None` after a failed reopen: the next save opens the file first.
    db: Option<Database>,
    path: PathBuf,
    /// Saves that failed since the last one that went through.
    failures: u32,
    /// Test hook: writes fail while set (a full disk).
    #[cfg(test)]
    pub(crate) disk_full: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl std::fmt::Debug for WorldStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorldStore").field("path", &self.path).finish_non_exhaustive()
    }
}

impl WorldStore {
    /// Opens the world at `path` for `terrain`, or creates it. Returns the
    /// store and every saved edit.
    ///
    /// # Errors
    /// [`WorldError::Corrupted`], [`WorldError::WrongVersion`],
    /// [`WorldError::TerrainVersion`] and [`WorldError::OtherPlanet`] (the
    /// file is left as it was), [`WorldError::InUse`],
    /// [`WorldError::Storage`].
    pub fn open(path: &Path, terrain: &Terrain) -> Result<(Self, Vec<(VoxelCoord, Voxel)>), WorldError> {
        // redb documents that opening a file damaged outside redb may panic
        // (we measured "Malformed allocator state" on flipped bytes, with
        // the integrity check on): such a file is refused like any other
        // corrupted one.
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| Self::open_checked(path, terrain))).unwrap_or_else(
            |panic| Err(WorldError::Corrupted { path: path.into(), reason: crate::panic_text(&*panic) }),
        )
    }

    fn open_checked(path: &Path, terrain: &Terrain) -> Result<(Self, Vec<(VoxelCoord, Voxel)>), WorldError> {
        let exists = std::fs::metadata(path).map(|m| m.len() > 0).unwrap_or(false);
        if !exists {
            let db = Database::create(path).map_err(|e| classify(path, e))?;
            let store = Self::with_db(db, path);
            store.write_identity(terrain)?;
            return Ok((store, Vec::new()));
        }
        // The read-only pass refuses a corrupted or foreign file before
        // anything could write to it.
        match Builder::new().set_check_integrity_on_open(true).open_read_only(path) {
            Ok(read_only) => {
                read_all(&read_only, path, terrain)?;
            }
            // Left by a killed writer: redb rolls it back to its last commit
            // when opened for writing; the checks below run on the result.
            Err(DatabaseError::RepairAborted) => {}
            Err(e) => return Err(classify(path, e)),
        }
        let db = Builder::new().set_check_integrity_on_open(true).open(path).map_err(|e| classify(path, e))?;
        // Read again on the handle we keep: a writer that committed between
        // the check and this open is not missed.
        let (format, edits) = read_all(&db, path, terrain)?;
        let store = Self::with_db(db, path);
        if format != FORMAT_VERSION {
            store.write_identity(terrain)?;
        }
        Ok((store, edits))
    }

    /// The terrain settings the world file at `path` was saved with, as
    /// `(name, value)` pairs, read without changing the file: `None` where
    /// there is no file yet, or where a killed writer left it to be rolled
    /// back first (opening it for writing does that, [`WorldStore::open`]);
    /// no pairs for a format-1 file, which names its planet by one text
    /// and holds none of the settings added since.
    ///
    /// # Errors
    /// [`WorldError::Corrupted`], [`WorldError::WrongVersion`],
    /// [`WorldError::InUse`], [`WorldError::Storage`].
    pub fn saved_settings(path: &Path) -> Result<Option<Vec<(String, String)>>, WorldError> {
        if !std::fs::metadata(path).is_ok_and(|m| m.len() > 0) {
            return Ok(None);
        }
        let db = match Builder::new().set_check_integrity_on_open(true).open_read_only(path) {
            Ok(db) => db,
            Err(DatabaseError::RepairAborted) => return Ok(None),
            Err(e) => return Err(classify(path, e)),
        };
        let txn = db.begin_read().map_err(|e| WorldError::Corrupted { path: path.into(), reason: e.to_string() })?;
        Ok(Some(match read_identity(&txn, path)?.1 {
            SavedTerrain::Legacy(_) => Vec::new(),
            SavedTerrain::Versioned { settings, .. } => settings,
        }))
    }

    fn with_db(db: Database, path: &Path) -> Self {
        Self {
            db: Some(db),
            path: path.into(),
            failures: 0,
            #[cfg(test)]
            disk_full: None,
        }
    }

    fn storage(&self, error: &dyn std::fmt::Display) -> WorldError {
        WorldError::Storage { path: self.path.clone(), message: error.to_string() }
    }

    /// Writes the format and the terrain (a new file, or one of format 1).
    fn write_identity(&self, terrain: &Terrain) -> Result<(), WorldError> {
        let db = self.db.as_ref().ok_or_else(|| self.storage(&"the world file is not open"))?;
        let txn = db.begin_write().map_err(|e| self.storage(&e))?;
        {
            let mut meta = txn.open_table(META).map_err(|e| self.storage(&e))?;
            meta.insert("format", [FORMAT_VERSION].as_slice()).map_err(|e| self.storage(&e))?;
            meta.insert("generator", terrain.generator.as_bytes()).map_err(|e| self.storage(&e))?;
            meta.insert("terrain_version", terrain.version.to_le_bytes().as_slice()).map_err(|e| self.storage(&e))?;
            meta.insert("settings", terrain.settings_bytes().as_slice()).map_err(|e| self.storage(&e))?;
            meta.remove("planet").map_err(|e| self.storage(&e))?;
            txn.open_table(CHUNK_EDITS).map_err(|e| self.storage(&e))?;
        }
        txn.commit().map_err(|e| self.storage(&e))
    }

    /// The world file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Saves that failed since the last one that went through (0 when the
    /// last save was written).
    #[must_use]
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// Replaces the saved edits of each LOD-0 chunk given (an empty list
    /// deletes the chunk's entry), all in one durable transaction. After a
    /// failure (or when the last save failed) the file is opened again on a
    /// new handle and the save retried once: a disk that was full takes
    /// the data as soon as there is room again.
    ///
    /// # Errors
    /// [`WorldError::Storage`]; nothing of the batch is saved then.
    pub fn save_chunks(&mut self, chunks: &[(ChunkKey, Vec<(VoxelCoord, Voxel)>)]) -> Result<(), WorldError> {
        let first = if self.failures > 0 { Err(self.storage(&"the last save failed")) } else { self.commit(chunks) };
        let result = first.or_else(|_| {
            self.reopen()?;
            self.commit(chunks)
        });
        match &result {
            Ok(()) => self.failures = 0,
            Err(_) => self.failures = self.failures.saturating_add(1),
        }
        result
    }

    /// Closes the handle and opens the file again: redb refuses every
    /// transaction of a handle that saw an I/O error.
    pub(crate) fn reopen(&mut self) -> Result<(), WorldError> {
        // The file lock is the handle's: the old one must go first.
        self.db = None;
        let builder = Builder::new();
        #[cfg(test)]
        if let Some(full) = &self.disk_full {
            let file =
                std::fs::OpenOptions::new().read(true).write(true).open(&self.path).map_err(|e| self.storage(&e))?;
            let disk = tests_support::FullDisk::new(file, full.clone()).map_err(|e| self.storage(&e))?;
            self.db = Some(builder.create_with_backend(disk).map_err(|e| classify(&self.path, e))?);
            return Ok(());
        }
        self.db = Some(builder.open(&self.path).map_err(|e| classify(&self.path, e))?);
        Ok(())
    }

    fn commit(&self, chunks: &[(ChunkKey, Vec<(VoxelCoord, Voxel)>)]) -> Result<(), WorldError> {
        let db = self.db.as_ref().ok_or_else(|| self.storage(&"the world file is not open"))?;
        let txn = db.begin_write().map_err(|e| self.storage(&e))?;
        {
            let mut table = txn.open_table(CHUNK_EDITS).map_err(|e| self.storage(&e))?;
            for (key, edits) in chunks {
                let db_key = (key.face as u8, key.x, key.y, key.layer);
                if edits.is_empty() {
                    table.remove(db_key).map_err(|e| self.storage(&e))?;
                } else {
                    table.insert(db_key, encode(*key, edits).as_slice()).map_err(|e| self.storage(&e))?;
                }
            }
        }
        txn.commit().map_err(|e| self.storage(&e))
    }

    /// How many chunks hold saved edits.
    ///
    /// # Errors
    /// [`WorldError::Storage`].
    pub fn saved_chunks(&self) -> Result<u64, WorldError> {
        let db = self.db.as_ref().ok_or_else(|| self.storage(&"the world file is not open"))?;
        let txn = db.begin_read().map_err(|e| self.storage(&e))?;
        txn.open_table(CHUNK_EDITS).map_err(|e| self.storage(&e))?.len().map_err(|e| self.storage(&e))
    }
}

fn classify(path: &Path, error: DatabaseError) -> WorldError {
    match error {
        DatabaseError::DatabaseAlreadyOpen => WorldError::InUse { path: path.into() },
        DatabaseError::Storage(StorageError::Corrupted(reason)) => WorldError::Corrupted { path: path.into(), reason },
        // redb's "not a redb database" (magic number) and short reads.
        DatabaseError::Storage(StorageError::Io(io))
            if matches!(io.kind(), std::io::ErrorKind::InvalidData | std::io::ErrorKind::UnexpectedEof) =>
        {
            WorldError::Corrupted { path: path.into(), reason: io.to_string() }
        }
        DatabaseError::UpgradeRequired(version) => WorldError::Corrupted {
            path: path.into(),
            reason: format!("redb file format {version} needs an upgrade this build does not do"),
        },
        other => WorldError::Storage { path: path.into(), message: other.to_string() },
    }
}

/// What a world file says its edits were made on.
enum SavedTerrain {
    /// Format 1: the planet's settings as one text (before versioned
    /// terrain).
    Legacy(String),
    /// The generator, its code version and its canonical settings.
    Versioned { generator: String, version: u32, settings: Vec<(String, String)> },
}

/// The file's format and the terrain it names, from its meta table.
fn read_identity(txn: &redb::ReadTransaction, path: &Path) -> Result<(u8, SavedTerrain), WorldError> {
    let corrupted = |reason: String| WorldError::Corrupted { path: path.into(), reason };
    let meta = txn.open_table(META).map_err(|e| corrupted(format!("no meta table ({e})")))?;
    let get = |name: &str| -> Result<Option<Vec<u8>>, WorldError> {
        Ok(meta.get(name).map_err(|e| corrupted(e.to_string()))?.map(|v| v.value().to_vec()))
    };
    let text = |bytes: Vec<u8>| String::from_utf8_lossy(&bytes).into_owned();
    let format = match get("format")?.as_deref() {
        Some(&[found]) if found == FORMAT_VERSION || found == 1 => found,
        Some(&[found]) => return Err(WorldError::WrongVersion { path: path.into(), found, supported: FORMAT_VERSION }),
        _ => return Err(corrupted("no format version".into())),
    };
    if format == 1 {
        let planet = get("planet")?.ok_or_else(|| corrupted("no planet".into()))?;
        return Ok((format, SavedTerrain::Legacy(text(planet))));
    }
    let generator = text(get("generator")?.ok_or_else(|| corrupted("no terrain generator".into()))?);
    let version = get("terrain_version")?
        .and_then(|v| <[u8; 4]>::try_from(v.as_slice()).ok())
        .map(u32::from_le_bytes)
        .ok_or_else(|| corrupted("no terrain version".into()))?;
    let settings = get("settings")?
        .as_deref()
        .and_then(parse_settings)
        .ok_or_else(|| corrupted("no readable terrain settings".into()))?;
    Ok((format, SavedTerrain::Versioned { generator, version, settings }))
}

/// The file's format and every saved edit, after checking the format, the
/// terrain and each value.
fn read_all(
    db: &impl ReadableDatabase,
    path: &Path,
    terrain: &Terrain,
) -> Result<(u8, Vec<(VoxelCoord, Voxel)>), WorldError> {
    let corrupted = |reason: String| WorldError::Corrupted { path: path.into(), reason };
    let txn = db.begin_read().map_err(|e| corrupted(e.to_string()))?;
    let (format, saved) = read_identity(&txn, path)?;
    match saved {
        SavedTerrain::Legacy(stored) => {
            if terrain.legacy.as_deref() != Some(stored.as_str()) {
                let given = terrain
                    .legacy
                    .clone()
                    .unwrap_or_else(|| format!("{} version {}", terrain.generator, terrain.version));
                return Err(WorldError::OtherPlanet { path: path.into(), stored, given });
            }
        }
        SavedTerrain::Versioned { generator, version, settings } => {
            if generator != terrain.generator {
                return Err(WorldError::OtherPlanet {
                    path: path.into(),
                    stored: generator,
                    given: terrain.generator.clone(),
                });
            }
            if version != terrain.version {
                return Err(WorldError::TerrainVersion {
                    path: path.into(),
                    generator,
                    stored: version,
                    this_build: terrain.version,
                });
            }
            terrain.compare_settings(&settings).map_err(|(stored, given)| WorldError::OtherPlanet {
                path: path.into(),
                stored,
                given,
            })?;
        }
    }
    let table = txn.open_table(CHUNK_EDITS).map_err(|e| corrupted(format!("no chunk table ({e})")))?;
    let mut edits = Vec::new();
    for entry in table.iter().map_err(|e| corrupted(e.to_string()))? {
        let (key, value) = entry.map_err(|e| corrupted(e.to_string()))?;
        let (face, x, y, layer) = key.value();
        let face = CubeFace::from_index(usize::from(face)).ok_or_else(|| corrupted(format!("cube face {face}")))?;
        let key = ChunkKey { face, lod: 0, x, y, layer };
        decode(key, value.value(), &mut edits).map_err(|reason| corrupted(format!("chunk {key:?}: {reason}")))?;
    }
    Ok((format, edits))
}

pub(crate) fn encode(key: ChunkKey, edits: &[(VoxelCoord, Voxel)]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(5 + 3 * edits.len());
    bytes.push(VALUE_FORMAT);
    bytes.extend_from_slice(&(edits.len() as u32).to_le_bytes());
    let size = CHUNK_SIZE as i64;
    for (at, voxel) in edits {
        let local = |index: i64, chunk: i64| (index - chunk * size) as u16;
        let (li, lj) = (local(at.i.into(), key.x.into()), local(at.j.into(), key.y.into()));
        let lh = local(at.h.into(), key.layer.into());
        let packed = li + 32 * (lj + 32 * lh);
        bytes.extend_from_slice(&packed.to_le_bytes());
        bytes.push(voxel.material());
    }
    bytes
}

pub(crate) fn decode(key: ChunkKey, bytes: &[u8], out: &mut Vec<(VoxelCoord, Voxel)>) -> Result<(), String> {
    let (&version, rest) = bytes.split_first().ok_or("empty value")?;
    if version != VALUE_FORMAT {
        return Err(format!("value format {version}, expected {VALUE_FORMAT}"));
    }
    let count = rest.get(..4).ok_or("truncated count")?;
    let count = u32::from_le_bytes([count[0], count[1], count[2], count[3]]) as usize;
    let entries = &rest[4..];
    if entries.len() != count * 3 {
        return Err(format!("{count} edits need {} bytes, found {}", count * 3, entries.len()));
    }
    let size = CHUNK_SIZE;
    for entry in entries.chunks_exact(3) {
        let packed = u32::from(u16::from_le_bytes([entry[0], entry[1]]));
        if packed >= size * size * size {
            return Err(format!("voxel index {packed} outside the chunk"));
        }
        let at = VoxelCoord {
            face: key.face,
            lod: 0,
            i: key.x * size + packed % size,
            j: key.y * size + packed / size % size,
            h: key.layer * size as i32 + (packed / (size * size)) as i32,
        };
        out.push((at, Voxel::from_material(entry[2])));
    }
    Ok(())
}

/// A disk that fills up on demand, for the tests of failed saves.
#[cfg(test)]
pub(crate) mod tests_support {
    use std::ops::Bound;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    use redb::backends::FileBackend;
    use redb::{BackendError, DatabaseError, StorageBackend};

    /// What redb's I/O methods return (without its `experimental-api-5`).
    type BackendIoError = std::io::Error;

    /// The world file, whose writes, syncs and growth fail with "no space
    /// left on device" while `full` is set.
    #[derive(Debug)]
    pub(crate) struct FullDisk {
        file: FileBackend,
        full: Arc<AtomicBool>,
    }

    impl FullDisk {
        pub(crate) fn new(file: std::fs::File, full: Arc<AtomicBool>) -> Result<Self, DatabaseError> {
            Ok(Self { file: FileBackend::new(file)?, full })
        }

        fn check(&self) -> Result<(), BackendIoError> {
            if self.full.load(Ordering::SeqCst) {
                Err(std::io::Error::from(std::io::ErrorKind::StorageFull))
            } else {
                Ok(())
            }
        }
    }

    impl StorageBackend for FullDisk {
        fn len(&self) -> Result<u64, BackendIoError> {
            self.file.len()
        }
        fn read(&self, offset: u64, out: &mut [u8]) -> Result<(), BackendIoError> {
            self.file.read(offset, out)
        }
        fn set_len(&self, len: u64) -> Result<(), BackendIoError> {
            self.check()?;
            self.file.set_len(len)
        }
        fn sync_data(&self) -> Result<(), BackendIoError> {
            self.check()?;
            self.file.sync_data()
        }
        fn write(&self, offset: u64, data: &[u8]) -> Result<(), BackendIoError> {
            self.check()?;
            self.file.write(offset, data)
        }
        fn close(&self) -> Result<(), BackendIoError> {
            self.file.close()
        }
        fn try_lock_range(&self, start: Bound<u64>, end: Bound<u64>) -> Result<bool, BackendError> {
            self.file.try_lock_range(start, end)
        }
        fn try_lock_shared_range(&self, start: Bound<u64>, end: Bound<u64>) -> Result<bool, BackendError> {
            self.file.try_lock_shared_range(start, end)
        }
        fn lock_range(&self, start: Bound<u64>, end: Bound<u64>) -> Result<(), BackendError> {
            self.file.lock_range(start, end)
        }
        fn lock_shared_range(&self, start: Bound<u64>, end: Bound<u64>) -> Result<(), BackendError> {
            self.file.lock_shared_range(start, end)
        }
        fn unlock_range(&self, start: Bound<u64>, end: Bound<u64>) -> Result<(), BackendError> {
            self.file.unlock_range(start, end)
        }
        fn query_lock_range(&self, start: Bound<u64>, end: Bound<u64>) -> Result<bool, BackendError> {
            self.file.query_lock_range(start, end)
        }
    }
}
