//! Closing seams between chunks of different LOD: edge constraining and
//! radial skirts (seam spec `003`, seeds `000` and `002`).

use rustc_hash::FxHashMap;

use nebula_math::{DVec3, FaceDirection, Vec3};
use nebula_voxel::{CHUNK_SIZE, VoxelSource};

use crate::MeshError;
use crate::mesh::{ChunkMesh, MeshVertex, VertexSource, along_axis};
use crate::render::SKIRT_CORNERS;

/// Constrains the edge vertices of a fine chunk to a neighbour `lod_diff`
/// LODs coarser on `edge`.
///
/// The coarse neighbour has a vertex every `step = 2^lod_diff` fine lattice
/// steps along the shared edge, and between two of them its edge is the
/// straight chord of the sphere. Every boundary vertex of this chunk whose
/// along-edge lattice coordinate (counted on the whole face, so steps wider
/// than a chunk work) is not a multiple of `step` is moved onto that chord:
/// the f64 lerp of the two canonical lattice positions at the same height,
/// by its fraction along the segment. The lattice identity of the vertex is
/// kept, so the chunk's own topology (and its T-junction-freedom) is
/// unchanged. Its morph target is the same lerp between the two ends'
/// morph targets (both at the vertex's height rounded down to even), so a
/// morphing edge stays a chord between the points its unconstrained
/// neighbours morph to, with no sawtooth.
///
/// # Errors
/// [`MeshError::LodDiffOutOfRange`] for `lod_diff` 0 or past the planet's
/// coarsest LOD, [`MeshError::RadialSide`] for ±Y.
pub fn constrain_edge_vertices(mesh: &mut ChunkMesh, edge: FaceDirection, lod_diff: u8) -> Result<(), MeshError> {
    let key = mesh.key;
    let max = mesh.layout.max_lod() - key.lod;
    if lod_diff == 0 || lod_diff > max {
        return Err(MeshError::LodDiffOutOfRange { lod: key.lod, lod_diff, max });
    }
    if edge.face_edge().is_none() {
        return Err(MeshError::RadialSide { side: edge });
    }
    let along = along_axis(edge);
    let step = 1i64 << lod_diff;
    // Along-edge coordinate of local 0, in the chunk's voxel units on the face.
    let first = i64::from(if along == 0 { key.x } else { key.y }) * i64::from(CHUNK_SIZE);
    let span = mesh.layout.voxel_span(key.lod);
    let sphere = *mesh.layout.sphere();
    for index in mesh.boundary_indices(edge) {
        let Some(local) = mesh.local(index) else { continue };
        let coord = first + i64::from(local[along]);
        let lower = coord.div_euclid(step) * step;
        if coord == lower {
            continue;
        }
        // The two coarse vertices, as face lattice points at height `y`
        // (local, at the chunk's LOD).
        let at = |c: i64, y: i32| -> Result<DVec3, MeshError> {
            let mut global = [
                i64::from(key.x) * i64::from(CHUNK_SIZE) + i64::from(local[0]),
                i64::from(key.layer) * i64::from(CHUNK_SIZE) + i64::from(y),
                i64::from(key.y) * i64::from(CHUNK_SIZE) + i64::from(local[2]),
            ];
            global[along] = c;
            let point = sphere.lattice_point(key.face, global[0] * span, global[2] * span, global[1] * span)?;
            Ok(sphere.position(point))
        };
        let t = (coord - lower) as f64 / step as f64;
        let (low, high) = (at(lower, local[1])?, at(lower + step, local[1])?);
        // `step` ≥ 2, so both ends are even along the edge: their morph
        // targets differ from them in height only.
        let even_y = local[1] - local[1].rem_euclid(2);
        let (morph_low, morph_high) = (at(lower, even_y)?, at(lower + step, even_y)?);
        mesh.move_vertex(index, low + (high - low) * t, morph_low + (morph_high - morph_low) * t);
    }
    Ok(())
}

/// Hangs a skirt of `skirt_depth` metres from the outline of the mesh on
/// `edge`, radially towards `planet_center` (in the mesh's frame; see
/// [`ChunkMesh::planet_center`]).
///
/// The outline is the chain of surface edges on the boundary plane that only
/// one surface triangle uses (for a smooth surface, the row of vertices along
/// the edge). Each outline edge gets a quad down to a copy of its two
/// vertices moved `skirt_depth` towards the centre (in f64), wound to
/// continue the surface and so face away from the chunk, where the crack
/// would be seen from. The lower vertices carry the normal of the vertex
/// above them (normal locking), so a skirt is shaded like the surface.
///
/// # Errors
/// [`MeshError::BadSkirtDepth`], [`MeshError::BadPlanetCenter`],
/// [`MeshError::RadialSide`].
pub fn generate_skirt(
    mesh: &mut ChunkMesh,
    edge: FaceDirection,
    skirt_depth: f32,
    planet_center: &Vec3,
) -> Result<(), MeshError> {
    check_skirt(edge, skirt_depth, planet_center)?;
    let outline = mesh.outline_edges(edge);
    hang_skirt(mesh, edge, skirt_depth, planet_center, outline);
    Ok(())
}

/// [`generate_skirt`] on each horizontal side given a depth in `depths`
/// (index as in [`FaceDirection::HORIZONTAL`]), the four outlines found
/// in one pass ([`ChunkMesh::outlines`]: skirts are not surface, so
/// hanging one leaves the others' outlines as they were).
///
/// # Errors
/// As [`generate_skirt`], before any skirt is hung.
pub(crate) fn generate_skirts(
    mesh: &mut ChunkMesh,
    depths: [Option<f32>; 4],
    planet_center: &Vec3,
) -> Result<(), MeshError> {
    let sides = || FaceDirection::HORIZONTAL.into_iter().zip(depths);
    for (side, depth) in sides() {
        depth.map_or(Ok(()), |depth| check_skirt(side, depth, planet_center))?;
    }
    for ((side, depth), outline) in sides().zip(mesh.outlines(depths.map(|depth| depth.is_some()))) {
        if let Some(depth) = depth {
            hang_skirt(mesh, side, depth, planet_center, outline);
        }
    }
    Ok(())
}

