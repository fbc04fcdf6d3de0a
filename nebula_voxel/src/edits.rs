//! Voxel edits layered over any [`VoxelSource`].
//!
//! Edits are made at LOD 0 and kept in an overlay beside the source, which is
//! never modified: regenerating a chunk re-reads the overlay, so an edit
//! cannot be lost. Coarser LODs see edits through the planet's own LOD rule
//! (see `ProceduralPlanet`): a voxel at LOD `L` is the LOD-0 voxel in its far
//! corner, so
//!
//! ```text
//!   edited_L(a, b, c) = edited_0((a+1)·s − 1, (b+1)·s − 1, (c+1)·s − 1)
//! ```
//!
//! and a fully geomorphed finer chunk still matches its parent after any
//! edit (as it does unedited: exactly with every octave at every LOD). A single dug voxel shows at LOD `L` only if it is that corner; a
//! crater shows at every LOD whose voxels are smaller than about the crater.

use std::collections::{BTreeSet, HashSet};
use std::ops::RangeInclusive;

// Persistent maps: a clone shares everything, an insert copies the path it
// changes, so an edit to a source a meshing snapshot holds costs the edit,
// not every edit so far.
use imbl::{HashMap as SharedMap, HashSet as SharedSet};

use nebula_math::{CubeFace, DVec3};

use crate::{
    CHUNK_SIZE, ChunkColumn, ChunkKey, ChunkLayout, ChunkVoxels, LayerView, PADDED_CHUNK_SIZE, PaddedChunkShape,
    SurfaceBounds, SurfaceSurvey, Voxel, VoxelCoord, VoxelError, VoxelSource,
};
use ndshape::ConstShape;

/// A [`VoxelSource`] with LOD-0 edits on top (see the module docs).
/// What lies above a chunk counts its edits too
/// ([`ChunkVoxels::set_covered_above`]): a shaft dug down into a cave lets
/// the sky light it, a roof built over the ground shades it, and the
/// chunks under such an edit are among its dirty ones.
/// Cloning is cheap whatever the edits: they are kept in persistent maps
/// (`imbl`) that a clone shares, and an edit after a clone copies only
/// what it changes (a `ProceduralPlanet` base shares its height memo too).
#[derive(Clone, Debug)]
pub struct EditedSource<S> {
    base: S,
    /// LOD-0 voxels that differ from `base`.
    fine: SharedMap<VoxelCoord, Voxel>,
    /// The keys of `fine` by LOD-0 chunk, for saving a chunk's edits.
    fine_by_chunk: SharedMap<ChunkKey, SharedSet<VoxelCoord>>,
    /// Chunks (any LOD) whose padded region holds a voxel the edits changed.
    touched_chunks: SharedSet<ChunkKey>,
    /// Per column (any LOD): lowest and highest LOD-0 layer edited inside.
    touched_columns: SharedMap<ChunkColumn, (i64, i64)>,
    /// Per LOD-0 voxel column (face, i, j): the highest layer ever edited
    /// in it, for the sky over the chunks below.
    edited_tops: SharedMap<(CubeFace, u32, u32), i32>,
    /// Chunks (any LOD) under an edit that opened or closed a voxel: what
    /// lies above them, and so their sky light, may differ from the base's.
    shaded_chunks: SharedSet<ChunkKey>,
}

/// What one batch of edits (a voxel, a sphere, a box) changed.
#[derive(Default)]
struct Batch {
    /// Chunks to re-mesh.
    dirty: BTreeSet<ChunkKey>,
    /// Chunks whose chunks below are already among `dirty` (and shaded).
    shaded_under: HashSet<ChunkKey>,
}

impl<S: VoxelSource> From<S> for EditedSource<S> {
    fn from(base: S) -> Self {
        Self::new(base)
    }
}

