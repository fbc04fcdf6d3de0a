//! The GPU form of a chunk mesh, and the vertex shader's twin on the CPU.
//!
//! ```text
//!   world position p, morph target t (f64, canonical), the chunk's LOD L
//!        ──►  high = f32(t), target_low = f16(t − high),
//!             offset = f16((p − t) / 2^L)
//!   eye e (f64, per frame)  ──►  high = f32(e), low = f32(e − high)
//!
//!   on the GPU:  base   = high − e.high                                (f32)
//!                target = base + (target_low − e.low)
//!                rel    = target + μ(|target + offset·2^L|) · offset·2^L   geomorph
//!                rel   += depth[side] · normalize(centre − rel)       lowered skirt corners
//! ```
//!
//! **Why high + low.** Design rule 6: a vertex shared by two chunks must
//! reach the rasteriser at the bit-identical clip position in both, or the
//! sub-pixel gap rounding leaves shows as pinholes where chunks meet. A
//! per-chunk f32 offset (origin − eye) plus a chunk-local f32 position
//! rounds differently in each chunk. Here every input of the vertex shader
//! is a function of the vertex's canonical f64 world position, its morph
//! target and its LOD (and the frame) alone, never of the chunk that draws
//! it, so the same arithmetic on the same numbers gives the same clip
//! position. `p.high − e.high` is exact when the two are within a factor of
//! 2 (Sterbenz), so precision near the camera is that of the low parts.
//!
//! **Why the high part is the morph target's.** Geomorphing collapses
//! distinct fine vertices onto one target (all of a parent cell's corners
//! that round down to the same even lattice point). At μ = 0 those vertices
//! must land on the bit-identical position too, or the triangles on either
//! side of the collapsed ones can leave a float-rounding pinhole between
//! them. A vertex that carried `morph target − position` as an offset added
//! to its own position reached the target by a different rounding from each
//! fine vertex (in 71 % of collapsing groups on Earth terrain, see the
//! tests). Here the target is a function of the target alone (`high`,
//! `target_low`), the fine position is the target plus the vertex's offset,
//! and `target + μ · offset` is exactly `target` at μ = 0 and exactly the
//! fine position at μ = 1.
//!
//! **Why half floats.** The two low parts are small: `target_low` is at
//! most half an f32 step of the planet's radius (0.25 m on Earth) and the
//! offset a few voxels of the chunk's LOD, which the scale 2^L brings to a
//! few units at every LOD (2^L is exact: the scale changes the exponent, not
//! the rounding, so the same offset stored at two LODs reads back the same).
//! An f16 keeps 11 significant bits: drawn positions are within 0.12 mm
//! (the target) plus 2^-12 of the offset (0.4 mm for an LOD-0 vertex 1.7 m
//! from its target) of the f64 truth, fixed in the world (no jitter as the
//! eye moves), the same in every chunk that shares the vertex. Two f32
//! triples took 24 bytes; two f16 triples take 12.
//!
//! **Why skirts at draw time, from edges.** A skirt is the quad under each
//! outline edge of a side, its top the two surface vertices, its bottom the
//! same two lowered towards the centre as deep as the renderer asks for
//! that side, from the LODs it actually draws next to it. So a mesh does
//! not depend on its neighbours' LODs, and a streamer can swap any chunk
//! without re-meshing the ones around it (see `MeshOptions`). A render mesh
//! keeps only the edges ([`RenderMesh::skirt_edges`]); the top corners are
//! placed by the same code as the surface vertices, so they land on the
//! same bits.
//!
//! Cost: 32 bytes per vertex against the 40 of a chunk-relative f32 vertex
//! ([`MeshVertex`](crate::MeshVertex)) and the 44 of this vertex with f32
//! low parts (before 2026-11-27); with u16 indices and skirts as edges in
//! the renderer, the still Earth view 1 km up at 640×400 holds 27.1 MB of
//! meshes (38.1 MB with skirts as triangles, 57.0 MB before that).

