//! Caves under a [`ProceduralPlanet`](crate::ProceduralPlanet)'s ground:
//! winding tunnels, chambers, and mouths where they reach the surface.
//!
//! # Shape
//!
//! Two networks of tunnels. Each follows the lines on the sphere where a
//! smooth noise `n` crosses zero (the "worm" lines of ridged noise: long,
//! winding, branching), at a depth below the local surface `H` that wanders
//! with a second noise, in a tunnel whose width and height swell with a
//! third into chambers:
//!
//! ```text
//!   e     = |n(d)| / (w · (1 + W·swell(d)) · region(d))     < 1 within the tunnel's width
//!   half  = r · (1 + R·swell(d)) · √(1 − e²)                 elliptic cross-section, layers
//!   air   ⇔ |depth − c(d)| < half,  depth = H − voxel centre (layers),
//!           and the voxel lies above sea level
//! ```
//!
//! The shallow network's centre `c` wanders from the surface down to a few
//! tunnel heights: where it rises within its half height of the ground the
//! tunnel opens (cave mouths, and the roofs left between two openings:
//! arches and overhangs). The deep network lies under it, never touching
//! it, and swells into larger chambers. `region` is a low-frequency noise
//! ramped to `[0, 1]`: about four fifths of the land has caves, the rest none.
//! Caves stay above the sea (the renderer's opaque sea is a sphere at sea
//! level), so an ocean is never hollow and the sea never hides an open cave.
//!
//! Everything is a function of a voxel column's direction (its far-corner
//! LOD-0 column, as for the heights) and its height `H`, so a column's
//! caves are computed once per column with its height and shared by the
//! chunk column's radial layers. A column with a tunnel over it has its
//! height computed exactly (every octave), so the depth is the same to the
//! bit wherever the voxel is read.
//!
//! # LOD rule: ground stays solid unless the cave is large at that LOD
//!
//! A voxel at LOD `L` is `s = 2^L` cells wide and layers tall; it samples
//! its far-corner LOD-0 voxel as the rest of the terrain does. It is cave
//! air only where that sample lies in the tunnel's **core**: the
//! cross-section shrunk by `(s − 1)/2` layers top and bottom, and its width
//! by `s − 1` cells (`e < 1 − (s − 1)/(2·half-width in cells)`). At LOD 0
//! the core is the tunnel. So a tunnel narrower or lower than about a
//! coarse voxel leaves no air at that LOD instead of a speckle of holes
//! (what sampling one voxel in `s³` gives where the tunnel is thinner than
//! `s`: the far-corner rule), and a chamber stays open at LODs whose voxels
//! it holds. Past [`Caves::coarsest_lod`] no cave survives and nothing is
//! evaluated. The measurements behind the choice are in the tests
//! (`coarse_cave_voxels_are_mostly_cave_at_lod_0`).
//!
//! The price is a pop where a chunk switches LOD over a cave (the coarse
//! chunk's cave is its fine cave's core), and the error bound δ(L) and
//! the skirts: where a coarse chunk is solid across a seam from a fine
//! chunk's tunnel, the seam is open down to the tunnel, so δ(L ≥ 1) reaches
//! the deepest cave air ([`Caves::deepest`]).

use nebula_math::DVec3;

use crate::VoxelError;
use crate::perlin::Fractal;
use crate::planet::smoothstep;

/// Caves open only above this altitude (layers over the base radius):
/// their air stays above the sea.
pub(crate) const SEA_MARGIN_LAYERS: f64 = 1.0;

/// Cave spans are stored in 1/64 layer (i16): enough for determinism, and
/// caves down to 511 layers.
const SPAN_UNITS: f64 = 64.0;

/// The region noise's value below which a place has no caves, and the
/// width of the ramp above it.
const REGION_FROM: f64 = -0.3;
const REGION_RAMP: f64 = 0.3;

/// The caves of one voxel column at one LOD: up to one span of air per
/// network, as depths below the column's height, in 1/64 layer.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct ColumnCaves {
    /// `[top, bottom]` depths of each network's air (`top < bottom`), or
    /// `[0, 0]` for none.
    spans: [[i16; 2]; 2],
    /// A tunnel passes over the column at LOD 0 (whatever this LOD keeps):
    /// its height must be exact, and a column of another LOD at the same
    /// place cannot lend its caves.
    pub(crate) near: bool,
}

