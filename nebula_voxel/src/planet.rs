//! A seeded procedural planet.
//!
//! # Terrain
//!
//! The surface height `H(d)` (metres above the base radius, for a unit
//! direction `d`) is a blend of three noise sums evaluated on the sphere, so
//! it is seamless across cube faces:
//!
//! ```text
//!   continents = fbm(d · radius / feature_size)          (Perlin, persistence 0.45)
//!   ridges     = (ridged_multi(d · radius / mountain_size) + 1) / 2          (in [0, 1])
//!   hills      = (fbm(d · radius / detail_size) + 1) / 2   (Perlin, persistence 0.5)
//!   mountains  = ridges³ · smoothstep(0.1, 0.4, continents)                  (in [0, 1])
//!   H = amplitude · clamp(slope·continents + 0.6·mountains, −1, 1)
//!     + detail_amplitude · hills · (1 + 6·mountains)
//! ```
//!
//! `slope` is 0.6 under the sea and 0.2 over land, so the land rises
//! gently from its coasts; the cube of the ridges keeps the mountain
//! chains narrow, and the mask stands them on the continents' cores. The
//! hills give the relief a player walks on (without them a planet-sized
//! landform is flat over any one chunk), and grow into the valleys and
//! spurs of the ranges. H rises with each of the three sums, which the
//! surface bounds rely on.
//!
//! The three sums are read as `octave_grid.rs` defines them: an octave
//! many voxels long comes bilinearly from a grid on the face lattice, the
//! finest at the column itself (`PlanetSettings::octave_grid`; 0 for every
//! octave at every column, the planets saved before grids). H is a
//! function of the LOD-0 column on its own face, the same at every LOD;
//! [`ProceduralPlanet::height_at`] between columns blends the grids too.
//!
//! Under the ground, caves (`caves.rs`): air where a tunnel's span of
//! depths under H holds the voxel's sample, above the sea.
//!
//! # LOD sampling rule: the far-corner voxel
//!
//! A voxel at LOD `L` is `s = 2^L` lattice cells wide and `s` radial layers
//! tall. It **is** one LOD-0 voxel: the one in its far corner (largest `i`,
//! `j` and layer inside it),
//!
//! ```text
//!   voxel_L(a, b, c) = voxel_0((a+1)·s − 1, (b+1)·s − 1, (c+1)·s − 1)
//! ```
//!
//! Why that corner: it makes every coarser LOD exactly what the geomorph
//! shader collapses a finer chunk to. The morph target of a fine lattice
//! vertex is the vertex with each coordinate rounded down to even
//! (`nebula_meshing`). Under that map a fine voxel at an odd index grows to
//! fill its whole coarse cell and one at an even index collapses to nothing,
//! so a fully morphed chunk at LOD `L` is the surface of the voxels
//! `voxel_L((2a+1), …)` — the parent's voxels by the rule above. The one
//! thing a collapse cannot reproduce is a one-voxel-thin sheet at an even
//! index, which shrinks to a zero-thickness wall instead of vanishing.
//!
//! Exactly so with every noise octave at every LOD (`band_limit` 0). The
//! presets band-limit coarse LODs ([`PlanetSettings::band_limit`]): there
//! a coarse column is its far-corner fine column less the octaves its LOD
//! leaves out, so a fully morphed chunk is its parent but where those move
//! a top across a layer boundary (2.2 % of the tops measured), within δ.
//!
//! No coarse voxel is built from the `s³` fine voxels below it (a LOD-18
//! chunk would need 10¹⁸ of them): each is one noise column and one
//! comparison, at the same cost per chunk at every LOD.
//!
//! # Error bound δ(L)
//!
//! A LOD-0 voxel at layer `k` is solid iff its centre `k + 1/2` is below
//! `H` at its column's centre, so the LOD-0 top over column `c₀` is within
//! 1/2 layer of `H(c₀)`. The coarse column's top is the LOD-0 top of its
//! sample column `c_s` rounded *down* to a multiple of `s`: between
//! `H(c_s) + 1/2 − s` and `H(c_s) + 1/2`. The fine columns under a coarse
//! one are at most `s − 1` cells from `c_s` along each axis, so with `S` the
//! steepest height change per lattice step (layers per cell),
//!
//! ```text
//!   |top_L − top_0| ≤ s + min(2·S·(s − 1) + dropped(L), relief)   layers,  δ(L) = that × layer height
//! ```
//!
//! where `relief` is the most H can vary anywhere (highest less lowest),
//! which wins at coarse LODs, and `dropped(L)` the most the octaves a
//! band-limited LOD leaves out can move H (`BandLimited`; 0 at LOD 0).
//! The relief caps both: H from any sums lies between its lowest and its
//! highest.
//!
//! This δ is what skirts are sized from ([`VoxelSource::geometric_error`]).
//! The LOD selection does not use it: it asks that a drawn voxel edge
//! subtend at most τ pixels ([`ChunkLayout::voxel_edge`]).
//!
//! `S` is built when the planet is: each noise sum's steepest step over
//! 4,096 places (×1.5 for the places not sampled), put through `combine`
//! as if the three were steepest in one place. The sums are alike
//! everywhere, so sampling finds their steepest steps, but the bound is
//! empirical, not proven. H's own steepest step at random places would
//! not do: the mountains are steepest along their crests, which random
//! places seldom hit. The tests `max_slope_holds_where_the_mountains_are_steepest`
//! and `geometric_error_bounds_the_voxel_tops` check S and δ against
//! places unrelated to the samples.
//!
//! # Surface bounds
//!
//! A column's bounds ([`VoxelSource::surface_bounds`]) hold H over its
//! whole patch. S times half the patch is tight for a small patch and
//! hopeless for a large one (kilometres either way at LOD 9 on an Earth, where the
//! terrain varies by hundreds of metres), so the bounds come from the
//! noise instead: each sum's range over the ball the patch lies in
//! ([`Fractal::range_near`]: every octave's value at the centre, give or
//! take its steepest change over the radius), through `combine`, which
//! rises with each sum. Five samples and S narrow that where they can (the
//! finest LODs). Under the sea and the snow line every column is sea bed,
//! which [`SurfaceBounds::sea_bed_only`] reports.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex, OnceLock};

use crate::caves::{Caves, ColumnCaves};
use crate::octave_grid::{CoarseGrids, GriddedSum, OctaveLevels, grid_states};
use crate::perlin::{Fractal, OctaveState};
use nebula_math::{CubeFace, Cubesphere, SphereMap};

use crate::{
    CHUNK_SIZE, ChunkColumn, ChunkKey, ChunkLayout, ChunkVoxels, LayerView, MAX_LOD, PADDED_CHUNK_SIZE,
    PaddedChunkShape, SurfaceBounds, SurfaceSurvey, Voxel, VoxelCoord, VoxelError, VoxelSource,
};
use ndshape::ConstShape;

/// Parameters of a [`ProceduralPlanet`].
#[derive(Clone, Debug, PartialEq)]
pub struct PlanetSettings {
    /// Radius of height 0, metres.
    pub radius: f64,
    /// Wanted voxel edge at LOD 0, metres. The planet uses the nearest size
    /// that puts `32 · 2^k` voxels along a face edge (see
    /// [`ProceduralPlanet::voxel_size`]).
    pub voxel_size: f64,
    /// Largest height above or depth below the base radius, metres.
    pub amplitude: f64,
    /// Wavelength of the largest landforms (continents and oceans), metres.
    pub feature_size: f64,
    /// Wavelength of the mountain chains on the continents, metres.
    pub mountain_size: f64,
    /// Height of the small hills on top of the landforms, metres.
    pub detail_amplitude: f64,
    /// Wavelength of the small hills, metres.
    pub detail_size: f64,
    /// Noise seed: equal settings and seed give identical planets.
    pub seed: u32,
    /// How tall the shallow cave tunnels are, metres (the deep ones and
    /// their chambers scale with it; see `caves.rs`): 0 for a planet
    /// without caves, the heightfield planets saved before caves existed.
    pub cave_size: f64,
    /// Wavelengths per grid spacing at which a noise octave is read from a
    /// grid on the face lattice instead of evaluated at every voxel column
    /// (`octave_grid.rs`): 16 for new planets (at most 1.9 % of such an
    /// octave's amplitude off the exact noise; a LOD-0 chunk generates
    /// 1.6× faster); 0 for every octave at every column, the terrain of
    /// the planets saved before grids.
    pub octave_grid: f64,
    /// How far, metres, reading one octave from a grid coarser than the
    /// ratio's 16 columns may move H by the interpolation bound
    /// (`octave_grid.rs`): the continents' long octaves then come from
    /// grids at coarse LODs too, which otherwise sum them at every column.
    /// `0.01 · voxel_size` for new planets; 0 for no grid coarser than 16
    /// columns, the terrain of the planets saved before coarse grids.
    pub octave_grid_error: f64,
    /// Voxels per wavelength under which a coarse LOD (1 and up) leaves a
    /// noise octave out (`BandLimited`): such an octave is sampled a few
    /// times a wavelength or less, so it adds a random bump of part of a
    /// voxel to each column (aliasing) and, through the voxel steps it
    /// rounds to, quads that show no terrain. 6 in the presets: Earth's
    /// views draw about 10 % fewer triangles with the same picture error.
    /// It loosens the nesting the geomorph relies on (a coarse column is
    /// no longer exactly its far-corner fine column, so fully morphed
    /// children are not quite their parent): at 6 the small planet's
    /// largest surface pop at a LOD switch grows from 2.26 to 2.35 px and
    /// Earth's stays 0.97 px; at 8 the small planet's reached 2.87 px,
    /// which is why the presets stop at 6. What is left out moves a column
    /// by at most [`BandLimited`]'s `dropped`, which
    /// [`VoxelSource::geometric_error`] and the surface bounds allow for.
    /// LOD 0 keeps every octave either way. 0 (every octave at every LOD)
    /// is the terrain of the planets saved before it.
    pub band_limit: f64,
}

impl PlanetSettings {
    /// A planet of `radius` metres and `voxel_size`-metre voxels with relief
    /// scaled to it, capped at Earth's: continents 75 % of the radius
    /// across (at most 2,500 km), mountain chains as far apart (at most
    /// 60 km), relief 6 % of the radius (at most 4 km), hills 0.6 % of it
    /// (at most 60 m) and 7.5 % of it across (at most 3 km), seven times
    /// taller on the mountains; cave tunnels five voxels tall (at most 1/30 of
    /// the relief).
    #[must_use]
    pub fn scaled(seed: u32, radius: f64, voxel_size: f64) -> Self {
        Self {
            radius,
            voxel_size,
            amplitude: (radius * 0.06).min(4_000.0),
            feature_size: (radius * 0.75).min(2_500_000.0),
            mountain_size: (radius * 0.75).min(60_000.0),
            detail_amplitude: (radius * 0.006).min(60.0),
            detail_size: (radius * 0.075).min(3_000.0),
            seed,
            // Caves stay above the sea: a planet with low land gets
            // smaller ones.
            cave_size: (5.0 * voxel_size).min(radius * 0.06 / 30.0),
            octave_grid: 16.0,
            octave_grid_error: 0.01 * voxel_size,
            band_limit: 6.0,
        }
    }

    /// An Earth-sized planet: 6,371 km, ~1.2 m voxels, continents
    /// 2,500 km across, 4 km of relief, mountain chains 60 km apart.
    #[must_use]
    pub fn earth(seed: u32) -> Self {
        Self::scaled(seed, 6_371_000.0, 1.0)
    }

    /// A small planet for tests and demos: 2 km radius, ~1.5 m voxels
    /// (LOD 0..=6), 120 m of relief with 12 m hills 150 m across.
    #[must_use]
    pub fn small(seed: u32) -> Self {
        Self::scaled(seed, 2_000.0, 1.5)
    }

    /// Settings added since worlds were first saved with canonical
    /// settings, each with the value that gives the planets saved before
    /// it existed: a saved world without such a setting is that value's
    /// planet, so adding a setting does not lock old saves out. A new
    /// field goes here with the value that reproduces the terrain without
    /// it.
    pub const ADDED_SETTINGS: &'static [(&'static str, &'static str)] =
        &[("band_limit", "0.0"), ("cave_size", "0.0"), ("octave_grid", "0.0"), ("octave_grid_error", "0.0")];

    /// The field of the setting named `name` in [`Self::ADDED_SETTINGS`]
    /// (each a number of metres or voxels), `None` for any other name: so
    /// that a saved world's value of one can be taken over.
    pub fn added_setting_mut(&mut self, name: &str) -> Option<&mut f64> {
        match name {
            "band_limit" => Some(&mut self.band_limit),
            "cave_size" => Some(&mut self.cave_size),
            "octave_grid" => Some(&mut self.octave_grid),
            "octave_grid_error" => Some(&mut self.octave_grid_error),
            _ => None,
        }
    }

    /// The settings as canonical `(name, value)` pairs, sorted by name, for
    /// a saved world's identity: independent of field order and of `Debug`
    /// formatting, numbers in Rust's shortest text that reads back to the
    /// same `f64`.
    #[must_use]
    pub fn canonical(&self) -> Vec<(&'static str, String)> {
        // Destructured so that a new field cannot be forgotten here.
        let Self {
            radius,
            voxel_size,
            amplitude,
            feature_size,
            mountain_size,
            detail_amplitude,
            detail_size,
            seed,
            cave_size,
            octave_grid,
            octave_grid_error,
            band_limit,
        } = self;
        let mut pairs = vec![
            ("amplitude", format!("{amplitude:?}")),
            ("band_limit", format!("{band_limit:?}")),
            ("cave_size", format!("{cave_size:?}")),
            ("detail_amplitude", format!("{detail_amplitude:?}")),
            ("detail_size", format!("{detail_size:?}")),
            ("feature_size", format!("{feature_size:?}")),
            ("mountain_size", format!("{mountain_size:?}")),
            ("octave_grid", format!("{octave_grid:?}")),
            ("octave_grid_error", format!("{octave_grid_error:?}")),
            ("radius", format!("{radius:?}")),
            ("seed", seed.to_string()),
            ("voxel_size", format!("{voxel_size:?}")),
        ];
        pairs.sort_unstable();
        pairs
    }
}

/// A seeded, deterministic procedural planet (see the module docs for the
/// terrain, the LOD sampling rule and the error bound).
#[derive(Clone, Debug)]
pub struct ProceduralPlanet {
    settings: PlanetSettings,
    layout: ChunkLayout,
    continents: Fractal,
    ridges: Fractal,
    hills: Fractal,
    /// `radius / detail_size`: unit direction → hill noise space.
    detail_scale: f64,
    /// Metres per radial layer (= voxel size at LOD 0).
    layer_height: f64,
    /// `radius / feature_size`: unit direction → noise space.
    noise_scale: f64,
    /// `radius / mountain_size`: unit direction → ridge noise space.
    ridge_scale: f64,
    /// Each noise sum's steepest change per lattice step (continents,
    /// ridges, hills), measured ([`Self::measure_slopes`]).
    sum_steps: [f64; 3],
    /// S: steepest height change per lattice step, layers per cell.
    max_slope: f64,
    /// The caves under the ground (`caves.rs`).
    caves: Caves,
    /// Which octaves of the continents, ridges and hills come from grids
    /// (`octave_grid.rs`).
    levels: [OctaveLevels; 3],
    /// Per sum and octave, how much further than a ball's radius its noise
    /// is read (noise space): the grids' reach, for
    /// [`Self::sum_ranges`].
    widen: [Vec<f64>; 3],
    /// Per LOD, the sums its columns are made of
    /// ([`PlanetSettings::band_limit`]).
    bands: Vec<BandLimited>,
    /// Heights of recently filled chunk columns, shared by their radial
    /// layers, and by clones (a memo of the same pure function, so a clone
    /// made for an edit keeps what is cached).
    heights: Arc<HeightCache>,
}