use bytemuck::{Pod, Zeroable};
use half::{f16, slice::HalfFloatSliceExt};
use nebula_math::{DVec3, FaceDirection, Vec3, morph_factor};

use crate::ChunkMesh;

/// One vertex as the GPU reads it: 32 bytes, `#[repr(C)]`, [`Pod`].
///
/// | bytes | field | vertex format |
/// |---|---|---|
/// | 0–11 | `position_high`: f32 × 3, f32 of the morph target's world position | `Float32x3` |
/// | 12–17 | `offset`: f16 × 3, (world position − morph target) / 2^LOD | `Float16x4` (with `target_low.x`) |
/// | 18–23 | `target_low`: f16 × 3, morph target − high | `Float16x2` (`.y`, `.z`) |
/// | 24–27 | `normal`: octahedral, 2 × i16 | `Snorm16x2` |
/// | 28–31 | `packed`: material (bits 0–7), sky light (8–15), flags (16–23), LOD of the offset's scale (24–31) | `Uint32` |
///
/// A render mesh holds surface vertices only. ([`ChunkMesh::render_vertices`]
/// also converts a chunk mesh's skirt vertices: such a vertex holds the
/// surface vertex it hangs from, and `flags` says it is a skirt and on
/// which side, [`MeshVertex::skirt_side`](crate::MeshVertex::skirt_side).)
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct RenderVertex {
    /// f32 of the morph target's f64 world position (shared by every vertex
    /// that collapses onto it).
    pub position_high: [f32; 3],
    /// f16 of (world position − morph target) / 2^LOD, the LOD in `packed`.
    pub offset: [f16; 3],
    /// f16 of (morph target − `position_high`).
    pub target_low: [f16; 3],
    /// Unit normal, octahedral encoding, snorm16 × 2.
    pub normal: [i16; 2],
    /// Material id in bits 0–7, [`MeshVertex::sky_light`](crate::MeshVertex::sky_light)
    /// in bits 8–15, [`MeshVertex`](crate::MeshVertex) flags in bits 16–23,
    /// the LOD that scales `offset` in bits 24–31.
    pub packed: u32,
}

/// Bits of [`RenderVertex::packed`] above which the offset's LOD lies.
const OFFSET_LOD_SHIFT: u32 = 24;

/// A vector split into a high f32 part and the f32 of the rest.
#[must_use]
pub fn split_high_low(v: DVec3) -> ([f32; 3], [f32; 3]) {
    let high = v.as_vec3();
    ((high).to_array(), (v - high.as_dvec3()).as_vec3().to_array())
}

/// Octahedral encoding of a unit vector into two snorm16 values.
#[must_use]
pub fn encode_normal(n: Vec3) -> [i16; 2] {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(f32::MIN_POSITIVE);
    let sign = |x: f32| if x >= 0.0 { 1.0 } else { -1.0 };
    let (u, v) = if n.z >= 0.0 { (n.x, n.y) } else { ((1.0 - n.y.abs()) * sign(n.x), (1.0 - n.x.abs()) * sign(n.y)) };
    [round_to_i16(u.clamp(-1.0, 1.0) * 32767.0), round_to_i16(v.clamp(-1.0, 1.0) * 32767.0)]
}

/// `x.round() as i16` for |x| ≤ 32767 (NaN gives 0 too), without a call:
/// x86-64's baseline has no rounding instruction, so `round` is libm's
/// `roundf` (an eighth of making a render mesh). Truncation is a
/// conversion, and x less its truncation is exact.
fn round_to_i16(x: f32) -> i16 {
    let truncated = x as i32;
    let fraction = x - truncated as f32;
    let rounded = (truncated + i32::from(fraction >= 0.5) - i32::from(fraction <= -0.5)) as i16;
    debug_assert_eq!(rounded, x.round() as i16);
    rounded
}