impl ColumnCaves {
    /// No cave.
    pub(crate) const NONE: Self = Self { spans: [[0; 2]; 2], near: false };

    /// Whether a voxel whose sample centre lies `depth` layers under the
    /// column's height, at `altitude` layers over the base radius, is cave
    /// air.
    #[inline]
    pub(crate) fn holds(&self, depth: f64, altitude: f64) -> bool {
        if !self.near || altitude < SEA_MARGIN_LAYERS {
            return false;
        }
        let depth = depth * SPAN_UNITS;
        self.spans.iter().any(|&[top, bottom]| f64::from(top) < depth && depth < f64::from(bottom))
    }

    /// Whether a voxel sampled `depth` layers under the column's height
    /// (`depth > 0`), at `altitude`, and every voxel of `span` layers above
    /// it up to the ground are air: all their samples lie in one span
    /// (a cave mouth). The shallowest of those samples lies
    /// `depth − span·(⌈depth/span⌉ − 1)` down, in `(0, span]`: the span's
    /// top may lie below the ground as long as it is above that.
    pub(crate) fn open_from_the_surface(&self, depth: f64, altitude: f64, span: f64) -> bool {
        let shallowest = (depth - span * ((depth / span).ceil() - 1.0)) * SPAN_UNITS;
        self.holds(depth, altitude)
            && self
                .spans
                .iter()
                .any(|&[top, bottom]| f64::from(top) < shallowest && depth * SPAN_UNITS < f64::from(bottom))
    }
}

/// One network of tunnels (module docs), lengths in layers and cells.
#[derive(Clone, Debug)]
struct Network {
    course: Fractal,
    course_scale: f64,
    depth: Fractal,
    depth_scale: f64,
    swell: Fractal,
    swell_scale: f64,
    /// `w`: |n| at the edge of an unswollen tunnel.
    width: f64,
    /// The same edge in lattice cells from the tunnel's middle line
    /// (nominal: where n changes at its typical rate), for the LOD rule.
    half_width_cells: f64,
    /// `W`: how many times wider a chamber gets.
    widen: f64,
    /// `c = centre.0 + centre.1 · noise`, layers.
    centre: (f64, f64),
    /// `r`, layers.
    half_height: f64,
    /// `R`: how many times taller a chamber gets.
    heighten: f64,
}

/// A noise's sums at every direction of `directions` scaled by `scale`,
/// each bit for bit [`Fractal::get`]'s: neighbouring columns lie in one
/// lattice cell of these long wavelengths, and a batch hashes its corners
/// once for the run.
fn sums_at(fractal: &Fractal, scale: f64, directions: &[DVec3]) -> Vec<f64> {
    let points: Vec<[f64; 3]> = directions.iter().map(|d| (*d * scale).to_array()).collect();
    let mut sums = vec![0.0; points.len()];
    fractal.get_many(&points, &mut sums);
    sums
}

/// How much a place's region noise lets caves in, in `(0, 1]`, or `None`
/// where it lets none in.
fn region_weight(noise: f64) -> Option<f64> {
    let weight = smoothstep((noise - REGION_FROM) / REGION_RAMP);
    (weight > 0.0).then_some(weight)
}

/// The typical |∇n| of the course noise (2-octave fBm) along the sphere,
/// per unit of noise space: sets the tunnel's width in noise units from its
/// width in metres. (Its mean 3D gradient is 1.24, measured at 20,000
/// places, 1.24 near its zeros too; along a surface, √(2/3) of that.)
const COURSE_TYPICAL_GRADIENT: f64 = 1.0;

impl Network {
    /// The deepest air below the surface, layers.
    fn deepest(&self) -> f64 {
        self.centre.0 + self.centre.1 + self.half_height * (1.0 + self.heighten)
    }

    /// The shallowest, layers (negative: it can open at the surface).
    fn shallowest(&self) -> f64 {
        self.centre.0 - self.centre.1 - self.half_height * (1.0 + self.heighten)
    }

    /// Whether any tunnel of this network keeps air at voxels `span`
    /// layers tall.
    fn survives(&self, span: f64) -> bool {
        let widest = self.half_width_cells * (1.0 + self.widen);
        let tallest = self.half_height * (1.0 + self.heighten);
        (span - 1.0) / (2.0 * widest) < 1.0 && tallest - 0.5 * (span - 1.0) > 0.0
    }

