//! Saved worlds: per-chunk edit diffs in a redb database.
//!
//! ```text
//!   table "meta"         "format" → [FORMAT_VERSION]
//!                        "planet" → the planet's identity (its settings)
//!   table "chunk_edits"  (face, x, y, layer) of a LOD-0 chunk
//!                        → [version u8][count u32 LE][count × (local u16 LE, material u8)]
//! ```
//!
//! `local` is `i + 32·(j + 32·h)` inside the chunk. A value holds every
//! edited voxel of its chunk, so a save rewrites only the chunks an edit
//! touched, and a batch of edits is one write transaction: redb commits it
//! durably (fsync, copy-on-write pages, a checksummed two-phase commit) or
//! not at all, so a process killed mid-save loses at most the batch it was
//! writing and the file still opens.
//!
//! Opening checks the file read-only first (redb's integrity check, the
//! format version, the planet, every value's encoding) and refuses a
//! corrupted, foreign or wrong-version file before anything could write to
//! it. Only a file left by a killed writer is opened for writing straight
//! away: redb must roll it back to its last commit first.

use std::path::{Path, PathBuf};

use nebula_voxel::{CHUNK_SIZE, ChunkKey, CubeFace, Voxel, VoxelCoord};
use redb::{
    Builder, Database, DatabaseError, ReadableDatabase, ReadableTable, ReadableTableMetadata, StorageError,
    TableDefinition,
};

use crate::WorldError;

/// The format this build reads and writes, stored in the meta table and in
/// every chunk value.
pub const FORMAT_VERSION: u8 = 1;

pub(crate) const META: TableDefinition<&str, &[u8]> = TableDefinition::new("meta");
const CHUNK_EDITS: TableDefinition<(u8, u32, u32, i32), &[u8]> = TableDefinition::new("chunk_edits");

/// An open world file.
pub struct WorldStore {
    db: Database,
    path: PathBuf,
}

impl std::fmt::Debug for WorldStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorldStore").field("path", &self.path).finish_non_exhaustive()
    }
}

