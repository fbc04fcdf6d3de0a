//! Saved worlds: reopening, corruption, wrong versions, other planets.

use std::path::{Path, PathBuf};

use nebula_voxel::{DVec3, LayerView, PlanetSettings, ProceduralPlanet, Voxel, VoxelCoord, VoxelSource};

use crate::*;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("nebula-world-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir.join("world.redb")
}

fn unit(state: &mut u64) -> f64 {
    nebula_math::unit_random(state)
}

/// A point in the air of one of `planet`'s deep caves (sealed: its layer
/// view is the sealed caves'), with air 1.5 m over it too, from random
/// directions drawn from `state`.
fn air_in_a_deep_cave(planet: &ProceduralPlanet, state: &mut u64) -> DVec3 {
    let layout = planet.layout();
    let radius = layout.sphere().radius();
    let air = |p: DVec3| layout.voxel_at(p).is_ok_and(|at| !planet.voxel(at).unwrap().is_solid());
    for _ in 0..5_000 {
        let dir = DVec3::new(unit(state) - 0.5, unit(state) - 0.5, unit(state) - 0.5).normalize();
        let ground = planet.surface_point(dir).length();
        if ground < radius + 40.0 {
            continue;
        }
        let found = (1..140)
            .map(|k| dir * (ground - f64::from(k) * 0.5))
            .find(|&p| planet.layer_view(p) == LayerView::FromSealedCaves && air(p) && air(p + dir * 1.5));
        if let Some(point) = found {
            return point;
        }
    }
    panic!("no deep cave found");
}

/// A world at `path` with spheres dug and boxes and single blocks placed
/// at random spots of the ground, some next to cube edges.
fn edited_world(settings: &PlanetSettings, path: &Path, batches: usize) -> World {
    let mut world = World::open(settings.clone(), Some(path)).unwrap();
    let mut state = 0xed17_u64;
    for n in 0..batches {
        let mut direction = DVec3::new(unit(&mut state) - 0.5, unit(&mut state) - 0.5, unit(&mut state) - 0.5);
        if n % 4 == 0 {
            let axis = n % 3;
            direction[axis] = direction.abs().max_element().copysign(direction[axis]);
        }
        let ground = world.source().base().surface_point(direction.normalize());
        let size = world.source().base().voxel_size();
        let edits = [
            Edit::Sphere { center: ground, radius: 3.0 * size, voxel: Voxel::AIR },
            Edit::Box { min: ground - DVec3::splat(size), max: ground + DVec3::splat(2.0 * size), voxel: Voxel::STONE },
            Edit::Sphere {
                center: ground + direction.normalize() * 6.0 * size,
                radius: 1.2 * size,
                voxel: Voxel::SAND,
            },
        ];
        world.apply(&edits).unwrap();
    }
    world
}

fn edited_voxels(world: &World) -> Vec<(VoxelCoord, Voxel)> {
    let mut edits: Vec<_> = world.source().edits().collect();
    edits.sort_unstable_by_key(|&(at, _)| at);
    edits
}

#[test]
fn a_reopened_world_has_the_same_voxels() {
    for settings in [PlanetSettings::small(3), PlanetSettings::earth(11)] {
        let path = scratch(&format!("reopen-{}", settings.seed));
        let world = edited_world(&settings, &path, 12);
        let before = edited_voxels(&world);
        assert!(before.len() > 100, "the edits changed {} voxels", before.len());
        drop(world);
        let again = World::open(settings.clone(), Some(&path)).unwrap();
        assert_eq!(edited_voxels(&again), before, "reopened edits differ");
        for &(at, voxel) in &before {
            assert_eq!(again.source().voxel(at).unwrap(), voxel, "{at:?}");
        }
        let bytes = std::fs::metadata(&path).unwrap().len();
        println!(
            "{} edited voxels in {} chunks: {bytes} bytes ({:.0} bytes per 1,000 edited voxels)",
            before.len(),
            again.store().unwrap().saved_chunks().unwrap(),
            bytes as f64 * 1000.0 / before.len() as f64
        );
        // Undoing every edit empties the file's chunk table.
        let mut again = again;
        let undo: Vec<_> =
            before.iter().map(|&(at, _)| Edit::Voxel { at, voxel: again.source().base().voxel(at).unwrap() }).collect();
        again.apply(&undo).unwrap();
        assert_eq!(again.edit_count(), 0);
        assert_eq!(again.store().unwrap().saved_chunks().unwrap(), 0);
    }
}

/// What opening `path` gives, with a panic reported as such.
fn open_outcome(settings: &PlanetSettings, path: &Path) -> Result<Vec<(VoxelCoord, Voxel)>, WorldError> {
    let settings = settings.clone();
    let path = path.to_path_buf();
    std::panic::catch_unwind(move || World::open(settings, Some(&path)).map(|w| edited_voxels(&w)))
        .unwrap_or_else(|_| panic!("opening a damaged world panicked"))
}

#[test]
fn damaged_foreign_and_wrong_version_files_are_refused_untouched() {
    let settings = PlanetSettings::small(5);
    let good = scratch("damage-good");
    let want = edited_voxels(&edited_world(&settings, &good, 6));
    let original = std::fs::read(&good).unwrap();
    let damaged = scratch("damage");
    let mut refused = 0;
    let mut state = 0xbad_u64;
    let mut cases: Vec<(String, Vec<u8>)> = vec![
        ("truncated to half".into(), original[..original.len() / 2].to_vec()),
        ("a text file".into(), b"these are not the voxels you are looking for\n".repeat(100)),
        ("zeroed header".into(), [vec![0; 512], original[512..].to_vec()].concat()),
    ];
    for n in 0..24 {
        let mut bytes = original.clone();
        let at = (unit(&mut state) * bytes.len() as f64) as usize;
        let len = 1 + n % 16;
        for b in &mut bytes[at..(at + len).min(original.len())] {
            *b ^= 0x5a;
        }
        cases.push((format!("{len} bytes flipped at {at}"), bytes));
    }
    for (what, bytes) in cases {
        std::fs::write(&damaged, &bytes).unwrap();
        match open_outcome(&settings, &damaged) {
            Err(WorldError::Corrupted { .. }) => {
                refused += 1;
                assert!(std::fs::read(&damaged).unwrap() == bytes, "{what}: a refused file was modified");
            }
            Err(other) => panic!("{what}: {other}"),
            // Bytes redb does not read (free pages) may change nothing.
            Ok(got) => assert!(got == want, "{what}: opened with other voxels"),
        }
    }
    println!("{refused} of 27 damaged files refused; the rest opened with the same voxels");
    assert!(refused >= 3, "only {refused} refused");

    // Another planet's world, and a format from the future.
    std::fs::write(&damaged, &original).unwrap();
    let other = open_outcome(&PlanetSettings::small(6), &damaged);
    assert!(matches!(other, Err(WorldError::OtherPlanet { .. })), "{other:?}");
    assert!(std::fs::read(&damaged).unwrap() == original, "another planet's file was modified");
    {
        let db = redb::Database::open(&damaged).unwrap();
        let txn = db.begin_write().unwrap();
        txn.open_table(store::META).unwrap().insert("format", [FORMAT_VERSION + 1].as_slice()).unwrap();
        txn.commit().unwrap();
    }
    let future = std::fs::read(&damaged).unwrap();
    let refused = open_outcome(&settings, &damaged);
    assert!(
        matches!(refused, Err(WorldError::WrongVersion { found, supported: FORMAT_VERSION, .. }) if found == FORMAT_VERSION + 1),
        "{refused:?}"
    );
    assert!(std::fs::read(&damaged).unwrap() == future, "a wrong-version file was modified");
}

#[test]
fn a_full_disk_fails_saves_and_a_later_save_writes_everything() {
    // The world's file on a disk that fills up on demand (writes, syncs
    // and growth fail with "no space left"): after the first failure redb
    // refuses every transaction of that handle, so recovery needs a new
    // one. Edits made while the disk is full stay applied and counted as
    // unsaved; once there is room the next save writes them all, and the
    // file reopens with every edit.
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let settings = PlanetSettings::small(9);
    let path = scratch("full-disk");
    let mut world = World::open(settings.clone(), Some(&path)).unwrap();
    let full = Arc::new(AtomicBool::new(false));
    {
        let store = world.store.as_mut().unwrap();
        store.disk_full = Some(full.clone());
        store.reopen().unwrap();
    }
    let size = world.source().base().voxel_size();
    let mut state = 0xf011_u64;
    let mut dig = |world: &mut World| {
        let direction = DVec3::new(unit(&mut state) - 0.5, unit(&mut state) - 0.5, unit(&mut state) - 0.5).normalize();
        let ground = world.source().base().surface_point(direction);
        world.apply(&[Edit::Sphere { center: ground, radius: 2.5 * size, voxel: Voxel::AIR }])
    };
    dig(&mut world).unwrap();
    assert_eq!(world.unsaved_chunks(), 0);
    full.store(true, Ordering::SeqCst);
    for attempt in 0..3 {
        let failed = dig(&mut world);
        assert!(matches!(failed, Err(WorldError::Storage { .. })), "attempt {attempt}: {failed:?}");
        assert!(world.unsaved_chunks() > 0);
        assert!(world.store().unwrap().failures() > 0);
    }
    let pending = world.unsaved_chunks();
    assert!(matches!(world.save(), Err(WorldError::Storage { .. })), "the disk is still full");
    full.store(false, Ordering::SeqCst);
    assert_eq!(world.save().unwrap(), pending, "the save after the disk has room writes every pending chunk");
    assert_eq!(world.unsaved_chunks(), 0);
    assert_eq!(world.store().unwrap().failures(), 0);
    dig(&mut world).unwrap();
    let want = edited_voxels(&world);
    drop(world);
    let reopened = World::open(settings, Some(&path)).unwrap();
    assert_eq!(edited_voxels(&reopened), want, "edits made while the disk was full were lost");
    println!("full disk: 3 edits refused, {pending} chunks pending, all saved once the disk had room");

    // The control: the same first failure without reopening stays failed
    // (redb's "previous I/O error"), which is what main did for the rest
    // of the session.
    let path = scratch("full-disk-control");
    let store_dir = World::open(PlanetSettings::small(9), Some(&path)).unwrap();
    drop(store_dir);
    let file = std::fs::OpenOptions::new().read(true).write(true).open(&path).unwrap();
    let full = Arc::new(AtomicBool::new(false));
    let db = redb::Builder::new()
        .create_with_backend(store::tests_support::FullDisk::new(file, full.clone()).unwrap())
        .unwrap();
    let write = |db: &redb::Database| -> Result<(), String> {
        let txn = db.begin_write().map_err(|e| e.to_string())?;
        txn.open_table(store::META)
            .map_err(|e| e.to_string())?
            .insert("probe", [1u8].as_slice())
            .map_err(|e| e.to_string())?;
        txn.commit().map_err(|e| e.to_string())
    };
    full.store(true, Ordering::SeqCst);
    assert!(write(&db).is_err());
    full.store(false, Ordering::SeqCst);
    let again = write(&db);
    assert!(again.is_err(), "redb took a write on a handle that saw an I/O error: the reopen would not be needed");
    println!("control, same handle after the disk has room: {}", again.unwrap_err());
}

#[test]
fn a_world_open_in_another_process_is_in_use() {
    // This test runs itself as the other process: with the variable set,
    // it holds the world open until its input closes.
    const HOLD: &str = "NEBULA_TEST_HOLD_WORLD";
    if let Ok(path) = std::env::var(HOLD) {
        let world = World::open(PlanetSettings::small(2), Some(Path::new(&path))).unwrap();
        println!("HOLDING");
        std::io::Write::flush(&mut std::io::stdout()).unwrap();
        let _ = std::io::Read::read_to_end(&mut std::io::stdin(), &mut Vec::new());
        drop(world);
        return;
    }
    use std::io::BufRead;
    let path = scratch("in-use");
    drop(World::open(PlanetSettings::small(2), Some(&path)).unwrap());
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "tests::a_world_open_in_another_process_is_in_use", "--nocapture", "--test-threads=1"])
        .env(HOLD, &path)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut lines = stdout.lines();
    assert!(lines.any(|line| line.is_ok_and(|l| l.contains("HOLDING"))), "the other process never opened the world");
    let before = std::fs::read(&path).unwrap();
    let refused = World::open(PlanetSettings::small(2), Some(&path));
    assert!(matches!(refused, Err(WorldError::InUse { .. })), "{refused:?}");
    assert!(std::fs::read(&path).unwrap() == before, "the file was written while another process had it");
    drop(child.stdin.take());
    assert!(child.wait().unwrap().success());
    World::open(PlanetSettings::small(2), Some(&path)).expect("opens once the other process has closed it");
}

#[test]
fn a_world_knows_its_terrain() {
    let settings = PlanetSettings::small(3);
    let this = Terrain::of_planet(&settings);
    let planet = || ProceduralPlanet::new(settings.clone()).unwrap();
    let edit = |world: &mut World| {
        let ground = world.source().base().surface_point(DVec3::Y);
        world.apply(&[Edit::Sphere { center: ground, radius: 3.0, voxel: Voxel::AIR }]).unwrap();
        edited_voxels(world)
    };

    // Saved by a build whose terrain code is another version: refused as
    // such, untouched.
    let path = scratch("terrain-version");
    let newer = Terrain { version: this.version + 1, ..this.clone() };
    edit(&mut World::with_source(planet(), &newer, Some(&path)).unwrap());
    let bytes = std::fs::read(&path).unwrap();
    let refused = World::open(settings.clone(), Some(&path)).unwrap_err();
    assert!(
        matches!(refused, WorldError::TerrainVersion { stored, this_build, .. } if stored == this.version + 1 && this_build == this.version),
        "{refused:?}"
    );
    let message = refused.to_string();
    assert!(
        message.contains(&format!("terrain version {}", this.version + 1))
            && message.contains(&format!("this build has {}", this.version)),
        "{message}"
    );
    assert!(std::fs::read(&path).unwrap() == bytes, "refused file was modified");

    // Saved before a setting existed: it opens where this build has the
    // value that gives the older planets, and only there.
    let path = scratch("added-setting");
    let without = Terrain {
        settings: this.settings.iter().filter(|(n, _)| n != "mountain_size").cloned().collect(),
        ..this.clone()
    };
    let want = edit(&mut World::with_source(planet(), &without, Some(&path)).unwrap());
    let value = this.settings.iter().find(|(n, _)| n == "mountain_size").unwrap().1.clone();
    let knows = Terrain { added_settings: vec![("mountain_size".into(), value)], ..this.clone() };
    let opened = World::with_source(planet(), &knows, Some(&path)).unwrap();
    assert_eq!(edited_voxels(&opened), want);
    drop(opened);
    for other in
        [Terrain { added_settings: vec![("mountain_size".into(), "1.0".into())], ..this.clone() }, this.clone()]
    {
        let refused = World::with_source(planet(), &other, Some(&path));
        assert!(
            matches!(&refused, Err(WorldError::OtherPlanet { stored, .. }) if stored.contains("mountain_size")),
            "{refused:?}"
        );
    }

    // Another seed: another planet, named by the setting that differs.
    let refused = World::open(PlanetSettings::small(4), Some(&path)).unwrap_err();
    assert!(refused.to_string().contains("seed=3") && refused.to_string().contains("seed=4"), "{refused}");

    // A format-1 world (settings' Debug text, before terrain versions and
    // caves) of this planet without caves opens with its edits and is
    // rewritten as this format; one of another planet, or this one with
    // caves, is refused untouched.
    let path = scratch("format-1");
    let ground = planet().surface_point(DVec3::Z);
    let at = planet().layout().voxel_at(ground).unwrap();
    let key = planet().layout().chunk_of(at);
    let write_v1 = |path: &Path, planet_text: &str| {
        let db = redb::Database::create(path).unwrap();
        let txn = db.begin_write().unwrap();
        {
            let mut meta = txn.open_table(store::META).unwrap();
            meta.insert("format", [1u8].as_slice()).unwrap();
            meta.insert("planet", planet_text.as_bytes()).unwrap();
            let chunks: redb::TableDefinition<(u8, u32, u32, i32), &[u8]> = redb::TableDefinition::new("chunk_edits");
            let mut table = txn.open_table(chunks).unwrap();
            table
                .insert((key.face as u8, key.x, key.y, key.layer), store::encode(key, &[(at, Voxel::SNOW)]).as_slice())
                .unwrap();
        }
        txn.commit().unwrap();
    };
    // What format-1 builds wrote: the Debug text of the settings before
    // `cave_size`, `octave_grid`, `octave_grid_error` and `band_limit`, the
    // last fields, were added.
    let heightfield = PlanetSettings {
        cave_size: 0.0,
        octave_grid: 0.0,
        octave_grid_error: 0.0,
        band_limit: 0.0,
        ..settings.clone()
    };
    let format_1_text = |settings: &PlanetSettings| {
        format!("{settings:?}")
            .replace(", cave_size: 0.0, octave_grid: 0.0, octave_grid_error: 0.0, band_limit: 0.0 }", " }")
    };
    let text = format_1_text(&heightfield);
    assert!(!text.contains("cave") && !text.contains("octave") && !text.contains("band"));
    write_v1(&path, &format_1_text(&heightfield));
    let bytes = std::fs::read(&path).unwrap();
    assert!(matches!(World::open(settings.clone(), Some(&path)), Err(WorldError::OtherPlanet { .. })));
    assert!(std::fs::read(&path).unwrap() == bytes, "a format-1 file of another planet was modified");
    // A format-1 file has none of the settings added since: taken over,
    // they are those that give its planet.
    assert_eq!(World::saved_settings_over(settings.clone(), &path, &[]).unwrap(), heightfield);
    let settings = heightfield;
    let opened = World::open(settings.clone(), Some(&path)).unwrap();
    assert_eq!(opened.source().voxel(at).unwrap(), Voxel::SNOW);
    drop(opened);
    let db = redb::Database::open(&path).unwrap();
    let format = redb::ReadableDatabase::begin_read(&db)
        .unwrap()
        .open_table(store::META)
        .unwrap()
        .get("format")
        .unwrap()
        .unwrap()
        .value()
        .to_vec();
    assert_eq!(format, [FORMAT_VERSION]);
    drop(db);
    assert_eq!(World::open(settings.clone(), Some(&path)).unwrap().source().voxel(at).unwrap(), Voxel::SNOW);
    let path = scratch("format-1-other");
    let other = PlanetSettings { cave_size: 0.0, octave_grid: 0.0, octave_grid_error: 0.0, ..PlanetSettings::small(4) };
    write_v1(&path, &format_1_text(&other));
    let bytes = std::fs::read(&path).unwrap();
    assert!(matches!(World::open(settings, Some(&path)), Err(WorldError::OtherPlanet { .. })));
    assert!(std::fs::read(&path).unwrap() == bytes, "a foreign format-1 file was modified");
}