    /// Whether a tunnel of this network can pass over a column whose
    /// course noise is `course` and region weight `region`, whatever its
    /// swell: `|n|` under `w · wide` at its widest (the swell at 1).
    /// Elsewhere [`Self::column`]'s `e` is at least 1 for any swell (each
    /// operation there rises with the swell, rounding included), so it is
    /// asked only where one can.
    fn may_pass(&self, course: f64, region: f64) -> bool {
        course.abs() < self.width * ((1.0 + self.widen) * region)
    }

    /// This network's air over the column in unit direction `d` whose
    /// course and swell noises are `course` and `swell` (`region` in
    /// `[0, 1]`), for voxels `span` layers tall: `(near, span in 1/64
    /// layer)`. The depth noise is read only where the column holds air
    /// (a column in many).
    fn column(&self, d: DVec3, course: f64, swell: f64, region: f64, span: f64) -> (bool, [i16; 2]) {
        let swell = swell.clamp(0.0, 1.0);
        let wide = (1.0 + self.widen * swell) * region;
        let e = course.abs() / (self.width * wide);
        if e >= 1.0 || wide <= 0.0 {
            return (false, [0, 0]);
        }
        let core = 1.0 - (span - 1.0) / (2.0 * self.half_width_cells * wide);
        let half = self.half_height * (1.0 + self.heighten * swell) * (1.0 - e * e).sqrt() - 0.5 * (span - 1.0);
        if e >= core || half <= 0.0 {
            return (true, [0, 0]);
        }
        let depth = self.depth.get((d * self.depth_scale).to_array());
        let centre = self.centre.0 + self.centre.1 * depth.clamp(-1.0, 1.0);
        let units = |depth: f64| (depth * SPAN_UNITS).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
        (true, [units(centre - half), units(centre + half)])
    }

    /// The course and swell noises at unit `directions` where a tunnel
    /// may pass ([`Self::may_pass`], `regions` by direction), each as
    /// [`Fractal::get`] gives it; `None` elsewhere. Each noise is one batch
    /// over the run, the swell's only over the columns the course leaves a
    /// tunnel possible at (about one in twenty at LOD 0). (Stopping each
    /// column's course at the octave whose bounds rule a tunnel out cost
    /// as much as it saved: the second octave's batch broke up.)
    fn noises(&self, directions: &[DVec3], regions: &[f64]) -> Vec<Option<(f64, f64)>> {
        let courses: Vec<(usize, f64)> = sums_at(&self.course, self.course_scale, directions)
            .into_iter()
            .enumerate()
            .filter(|&(k, course)| self.may_pass(course, regions[k]))
            .collect();
        let swell_directions: Vec<DVec3> = courses.iter().map(|&(k, _)| directions[k]).collect();
        let swells = sums_at(&self.swell, self.swell_scale, &swell_directions);
        let mut noises = vec![None; directions.len()];
        for (&(k, course), swell) in courses.iter().zip(swells) {
            noises[k] = Some((course, swell));
        }
        noises
    }
}

/// The cave networks of a planet (module docs).
#[derive(Clone, Debug)]
pub(crate) struct Caves {
    networks: Vec<Network>,
    region: Fractal,
    region_scale: f64,
    coarsest_lod: Option<u8>,
    deepest: f64,
}