impl<S: VoxelSource> EditedSource<S> {
    /// Wraps `base` with no edits yet.
    pub fn new(base: S) -> Self {
        Self {
            base,
            fine: SharedMap::new(),
            fine_by_chunk: SharedMap::new(),
            touched_chunks: SharedSet::new(),
            touched_columns: SharedMap::new(),
            edited_tops: SharedMap::new(),
            shaded_chunks: SharedSet::new(),
        }
    }

    /// The unedited source.
    pub fn base(&self) -> &S {
        &self.base
    }

    /// The LOD-0 voxels that differ from the base, for saving. Replaying
    /// them with [`EditedSource::set_voxel`] on a fresh source restores the
    /// same planet.
    pub fn edits(&self) -> impl Iterator<Item = (VoxelCoord, Voxel)> + '_ {
        self.fine.iter().map(|(&at, &voxel)| (at, voxel))
    }

    /// How many LOD-0 voxels differ from the base.
    pub fn edit_count(&self) -> usize {
        self.fine.len()
    }

    /// The edited voxels inside LOD-0 chunk `key` (padding excluded),
    /// sorted: what a save stores for that chunk.
    pub fn chunk_edits(&self, key: ChunkKey) -> Vec<(VoxelCoord, Voxel)> {
        let mut edits: Vec<_> = self
            .fine_by_chunk
            .get(&key)
            .into_iter()
            .flatten()
            .filter_map(|at| self.fine.get(at).map(|&voxel| (*at, voxel)))
            .collect();
        edits.sort_unstable_by_key(|&(at, _)| at);
        edits
    }

    /// Sets one LOD-0 voxel. Returns the chunks, at every LOD, whose voxels
    /// (padding included) changed and must be re-meshed, sorted.
    ///
    /// # Errors
    /// [`VoxelError::VoxelOutOfRange`] for a coordinate off the planet or not
    /// at LOD 0.
    pub fn set_voxel(&mut self, at: VoxelCoord, voxel: Voxel) -> Result<Vec<ChunkKey>, VoxelError> {
        let mut batch = Batch::default();
        self.set_voxel_into(at, voxel, &mut batch)?;
        Ok(batch.dirty.into_iter().collect())
    }

    /// Sets every LOD-0 voxel whose centre lies within `radius` metres of
    /// `center` (across chunk and cube-face edges) to `voxel`: `Voxel::AIR`
    /// digs a crater, a material builds a ball. Returns the dirty chunks.
    ///
    /// # Errors
    /// [`VoxelError::NonFinite`] / [`VoxelError::OutOfRange`] for a bad
    /// centre or radius (at most 64 voxels).
    pub fn fill_sphere(&mut self, center: DVec3, radius: f64, voxel: Voxel) -> Result<Vec<ChunkKey>, VoxelError> {
        if !radius.is_finite() {
            return Err(VoxelError::NonFinite { name: "radius", value: radius });
        }
        self.fill_where(center, radius, voxel, |p| p.distance(center) <= radius)
    }

    /// Sets every LOD-0 voxel whose centre lies in the world-axis-aligned
    /// box from `min` to `max` (metres, planet centre at the origin) to
    /// `voxel`. Returns the dirty chunks.
    ///
    /// # Errors
    /// [`VoxelError::NonFinite`] for NaN or infinite corners,
    /// [`VoxelError::OutOfRange`] for `min` above `max` on an axis or a box
    /// more than 128 voxels across.
    pub fn fill_box(&mut self, min: DVec3, max: DVec3, voxel: Voxel) -> Result<Vec<ChunkKey>, VoxelError> {
        for value in min.to_array().into_iter().chain(max.to_array()) {
            if !value.is_finite() {
                return Err(VoxelError::NonFinite { name: "box corner", value });
            }
        }
        let extent = max - min;
        if extent.min_element() < 0.0 {
            return Err(VoxelError::OutOfRange {
                name: "box extent",
                requirement: "max ≥ min on every axis",
                value: extent.min_element(),
            });
        }
        let inside = |p: DVec3| p.cmpge(min).all() && p.cmple(max).all();
        self.fill_where((min + max) * 0.5, extent.length() * 0.5, voxel, inside)
    }

    /// Sets every LOD-0 voxel whose centre is within `reach` metres of
    /// `center` and satisfies `inside` to `voxel`.
    fn fill_where(
        &mut self,
        center: DVec3,
        reach: f64,
        voxel: Voxel,
        inside: impl Fn(DVec3) -> bool,
    ) -> Result<Vec<ChunkKey>, VoxelError> {
        let layout = *self.base.layout();
        let sphere = layout.sphere();
        let voxel_size = sphere.layer_height();
        if !(0.0..=64.0 * voxel_size).contains(&reach) {
            return Err(VoxelError::OutOfRange { name: "radius", requirement: "in [0, 64 voxels]", value: reach });
        }
        let (face, fi, fj) = sphere.face_coords_of(center)?;
        let layer = sphere.radius_to_layer(center.length());
        if layer.abs() > f64::from(i32::MAX / 4) {
            return Err(VoxelError::OutOfRange {
                name: "centre",
                requirement: "within the planet's radial range",
                value: center.length(),
            });
        }
        // Cells shrink towards face corners (by up to √2): widen the search.
        let reach_ij = (reach / layout.sphere().cell_width() * 1.5).ceil() as i64 + 1;
        let reach_h = (reach / voxel_size).ceil() as i64 + 1;
        let per_edge = i64::from(layout.voxels_per_edge(0));
        let mut batch = Batch::default();
        let mut seen = HashSet::new();
        for di in -reach_ij..=reach_ij {
            for dj in -reach_ij..=reach_ij {
                let (ci, cj) = (fi.floor() as i64 + di, fj.floor() as i64 + dj);
                let Some((f, i, j)) = face.wrap_cell(ci, cj, per_edge) else { continue };
                if !seen.insert((f, i, j)) {
                    continue;
                }
                let direction = sphere.direction(f, i as f64 + 0.5, j as f64 + 0.5);
                for dh in -reach_h..=reach_h {
                    let h = layer.floor() as i64 + dh;
                    if inside(direction * sphere.layer_radius(h as f64 + 0.5)) {
                        let at = VoxelCoord { face: f, lod: 0, i: i as u32, j: j as u32, h: h as i32 };
                        self.set_voxel_into(at, voxel, &mut batch)?;
                    }
                }
            }
        }
        Ok(batch.dirty.into_iter().collect())
    }

    fn set_voxel_into(&mut self, at: VoxelCoord, voxel: Voxel, batch: &mut Batch) -> Result<(), VoxelError> {
        if at.lod != 0 {
            return Err(VoxelError::VoxelOutOfRange { at, reason: "edits are made at LOD 0".into() });
        }
        let layout = *self.base.layout();
        layout.check_voxel(at)?;
        let old = self.voxel(at)?;
        if old == voxel {
            return Ok(());
        }
        let chunk = layout.chunk_of(at);
        if self.base.voxel(at)? == voxel {
            self.fine.remove(&at);
            if let Some(set) = self.fine_by_chunk.get_mut(&chunk) {
                set.remove(&at);
                if set.is_empty() {
                    self.fine_by_chunk.remove(&chunk);
                }
            }
        } else {
            self.fine.insert(at, voxel);
            self.fine_by_chunk.entry(chunk).or_default().insert(at);
        }
        let top = self.edited_tops.entry((at.face, at.i, at.j)).or_insert(at.h);
        *top = (*top).max(at.h);
        // Opening or closing a voxel may change what sees the sky below it.
        let shades_below = old.is_solid() != voxel.is_solid();
        // The voxel is itself the voxel at every LOD where it is the far
        // corner of its cell (all three indices ≡ −1 mod 2^L).
        let mut cell = at;
        for lod in 0..=layout.max_lod() {
            if lod > 0 {
                let span = layout.voxel_span(lod);
                let corner = |index: i64| (index + 1).rem_euclid(span) == 0;
                if !(corner(at.i.into()) && corner(at.j.into()) && corner(at.h.into())) {
                    break;
                }
                let Some(up) = cell.parent() else { break };
                cell = up;
            }
            self.mark_changed(&layout, cell, shades_below, batch);
        }
        // Every coarser column over the voxel bounds it too, whether or not
        // its LOD shows it: queries of LOD-0 voxels (picking) may skip a
        // coarse column by its bounds.
        let h = i64::from(at.h);
        for lod in 1..=layout.max_lod() {
            let shift = u32::from(lod) + CHUNK_SIZE.trailing_zeros();
            let column = ChunkColumn { face: at.face, lod, x: at.i >> shift, y: at.j >> shift };
            let range = self.touched_columns.entry(column).or_insert((h, h));
            *range = (range.0.min(h), range.1.max(h));
        }
        Ok(())
    }

    /// Records that the effective value of `cell` changed: its chunk and
    /// every chunk holding it as padding become dirty; with
    /// `shades_below` (it turned solid or air), so do the chunks under
    /// those, down to the lowest surface their columns may have, whose
    /// sky light it may change.
    fn mark_changed(&mut self, layout: &ChunkLayout, cell: VoxelCoord, shades_below: bool, batch: &mut Batch) {
        let key = layout.chunk_of(cell);
        // Every chunk holding a voxel next to the cell, diagonals included
        // (across chunk and cube-face edges), holds the cell in its
        // padding: the mesher reads the padding's corners for the light at
        // a chunk's corner edges.
        let per_edge = i64::from(layout.voxels_per_edge(cell.lod));
        let mut keys = vec![key];
        for (di, dj) in (0..9).map(|n| (n % 3 - 1, n / 3 - 1)) {
            let Some((face, i, j)) = cell.face.wrap_cell(i64::from(cell.i) + di, i64::from(cell.j) + dj, per_edge)
            else {
                continue;
            };
            for dh in -1..=1 {
                let next = VoxelCoord { face, lod: cell.lod, i: i as u32, j: j as u32, h: cell.h + dh };
                let holder = layout.chunk_of(next);
                if !keys.contains(&holder) {
                    keys.push(holder);
                }
            }
        }
        let span = layout.voxel_span(cell.lod);
        let (bottom, top) = (i64::from(cell.h) * span, i64::from(cell.h) * span + span - 1);
        let range = self.touched_columns.entry(key.column()).or_insert((bottom, top));
        *range = (range.0.min(bottom), range.1.max(top));
        for key in keys {
            self.touched_chunks.insert(key);
            batch.dirty.insert(key);
            if shades_below && batch.shaded_under.insert(key) {
                let lowest = self
                    .surface_bounds(key.column())
                    .map_or(key.layer, |bounds| *bounds.chunk_layers(layout, key.lod).start());
                for below in (lowest..key.layer).map(|layer| ChunkKey { layer, ..key }) {
                    self.shaded_chunks.insert(below);
                    batch.dirty.insert(below);
                }
            }
        }
    }

    /// Whether padded voxel column `(x, z)` of `key`, at `(face, i, j)`, is
    /// covered above the padded chunk once the edits over it count (`base`:
    /// the base's answer, which stands where no edit lies above). Read voxel
    /// by voxel from the padded chunk's top up past the highest surface
    /// the column may have; the base is asked only where it said covered
    /// and no edit decides (each of its voxels costs a noise evaluation).
    fn covered_above_edited(&self, key: ChunkKey, (face, i, j): (CubeFace, u32, u32), base: bool) -> bool {
        let layout = self.layout();
        let span = layout.voxel_span(key.lod);
        // LOD `L` shows the LOD-0 voxel in each cell's far corner.
        let corner = |index: i64| (index + 1) * span - 1;
        let (fine_i, fine_j) = (corner(i.into()) as u32, corner(j.into()) as u32);
        let Some(&edited_top) = self.edited_tops.get(&(face, fine_i, fine_j)) else { return base };
        let first = i64::from(key.layer) * i64::from(CHUNK_SIZE) + i64::from(PADDED_CHUNK_SIZE) - 1;
        if i64::from(edited_top) < first * span {
            return base;
        }
        let chunk = i64::from(CHUNK_SIZE);
        let column =
            ChunkColumn { face, lod: key.lod, x: (i64::from(i) / chunk) as u32, y: (i64::from(j) / chunk) as u32 };
        let Ok(bounds) = self.surface_bounds(column) else { return base };
        let last = bounds.max_layer.max(i64::from(edited_top)).div_euclid(span) + 1;
        (first..=last).any(|h| {
            let fine = VoxelCoord { face, lod: 0, i: fine_i, j: fine_j, h: corner(h) as i32 };
            match self.fine.get(&fine) {
                Some(voxel) => voxel.is_solid(),
                // Where the base is open above the chunk, it is air here.
                None => {
                    base && self
                        .base
                        .voxel(VoxelCoord { face, lod: key.lod, i, j, h: h as i32 })
                        .is_ok_and(|v| v.is_solid())
                }
            }
        })
    }

    /// The effective voxel given the base's value for the same coordinates:
    /// the edited LOD-0 voxel in its far corner, if there is one.
    fn edited(&self, at: VoxelCoord, base: Voxel) -> Voxel {
        if self.fine.is_empty() {
            return base;
        }
        let span = self.base.layout().voxel_span(at.lod);
        let corner = |index: i64| (index + 1) * span - 1;
        let fine = VoxelCoord {
            lod: 0,
            i: corner(at.i.into()) as u32,
            j: corner(at.j.into()) as u32,
            h: corner(at.h.into()) as i32,
            ..at
        };
        self.fine.get(&fine).copied().unwrap_or(base)
    }
}