/// Chunk columns whose heights [`HeightCache`] keeps: 28 MB (each holds
/// 34 × 34 voxel columns of 24 bytes). A streaming renderer asks for a
/// column's layers one after another (they share a priority), and for a
/// column's parent a little before the column (coarse first): a few
/// hundred columns catch most of both. 2,048 held 57 MB, the largest
/// block of the 1 km/s flights' heap after the GPU's; at 1,024 the
/// flights meshed 0–8 % fewer chunks in the same 30 s (alternating runs:
/// mountains 59.3–62.6 k against 61.9–63.1 k, land 53.5–55.8 k against
/// 55.0–59.9 k), about the runs' own spread.
const HEIGHT_CACHE_COLUMNS: usize = 1024;

/// The noise sums the columns of one LOD are made of: at LOD 1 and up,
/// without the octaves shorter than [`PlanetSettings::band_limit`] voxels
/// of the LOD, which its columns sample a few times a wavelength or less.
/// Such an octave adds to each column a bump of part of a voxel that
/// follows no terrain (aliasing), which the rounding to whole voxels turns
/// into steps and quads; left out, a coarse column's height is the
/// smoother sum a voxel of its size can show (README, "Coarse LODs
/// without the octaves they cannot show").
#[derive(Clone, Debug)]
struct BandLimited {
    /// The continents, ridges and hills, each with the octaves it keeps
    /// (every octave at LOD 0).
    sums: [Fractal; 3],
    /// Which of those come from grids (`octave_grid.rs`): the planet's
    /// grids, none holding an octave left out.
    levels: [OctaveLevels; 3],
    /// How far each sum's octaves left out can move it, at most (noise
    /// units, 0 where none is left out).
    tails: [f64; 3],
    /// How far, layers, they can move H at most anywhere: what
    /// [`VoxelSource::geometric_error`] adds for them (the surface bounds
    /// add their reach over the column's own ranges,
    /// [`ProceduralPlanet::dropped_within`]).
    dropped: f64,
}

impl BandLimited {
    /// How many octaves each sum keeps.
    fn kept(&self) -> [usize; 3] {
        self.sums.each_ref().map(Fractal::octaves)
    }
}

/// What a column's top material depends on besides its height.
#[derive(Clone, Copy, Debug)]
struct Climate {
    /// +Z is north.
    sin_latitude: f64,
    /// The continents sum: how far inland.
    continents: f64,
    /// The mountains term ([`ProceduralPlanet::mountains`]).
    mountains: f64,
}

/// Where [`ProceduralPlanet::surface`] changes its answer at one latitude.
#[derive(Clone, Copy)]
struct SurfaceThresholds {
    /// Heights, metres: the snow line, bare rock, sea level, the shore,
    /// the tree line.
    heights: [f64; 5],
    /// Continents sums: the deserts' edge, the forests' edge, each as a
    /// range `(low, high)` that holds it (one value where known exactly:
    /// a chunk's columns share ranges over their latitudes, which decide
    /// alike for any sum outside them; `ProceduralPlanet::surface`).
    continents: [(f64, f64); 2],
    /// The mountains term above which rock is bare.
    mountains: f64,
}

impl SurfaceThresholds {
    /// Whether the climate's edges are the column's own, not ranges.
    fn exact(&self) -> bool {
        self.continents.iter().all(|(low, high)| low == high)
    }
}

/// One open column's ends at a look of `ProceduralPlanet::columns_at`,
/// each `(low, high)`: the continents sum, the mountains term and H.
#[derive(Clone, Copy)]
struct LookEnds {
    continents: (f64, f64),
    mountains: (f64, f64),
    heights: (f64, f64),
}

/// Ranges `(low, high)` of the three noise sums of [`ProceduralPlanet::combine`]
/// over some place.
#[derive(Clone, Copy, Debug)]
struct SumRanges {
    continents: (f64, f64),
    ridges: (f64, f64),
    hills: (f64, f64),
}

impl SumRanges {
    /// Anything the sums can be.
    const EVERYWHERE: Self = Self {
        continents: (f64::NEG_INFINITY, f64::INFINITY),
        ridges: (f64::NEG_INFINITY, f64::INFINITY),
        hills: (f64::NEG_INFINITY, f64::INFINITY),
    };
}

/// The heights (in layers) of a chunk column's padded voxel columns, by
/// column, for the chunks of its other radial layers.
///
/// Why: a chunk's cost is almost all noise — 34 × 34 columns of about 40
/// Perlin octaves each — and the voxels of a column do not depend on the
/// layer. Around a streaming view a surface column holds 2–3 chunks (the
/// surface bounds allow for slope), so the heights are computed once, not
/// once per layer. A memo of a pure function: the voxels are the same
/// with or without it.
#[derive(Default)]
struct HeightCache {
    entries: Mutex<HeightEntries>,
    /// H in layers by lattice point `(face, i, j)` where the LOD tree's
    /// column bounds sample it (`column_relief`: at the LOD-0 columns whose
    /// far corners are each column's corners and centre). A node's
    /// children share its corners and centre and each other's edges: 8
    /// new points for 4 children instead of 20 (a 12°
    /// lens's tree has 276,000 nodes; full-height samples were 9 % of the
    /// view's CPU time). Emptied when it reaches `HEIGHT_CACHE_POINTS`.
    points: Mutex<HashMap<(CubeFace, i64, i64), f64>>,
}

/// Grid cells along each side of a column where
/// [`VoxelSource::surface_top_radius`] samples H.
const TOP_GRID: i64 = 8;

/// Lattice points [`HeightCache`] keeps at most: about 3 MB.
const HEIGHT_CACHE_POINTS: usize = 1 << 16;

/// The cached heights by column, and the columns oldest first. A column's
/// cell is made empty by the first thread to ask for it, which fills it;
/// others asking meanwhile wait for that one computation
/// ([`HeightCache::get_or_compute`]).
type HeightEntries = (HashMap<ChunkColumn, Arc<OnceLock<Arc<[Column]>>>>, VecDeque<ChunkColumn>);

/// One voxel column: its height in layers and the material of its top
/// voxel (by height and climate, see [`ProceduralPlanet::surface`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Column {
    /// H in layers, or within `slack` of it.
    height: f64,
    surface: Voxel,
    /// How far from H `height` may be, layers: 0 exactly when every octave
    /// is in; otherwise no voxel or material threshold of the LOD the
    /// column was made for lies within it (`ProceduralPlanet::columns_at`).
    /// Always 0 under a tunnel (`caves.near`).
    slack: f32,
    /// The caves under the column at the LOD it was made for.
    caves: ColumnCaves,
}

impl Column {
    /// A column not computed yet.
    const UNKNOWN: Self = Self { height: f64::NAN, surface: Voxel::AIR, slack: 0.0, caves: ColumnCaves::NONE };

    /// The voxel whose sample centre lies at `centre` layers over the base
    /// radius, for voxels `span` layers tall: by depth under the column's
    /// height, less its caves.
    #[inline]
    fn voxel(&self, centre: f64, span: f64) -> Voxel {
        let voxel = self.ground_voxel(centre, span);
        if voxel != Voxel::AIR && self.caves.holds(self.height - centre, centre) { Voxel::AIR } else { voxel }
    }

    /// [`Column::voxel`] without its caves: what it is where no tunnel
    /// passes over the column (`caves.near` false).
    #[inline]
    fn ground_voxel(&self, centre: f64, span: f64) -> Voxel {
        classify_depth(*self, self.height - centre, span)
    }

    /// Whether the voxel sampled at `centre` layers and everything above it
    /// is air: it is over the ground, or in a cave mouth's air.
    fn open_to_sky(&self, centre: f64, span: f64) -> bool {
        let depth = self.height - centre;
        depth <= 0.0 || self.caves.open_from_the_surface(depth, centre, span)
    }
}

impl HeightCache {
    /// `column`'s heights if they are made (never waits for a computation
    /// under way).
    fn get(&self, column: ChunkColumn) -> Option<Arc<[Column]>> {
        self.entries.lock().ok()?.0.get(&column)?.get().cloned()
    }

    /// `column`'s heights, made by `compute` if no thread has made them or
    /// is making them; while another thread is, it waits for its result.
    /// A streaming renderer's workers take a column's layers together
    /// (they share a priority), so without the wait two workers often
    /// computed the same column at once: 4,160 of the 15,171 columns
    /// computed for a hillside view (27 %) were such twins.
    fn get_or_compute(&self, column: ChunkColumn, compute: impl FnOnce() -> Arc<[Column]>) -> Arc<[Column]> {
        let cell = {
            let Ok(mut entries) = self.entries.lock() else { return compute() };
            let (map, order) = &mut *entries;
            let cell = map
                .entry(column)
                .or_insert_with(|| {
                    order.push_back(column);
                    Arc::default()
                })
                .clone();
            // The oldest go; one being computed lives on in its threads'
            // hands and is lost to later askers only.
            while order.len() > HEIGHT_CACHE_COLUMNS {
                if let Some(oldest) = order.pop_front() {
                    map.remove(&oldest);
                }
            }
            cell
        };
        cell.get_or_init(compute).clone()
    }

    /// H in layers at lattice point `(i, j)` of `face` if the memo has it.
    fn known(&self, face: CubeFace, i: i64, j: i64) -> Option<f64> {
        self.points.lock().ok()?.get(&(face, i, j)).copied()
    }

    /// H in layers at lattice point `(i, j)` of `face`, from the memo or
    /// from `compute`.
    fn point(&self, face: CubeFace, i: i64, j: i64, compute: impl FnOnce() -> f64) -> f64 {
        let known = self.points.lock().ok().and_then(|points| points.get(&(face, i, j)).copied());
        if let Some(h) = known {
            return h;
        }
        let h = compute();
        if let Ok(mut points) = self.points.lock() {
            if points.len() >= HEIGHT_CACHE_POINTS {
                points.clear();
            }
            points.insert((face, i, j), h);
        }
        h
    }
}

impl std::fmt::Debug for HeightCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let columns = self.entries.lock().map_or(0, |e| e.0.len());
        f.debug_struct("HeightCache").field("columns", &columns).finish()
    }
}

impl ProceduralPlanet {
    /// The caves (for tests).
    #[cfg(test)]
    pub(crate) fn caves(&self) -> &Caves {
        &self.caves
    }

    /// Whether columns of `lod` leave the deep cave network's layers out
    /// for an eye over the ground, and the rest for an eye in it
    /// (`layer_view`): where its
    /// air is sealed at this LOD. Neighbouring voxel columns `s` cells
    /// apart differ in height by at most `s·S` layers, and the networks'
    /// spans shrink by `(s − 1)/2` each at this LOD (`caves.rs`), so deep
    /// air touches no shallow or open air while `s·S + 2 ≤ separation +
    /// s − 1`; `SEALED_MARGIN` keeps 2 layers spare.
    fn hides_buried(&self, lod: u8) -> bool {
        let s = self.layout.voxel_span(lod) as f64;
        // (The separation is built as exactly this for s = 4; rounding in
        // rebuilding it must not turn LOD 2 off.)
        self.caves.at_lod(lod) && s * self.max_slope + SEALED_MARGIN <= self.caves.separation() + 1e-9
    }

    /// The version of the terrain code: the same settings give the same
    /// voxels within a version. Bump it with any change that moves a
    /// voxel (noise, octaves, slopes, materials), so that saved worlds are
    /// refused instead of replayed onto other ground; a test fingerprints
    /// the terrain to catch a forgotten bump.
    pub const TERRAIN_VERSION: u32 = 1;

    /// Builds the planet.
    ///
    /// # Errors
    /// [`VoxelError::NonFinite`] or [`VoxelError::OutOfRange`] for NaN,
    /// infinite, zero or negative parameters, an amplitude or detail
    /// amplitude of a quarter of the radius or more, or a voxel size that
    /// needs more than
    /// [`MAX_LOD`](crate::MAX_LOD) LODs.
    pub fn new(settings: PlanetSettings) -> Result<Self, VoxelError> {
        let positive = |name, value: f64| {
            if !value.is_finite() {
                Err(VoxelError::NonFinite { name, value })
            } else if value <= 0.0 {
                Err(VoxelError::OutOfRange { name, requirement: "> 0", value })
            } else {
                Ok(value)
            }
        };
        let radius = positive("radius", settings.radius)?;
        let voxel_size = positive("voxel size", settings.voxel_size)?;
        positive("feature size", settings.feature_size)?;
        positive("mountain size", settings.mountain_size)?;
        positive("detail size", settings.detail_size)?;
        if !settings.detail_amplitude.is_finite() {
            return Err(VoxelError::NonFinite { name: "detail amplitude", value: settings.detail_amplitude });
        }
        if !settings.amplitude.is_finite() {
            return Err(VoxelError::NonFinite { name: "amplitude", value: settings.amplitude });
        }
        if !(0.0..radius / 4.0).contains(&settings.detail_amplitude) {
            return Err(VoxelError::OutOfRange {
                name: "detail amplitude",
                requirement: "≥ 0 and below a quarter of the radius",
                value: settings.detail_amplitude,
            });
        }
        for (name, value) in [
            ("octave grid", settings.octave_grid),
            ("octave grid error", settings.octave_grid_error),
            ("band limit", settings.band_limit),
        ] {
            if !value.is_finite() {
                return Err(VoxelError::NonFinite { name, value });
            }
            if value < 0.0 {
                return Err(VoxelError::OutOfRange { name, requirement: "≥ 0", value });
            }
        }
        if !(0.0..radius / 4.0).contains(&settings.amplitude) {
            return Err(VoxelError::OutOfRange {
                name: "amplitude",
                requirement: "≥ 0 and below a quarter of the radius",
                value: settings.amplitude,
            });
        }
        // Chunks per face edge at LOD 0 = 2^max_lod, as close as a power of
        // two gets to the wanted voxel size (in log space).
        let wanted = radius * std::f64::consts::FRAC_PI_2 / voxel_size / f64::from(CHUNK_SIZE);
        let max_lod = wanted.log2().round().max(0.0);
        if max_lod > f64::from(MAX_LOD) {
            return Err(VoxelError::OutOfRange {
                name: "voxel size",
                requirement: "large enough for at most 24 LODs",
                value: voxel_size,
            });
        }
        let max_lod = max_lod as u8;
        let resolution = CHUNK_SIZE << max_lod;
        let layer_height = radius * std::f64::consts::FRAC_PI_2 / f64::from(resolution);
        let sphere = Cubesphere::new(radius, resolution, layer_height, SphereMap::EquiAngular)?;
        let layout = ChunkLayout::new(sphere, max_lod)?;
        // Enough octaves that the finest wavelength is about 4 voxels.
        let octaves_for = |wavelength: f64| (wavelength / (4.0 * layer_height)).log2().ceil().clamp(1.0, 16.0) as usize;
        let continents = Fractal::fbm(settings.seed, octaves_for(settings.feature_size), 0.45, 2.0);
        let ridges = Fractal::ridged(settings.seed.wrapping_add(1), octaves_for(settings.mountain_size), 2.0);
        let hill_octaves = (settings.detail_size / (4.0 * layer_height)).log2().ceil().clamp(1.0, 12.0) as usize;
        let hills = Fractal::fbm(settings.seed.wrapping_add(2), hill_octaves, 0.5, std::f64::consts::PI * 2.0 / 3.0);
        // No caves until the slopes are known (they set how far apart the
        // two networks must lie); the size is checked now.
        Caves::new(settings.cave_size, radius, layer_height, max_lod, settings.seed, 0.0)?;
        let (noise_scale, ridge_scale, detail_scale) =
            (radius / settings.feature_size, radius / settings.mountain_size, radius / settings.detail_size);
        // A lattice cell is at most this many radians across along an axis
        // (the equi-angular map's cells are widest at the middle of a face
        // edge: (π/2)/N); the bounds' reach takes 1 % more for rounding.
        let cell_angle = std::f64::consts::FRAC_PI_2 / f64::from(resolution);
        let gridded = |fractal: &Fractal, scale: f64, sum: usize| {
            // How fast H changes with this sum, at most: a unit step of it
            // alone, anywhere.
            let mut unit = [0.0; 3];
            unit[sum] = 1.0;
            let metres_per_unit = height_step(&settings, SumRanges::EVERYWHERE, unit);
            let coarse = CoarseGrids { metres_per_unit, error: settings.octave_grid_error };
            // A unit of noise space is 1/scale radians.
            let levels = OctaveLevels::new(fractal, 1.0 / (scale * cell_angle), settings.octave_grid, coarse);
            let widen = levels.reach().iter().map(|cells| cells * cell_angle * 1.01 * scale).collect();
            (levels, widen)
        };
        let (continents_levels, continents_widen) = gridded(&continents, noise_scale, 0);
        let (ridges_levels, ridges_widen) = gridded(&ridges, ridge_scale, 1);
        let (hills_levels, hills_widen) = gridded(&hills, detail_scale, 2);
        let mut planet = Self {
            caves: Caves::new(0.0, radius, layer_height, max_lod, settings.seed, 0.0)?,
            detail_scale,
            hills,
            noise_scale,
            ridge_scale,
            levels: [continents_levels, ridges_levels, hills_levels],
            widen: [continents_widen, ridges_widen, hills_widen],
            settings,
            layout,
            continents,
            ridges,
            layer_height,
            sum_steps: [0.0; 3],
            max_slope: 0.0,
            bands: Vec::new(),
            heights: Arc::default(),
        };
        planet.bands = (0..=max_lod).map(|lod| planet.band_limited(lod)).collect();
        let (sum_steps, max_slope) = planet.measure_slopes();
        planet.sum_steps = sum_steps;
        // Both bound the slope everywhere; the second, sum by sum, is the
        // one `surface_bounds` narrows place by place.
        planet.max_slope = max_slope.min(planet.slope_within(SumRanges::EVERYWHERE));
        // The deep network sealed at LODs 0–2 (`hides_buried`).
        let separation = SEALED_SPAN * planet.max_slope + SEALED_MARGIN;
        planet.caves =
            Caves::new(planet.settings.cave_size, radius, layer_height, max_lod, planet.settings.seed, separation)?;
        Ok(planet)
    }