impl Caves {
    /// The caves of a planet of `radius` metres with `layer_height`-metre
    /// layers, tunnels about `size` metres tall (0: none), from `seed`;
    /// the deep network at least `separation` layers under the shallow one
    /// (see [`Caves::separation`]).
    ///
    /// # Errors
    /// [`VoxelError::NonFinite`] / [`VoxelError::OutOfRange`] for a NaN,
    /// infinite or negative size, or caves deeper than 500 layers.
    pub(crate) fn new(
        size: f64,
        radius: f64,
        layer_height: f64,
        max_lod: u8,
        seed: u32,
        separation: f64,
    ) -> Result<Self, VoxelError> {
        if !size.is_finite() {
            return Err(VoxelError::NonFinite { name: "cave size", value: size });
        }
        if size < 0.0 {
            return Err(VoxelError::OutOfRange { name: "cave size", requirement: "≥ 0", value: size });
        }
        let c = size / layer_height;
        // Metres → noise space of a unit direction, for a wavelength.
        let scale = |wavelength_m: f64| radius / wavelength_m;
        let network = |salt: u32, course_m: f64, half_width: f64, widen, centre, half_height, heighten| {
            let course_scale = scale(course_m);
            Network {
                course: Fractal::fbm(seed.wrapping_add(salt), 2, 0.5, 2.0),
                course_scale,
                depth: Fractal::fbm(seed.wrapping_add(salt + 2), 1, 0.5, 2.0),
                depth_scale: scale(50.0 * size),
                swell: Fractal::fbm(seed.wrapping_add(salt + 3), 1, 0.5, 2.0),
                swell_scale: scale(15.0 * size),
                width: half_width * layer_height / course_m * COURSE_TYPICAL_GRADIENT,
                half_width_cells: half_width,
                widen,
                centre,
                half_height,
                heighten,
            }
        };
        let networks = if c > 0.0 {
            // Shallow: from the surface down to about three tunnel
            // heights, 3 m half wide on an Earth (5 m caves).
            let shallow = network(101, 18.0 * size, 0.6 * c, 0.5, (1.6 * c, 1.6 * c), 0.5 * c, 0.5);
            // Deep: `separation` under the shallow one or more, never
            // touching it, with chambers four times as wide and 2.5 times
            // as tall.
            let (swing, half_height, heighten) = (1.2 * c, 0.7 * c, 1.5);
            let centre = (7.0 * c).max(shallow.deepest() + separation + swing + half_height * (1.0 + heighten));
            let deep = network(111, 25.0 * size, 0.8 * c, 3.0, (centre, swing), half_height, heighten);
            vec![shallow, deep]
        } else {
            Vec::new()
        };
        let deepest = networks.iter().map(Network::deepest).fold(0.0, f64::max);
        if deepest * SPAN_UNITS > f64::from(i16::MAX) {
            return Err(VoxelError::OutOfRange {
                name: "cave size",
                requirement: "caves at most 500 layers deep (about 50 voxels)",
                value: size,
            });
        }
        let coarsest_lod =
            (0..=max_lod).take_while(|&lod| networks.iter().any(|n| n.survives(f64::from(1u32 << lod)))).last();
        Ok(Self {
            networks,
            region: Fractal::fbm(seed.wrapping_add(121), 1, 0.5, 2.0),
            // Regions a few kilometres across, a few to a small planet.
            region_scale: if c > 0.0 { scale((400.0 * size).min(radius / 4.0)) } else { 0.0 },
            coarsest_lod,
            deepest,
        })
    }

    /// The coarsest LOD any cave keeps air at, or `None` without caves.
    pub(crate) fn coarsest_lod(&self) -> Option<u8> {
        self.coarsest_lod
    }

    /// Whether voxels of `lod` can be cave air anywhere.
    pub(crate) fn at_lod(&self, lod: u8) -> bool {
        self.coarsest_lod.is_some_and(|coarsest| lod <= coarsest)
    }

    /// The deepest cave air anywhere, layers below the surface (0 without
    /// caves).
    pub(crate) fn deepest(&self) -> f64 {
        self.deepest
    }

    /// The deepest air of the shallow network, the one that opens at the
    /// surface, layers below it (0 without caves).
    pub(crate) fn shallow_deepest(&self) -> f64 {
        self.networks.first().map_or(0.0, Network::deepest)
    }

    /// Layers of rock, at the least, between the shallow network's air
    /// and the deep network's, measured down the same column (0 without
    /// caves). Where the ground changes by less than this between
    /// neighbouring voxel columns, no deep air touches shallow or open
    /// air: the deep network is sealed, seen only from inside it.
    pub(crate) fn separation(&self) -> f64 {
        match self.networks.as_slice() {
            [shallow, deep] => deep.shallowest() - shallow.deepest(),
            _ => 0.0,
        }
    }

    /// The caves of the voxel column in unit direction `d`, for voxels
    /// `span` layers tall.
    pub(crate) fn column(&self, d: DVec3, span: f64) -> ColumnCaves {
        let mut caves = ColumnCaves::default();
        if self.networks.is_empty() {
            return caves;
        }
        let Some(region) = region_weight(self.region.get((d * self.region_scale).to_array())) else {
            return caves;
        };
        for (network, span_out) in self.networks.iter().zip(&mut caves.spans) {
            let course = network.course.get((d * network.course_scale).to_array());
            if !network.may_pass(course, region) {
                continue;
            }
            let swell = network.swell.get((d * network.swell_scale).to_array());
            let (near, air) = network.column(d, course, swell, region, span);
            caves.near |= near;
            *span_out = air;
        }
        caves
    }