/// [`generate_skirt`]'s errors.
fn check_skirt(edge: FaceDirection, skirt_depth: f32, planet_center: &Vec3) -> Result<(), MeshError> {
    if !skirt_depth.is_finite() || skirt_depth < 0.0 {
        return Err(MeshError::BadSkirtDepth { depth: skirt_depth });
    }
    if !planet_center.is_finite() {
        return Err(MeshError::BadPlanetCenter { center: planet_center.to_array() });
    }
    if edge.face_edge().is_none() {
        return Err(MeshError::RadialSide { side: edge });
    }
    Ok(())
}

/// Hangs the skirt of a checked [`generate_skirt`] from `outline`, the
/// mesh's outline edges on `edge`.
fn hang_skirt(
    mesh: &mut ChunkMesh,
    edge: FaceDirection,
    skirt_depth: f32,
    planet_center: &Vec3,
    outline: Vec<(u32, u32)>,
) {
    let center = mesh.origin + planet_center.as_dvec3();
    let depth = f64::from(skirt_depth);
    mesh.skirt_depths[crate::side_index(edge)] = skirt_depth;
    let mut lower: FxHashMap<u32, u32> = FxHashMap::default();
    let mut bottom_of = |mesh: &mut ChunkMesh, top: u32| -> u32 {
        *lower.entry(top).or_insert_with(|| {
            let t = top as usize;
            let world = mesh.world[t];
            let inward = (center - world).normalize_or_zero() * depth;
            let vertex = mesh.vertices[t];
            let morph = mesh.morph_world[t] + inward;
            mesh.push_vertex(
                world + inward,
                morph,
                vertex.normal,
                (vertex.material, vertex.sky_light),
                MeshVertex::skirt_flags(edge),
                VertexSource::Skirt { top },
            )
        })
    };
    let first = mesh.indices.len();
    for (a, b) in outline {
        let lows = [bottom_of(mesh, a), bottom_of(mesh, b)];
        // The surface runs a → b; the skirt continues it, so it runs b → a.
        // Each triangle starts at a skirt vertex (same winding, rotated) so
        // that flat-interpolated flags mark the whole triangle as skirt.
        mesh.indices.extend(SKIRT_CORNERS.map(|(end, low)| if low { lows[end] } else { [a, b][end] }));
        mesh.skirt_triangles += 2;
    }
    mesh.skirt_ranges[crate::side_index(edge)] = first..mesh.indices.len();
}

/// The outline edges `[a, b]` that the skirt triangles `indices` (one
/// side's, as [`generate_skirt`] lays them out: six corners per edge,
/// [`SKIRT_CORNERS`]) hang from.
pub(crate) fn skirt_outline(indices: &[u32]) -> impl Iterator<Item = [u32; 2]> + '_ {
    let top = |end: usize| SKIRT_CORNERS.iter().position(|&corner| corner == (end, false)).unwrap_or(end);
    let (a, b) = (top(0), top(1));
    indices.chunks_exact(SKIRT_CORNERS.len()).map(move |quad| [quad[a], quad[b]])
}

/// How deep a skirt must hang on an edge between a chunk at `fine_lod` and
/// one at `coarse_lod`, in metres, for every geomorph state of both:
///
/// ```text
///   depth = δ(fine + 1) + δ(coarse + 1) + sagitta(coarse) + bias
///   sagitta(L) = (1.5 · 32 · 2^L · cell width)² / (8 · radius)   chord sag of
///                                                    a whole chunk side at L
///   bias = one voxel at the fine LOD
///   (LODs past the planet's coarsest are clamped to it: it never morphs)
/// ```
///
/// δ(L) bounds how far each LOD's voxel surface lies from the LOD-0 surface
/// radially (see `nebula_voxel::ProceduralPlanet`). A chunk at LOD `L`
/// morphing towards its parent lies between its own surface and the
/// parent's, so within δ(L + 1); the two sides of the edge differ by at most
/// δ(fine + 1) + δ(coarse + 1) anywhere along it. Edges on a chunk's side,
/// morphed or not, are chords between its canonical boundary vertices, at
/// most the side long, that sag below the sphere by up to the sagitta (1.5
/// covers the longest equi-angular cell edge, √2 × the shortest). The bias
/// absorbs the staircase of the voxel surface itself. The order of the two
/// LODs does not matter.
#[must_use]
pub fn skirt_depth<S: VoxelSource + ?Sized>(source: &S, fine_lod: u8, coarse_lod: u8) -> f64 {
    let layout = source.layout();
    let sphere = layout.sphere();
    let (fine_lod, coarse_lod) = (fine_lod.min(coarse_lod), fine_lod.max(coarse_lod));
    let morphed = |lod: u8| lod.saturating_add(1).min(layout.max_lod());
    let chord = 1.5 * f64::from(CHUNK_SIZE) * layout.voxel_span(coarse_lod) as f64 * sphere.cell_width();
    let sagitta = chord * chord / (8.0 * sphere.radius());
    let bias = layout.voxel_span(fine_lod) as f64 * sphere.layer_height();
    source.geometric_error(morphed(fine_lod)) + source.geometric_error(morphed(coarse_lod)) + sagitta + bias
}