/// Decodes [`encode_normal`] (the shader's `decode_normal`).
#[must_use]
pub fn decode_normal(e: [i16; 2]) -> Vec3 {
    let (x, y) = (f32::from(e[0]) / 32767.0, f32::from(e[1]) / 32767.0);
    let mut n = Vec3::new(x, y, 1.0 - x.abs() - y.abs());
    let t = (-n.z).max(0.0);
    n.x += if n.x >= 0.0 { -t } else { t };
    n.y += if n.y >= 0.0 { -t } else { t };
    n.normalize_or_zero()
}

/// What the vertex shader reads per frame, in the form the GPU gets it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameDraw {
    /// The eye, high part.
    pub eye_high: [f32; 3],
    /// The eye, low part.
    pub eye_low: [f32; 3],
    /// K, pixels per radian.
    pub k: f64,
    /// τ, pixels.
    pub threshold_px: f64,
    /// Geomorphing on.
    pub morph: bool,
}

impl FrameDraw {
    /// The constants for an eye at `eye`.
    #[must_use]
    pub fn new(eye: DVec3, k: f64, threshold_px: f64, morph: bool) -> Self {
        let (eye_high, eye_low) = split_high_low(eye);
        Self { eye_high, eye_low, k, threshold_px, morph }
    }

    /// The eye the GPU sees (high + low), f64.
    #[must_use]
    pub fn eye(&self) -> DVec3 {
        Vec3::from_array(self.eye_high).as_dvec3() + Vec3::from_array(self.eye_low).as_dvec3()
    }
}

/// What the vertex shader reads per chunk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChunkDraw {
    /// The error of the LOD the chunk merges into (its parent's voxel
    /// edge), metres; +∞ for the coarsest LOD, which never morphs.
    pub parent_error: f64,
    /// Skirt depth per horizontal side (index as in
    /// [`FaceDirection::HORIZONTAL`]), metres.
    pub skirt_depths: [f32; 4],
    /// Bit `FaceDirection as usize` set: every surface face looking towards
    /// that side looks away from the eye, so its triangles are left out
    /// ([`drawn_ranges`]); drawn, they would be back faces, always behind
    /// the front of the closed surface. Of a wall side, the faces the
    /// morph keeps at least a voxel tall ([`ChunkMesh::surface_parts`]).
    ///
    /// A face may be left out only where it looks away by enough that the
    /// rasteriser's rounding cannot turn it: the faces either side of it
    /// then overlap on screen by its width, and rounding their unshared
    /// edges apart can open a pinhole. Drawn, a face whose rounded corners
    /// turn it to the eye is rasterised exactly in such a gap (it shares
    /// both edges), and culled where there is none.
    pub hidden_sides: u8,
    /// Bit `FaceDirection as usize` set: of a wall side, the faces the
    /// morph flattens are left out too (they shrink with μ, so they must
    /// look away by more to be left out).
    pub hidden_flattening: u8,
    /// Bit `FaceDirection as usize` set (horizontal sides): the faces
    /// around that side's stubs ([`ChunkMesh::plugged_inside`]) are left
    /// out. Only where every chunk of the column and of the neighbouring
    /// column of the same LOD there is drawn plugged inside, none with a
    /// stub exposed ([`ChunkMesh::stubs_exposed`]) and none with a pocket
    /// reaching a layer either column draws
    /// ([`ChunkMesh::pockets_beyond`]): the chunks' rock then closes each
    /// pocket on every side, and what is left out looks into a cavity
    /// inside it.
    pub hidden_stubs: u8,
}

/// How many parts a surface is drawn in ([`ChunkMesh::surface_parts`]).
pub const SURFACE_PARTS: usize = 16;

impl ChunkDraw {
    /// Draw constants leaving nothing out.
    #[must_use]
    pub fn new(parent_error: f64, skirt_depths: [f32; 4]) -> Self {
        Self { parent_error, skirt_depths, hidden_sides: 0, hidden_flattening: 0, hidden_stubs: 0 }
    }

    /// The surface parts drawn (bit n: part n of
    /// [`ChunkMesh::surface_parts`]).
    #[must_use]
    pub fn drawn_parts(&self) -> u16 {
        let flattening = !self.hidden_flattening;
        u16::from(!self.hidden_sides) & 0x3f | Self::wall_parts(flattening) | u16::from(!self.hidden_stubs & 0x3f) << 10
    }