    /// The sums LOD `lod`'s columns are made of ([`BandLimited`]): each
    /// keeps its octaves of a wavelength of at least
    /// [`PlanetSettings::band_limit`] voxels of the LOD (every octave at
    /// LOD 0, or with a band limit of 0).
    fn band_limited(&self, lod: u8) -> BandLimited {
        let voxel_m = self.layout.voxel_span(lod) as f64 * self.layer_height;
        let shortest = if lod == 0 { 0.0 } else { self.settings.band_limit * voxel_m };
        let settings = &self.settings;
        let sums = [
            (&self.continents, settings.feature_size),
            (&self.ridges, settings.mountain_size),
            (&self.hills, settings.detail_size),
        ];
        // A unit of noise space is the sum's size along the surface, and
        // octave k's wavelength its size over the lacunarity to the k.
        let kept = sums.map(|(fractal, size)| {
            (0..fractal.octaves()).take_while(|&k| size / fractal.lacunarity().powi(k as i32) >= shortest).count()
        });
        // What the octaves left out add at most, each sum through H's
        // steepest response to it anywhere.
        let tails = [0, 1, 2].map(|n| {
            let fractal = sums[n].0;
            (kept[n]..fractal.octaves()).map(|k| fractal.octave_amplitude(k)).sum::<f64>()
        });
        let dropped = self.tails_reach(tails, SumRanges::EVERYWHERE);
        BandLimited {
            sums: [0, 1, 2].map(|n| sums[n].0.with_octaves(kept[n])),
            levels: [0, 1, 2].map(|n| self.levels[n].with_octaves(kept[n])),
            tails,
            dropped,
        }
    }

    /// How far, layers, the octaves LOD `lod`'s sums leave out
    /// ([`BandLimited`]) can move H where the full sums lie in `ranges`:
    /// each sum's tail through H's steepest response to it there (the
    /// ranges widened by the tails, where the partial sums may lie), as
    /// the slope bound goes place by place. In lowland the ridges' tail
    /// moves nothing and the hills' little; over mountains it is most of
    /// [`BandLimited::dropped`], the bound anywhere.
    fn dropped_within(&self, lod: u8, ranges: SumRanges) -> f64 {
        self.tails_reach(self.bands[usize::from(lod)].tails, ranges)
    }

    /// How far, layers, sums off by at most `tails` (noise units) can move
    /// H where the exact sums lie in `ranges` (see [`Self::dropped_within`]).
    fn tails_reach(&self, tails: [f64; 3], ranges: SumRanges) -> f64 {
        if tails.iter().all(|&t| t == 0.0) {
            return 0.0;
        }
        let widen = |(low, high): (f64, f64), tail: f64| (low - tail, high + tail);
        let widened = SumRanges {
            continents: widen(ranges.continents, tails[0]),
            ridges: widen(ranges.ridges, tails[1]),
            hills: widen(ranges.hills, tails[2]),
        };
        height_step(&self.settings, widened, tails) / self.layer_height
    }

    /// The same planet with an empty height cache of its own (clones share
    /// theirs): every column computed afresh, the same voxels. What a cold
    /// start costs, and what the cache's tests compare against.
    #[must_use]
    pub fn with_empty_cache(&self) -> Self {
        Self { heights: Arc::default(), ..self.clone() }
    }

    /// The settings the planet was built from.
    #[must_use]
    pub fn settings(&self) -> &PlanetSettings {
        &self.settings
    }

    /// The voxel edge at LOD 0 actually used, metres (also the radial layer
    /// height).
    #[must_use]
    pub fn voxel_size(&self) -> f64 {
        self.layer_height
    }

    /// S in the error bound: steepest height change per lattice step, in
    /// layers per cell.
    #[must_use]
    pub fn max_slope(&self) -> f64 {
        self.max_slope
    }

    /// The point on the terrain surface (height 0 plus [`Self::height_at`])
    /// in direction `direction` (any length).
    #[must_use]
    pub fn surface_point(&self, direction: nebula_math::DVec3) -> nebula_math::DVec3 {
        let direction = direction.normalize();
        direction * (self.settings.radius + self.height_at(direction))
    }

    /// Terrain height above the base radius, metres, in unit direction
    /// `direction` (NaN for a direction that is not finite or is zero).
    /// At a voxel column's centre it is the column's height: between
    /// columns the grids' octaves (`octave_grid.rs`) blend bilinearly on
    /// the face the direction lies on.
    #[must_use]
    pub fn height_at(&self, direction: nebula_math::DVec3) -> f64 {
        let Ok((face, i, j)) = self.layout.sphere().face_coords_of(direction) else { return f64::NAN };
        let [continents, ridges, hills] = self.sums_at_columns(face, &[[i - 0.5, j - 0.5]], &[direction], 1, 0)[0];
        self.combine(continents, ridges, hills)
    }

    /// [`grid_states`] of the three sums at `points` of `face`, as LOD
    /// `band` keeps them ([`BandLimited`]).
    fn grid_states(
        &self,
        face: CubeFace,
        points: &[[f64; 2]],
        spacing: i64,
        band: u8,
    ) -> [(usize, Vec<OctaveState>); 3] {
        grid_states(self.layout.sphere(), face, self.gridded(band), points, spacing)
    }

    /// The three sums as [`grid_states`] reads them, as LOD `band` keeps
    /// them ([`BandLimited`]; LOD 0: H's).
    fn gridded(&self, band: u8) -> [GriddedSum<'_>; 3] {
        let BandLimited {
            sums: [continents, ridges, hills],
            levels: [continents_levels, ridges_levels, hills_levels],
            ..
        } = &self.bands[usize::from(band)];
        [
            GriddedSum { fractal: continents, scale: self.noise_scale, levels: continents_levels },
            GriddedSum { fractal: ridges, scale: self.ridge_scale, levels: ridges_levels },
            GriddedSum { fractal: hills, scale: self.detail_scale, levels: hills_levels },
        ]
    }

    /// The three noise sums of [`Self::combine`] at `points` (LOD-0 column
    /// coordinates on `face`, whole or not) in unit `directions` (one per
    /// point, its direction), every octave LOD `band` keeps in
    /// ([`BandLimited`]; LOD 0 keeps all, H itself): those of grids
    /// coarser than `spacing` interpolated (`octave_grid.rs`), the rest
    /// evaluated at the direction. A column of LOD `L` (its far-corner LOD-0 column)
    /// may ask with spacing `2^L`, a whole column with the largest power
    /// of two that its indices plus one share: the same sums either way.
    fn sums_at_columns(
        &self,
        face: CubeFace,
        points: &[[f64; 2]],
        directions: &[nebula_math::DVec3],
        spacing: i64,
        band: u8,
    ) -> Vec<[f64; 3]> {
        let levels = &self.bands[usize::from(band)].levels;
        // Every octave direct (a node of every grid, the LOD tree's bound
        // samples among them): the sums as `Fractal::get` gives them, bit
        // for bit what the batches would.
        if levels.iter().all(|levels| levels.exact_at(spacing)) {
            return directions
                .iter()
                .map(|d| self.gridded(band).map(|sum| sum.fractal.get((*d * sum.scale).to_array())))
                .collect();
        }
        let resumed = self.grid_states(face, points, spacing, band);
        let all: Vec<usize> = (0..points.len()).collect();
        let mut out = vec![[0.0; 3]; points.len()];
        for (n, (sum, (start, states))) in self.gridded(band).iter().zip(&resumed).enumerate() {
            let fractal = sum.fractal;
            let noise_points: Vec<[f64; 3]> = directions.iter().map(|d| (*d * sum.scale).to_array()).collect();
            let mut batch = fractal.resume(&noise_points, states, *start);
            while !batch.done(fractal) {
                fractal.step(&mut batch, &all);
            }
            for (k, out) in out.iter_mut().enumerate() {
                out[n] = fractal.bounds(&batch, k).0;
            }
        }
        out
    }

    /// The ranges of the three noise sums over a ball of directions (unit
    /// centre, radius in radians; [`Self::patch_ball`] of a square of
    /// lattice cells): H over it
    /// lies between [`Self::combine`] of their ends (`heights`), and its
    /// slope within [`Self::slope_within`] of them.
    ///
    /// Every direction of a square lies within the angle to its farthest
    /// corner or edge middle of the centre's (its edges are great-circle
    /// arcs; 1 % more for rounding), so each noise sum lies in its range over that ball
    /// ([`Fractal::range_near`]), and H, which rises with each sum
    /// ([`Self::combine`]: the ridges and the mask are never negative),
    /// between the heights of the ranges' ends.
    ///
    /// Why: S times the distance (the five-sample bound) grows without end
    /// with a column's size, while H's range is that of the octaves coarse
    /// enough to matter; at LOD 9 on an Earth S allows kilometres where the
    /// terrain varies by hundreds of metres.
    fn sum_ranges(&self, (centre, reach): (nebula_math::DVec3, f64)) -> SumRanges {
        let [continents, ridges, hills] =
            self.gridded(0).map(|sum| (sum.fractal, (centre * sum.scale).to_array(), reach * sum.scale));
        SumRanges {
            continents: continents.0.range_near(continents.1, continents.2, &self.widen[0]),
            ridges: ridges.0.range_near(ridges.1, ridges.2, &self.widen[1]),
            hills: hills.0.range_near(hills.1, hills.2, &self.widen[2]),
        }
    }

    /// The ball (unit centre direction, radius in radians) that holds the
    /// square of lattice cells `[i − half, i + half] × [j − half, j + half]`
    /// on `face` ([`Self::sum_ranges`]).
    fn patch_ball(&self, face: CubeFace, (i, j): (f64, f64), half: f64) -> (nebula_math::DVec3, f64) {
        let sphere = self.layout.sphere();
        // The nine points share three warped coordinates along each axis:
        // six `tan`s, not eighteen (they were a tenth of a narrow lens's
        // first frame). Index 1 is the centre's (`i + 0·half` is `i`).
        let warped = |c: f64| [-1.0, 0.0, 1.0].map(|a: f64| sphere.warp(c + a * half));
        let (warped_i, warped_j) = (warped(i), warped(j));
        let centre = sphere.direction_warped(face, warped_i[1], warped_j[1]);
        // The largest angle is the smallest cosine: one `acos`, not eight.
        let mut cosine = 1.0_f64;
        for (a, b) in [(0, 0), (2, 0), (0, 2), (2, 2), (1, 0), (1, 2), (0, 1), (2, 1)] {
            cosine = cosine.min(centre.dot(sphere.direction_warped(face, warped_i[a], warped_j[b])));
        }
        // A chord is shorter than its angle; 1 % more for rounding.
        (centre, cosine.clamp(-1.0, 1.0).acos() * 1.01)
    }

    /// Bounds `(low, high)`, in layers, of H where the sums lie in `ranges`.
    fn heights(&self, ranges: SumRanges) -> (f64, f64) {
        let SumRanges { continents, ridges, hills } = ranges;
        (
            self.combine(continents.0, ridges.0, hills.0) / self.layer_height,
            self.combine(continents.1, ridges.1, hills.1) / self.layer_height,
        )
    }

    /// The steepest H changes per lattice step, layers per cell, where the
    /// sums lie in `ranges`: each sum's steepest step
    /// ([`Self::measure_slopes`]) through [`Self::combine`] as if all
    /// three were at their steepest at once, each factor at its largest in
    /// `ranges` (a product `f·g` steps by at most `Δf·max g + max f·Δg`).
    ///
    /// Why not H's own steepest step, sampled: the mountains cover a few
    /// per cent of a planet and are steepest along their crests, which
    /// random places seldom hit (4,096 of them put S at 0.77 layers per
    /// cell on an Earth whose ranges reach 1.3). Each sum on its own is
    /// alike everywhere, so its steepest step is found at places of any
    /// kind, and the worst case covers the places where they add up. Where
    /// no mountain can be (the lowlands, most of a planet) the bound is
    /// that of the continents and hills alone.
    fn slope_within(&self, ranges: SumRanges) -> f64 {
        height_step(&self.settings, ranges, self.sum_steps) / self.layer_height
    }