impl<S: VoxelSource> EditedSource<S> {
    /// `bounds` of the base's `column`, widened to hold its edits.
    fn widened(&self, column: ChunkColumn, mut bounds: SurfaceBounds) -> SurfaceBounds {
        if let Some(&(low, high)) = self.touched_columns.get(&column) {
            let span = self.layout().voxel_span(column.lod);
            bounds.min_layer = bounds.min_layer.min(low - span);
            bounds.max_layer = bounds.max_layer.max(high + span);
            let sphere = self.layout().sphere();
            bounds.min_radius = sphere.layer_radius(bounds.min_layer as f64);
            bounds.max_radius = sphere.layer_radius(bounds.max_layer as f64 + 1.0);
            // An edit may have put anything there.
            bounds.sea_bed_only = false;
        }
        bounds
    }
}

impl<S: VoxelSource> VoxelSource for EditedSource<S> {
    fn layout(&self) -> &ChunkLayout {
        self.base.layout()
    }

    fn voxel(&self, at: VoxelCoord) -> Result<Voxel, VoxelError> {
        Ok(self.edited(at, self.base.voxel(at)?))
    }

    fn column_voxels(&self, bottom: VoxelCoord, out: &mut [Voxel]) -> Result<(), VoxelError> {
        self.base.column_voxels(bottom, out)?;
        for (h, voxel) in (bottom.h..).zip(out.iter_mut()) {
            *voxel = self.edited(VoxelCoord { h, ..bottom }, *voxel);
        }
        Ok(())
    }