    /// The parts of the flattened faces of the wall sides set in `sides`
    /// (`FaceDirection::HORIZONTAL[k]` is side k).
    fn wall_parts(sides: u8) -> u16 {
        u16::from(sides & 0xf) << 6
    }
}

impl RenderVertex {
    /// The camera-relative position the vertex shader computes (before the
    /// projection), in f64 from the same f32 inputs: the CPU twin used by
    /// the crack oracle and the pop measurement. The relative position
    /// itself is formed in f32 exactly as on the GPU.
    #[must_use]
    pub fn drawn_relative(&self, frame: &FrameDraw, chunk: &ChunkDraw) -> DVec3 {
        let target = Vec3::from_array(std::array::from_fn(|k| {
            (self.position_high[k] - frame.eye_high[k]) + (self.target_low[k].to_f32() - frame.eye_low[k])
        }));
        let offset = self.offset_metres();
        let fine = target + offset;
        let mut rel = fine.as_dvec3();
        if frame.morph {
            let mu = vertex_morph_factor(frame, chunk, rel.length());
            rel = target.as_dvec3() + offset.as_dvec3() * mu;
        }
        if self.flags() & crate::MeshVertex::SKIRT != 0 {
            let side = usize::from((self.flags() >> crate::MeshVertex::SIDE_SHIFT) & 3);
            rel = lowered(rel, frame, chunk.skirt_depths[side]);
        }
        rel
    }

    /// The morph target's world position as the GPU reads it (its f32 and
    /// f16 parts, summed in f64).
    #[must_use]
    pub fn target_position(&self) -> DVec3 {
        self.target_with_low(Vec3::from_array(self.target_low.map(f16::to_f32)))
    }

    /// World position − morph target, metres, as the GPU reads it: the f16
    /// offset times 2^LOD (exact in f32).
    #[must_use]
    pub fn offset_metres(&self) -> Vec3 {
        self.offset_from(Vec3::from_array(self.offset.map(f16::to_f32)))
    }

    /// [`Self::target_position`] from `target_low` already in f32.
    fn target_with_low(&self, low: Vec3) -> DVec3 {
        Vec3::from_array(self.position_high).as_dvec3() + low.as_dvec3()
    }

    /// [`Self::offset_metres`] from `offset` already in f32: times 2^LOD.
    fn offset_from(&self, offset: Vec3) -> Vec3 {
        offset * f32::from_bits((127 + (self.packed >> OFFSET_LOD_SHIFT)) << 23)
    }

    /// The material id.
    #[must_use]
    pub fn material(&self) -> u8 {
        (self.packed & 0xff) as u8
    }

    /// The sky light, 0–255 ([`MeshVertex::sky_light`](crate::MeshVertex::sky_light)).
    #[must_use]
    pub fn sky_light(&self) -> u8 {
        ((self.packed >> 8) & 0xff) as u8
    }

    /// The flags ([`MeshVertex`](crate::MeshVertex) constants).
    #[must_use]
    pub fn flags(&self) -> u16 {
        ((self.packed >> 16) & 0xff) as u16
    }
}

/// μ of a vertex at `distance` metres from the eye in a chunk drawn with
/// `chunk`'s parent error: [`nebula_math::morph_factor`] of ρ_parent/τ, as
/// the shader computes it.
#[must_use]
pub fn vertex_morph_factor(frame: &FrameDraw, chunk: &ChunkDraw, distance: f64) -> f64 {
    let rho = chunk.parent_error * frame.k / distance.max(1e-3);
    morph_factor(rho / frame.threshold_px)
}

/// Where a skirt vertex hangs: `relative` (a drawn surface vertex, camera
/// relative) moved `depth` metres towards the planet centre, as the skirt
/// vertex shader moves it (the centre from the frame's eye).
#[must_use]
pub fn lowered(relative: DVec3, frame: &FrameDraw, depth: f32) -> DVec3 {
    let centre = -frame.eye();
    relative + (centre - relative).normalize_or_zero() * f64::from(depth)
}