    /// The voxel columns in `directions` for voxels `span` layers tall:
    /// the voxels and material each gets from its exact height
    /// ([`Self::height_at`]), from as few octaves as decide them.
    ///
    /// Each octave runs over all the columns still open, a run of
    /// neighbouring columns in one noise cell paying its corner hashes once
    /// and two neighbours in one cell blended at once in SIMD lanes
    /// ([`Fractal::step`]). A column depends on H only through comparisons
    /// with thresholds (`undecided_apart_from_edges`, `meets_edges`):
    /// voxel centres every `span` layers, the depths where dirt and stone
    /// begin, and the material heights.
    /// The three sums go coarse octaves first, and a column leaves once the
    /// bounds of its height ([`Fractal::bounds`] through `combine`, which
    /// rises with each sum) hold no threshold; its height is then the
    /// middle of them, which every comparison treats as it treats H. A
    /// column kept to the last octave has H bit for bit (H of the octaves
    /// the LOD keeps, [`BandLimited`]). Coarse voxels are
    /// tens to thousands of layers tall, so most columns there leave long
    /// before the octaves of a metre or less; at LOD 0 few do.
    ///
    /// `resumed` holds each sum's octaves from grids ([`grid_states`]):
    /// the octave it goes on from and the state there, by column.
    fn columns_at(
        &self,
        directions: &[nebula_math::DVec3],
        resumed: [(usize, Vec<OctaveState>); 3],
        lod: u8,
        caves_possible: bool,
    ) -> Vec<Column> {
        let span = self.layout.voxel_span(lod) as f64;
        // The sums as this LOD keeps them (`BandLimited`).
        let [continents_sum, ridges_sum, hills_sum] = &self.bands[usize::from(lod)].sums;
        // The caves first: a column under a tunnel needs its exact height.
        let caves: Vec<ColumnCaves> = if caves_possible && self.caves.at_lod(lod) {
            self.caves.columns(directions, span)
        } else {
            vec![ColumnCaves::NONE; directions.len()]
        };
        // A sum the grids finished (the continents at LOD 0) steps no
        // more: its points are never read.
        let points = |fractal: &Fractal, start: usize, scale: f64| -> Vec<[f64; 3]> {
            if start >= fractal.octaves() {
                return Vec::new();
            }
            directions.iter().map(|d| (*d * scale).to_array()).collect()
        };
        let [continents, ridges, hills] = &resumed;
        let mut batches = [
            continents_sum.resume(&points(continents_sum, continents.0, self.noise_scale), &continents.1, continents.0),
            ridges_sum.resume(&points(ridges_sum, ridges.0, self.ridge_scale), &ridges.1, ridges.0),
            hills_sum.resume(&points(hills_sum, hills.0, self.detail_scale), &hills.1, hills.0),
        ];
        let mut columns = vec![Column::UNKNOWN; directions.len()];
        let mut open: Vec<usize> = (0..directions.len()).collect();
        // The columns whose ridges can still matter. Where the continents
        // sum ends at or below `MOUNTAIN_START` the mountain mask is 0, so
        // H and the climate are the same bit for bit whatever the ridges
        // add (`combine`: `mountains` is their term times the mask): such a
        // column's ridges stop at the octave that shows it (most of a
        // planet's lowland and sea; 16 of an Earth column's 44 octaves).
        let mut ridged: Vec<usize> = open.clone();
        // The material thresholds by column, once (each look uses them),
        // with the chunk's shared climate ranges until a column needs its
        // own edges.
        let mut thresholds = self.surface_thresholds_over(directions);
        let voxel_m = span * self.layer_height;
        let (amplitude, detail_amplitude) = (self.settings.amplitude, self.settings.detail_amplitude);
        // Looks are counted from the first round whose octaves left could,
        // even at best, leave a voxel's height of room (the fBm sums' rest
        // through `combine`'s least slopes): a look costs about what an
        // octave does, so there is one then and every other round after.
        let mut eligible_rounds = 0_usize;
        loop {
            let [continents, ridges, hills] = &mut batches;
            continents_sum.step(continents, &open);
            // The continents' bounds only narrow as octaves come in (each
            // adds at most the weight `rest` allowed for), so a column
            // whose high end is below the mountains' start stays there; a
            // millionth spare for rounding. A column decided at the last
            // look (its height no longer NaN) has left `open` and leaves
            // here too: `ridged` stays within `open`.
            ridged.retain(|&k| {
                columns[k].height.is_nan() && continents_sum.bounds(continents, k).1 > MOUNTAIN_START - 1e-6
            });
            ridges_sum.step(ridges, &ridged);
            // The hills' octaves wait while the continents' still to come
            // can move H four times as far as theirs (through `combine`'s
            // steepest slope, and the hills' roughest where a column may
            // rise into mountains): a column decided meanwhile never needs
            // them, as most of a coarse chunk's are (its voxels are
            // hundreds of metres tall; a plain's hills, tens). Which sums
            // are stepped changes no voxel: the looks go by the bounds.
            let roughest = if ridged.is_empty() { 1.0 } else { 1.0 + MOUNTAIN_ROUGHNESS };
            let continents_left = amplitude * OCEAN_SLOPE * continents_sum.fbm_rest(continents.octave());
            let hills_left = detail_amplitude * roughest * hills_sum.fbm_rest(hills.octave());
            if 4.0 * hills_left >= continents_left || continents.done(continents_sum) {
                hills_sum.step(hills, &open);
            }
            let last = batches[0].done(continents_sum) && batches[1].done(ridges_sum) && batches[2].done(hills_sum);
            if !last {
                let best = 2.0 * amplitude * LAND_SLOPE * continents_sum.fbm_rest(batches[0].octave())
                    + detail_amplitude * hills_sum.fbm_rest(batches[2].octave());
                if best >= voxel_m {
                    continue;
                }
                eligible_rounds += 1;
                if eligible_rounds.is_multiple_of(2) {
                    continue;
                }
            }
            let continents_spread = voxel_m / (LAND_SLOPE * self.settings.amplitude);
            let ends_at = |k: usize| {
                let (c_low, c_high) = continents_sum.bounds(&batches[0], k);
                let (r_low, r_high) = ridges_sum.bounds(&batches[1], k);
                let (h_low, h_high) = hills_sum.bounds(&batches[2], k);
                let (m_low, m_high) = (self.mountains(c_low, r_low), self.mountains(c_high, r_high));
                LookEnds {
                    continents: (c_low, c_high),
                    mountains: (m_low, m_high),
                    heights: (self.height_of(c_low, m_low, h_low), self.height_of(c_high, m_high, h_high)),
                }
            };
            // A look decides no column whose ends of H lie a voxel or more
            // apart (they hold a voxel threshold): where 16 columns spread
            // over the open ones all do, this look is skipped (staying open
            // is always safe). On a mountain's slopes the hills are taller
            // than the eligibility above allows for (their roughness): a
            // high-mountain LOD-0 chunk's first look decided none of its
            // 1,156 columns. Skipped to the next look, not the next round:
            // a look a round later was slower (mountains 158 → 167 µs).
            if !last && open.len() >= 64 {
                let step = open.len() / 16;
                let sampled = open.iter().step_by(step).take(16);
                if sampled.map(|&k| ends_at(k).heights).all(|(low, high)| high - low >= voxel_m) {
                    continue;
                }
            }
            // Each open column's ends of H and of the climate first, in one
            // pass with no branch between columns (their arithmetic
            // overlaps), then the tests.
            let ends: Vec<LookEnds> = open.iter().map(|&k| ends_at(k)).collect();
            let mut ends = ends.into_iter();
            open.retain(|&k| {
                let LookEnds { continents: (c_low, c_high), mountains: (m_low, m_high), heights: (low, high) } =
                    ends.next().expect("one per open column");
                if !last && caves[k].near {
                    return true;
                }
                // The continents alone spread H by at least
                // LAND_SLOPE·amplitude per unit (`combine`, short of its clamp): a spread of a voxel or
                // more holds a voxel threshold, so such a column stays open
                // without the full test (staying open is always safe).
                if !last && c_high - c_low >= continents_spread {
                    return true;
                }
                // The climate's ranges, as H's (`mountains` rises with both sums).
                let climates = [(c_low, m_low), (c_high, m_high)].map(|(continents, mountains)| Climate {
                    sin_latitude: directions[k].z,
                    continents,
                    mountains,
                });
                if !last && self.undecided_apart_from_edges(low, high, climates, &thresholds[k], span) {
                    return true;
                }
                if !last && meets_edges(climates, &thresholds[k]) {
                    // The chunk's shared climate ranges hold the column's
                    // own edges: where they alone leave it open, its own
                    // may not (over a coarse chunk they span degrees).
                    // Looked up only then: a column open for its height
                    // stays open whatever its edges (three `exp`s a look
                    // were 7 % of a LOD-5 chunk).
                    if thresholds[k].exact() {
                        return true;
                    }
                    thresholds[k] = self.surface_thresholds(directions[k].z);
                    if meets_edges(climates, &thresholds[k]) {
                        return true;
                    }
                }
                let height = if last { low } else { 0.5 * (low + high) };
                // Where no threshold lies between the ends, the middle
                // classifies as any point between them does.
                let climate = Climate {
                    continents: 0.5 * (climates[0].continents + climates[1].continents),
                    mountains: 0.5 * (climates[0].mountains + climates[1].mountains),
                    ..climates[0]
                };
                // Rounded up (f32), so the slack still holds H; never 0
                // unless every octave is in (0 means exact).
                let slack = if last {
                    0.0
                } else {
                    ((0.5 * (high - low) / self.layer_height * (1.0 + 1e-6)) as f32).max(f32::MIN_POSITIVE)
                };
                columns[k] = Column { slack, caves: caves[k], ..self.sample(height, climate, &thresholds[k]) };
                false
            });
            // At the last octave every column is decided.
            if open.is_empty() || last {
                break;
            }
        }
        columns
    }

    /// Whether any threshold a column is compared against lies between
    /// heights `low` and `high` or between the two `climates`: its edges
    /// ([`meets_edges`]) or the rest ([`Self::undecided_apart_from_edges`]).
    #[cfg(test)]
    fn undecided(
        &self,
        low: f64,
        high: f64,
        climates: [Climate; 2],
        thresholds: &SurfaceThresholds,
        span: f64,
    ) -> bool {
        meets_edges(climates, thresholds) || self.undecided_apart_from_edges(low, high, climates, thresholds, span)
    }

    /// Whether some threshold a column of `span`-layer voxels is compared
    /// against lies between heights `low` and `high` (metres) or between
    /// the mountains terms of the two `climates`, give or take rounding: a
    /// height or mountains threshold ([`Self::surface_thresholds`]), or in
    /// layers a voxel centre (`(h + 1)·span − 1/2`) or the depth below one
    /// where dirt gives way to stone (3 layers more, `classify_depth`).
    /// The climate's edges are the rest a column waits on
    /// ([`meets_edges`]). (It was kept out of line while the voxel fill
    /// shared `columns_at`'s function, whose loop it slowed; the fill is
    /// its own function now, and inlined it measures the same or 1–2 %
    /// faster.)
    #[inline]
    fn undecided_apart_from_edges(
        &self,
        low: f64,
        high: f64,
        [least, most]: [Climate; 2],
        thresholds: &SurfaceThresholds,
        span: f64,
    ) -> bool {
        let between = |t: f64, low: f64, high: f64| low - ROUNDING <= t && t <= high + ROUNDING;
        thresholds.heights.iter().any(|&t| between(t, low, high))
            || between(thresholds.mountains, least.mountains, most.mountains)
            || self.undecided_voxels((low - ROUNDING) / self.layer_height, (high + ROUNDING) / self.layer_height, span)
    }

    /// The voxel thresholds of [`Self::undecided_apart_from_edges`], heights in layers.
    fn undecided_voxels(&self, low: f64, high: f64, span: f64) -> bool {
        // `span` is a power of two: times its inverse is the quotient to the
        // bit, without a division's latency.
        let inverse = 1.0 / span;
        [-0.5, 2.5].iter().any(|&offset| offset + span * ceil((low - offset) * inverse) <= high)
    }

    /// The height from the three noise sums at a point (module docs).
    fn combine(&self, continents: f64, ridges: f64, hills: f64) -> f64 {
        self.height_of(continents, self.mountains(continents, ridges), hills)
    }

    /// [`Self::combine`] with its mountains term already known.
    #[inline]
    fn height_of(&self, continents: f64, mountains: f64, hills: f64) -> f64 {
        let hills = unit_hills(hills);
        let slope = if continents < 0.0 { OCEAN_SLOPE } else { LAND_SLOPE };
        self.settings.amplitude * (slope * continents + MOUNTAIN_SHARE * mountains).clamp(-1.0, 1.0)
            + self.settings.detail_amplitude * hills * (1.0 + MOUNTAIN_ROUGHNESS * mountains)
    }

    /// The mountains term of [`Self::combine`] in `[0, 1]`, from the
    /// continents and ridges sums: it rises with each.
    fn mountains(&self, continents: f64, ridges: f64) -> f64 {
        unit_ridges(ridges).powi(MOUNTAIN_SHARPNESS) * mountain_mask(continents)
    }

    /// H in layers at lattice points `corners` of `face` (each a multiple
    /// of `spacing`, a power of two): at each, that of the LOD-0 column
    /// whose far corner it is (a node of every grid of `spacing` or finer),
    /// through the memo of the LOD tree's bound samples. Those the memo
    /// does not have are summed together, so that the coarse octave grids'
    /// nodes around them are made once, not once per corner.
    fn corner_heights(&self, face: CubeFace, spacing: i64, corners: &[(i64, i64)]) -> Vec<f64> {
        let mut heights: Vec<Option<f64>> = corners.iter().map(|&(i, j)| self.heights.known(face, i, j)).collect();
        let missing: Vec<(i64, i64)> =
            corners.iter().zip(&heights).filter(|(_, h)| h.is_none()).map(|(&c, _)| c).collect();
        if !missing.is_empty() {
            // A lattice point's column is the one below and left of it.
            let points: Vec<[f64; 2]> = missing.iter().map(|&(i, j)| [(i - 1) as f64, (j - 1) as f64]).collect();
            let sphere = self.layout.sphere();
            let directions: Vec<nebula_math::DVec3> =
                points.iter().map(|&[u, v]| sphere.direction(face, u + 0.5, v + 0.5)).collect();
            let sums = self.sums_at_columns(face, &points, &directions, spacing, 0);
            let mut made = missing.iter().zip(sums).map(|(&(i, j), [c, r, h])| {
                let height = self.combine(c, r, h) / self.layer_height;
                debug_assert_eq!(height.to_bits(), self.column_height_layers(face, i - 1, j - 1).to_bits());
                self.heights.point(face, i, j, || height)
            });
            for height in heights.iter_mut().filter(|h| h.is_none()) {
                *height = made.next();
            }
        }
        heights.into_iter().map(|h| h.unwrap_or(f64::NAN)).collect()
    }