    fn fill_chunk(&self, key: ChunkKey, out: &mut ChunkVoxels) -> Result<(), VoxelError> {
        self.base.fill_chunk(key, out)?;
        let touched = self.touched_chunks.contains(&key);
        if !touched && !self.shaded_chunks.contains(&key) {
            return Ok(());
        }
        let per_edge = i64::from(self.layout().voxels_per_edge(key.lod));
        let size = i64::from(CHUNK_SIZE);
        for z in 0..PADDED_CHUNK_SIZE {
            for x in 0..PADDED_CHUNK_SIZE {
                let (ci, cj) = (i64::from(key.x) * size + i64::from(x) - 1, i64::from(key.y) * size + i64::from(z) - 1);
                // Corner-gap padding has no voxel of its own: leave the base's.
                let Some((face, i, j)) = key.face.wrap_cell(ci, cj, per_edge) else { continue };
                if touched {
                    let voxels = out.as_mut_slice();
                    for y in 0..PADDED_CHUNK_SIZE {
                        let h = i64::from(key.layer) * size + i64::from(y) - 1;
                        let at = VoxelCoord { face, lod: key.lod, i: i as u32, j: j as u32, h: h as i32 };
                        let index = PaddedChunkShape::linearize([x, y, z]) as usize;
                        voxels[index] = self.edited(at, voxels[index]);
                    }
                }
                // A shaft dug over a cave lets the sky in; a roof built
                // over the ground keeps it out.
                if let Some(base) = out.covered_above((x, z)) {
                    let covered = self.covered_above_edited(key, (face, i as u32, j as u32), base);
                    out.set_covered_above((x, z), covered);
                }
            }
        }
        Ok(())
    }