/// The six corners of the two triangles of the skirt quad under an
/// outline edge (a, b): which end (0 = a, 1 = b) and whether it is the
/// lowered copy. The surface runs a → b; the skirt continues it, so it
/// runs b → a, wound as the surface so that it faces away from the chunk
/// (the skirt vertex shader's `SKIRT_ENDS` / `SKIRT_LOWERED` twin; the
/// same triangles [`generate_skirt`](crate::generate_skirt) makes).
pub const SKIRT_CORNERS: [(usize, bool); 6] = [(0, true), (1, false), (0, false), (1, true), (1, false), (0, true)];

/// A chunk mesh in the form a renderer uploads: [`RenderVertex`]es of the
/// surface, its triangle list by the side its faces look to, and each
/// side's skirt as the outline edges it hangs from.
///
/// A skirt is not stored as triangles: a renderer draws the quad under
/// each outline edge from the edge's two surface vertices, lowered at draw
/// time ([`SKIRT_CORNERS`], [`lowered`]). Every chunk carries a skirt on
/// each of its four sides (its neighbours' LODs may change without a new
/// mesh) and a frame lowers a few of them: stored as triangles with their
/// lowered vertices they took 44 bytes per outline edge and about a
/// quarter of a chunk's bytes; as a pair of u16 vertex indices, 4 bytes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderMesh {
    /// The surface's vertices.
    pub vertices: Vec<RenderVertex>,
    /// The surface's triangle list.
    pub indices: Vec<u32>,
    /// The surface's triangles in the parts a renderer may leave out apart
    /// (as in [`ChunkMesh::surface_parts`]): ranges of `indices` that
    /// together are `indices`.
    pub surface_parts: [std::ops::Range<usize>; SURFACE_PARTS],
    /// Outline edges `[a, b]` skirts hang from (vertex indices; the surface
    /// runs a → b along the chunk's side).
    pub skirt_edges: Vec<[u32; 2]>,
    /// The range of `skirt_edges` of each side's skirt (index as in
    /// `FaceDirection::HORIZONTAL`).
    pub skirt_ranges: [std::ops::Range<usize>; 4],
    /// A radius, metres, under which no point of the surface is drawn,
    /// morphed or not (skirts hang lower): what an occlusion test may take
    /// as rock under the chunk's patch. `INFINITY` for an empty mesh.
    pub lowest_radius: f64,
    /// Whether some of the chunk's dark cave air was meshed as rock
    /// ([`ChunkMesh::dark_air_plugged`]).
    pub dark_air_plugged: bool,
    /// [`ChunkMesh::plugged_inside`].
    pub plugged_inside: bool,
    /// [`ChunkMesh::stubs_exposed`].
    pub stubs_exposed: bool,
    /// [`ChunkMesh::pockets_beyond`].
    pub pockets_beyond: [bool; 2],
}

impl RenderMesh {
    /// Each vertex's [`RenderVertex::target_position`] and
    /// [`RenderVertex::offset_metres`], in order, the same values bit for
    /// bit (tested), with their f16 parts converted together (as `ChunkMesh::render_vertices`
    /// makes them): one value at a time, a call and a feature test each,
    /// they were a twentieth of a 12° lens view's CPU time, in a renderer's
    /// cull boxes.
    #[must_use]
    pub fn targets_and_offsets(&self) -> Vec<(DVec3, Vec3)> {
        // Copied three at a time (an iterator over both arrays chained
        // went value by value: most of this function's time).
        let mut halves: Vec<f16> = Vec::with_capacity(6 * self.vertices.len());
        for vertex in &self.vertices {
            halves.extend_from_slice(&vertex.offset);
            halves.extend_from_slice(&vertex.target_low);
        }
        let mut floats = vec![0.0_f32; halves.len()];
        halves.convert_to_f32_slice(&mut floats);
        self.vertices
            .iter()
            .zip(floats.chunks_exact(6))
            .map(|(vertex, parts)| {
                let (offset, low) = (Vec3::new(parts[0], parts[1], parts[2]), Vec3::new(parts[3], parts[4], parts[5]));
                (vertex.target_with_low(low), vertex.offset_from(offset))
            })
            .collect()
    }