    /// [`Self::column`] of every direction of `directions` (a chunk's
    /// columns, neighbours next to each other), equal to it column for
    /// column: the region and course noises are summed over the run in
    /// batches, whose lattice cells neighbouring columns share, instead of
    /// hashing a cell's corners for every column and noise (13 % of a
    /// meshing thread's time in a 1 km/s flight); a column's swell and
    /// depth are read only where its course lets a tunnel pass
    /// ([`Network::noises`]).
    pub(crate) fn columns(&self, directions: &[DVec3], span: f64) -> Vec<ColumnCaves> {
        let mut caves = vec![ColumnCaves::NONE; directions.len()];
        if self.networks.is_empty() {
            return caves;
        }
        let regions = sums_at(&self.region, self.region_scale, directions);
        let (open, regions): (Vec<usize>, Vec<f64>) =
            regions.into_iter().enumerate().filter_map(|(k, noise)| Some((k, region_weight(noise)?))).unzip();
        let open_directions: Vec<DVec3> = open.iter().map(|&k| directions[k]).collect();
        for (n, network) in self.networks.iter().enumerate() {
            let noises = network.noises(&open_directions, &regions);
            for (j, &k) in open.iter().enumerate() {
                let Some((course, swell)) = noises[j] else { continue };
                let (near, air) = network.column(open_directions[j], course, swell, regions[j], span);
                caves[k].near |= near;
                caves[k].spans[n] = air;
            }
        }
        caves
    }

    /// Whether a patch within `reach` radians of unit direction `centre`
    /// may hold caves at all (the region noise's range over it).
    pub(crate) fn may_be_near(&self, centre: DVec3, reach: f64) -> bool {
        !self.networks.is_empty()
            && self.region.range_near((centre * self.region_scale).to_array(), reach * self.region_scale, &[]).1
                > REGION_FROM
    }