    /// The highest H in layers at lattice points `corners` (`(i, j,
    /// shared)`, `shared`: whether the memo of [`Self::corner_heights`] may
    /// have it; each a multiple of `spacing`, a power of two: their columns
    /// are nodes of the grids of that spacing and finer), the highest of
    /// their heights or over it by at most `tolerance` layers (0: bit for
    /// bit):
    /// the octaves of coarser grids come interpolated at all the corners
    /// at once ([`grid_states`]), then the three sums go octave by octave
    /// over the corners still open, and a corner whose H can no longer
    /// reach the highest lower bound of another's leaves (its H is at most
    /// that other's), until those left are within `tolerance` of it. The memo's heights are used where it has them; a
    /// tight top samples 81 corners, and summing every octave of each was
    /// most of the LOD thread's noise. (Corner by corner, each making the
    /// coarser grids' nodes of its own, the tops of LOD-0 and LOD-1
    /// columns took 895 and 524 µs each, over 70 % of the tops' time
    /// through a 12° lens.)
    fn highest_height(
        &self,
        face: CubeFace,
        spacing: i64,
        corners: impl Iterator<Item = (i64, i64, bool)>,
        tolerance: f64,
    ) -> f64 {
        let sphere = self.layout.sphere();
        // The corners to sum: those the memo does not have.
        let mut highest_known = f64::NEG_INFINITY;
        let mut summed = Vec::new();
        for (i, j, shared) in corners {
            match shared.then(|| self.heights.known(face, i, j)).flatten() {
                Some(height) => highest_known = highest_known.max(height),
                None => summed.push((i, j)),
            }
        }
        let directions: Vec<nebula_math::DVec3> =
            summed.iter().map(|&(i, j)| sphere.direction(face, (i - 1) as f64 + 0.5, (j - 1) as f64 + 0.5)).collect();
        let points = |scale: f64| -> Vec<[f64; 3]> { directions.iter().map(|d| (*d * scale).to_array()).collect() };
        let fractals = [&self.continents, &self.ridges, &self.hills];
        // A lattice point's column is the one below and left of it.
        let columns: Vec<[f64; 2]> = summed.iter().map(|&(i, j)| [(i - 1) as f64, (j - 1) as f64]).collect();
        debug_assert!(summed.iter().all(|&(i, j)| i % spacing == 0 && j % spacing == 0));
        let [continents, ridges, hills] = self.grid_states(face, &columns, spacing, 0);
        let mut batches = [
            self.continents.resume(&points(self.noise_scale), &continents.1, continents.0),
            self.ridges.resume(&points(self.ridge_scale), &ridges.1, ridges.0),
            self.hills.resume(&points(self.detail_scale), &hills.1, hills.0),
        ];
        // In metres: the highest lower bound so far.
        let mut floor = highest_known * self.layer_height;
        let mut open: Vec<usize> = (0..directions.len()).collect();
        let mut highs = vec![f64::NEG_INFINITY; directions.len()];
        while !open.is_empty() {
            for (fractal, batch) in fractals.iter().zip(&mut batches) {
                fractal.step(batch, &open);
            }
            let last = fractals.iter().zip(&batches).all(|(fractal, batch)| batch.done(fractal));
            for &k in &open {
                let [c, r, h] = [0, 1, 2].map(|n| fractals[n].bounds(&batches[n], k));
                floor = floor.max(self.combine(c.0, r.0, h.0));
                highs[k] = self.combine(c.1, r.1, h.1);
            }
            if last {
                break;
            }
            // `combine` rises with each sum: a corner whose bound is under
            // another's lower bound is lower than it (a micrometre spare
            // for the sums' rounding).
            open.retain(|&k| highs[k] >= floor - ROUNDING);
            // Done once every corner left is within the tolerance of the
            // highest lower bound: the highest upper bound is then at most
            // that over the highest H (the octaves left would only bring
            // it down to it).
            if open.iter().all(|&k| highs[k] - floor <= tolerance * self.layer_height) {
                break;
            }
        }
        let highest = open.iter().map(|&k| highs[k] / self.layer_height).fold(highest_known, f64::max);
        #[cfg(debug_assertions)]
        {
            let exact = summed
                .iter()
                .map(|&(i, j)| self.column_height_layers(face, i - 1, j - 1))
                .fold(highest_known, f64::max);
            debug_assert!(highest >= exact && highest <= exact + tolerance + 1e-9, "{highest} for {exact}");
        }
        highest
    }

    /// Height in layers of LOD-0 column `(i, j)` of `face` (which may lie
    /// just past the face's edge: the face's own grids and map, extended).
    fn column_height_layers(&self, face: CubeFace, i: i64, j: i64) -> f64 {
        // The grids whose nodes include this column are evaluated there.
        let spacing = 1_i64 << (i + 1).trailing_zeros().min((j + 1).trailing_zeros()).min(62);
        let direction = self.layout.sphere().direction(face, i as f64 + 0.5, j as f64 + 0.5);
        let [continents, ridges, hills] =
            self.sums_at_columns(face, &[[i as f64, j as f64]], &[direction], spacing, 0)[0];
        self.combine(continents, ridges, hills) / self.layer_height
    }

    /// Height in layers of voxel column `(ci, cj)` at `lod`: at the centre
    /// of its far-corner LOD-0 column (see the module docs). Columns beyond
    /// a face edge are read on the neighbouring face, in that face's frame.
    /// In the gap beyond two edges (a cube corner) the nearest column on the
    /// face stands in: such voxels are never face neighbours of a chunk's
    /// own.
    fn column(&self, face: CubeFace, lod: u8, ci: i64, cj: i64) -> Column {
        let direction = self.layout.sample_direction(face, lod, ci, cj);
        let (owner, [u, v]) = self.sample_column(face, lod, ci, cj);
        let spacing = self.layout.voxel_span(lod);
        let [continents, ridges, hills] = self.sums_at_columns(owner, &[[u, v]], &[direction], spacing, lod)[0];
        let climate = Climate { sin_latitude: direction.z, continents, mountains: self.mountains(continents, ridges) };
        let caves = if self.caves.at_lod(lod) {
            self.caves.column(direction, self.layout.voxel_span(lod) as f64)
        } else {
            ColumnCaves::NONE
        };
        let thresholds = self.surface_thresholds(climate.sin_latitude);
        Column { caves, ..self.sample(self.combine(continents, ridges, hills), climate, &thresholds) }
    }

    /// The face that owns voxel column `(ci, cj)` of `lod` on `face` and
    /// the LOD-0 column it samples there, as [`ChunkLayout::sample_direction`]
    /// finds them (far corner, wrapped across a face edge, clamped in a
    /// cube corner's gap).
    fn sample_column(&self, face: CubeFace, lod: u8, ci: i64, cj: i64) -> (CubeFace, [f64; 2]) {
        let (owner, ci, cj) = self.layout.sample_cell(face, lod, ci, cj);
        let span = self.layout.voxel_span(lod);
        (owner, [((ci + 1) * span - 1) as f64, ((cj + 1) * span - 1) as f64])
    }

    /// The column whose terrain height is `height_m` metres, in `climate`.
    /// `thresholds` are [`Self::surface_thresholds`] at its latitude.
    fn sample(&self, height_m: f64, climate: Climate, thresholds: &SurfaceThresholds) -> Column {
        Column {
            height: height_m / self.layer_height,
            surface: self.surface(height_m, climate, thresholds),
            slack: 0.0,
            caves: ColumnCaves::NONE,
        }
    }

    /// Where [`Self::surface`] changes its answer at `sin_latitude`.
    fn surface_thresholds(&self, sin_latitude: f64) -> SurfaceThresholds {
        let latitude = latitude_degrees(sin_latitude);
        let bell = |centre: f64, width: f64| {
            let value = bell(latitude, centre, width);
            (value, value)
        };
        self.thresholds_with(sin_latitude, [bell(24.0, 9.0), bell(0.0, 12.0), bell(52.0, 10.0)])
    }