    /// Bytes of its vertices, indices and skirt edges.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        (size_of_val(self.vertices.as_slice())
            + size_of_val(self.indices.as_slice())
            + size_of_val(self.skirt_edges.as_slice())) as u64
    }

    /// The index ranges of the surface drawn with `draw` (the parts it
    /// does not hide).
    pub fn drawn_ranges(&self, draw: &ChunkDraw) -> impl Iterator<Item = std::ops::Range<usize>> + use<> {
        drawn_ranges(&self.surface_parts, draw)
    }

    /// Triangles of each part of the surface (as in
    /// [`ChunkMesh::surface_parts`]), and of each side's skirt (two per
    /// outline edge).
    #[must_use]
    pub fn triangle_counts(&self) -> ([usize; SURFACE_PARTS], [usize; 4]) {
        (self.surface_parts.clone().map(|r| r.len() / 3), self.skirt_ranges.clone().map(|r| 2 * r.len()))
    }

    /// The triangles drawn with `frame` and `chunk`, camera relative, as
    /// the vertex shaders place them: the surface but the hidden sides,
    /// then the skirts of the sides lowered (the CPU twin of a renderer's
    /// draws, for the crack oracle and pop measurements).
    #[must_use]
    pub fn drawn_triangles(&self, frame: &FrameDraw, chunk: &ChunkDraw) -> Vec<[DVec3; 3]> {
        let placed: Vec<DVec3> = self.vertices.iter().map(|v| v.drawn_relative(frame, chunk)).collect();
        let placed = &placed;
        let surface = self
            .drawn_ranges(chunk)
            .flat_map(|range| self.indices[range].chunks_exact(3))
            .map(|t| [placed[t[0] as usize], placed[t[1] as usize], placed[t[2] as usize]]);
        let skirts = lowered_skirts(&self.skirt_ranges, chunk).flat_map(|(side, range)| {
            let depth = chunk.skirt_depths[side];
            self.skirt_edges[range].iter().flat_map(move |edge| {
                let corner = |(end, low): (usize, bool)| {
                    let top = placed[edge[end] as usize];
                    if low { lowered(top, frame, depth) } else { top }
                };
                let corners = SKIRT_CORNERS.map(corner);
                [[corners[0], corners[1], corners[2]], [corners[3], corners[4], corners[5]]]
            })
        });
        surface.chain(skirts).collect()
    }
}

/// The index ranges of the surface parts `draw` does not hide (as in
/// [`ChunkMesh::surface_parts`]), in index order, adjacent ranges merged.
/// No allocation: a renderer calls it for every drawn chunk every frame.
pub fn drawn_ranges(
    surface: &[std::ops::Range<usize>; SURFACE_PARTS],
    draw: &ChunkDraw,
) -> impl Iterator<Item = std::ops::Range<usize>> + use<> {
    let parts = draw.drawn_parts();
    let mut ranges: [std::ops::Range<usize>; SURFACE_PARTS] = Default::default();
    let mut count = 0;
    let shown = surface.iter().enumerate().filter(|(part, _)| parts & (1 << part) != 0);
    for (_, range) in shown.filter(|(_, r)| !r.is_empty()) {
        ranges[count] = range.clone();
        count += 1;
    }
    ranges[..count].sort_unstable_by_key(|r| r.start);
    let mut merged = 0;
    for n in 0..count {
        if merged > 0 && ranges[merged - 1].end == ranges[n].start {
            ranges[merged - 1].end = ranges[n].end;
        } else {
            ranges[merged] = ranges[n].clone();
            merged += 1;
        }
    }
    ranges.into_iter().take(merged)
}

