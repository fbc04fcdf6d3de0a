//! Saved worlds: reopening, corruption, wrong versions, other planets.

use std::path::{Path, PathBuf};

use nebula_voxel::{DVec3, PlanetSettings, Voxel, VoxelCoord, VoxelSource};

use crate::*;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("nebula-world-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir.join("world.redb")
}

fn unit(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64
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
    assert!(matches!(refused, Err(WorldError::WrongVersion { found: 2, supported: 1, .. })), "{refused:?}");
    assert!(std::fs::read(&damaged).unwrap() == future, "a wrong-version file was modified");
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