    /// [`Self::surface_thresholds`] at each unit direction of
    /// `directions` (a chunk's columns), with the climate's edges as
    /// ranges over all their latitudes: a chunk spans a fraction of a
    /// degree (a LOD-0 chunk's ranges are about 3·10⁻⁵ wide), so the
    /// ranges decide the material alike almost everywhere, for six `exp`s
    /// a chunk instead of three a column (8–10 % of a chunk's generation);
    /// a column whose sums meet a range looks up its own edges
    /// ([`SurfaceThresholds::exact`]; `columns_at`, `surface`).
    fn surface_thresholds_over(&self, directions: &[nebula_math::DVec3]) -> Vec<SurfaceThresholds> {
        let (least, most) = directions
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(least, most), d| (least.min(d.z.abs()), most.max(d.z.abs())));
        // None (or not a number): each its own.
        if least > most {
            return directions.iter().map(|d| self.surface_thresholds(d.z)).collect();
        }
        // A billionth of a degree and a trillionth of a bell spare for
        // rounding: each bell is highest at its centre (or the latitude
        // nearest it) and lowest at one of the ends.
        let (low, high) = (latitude_degrees(least) - 1e-9, latitude_degrees(most) + 1e-9);
        let range = |centre: f64, width: f64| {
            let lowest = bell(low, centre, width).min(bell(high, centre, width));
            (lowest - 1e-12, bell(centre.clamp(low, high), centre, width) + 1e-12)
        };
        let bells = [range(24.0, 9.0), range(0.0, 12.0), range(52.0, 10.0)];
        directions.iter().map(|d| self.thresholds_with(d.z, bells)).collect()
    }

    /// The thresholds at `sin_latitude` whose climate bells (the deserts'
    /// at 24°, the wet belts' at 0° and 52°) lie in these ranges.
    fn thresholds_with(&self, sin_latitude: f64, [desert, tropics, temperate]: [(f64, f64); 3]) -> SurfaceThresholds {
        let amplitude = self.settings.amplitude;
        // Deserts under the subtropical highs, inland; forests where it
        // rains, in the tropics and the temperate belt, from the coasts
        // (each rises with its bells: their ranges give theirs).
        let desert_from = |bell: f64| DESERT_INLAND - bell;
        let forest_below = |tropics: f64, temperate: f64| FOREST_INLAND * tropics.max(temperate) - 0.1;
        SurfaceThresholds {
            heights: [
                self.snow_line(sin_latitude),
                BARE_ROCK * amplitude,
                0.0,
                (0.001 * amplitude).max(2.0 * self.layer_height),
                TREE_LINE * amplitude,
            ],
            continents: [
                (desert_from(desert.1), desert_from(desert.0)),
                (forest_below(tropics.0, temperate.0), forest_below(tropics.1, temperate.1)),
            ],
            mountains: ROCKY_MOUNTAINS,
        }
    }

    /// The material of a column's top voxel, from its height (metres) and
    /// climate: snow above a snow line that comes down to the sea near the
    /// poles, sea bed below sea level, bare rock high up and where the
    /// mountains rise (their steep flanks: a stand-in for slope, which a
    /// column does not know), sand at the shore and in the subtropical
    /// deserts inland, forest in the wet belts (tropical and temperate)
    /// below the tree line, grass elsewhere.
    /// `thresholds` are [`Self::surface_thresholds`] at its latitude, or
    /// ranges that hold them: where the continents sum lies within a
    /// range, the exact ones are found.
    fn surface(&self, height_m: f64, climate: Climate, thresholds: &SurfaceThresholds) -> Voxel {
        let within = |(low, high): (f64, f64)| low < high && (low..=high).contains(&climate.continents);
        let exact;
        let thresholds = if thresholds.continents.into_iter().any(within) {
            exact = self.surface_thresholds(climate.sin_latitude);
            &exact
        } else {
            thresholds
        };
        let SurfaceThresholds { heights: [snow_line, bare_rock, sea_level, shore, tree_line], continents, mountains } =
            *thresholds;
        // Outside a range, either end of it decides as the edge would.
        let [(desert_from, _), (forest_below, _)] = continents;
        if height_m > snow_line {
            Voxel::SNOW
        } else if height_m < sea_level {
            Voxel::SEABED
        } else if height_m > bare_rock || climate.mountains > mountains {
            Voxel::STONE
        } else if height_m < shore || climate.continents > desert_from {
            Voxel::SAND
        } else if height_m < tree_line && climate.continents < forest_below {
            Voxel::FOREST
        } else {
            Voxel::GRASS
        }
    }

    /// Height (metres) above which a column at `sin_latitude` is snow: more
    /// than half the relief at the equator, 15 % of it below sea level at
    /// the poles.
    fn snow_line(&self, sin_latitude: f64) -> f64 {
        self.settings.amplitude * (0.55 - 0.7 * sin_latitude.abs().powi(4))
    }

    /// The lowest [`Self::snow_line`] anywhere over `column`: at the
    /// latitude nearest a pole among its corners and centre, pushed
    /// polewards by the column's angular size (the patch can reach that
    /// much further).
    fn lowest_snow_line(&self, column: ChunkColumn) -> f64 {
        let sphere = self.layout.sphere();
        let size = f64::from(CHUNK_SIZE) * self.layout.voxel_span(column.lod) as f64;
        let (i0, j0) = (f64::from(column.x) * size, f64::from(column.y) * size);
        let grid = sphere.patch_directions(column.face, i0, j0, size);
        let polewards = [(0, 0), (2, 0), (0, 2), (2, 2), (1, 1)]
            .into_iter()
            .fold(0.0_f64, |polewards, (a, b)| polewards.max(grid[a][b].z.abs()));
        let reach = size * self.layer_height / self.settings.radius * 2.0;
        self.snow_line((polewards + reach).min(1.0))
    }

    /// The heights of `column`'s padded voxel columns (x fastest, as
    /// `PaddedChunkShape` orders x and z), from the cache or computed.
    fn padded_heights(&self, column: ChunkColumn) -> Arc<[Column]> {
        self.heights.get_or_compute(column, || self.compute_padded_heights(column))
    }

    /// [`Self::padded_heights`] computed, with what the cache holds of
    /// the column's parent and neighbours.
    fn compute_padded_heights(&self, column: ChunkColumn) -> Arc<[Column]> {
        let size = i64::from(CHUNK_SIZE);
        let (base_i, base_j) = (i64::from(column.x) * size - 1, i64::from(column.y) * size - 1);
        let padded = i64::from(PADDED_CHUNK_SIZE);
        let per_edge = i64::from(self.layout.voxels_per_edge(column.lod));
        let span = self.layout.voxel_span(column.lod) as f64;
        // Every other column (odd i and j) samples the same LOD-0 column
        // as one of the parent's (see the module docs): with the parent's
        // heights at hand, a quarter of the noise is already paid. Only
        // columns on this face: a wrapped one is read in the other face's
        // frame, where the two LODs' far corners need not agree.
        // (Only where the two LODs keep the same octaves, `BandLimited`.)
        let same_sums = |lod: u8| self.bands[usize::from(lod)].kept() == self.bands[usize::from(column.lod)].kept();
        let parent = (column.lod < self.layout.max_lod())
            .then(|| ChunkColumn { face: column.face, lod: column.lod + 1, x: column.x / 2, y: column.y / 2 })
            .filter(|parent| same_sums(parent.lod))
            .and_then(|parent| self.heights.get(parent).map(|heights| (parent, heights)));
        let from_parent = |i: i64, j: i64| {
            let (parent, heights) = parent.as_ref()?;
            let inside = |c: i64| (0..per_edge).contains(&c);
            if i % 2 == 0 || j % 2 == 0 || !inside(i) || !inside(j) {
                return None;
            }
            let q = |c: i64, chunk: u32| (c - 1) / 2 - i64::from(chunk) * size + 1;
            let (qi, qj) = (q(i, parent.x), q(j, parent.y));
            let within = |q: i64| (0..padded).contains(&q);
            if !within(qi) || !within(qj) {
                return None;
            }
            // Made for the parent's voxels, twice as tall: it may leave a
            // threshold of these open. Its caves are the parent's LOD's
            // (and none past the caves' coarsest LOD): only a column with
            // no tunnel near lends itself where these voxels can be caves.
            let known = heights[(qj * padded + qi) as usize];
            if self.caves.at_lod(column.lod) && (known.caves.near || !self.caves.at_lod(parent.lod)) {
                return None;
            }
            let slack = f64::from(known.slack);
            (!self.undecided_voxels(known.height - slack, known.height + slack, span)).then_some(known)
        };
        // The padding ring and the rows next to it are the same LOD's
        // columns of the neighbouring chunks: copied when those are cached
        // (same face only, as for the parent).
        let neighbours: Vec<(ChunkColumn, Arc<[Column]>)> =
            [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)]
                .into_iter()
                .filter_map(|(dx, dy): (i64, i64)| {
                    let (x, y) = (i64::from(column.x) + dx, i64::from(column.y) + dy);
                    let chunks = i64::from(self.layout.chunks_per_edge(column.lod));
                    if !(0..chunks).contains(&x) || !(0..chunks).contains(&y) {
                        return None;
                    }
                    let neighbour = ChunkColumn { face: column.face, lod: column.lod, x: x as u32, y: y as u32 };
                    self.heights.get(neighbour).map(|heights| (neighbour, heights))
                })
                .collect();
        let from_neighbour = |i: i64, j: i64| {
            let inside = |c: i64| (0..per_edge).contains(&c);
            if !inside(i) || !inside(j) {
                return None;
            }
            neighbours.iter().find_map(|(neighbour, heights)| {
                let (qi, qj) = (i - (i64::from(neighbour.x) * size - 1), j - (i64::from(neighbour.y) * size - 1));
                let within = |q: i64| (0..padded).contains(&q);
                (within(qi) && within(qj)).then(|| heights[(qj * padded + qi) as usize])
            })
        };
        // Columns on this face: their directions from one warp per row and
        // per column of the chunk (bit-identical to `sample_direction`).
        let sphere = self.layout.sphere();
        let warped = |base: i64| -> Vec<Option<f64>> {
            (base..base + padded)
                .map(|c| (0..per_edge).contains(&c).then(|| sphere.warp(self.layout.sample_coord(c, column.lod))))
                .collect()
        };
        let (warped_i, warped_j) = (warped(base_i), warped(base_j));
        let mut heights = vec![Column::UNKNOWN; (padded * padded) as usize];
        let mut missing = Vec::with_capacity(heights.len());
        let mut directions = Vec::with_capacity(heights.len());
        // Each missing column's owning face and LOD-0 column there.
        let mut samples = Vec::with_capacity(heights.len());
        let span_columns = self.layout.voxel_span(column.lod);
        let on_face = |c: i64| (0..per_edge).contains(&c);
        for (n, height) in (0..padded * padded).zip(&mut heights) {
            let (i, j) = (base_i + n % padded, base_j + n / padded);
            let edge_rows = |c: i64| c < 2 || c >= padded - 2;
            let near_edge = edge_rows(n % padded) || edge_rows(n / padded);
            if let Some(known) = from_parent(i, j).or_else(|| near_edge.then(|| from_neighbour(i, j)).flatten()) {
                *height = known;
            } else {
                missing.push(n as usize);
                directions.push(match (warped_i[(n % padded) as usize], warped_j[(n / padded) as usize]) {
                    (Some(wi), Some(wj)) => sphere.direction_warped(column.face, wi, wj),
                    _ => self.layout.sample_direction(column.face, column.lod, i, j),
                });
                samples.push(if on_face(i) && on_face(j) {
                    // On the face: the column itself (`sample_column`'s
                    // far corner, with nothing to wrap or clamp).
                    (column.face, [((i + 1) * span_columns - 1) as f64, ((j + 1) * span_columns - 1) as f64])
                } else {
                    self.sample_column(column.face, column.lod, i, j)
                });
            }
        }
        // The grids' octaves, face by face (a chunk at a face edge has
        // padding owned by its neighbours).
        let resumed = self.grid_states_by_face(&samples, span_columns, column.lod);
        // No cave where the column's relief (its chunk column and a voxel
        // beyond: the padding) keeps every voxel under the caves' sea
        // margin or out of every cave region (`column_relief`, which the
        // LOD tree has mostly asked for already): the sea's chunks and
        // cave-free land skip the caves' noise. Their voxels are the same:
        // no cave air can lie there, and a column with no tunnel over it
        // is made as any other (its `near` unset, it may also be lent to
        // a finer column, whose relief lies within this one's).
        let caves_possible = self.caves_near(column);
        for (n, computed) in missing.into_iter().zip(self.columns_at(&directions, resumed, column.lod, caves_possible))
        {
            heights[n] = computed;
        }
        heights.into()
    }

    /// A padded chunk's voxels (`key`'s) from its columns' `heights`, as
    /// `classify` finds each. Not inlined: a loop of its own, whatever
    /// the column heights around it inline.
    #[inline(never)]
    fn fill_voxels(&self, heights: &[Column], key: ChunkKey, voxels: &mut [Voxel]) {
        let base_h = i64::from(key.layer) * i64::from(CHUNK_SIZE) - 1;
        let span = self.layout.voxel_span(key.lod) as f64;
        let size = PADDED_CHUNK_SIZE as usize;
        // Row by row along x, as the voxels are stored: the same arithmetic
        // as `classify`, one corner centre per row. Where no tunnel passes
        // over any of the chunk's columns (most chunks), without asking
        // each voxel about caves: the rows vectorise.
        let caves = heights.iter().any(|column| column.caves.near);
        for z in 0..size {
            let columns = &heights[z * size..(z + 1) * size];
            // A row whose centre lies over its highest column is air, and
            // one deeper than dirt under its lowest is each column's deep
            // voxel, stone or (under the sea) sea bed, where no tunnel can
            // hollow it: `classify_depth`'s tests on the extremes decide for
            // every column (`h − centre` rises with `h`). Most rows of a
            // chunk on a steep slope are one or the other (high mountains'
            // lowest surface chunk: 1,148 of 1,156).
            let (lowest, highest) = columns
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(low, high), c| (low.min(c.height), high.max(c.height)));
            let mut deep = [Voxel::STONE; PADDED_CHUNK_SIZE as usize];
            for (voxel, column) in deep.iter_mut().zip(columns) {
                if column.surface == Voxel::SEABED {
                    *voxel = Voxel::SEABED;
                }
            }
            for y in 0..size {
                let centre = self.layout.sample_layer(base_h + y as i64, key.lod);
                let start = PaddedChunkShape::linearize([0, y as u32, z as u32]) as usize;
                if highest - centre <= 0.0 {
                    voxels[start..start + size].fill(Voxel::AIR);
                    continue;
                }
                if !caves && lowest - centre > span + 3.0 {
                    voxels[start..start + size].copy_from_slice(&deep);
                    continue;
                }
                let row = voxels[start..start + size].iter_mut().zip(columns);
                if caves {
                    row.for_each(|(voxel, column)| *voxel = column.voxel(centre, span));
                } else {
                    row.for_each(|(voxel, column)| *voxel = column.ground_voxel(centre, span));
                }
            }
        }
    }

    /// [`grid_states`] at `samples` (each a face and a LOD-0 column on
    /// it) for columns of `spacing` LOD-0 columns, in their order: one
    /// call per face among them.
    fn grid_states_by_face(
        &self,
        samples: &[(CubeFace, [f64; 2])],
        spacing: i64,
        band: u8,
    ) -> [(usize, Vec<OctaveState>); 3] {
        // Most chunks lie within one face: their samples are the points,
        // in order.
        if let Some(&(face, _)) = samples.first()
            && samples.iter().all(|&(f, _)| f == face)
        {
            let points: Vec<[f64; 2]> = samples.iter().map(|&(_, point)| point).collect();
            return self.grid_states(face, &points, spacing, band);
        }
        let mut out: [(usize, Vec<OctaveState>); 3] =
            std::array::from_fn(|_| (0, vec![OctaveState::START; samples.len()]));
        let mut faces: Vec<CubeFace> = samples.iter().map(|&(face, _)| face).collect();
        faces.sort_unstable();
        faces.dedup();
        for face in faces {
            let (indices, points): (Vec<usize>, Vec<[f64; 2]>) =
                samples.iter().enumerate().filter(|(_, (f, _))| *f == face).map(|(n, &(_, point))| (n, point)).unzip();
            let resumed = self.grid_states(face, &points, spacing, band);
            for ((start, states), (out_start, out_states)) in resumed.into_iter().zip(&mut out) {
                *out_start = start;
                for (n, state) in indices.iter().zip(states) {
                    out_states[*n] = state;
                }
            }
        }
        out
    }

    /// Voxel `h` (in voxels of `lod`) of `column`: solid iff its far-corner
    /// LOD-0 voxel's centre is below the column's height. The material goes
    /// by depth in voxels of `lod`, so the top voxel of a column has the
    /// surface material at every LOD (no colour pop).
    fn classify(&self, column: Column, h: i64, lod: u8) -> Voxel {
        column.voxel(self.layout.sample_layer(h, lod), self.layout.voxel_span(lod) as f64)
    }

    /// Each noise sum's steepest change between neighbouring lattice cells
    /// at 4,096 places, times 1.5 for the places not visited (for
    /// [`Self::slope_within`]), and S from the same places: found, not
    /// proven, but of sums that are alike everywhere.
    ///
    /// S is [`Self::slope_within`] everywhere, made tighter by taking each
    /// sum's step together with its value at the same place: a hill is
    /// not at its highest where it is steepest, nor a ridge's cube.
    fn measure_slopes(&self) -> ([f64; 3], f64) {
        // A fixed sequence of places (not the seed: the bound must not depend
        // on luck with the terrain seed's own random numbers).
        let sphere = self.layout.sphere();
        let n = f64::from(sphere.resolution());
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = || nebula_math::unit_random(&mut state);
        let sums =
            [(&self.continents, self.noise_scale), (&self.ridges, self.ridge_scale), (&self.hills, self.detail_scale)];
        let mut steepest = [0.0_f64; 3];
        // (step, largest value) of the ridges' cube and of the hills in
        // [0, 1], by place.
        let (mut cubes, mut hills) = (Vec::with_capacity(4096), Vec::with_capacity(4096));
        let step_and_largest = |[here, along_i, along_j]: [f64; 3]| {
            ((along_i - here).abs().max((along_j - here).abs()), here.max(along_i).max(along_j))
        };
        for sample in 0..4096 {
            let face = CubeFace::ALL[sample % 6];
            let (i, j) = (next() * (n - 1.0), next() * (n - 1.0));
            let places =
                [sphere.direction(face, i, j), sphere.direction(face, i + 1.0, j), sphere.direction(face, i, j + 1.0)];
            let values = sums.map(|(fractal, scale)| places.map(|d| fractal.get((d * scale).to_array())));
            for (values, steepest) in values.iter().zip(&mut steepest) {
                *steepest = steepest.max(step_and_largest(*values).0);
            }
            cubes.push(step_and_largest(values[1].map(|r| unit_ridges(r).powi(MOUNTAIN_SHARPNESS))));
            hills.push(step_and_largest(values[2].map(unit_hills)));
        }
        let steps = steepest.map(|step| step * 1.5);
        // As `slope_within`: mountains = cube · mask steps by at most
        // Δcube·1 + cube·Δmask.
        let mask_step = 1.5 / MOUNTAIN_INLAND * steps[0];
        let mountains_step = cubes.iter().map(|&(step, cube)| 1.5 * step + cube * mask_step).fold(0.0, f64::max);
        let detail = hills
            .iter()
            .map(|&(step, hill)| 1.5 * step * (1.0 + MOUNTAIN_ROUGHNESS) + MOUNTAIN_ROUGHNESS * hill * mountains_step)
            .fold(0.0, f64::max);
        let slope = self.settings.amplitude
            * (OCEAN_SLOPE.max(LAND_SLOPE) * steps[0] + MOUNTAIN_SHARE * mountains_step)
            + self.settings.detail_amplitude * detail;
        (steps, slope / self.layer_height)
    }

    /// The most the terrain height varies anywhere, metres: from the
    /// lowest H can be to the highest (what a renderer's relief-dependent
    /// effects scale with).
    #[must_use]
    pub fn relief(&self) -> f64 {
        self.highest() - self.lowest()
    }

    /// The highest H can be, metres above the base radius (`combine`).
    fn highest(&self) -> f64 {
        self.settings.amplitude + self.settings.detail_amplitude * (1.0 + MOUNTAIN_ROUGHNESS)
    }

    /// The lowest H can be, metres (`combine`: the hills are never negative).
    fn lowest(&self) -> f64 {
        -self.settings.amplitude
    }
}

/// `x.ceil()` for |x| < 2⁶³, without the libm call baseline x86-64 makes
/// of it (no SSE4.1 `roundsd`): the hottest test of `columns_at`.
fn ceil(x: f64) -> f64 {
    let truncated = x as i64 as f64;
    if truncated < x { truncated + 1.0 } else { truncated }
}

/// The coarsest voxels (in lattice cells) whose deep caves stay sealed,
/// and the layers of rock kept spare beyond the slope
/// (`ProceduralPlanet::hides_buried`).
const SEALED_SPAN: f64 = 4.0;
const SEALED_MARGIN: f64 = 2.0;

/// Shares of the amplitude: bare rock above, forest below.
const BARE_ROCK: f64 = 0.35;
const TREE_LINE: f64 = 0.25;
/// The mountains term above which a column is bare rock.
const ROCKY_MOUNTAINS: f64 = 0.3;
/// The continents sum above which a column is desert, less the
/// subtropical bell; and below which it is forest, times the wet belts'.
const DESERT_INLAND: f64 = 1.2;
const FOREST_INLAND: f64 = 0.5;

/// Degrees of latitude at `sin_latitude` (either hemisphere alike).
fn latitude_degrees(sin_latitude: f64) -> f64 {
    sin_latitude.abs().min(1.0).asin().to_degrees()
}

/// Slack for rounding in the comparisons that tell whether a column is
/// decided (`ProceduralPlanet::undecided_apart_from_edges`, [`meets_edges`]).
const ROUNDING: f64 = 1e-6;

/// Whether the continents sums between `climates` meet one of the
/// climate's edges (or their ranges) in `thresholds`, give or take
/// rounding: what, with `ProceduralPlanet::undecided_apart_from_edges`,
/// keeps a column open.
fn meets_edges([least, most]: [Climate; 2], thresholds: &SurfaceThresholds) -> bool {
    thresholds
        .continents
        .iter()
        .any(|&(t_low, t_high)| t_low - ROUNDING <= most.continents && least.continents <= t_high + ROUNDING)
}

/// A climate belt's bell at `latitude` degrees: 1 at `centre`, falling
/// over `width` degrees.
fn bell(latitude: f64, centre: f64, width: f64) -> f64 {
    (-((latitude - centre) / width).powi(2)).exp()
}

/// H per unit of the continents sum below sea level (ocean depth), and
/// above it (lowland height), shares of the amplitude: the land rises
/// gently from its coasts, so lowlands are wide and mountains stand out.
const OCEAN_SLOPE: f64 = 0.6;
const LAND_SLOPE: f64 = 0.2;
/// The share of the amplitude the mountain chains add at most, and the
/// power of the ridge sum (in `[0, 1]`) that makes them: a high power keeps
/// the chains narrow, with lowland between them.
const MOUNTAIN_SHARE: f64 = 0.6;
const MOUNTAIN_SHARPNESS: i32 = 3;
/// How many times taller the hills grow on the mountains: the valleys and
/// spurs of a range.
const MOUNTAIN_ROUGHNESS: f64 = 6.0;
/// Mountains come in where the continents sum passes `MOUNTAIN_START`,
/// fully `MOUNTAIN_INLAND` further inland: the chains stand on the
/// continents' cores, lowland around them.
const MOUNTAIN_START: f64 = 0.1;
const MOUNTAIN_INLAND: f64 = 0.3;

/// The ridges sum mapped into `[0, 1]` (`combine`): rises with it.
fn unit_ridges(ridges: f64) -> f64 {
    ((ridges + 1.0) * 0.5).clamp(0.0, 1.0)
}

/// The hills sum mapped into `[0, 1]` (`combine`): rises with it.
fn unit_hills(hills: f64) -> f64 {
    (hills.clamp(-1.0, 1.0) + 1.0) * 0.5
}

/// How far the mountains have come in from the coast, in `[0, 1]`, from
/// the continents sum: rises with it.
fn mountain_mask(continents: f64) -> f64 {
    smoothstep((continents - MOUNTAIN_START) / MOUNTAIN_INLAND)
}