impl WorldStore {
    /// Opens the world at `path` for the planet named `planet` (any string
    /// that changes when the terrain would: `format!("{settings:?}")` for a
    /// procedural planet), or creates it. Returns the store and every saved
    /// edit.
    ///
    /// # Errors
    /// [`WorldError::Corrupted`], [`WorldError::WrongVersion`] and
    /// [`WorldError::OtherPlanet`] (the file is left as it was),
    /// [`WorldError::InUse`], [`WorldError::Storage`].
    pub fn open(path: &Path, planet: &str) -> Result<(Self, Vec<(VoxelCoord, Voxel)>), WorldError> {
        // redb documents that opening a file damaged outside redb may panic
        // (we measured "Malformed allocator state" on flipped bytes, with
        // the integrity check on): such a file is refused like any other
        // corrupted one.
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| Self::open_checked(path, planet))).unwrap_or_else(
            |panic| {
                let reason = panic
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_owned())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "the database reader gave up".into());
                Err(WorldError::Corrupted { path: path.into(), reason })
            },
        )
    }

    fn open_checked(path: &Path, planet: &str) -> Result<(Self, Vec<(VoxelCoord, Voxel)>), WorldError> {
        let storage = |e: &dyn std::fmt::Display| WorldError::Storage { path: path.into(), message: e.to_string() };
        let exists = std::fs::metadata(path).map(|m| m.len() > 0).unwrap_or(false);
        if !exists {
            let db = Database::create(path).map_err(|e| classify(path, e))?;
            let store = Self { db, path: path.into() };
            let txn = store.db.begin_write().map_err(|e| storage(&e))?;
            {
                let mut meta = txn.open_table(META).map_err(|e| storage(&e))?;
                meta.insert("format", [FORMAT_VERSION].as_slice()).map_err(|e| storage(&e))?;
                meta.insert("planet", planet.as_bytes()).map_err(|e| storage(&e))?;
                txn.open_table(CHUNK_EDITS).map_err(|e| storage(&e))?;
            }
            txn.commit().map_err(|e| storage(&e))?;
            return Ok((store, Vec::new()));
        }
        let checked = Builder::new().set_check_integrity_on_open(true).open_read_only(path);
        let edits = match checked {
            Ok(read_only) => {
                let edits = read_all(&read_only, path, planet)?;
                drop(read_only);
                edits
            }
            // Left by a killed writer: redb rolls it back to its last commit
            // when opened for writing; the checks below run on the result.
            Err(DatabaseError::RepairAborted) => Vec::new(),
            Err(e) => return Err(classify(path, e)),
        };
        let db = Builder::new().set_check_integrity_on_open(true).open(path).map_err(|e| classify(path, e))?;
        let edits = if edits.is_empty() { read_all(&db, path, planet)? } else { edits };
        Ok((Self { db, path: path.into() }, edits))
    }

    /// The world file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Replaces the saved edits of each LOD-0 chunk given (an empty list
    /// deletes the chunk's entry), all in one durable transaction.
    ///
    /// # Errors
    /// [`WorldError::Storage`]; nothing of the batch is saved then.
    pub fn save_chunks(&self, chunks: &[(ChunkKey, Vec<(VoxelCoord, Voxel)>)]) -> Result<(), WorldError> {
        let storage =
            |e: &dyn std::fmt::Display| WorldError::Storage { path: self.path.clone(), message: e.to_string() };
        let txn = self.db.begin_write().map_err(|e| storage(&e))?;
        {
            let mut table = txn.open_table(CHUNK_EDITS).map_err(|e| storage(&e))?;
            for (key, edits) in chunks {
                let db_key = (key.face as u8, key.x, key.y, key.layer);
                if edits.is_empty() {
                    table.remove(db_key).map_err(|e| storage(&e))?;
                } else {
                    table.insert(db_key, encode(*key, edits).as_slice()).map_err(|e| storage(&e))?;
                }
            }
        }
        txn.commit().map_err(|e| storage(&e))
    }

    /// How many chunks hold saved edits.
    ///
    /// # Errors
    /// [`WorldError::Storage`].
    pub fn saved_chunks(&self) -> Result<u64, WorldError> {
        let storage =
            |e: &dyn std::fmt::Display| WorldError::Storage { path: self.path.clone(), message: e.to_string() };
        let txn = self.db.begin_read().map_err(|e| storage(&e))?;
        txn.open_table(CHUNK_EDITS).map_err(|e| storage(&e))?.len().map_err(|e| storage(&e))
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

/// Every saved edit, after checking the format, the planet and each value.
fn read_all(db: &impl ReadableDatabase, path: &Path, planet: &str) -> Result<Vec<(VoxelCoord, Voxel)>, WorldError> {
    let corrupted = |reason: String| WorldError::Corrupted { path: path.into(), reason };
    let txn = db.begin_read().map_err(|e| corrupted(e.to_string()))?;
    let meta = txn.open_table(META).map_err(|e| corrupted(format!("no meta table ({e})")))?;
    let format = meta.get("format").map_err(|e| corrupted(e.to_string()))?.map(|v| v.value().to_vec());
    match format.as_deref() {
        Some([FORMAT_VERSION]) => {}
        Some([found]) => {
            return Err(WorldError::WrongVersion { path: path.into(), found: *found, supported: FORMAT_VERSION });
        }
        _ => return Err(corrupted("no format version".into())),
    }
    let stored = meta.get("planet").map_err(|e| corrupted(e.to_string()))?.map(|v| v.value().to_vec());
    let stored = String::from_utf8_lossy(&stored.ok_or_else(|| corrupted("no planet".into()))?).into_owned();
    if stored != planet {
        return Err(WorldError::OtherPlanet { path: path.into(), stored, given: planet.into() });
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
    Ok(edits)
}

pub(crate) fn encode(key: ChunkKey, edits: &[(VoxelCoord, Voxel)]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(5 + 3 * edits.len());
    bytes.push(FORMAT_VERSION);
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
    if version != FORMAT_VERSION {
        return Err(format!("value format {version}, expected {FORMAT_VERSION}"));
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