/// The skirts `draw` lowers: each side (index as in
/// `FaceDirection::HORIZONTAL`) with a depth above 0 and outline edges,
/// and its range of a [`RenderMesh`]'s `skirt_edges`.
pub fn lowered_skirts(
    skirts: &[std::ops::Range<usize>; 4],
    draw: &ChunkDraw,
) -> impl Iterator<Item = (usize, std::ops::Range<usize>)> + use<> {
    let depths = draw.skirt_depths;
    skirts.clone().into_iter().enumerate().filter(move |(side, r)| depths[*side] > 0.0 && !r.is_empty())
}

impl ChunkMesh {
    /// The mesh in the form a renderer uploads: the surface's vertices and
    /// triangles, the skirts as the outline edges they hang from.
    #[must_use]
    pub fn render_mesh(&self) -> RenderMesh {
        // Skirt vertices (the lowered copies) are left out, the others
        // renumbered in order.
        let mut renumbered = vec![u32::MAX; self.vertices.len()];
        let mut surface = Vec::with_capacity(self.vertices.len());
        for (i, number) in renumbered.iter_mut().enumerate() {
            if self.skirt_top(i).is_none() {
                *number = surface.len() as u32;
                surface.push(i);
            }
        }
        let indices = self.indices[..self.surface_index_count].iter().map(|&i| renumbered[i as usize]).collect();
        let mut skirt_edges = Vec::new();
        let skirt_ranges = self.skirt_ranges.clone().map(|range| {
            let first = skirt_edges.len();
            let edges = crate::seams::skirt_outline(&self.indices[range]);
            skirt_edges.extend(edges.map(|[a, b]| [renumbered[a as usize], renumbered[b as usize]]));
            first..skirt_edges.len()
        });
        RenderMesh {
            vertices: self.render_vertices_of(&surface),
            indices,
            surface_parts: self.surface_parts(),
            skirt_edges,
            skirt_ranges,
            lowest_radius: self.lowest_radius(&surface),
            dark_air_plugged: self.dark_air_plugged,
            plugged_inside: self.plugged_inside,
            stubs_exposed: self.stubs_exposed,
            pockets_beyond: self.pockets_beyond,
        }
    }

    /// [`RenderMesh::lowest_radius`] of the surface vertices `surface`:
    /// every drawn point lies on a triangle between vertices that each lie
    /// between its position and its morph target, so in the convex hull of
    /// those points. Along any unit direction `c` the hull reaches no lower
    /// than its lowest point, `min p · c`, and a point `q` is at least
    /// `q · c` from the centre: no drawn point is nearer the centre than
    /// `min p · c` (the chords' sag taken off), with `c` the direction of
    /// the points' sum. Less what the renderer's f32 and f16 can move a
    /// point: its offset from the morph target is an f16 in voxels of the
    /// chunk's LOD, a few at most (2⁻⁹ of a voxel apart there), the rest a
    /// centimetre. A dot product a point: the least length times the least
    /// cosine (a square root and two divisions a point, and a lower bound)
    /// was a third of making a render mesh.
    fn lowest_radius(&self, surface: &[usize]) -> f64 {
        if surface.is_empty() {
            return f64::INFINITY;
        }
        let mut sum = DVec3::ZERO;
        for &i in surface {
            sum += self.world[i] + self.morph_world[i];
        }
        let margins = 0.01 + self.layout.voxel_edge(self.key.lod) / 256.0;
        let centre = sum.normalize_or_zero();
        if centre == DVec3::ZERO {
            // Points whose sum has no direction (or is not finite): no
            // bound but the centre.
            return -margins;
        }
        let mut lowest = f64::INFINITY;
        for &i in surface {
            // A comparison, not `f64::min` (which takes care over NaN): the
            // loop then runs two points at a time.
            for along in [self.world[i].dot(centre), self.morph_world[i].dot(centre)] {
                lowest = if along < lowest { along } else { lowest };
            }
        }
        lowest.max(0.0) - margins
    }