pub(crate) fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// The most H (metres) changes where the sums lie in `ranges` and step by
/// at most `[continents, ridges, hills]`: each step through
/// [`ProceduralPlanet::combine`] as if all three came at once, each factor
/// at its largest in `ranges` (a product `f·g` steps by at most
/// `Δf·max g + max f·Δg`). With unit steps over
/// [`SumRanges::EVERYWHERE`], how fast H can change with each sum (the
/// octave grids' [`CoarseGrids`]).
fn height_step(
    settings: &PlanetSettings,
    ranges: SumRanges,
    [continents_step, ridges_step, hills_step]: [f64; 3],
) -> f64 {
    let (continents_low, continents_high) = ranges.continents;
    let ridges = unit_ridges(ranges.ridges.1);
    let hills = unit_hills(ranges.hills.1);
    let mask = mountain_mask(continents_high);
    // smoothstep rises by at most 1.5 over its width, and not at all
    // below it; the ridges in [0, 1] step by half the sum's.
    let mask_step = if mask > 0.0 { 1.5 / MOUNTAIN_INLAND * continents_step } else { 0.0 };
    let ridges_cubed_step = 3.0 * ridges * ridges * 0.5 * ridges_step;
    let mountains = ridges.powi(MOUNTAIN_SHARPNESS) * mask;
    let mountains_step = ridges_cubed_step * mask + ridges.powi(MOUNTAIN_SHARPNESS) * mask_step;
    let slope = if continents_low < 0.0 { OCEAN_SLOPE } else { LAND_SLOPE };
    let landforms = settings.amplitude * (slope * continents_step + MOUNTAIN_SHARE * mountains_step);
    let detail = settings.detail_amplitude
        * (0.5 * hills_step * (1.0 + MOUNTAIN_ROUGHNESS * mountains) + MOUNTAIN_ROUGHNESS * hills * mountains_step);
    landforms + detail
}

/// What the surface bounds of a column are made from: its heights' range
/// and slope, found once (the noise), for bounds with any cave depth
/// ([`ProceduralPlanet::bounds_reaching`]: arithmetic alone).
struct ColumnRelief {
    column: ChunkColumn,
    /// Voxel span at the column's LOD, in layers.
    span: f64,
    /// Range of H over the column and a voxel beyond, in layers, widened
    /// by what the sums of the LODs under it leave out ([`BandLimited`]).
    low: f64,
    high: f64,
    /// The slope bound over it.
    slope: f64,
    /// How far the sums of the LODs under it can lie from H there
    /// ([`ProceduralPlanet::dropped_within`]), layers.
    dropped: f64,
    /// Whether a cave may lie under it.
    caves_near: bool,
}

impl ProceduralPlanet {
    /// The ball over which [`Self::column_relief`] bounds the noise:
    /// `column` and a voxel beyond (for the neighbouring voxel columns).
    fn relief_ball(&self, column: ChunkColumn) -> (nebula_math::DVec3, f64) {
        let span = self.layout.voxel_span(column.lod) as f64;
        let chunk = f64::from(CHUNK_SIZE) * span;
        let centre = ((f64::from(column.x) + 0.5) * chunk, (f64::from(column.y) + 0.5) * chunk);
        self.patch_ball(column.face, centre, chunk / 2.0 + span)
    }

    /// [`ColumnRelief::caves_near`] of `column` (on the planet), sampling
    /// H only where the noise's ranges leave it open: not where no cave is
    /// made at its LOD or none can be near, nor where the ranges' lowest
    /// ground already reaches the caves' sea margin (the relief's high end
    /// lies over it), as in high mountains, whose chunks sampled five
    /// columns' every octave for it.
    fn caves_near(&self, column: ChunkColumn) -> bool {
        if !self.caves.at_lod(column.lod) {
            return false;
        }
        let ball = self.relief_ball(column);
        if !self.caves.may_be_near(ball.0, ball.1) {
            return false;
        }
        let span = self.layout.voxel_span(column.lod) as f64;
        let low = self.heights(self.sum_ranges(ball)).0.max(self.lowest() / self.layer_height);
        low + span >= crate::caves::SEA_MARGIN_LAYERS
            || self.column_relief(column).is_ok_and(|relief| relief.caves_near)
    }

    /// The noise behind [`VoxelSource::surface_bounds`] for `column`.
    fn column_relief(&self, column: ChunkColumn) -> Result<ColumnRelief, VoxelError> {
        self.layout.check_key(column.chunk(0))?;
        let span = self.layout.voxel_span(column.lod) as f64;
        let chunk = f64::from(CHUNK_SIZE) * span;
        // H's range from the noise's ranges (`sum_ranges`: at most one
        // evaluation, tight at coarse LODs). Where S over half a column is
        // narrower (fine LODs), also sample the four corners and the
        // centre: every voxel column's sample is within `step` = half the
        // column (in |Δi| + |Δj|) of one of them — as close as a 3 × 3 grid
        // gets, for 5 samples instead of 9 — so S·step covers what lies
        // between. (The LOD tree asks for every node it creates: this is
        // its hottest call.) Each "corner" is the LOD-0 column whose far
        // corner it is, half a cell in along both axes: the samples span
        // the square of the column's own samples (far corners too), and
        // sit on the nodes of every grid of up to 16 columns
        // (`octave_grid.rs`): only the coarse grids are interpolated for
        // them, 2 × 2 nodes each.
        let step = chunk / 2.0;
        let ball = self.relief_ball(column);
        let ranges = self.sum_ranges(ball);
        let slope = self.slope_within(ranges).min(self.max_slope);
        let margin = slope * step;
        let (mut low, mut high) = self.heights(ranges);
        if 2.0 * margin < high - low {
            // Whole lattice coordinates (a chunk is 32 voxels of `span`).
            let cells = i64::from(CHUNK_SIZE) * self.layout.voxel_span(column.lod);
            let corners = [(0, 0), (2, 0), (0, 2), (2, 2), (1, 1)].map(|(a, b)| {
                (i64::from(column.x) * cells + a * cells / 2, i64::from(column.y) * cells + b * cells / 2)
            });
            let heights = self.corner_heights(column.face, cells / 2, &corners);
            let sampled_low = heights.iter().copied().fold(f64::INFINITY, f64::min);
            let sampled_high = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            low = low.max(sampled_low - margin);
            high = high.min(sampled_high + margin);
        }
        let (lowest, highest) = (self.lowest() / self.layer_height, self.highest() / self.layer_height);
        // The columns of every LOD up to this one's, without the octaves
        // they leave out (`BandLimited`: the coarser, the more).
        let dropped = self.dropped_within(column.lod, ranges);
        let (low, high) = (low.max(lowest) - dropped, high.min(highest) + dropped);
        let caves_near = self.caves.at_lod(column.lod)
            && high + span >= crate::caves::SEA_MARGIN_LAYERS
            && self.caves.may_be_near(ball.0, ball.1);
        Ok(ColumnRelief { column, span, low, high, slope, dropped, caves_near })
    }

    /// [`VoxelSource::surface_bounds`] of the column of `relief` with caves
    /// reaching `cave_depth` layers under the ground: all of them
    /// (`Caves::deepest`), or the shallow network alone where the deep one
    /// is sealed ([`VoxelSource::surface_chunk_layers_seen`]); and with
    /// `sealed_top`, only what lies under that many layers of rock (the
    /// sealed caves' surface, seen from inside them).
    fn bounds_reaching(&self, relief: &ColumnRelief, cave_depth: f64, sealed_top: Option<f64>) -> SurfaceBounds {
        let ColumnRelief { column, span, low, high, slope, caves_near, .. } = *relief;
        // A column's voxel top lies in (H + 1/2 − span, H + 1/2] of its sample
        // column's height H. A solid voxel with air beside it lies down to
        // the top of the neighbouring voxel column, whose sample is up to
        // one voxel (span cells) further out: S·span lower still, and its
        // top again up to a voxel below its H.
        let neighbour = slope * span + span;
        let mut min_layer = (low + 0.5 - span - neighbour).floor() as i64;
        // Cave air lies at most `deepest` layers under its column's H
        // (which is above `low − neighbour` over the patch and a voxel
        // beyond), above the sea; the rock under and beside it a voxel
        // lower still.
        if caves_near {
            let cave_floor = (low - neighbour - cave_depth - span).floor() as i64 - 1;
            min_layer = min_layer.min(cave_floor);
        }
        let mut max_layer = (high + 0.5).ceil() as i64;
        if let Some(top) = sealed_top {
            // The rock over the sealed air, a voxel up, under the highest
            // ground near the patch.
            max_layer = max_layer.min((high + 0.5 + span - top).ceil() as i64 + 1);
        }
        let sphere = self.layout.sphere();
        // Every column's H is below `high`; where that is under the sea and under the snow line (which dips
        // below sea level near the poles), every column is sea bed
        // (`surface`), and so is every voxel under it (`classify_depth`).
        let highest_m = high * self.layer_height;
        let sea_bed_only = highest_m < 0.0 && highest_m < self.lowest_snow_line(column);
        SurfaceBounds {
            min_layer,
            max_layer,
            min_radius: sphere.layer_radius(min_layer as f64),
            max_radius: sphere.layer_radius(max_layer as f64 + 1.0),
            sea_bed_only,
        }
    }

    /// The bounds of the surface an eye with `view` sees in the column of
    /// `relief`.
    fn bounds_seen(&self, relief: &ColumnRelief, view: LayerView) -> SurfaceBounds {
        match view {
            _ if !self.hides_buried(relief.column.lod) => self.bounds_reaching(relief, self.caves.deepest(), None),
            LayerView::All => self.bounds_reaching(relief, self.caves.deepest(), None),
            LayerView::FromAbove => self.bounds_reaching(relief, self.caves.shallow_deepest(), None),
            LayerView::FromSealedCaves => self.bounds_reaching(
                relief,
                self.caves.deepest(),
                Some(self.caves.shallow_deepest() + self.caves.separation()),
            ),
        }
    }
}

impl VoxelSource for ProceduralPlanet {
    fn layout(&self) -> &ChunkLayout {
        &self.layout
    }

    fn voxel(&self, at: VoxelCoord) -> Result<Voxel, VoxelError> {
        self.layout.check_voxel(at)?;
        let column = self.column(at.face, at.lod, at.i.into(), at.j.into());
        Ok(self.classify(column, at.h.into(), at.lod))
    }

    fn column_voxels(&self, bottom: VoxelCoord, out: &mut [Voxel]) -> Result<(), VoxelError> {
        self.layout.check_voxel(bottom)?;
        let top = i32::try_from(out.len()).ok().and_then(|n| bottom.h.checked_add(n - 1));
        self.layout.check_voxel(VoxelCoord { h: top.unwrap_or(i32::MAX), ..bottom })?;
        // The column's noise once, for every voxel of it.
        let column = self.column(bottom.face, bottom.lod, bottom.i.into(), bottom.j.into());
        for (h, voxel) in (i64::from(bottom.h)..).zip(out.iter_mut()) {
            *voxel = self.classify(column, h, bottom.lod);
        }
        Ok(())
    }

    fn fill_chunk(&self, key: ChunkKey, out: &mut ChunkVoxels) -> Result<(), VoxelError> {
        self.layout.check_key(key)?;
        out.set_key(key);
        let base_h = i64::from(key.layer) * i64::from(CHUNK_SIZE) - 1;
        let heights = self.padded_heights(key.column());
        self.fill_voxels(&heights, key, out.as_mut_slice());
        let span = self.layout.voxel_span(key.lod) as f64;
        let size = PADDED_CHUNK_SIZE as usize;
        let above = self.layout.sample_layer(base_h + size as i64, key.lod);
        for (n, column) in heights.iter().enumerate() {
            out.set_covered_above(((n % size) as u32, (n / size) as u32), !column.open_to_sky(above, span));
        }
        Ok(())
    }

    fn surface_bounds(&self, column: ChunkColumn) -> Result<SurfaceBounds, VoxelError> {
        Ok(self.bounds_reaching(&self.column_relief(column)?, self.caves.deepest(), None))
    }

    fn surface_top_radius(&self, column: ChunkColumn) -> Result<f64, VoxelError> {
        let relief = self.column_relief(column)?;
        // H at a 9 × 9 grid of the far-corner columns (as `column_relief`
        // samples 5 of them, which this grid holds): every voxel column's
        // sample, at any LOD under the column, is within `spacing` (in
        // |Δi| + |Δj|) of one, so S·spacing covers what lies between.
        let cells = i64::from(CHUNK_SIZE) * self.layout.voxel_span(column.lod);
        let spacing = cells / TOP_GRID;
        let corners = (0..=TOP_GRID).flat_map(|a| (0..=TOP_GRID).map(move |b| (a, b))).map(|(a, b)| {
            // The memo holds the tree's samples (its nodes' corners and
            // centres, here and at the children): not the rest, which
            // would crowd them out.
            let shared = a % (TOP_GRID / 2) == 0 && b % (TOP_GRID / 2) == 0;
            (i64::from(column.x) * cells + a * spacing, i64::from(column.y) * cells + b * spacing, shared)
        });
        // Only their highest H is needed, and only to within a quarter of
        // the column's own voxel (a top is a bound, rounded up to a layer
        // and widened by the slope between samples, several voxels):
        // found without summing every octave at every corner, nor the
        // last octaves at the highest (`highest_height`).
        let tolerance = 0.25 * self.layout.voxel_span(column.lod) as f64;
        let sampled = self.highest_height(column.face, spacing, corners, tolerance);
        let high = relief.high.min(sampled + relief.slope * spacing as f64 + relief.dropped);
        // A voxel's top is within half a layer over its column's H (as in
        // `bounds_reaching`).
        let max_layer = (high + 0.5).ceil();
        Ok(self.layout.sphere().layer_radius(max_layer + 1.0))
    }

    fn layer_view(&self, eye: nebula_math::DVec3) -> LayerView {
        if self.caves.coarsest_lod().is_none() || !self.hides_buried(0) {
            return LayerView::All;
        }
        // Deep in the ground (between the networks or deeper): in the
        // sealed caves, if in any. The middle of the rock between them
        // leaves room for the eye's column's height against H here.
        let depth = (self.height_at(eye.normalize_or_zero())
            - self.layout.sphere().radius_to_layer(eye.length()) * self.layer_height)
            / self.layer_height;
        if depth > self.caves.shallow_deepest() + 0.5 * self.caves.separation() {
            LayerView::FromSealedCaves
        } else {
            LayerView::FromAbove
        }
    }

    fn surface_chunk_layers_seen(
        &self,
        column: ChunkColumn,
        view: LayerView,
    ) -> Result<std::ops::RangeInclusive<i32>, VoxelError> {
        let bounds = self.bounds_seen(&self.column_relief(column)?, view);
        Ok(bounds.chunk_layers(&self.layout, column.lod))
    }

    fn surface_survey(&self, column: ChunkColumn) -> Result<SurfaceSurvey, VoxelError> {
        // One noise evaluation for every view.
        let relief = self.column_relief(column)?;
        Ok(SurfaceSurvey::new(self.bounds_seen(&relief, LayerView::All), |view| {
            self.bounds_seen(&relief, view).chunk_layers(&self.layout, column.lod)
        }))
    }

    fn lowest_surface_radius(&self) -> Option<f64> {
        // A LOD-0 top is within half a layer of H.
        Some(self.settings.radius + self.lowest() - self.layer_height)
    }