    /// Whether the shallow network can open at the surface (its air reaches
    /// depth 0): a test's sanity check on the parameters.
    #[cfg(test)]
    pub(crate) fn opens_at_the_surface(&self) -> bool {
        self.networks.first().is_some_and(|n| n.shallowest() < 0.0)
            && self.networks.windows(2).all(|w| w[0].deepest() < w[1].shallowest())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{PlanetSettings, ProceduralPlanet, VoxelSource};

    #[test]
    fn a_mouth_is_open_to_the_sky_down_to_its_floor() {
        // A span from 0.3 layers under the ground down to 5: the ground's
        // top voxel (sample 0.5 down) is already in it, so every voxel down
        // to the floor sees the sky; with its top below the first sample
        // (0.6), none does; at LOD 1 (samples 1.5, 3.5 down: voxels two
        // layers tall) the first sample decides too.
        let caves = |top: f64| ColumnCaves {
            spans: [[(top * SPAN_UNITS) as i16, (5.0 * SPAN_UNITS) as i16], [0; 2]],
            near: true,
        };
        let altitude = 100.0;
        for depth in [0.5, 1.5, 2.5, 4.5] {
            assert!(caves(0.3).open_from_the_surface(depth, altitude, 1.0), "{depth}");
            assert!(!caves(0.6).open_from_the_surface(depth, altitude, 1.0), "{depth}");
        }
        assert!(!caves(0.3).open_from_the_surface(5.5, altitude, 1.0), "under the floor");
        assert!(caves(1.2).open_from_the_surface(3.5, altitude, 2.0));
        assert!(!caves(1.6).open_from_the_surface(3.5, altitude, 2.0));
        assert!(!caves(0.3).open_from_the_surface(1.5, 0.5, 1.0), "under the sea margin");
    }

    #[test]
    fn the_presets_caves_open_at_the_surface_and_their_networks_stay_apart() {
        for settings in [PlanetSettings::earth(1), PlanetSettings::small(1)] {
            let planet = ProceduralPlanet::new(settings.clone()).unwrap();
            let layer = planet.voxel_size();
            let caves = planet.caves();
            assert!(caves.opens_at_the_surface());
            let coarsest = caves.coarsest_lod().unwrap();
            println!(
                "radius {} m: caves {} m, shallow down to {:.1} m, all down to {:.1} m, {:.1} layers apart (S = {:.2}), kept to LOD {coarsest}",
                settings.radius,
                settings.cave_size,
                caves.shallow_deepest() * layer,
                caves.deepest() * layer,
                caves.separation(),
                planet.max_slope()
            );
            assert!((1..=6).contains(&coarsest));
            assert!(caves.separation() >= 4.0 * planet.max_slope() + 2.0 - 1e-9);
            // δ covers the deepest cave at every coarse LOD.
            for lod in 1..=planet.layout().max_lod() {
                assert!(planet.geometric_error(lod) >= caves.deepest() * layer);
            }
        }
        let none = Caves::new(0.0, 6_371_000.0, 1.0, 18, 1, 0.0).unwrap();
        assert_eq!((none.coarsest_lod(), none.deepest()), (None, 0.0));
        assert!(matches!(Caves::new(f64::NAN, 1.0, 1.0, 3, 1, 0.0), Err(VoxelError::NonFinite { .. })));
        assert!(matches!(Caves::new(-1.0, 1.0, 1.0, 3, 1, 0.0), Err(VoxelError::OutOfRange { .. })));
        assert!(matches!(Caves::new(60.0, 6_371_000.0, 1.0, 18, 1, 0.0), Err(VoxelError::OutOfRange { .. })));
    }

    /// A patch of `side`² columns `step` radians apart around `centre`,
    /// row by row (as a chunk's columns come).
    fn patch(centre: DVec3, side: usize, step: f64) -> Vec<DVec3> {
        let east = DVec3::Z.cross(centre).try_normalize().unwrap_or(DVec3::X);
        let north = centre.cross(east);
        let offset = |k: usize| (k as f64 - side as f64 / 2.0) * step;
        (0..side * side).map(|k| (centre + east * offset(k % side) + north * offset(k / side)).normalize()).collect()
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        /// A chunk's columns in one batch are each what one column alone
        /// is, at LOD 0 and coarser, in cave regions and out of them.
        #[test]
        fn caves_of_a_run_of_columns_are_each_columns_own(
            seed in 0u32..1000,
            (x, y, z) in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            lod in 0u8..5,
        ) {
            let Some(centre) = DVec3::new(x, y, z).try_normalize() else { return Ok(()) };
            let caves = Caves::new(5.0, 6_371_000.0, 1.0, 18, seed, 8.0).unwrap();
            let span = f64::from(1u32 << lod);
            // Columns `span` metres apart on an Earth, and a patch wide
            // enough to meet a tunnel: look for one nearby first.
            let near_a_tunnel = patch(centre, 48, 40.0 / 6_371_000.0)
                .into_iter()
                .find(|&d| caves.column(d, 1.0).near)
                .unwrap_or(centre);
            // Interleaved with a patch where the region lets no cave in,
            // so the batch mixes open and closed columns.
            let closed = (1..200)
                .map(|k| (centre + DVec3::new(0.37, -0.61, 0.7) * (f64::from(k) * 1e-3)).normalize())
                .find(|&d| region_weight(caves.region.get((d * caves.region_scale).to_array())).is_none());
            let mut directions = patch(near_a_tunnel, 24, span / 6_371_000.0);
            if let Some(closed) = closed {
                let others = patch(closed, 24, span / 6_371_000.0);
                directions = directions.into_iter().zip(others).flat_map(|(a, b)| [a, b]).collect();
            }
            let batch = caves.columns(&directions, span);
            for (d, batched) in directions.iter().zip(batch) {
                proptest::prop_assert_eq!(batched, caves.column(*d, span));
            }
        }
    }

    #[test]
    fn the_batch_test_meets_tunnels() {
        // The property above compares columns near tunnels, not only
        // empty ones: at least one random place in eight has a tunnel with
        // air within a 2 km patch (the property searches such a patch).
        let caves = Caves::new(5.0, 6_371_000.0, 1.0, 18, 7, 8.0).unwrap();
        let found = (0..64)
            .map(|k| {
                let a = f64::from(k) * 2.399_963;
                DVec3::new(a.cos(), a.sin(), (f64::from(k) / 32.0) - 1.0).normalize()
            })
            .filter(|&centre| {
                let directions = patch(centre, 48, 40.0 / 6_371_000.0);
                caves.columns(&directions, 1.0).iter().any(|c| c.near && c.spans != [[0; 2]; 2])
            })
            .count();
        assert!(found >= 8, "only {found} of 64 places near a tunnel with air");
    }
}