    /// The vertices in GPU form (see [`RenderVertex`]), in the order of
    /// [`ChunkMesh::vertices`], so [`ChunkMesh::indices`] index them.
    #[must_use]
    pub fn render_vertices(&self) -> Vec<RenderVertex> {
        self.render_vertices_of(&(0..self.vertices.len()).collect::<Vec<_>>())
    }

    /// Vertices `indices` in GPU form, in that order. Their f16 parts are
    /// converted together: `half` converts a slice with the CPU's
    /// conversion instructions where it has them, as it does one value
    /// (f64 through f32), but without a call and a feature test per value
    /// (those were a quarter of making a render mesh).
    fn render_vertices_of(&self, indices: &[usize]) -> Vec<RenderVertex> {
        let lod = self.key.lod;
        // 2^-LOD is exact: the offset keeps its bits at every LOD.
        let scale = f64::from(1_u32 << lod).recip();
        let mut vertices = Vec::with_capacity(indices.len());
        // Per vertex: its offset, then its target's low part.
        let mut low_parts = Vec::with_capacity(6 * indices.len());
        for &i in indices {
            let v = self.vertices[i];
            // A skirt vertex carries the vertex it hangs from; the renderer
            // lowers it by the side's depth.
            let from = self.skirt_top(i).map_or(i, |top| top as usize);
            let (world, target) = (self.world[from], self.morph_world[from]);
            let position_high = target.as_vec3();
            let target_low = target - position_high.as_dvec3();
            let offset = (world - target) * scale;
            low_parts.extend_from_slice(&[offset.x, offset.y, offset.z, target_low.x, target_low.y, target_low.z]);
            vertices.push(RenderVertex {
                position_high: position_high.to_array(),
                offset: [f16::ZERO; 3],
                target_low: [f16::ZERO; 3],
                normal: encode_normal(v.normal),
                packed: u32::from(v.material)
                    | (u32::from(v.sky_light) << 8)
                    | (u32::from(v.flags & 0xff) << 16)
                    | (u32::from(lod) << OFFSET_LOD_SHIFT),
            });
        }
        let mut halves = vec![f16::ZERO; low_parts.len()];
        halves.convert_from_f64_slice(&low_parts);
        debug_assert!(
            halves.iter().zip(&low_parts).all(|(&half, &low)| half.to_bits() == f16::from_f64(low).to_bits())
        );
        for (vertex, half) in vertices.iter_mut().zip(halves.chunks_exact(6)) {
            vertex.offset = [half[0], half[1], half[2]];
            vertex.target_low = [half[3], half[4], half[5]];
        }
        vertices
    }

    /// The skirt depths this mesh was generated with, as a [`ChunkDraw`]
    /// with `parent_error`.
    #[must_use]
    pub fn chunk_draw(&self, parent_error: f64) -> ChunkDraw {
        ChunkDraw::new(parent_error, self.skirt_depths)
    }
}

/// The index of `side` in [`FaceDirection::HORIZONTAL`] (0 for ±Y, which
/// have no skirts).
#[must_use]
pub fn side_index(side: FaceDirection) -> usize {
    FaceDirection::HORIZONTAL.iter().position(|&s| s == side).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::round_to_i16;
    use proptest::prelude::*;

    /// Every half-way value an encoded normal can meet, and the floats
    /// either side of it, round as `f32::round` does (away from zero).
    #[test]
    fn rounding_to_i16_takes_halves_away_from_zero_as_round_does() {
        for k in -32767..32767 {
            let half = k as f32 + 0.5;
            let next = |x: f32, step: i32| f32::from_bits(x.to_bits().wrapping_add_signed(step));
            for x in [k as f32, half, next(half, 1), next(half, -1), next(k as f32, 1), next(k as f32, -1)] {
                if x.abs() <= 32767.0 {
                    assert_eq!(round_to_i16(x), x.round() as i16, "{x}");
                }
            }
        }
        assert_eq!(round_to_i16(f32::NAN), 0);
    }

    proptest! {
        #[test]
        fn rounding_to_i16_is_round(x in -32767.0f32..=32767.0) {
            prop_assert_eq!(round_to_i16(x), x.round() as i16);
        }
    }
}