#[test]
fn a_world_keeps_the_settings_added_since_it_was_saved_unless_given() {
    // A world saved before the presets' band limit and coarse grids (both
    // 0 then) is refused with today's presets; with those two taken over
    // from its file it opens with its edits. A setting given explicitly is
    // kept, checked against the file, and refused untouched. No file yet:
    // the settings as they were.
    let presets = PlanetSettings::small(4);
    assert!(presets.band_limit > 0.0 && presets.octave_grid_error > 0.0);
    let saved = PlanetSettings { band_limit: 0.0, octave_grid_error: 0.0, ..presets.clone() };
    let path = scratch("added-settings");
    assert_eq!(World::saved_settings_over(presets.clone(), &path, &[]).unwrap(), presets);
    let mut world = World::open(saved.clone(), Some(&path)).unwrap();
    let ground = world.source().base().surface_point(DVec3::X);
    let at = world.source().base().layout().voxel_at(ground).unwrap();
    world.apply(&[Edit::Sphere { center: ground, radius: 3.0, voxel: Voxel::SNOW }]).unwrap();
    assert_eq!(world.unsaved_chunks(), 0);
    drop(world);
    assert!(matches!(World::open(presets.clone(), Some(&path)), Err(WorldError::OtherPlanet { .. })));
    let taken = World::saved_settings_over(presets.clone(), &path, &[]).unwrap();
    assert_eq!(taken, saved);
    assert_eq!(World::open(taken, Some(&path)).unwrap().source().voxel(at).unwrap(), Voxel::SNOW);
    let given = World::saved_settings_over(presets.clone(), &path, &["band_limit"]).unwrap();
    assert_eq!((given.band_limit, given.octave_grid_error), (presets.band_limit, 0.0));
    let bytes = std::fs::read(&path).unwrap();
    assert!(matches!(World::open(given, Some(&path)), Err(WorldError::OtherPlanet { .. })));
    assert!(std::fs::read(&path).unwrap() == bytes, "a refused world file was modified");
}

#[test]
fn bad_edits_are_errors_and_the_good_ones_before_them_are_kept() {
    let settings = PlanetSettings::small(4);
    let path = scratch("bad-edits");
    let mut world = World::open(settings.clone(), Some(&path)).unwrap();
    let ground = world.source().base().surface_point(DVec3::X);
    let result = world.apply(&[
        Edit::Sphere { center: ground, radius: 2.0, voxel: Voxel::AIR },
        Edit::Sphere { center: ground, radius: f64::NAN, voxel: Voxel::AIR },
    ]);
    assert!(matches!(result, Err(WorldError::Voxel(_))), "{result:?}");
    let kept = world.edit_count();
    assert!(kept > 0);
    // The chunks the kept edits changed are not lost for the renderer.
    let unreported = world.take_unreported();
    assert!(!unreported.is_empty(), "the chunks of the kept crater were lost");
    assert!(world.take_unreported().is_empty());
    for bad in [
        Edit::Box { min: ground, max: ground - DVec3::ONE, voxel: Voxel::STONE },
        Edit::Box { min: ground, max: ground + DVec3::splat(1e6), voxel: Voxel::STONE },
        Edit::Sphere { center: DVec3::splat(f64::INFINITY), radius: 1.0, voxel: Voxel::AIR },
    ] {
        assert!(matches!(world.apply(&[bad]), Err(WorldError::Voxel(_))), "{bad:?}");
    }
    assert!(matches!(world.pick(ground, DVec3::ZERO, 10.0), Err(WorldError::Voxel(_))));
    drop(world);
    assert_eq!(World::open(settings, Some(&path)).unwrap().edit_count(), kept);
}

fn any_chunk() -> impl proptest::strategy::Strategy<Value = ChunkKey> {
    use proptest::prelude::*;
    (0usize..6, 0u32..1 << 12, 0u32..1 << 12, -1000i32..1000).prop_map(|(face, x, y, layer)| ChunkKey {
        face: nebula_voxel::CubeFace::ALL[face],
        lod: 0,
        x,
        y,
        layer,
    })
}

proptest::proptest! {
    /// A chunk's saved edits decode to what was encoded.
    #[test]
    fn chunk_diffs_round_trip(key in any_chunk(), cells in proptest::collection::btree_map(0u32..32 * 32 * 32, 0u8..=255, 0..200)) {
        let edits: Vec<(VoxelCoord, Voxel)> = cells
            .iter()
            .map(|(&cell, &material)| {
                let at = VoxelCoord {
                    face: key.face,
                    lod: 0,
                    i: key.x * 32 + cell % 32,
                    j: key.y * 32 + cell / 32 % 32,
                    h: key.layer * 32 + (cell / 1024) as i32,
                };
                (at, Voxel::from_material(material))
            })
            .collect();
        let mut back = Vec::new();
        store::decode(key, &store::encode(key, &edits), &mut back).unwrap();
        back.sort_unstable_by_key(|&(at, _)| at);
        let mut want = edits.clone();
        want.sort_unstable_by_key(|&(at, _)| at);
        proptest::prop_assert_eq!(back, want);
    }

    /// Arbitrary bytes as a chunk value never panic: an error, or voxels
    /// inside that chunk.
    #[test]
    fn any_bytes_decode_to_an_error_or_voxels_of_the_chunk(key in any_chunk(), bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..64)) {
        let mut out = Vec::new();
        if store::decode(key, &bytes, &mut out).is_ok() {
            for (at, _) in out {
                proptest::prop_assert_eq!((at.i / 32, at.j / 32, at.h.div_euclid(32)), (key.x, key.y, key.layer));
            }
        }
    }
}

mod walking {
    use nebula_voxel::{DVec3, PlanetSettings, ProceduralPlanet, Voxel, VoxelSource};

    use crate::walk::{Body, Walker, ground_below, is_solid, local_frame, move_body};
    use crate::{Edit, World};

    fn unit(state: &mut u64) -> f64 {
        super::unit(state)
    }

    /// How deep `body` overlaps the nearest solid voxel's local box on its
    /// least-overlapping axis (≤ 0: not inside any block).
    fn deepest_overlap<S: VoxelSource + ?Sized>(source: &S, body: Body) -> f64 {
        let (east, north, up) = local_frame(body.feet).unwrap();
        let layout = source.layout();
        let sphere = layout.sphere();
        let centre = layout.voxel_at(body.feet + up * body.height * 0.5).unwrap();
        let low = [-body.half_width, -body.half_width, 0.0];
        let high = [body.half_width, body.half_width, body.height];
        let per_edge = i64::from(layout.voxels_per_edge(0));
        let mut worst = f64::NEG_INFINITY;
        for di in -4i64..=4 {
            for dj in -4i64..=4 {
                let Some((face, i, j)) =
                    centre.face.wrap_cell(i64::from(centre.i) + di, i64::from(centre.j) + dj, per_edge)
                else {
                    continue;
                };
                for dh in -4i64..=4 {
                    let h = i64::from(centre.h) + dh;
                    let at = nebula_voxel::VoxelCoord { face, lod: 0, i: i as u32, j: j as u32, h: h as i32 };
                    if !source.voxel(at).unwrap().is_solid() {
                        continue;
                    }
                    let mut overlap = f64::INFINITY;
                    for (k, axis) in [east, north, up].iter().enumerate() {
                        let mut span = (f64::INFINITY, f64::NEG_INFINITY);
                        for (a, b, r) in
                            [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)]
                        {
                            let p = sphere.direction(face, (i + a) as f64, (j + b) as f64)
                                * sphere.layer_radius((h + r) as f64);
                            let x = (p - body.feet).dot(*axis);
                            span = (span.0.min(x), span.1.max(x));
                        }
                        overlap = overlap.min(span.1.min(high[k]) - span.0.max(low[k]));
                    }
                    worst = worst.max(overlap);
                }
            }
        }
        worst
    }

    #[test]
    fn a_dropped_walker_lands_on_the_ground_and_stays_out_of_blocks() {
        for planet in [
            ProceduralPlanet::new(PlanetSettings::small(3)).unwrap(),
            ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap(),
        ] {
            let size = planet.voxel_size();
            let mut state = 0x1a_u64;
            for _ in 0..6 {
                let up = DVec3::new(unit(&mut state) - 0.5, unit(&mut state) - 0.5, unit(&mut state) - 0.5).normalize();
                let mut walker = Walker::new(planet.surface_point(up) + up * 3.0);
                for _ in 0..120 {
                    walker.step(&planet, 1.0 / 60.0, DVec3::ZERO, None).unwrap();
                }
                assert!(walker.on_ground, "a walker dropped 3 m is not standing after 2 s");
                let ground = ground_below(&planet, walker.body.feet + up * 0.5, 10.0).unwrap().expect("ground");
                let height = walker.body.feet.length() - ground.point.length();
                assert!(height.abs() < 0.03 * size, "feet {height} m over the top of the ground voxel");
                assert!(!is_solid(&planet, walker.body.feet + up * 0.05 * size).unwrap());
                assert!(deepest_overlap(&planet, walker.body) <= 0.02 * size);
            }
        }
    }

    #[test]
    fn a_long_fall_lands_at_terminal_speed() {
        // Dropped 3 km over Earth's ground at 10 frames a second: the fall
        // stays under terminal speed, never moves more than a collision
        // step allows, and lands on the ground (main refused to move after
        // 16 s of falling: more than 16 m per step).
        let planet = ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
        let up = DVec3::new(0.4, 0.7, -0.6).normalize();
        let mut walker = Walker::new(planet.surface_point(up) + up * 3_000.0);
        let mut seconds = 0.0;
        while !walker.on_ground {
            walker.step(&planet, 0.1, DVec3::new(3.0, 0.0, 0.0), None).unwrap();
            assert!(walker.vertical_speed >= -crate::walk::TERMINAL_SPEED);
            seconds += 0.1;
            assert!(seconds < 120.0, "still falling after 2 minutes");
        }
        assert!(!is_solid(&planet, walker.body.feet + walker.body.feet.normalize() * 0.05).unwrap());
        assert!(deepest_overlap(&planet, walker.body) <= 0.02 * planet.voxel_size());
        println!("a 3 km fall landed after {seconds:.1} s");
    }

    #[test]
    fn flying_straight_over_a_pole_goes_on_over_it() {
        // 200 steps of 0.5 km forward from 30 km before the +Z pole, 1 km
        // up: the orientation carried along passes the pole and goes on
        // down the far side. The demo's old heading, measured from north
        // (+Z), flips at the pole and sends the camera back: the control.
        use crate::walk::Orientation;
        let radius = 6_372_000.0;
        let start = DVec3::new(30_000.0 / radius, 0.0, 1.0).normalize() * radius;
        let fly = |forward_at: &mut dyn FnMut(DVec3) -> DVec3| {
            let mut eye = start;
            let mut farthest_past = f64::NEG_INFINITY;
            for _ in 0..200 {
                let forward = forward_at(eye);
                eye = (eye + forward * 500.0).normalize() * radius;
                // Metres past the pole along the flight's great circle (-x).
                farthest_past = farthest_past.max(-eye.x);
            }
            farthest_past
        };
        let mut orientation = Orientation::looking(start, -DVec3::X).unwrap();
        let carried = fly(&mut |eye| {
            orientation.move_to(eye);
            orientation.forward()
        });
        let north = fly(&mut |eye| local_frame(eye).unwrap().1);
        println!("past the pole: {carried:.0} m carried along, {north:.0} m north-relative");
        assert!(carried > 60_000.0, "stopped {carried} m past the pole");
        assert!(north < 1_000.0, "the control went {north} m past the pole: the check cannot tell");
        // Turning and pitching.
        let mut o = Orientation::looking(start, -DVec3::X).unwrap();
        let before = o.forward().dot(o.up()).asin();
        o.turn(std::f64::consts::FRAC_PI_2, 0.3);
        assert!((o.forward().dot(o.up()) - (before + 0.3).sin()).abs() < 1e-12);
        assert!(o.heading().dot(DVec3::Y).abs() > 0.999, "a quarter turn from -x heads along y");
        o.turn(0.0, 10.0);
        assert!((o.forward().dot(o.up()) - Orientation::MAX_PITCH.sin()).abs() < 1e-12);
        assert!(Orientation::looking(start, start).is_err(), "straight up has no heading");
    }

    /// A body from `feet` after a second of falling along −`up` with no
    /// collision (the walking tests' control).
    fn fall_without_collision(feet: DVec3, up: DVec3) -> Body {
        let mut ghost = Walker::new(feet);
        for _ in 0..60 {
            ghost.vertical_speed -= crate::walk::GRAVITY / 60.0;
            ghost.body.feet += up * ghost.vertical_speed / 60.0;
        }
        ghost.body
    }

    #[test]
    fn a_walker_stands_and_walks_on_a_caves_floor_and_picks_its_ceiling() {
        // Walking and picking read the voxels, caves included: a walker let
        // go in one of the Earth's deep caves lands on the cave's floor,
        // tens of metres under the ground, walks about it without entering
        // the rock, and a pick straight up from its eye hits the cave's
        // ceiling, not the ground's surface. The control: the same fall
        // with no collision goes through the floor into the rock.
        let planet = ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap();
        let size = planet.voxel_size();
        let mut state = 0xca7e_u64;
        for _ in 0..3 {
            let start = super::air_in_a_deep_cave(&planet, &mut state);
            let up = start.normalize();
            let ground = planet.surface_point(up).length();
            let mut walker = Walker { step_up: 1.05 * size, ..Walker::new(start) };
            for _ in 0..240 {
                walker.step(&planet, 1.0 / 60.0, DVec3::ZERO, None).unwrap();
            }
            assert!(walker.on_ground, "no floor under {start:?}");
            let floor = walker.body.feet;
            assert!(floor.length() <= start.length() + 0.01 && floor.length() < ground - 10.0, "{floor:?}");
            // Standing on rock: in air, and a tenth of a voxel lower it
            // would be in the floor.
            assert!(!is_solid(&planet, floor + up * 0.5 * size).unwrap());
            let lower = Body { feet: floor - up * 0.1 * size, ..walker.body };
            assert!(deepest_overlap(&planet, lower) > 0.0, "nothing under the walker at {floor:?}");
            let mut worst = f64::NEG_INFINITY;
            for step in 0..240 {
                let (e, n, _) = local_frame(walker.body.feet).unwrap();
                let angle = step as f64 * 0.03 + unit(&mut state);
                walker.step(&planet, 1.0 / 60.0, (e * angle.cos() + n * angle.sin()) * 3.0, None).unwrap();
                worst = worst.max(deepest_overlap(&planet, walker.body));
            }
            assert!(worst <= 0.02 * size, "a walk in a cave entered a block {worst} m deep");
            let feet = walker.body.feet;
            assert!(feet.length() < planet.surface_point(feet).length() - 10.0, "walked out of the cave");
            let eye = walker.eye().unwrap();
            let over = planet.surface_point(eye).length() - eye.length();
            let hit = nebula_voxel::pick(&planet, eye, eye.normalize(), 300.0).unwrap().expect("a ceiling");
            assert!(hit.distance < over - 5.0, "the pick went {} m of {over} m to the surface", hit.distance);
            assert!(hit.distance > 0.0);
            // Control: no collision, the same fall sinks into the floor.
            let ghost = fall_without_collision(floor + up * 0.01, up);
            assert!(deepest_overlap(&planet, ghost) > 0.1 * size, "the overlap check cannot see the floor");
        }
    }

    #[test]
    fn walls_stop_a_walker_and_random_walks_never_enter_a_block() {
        // A wall of stone built in front of the walker stops it; then random
        // walks and jumps (small planet and Earth, across a cube edge too)
        // never leave the body inside a block deeper than the contact
        // tolerance. The control moves the same way with no collision and
        // must end up inside the ground.
        let mut state = 0x3a11_u64;
        for settings in [PlanetSettings::small(3), PlanetSettings::earth(11)] {
            let mut world = World::open(settings, None).unwrap();
            let planet = world.source().base().clone();
            let size = planet.voxel_size();
            let up = DVec3::new(1.0, 1.0, 0.02).normalize();
            let (east, _, _) = local_frame(up).unwrap();
            // Spawned in the air (the smooth surface point can be inside a
            // voxel that sticks up) and left to land.
            let mut lander = Walker::new(planet.surface_point(up) + up * 3.0);
            for _ in 0..120 {
                lander.step(&planet, 1.0 / 60.0, DVec3::ZERO, None).unwrap();
            }
            assert!(lander.on_ground);
            let feet = lander.body.feet;
            let wall = feet + east * 4.0 * size + up * 2.0 * size;
            world
                .apply(&[Edit::Box {
                    min: wall - DVec3::splat(1.5 * size),
                    max: wall + DVec3::splat(1.5 * size),
                    voxel: Voxel::STONE,
                }])
                .unwrap();
            let source = world.voxels();
            let mut walker = Walker { step_up: 1.05 * size, ..Walker::new(feet) };
            for _ in 0..240 {
                walker.step(&*source, 1.0 / 60.0, east * 4.0, None).unwrap();
            }
            let walked = (walker.body.feet - feet).dot(east);
            assert!(walked < 4.0 * size && walked > size, "walked {walked} m towards a wall 4 voxels away");
            assert!(deepest_overlap(&*source, walker.body) <= 0.02 * size);

            // Random walks over a cube edge (+X/+Y here).
            for _ in 0..4 {
                let mut walker = Walker { step_up: 1.05 * size, ..lander };
                let mut worst = f64::NEG_INFINITY;
                for step in 0..300 {
                    if step % 30 == 0 {
                        let (e, n, _) = local_frame(walker.body.feet).unwrap();
                        let angle = unit(&mut state) * std::f64::consts::TAU;
                        let speed = 2.0 + unit(&mut state) * 6.0;
                        let heading = (e * angle.cos() + n * angle.sin()) * speed;
                        let jump = (unit(&mut state) < 0.5).then_some(5.0);
                        walker.step(&*source, 1.0 / 60.0, heading, jump).unwrap();
                    }
                    let (e, n, _) = local_frame(walker.body.feet).unwrap();
                    let heading = e * (step as f64 * 0.05).cos() * 5.0 + n * (step as f64 * 0.05).sin() * 5.0;
                    walker.step(&*source, 1.0 / 60.0, heading, None).unwrap();
                    worst = worst.max(deepest_overlap(&*source, walker.body));
                }
                assert!(worst <= 0.02 * size, "a walk entered a block {worst} m deep");
            }
            // Control: the same fall with no collision sinks into the ground.
            let ghost = fall_without_collision(feet, up);
            assert!(deepest_overlap(&*source, ghost) > 0.1 * size, "the overlap check cannot see a body in the ground");
        }
    }

    #[test]
    fn bad_motion_is_an_error() {
        let planet = ProceduralPlanet::new(PlanetSettings::small(3)).unwrap();
        let feet = planet.surface_point(DVec3::Y) + DVec3::Y;
        let body = Body { feet, half_width: 0.3, height: 1.8 };
        assert!(move_body(&planet, body, DVec3::NAN).is_err());
        assert!(move_body(&planet, Body { half_width: f64::INFINITY, ..body }, DVec3::ZERO).is_err());
        assert!(move_body(&planet, Body { height: 100.0, ..body }, DVec3::ZERO).is_err());
        assert!(Walker::new(feet).step(&planet, 5.0, DVec3::ZERO, None).is_err());
        assert!(Walker::new(feet).step(&planet, f64::NAN, DVec3::ZERO, None).is_err());
        assert!(local_frame(DVec3::ZERO).is_err());
    }
}

