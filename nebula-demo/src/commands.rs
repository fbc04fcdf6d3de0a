//! The command-line subcommands on worlds: `pick` and `edit`. Thin: the
//! work is `nebula_world`'s; this parses arguments and prints JSON.

use std::io::{BufRead, Write};
use std::time::Instant;

use anyhow::{Context, bail};
use nebula_math::DVec3;
use nebula_voxel::{Voxel, VoxelCoord, VoxelHit, VoxelSource};
use nebula_world::{Edit, World};
use serde_json::{Value, json};

/// Rays reach this far (metres): the planet's far side from low orbit.
pub const PICK_REACH: f64 = 50_000_000.0;

/// JSON for the first solid voxel from `eye` towards `look_at`.
///
/// # Errors
/// A bad ray or a voxel source error.
pub fn pick(world: &World, eye: DVec3, look_at: DVec3) -> anyhow::Result<Value> {
    let start = Instant::now();
    let hit = world.pick(eye, look_at - eye, PICK_REACH)?;
    let micros = start.elapsed().as_secs_f64() * 1e6;
    Ok(match hit {
        None => json!({ "hit": false, "micros": micros }),
        Some(hit) => hit_json(&hit, world.source().voxel(hit.voxel)?, micros),
    })
}

fn hit_json(hit: &VoxelHit, voxel: Voxel, micros: f64) -> Value {
    json!({
        "hit": true,
        "voxel": voxel_json(hit.voxel),
        "face": hit.face.map(|f| format!("{f:?}")),
        "normal": hit.normal.to_array(),
        "point": hit.point.to_array(),
        "distance": hit.distance,
        "before": hit.before.map(voxel_json),
        "material": voxel.name().map_or_else(|| json!(voxel.material()), |name| json!(name)),
        "micros": micros,
    })
}

fn voxel_json(at: VoxelCoord) -> Value {
    json!({ "face": format!("{:?}", at.face), "i": at.i, "j": at.j, "h": at.h })
}

/// Parses a material name (`air`, `stone`, …).
///
/// # Errors
/// An unknown name, with the known ones.
pub fn material(name: &str) -> anyhow::Result<Voxel> {
    Voxel::named(name).with_context(|| {
        let known: Vec<&str> = Voxel::NAMED.iter().map(|(n, _)| *n).collect();
        format!("unknown material '{name}' (known: {})", known.join(", "))
    })
}

/// Parses comma-separated finite numbers, exactly `n` of them.
///
/// # Errors
/// Wrong count, or a value that is not a finite number.
pub fn numbers(text: &str, n: usize, what: &str) -> anyhow::Result<Vec<f64>> {
    let values: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>().with_context(|| format!("{what}: '{p}' is not a number")))
        .collect::<Result<_, _>>()?;
    if values.len() != n {
        bail!("{what} takes {n} comma-separated numbers, got {} in '{text}'", values.len());
    }
    if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
        bail!("{what}: {bad} is not finite");
    }
    Ok(values)
}

/// An edit from its shape arguments: `sphere X,Y,Z,R` or
/// `box X0,Y0,Z0,X1,Y1,Z1` (metres, planet centre at the origin).
///
/// # Errors
/// An unknown shape or bad numbers.
pub fn shape_edit(shape: &str, numbers_text: &str, voxel: Voxel) -> anyhow::Result<Edit> {
    Ok(match shape {
        "sphere" => {
            let v = numbers(numbers_text, 4, "--sphere")?;
            Edit::Sphere { center: DVec3::new(v[0], v[1], v[2]), radius: v[3], voxel }
        }
        "box" => {
            let v = numbers(numbers_text, 6, "--box")?;
            Edit::Box { min: DVec3::new(v[0], v[1], v[2]), max: DVec3::new(v[3], v[4], v[5]), voxel }
        }
        other => bail!("unknown edit shape '{other}' (sphere or box)"),
    })
}

/// Applies `edits` as one saved batch and describes it as JSON.
///
/// # Errors
/// A bad edit or a failed save.
pub fn edit(world: &mut World, edits: &[Edit]) -> anyhow::Result<Value> {
    let before = world.edit_count();
    let start = Instant::now();
    let applied = world.apply(edits)?;
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let lod0: Vec<Value> = applied
        .dirty
        .iter()
        .filter(|key| key.lod == 0)
        .map(|k| json!({ "face": format!("{:?}", k.face), "x": k.x, "y": k.y, "layer": k.layer }))
        .collect();
    Ok(json!({
        "edited_voxels": world.edit_count(),
        "edited_voxels_before": before,
        "chunks_touched": lod0,
        "dirty_chunks_all_lods": applied.dirty.len(),
        "saved_chunks": applied.saved_chunks,
        "ms": ms,
    }))
}

/// Reads edits from `input`, one per line (`sphere X,Y,Z,R MATERIAL` or
/// `box X0,Y0,Z0,X1,Y1,Z1 MATERIAL`; blank lines and `#` comments
/// skipped), applies and saves each as its own batch, and writes one JSON
/// line per saved batch to `output` (flushed: a line printed is a batch
/// on disk).
///
/// # Errors
/// A bad line (with its number), a failed save, or I/O.
pub fn edit_script(world: &mut World, input: impl BufRead, mut output: impl Write) -> anyhow::Result<()> {
    for (n, line) in input.lines().enumerate() {
        let line = line.context("reading the edit script")?;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let parts: Vec<&str> = line.split_whitespace().collect();
        let [shape, values, name] = parts.as_slice() else {
            bail!("line {}: expected 'sphere|box NUMBERS MATERIAL', got '{line}'", n + 1);
        };
        let edit = shape_edit(shape, values, material(name)?).with_context(|| format!("line {}", n + 1))?;
        let mut report = self::edit(world, &[edit]).with_context(|| format!("line {}", n + 1))?;
        report["line"] = json!(n + 1);
        writeln!(output, "{report}")?;
        output.flush()?;
    }
    Ok(())
}