    fn geometric_error(&self, lod: u8) -> f64 {
        if lod == 0 {
            return 0.0;
        }
        let span = self.layout.voxel_span(lod) as f64;
        // Or, past some LOD, the whole relief: no top is further from
        // another than that (module docs).
        let relief = self.relief() / self.layer_height;
        // Where a chunk of this LOD is solid across a seam from a finer
        // one's cave (or mouth), the finer surface lies as deep as the
        // deepest cave air (`caves.rs`).
        let caves = if self.caves.coarsest_lod().is_some() { self.caves.deepest() + span } else { 0.0 };
        // And what the LOD's sums leave out (`BandLimited`), within the
        // same cap: `combine` clamps each of its terms, so H from any sums,
        // band-limited ones too, lies between the lowest and the highest.
        let dropped = self.bands[usize::from(lod)].dropped;
        (span + (2.0 * self.max_slope * (span - 1.0) + dropped).min(relief) + caves) * self.layer_height
    }
}

/// The voxel whose sample lies `depth` layers below its column's surface
/// (`span` layers per voxel). Under the sea the whole column is sea bed
/// (sediment), so a wall of the sea floor is sea bed too and gets the
/// renderer's water.
fn classify_depth(column: Column, depth: f64, span: f64) -> Voxel {
    if depth <= 0.0 {
        return Voxel::AIR;
    }
    if depth <= span || column.surface == Voxel::SEABED {
        column.surface
    } else if depth <= span + 3.0 {
        Voxel::DIRT
    } else {
        Voxel::STONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_column_asked_for_during_its_computation_is_computed_once() {
        let cache = HeightCache::default();
        let column = ChunkColumn { face: CubeFace::PosZ, lod: 2, x: 3, y: 4 };
        let made: Arc<[Column]> = vec![Column::UNKNOWN; 4].into();
        let (started, computing) = std::sync::mpsc::channel();
        std::thread::scope(|scope| {
            let first = scope.spawn(|| {
                cache.get_or_compute(column, || {
                    started.send(()).expect("the test waits");
                    std::thread::sleep(std::time::Duration::from_millis(100));
                    made.clone()
                })
            });
            computing.recv().expect("the first computation starts");
            assert!(cache.get(column).is_none(), "not made yet");
            // Asked while the first computation is under way: it waits
            // for that one.
            let second = cache.get_or_compute(column, || panic!("computed twice"));
            let first = first.join().expect("no panic");
            assert!(Arc::ptr_eq(&first, &made) && Arc::ptr_eq(&second, &made));
        });
        assert!(cache.get(column).is_some_and(|heights| Arc::ptr_eq(&heights, &made)));
    }

    /// The columns a chunk is filled from hold their height (every octave
    /// in, the grids read as a point between columns reads them) within
    /// their slack, with no voxel or material threshold of their
    /// LOD in between (so they classify as H does: the voxel-level check is
    /// `filled_chunks_equal_voxels_read_one_by_one`), and bit for bit where
    /// the slack is 0; without a band limit most coarse columns are
    /// decided before the last octave (band-limited, a coarse sum is a few
    /// octaves long), and LOD-0 columns come out exact far more often.
    #[test]
    fn columns_hold_their_height_within_their_slack() {
        // The presets (band-limited: their coarse sums a few octaves long,
        // summed to the last by every column), and with every octave.
        let presets = [PlanetSettings::earth(9), PlanetSettings::small(9)];
        let every_octave = presets.clone().map(|s| PlanetSettings { band_limit: 0.0, ..s });
        for planet in presets.into_iter().chain(every_octave).map(|s| ProceduralPlanet::new(s).unwrap()) {
            let mut exact_share = Vec::new();
            for (n, lod) in [0u8, 2, 7, 12].into_iter().enumerate() {
                let lod = lod.min(planet.layout.max_lod());
                let span = planet.layout.voxel_span(lod) as f64;
                let per_edge = i64::from(planet.layout.voxels_per_edge(lod));
                let face = CubeFace::ALL[n];
                // A padded chunk's columns, at a face edge for the last one.
                let base = if n == 3 { (-1, per_edge - 33) } else { (per_edge / 5, per_edge / 2) };
                let cells: Vec<_> = (0..34 * 34).map(|k| (base.0 + k % 34, base.1 + k / 34)).collect();
                let directions: Vec<_> =
                    cells.iter().map(|&(i, j)| planet.layout.sample_direction(face, lod, i, j)).collect();
                let samples: Vec<_> = cells.iter().map(|&(i, j)| planet.sample_column(face, lod, i, j)).collect();
                let resumed = planet.grid_states_by_face(&samples, planet.layout.voxel_span(lod), lod);
                let columns = planet.columns_at(&directions, resumed, lod, true);
                let mut exact = 0;
                for ((direction, column), &(owner, point)) in directions.iter().zip(&columns).zip(&samples) {
                    // Every grid read at the column, as for a point between
                    // columns: the same sums as a chunk of this LOD reads.
                    let [continents, ridges, hills] = planet.sums_at_columns(owner, &[point], &[*direction], 1, lod)[0];
                    let truth = planet.combine(continents, ridges, hills);
                    let climate = Climate {
                        sin_latitude: direction.z,
                        continents,
                        mountains: planet.mountains(continents, ridges),
                    };
                    let layers = truth / planet.layer_height;
                    if column.slack == 0.0 {
                        exact += 1;
                        assert_eq!(layers.to_bits(), column.height.to_bits(), "lod {lod}");
                        continue;
                    }
                    let slack = f64::from(column.slack);
                    assert!((layers - column.height).abs() <= slack, "lod {lod}: {layers} vs {column:?}");
                    let (low, high) =
                        ((column.height - slack) * planet.layer_height, (column.height + slack) * planet.layer_height);
                    let thresholds = planet.surface_thresholds(climate.sin_latitude);
                    assert!(
                        !planet.undecided(low, high, [climate; 2], &thresholds, span),
                        "lod {lod}: {column:?} undecided"
                    );
                    assert_eq!(column.surface, planet.sample(truth, climate, &thresholds).surface);
                }
                exact_share.push(exact as f64 / columns.len() as f64);
            }
            let band_limit = planet.settings.band_limit;
            println!(
                "share of columns to the last octave, LODs 0, 2, 7, 12 (band limit {band_limit}): {exact_share:.2?}"
            );
            assert!(
                band_limit > 0.0 || (exact_share[2] < 0.5 && exact_share[3] < 0.5),
                "coarse columns should leave early: {exact_share:?}"
            );
        }
    }

    /// A chunk's shared climate ranges decide every column's material as
    /// its own edges do, right at the edges too (where a range holds the
    /// continents sum, the exact edge is found), over random chunks of an
    /// Earth at LODs 0 to 8 (a LOD-0 chunk's ranges are about 3·10⁻⁵ wide,
    /// a LOD-8 chunk's span a degree); the ranges are in use at most.
    #[test]
    fn shared_climate_ranges_decide_as_each_columns_own_edges() {
        let planet = ProceduralPlanet::new(PlanetSettings::earth(3)).unwrap();
        let amplitude = planet.settings.amplitude;
        let mut state = 0x5eed_u64;
        let mut shared_chunks = 0;
        for n in 0..120 {
            let face = CubeFace::ALL[n % 6];
            let lod = (n % 9) as u8;
            let per_edge = i64::from(planet.layout.voxels_per_edge(lod));
            let mut at = || (nebula_math::unit_random(&mut state) * (per_edge - 34) as f64) as i64;
            let (i0, j0) = (at(), at());
            let directions: Vec<_> =
                (0..34 * 34).map(|k| planet.layout.sample_direction(face, lod, i0 + k % 34, j0 + k / 34)).collect();
            let ranged = planet.surface_thresholds_over(&directions);
            let mut shared = false;
            for (d, ranged) in directions.iter().zip(&ranged) {
                let exact = planet.surface_thresholds(d.z);
                shared |= ranged.continents != exact.continents;
                let [(desert, _), (forest, _)] = exact.continents;
                let [(desert_low, desert_high), (forest_low, forest_high)] = ranged.continents;
                for continents in [desert, forest, desert_low, desert_high, forest_low, forest_high]
                    .into_iter()
                    .flat_map(|c| [c.next_down(), c, c.next_up()])
                {
                    for height_m in [0.1 * amplitude, 0.3 * amplitude] {
                        let climate = Climate { sin_latitude: d.z, continents, mountains: 0.0 };
                        assert_eq!(
                            planet.surface(height_m, climate, ranged),
                            planet.surface(height_m, climate, &exact),
                            "{continents} at {height_m} m against {:?}",
                            exact.continents
                        );
                    }
                }
            }
            shared_chunks += usize::from(shared);
        }
        assert!(shared_chunks >= 60, "the ranges were shared at {shared_chunks} chunks of 120");
    }

    /// The octave grids move the terrain by little against every octave at
    /// every column (the same seed with `octave_grid` 0): at the highland
    /// columns (H over 400 m, where the mountains' detail is) among 40,000
    /// random LOD-0 columns of an Earth, 99 % within a tenth of a voxel
    /// and all within half of one (measured: 0.05 and 0.31 voxels; over
    /// all columns 0.015 and 0.24). Every octave read from the 16-column
    /// grid (ratio 0.01: 0.33 and 0.69) fails it.
    #[test]
    fn the_octave_grids_stay_close_to_the_exact_noise() {
        let deviations = |octave_grid: f64, octave_grid_error: f64| {
            let exact = ProceduralPlanet::new(PlanetSettings { octave_grid: 0.0, ..PlanetSettings::earth(3) }).unwrap();
            let grid =
                ProceduralPlanet::new(PlanetSettings { octave_grid, octave_grid_error, ..PlanetSettings::earth(3) })
                    .unwrap();
            let per_edge = i64::from(grid.layout.voxels_per_edge(0));
            let mut state = 0x1234_5678_u64;
            let mut deviations: Vec<f64> = (0..40_000)
                .filter_map(|_| {
                    let face = CubeFace::ALL[(nebula_math::unit_random(&mut state) * 6.0) as usize % 6];
                    let mut coord = || (nebula_math::unit_random(&mut state) * per_edge as f64) as i64;
                    let (i, j) = (coord(), coord());
                    let truth = exact.column(face, 0, i, j).height;
                    (truth * exact.layer_height > 400.0).then(|| (grid.column(face, 0, i, j).height - truth).abs())
                })
                .collect();
            deviations.sort_by(f64::total_cmp);
            (deviations[deviations.len() * 99 / 100], deviations[deviations.len() - 1])
        };
        let presets = PlanetSettings::earth(3);
        for (name, error) in [("ratio 16", 0.0), ("ratio 16 with coarse grids", presets.octave_grid_error)] {
            let (p99, largest) = deviations(16.0, error);
            println!("{name}: 99 % within {p99:.4} voxels, largest {largest:.4}");
            assert!(p99 < 0.1 && largest < 0.5, "{name}: 99 % within {p99} voxels, largest {largest}");
        }
        let (p99, largest) = deviations(0.01, 0.0);
        assert!(p99 >= 0.1 || largest >= 0.5, "every octave from 16-column grids should show: {p99}, {largest}");
        // Grids as coarse as the ratio alone allows, with no error budget.
        let (p99, largest) = deviations(16.0, 1e9);
        println!("ratio 16, no budget: 99 % within {p99:.4} voxels, largest {largest:.4}");
        assert!(p99 >= 0.1 || largest >= 0.5, "coarse grids past the budget should show: {p99}, {largest}");
    }

    /// A band-limited column (`BandLimited`) lies within what its chunk
    /// column's relief allows for the octaves left out (`dropped_within`,
    /// which widens the surface bounds and tight tops) of H at its
    /// far-corner LOD-0 column, at random places and over high mountains,
    /// LODs 1–9; and that allowance is not slack beyond use: somewhere the
    /// column comes within a tenth of it.
    #[test]
    fn band_limited_columns_lie_within_their_reliefs_allowance() {
        let planet = ProceduralPlanet::new(PlanetSettings::earth(21)).unwrap();
        assert!(planet.settings.band_limit > 0.0, "the preset is band-limited");
        let layout = planet.layout;
        let mut state = 0x0BA4D_u64;
        let (mut checked, mut closest) = (0, 0.0_f64);
        for n in 0..400 {
            let mut unit = || nebula_math::unit_random(&mut state);
            let lod = 1 + (n % 9) as u8;
            let face = CubeFace::ALL[n % 6];
            let per_edge = i64::from(layout.voxels_per_edge(lod));
            let (ci, cj) = ((unit() * per_edge as f64) as i64, (unit() * per_edge as f64) as i64);
            let span = layout.voxel_span(lod);
            let column = ChunkColumn { face, lod, x: (ci / 32) as u32, y: (cj / 32) as u32 };
            let allowance = planet.column_relief(column).unwrap().dropped;
            let coarse = planet.column(face, lod, ci, cj).height;
            let fine = planet.column(face, 0, (ci + 1) * span - 1, (cj + 1) * span - 1).height;
            let off = (coarse - fine).abs();
            assert!(off <= allowance, "{column:?} ({ci}, {cj}): {off} layers from H, allowed {allowance}");
            if allowance > 0.0 {
                closest = closest.max(off / allowance);
                checked += 1;
            }
        }
        println!("{checked} band-limited columns; the closest came to {closest:.3} of its allowance");
        assert!(checked > 300 && closest > 0.1, "{checked} checked, closest {closest}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        /// A LOD-0 column read as the far-corner column of a coarser LOD
        /// has the same height bit for bit as the LOD-0 column summed with
        /// that LOD's octaves (`BandLimited`; the grids finer than that LOD
        /// evaluated at it, as its nodes; `octave_grid.rs`), on any face,
        /// near its edges too, and lies within what those leave out of H;
        /// and `height_at` through the inverse map at the column's centre
        /// agrees with the LOD-0 column to a millionth of a layer.
        #[test]
        fn a_column_reads_the_same_at_every_lod(
            face in 0usize..6,
            (a, b) in (0.0f64..1.0, 0.0f64..1.0),
            lod in 1u8..7,
        ) {
            // Every octave at every LOD (the coarse column is the LOD-0
            // column's, bit for bit) and the preset, band-limited (the
            // LOD's sums leave octaves out).
            for band_limit in [0.0, PlanetSettings::earth(5).band_limit] {
            let planet = ProceduralPlanet::new(PlanetSettings { band_limit, ..PlanetSettings::earth(5) }).unwrap();
            let face = CubeFace::ALL[face];
            let per_edge = i64::from(planet.layout.voxels_per_edge(lod));
            let (ci, cj) = ((a * per_edge as f64) as i64, (b * per_edge as f64) as i64);
            let span = planet.layout.voxel_span(lod);
            let (i, j) = ((ci + 1) * span - 1, (cj + 1) * span - 1);
            let coarse = planet.column(face, lod, ci, cj).height;
            let fine = planet.column(face, 0, i, j).height;
            let direction = planet.layout.sample_direction(face, 0, i, j);
            let [continents, ridges, hills] =
                planet.sums_at_columns(face, &[[i as f64, j as f64]], &[direction], 1, lod)[0];
            let fine_band = planet.combine(continents, ridges, hills) / planet.layer_height;
            proptest::prop_assert_eq!(coarse.to_bits(), fine_band.to_bits(), "LOD {} against LOD 0", lod);
            if band_limit == 0.0 {
                proptest::prop_assert_eq!(coarse.to_bits(), fine.to_bits(), "LOD {} against H", lod);
            }
            let dropped = planet.bands[usize::from(lod)].dropped;
            proptest::prop_assert!((coarse - fine).abs() <= dropped, "{} from H {}: over {}", coarse, fine, dropped);
            let between = planet.height_at(direction) / planet.layer_height;
            proptest::prop_assert!((between - fine).abs() < 1e-6, "height_at {} against {}", between, fine);
            }
        }
    }
}