mod streaming {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};

    use nebula_lod::{Camera, LodSettings};
    use nebula_voxel::{DVec3, LayerView, PlanetSettings, ProceduralPlanet, VoxelSource};

    use super::unit;
    use crate::stream::{MeshHandle, Streamer};

    /// A renderer's handle that counts the live ones.
    struct Counted {
        bytes: u64,
        live: Arc<AtomicUsize>,
    }

    impl MeshHandle for Counted {
        fn bytes(&self) -> u64 {
            self.bytes
        }
    }

    impl Drop for Counted {
        fn drop(&mut self) {
            self.live.fetch_sub(1, Ordering::SeqCst);
        }
    }

    #[test]
    fn a_descent_streams_complete_frames_within_budget_and_frees_what_it_drops() {
        // From orbit down to 40 m and sideways over the small planet with
        // a 48 MiB budget (a frame needs about 30): every frame has something drawn for every
        // visible leaf (no holes), the meshes held stay within the budget,
        // every handle the streamer drops is freed (live handles = chunks
        // held), and standing still it settles.
        let planet =
            Arc::new(nebula_voxel::EditedSource::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap()));
        let live = Arc::new(AtomicUsize::new(0));
        let mut upload = {
            let live = live.clone();
            move |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| {
                live.fetch_add(1, Ordering::SeqCst);
                Counted { bytes: mesh.bytes(), live: live.clone() }
            }
        };
        let up = DVec3::new(0.35, 0.55, 0.76).normalize();
        let ground = planet.base().surface_point(up).length();
        let side = up.any_orthonormal_vector();
        let camera_at = |t: f64| {
            let altitude = 40.0 + (ground * 2.0) * (1.0 - t.min(1.0)).powi(3);
            let dir = (up + side * (t - 1.0).max(0.0) * 0.05).normalize();
            let position = dir * (ground + altitude);
            Camera { position, forward: (side - dir * 0.5).normalize(), up: dir, aspect: 1.6 }
        };
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let mut streamer = Streamer::new(planet.clone(), lod, camera_at(0.0), 2, &mut upload).unwrap();
        let budget = 48 << 20;
        streamer.cache.max_bytes = budget;
        let mut fullest = 0;
        // The descent (400 frames), then standing at its end while the
        // cache fills with what prefetching meshes, until the budget is
        // half full (a loaded machine meshes less in the descent itself).
        for frame in 0..8_000 {
            if frame >= 400 && fullest > budget / 2 {
                break;
            }
            streamer.update(camera_at(f64::from(frame.min(400)) / 200.0), &mut upload);
            assert_eq!(streamer.draw_list().holes, 0, "frame {frame} has a hole");
            assert_eq!(live.load(Ordering::SeqCst), streamer.cache.chunks(), "frame {frame}: handles leaked");
            fullest = fullest.max(streamer.cache.held_bytes());
            std::thread::sleep(std::time::Duration::from_millis(4));
        }
        assert!(fullest <= budget + budget / 10, "held {fullest} bytes, budget {budget}");
        assert!(fullest > budget / 2, "the budget was never approached ({fullest} bytes): the check cannot tell");
        let mut still = 0;
        while !streamer.settled() {
            streamer.update(camera_at(2.0), &mut upload);
            std::thread::sleep(std::time::Duration::from_millis(4));
            still += 1;
            assert!(still < 5_000, "did not settle");
        }
        println!(
            "descent: held at most {:.1} MB of {} MB; settled {still} frames after stopping",
            fullest as f64 / 1e6,
            budget >> 20
        );
        drop(streamer);
        assert_eq!(live.load(Ordering::SeqCst), 0, "handles outlived the streamer");
    }

    /// What a hold-then-turn showed: the worst frame of the turn.
    struct Turn {
        /// Triangles of the settled view before the turn and after it.
        settled: (usize, usize),
        /// Fewest triangles drawn in a frame of the turn.
        fewest: usize,
        /// Coarsest stand-in of a frame of the turn, LODs above its leaf.
        coarsest: u8,
    }

    /// Settles the view from `eye` looking along `forward`, holds it 400
    /// frames (until prefetching is done, with it on), then turns 120° about
    /// the radial up in 15 frames of 33 ms (0.5 s at 30 fps) and settles
    /// again.
    fn hold_then_turn(
        planet: &Arc<nebula_voxel::EditedSource<ProceduralPlanet>>,
        eye: DVec3,
        forward: DVec3,
        prefetch: bool,
    ) -> Turn {
        let up = eye.normalize();
        let camera = |angle: f64| {
            let f = nebula_math::DQuat::from_axis_angle(up, angle) * forward;
            Camera { position: eye, forward: f, up, aspect: 1.6 }
        };
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let mut streamer = Streamer::new(planet.clone(), lod, camera(0.0), 2, &mut { upload }).unwrap();
        streamer.cache.prefetch = prefetch;
        let settle = |streamer: &mut Streamer<_, Sized>, angle: f64| {
            for frames in 0.. {
                streamer.update(camera(angle), &mut { upload });
                if streamer.settled() {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(5));
                assert!(frames < 20_000, "did not settle");
            }
            streamer.figures().triangles
        };
        let before = settle(&mut streamer, 0.0);
        if prefetch {
            // Prefetched means done: once it says so, a still camera's
            // later frames find no meshing work (right after the view
            // settled it once said so before the prefetch set was made for
            // the refined tree, and 18,000 jobs came a few frames later).
            let mut frames = 0;
            while !streamer.prefetched() {
                streamer.update(camera(0.0), &mut { upload });
                std::thread::sleep(std::time::Duration::from_millis(5));
                frames += 1;
                assert!(frames < 40_000, "prefetching never ended");
            }
            for _ in 0..2 * crate::stream::PREFETCH_REFRESH_FRAMES {
                streamer.update(camera(0.0), &mut { upload });
                assert!(
                    streamer.prefetched() && streamer.jobs_in_flight() == 0,
                    "prefetching went on after it was done"
                );
            }
        }
        let mut held = 0;
        while held < 400 || (prefetch && !streamer.prefetched()) {
            streamer.update(camera(0.0), &mut { upload });
            std::thread::sleep(std::time::Duration::from_millis(5));
            held += 1;
            assert!(held < 40_000, "prefetching never ended");
        }
        let (mut fewest, mut coarsest) = (usize::MAX, 0);
        let turn = 120f64.to_radians();
        for frame in 1..=15 {
            streamer.update(camera(turn * f64::from(frame) / 15.0), &mut { upload });
            let figures = streamer.figures();
            assert_eq!(figures.holes, 0);
            fewest = fewest.min(figures.triangles);
            coarsest = coarsest.max(figures.max_stand_in_levels);
            std::thread::sleep(std::time::Duration::from_millis(33));
        }
        let after = settle(&mut streamer, turn);
        Turn { settled: (before, after), fewest, coarsest }
    }

    #[test]
    fn sealed_caves_are_streamed_only_for_an_eye_among_them() {
        // The Earth's deep caves are sealed (`nebula_voxel`'s
        // `layer_view`): over the ground the streamer meshes and draws no
        // layer that only they reach; down in one it draws them and, near
        // it (LODs 0–2), nothing else, every frame of the way complete;
        // back up it frees them.
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap());
        // A deep cave: air under the ground where the planet says an eye
        // sees what is buried.
        let deep_eye = super::air_in_a_deep_cave(&planet, &mut 17u64);
        let up = deep_eye.normalize();
        let above = planet.surface_point(up) + up * 30.0;
        let side = up.any_orthonormal_vector();
        let camera = |position: DVec3| Camera { position, forward: (side - up * 0.3).normalize(), up, aspect: 1.6 };
        assert_eq!(planet.layer_view(above), LayerView::FromAbove);
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let mut upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let mut streamer = Streamer::new(planet.clone(), lod, camera(above), 2, &mut upload).unwrap();
        // Drawn chunks in layers only the deep caves reach, and drawn
        // chunks near the eye (LODs 0–2) an eye in them cannot see.
        let outside = |streamer: &Streamer<ProceduralPlanet, Sized>, view: LayerView, near: bool| {
            streamer
                .drawn()
                .filter(|(key, ..)| {
                    (!near || key.lod <= 2)
                        && !planet.surface_chunk_layers_seen(key.column(), view).unwrap().contains(&key.layer)
                })
                .count()
        };
        let buried = |streamer: &Streamer<ProceduralPlanet, Sized>| outside(streamer, LayerView::FromAbove, false);
        let unsealed =
            |streamer: &Streamer<ProceduralPlanet, Sized>| outside(streamer, LayerView::FromSealedCaves, true);
        let mut go = |streamer: &mut Streamer<ProceduralPlanet, Sized>, position: DVec3| {
            let mut frames = 0;
            loop {
                streamer.update(camera(position), &mut upload);
                assert_eq!(streamer.draw_list().holes, 0, "frame {frames} has a hole");
                frames += 1;
                if frames > 8 && streamer.settled() {
                    break;
                }
                assert!(frames < 5_000, "did not settle");
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
        };
        go(&mut streamer, above);
        assert_eq!(buried(&streamer), 0, "buried layers drawn over the ground");
        let (over, over_unsealed) = (streamer.drawn().count(), unsealed(&streamer));
        assert!(over_unsealed > 0, "the sealed-cave check cannot tell");
        go(&mut streamer, deep_eye);
        let (down, down_all) = (buried(&streamer), streamer.drawn().count());
        assert!(down > 0, "no buried layer drawn in a deep cave");
        assert_eq!(unsealed(&streamer), 0, "the ground drawn from inside a sealed cave");
        go(&mut streamer, above);
        assert_eq!(buried(&streamer), 0, "buried layers still drawn after coming back up");
        println!(
            "deep cave at {deep_eye:.1}: {down} chunks of buried layers drawn down there ({down_all} drawn in all), \
             none over the ground ({over} drawn there)"
        );
    }

    /// A mesh handle that only knows its size.
    struct Sized(u64);

    impl MeshHandle for Sized {
        fn bytes(&self) -> u64 {
            self.0
        }
    }

    /// Updates `streamer` for the still `camera` (2 ms between frames)
    /// until its view is settled with every seam meshed for the LODs drawn
    /// around it; panics past `max_frames`.
    fn settle_seams<S: VoxelSource + 'static>(streamer: &mut Streamer<S, Sized>, camera: Camera, max_frames: u32) {
        let mut upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        for frames in 0.. {
            streamer.update(camera, &mut upload);
            if streamer.settled() && streamer.figures().unsettled == 0 {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
            assert!(frames < max_frames, "did not settle");
        }
    }

    #[test]
    fn a_paused_streamer_starts_no_job_and_settles_once_resumed() {
        // Paused from its first frame, a small planet's view stays drawn
        // by the face roots alone (stand-ins, never a hole) with every
        // job queued and none running; resumed, it settles. Without the
        // pause the same frames mesh: the check can tell.
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::small(3)).unwrap());
        let up = DVec3::new(0.3, 0.8, 0.5).normalize();
        let eye = planet.surface_point(up) + up * 60.0;
        let camera = Camera { position: eye, forward: up.any_orthonormal_vector() - up * 0.3, up, aspect: 1.6 };
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let frames = |paused: bool| {
            let mut streamer = Streamer::new(planet.clone(), lod, camera, 2, &mut { upload }).unwrap();
            streamer.set_meshing_paused(paused);
            let held = streamer.cache.chunks();
            for _ in 0..60 {
                streamer.update(camera, &mut { upload });
                assert_eq!(streamer.draw_list().holes, 0);
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
            (streamer.cache.chunks() - held, streamer)
        };
        let (meshed, _) = frames(false);
        assert!(meshed > 20, "unpaused, only {meshed} chunks were meshed: the check cannot tell");
        let (meshed, mut streamer) = frames(true);
        assert_eq!(meshed, 0, "paused, {meshed} chunks were meshed");
        assert!(streamer.jobs_in_flight() > 0 && streamer.draw_list().stand_ins > 0 && !streamer.settled());
        streamer.set_meshing_paused(false);
        for frame in 0.. {
            streamer.update(camera, &mut { upload });
            if streamer.settled() {
                break;
            }
            assert!(frame < 20_000, "did not settle once resumed");
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    }

    /// `count` random poses over `planet`'s land (the sea hides alike
    /// whatever came before, and is not what the tests using these check),
    /// drawn from `seed`: an eye between `altitude` metres over the ground,
    /// looking along a random heading between `down` degrees under the
    /// horizontal. Eyes and forward directions.
    fn land_poses(
        planet: &ProceduralPlanet,
        seed: u64,
        count: usize,
        altitude: (f64, f64),
        down: (f64, f64),
    ) -> Vec<(DVec3, DVec3)> {
        let mut state = seed;
        let mut poses = Vec::new();
        while poses.len() < count {
            let direction = DVec3::new(unit(&mut state) - 0.5, unit(&mut state) - 0.5, unit(&mut state) - 0.5);
            let Some(up) = direction.try_normalize() else { continue };
            let ground = planet.surface_point(up);
            if ground.length() < planet.settings().radius + 20.0 {
                continue;
            }
            let eye = ground + up * (altitude.0 + (altitude.1 - altitude.0) * unit(&mut state));
            let east = up.any_orthonormal_vector();
            let heading = nebula_math::DQuat::from_axis_angle(up, std::f64::consts::TAU * unit(&mut state)) * east;
            let down = (down.0 + (down.1 - down.0) * unit(&mut state)).to_radians();
            poses.push((eye, heading * down.cos() - up * down.sin()));
        }
        poses
    }

    #[test]
    fn a_view_held_then_turned_keeps_its_detail() {
        // Random poses over Earth's land, 200 m to 2 km over the ground,
        // looking 5-25 degrees down: after standing still past the cache's
        // ageing (300 frames) and turning 120 degrees in half a second, no
        // frame draws a stand-in more than STAND_IN_LEVEL_STEP LODs above
        // its leaf or less than 40 % of the settled views' triangles. With
        // prefetching off (what main did), the same turn flashes to
        // coarse stand-ins: the check can tell.
        let planet =
            Arc::new(nebula_voxel::EditedSource::new(ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap()));
        let poses = land_poses(planet.base(), 0x7, 2, (200.0, 2_000.0), (5.0, 25.0));
        for (n, &(eye, forward)) in poses.iter().enumerate() {
            let turn = hold_then_turn(&planet, eye, forward, true);
            let least = turn.settled.0.min(turn.settled.1);
            println!(
                "pose {n}: settled {} / {} triangles, turn: fewest {} ({:.0} %), coarsest stand-in {} LODs up",
                turn.settled.0,
                turn.settled.1,
                turn.fewest,
                100.0 * turn.fewest as f64 / least as f64,
                turn.coarsest
            );
            assert!(
                turn.coarsest <= crate::stream::STAND_IN_LEVEL_STEP,
                "pose {n}: stand-in {} LODs up",
                turn.coarsest
            );
            assert!(turn.fewest * 10 >= least * 4, "pose {n}: {} triangles of {least}", turn.fewest);
        }
        let (eye, forward) = poses[0];
        let control = hold_then_turn(&planet, eye, forward, false);
        println!(
            "prefetch off: fewest {} of {} triangles, coarsest stand-in {} LODs up",
            control.fewest, control.settled.1, control.coarsest
        );
        assert!(control.coarsest > crate::stream::STAND_IN_LEVEL_STEP, "the control did not flash");
    }

    /// Of what `streamer` draws for a camera at `eye`: the LOD-0 columns
    /// drawn with a mesh whose dark air is plugged, and how many of them
    /// lie where the planet around a narrow view's focus is drawn at LOD 0
    /// (its parent nearer than its split distance: `unplug_due`'s rule
    /// says those are drawn whole).
    fn plugged_lod_0<S: VoxelSource + 'static>(
        streamer: &Streamer<S, Sized>,
        eye: DVec3,
    ) -> (std::collections::HashSet<nebula_voxel::ChunkColumn>, usize) {
        let plugged: std::collections::HashSet<_> = streamer
            .drawn()
            .filter(|(key, chunk, _)| key.lod == 0 && chunk.dark_air_plugged)
            .map(|(key, _, _)| key.column())
            .collect();
        let near = plugged
            .iter()
            .filter(|&&column| streamer.tree().surround_split_ratio(column, eye).is_none_or(|ratio| ratio < 1.0))
            .count();
        (plugged, near)
    }

    /// The streamer settled for `camera`.
    fn settle<S: VoxelSource + 'static>(streamer: &mut Streamer<S, Sized>, camera: Camera) {
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        for frames in 0.. {
            streamer.update(camera, &mut { upload });
            if streamer.settled() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
            assert!(frames < 40_000, "did not settle");
        }
    }

    /// A lens's flight from a pose (`eye`, looking along `forward`): the
    /// camera at `t` from 0 to 1, 1.5 km on along the ground, tilting from
    /// the pose's pitch down to 50 degrees (the ground the lens then sees
    /// lies near).
    fn lens_flight(eye: DVec3, forward: DVec3) -> impl Fn(f64) -> Camera {
        let up = eye.normalize();
        let level = (forward - up * forward.dot(up)).normalize();
        let (pitch, last) = (forward.dot(-up).asin(), 50f64.to_radians());
        move |t: f64| {
            let down = pitch + (last - pitch) * t;
            Camera {
                position: eye + level * 1_500.0 * t,
                forward: level * down.cos() - up * down.sin(),
                up,
                aspect: 1.6,
            }
        }
    }

    #[test]
    fn a_narrow_lens_plugs_lod_0_only_where_a_wide_view_draws_lod_1_and_opens_it_as_the_eye_comes() {
        // Random poses 150-300 m over Earth's land, 2-4 degrees down,
        // through a 12-degree lens 200 px tall: LOD 0 is drawn kilometres
        // out, and its dark caves are plugged there (some drawn chunks
        // are), never where the surround (60 degrees) draws LOD 0 itself.
        // Flying 1.5 km on towards them while tilting down to 50 degrees
        // (the ground the lens then sees lies within that reach), the
        // chunks plugged that the eye came near are drawn whole once
        // settled; zoomed out to 60 degrees part way, none is drawn
        // plugged; a 60-degree view of the same pose plugs no LOD-0 chunk.
        // With the streamer broken to keep its plugs, the flight's check
        // fails.
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap());
        let poses = land_poses(&planet, 0x1e75, 2, (150.0, 300.0), (2.0, 4.0));
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lens = LodSettings { screen_height_px: 200.0, fov_y_degrees: 12.0, ..LodSettings::default() };
        let frames = 30;
        let flight = |eye: DVec3, forward: DVec3, plugs_kept: bool| {
            let camera = lens_flight(eye, forward);
            let mut streamer = Streamer::new(planet.clone(), lens, camera(0.0), 2, &mut { upload }).unwrap();
            streamer.selection_mut().plugs_kept = plugs_kept;
            settle(&mut streamer, camera(0.0));
            let (first, near_first) = plugged_lod_0(&streamer, eye);
            for frame in 1..=frames {
                streamer.update(camera(f64::from(frame) / f64::from(frames)), &mut { upload });
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
            let end = camera(1.0);
            settle(&mut streamer, end);
            let (now, near_now) = plugged_lod_0(&streamer, end.position);
            let opened = streamer
                .drawn()
                .filter(|(key, chunk, _)| first.contains(&key.column()) && !chunk.dark_air_plugged)
                .count();
            (first.len(), near_first, now.len(), near_now, opened)
        };
        for (n, &(eye, forward)) in poses.iter().enumerate() {
            let (first, near_first, now, near_now, opened) = flight(eye, forward, false);
            println!(
                "pose {n}: {first} LOD-0 columns drawn plugged ({near_first} near); after the flight: {now} \
                 ({near_now} near), {opened} chunks of the first drawn whole"
            );
            assert!(first > 0, "pose {n}: nothing plugged");
            assert_eq!((near_first, near_now), (0, 0), "pose {n}: plugged chunks drawn near");
            assert!(opened > 0, "pose {n}: no plugged chunk opened");
        }
        let (eye, forward) = poses[0];
        let (.., near_now, _) = flight(eye, forward, true);
        println!("plugs kept: {near_now} plugged LOD-0 columns near after the flight");
        assert!(near_now > 0, "the control drew no plugged chunk near");
        // Zoomed out part way: settled frame by frame along the flight
        // until some plugged chunks drawn lie between split and merge
        // (ratio 1 to 1 / (1 - hysteresis)), where a wide view's tree
        // keeps the LOD 0 it holds; zoomed out to the surround's 60
        // degrees there, they are drawn whole.
        let camera = lens_flight(eye, forward);
        let mut streamer = Streamer::new(planet.clone(), lens, camera(0.0), 2, &mut { upload }).unwrap();
        let merge = 1.0 / (1.0 - lens.hysteresis);
        let banded = (0..=frames).find_map(|frame| {
            let now = camera(f64::from(frame) / f64::from(frames));
            settle(&mut streamer, now);
            let (plugged, _) = plugged_lod_0(&streamer, now.position);
            let ratio = |column| streamer.tree().surround_split_ratio(column, now.position);
            let banded = plugged.into_iter().filter(|&c| ratio(c).is_some_and(|r| (1.0..merge).contains(&r))).count();
            (banded > 0).then_some((frame, banded, now))
        });
        let (frame, banded, now) = banded.expect("no plugged chunk drawn between split and merge");
        streamer.set_view(lens.threshold_px, lens.screen_height_px, 60.0).unwrap();
        settle(&mut streamer, now);
        let zoomed_out = plugged_lod_0(&streamer, now.position).0.len();
        println!("frame {frame}: {banded} plugged LOD-0 columns between split and merge; zoomed out: {zoomed_out}");
        assert_eq!(zoomed_out, 0, "a 60-degree view drew plugged LOD 0");
        let wide = LodSettings { fov_y_degrees: 60.0, ..lens };
        let camera = Camera { position: eye, forward, up: eye.normalize(), aspect: 1.6 };
        let mut streamer = Streamer::new(planet.clone(), wide, camera, 2, &mut { upload }).unwrap();
        settle(&mut streamer, camera);
        assert!(plugged_lod_0(&streamer, eye).0.is_empty(), "a 60-degree view plugged LOD 0");
    }

    /// Of what `streamer` draws: the chunks drawn leaving out stubs
    /// (`ChunkDraw::hidden_stubs`), and those of them where a side's stubs
    /// are left out though no column of its LOD is drawn across the side,
    /// or a chunk of its column or of that one is drawn now with a mesh
    /// not plugged inside, with a stub exposed, or with a pocket that is
    /// no stub reaching a layer either column draws
    /// (`LoadedChunk::pockets_beyond`), or where radial stubs are left out
    /// (a chunk plugged inside keeps none).
    fn stubs_left_out<S: VoxelSource + 'static>(streamer: &Streamer<S, Sized>) -> (usize, usize) {
        type Column = std::collections::HashMap<i32, (bool, [bool; 2])>;
        let mut columns: std::collections::HashMap<nebula_voxel::ChunkColumn, Column> = Default::default();
        for (key, chunk, _) in streamer.drawn() {
            let closed = chunk.plugged_inside && !chunk.stubs_exposed;
            columns.entry(key.column()).or_default().insert(key.layer, (closed, chunk.pockets_beyond));
        }
        let reaches = |from: &Column, into: &Column| {
            from.iter().any(|(layer, (_, [up, down]))| {
                (*up && into.contains_key(&(layer + 1))) || (*down && into.contains_key(&(layer - 1)))
            })
        };
        let closed = |column: &Column| column.values().all(|(closed, _)| *closed);
        let layout = streamer.voxels().layout();
        let (mut leaving_out, mut wrong) = (0, 0);
        for (key, _, draw) in streamer.drawn() {
            if draw.hidden_stubs == 0 {
                continue;
            }
            leaving_out += 1;
            let own = &columns[&key.column()];
            let sides_closed = nebula_math::FaceDirection::ALL.into_iter().all(|side| {
                if draw.hidden_stubs & (1 << side as u8) == 0 {
                    return true;
                }
                let Some(edge) = side.face_edge() else { return false };
                columns.get(&layout.neighbor(key, edge).column()).is_some_and(|across| {
                    closed(own)
                        && closed(across)
                        && !reaches(own, across)
                        && !reaches(across, own)
                        && !reaches(own, own)
                })
            });
            if !sides_closed {
                wrong += 1;
            }
        }
        (leaving_out, wrong)
    }

    /// Of what `streamer` draws: the plug groups
    /// (`nebula_meshing::plug_group`) drawn with a chunk plugged inside
    /// that filled dark air (it plugs the layers it shares with the chunks
    /// of its group) and a chunk not plugged inside.
    fn groups_drawn_with_both_plug_choices<S: VoxelSource + 'static>(streamer: &Streamer<S, Sized>) -> usize {
        let mut groups: std::collections::HashMap<nebula_voxel::ChunkColumn, (bool, bool)> = Default::default();
        for (key, chunk, _) in streamer.drawn() {
            let column = key.column();
            let entry = groups.entry(nebula_meshing::plug_group_key(column)).or_default();
            entry.0 |= chunk.plugged_inside && chunk.dark_air_plugged;
            entry.1 |= !chunk.plugged_inside;
        }
        groups.values().filter(|&&(inside, open)| inside && open).count()
    }

    #[test]
    fn stubs_are_left_out_only_between_chunks_drawn_plugged_inside_on_every_frame_of_a_lens_flight() {
        // A 12-degree lens 200 px tall over Earth's land, 150-300 m up:
        // far LOD-0 chunks are plugged inside, and many leave out their
        // stubs towards neighbours plugged so too. On every frame of a
        // 1.5 km flight tilting down to 50 degrees (the chunks the eye
        // comes near meshed open again, those it leaves behind dropped, a
        // frame drawing the plan before while the LOD thread plans), a
        // chunk leaves out a side's stubs only where both columns are
        // drawn that frame plugged inside with no stub exposed and no
        // pocket reaching a layer either draws, and no plug group is drawn
        // with a chunk plugged inside (plugging what it shares with the
        // group's others) and one open; also while settling where the
        // flight ends, a mesh drawn a frame. (The cache's control:
        // `a_plug_group_plugged_inside_is_drawn_open_in_all_its_chunks_at_once`.)
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap());
        let (eye, forward) = land_poses(&planet, 0x57b7, 1, (150.0, 300.0), (2.0, 4.0))[0];
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lens = LodSettings { screen_height_px: 200.0, fov_y_degrees: 12.0, ..LodSettings::default() };
        let camera = lens_flight(eye, forward);
        let flight = || {
            let mut streamer = Streamer::new(planet.clone(), lens, camera(0.0), 2, &mut { upload }).unwrap();
            settle(&mut streamer, camera(0.0));
            // One mesh drawn a frame: a column's layers come frame by frame.
            streamer.cache.max_upload_bytes = 1;
            let (settled, wrong) = stubs_left_out(&streamer);
            let both = groups_drawn_with_both_plug_choices(&streamer);
            println!("settled: {settled} chunks leave out stubs");
            assert!(settled > 100, "only {settled} chunks leave out stubs");
            assert_eq!((wrong, both), (0, 0), "settled");
            let (mut most, mut frames) = (0, 0);
            for frame in 1..=120 {
                streamer.update(camera(f64::from(frame.min(90)) / 90.0), &mut { upload });
                let (leaving_out, wrong) = stubs_left_out(&streamer);
                let both = groups_drawn_with_both_plug_choices(&streamer);
                assert_eq!(wrong, 0, "frame {frame}: stubs left out where they may be seen");
                assert_eq!(both, 0, "frame {frame}: a plug group drawn with both plug choices");
                most = most.max(leaving_out);
                frames += usize::from(leaving_out > 0);
                std::thread::sleep(std::time::Duration::from_millis(3));
            }
            // Settled where the flight ends (the columns it came near
            // meshed open, a mesh a frame).
            for frame in 0.. {
                streamer.update(camera(1.0), &mut { upload });
                let both = groups_drawn_with_both_plug_choices(&streamer);
                assert_eq!(stubs_left_out(&streamer).1, 0, "settling: stubs left out where they may be seen");
                assert_eq!(both, 0, "settling: a plug group drawn with both plug choices");
                if streamer.settled() {
                    break;
                }
                assert!(frame < 40_000, "did not settle");
            }
            println!("in flight: up to {most} chunks leave out stubs, in {frames} of 120 frames");
            frames
        };
        let frames = flight();
        assert!(frames > 10, "stubs left out in {frames} frames only");
    }

    /// A streamer of `world` (the small planet) settled, and past `frames`
    /// frames, for a still camera `height` metres over a ground point and
    /// 80 m to its side, looking `lift` metres over the point; the camera
    /// and the ground point.
    fn settled_over_the_ground(
        world: &crate::World,
        height: f64,
        lift: f64,
        frames: u32,
    ) -> (Streamer<nebula_voxel::EditedSource<ProceduralPlanet>, Sized>, Camera, DVec3) {
        let up = DVec3::new(0.3, 0.8, 0.5).normalize();
        let ground = world.source().base().surface_point(up);
        let eye = ground + up * height - up.any_orthonormal_vector() * 80.0;
        let camera = Camera { position: eye, forward: ground + up * lift - eye, up, aspect: 1.6 };
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let mut streamer = Streamer::new(world.voxels(), lod, camera, 2, &mut { upload }).unwrap();
        for done in 0.. {
            streamer.update(camera, &mut { upload });
            if streamer.settled() && done > frames {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
            assert!(done < 20_000, "did not settle");
        }
        (streamer, camera, ground)
    }

    #[test]
    fn a_still_view_gets_the_cull_alone_once_its_tree_stands() {
        // The LOD thread sends a whole copy of its tree only when the tree
        // changed since the copy the frame thread holds: a still camera
        // over a settled tree gets its cull (and plan) alone, every frame
        // still taking what the thread made.
        let world = crate::World::open(PlanetSettings::small(7), None).unwrap();
        // 300 m up, looking level: far ground in view, so that more than
        // one LOD is drawn (30 m up on the small planet, all that is seen
        // is LOD 0, the rest behind the ground's horizon).
        let (mut streamer, camera, _) = settled_over_the_ground(&world, 300.0, 300.0, 20);
        // Every frame takes the LOD thread's plan (waiting for it), as the
        // counts below assume.
        streamer.set_draw_while_planning(false);
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        // Its figures by LOD add up, and name the LODs drawn.
        let figures = streamer.figures();
        assert_eq!(figures.lod_triangles.iter().sum::<usize>(), figures.triangles);
        assert_eq!(figures.lod_histogram.iter().sum::<usize>(), figures.chunks);
        assert!(figures.lod_triangles.iter().zip(&figures.lod_histogram).all(|(&t, &n)| t == 0 || n > 0));
        assert!(figures.lod_histogram.iter().filter(|&&n| n > 0).count() > 1, "one LOD drawn: {figures:?}");
        let (copies, (taken, _)) = (streamer.lod_tree_copies(), streamer.lod_thread_frames());
        assert!(copies >= 1, "no tree came from the LOD thread");
        for _ in 0..50 {
            streamer.update(camera, &mut { upload });
        }
        let (taken_after, _) = streamer.lod_thread_frames();
        assert!(taken_after >= taken + 45, "the thread's work served {} of 50 still frames", taken_after - taken);
        assert_eq!(streamer.lod_tree_copies(), copies, "a still view's tree was copied again");
    }

    #[test]
    fn a_settled_views_prefetching_is_planned_without_the_view_and_as_the_full_plan_would() {
        // Once a still view is settled, the meshes that come for
        // prefetching change the cached columns every frame, but none the
        // view's part of the plan reads: the LOD thread plans those frames
        // from the view's part of the plan before (`SettledView`), and
        // makes the full plan beside each to check it (tests only: the
        // frame thread panics where they differ). The draw list stays the
        // same every frame. Broken to queue no job, the check fails.
        let run = |queue_nothing: bool| {
            let world = crate::World::open(PlanetSettings::small(7), None).unwrap();
            let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
            let up = DVec3::new(0.3, 0.8, 0.5).normalize();
            let eye = world.source().base().surface_point(up) + up * 30.0;
            let forward = up.any_orthonormal_vector();
            let camera = Camera { position: eye, forward, up, aspect: 1.6 };
            let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
            let mut streamer = Streamer::new(world.voxels(), lod, camera, 2, &mut { upload }).unwrap();
            // Every frame takes the LOD thread's plan (waiting for it), as the
            // counts below assume.
            streamer.set_draw_while_planning(false);
            streamer.selection_mut().prefetch_plans_queue_nothing = queue_nothing;
            // The view settled, its prefetching begun.
            for done in 0.. {
                streamer.update(camera, &mut { upload });
                if streamer.settled() && streamer.lod_plans_for_prefetching() > 0 {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(1));
                assert!(done < 20_000, "did not settle or begin prefetching");
            }
            let (drawn, meshed) = (streamer.draw_list().columns.clone(), streamer.figures().times.chunks_meshed);
            let (prefetch_plans, frames) = (streamer.lod_plans_for_prefetching(), streamer.lod_thread_frames());
            for frame in 0..200 {
                streamer.update(camera, &mut { upload });
                assert!(streamer.draw_list().columns == drawn, "frame {frame} of the hold draws something else");
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            let prefetching = streamer.lod_plans_for_prefetching() - prefetch_plans;
            let planned = streamer.lod_thread_frames().0 - frames.0;
            let prefetched = streamer.figures().times.chunks_meshed - meshed;
            println!("{prefetching} of {planned} plans taken prefetch-only while {prefetched} chunks were prefetched");
            (prefetching, prefetched)
        };
        let (prefetching, prefetched) = run(false);
        assert!(prefetched >= 50, "only {prefetched} chunks prefetched in 200 frames");
        assert!(prefetching >= 20, "{prefetching} prefetch-only plans while {prefetched} chunks were prefetched");
        let broken = std::panic::catch_unwind(|| run(true));
        assert!(broken.is_err(), "prefetch-only plans queueing nothing went unnoticed");
    }

    #[test]
    fn a_still_settled_view_is_planned_anew_only_where_time_can_change_it() {
        // A still camera over a settled view gets the LOD thread's plan
        // before again instead of a new one (`Repeatable`), but where a
        // column out of use is old enough to free: the same draw list
        // every frame, and what the view turned from is still freed for
        // age. Prefetching off: nothing out of view is kept.
        let world = crate::World::open(PlanetSettings::small(7), None).unwrap();
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let up = DVec3::new(0.3, 0.8, 0.5).normalize();
        let eye = world.source().base().surface_point(up) + up * 30.0;
        let side = up.any_orthonormal_vector();
        let looking = |forward: DVec3| Camera { position: eye, forward, up, aspect: 1.6 };
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let mut streamer = Streamer::new(world.voxels(), lod, looking(side), 2, &mut { upload }).unwrap();
        // Every frame takes the LOD thread's plan (waiting for it), as the
        // counts below assume.
        streamer.set_draw_while_planning(false);
        streamer.cache.prefetch = false;
        streamer.cache.free_after_frames = u64::MAX / 2;
        let settle = |streamer: &mut Streamer<_, Sized>, camera: Camera| {
            for done in 0.. {
                streamer.update(camera, &mut { upload });
                if streamer.settled() && streamer.jobs_in_flight() == 0 && done > 20 {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
                assert!(done < 20_000, "did not settle");
            }
        };
        settle(&mut streamer, looking(side));
        // Turned away: the first view's columns are out of use from now.
        let turned = looking(-side);
        settle(&mut streamer, turned);
        let (held, repeats) = (streamer.cache.chunks(), streamer.lod_plans_repeated());
        let drawn = streamer.draw_list().columns.clone();
        streamer.cache.free_after_frames = 5;
        for frame in 0..60 {
            streamer.update(turned, &mut { upload });
            assert!(streamer.draw_list().columns == drawn, "frame {frame} of the hold draws something else");
        }
        let repeated = streamer.lod_plans_repeated() - repeats;
        println!("{repeated} of 60 still frames repeated a plan; {held} chunks held -> {}", streamer.cache.chunks());
        assert!(repeated >= 40, "{repeated} of 60 still frames repeated the plan before");
        assert!(
            streamer.cache.chunks() < held,
            "nothing out of use was freed for age in 60 still frames ({held} chunks held)"
        );
    }

    #[test]
    fn a_tower_that_adds_a_chunk_layer_keeps_its_column_on_screen() {
        // A tower on the ground in view up to 8 voxels into the chunk layer
        // above the column's highest: its column gains a layer. The column stays drawn
        // (its old layers) until the new layer is meshed, so no frame draws
        // it, or the face, through a coarse stand-in.
        let mut world = crate::World::open(PlanetSettings::small(7), None).unwrap();
        // Settled past the cache's ageing too.
        let (mut streamer, camera, ground) = settled_over_the_ground(&world, 30.0, 20.0, 310);
        let up = ground.normalize();
        let size = world.source().base().voxel_size();
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let before = streamer.figures().triangles;
        let layout = world.source().layout();
        let column = layout.chunk_of(layout.voxel_at(ground).unwrap()).column();
        let layers_before = world.source().surface_chunk_layers(column).unwrap();
        let half = DVec3::splat(1.5 * size);
        let top_layer = f64::from((layers_before.end() + 1) * nebula_voxel::CHUNK_SIZE as i32 + 8);
        let top = up * layout.sphere().layer_radius(top_layer);
        let applied = world
            .apply(&[crate::Edit::Box {
                min: ground.min(top) - half,
                max: ground.max(top) + half,
                voxel: nebula_voxel::Voxel::STONE,
            }])
            .unwrap();
        let layers_after = world.source().surface_chunk_layers(column).unwrap();
        assert!(
            layers_after.end() > layers_before.end(),
            "the tower added no layer: {layers_before:?} -> {layers_after:?}"
        );
        streamer.set_voxels(world.voxels(), &applied.dirty).unwrap();
        let mut frames = 0;
        loop {
            streamer.update(camera, &mut { upload });
            let figures = streamer.figures();
            assert!(
                figures.max_stand_in_levels <= crate::stream::STAND_IN_LEVEL_STEP,
                "frame {frames}: a stand-in {} LODs up",
                figures.max_stand_in_levels
            );
            assert!(
                figures.triangles * 10 >= before * 9,
                "frame {frames}: {} triangles of {before}",
                figures.triangles
            );
            if streamer.settled() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
            frames += 1;
            assert!(frames < 20_000, "did not settle after the edit");
        }
        println!("tower: {frames} frames to settle, {before} -> {} triangles", streamer.figures().triangles);
    }

    /// Every drawn chunk's mesh against a fresh one of its key, made from
    /// `voxels` for the LODs around it it was made for: how many differ.
    fn stale_meshes<S: VoxelSource + 'static>(streamer: &Streamer<S, Sized>, voxels: &S) -> usize {
        let seams = streamer.seam_strategy();
        let mut buffer = nebula_meshing::ChunkMeshBuffer::new();
        streamer
            .drawn()
            .filter(|(key, chunk, _)| {
                let context = crate::seams::mesh_context(key.lod, &chunk.made_for);
                let fresh = nebula_meshing::mesh_chunk(voxels, *key, &context, seams.mesh_options(), &mut buffer)
                    .expect("meshes")
                    .render_mesh();
                chunk.cpu.as_deref() != Some(&fresh)
            })
            .count()
    }

    #[test]
    fn a_turning_view_is_drawn_from_the_plan_before_while_the_next_is_made_and_misses_no_leaf() {
        // The LOD thread made slow (12 ms before each update, tests only)
        // and the camera turning 1° a frame, frames 2 ms apart: frames
        // whose plan is not ready draw the plan before, while its margin
        // covers the camera, instead of waiting. Each frame, the leaves the
        // camera sees (the frame thread's tree culled for it here) that no
        // drawn column covers (the leaf, an ancestor or a descendant) are
        // counted, those the ground's horizon hides aside (left out of the
        // draw list): frames that wait for each plan leave 59 over this
        // turn (under the sea), a draw list drawn past its margin leaves
        // thousands (broken to draw the plan before for any camera:
        // 15,718–17,063).
        let run = |draw_while_planning: bool, serve_any_camera: bool| {
            let world = crate::World::open(PlanetSettings::small(7), None).unwrap();
            let (mut streamer, camera, _) = settled_over_the_ground(&world, 30.0, 0.0, 20);
            let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
            streamer.selection_mut().plan_delay_ms = 12;
            streamer.set_draw_while_planning(draw_while_planning);
            streamer.serve_any_camera = serve_any_camera;
            let before = streamer.frames_drawn_while_planning();
            let mut uncovered = 0;
            for frame in 0..150 {
                let turn = nebula_math::DQuat::from_axis_angle(camera.up.normalize(), f64::from(frame).to_radians());
                let turned = Camera { forward: turn * camera.forward, ..camera };
                streamer.update(turned, &mut { upload });
                let mut tree = streamer.tree().clone();
                tree.cull(&turned).unwrap();
                let drawn: Vec<nebula_voxel::ChunkColumn> =
                    streamer.draw_list().columns.iter().map(|&(column, _)| column).collect();
                let overlaps = |a: nebula_voxel::ChunkColumn, b: nebula_voxel::ChunkColumn| {
                    let (fine, coarse) = if a.lod <= b.lod { (a, b) } else { (b, a) };
                    let up = u32::from(coarse.lod - fine.lod);
                    fine.face == coarse.face && fine.x >> up == coarse.x && fine.y >> up == coarse.y
                };
                let hidden: std::collections::HashSet<nebula_voxel::ChunkColumn> =
                    streamer.draw_list().behind_horizon_leaves.iter().copied().collect();
                uncovered += tree
                    .visible_leaves()
                    .iter()
                    .filter(|&&leaf| !hidden.contains(&leaf) && !drawn.iter().any(|&d| overlaps(d, leaf)))
                    .count();
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            (streamer.frames_drawn_while_planning() - before, uncovered)
        };
        let (waited, waiting) = run(false, false);
        assert_eq!(waited, 0, "frames drew the plan before with drawing while planning off");
        let (drawn_again, uncovered) = run(true, false);
        println!(
            "{drawn_again} of 150 frames drew the plan before; {uncovered} leaves uncovered ({waiting} waiting for each plan)"
        );
        assert!(drawn_again >= 10, "only {drawn_again} of 150 frames drew the plan before while the next was made");
        assert!(uncovered <= 150, "{uncovered} leaves in view uncovered by the draw list over 150 frames");
        let (_, uncovered) = run(true, true);
        println!("drawn for any camera: {uncovered} leaves uncovered");
        assert!(uncovered > 1_500, "the plan before drawn for any camera left only {uncovered} leaves uncovered");
    }

    /// A camera `height` metres over `planet`'s ground at a fixed place and
    /// 60 m to its side, looking at it (seams across LODs in view), and the
    /// LOD settings of a 400-pixel 60° screen.
    fn looking_at_the_ground(planet: &ProceduralPlanet, height: f64) -> (Camera, LodSettings) {
        let up = DVec3::new(0.3, 0.8, 0.5).normalize();
        let ground = planet.surface_point(up);
        let eye = ground + up * height - up.any_orthonormal_vector() * 60.0;
        let camera = Camera { position: eye, forward: ground - eye, up, aspect: 1.6 };
        (camera, LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() })
    }

    #[test]
    fn a_mesh_collected_for_lods_no_longer_drawn_around_it_is_meshed_again_before_the_view_settles() {
        // A constrained chunk's mesh that comes back from a worker made for
        // other LODs around it than those drawn now (the tree moved while
        // it was meshed) must be meshed again: the view is not settled
        // while that seam waits with fallback skirts. The first version
        // dropped the job (the plan's filter of chunks collected this
        // update caught it too) and called such a view settled with a seam
        // waiting, which a CI run saw once.
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
        let (camera, lod) = looking_at_the_ground(&planet, 40.0);
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let mut streamer = Streamer::new(planet, lod, camera, 2, &mut { upload }).unwrap();
        // The next update collects the mesh put in its way (it waits for
        // the LOD thread's plan, not drawing the one before again).
        streamer.set_draw_while_planning(false);
        streamer.keep_cpu_meshes(true);
        streamer.set_seam_strategy(crate::seams::SeamStrategy::Constrained);
        settle_seams(&mut streamer, camera, 20_000);
        let (key, right, mesh) = streamer
            .drawn()
            .find(|(_, chunk, _)| chunk.made_for != crate::seams::SAME_ALL_ROUND)
            .map(|(key, chunk, _)| (key, chunk.made_for, chunk.cpu.as_deref().cloned().expect("kept")))
            .expect("a constrained seam in view");
        let mut wrong = right;
        wrong[0] = match right[0] {
            nebula_lod::NeighborLodRelation::Same => nebula_lod::NeighborLodRelation::LowerThanNeighbor,
            _ => nebula_lod::NeighborLodRelation::Same,
        };
        streamer.finished.push_back(crate::stream::MeshResult {
            key,
            seams: crate::seams::SeamStrategy::Constrained,
            relations: wrong,
            generation: streamer.generation,
            result: Ok(crate::stream::Made::Mesh(Box::new(mesh))),
            millis: 0.0,
        });
        streamer.update(camera, &mut { upload });
        let made_for = |streamer: &Streamer<ProceduralPlanet, Sized>| {
            streamer.drawn().find(|(k, _, _)| *k == key).map(|(_, chunk, _)| chunk.made_for)
        };
        assert_eq!(made_for(&streamer), Some(wrong), "the mesh made for other LODs was not taken: it tests nothing");
        let waiting = streamer.figures().unsettled;
        assert!(waiting > 0, "no seam counted as waiting for {key:?}");
        assert!(!streamer.settled(), "settled with {waiting} columns waiting for their seams");
        settle_seams(&mut streamer, camera, 20_000);
        assert_eq!(made_for(&streamer), Some(right), "{key:?} not meshed again for the LODs drawn around it");
    }

    #[test]
    fn stitched_views_hold_what_their_voxels_and_neighbours_make_after_an_edit_across_a_seam() {
        // A stitched chunk holds the voxels of its coarser neighbour along
        // the seam up to a coarse voxel deep, past its own padding. An edit
        // there (the far-corner voxels the coarse voxels sample, one fine
        // voxel or more beyond the seam) leaves the fine chunk's own voxels
        // alone; once settled, every drawn chunk must still be the mesh its
        // voxels and the LODs around it make.
        let settings = PlanetSettings::small(7);
        let mut world = crate::World::open(settings, None).unwrap();
        let (camera, lod) = looking_at_the_ground(world.source().base(), 200.0);
        let eye = camera.position;
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let mut streamer = Streamer::new(world.voxels(), lod, camera, 2, &mut { upload }).unwrap();
        streamer.keep_cpu_meshes(true);
        streamer.set_seam_strategy(crate::seams::SeamStrategy::Stitched);
        let settle = |streamer: &mut Streamer<_, Sized>| settle_seams(streamer, camera, 20_000);
        settle(&mut streamer);
        assert_eq!(stale_meshes(&streamer, &*world.voxels()), 0, "settled before any edit");
        // The drawn chunk nearest the eye stitched on its +X or +Z side to a
        // coarser column on the same face.
        let layout = *world.source().layout();
        let sphere = *layout.sphere();
        let (key, lod_diff, positive_x) = streamer
            .drawn()
            .filter_map(|(key, chunk, _)| {
                [(0, true), (2, false)].into_iter().find_map(|(index, positive_x)| match chunk.made_for[index] {
                    nebula_lod::NeighborLodRelation::HigherThanNeighbor { lod_diff } => {
                        Some((key, lod_diff, positive_x))
                    }
                    _ => None,
                })
            })
            .filter(|(key, _, positive_x)| {
                let edge = if *positive_x { nebula_math::FaceEdge::PosU } else { nebula_math::FaceEdge::PosV };
                layout.neighbor(*key, edge).face == key.face
            })
            .min_by(|a, b| {
                let distance = |key: &nebula_voxel::ChunkKey| layout.chunk_origin(*key).unwrap().distance(eye);
                distance(&a.0).total_cmp(&distance(&b.0))
            })
            .expect("a stitched seam in view");
        // The coarse voxels across the seam, along the chunk's side, over
        // its height: flip each one's far-corner LOD-0 voxel.
        let span = layout.voxel_span(key.lod);
        let coarse = span << lod_diff;
        let size = 32 * span;
        let seam = i64::from(if positive_x { key.x } else { key.y } + 1) * size;
        let along0 = i64::from(if positive_x { key.y } else { key.x }) * size;
        let bottom = i64::from(key.layer) * size;
        let mut edits = Vec::new();
        for along in (along0..along0 + size).step_by(coarse as usize) {
            for h in (bottom..bottom + size).step_by(coarse as usize) {
                let far = |c: i64| (c / coarse + 1) * coarse - 1;
                let (i, j) = if positive_x { (seam + coarse - 1, far(along)) } else { (far(along), seam + coarse - 1) };
                let at =
                    nebula_voxel::VoxelCoord { face: key.face, lod: 0, i: i as u32, j: j as u32, h: far(h) as i32 };
                let voxel = if world.source().voxel(at).unwrap().is_solid() {
                    nebula_voxel::Voxel::AIR
                } else {
                    nebula_voxel::Voxel::STONE
                };
                edits.push(crate::Edit::Voxel { at, voxel });
            }
        }
        let applied = world.apply(&edits).unwrap();
        assert!(!applied.dirty.contains(&key), "the edit reached the fine chunk's own padding: it tests nothing");
        streamer.set_voxels(world.voxels(), &applied.dirty).unwrap();
        settle(&mut streamer);
        let stale = stale_meshes(&streamer, &*world.voxels());
        println!(
            "{} voxels flipped across the seam of {key:?} ({lod_diff} LODs coarser across, {:.1} m per fine voxel): \
             {stale} stale meshes",
            edits.len(),
            span as f64 * sphere.layer_height()
        );
        assert_eq!(stale, 0, "meshes that no longer match their voxels after the edit");
    }

    #[test]
    fn a_stitched_view_turned_to_draws_what_a_fresh_one_does() {
        // Earth, 1 km over land: held until settled and prefetched, then
        // turned 90 degrees and settled again. Every drawn chunk must be
        // made for the LODs a fresh streamer settled on that view makes it
        // for, with the same mesh: meshes made ahead (prefetching) for the
        // LOD tree's relations, or kept for sides out of view, must not
        // survive where they differ (a mesh kept for a side with nothing
        // drawn across left a wall open above a neighbour culled just
        // under the frustum: one crack pixel after the turn).
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::earth(11)).unwrap());
        let eye = DVec3::new(6_219_094.0, 1_243_818.8, 621_909.4);
        let up = eye.normalize();
        let ahead = DVec3::new(-36.26, 93.18, -1.69);
        let camera = |forward: DVec3| Camera { position: eye, forward, up, aspect: 1.6 };
        let turned = camera(DVec3::new(-26.37, -5.28, 96.32));
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let settle = |streamer: &mut Streamer<ProceduralPlanet, Sized>, camera: Camera, prefetched: bool| {
            for frames in 0.. {
                streamer.update(camera, &mut { upload });
                let done = streamer.settled() && streamer.figures().unsettled == 0;
                if done && (!prefetched || streamer.prefetched()) {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
                assert!(frames < 60_000, "did not settle");
            }
        };
        let drawn = |streamer: &Streamer<ProceduralPlanet, Sized>| -> std::collections::BTreeMap<_, _> {
            streamer
                .drawn()
                .map(|(key, chunk, draw)| {
                    (key, (chunk.made_for, chunk.cpu.as_deref().cloned().unwrap_or_default(), draw.skirt_depths))
                })
                .collect()
        };
        let mut streamer = Streamer::new(planet.clone(), lod, camera(ahead), 2, &mut { upload }).unwrap();
        streamer.keep_cpu_meshes(true);
        streamer.set_seam_strategy(crate::seams::SeamStrategy::Stitched);
        settle(&mut streamer, camera(ahead), true);
        settle(&mut streamer, turned, false);
        let mut fresh = Streamer::new(planet.clone(), lod, turned, 2, &mut { upload }).unwrap();
        fresh.keep_cpu_meshes(true);
        fresh.set_seam_strategy(crate::seams::SeamStrategy::Stitched);
        settle(&mut fresh, turned, false);
        let (after, expected) = (drawn(&streamer), drawn(&fresh));
        let differ: Vec<_> =
            expected.iter().filter(|(key, v)| after.get(key) != Some(v)).map(|(key, _)| *key).collect();
        println!("turned: {} chunks drawn, {} differ from a fresh view", after.len(), differ.len());
        assert_eq!(after.len(), expected.len(), "other chunks drawn");
        assert!(differ.is_empty(), "drawn otherwise than a fresh view: {:?}", &differ[..differ.len().min(6)]);
    }

    #[test]
    fn the_grounds_horizon_settles_on_one_view_whatever_came_first() {
        // Random poses over Earth's land, 100 m to 1.5 km up, looking a few
        // degrees down (the ground in front hides much there), with far
        // tops slow to sample (a few hundred come a plan): a view is
        // settled only once every top it waits for has come, so it then
        // draws what it draws once no top is left to sample (settled
        // before them, it went on to hide more). And a
        // view settled without the horizon (every leaf meshed), then with
        // it, draws the same: a leaf meshed before the ground in front hid
        // it adds nothing to that ground. Settled, what the ground hides is
        // not drawn at all.
        let slow = |planet: ProceduralPlanet| Flaky {
            planet,
            panics: AtomicUsize::new(0),
            at_roots: false,
            bounds_panics: AtomicUsize::new(0),
            top_delay: std::time::Duration::from_millis(2),
            tops: AtomicUsize::new(0),
        };
        let earth = ProceduralPlanet::new(PlanetSettings::earth(5)).unwrap();
        let poses = land_poses(&earth, 0x25, 2, (100.0, 1_500.0), (1.0, 7.0));
        let planet = Arc::new(slow(earth));
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        type Drawn = std::collections::BTreeMap<nebula_voxel::ChunkKey, [nebula_lod::NeighborLodRelation; 4]>;
        let drawn = |streamer: &Streamer<Flaky, Sized>| {
            streamer.drawn().map(|(key, chunk, _)| (key, chunk.made_for)).collect::<Drawn>()
        };
        let settle = |streamer: &mut Streamer<Flaky, Sized>, camera: Camera| {
            settle_seams(streamer, camera, 60_000);
            drawn(streamer)
        };
        let differ = |a: &Drawn, b: &Drawn| {
            a.iter().filter(|&(key, made_for)| b.get(key) != Some(made_for)).count()
                + b.keys().filter(|&key| !a.contains_key(key)).count()
        };
        for (n, &(eye, forward)) in poses.iter().enumerate() {
            let camera = Camera { position: eye, forward, up: eye.normalize(), aspect: 1.6 };
            let mut fresh = Streamer::new(planet.clone(), lod, camera, 2, &mut { upload }).unwrap();
            let settled = settle(&mut fresh, camera);
            let hidden = fresh.draw_list().behind_horizon;
            // Settled (no stand-in drawn), nothing is drawn for the hidden
            // leaves: every column drawn is a leaf of the tree (no
            // sea here), and no backstop is drawn.
            let leaves: std::collections::HashSet<_> = fresh.tree().leaf_columns().collect();
            let not_leaves = settled.keys().filter(|key| !leaves.contains(&key.column())).count();
            assert_eq!((not_leaves, fresh.draw_list().backstops), (0, 0), "pose {n}: hidden ground drawn settled");
            // On until no top has come for a second.
            let (mut tops, mut since) = (planet.tops.load(Ordering::SeqCst), std::time::Instant::now());
            while since.elapsed().as_secs_f64() < 1.0 {
                fresh.update(camera, &mut { upload });
                std::thread::sleep(std::time::Duration::from_millis(2));
                let now = planet.tops.load(Ordering::SeqCst);
                if now != tops {
                    (tops, since) = (now, std::time::Instant::now());
                }
            }
            let later = drawn(&fresh);
            let mut meshed_first = Streamer::new(planet.clone(), lod, camera, 2, &mut { upload }).unwrap();
            meshed_first
                .set_draw_options(crate::stream::DrawOptions { terrain_occlusion: false, ..Default::default() });
            let everything = settle(&mut meshed_first, camera);
            meshed_first.set_draw_options(crate::stream::DrawOptions::default());
            let after = settle(&mut meshed_first, camera);
            println!(
                "pose {n}: {} chunks drawn settled ({hidden} leaves hidden, {tops} tops sampled), {} differ once \
                 no top is left; {} drawn without the horizon, {} differ after meshing those first",
                settled.len(),
                differ(&settled, &later),
                everything.len(),
                differ(&settled, &after),
            );
            assert!(hidden > 0 && settled.len() < everything.len(), "pose {n}: the ground hides nothing here");
            assert_eq!(differ(&settled, &later), 0, "pose {n}: settled before its last tops came");
            assert_eq!(differ(&settled, &after), 0, "pose {n}: a view that meshed everything first settles on others");
        }
    }

    #[test]
    fn hidden_ground_is_drawn_only_while_a_stand_in_covers_what_hides_it() {
        // Earth's land, looking a few degrees down from low (the ground in
        // front hides much), with every chunk of an even `x` failing to
        // fill for a while: leaves wait for meshes, so meshed ancestors
        // stand in for them over meshed leaves whose floors the ground's
        // horizon took. The hidden columns meshed are drawn as backstops
        // then (a stand-in may dip under those floors), and once every
        // failure has been retried the view settles on what a view that
        // never failed draws, no backstop drawn. Without the backstops
        // (the count stays 0) this fails.
        let earth = ProceduralPlanet::new(PlanetSettings::earth(5)).unwrap();
        let poses = land_poses(&earth, 0x25, 1, (100.0, 1_500.0), (1.0, 7.0));
        let flaky = |panics: usize| {
            Arc::new(Flaky {
                planet: earth.clone(),
                panics: AtomicUsize::new(panics),
                at_roots: false,
                bounds_panics: AtomicUsize::new(0),
                top_delay: std::time::Duration::ZERO,
                tops: AtomicUsize::new(0),
            })
        };
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let drawn = |streamer: &Streamer<Flaky, Sized>| streamer.drawn().map(|(key, _, _)| key).collect::<Vec<_>>();
        let (eye, forward) = poses[0];
        let camera = Camera { position: eye, forward, up: eye.normalize(), aspect: 1.6 };
        let mut sound = Streamer::new(flaky(0), lod, camera, 2, &mut { upload }).unwrap();
        settle_seams(&mut sound, camera, 60_000);
        let mut failing = Streamer::new(flaky(3_000), lod, camera, 2, &mut { upload }).unwrap();
        let (mut frames_with_backstops, mut most) = (0, 0);
        for _ in 0..20_000 {
            failing.update(camera, &mut { upload });
            let backstops = failing.draw_list().backstops;
            if backstops > 0 {
                frames_with_backstops += 1;
                most = most.max(backstops);
            }
            if failing.settled() && failing.prefetched() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        settle_seams(&mut failing, camera, 60_000);
        println!(
            "{frames_with_backstops} frames drew backstops (up to {most}); settled: {} chunks, {} without failures, \
             {} leaves hidden",
            drawn(&failing).len(),
            drawn(&sound).len(),
            failing.draw_list().behind_horizon
        );
        assert!(frames_with_backstops > 0, "no backstop drawn while stand-ins covered the ground in front");
        assert_eq!(failing.draw_list().backstops, 0, "backstops drawn once settled");
        assert_eq!(drawn(&failing), drawn(&sound), "settled on another view after the failures");
    }

    /// The small planet, whose chunks with an even `x` panic when filled
    /// while `panics` lasts (a game's voxel source with a bug).
    struct Flaky {
        planet: ProceduralPlanet,
        panics: AtomicUsize,
        /// Panic at the face roots too.
        at_roots: bool,
        /// Panics left in `surface_bounds` (what the LOD tree asks on the
        /// frame thread), for columns with an even `x` below the roots.
        bounds_panics: AtomicUsize,
        /// How long sampling a tight top takes, and the tops sampled.
        top_delay: std::time::Duration,
        tops: AtomicUsize,
    }

    impl Flaky {
        /// Panics while `bounds_panics` lasts, for columns with an even
        /// `x` below the roots.
        fn bounds_bug(&self, column: nebula_voxel::ChunkColumn) {
            if column.lod < self.planet.layout().max_lod()
                && column.x.is_multiple_of(2)
                && self.bounds_panics.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| n.checked_sub(1)).is_ok()
            {
                panic!("a bug in the game's surface bounds");
            }
        }
    }

    impl VoxelSource for Flaky {
        fn layout(&self) -> &nebula_voxel::ChunkLayout {
            self.planet.layout()
        }
        fn voxel(&self, at: nebula_voxel::VoxelCoord) -> Result<nebula_voxel::Voxel, nebula_voxel::VoxelError> {
            self.planet.voxel(at)
        }
        fn fill_chunk(
            &self,
            key: nebula_voxel::ChunkKey,
            out: &mut nebula_voxel::ChunkVoxels,
        ) -> Result<(), nebula_voxel::VoxelError> {
            let root = key.lod == self.planet.layout().max_lod();
            assert!(!(root && self.at_roots), "a bug in the game's voxel source at a root");
            if !root
                && key.x.is_multiple_of(2)
                && self.panics.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| n.checked_sub(1)).is_ok()
            {
                panic!("a bug in the game's voxel source");
            }
            self.planet.fill_chunk(key, out)
        }
        fn surface_bounds(
            &self,
            column: nebula_voxel::ChunkColumn,
        ) -> Result<nebula_voxel::SurfaceBounds, nebula_voxel::VoxelError> {
            self.bounds_bug(column);
            self.planet.surface_bounds(column)
        }
        // The planet's layers and views, so that a view of it draws what
        // one of the planet itself does (the trait's defaults mesh every
        // layer, sealed caves included).
        fn layer_view(&self, eye: DVec3) -> LayerView {
            self.planet.layer_view(eye)
        }
        fn surface_chunk_layers_seen(
            &self,
            column: nebula_voxel::ChunkColumn,
            view: LayerView,
        ) -> Result<std::ops::RangeInclusive<i32>, nebula_voxel::VoxelError> {
            self.bounds_bug(column);
            self.planet.surface_chunk_layers_seen(column, view)
        }
        fn surface_survey(
            &self,
            column: nebula_voxel::ChunkColumn,
        ) -> Result<nebula_voxel::SurfaceSurvey, nebula_voxel::VoxelError> {
            self.bounds_bug(column);
            self.planet.surface_survey(column)
        }
        fn surface_top_radius(&self, column: nebula_voxel::ChunkColumn) -> Result<f64, nebula_voxel::VoxelError> {
            std::thread::sleep(self.top_delay);
            self.tops.fetch_add(1, Ordering::SeqCst);
            self.planet.surface_top_radius(column)
        }
        fn geometric_error(&self, lod: u8) -> f64 {
            self.planet.geometric_error(lod)
        }
        fn lowest_surface_radius(&self) -> Option<f64> {
            self.planet.lowest_surface_radius()
        }
    }

    #[test]
    fn a_panicking_voxel_source_fails_chunks_not_the_game() {
        // 40 panics in the game's fill_chunk: each failing chunk is
        // reported once, drawn through its stand-in meanwhile (no hole in
        // any frame, nothing drawn empty), retried with backoff, and the
        // view settles to the same triangles as with a source that never
        // panics. Without the catch, rayon aborts the process here.
        let planet = || ProceduralPlanet::new(PlanetSettings::small(7)).unwrap();
        let up = DVec3::new(0.2, 0.9, 0.3).normalize();
        let ground = planet().surface_point(up);
        let eye = ground + up * 60.0;
        let camera = Camera { position: eye, forward: up.any_orthonormal_vector() - up * 0.3, up, aspect: 1.6 };
        let lod = LodSettings { screen_height_px: 400.0, fov_y_degrees: 60.0, ..LodSettings::default() };
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        // What a settled view draws: each chunk with its surface
        // triangles, sorted.
        fn settle<S: VoxelSource + 'static>(
            streamer: &mut Streamer<S, Sized>,
            camera: Camera,
        ) -> Vec<(nebula_voxel::ChunkKey, u32)> {
            let mut upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
            for frames in 0.. {
                streamer.update(camera, &mut upload);
                assert_eq!(streamer.draw_list().holes, 0, "frame {frames}: a hole");
                if streamer.settled() {
                    let mut drawn: Vec<_> =
                        streamer.drawn().map(|(key, chunk, _)| (key, chunk.surface_triangles.iter().sum())).collect();
                    drawn.sort_unstable();
                    return drawn;
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
                assert!(frames < 20_000, "did not settle");
            }
            unreachable!()
        }
        // A panic meshing a face root (before the first frame) is an error
        // of Streamer::new, not a panic in the game.
        let refused = Streamer::new(
            Arc::new(Flaky {
                planet: planet(),
                panics: AtomicUsize::new(0),
                at_roots: true,
                bounds_panics: AtomicUsize::new(0),
                top_delay: std::time::Duration::ZERO,
                tops: AtomicUsize::new(0),
            }),
            lod,
            camera,
            2,
            &mut { upload },
        );
        assert!(matches!(&refused, Err(crate::stream::StreamError::Panicked { .. })), "{:?}", refused.err());
        // Panics in the bounds the LOD tree asks for (its survey, or a
        // column's layers) on the frame thread too: the update fails, the
        // tree starts again from its roots.
        let flaky = Arc::new(Flaky {
            planet: planet(),
            panics: AtomicUsize::new(40),
            at_roots: false,
            bounds_panics: AtomicUsize::new(3),
            top_delay: std::time::Duration::ZERO,
            tops: AtomicUsize::new(0),
        });
        let mut streamer = Streamer::new(flaky.clone(), lod, camera, 2, &mut { upload }).unwrap();
        // Both views compared are planned on the frame thread: a plan the
        // LOD thread made ahead for a camera standing still has a margin
        // (1 m, 3°) for the camera that comes, and so draws a few leaves
        // just off screen and hides a few fewer behind the horizons than a
        // plan made for the camera itself. Which of the two made the
        // settled frame is timing's, so their lists of chunks differ now
        // and then (seen in CI: 291 triangles; the same picture).
        streamer.set_lod_thread(false);
        let drawn = settle(&mut streamer, camera);
        assert_eq!(flaky.panics.load(Ordering::SeqCst), 0, "the source never panicked: the check cannot tell");
        assert_eq!(flaky.bounds_panics.load(Ordering::SeqCst), 0, "the bounds never panicked");
        assert_eq!(streamer.lod_failures(), 3);
        let failures = streamer.take_mesh_failures();
        assert!(
            !failures.is_empty() && failures.iter().all(|f| f.message.contains("a bug in the game's voxel source"))
        );
        let mut keys: Vec<_> = failures.iter().map(|f| f.key).collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), failures.len(), "a chunk was reported twice");
        // Prefetching out of view retries its own failures too.
        for frames in 0.. {
            if streamer.prefetched() && streamer.failing_chunks() == 0 {
                break;
            }
            streamer.update(camera, &mut { upload });
            std::thread::sleep(std::time::Duration::from_millis(2));
            assert!(frames < 20_000, "{} chunks still failing", streamer.failing_chunks());
        }
        let plain = Arc::new(planet());
        let mut reference = Streamer::new(plain, lod, camera, 2, &mut { upload }).unwrap();
        reference.set_lod_thread(false);
        let expected = settle(&mut reference, camera);
        // The chunks drawn differently, if any.
        let differ: Vec<_> = drawn
            .iter()
            .filter(|d| !expected.contains(d))
            .map(|d| format!("+{d:?}"))
            .chain(expected.iter().filter(|e| !drawn.contains(e)).map(|e| format!("-{e:?}")))
            .collect();
        assert!(differ.is_empty(), "failed chunks are drawn other than they should be: {differ:?}");
        println!(
            "40 panics in {} chunks: reported once each, retried, settled at {} chunks",
            failures.len(),
            drawn.len()
        );
    }

    #[cfg(feature = "bevy")]
    #[test]
    fn the_ecs_system_applies_a_changed_view() {
        use crate::ecs::{PlanetStream, StreamView, insert_planet, stream_system};
        use bevy_ecs::prelude::{Schedule, World};
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
        let up = DVec3::Y;
        let camera = Camera { position: planet.surface_point(up) + up * 50.0, forward: DVec3::X - up, up, aspect: 1.6 };
        let lod = LodSettings { screen_height_px: 400.0, ..LodSettings::default() };
        let upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let streamer = Streamer::new(planet, lod, camera, 1, &mut { upload }).unwrap();
        let mut world = World::new();
        insert_planet(&mut world, streamer, camera, upload);
        let mut schedule = Schedule::default();
        schedule.add_systems(stream_system::<ProceduralPlanet, Sized>);
        schedule.run(&mut world);
        let fov =
            |world: &World| world.resource::<PlanetStream<ProceduralPlanet, Sized>>().0.tree().settings().fov_y_degrees;
        assert_eq!(fov(&world), 60.0);
        world.insert_resource(StreamView { threshold_px: 1.0, screen_height_px: 800.0, fov_y_degrees: 20.0 });
        schedule.run(&mut world);
        assert_eq!(fov(&world), 20.0, "a zoom did not reach the LOD tree");
        let settings = *world.resource::<PlanetStream<ProceduralPlanet, Sized>>().0.tree().settings();
        assert_eq!(settings.screen_height_px, 800.0);
    }

    #[test]
    fn uploads_per_frame_stay_within_their_byte_budget() {
        // 256 KiB a frame: a cold start on the small planet (megabytes of
        // meshes finishing at once) is spread over frames, each within the
        // budget or a single mesh, and the view still settles.
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
        let up = DVec3::new(0.5, 0.5, 0.7).normalize();
        let position = planet.surface_point(up) + up * 40.0;
        let camera = Camera { position, forward: up.any_orthonormal_vector() - up * 0.2, up, aspect: 1.6 };
        let lod = LodSettings { screen_height_px: 400.0, ..LodSettings::default() };
        let frame = std::sync::Mutex::new((0u64, 0u64));
        let mut upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| {
            let mut f = frame.lock().unwrap();
            f.0 += mesh.bytes();
            f.1 = f.1.max(mesh.bytes());
            Sized(mesh.bytes())
        };
        let mut streamer = Streamer::new(planet, lod, camera, 2, &mut upload).unwrap();
        let budget = 256 << 10;
        streamer.cache.max_upload_bytes = budget;
        let (mut fullest, mut frames) = (0, 0);
        *frame.lock().unwrap() = (0, 0);
        loop {
            streamer.update(camera, &mut upload);
            let (bytes, largest) = std::mem::take(&mut *frame.lock().unwrap());
            assert_eq!(bytes, streamer.figures().times.upload_bytes);
            assert!(bytes <= budget.max(largest), "frame {frames}: {bytes} bytes uploaded, budget {budget}");
            fullest = fullest.max(bytes);
            if streamer.settled() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
            frames += 1;
            assert!(frames < 20_000, "did not settle");
        }
        assert!(fullest > budget / 2, "the budget was never approached ({fullest} bytes): the check cannot tell");
        println!("uploads: at most {fullest} bytes a frame of {budget}, settled after {frames} frames");
    }

    #[test]
    fn meshing_threads_upload_what_they_make_when_given_an_uploader() {
        // With an uploader every mesh after the face roots is uploaded on
        // a meshing thread and the frame's mesh maker is never called; the
        // view settles to the same triangles as with uploads on the frame
        // thread, and the meshes it frees are freed alike.
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
        let up = DVec3::new(0.5, 0.5, 0.7).normalize();
        let position = planet.surface_point(up) + up * 40.0;
        let camera = Camera { position, forward: up.any_orthonormal_vector() - up * 0.2, up, aspect: 1.6 };
        let lod = LodSettings { screen_height_px: 400.0, ..LodSettings::default() };
        let settle = |on_workers: bool| {
            let live = Arc::new(AtomicUsize::new(0));
            let made = |live: &Arc<AtomicUsize>, mesh: &nebula_meshing::RenderMesh| {
                live.fetch_add(1, Ordering::SeqCst);
                Counted { bytes: mesh.bytes(), live: live.clone() }
            };
            let frame_uploads = AtomicUsize::new(0);
            let mut upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| {
                frame_uploads.fetch_add(1, Ordering::SeqCst);
                made(&live, mesh)
            };
            let mut streamer = Streamer::new(planet.clone(), lod, camera, 2, &mut upload).unwrap();
            let roots = frame_uploads.swap(0, Ordering::SeqCst);
            let on_mesh_threads = Arc::new(AtomicUsize::new(0));
            if on_workers {
                let (live, on_mesh_threads) = (live.clone(), on_mesh_threads.clone());
                streamer.set_uploader(Some(Arc::new(move |_key, mesh| {
                    let name = std::thread::current().name().unwrap_or_default().to_owned();
                    assert!(name.starts_with("nebula-mesh"), "uploaded on {name}");
                    on_mesh_threads.fetch_add(1, Ordering::SeqCst);
                    made(&live, mesh)
                })));
            }
            for frames in 0.. {
                streamer.update(camera, &mut upload);
                assert_eq!(streamer.draw_list().holes, 0);
                if streamer.settled() {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
                assert!(frames < 20_000, "did not settle");
            }
            let held = streamer.cache.chunks();
            let triangles = streamer.figures().triangles;
            let counts = (frame_uploads.load(Ordering::SeqCst), on_mesh_threads.load(Ordering::SeqCst));
            drop(streamer);
            // A worker still on a prefetch job drops what it made when it
            // finds the streamer gone.
            let start = std::time::Instant::now();
            while live.load(Ordering::SeqCst) > 0 && start.elapsed().as_secs() < 5 {
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
            (roots, counts, held, triangles, live.load(Ordering::SeqCst))
        };
        let (roots, (frame, workers), held, triangles, left) = settle(true);
        println!("uploader: {roots} roots, then {frame} uploads on the frame thread and {workers} on meshing threads");
        assert!(roots >= 6);
        assert_eq!(frame, 0, "the frame thread uploaded meshes");
        assert!(workers >= held - roots, "{workers} uploads for {held} chunks held");
        assert_eq!(left, 0, "handles outlived the streamer");
        let (_, (frame, workers), _, control, _) = settle(false);
        assert!(frame > 0 && workers == 0, "without an uploader the frame thread uploads");
        assert_eq!(triangles, control, "a different view with the uploader");
    }

    /// The niceness of each thread of this process named `prefix…`, and
    /// of the calling thread (Linux: field 19 of `/proc/self/task/*/stat`).
    #[cfg(target_os = "linux")]
    fn niceness(prefix: &str) -> (Vec<i64>, i64) {
        let nice = |dir: &std::path::Path| {
            let stat = std::fs::read_to_string(dir.join("stat")).ok()?;
            // After the name in parentheses: state is field 3, nice 19.
            stat.rsplit_once(')')?.1.split_whitespace().nth(16)?.parse::<i64>().ok()
        };
        let threads = std::fs::read_dir("/proc/self/task")
            .unwrap()
            .filter_map(|entry| {
                let dir = entry.ok()?.path();
                let name = std::fs::read_to_string(dir.join("comm")).ok()?;
                if name.starts_with(prefix) { nice(&dir) } else { None }
            })
            .collect();
        (threads, nice(std::path::Path::new("/proc/thread-self")).unwrap())
    }

    #[test]
    #[cfg(target_os = "linux")]
    fn meshing_threads_run_below_the_frame_threads_priority() {
        // The frame thread must not wait for a core while chunks mesh: the
        // streamer's meshing threads run at a lower priority (a higher
        // niceness) than the thread that made it.
        let planet = Arc::new(ProceduralPlanet::new(PlanetSettings::small(7)).unwrap());
        let up = DVec3::new(0.5, 0.5, 0.7).normalize();
        let position = planet.surface_point(up) + up * 40.0;
        let camera = Camera { position, forward: up.any_orthonormal_vector() - up * 0.2, up, aspect: 1.6 };
        let mut upload = |_key: nebula_voxel::ChunkKey, mesh: &nebula_meshing::RenderMesh| Sized(mesh.bytes());
        let _streamer = Streamer::new(planet, LodSettings::default(), camera, 2, &mut upload).unwrap();
        // The threads set their priority as they start.
        let start = std::time::Instant::now();
        loop {
            let (meshing, own) = niceness("nebula-mesh");
            if meshing.len() >= 2 && meshing.iter().all(|&n| n > own) {
                return;
            }
            assert!(
                start.elapsed().as_secs() < 10,
                "meshing threads' niceness {meshing:?}, the frame thread's {own}: not below it"
            );
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }
}

/// Faces looking down (ceilings, overhangs' undersides) are left out only
/// where the eye is behind every one of them (`ColumnSides::facing`):
/// over random Earth columns with such faces (LODs 0–2, caves on) and
/// random eyes from under the ground to 2 km up, each column whose
/// faces looking down are hidden has every such triangle facing away from
/// the eye. Control: with the column's top taken 80 m too low, some hidden
/// triangle faces the eye.
mod back_sides {
    use nebula_lod::NodeBounds;
    use nebula_meshing::{ChunkLodContext, ChunkMeshBuffer, FaceDirection, MeshOptions, mesh_chunk};
    use nebula_voxel::{ChunkColumn, DVec3, PlanetSettings, ProceduralPlanet, VoxelSource};

    use super::unit;
    use crate::stream::{ColumnSides, SLIVER_PX, WallScale};
    use nebula_math::ScreenSpace;
    use nebula_meshing::{ChunkDraw, FrameDraw, SURFACE_PARTS};

    /// A random direction and the column of a random LOD under `lods`
    /// holding the ground there.
    fn random_surface_column(earth: &ProceduralPlanet, lods: u8, state: &mut u64) -> (DVec3, ChunkColumn) {
        let layout = earth.layout();
        let direction = DVec3::new(unit(state) - 0.5, unit(state) - 0.5, unit(state) - 0.5).normalize();
        let lod = (unit(state) * f64::from(lods)) as u8;
        let ground = direction * (layout.sphere().radius() + earth.height_at(direction));
        let mut at = layout.voxel_at(ground).expect("on the planet");
        while at.lod < lod {
            at = at.parent().expect("a parent");
        }
        (direction, layout.chunk_of(at).column())
    }

    /// The radius of the top of `column`'s layer `top_layer`, its bounds
    /// and its sides.
    fn column_sides(earth: &ProceduralPlanet, column: ChunkColumn, top_layer: i32) -> (f64, NodeBounds, ColumnSides) {
        let layout = earth.layout();
        let layer_top = (i64::from(top_layer) + 1) * 32 * layout.voxel_span(column.lod);
        let top = layout.sphere().layer_radius(layer_top as f64);
        let bounds = NodeBounds::new(layout, column, &earth.surface_bounds(column).expect("bounds"));
        let sides = ColumnSides::of(layout, column, Some(&bounds));
        (top, bounds, sides)
    }

    #[test]
    fn faces_looking_down_are_hidden_only_behind_the_eye() {
        let earth = ProceduralPlanet::new(PlanetSettings::earth(3)).expect("earth");
        let layout = *earth.layout();
        let radius = layout.sphere().radius();
        let mut state = 0xd0_u64;
        let mut buffer = ChunkMeshBuffer::new();
        let (mut columns, mut hidden, mut shown, mut wrong, mut control_wrong) = (0, 0, 0, 0, 0);
        for _ in 0..4_000 {
            if columns >= 12 {
                break;
            }
            let (direction, column) = random_surface_column(&earth, 3, &mut state);
            let lod = column.lod;
            let layers = earth.surface_chunk_layers(column).expect("layers");
            let top_layer = *layers.end();
            // Triangles looking down: three world corners each.
            let mut down: Vec<[DVec3; 3]> = Vec::new();
            for layer in layers {
                let key = column.chunk(layer);
                let mesh = mesh_chunk(&earth, key, &ChunkLodContext::uniform(lod), MeshOptions::STREAMING, &mut buffer)
                    .expect("meshes");
                let range = mesh.surface_side_ranges()[FaceDirection::NegY as usize].clone();
                for triangle in mesh.indices()[range].chunks_exact(3) {
                    down.push([0, 1, 2].map(|k| mesh.world_position(triangle[k] as usize).expect("vertex")));
                }
            }
            if down.is_empty() {
                continue;
            }
            columns += 1;
            let (top, _, sides) = column_sides(&earth, column, top_layer);
            let faces_eye = |eye: DVec3| down.iter().any(|[a, b, c]| (eye - *a).dot((*b - *a).cross(*c - *a)) > 0.0);
            let ground = radius + earth.height_at(direction);
            for _ in 0..40 {
                let along = DVec3::new(unit(&mut state) - 0.5, unit(&mut state) - 0.5, unit(&mut state) - 0.5);
                let around = (direction + along * (3_000.0 / radius)).normalize();
                let eye = around * (ground + (unit(&mut state) * 2_050.0 - 50.0));
                let scale = WallScale {
                    eye,
                    screen: ScreenSpace::new(720.0, 60.0, 1.0).expect("screen"),
                    morph: false,
                    voxel_edge: layout.voxel_edge(lod),
                    parent_error: layout.merge_error(lod),
                };
                let is_hidden =
                    |top: f64| sides.facing(&scale, Some(top)).hidden & (1 << FaceDirection::NegY as u8) != 0;
                if is_hidden(top) {
                    hidden += 1;
                    wrong += usize::from(faces_eye(eye));
                } else {
                    shown += 1;
                }
                if is_hidden(top - 80.0) && faces_eye(eye) {
                    control_wrong += 1;
                }
            }
        }
        println!(
            "{columns} columns with faces looking down: {hidden} eyes hide them, {shown} do not; {wrong} hidden \
             wrongly; with the top 80 m too low {control_wrong}"
        );
        assert!(columns >= 12 && hidden > 0 && shown > 0, "{columns} columns, {hidden} hidden, {shown} shown");
        assert_eq!(wrong, 0);
        assert!(control_wrong > 0, "the check should catch a top taken too low");
    }

    /// A wall is left out only where it looks at least [`SLIVER_PX`] wide
    /// on screen (`ColumnSides::facing`): left out, the faces either side
    /// of it meet unshared, overlapping by that width, and a narrower one
    /// lets the rasteriser's rounding open a pinhole (a random view 3 km up
    /// had one). Over random Earth columns (LODs 0–4) and eyes around them
    /// from 5° to 80° up, at distances across the morph band (μ from 0 to
    /// 1), every triangle of a wall part left out (the faces the morph
    /// keeps a voxel tall, or flattens), placed as the vertex shader places
    /// it, keeps its lone corner (the one on the other layer) at least half
    /// of `SLIVER_PX` from the line of its other two, across the wall's
    /// edges as they lie unmorphed, on a 720-pixel, 60° screen. Control:
    /// the rule before it (left out a millimetre behind every wall's plane)
    /// leaves thinner ones out.
    #[test]
    fn walls_left_out_look_wide_enough_on_screen() {
        let earth = ProceduralPlanet::new(PlanetSettings::earth(3)).expect("earth");
        let layout = *earth.layout();
        let screen = ScreenSpace::new(720.0, 60.0, 1.0).expect("screen");
        let k = screen.k();
        let mut state = 0x511e_u64;
        let mut buffer = ChunkMeshBuffer::new();
        let (mut columns, mut tested, mut thin, mut control_thin, mut narrowest) = (0, 0, 0, 0, f64::INFINITY);
        let walls = FaceDirection::HORIZONTAL;
        while columns < 10 {
            let (_, column) = random_surface_column(&earth, 5, &mut state);
            let lod = column.lod;
            let layers = earth.surface_chunk_layers(column).expect("layers");
            let top_layer = *layers.end();
            let meshes: Vec<_> = layers
                .map(|layer| {
                    let key = column.chunk(layer);
                    mesh_chunk(&earth, key, &ChunkLodContext::uniform(lod), MeshOptions::STREAMING, &mut buffer)
                        .expect("meshes")
                })
                .collect();
            if meshes.iter().all(|mesh| walls.iter().all(|&side| mesh.surface_side_ranges()[side as usize].is_empty()))
            {
                continue;
            }
            columns += 1;
            let (top, bounds, sides) = column_sides(&earth, column, top_layer);
            let centre = (bounds.min + bounds.max) / 2.0;
            let parent_error = layout.merge_error(lod);
            let draw = ChunkDraw::new(parent_error, [0.0; 4]);
            let vertices: Vec<_> = meshes.iter().map(|mesh| mesh.render_vertices()).collect();
            for _ in 0..60 {
                // ρ_p/τ from 0.9 (μ = 0) to 1.6 (μ = 1).
                let distance = parent_error * k / (0.9 + 0.7 * unit(&mut state));
                let up = centre.normalize();
                let tangent = up.any_orthonormal_vector();
                let heading = unit(&mut state) * std::f64::consts::TAU;
                let across = tangent * heading.cos() + up.cross(tangent) * heading.sin();
                let elevation = (5.0 + 75.0 * unit(&mut state)).to_radians();
                let eye = centre + (up * elevation.sin() + across * elevation.cos()) * distance;
                let forward = (centre - eye).normalize();
                let right = forward.cross(up).normalize();
                let screen_up = right.cross(forward);
                let frame = FrameDraw::new(eye, k, 1.0, true);
                let unmorphed = FrameDraw::new(eye, k, 1.0, false);
                let project = |p: DVec3| {
                    let depth = p.dot(forward);
                    (depth > 0.0).then(|| [p.dot(right) * k / depth, p.dot(screen_up) * k / depth])
                };
                let scale = WallScale { eye, screen, morph: true, voxel_edge: layout.voxel_edge(lod), parent_error };
                // The old rule: a millimetre behind every plane is enough.
                let old = WallScale { voxel_edge: 1e12, morph: false, ..scale };
                for (rule, scale) in [(0, scale), (1, old)] {
                    let facing = sides.facing(&scale, Some(top));
                    let drawn =
                        ChunkDraw { hidden_sides: facing.hidden, hidden_flattening: facing.hidden_flattening, ..draw }
                            .drawn_parts();
                    // The walls' parts: sides 0–3 and their flattening
                    // faces, 6–9.
                    let hidden = (0..SURFACE_PARTS).filter(|&part| part % 6 < 4 && drawn & (1 << part) == 0);
                    for (mesh, vertices) in meshes.iter().zip(&vertices) {
                        for part in hidden.clone() {
                            let range = mesh.surface_parts()[part].clone();
                            for triangle in mesh.indices()[range].chunks_exact(3) {
                                let radii = [0, 1, 2]
                                    .map(|c| mesh.world_position(triangle[c] as usize).expect("vertex").length());
                                // The corner alone on its layer (a wall's
                                // triangle has two on one layer).
                                let Some(lone) = (0..3).find(|&c| {
                                    let (a, b) = (radii[(c + 1) % 3], radii[(c + 2) % 3]);
                                    (a - b).abs() < 1e-3 && (radii[c] - a).abs() > 1e-3
                                }) else {
                                    continue;
                                };
                                let placed = [0, 1, 2]
                                    .map(|c| project(vertices[triangle[c] as usize].drawn_relative(&frame, &draw)));
                                let [Some(p), Some(a)] = [placed[lone], placed[(lone + 1) % 3]] else {
                                    continue;
                                };
                                // Along the wall's edges as they lie unmorphed (the pair
                                // may morph onto one point: the wall shrinks along its
                                // length, which opens no sliver between its edges).
                                let [Some(a1), Some(b1)] = [(lone + 1) % 3, (lone + 2) % 3]
                                    .map(|c| project(vertices[triangle[c] as usize].drawn_relative(&unmorphed, &draw)))
                                else {
                                    continue;
                                };
                                let (edge, to) = ([b1[0] - a1[0], b1[1] - a1[1]], [p[0] - a[0], p[1] - a[1]]);
                                let width = (edge[0] * to[1] - edge[1] * to[0]).abs() / edge[0].hypot(edge[1]);
                                if rule == 0 {
                                    tested += 1;
                                    narrowest = narrowest.min(width);
                                    thin += usize::from(width < SLIVER_PX / 2.0);
                                } else {
                                    control_thin += usize::from(width < SLIVER_PX / 2.0);
                                }
                            }
                        }
                    }
                }
            }
        }
        println!(
            "{columns} columns: {tested} wall triangles left out, the narrowest {narrowest:.4} px wide, {thin} under \
             {:.4} px; the old rule leaves out {control_thin} under it",
            SLIVER_PX / 2.0
        );
        assert!(tested > 1_000, "too few walls left out to tell: {tested}");
        assert_eq!(thin, 0, "walls narrower than the rounding left out");
        assert!(control_thin > 0, "the check should catch the old rule");
    }
}