    fn surface_bounds(&self, column: ChunkColumn) -> Result<SurfaceBounds, VoxelError> {
        Ok(self.widened(column, self.base.surface_bounds(column)?))
    }

    fn surface_top_radius(&self, column: ChunkColumn) -> Result<f64, VoxelError> {
        let top = self.base.surface_top_radius(column)?;
        Ok(match self.touched_columns.contains_key(&column) {
            true => top.max(self.widened(column, self.base.surface_bounds(column)?).max_radius),
            false => top,
        })
    }

    fn surface_survey(&self, column: ChunkColumn) -> Result<SurfaceSurvey, VoxelError> {
        // Edits reach only the layers of all (`layer_view` says so).
        let base = self.base.surface_survey(column)?;
        let bounds = self.widened(column, base.bounds);
        let all = bounds.chunk_layers(self.layout(), column.lod);
        Ok(SurfaceSurvey::new(bounds, |view| if view == LayerView::All { all.clone() } else { base.layers(view) }))
    }

    fn geometric_error(&self, lod: u8) -> f64 {
        self.base.geometric_error(lod)
    }

    fn sea_bed_below(&self, column: ChunkColumn, radius: f64) -> Result<bool, VoxelError> {
        // An edit may have put anything anywhere in its column.
        if self.touched_columns.contains_key(&column) {
            self.layout().check_key(column.chunk(0))?;
            return Ok(false);
        }
        self.base.sea_bed_below(column, radius)
    }

    fn layer_view(&self, eye: DVec3) -> LayerView {
        // A shaft may open a sealed cave anywhere: with edits, every layer
        // is drawn (a world could tell where they reach; this keeps it
        // simple and safe).
        if self.touched_columns.is_empty() { self.base.layer_view(eye) } else { LayerView::All }
    }

    fn surface_chunk_layers_seen(
        &self,
        column: ChunkColumn,
        view: LayerView,
    ) -> Result<RangeInclusive<i32>, VoxelError> {
        // Edits reach only the layers of all (`layer_view` says so).
        match view {
            LayerView::All => self.surface_chunk_layers(column),
            _ => self.base.surface_chunk_layers_seen(column, view),
        }
    }

    fn lowest_surface_radius(&self) -> Option<f64> {
        // Digging opens surface down to the lowest edited layer.
        let lowest_edit = self.touched_columns.values().map(|&(low, _)| low).min();
        let base = self.base.lowest_surface_radius()?;
        Some(lowest_edit.map_or(base, |layer| base.min(self.layout().sphere().layer_radius(layer as f64))))
    }
}
