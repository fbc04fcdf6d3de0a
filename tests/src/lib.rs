//! Cross-crate checks that look at an assembled planet the way a player
//! would, on any machine and deterministically.
//!
//! - [`assemble`]: run the LOD selection for a camera and mesh every chunk
//!   in view with its real `ChunkLodContext`.
//! - [`cast_cracks`]: a CPU ray-cast crack oracle. A grid of view rays is
//!   cast; a ray went through a crack if the first triangle it meets faces
//!   away from it (it got inside the ground without crossing the surface),
//!   or if it reaches the sphere of minimum surface radius under the chunks
//!   in view without meeting any triangle. The BVH
//!   and traversal come from the `obvhs` crate (f32, camera-relative); each
//!   candidate triangle is then tested exactly in f64 with a 10⁻⁹
//!   barycentric tolerance, so shared edges never leak by rounding.
//! - [`boundary_topology`]: over every pair of neighbouring chunks, in
//!   lattice space: outline edges of same-LOD neighbours that do not match,
//!   and vertices of a finer chunk that lie inside a coarser neighbour's
//!   edge without sitting on it in the world (T-junctions that leak).
//!
//! ```
//! use nebula_lod::{Camera, LodSettings};
//! use nebula_math::DVec3;
//! use nebula_meshing::MeshOptions;
//! use nebula_tests::{assemble, cast_cracks};
//! use nebula_voxel::{PlanetSettings, ProceduralPlanet};
//!
//! let planet = ProceduralPlanet::new(PlanetSettings::small(2))?;
//! let eye = DVec3::new(0.0, 0.0, 3_000.0);
//! let camera = Camera { position: eye, forward: -eye, up: DVec3::X, aspect: 1.0 };
//! let settings = LodSettings { screen_height_px: 64.0, threshold_px: 2.0, ..LodSettings::default() };
//! let planet_view = assemble(&planet, &camera, settings, MeshOptions::default())?;
//! assert_eq!(nebula_tests::boundary_topology(&planet_view).t_junctions, 0);
//! let report = cast_cracks(&planet_view, &camera, 64, 64);
//! assert!(report.rays_on_planet > 1000);
//! assert_eq!(report.cracks, 0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod islands;

use std::collections::{HashMap, HashSet};
use std::time::Duration;

use nebula_lod::{Camera, ChunkLodContext, LodError, LodSettings, LodStats, LodTree, NeighborLodRelation};
use nebula_math::{DVec3, FaceDirection, FaceEdge, LatticePoint, ray_sphere};
use nebula_meshing::{ChunkMesh, MeshError, MeshOptions, mesh_chunks};
use nebula_voxel::{ChunkColumn, ChunkKey, VoxelSource};
use obvhs::BvhBuildParams;
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use rayon::prelude::*;

/// A set of chunk meshes in one f64 world frame (each mesh keeps its f64
/// origin; [`ChunkMesh::world_position`] gives world vertices), with the
/// LOD relations they were meshed with.
pub struct PlanetView {
    /// Meshes of the chunks (empty chunks left out).
    pub meshes: Vec<ChunkMesh>,
    /// The leaves and their neighbour relations.
    pub contexts: HashMap<ChunkColumn, ChunkLodContext>,
    /// Lowest surface radius under the meshed chunks: the oracle's sphere.
    /// Taken over the chunks in view rather than the whole planet, so rays
    /// that graze low terrain still reach it and get checked.
    pub min_surface_radius: f64,
    /// Vertical field of view of the camera, degrees.
    pub fov_y_degrees: f64,
    /// The planet's coarsest LOD.
    pub max_lod: u8,
    /// The LOD selection's figures, when a [`LodTree`] chose the leaves.
    pub stats: Option<LodStats>,
}

/// Why an assembly failed.
#[derive(Debug, thiserror::Error)]
pub enum AssemblyError {
    /// The LOD selection refused the camera or settings.
    #[error("LOD selection failed: {0}")]
    Lod(LodError),
    /// A chunk could not be meshed.
    #[error("meshing failed: {0}")]
    Mesh(MeshError),
}

/// Runs the LOD selection for `camera` and meshes every chunk in view with
/// its real neighbour relations.
///
/// # Errors
/// [`AssemblyError`] if the LOD selection or a chunk's meshing fails.
pub fn assemble<S: VoxelSource + ?Sized>(
    source: &S,
    camera: &Camera,
    settings: LodSettings,
    options: MeshOptions,
) -> Result<PlanetView, AssemblyError> {
    let mut tree = LodTree::new(source, settings).map_err(AssemblyError::Lod)?;
    tree.update(source, camera).map_err(AssemblyError::Lod)?;
    tree.cull(camera).map_err(AssemblyError::Lod)?;
    view_of_tree(source, &tree, options)
}

/// Meshes the chunks of `tree` in view at its last
/// [`LodTree::cull`] (for a tree the caller updates along a path).
///
/// # Errors
/// [`AssemblyError::Mesh`] if a chunk cannot be meshed.
pub fn view_of_tree<S: VoxelSource + ?Sized>(
    source: &S,
    tree: &LodTree,
    options: MeshOptions,
) -> Result<PlanetView, AssemblyError> {
    let contexts = tree.leaves().into_iter().filter_map(|c| tree.context(c).map(|ctx| (c, ctx))).collect();
    let jobs: Vec<_> = tree
        .visible_chunks()
        .into_iter()
        .filter_map(|key| tree.context(key.column()).map(|context| (key, context)))
        .collect();
    Ok(PlanetView {
        meshes: mesh_jobs(source, &jobs, options)?,
        contexts,
        min_surface_radius: tree
            .visible_leaves()
            .iter()
            .filter_map(|&c| tree.node_bounds(c))
            .map(|b| b.min_radius)
            .reduce(f64::min)
            .unwrap_or_else(|| tree.min_surface_radius()),
        fov_y_degrees: tree.settings().fov_y_degrees,
        max_lod: tree.max_lod(),
        stats: Some(tree.stats()),
    })
}

/// Meshes hand-picked leaves (every surface layer of each) with the given
/// relations: for configurations a camera does not easily produce, such
/// as a LOD difference of 3 on one edge.
///
/// # Errors
/// [`AssemblyError::Mesh`] if a chunk cannot be meshed.
pub fn assemble_leaves<S: VoxelSource + ?Sized>(
    source: &S,
    leaves: &[(ChunkColumn, ChunkLodContext)],
    fov_y_degrees: f64,
    options: MeshOptions,
) -> Result<PlanetView, AssemblyError> {
    let mut jobs = Vec::new();
    let mut min_surface_radius = f64::INFINITY;
    for &(column, context) in leaves {
        let error = |e: nebula_voxel::VoxelError| AssemblyError::Mesh(e.into());
        min_surface_radius = min_surface_radius.min(source.surface_bounds(column).map_err(error)?.min_radius);
        let layers = source.surface_chunk_layers(column).map_err(error)?;
        jobs.extend(layers.map(|layer| (column.chunk(layer), context)));
    }
    Ok(PlanetView {
        meshes: mesh_jobs(source, &jobs, options)?,
        contexts: leaves.iter().copied().collect(),
        min_surface_radius,
        fov_y_degrees,
        max_lod: source.layout().max_lod(),
        stats: None,
    })
}

fn mesh_jobs<S: VoxelSource + ?Sized>(
    source: &S,
    jobs: &[(ChunkKey, ChunkLodContext)],
    options: MeshOptions,
) -> Result<Vec<ChunkMesh>, AssemblyError> {
    let mut meshes = Vec::with_capacity(jobs.len());
    for result in mesh_chunks(source, jobs, options) {
        let mesh = result.map_err(AssemblyError::Mesh)?;
        if !mesh.is_empty() {
            meshes.push(mesh);
        }
    }
    Ok(meshes)
}

/// What the crack oracle saw.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CrackReport {
    /// Rays cast.
    pub rays: usize,
    /// Rays that reach the sphere of minimum surface radius or meet a
    /// triangle: the rays that could show a crack.
    pub rays_on_planet: usize,
    /// Rays that went through a crack: first hit a back face, or reached
    /// the sphere without a hit.
    pub cracks: usize,
    /// The chunks nearest to the first cracked ray (by distance from the
    /// ray's point on the sphere to the chunk's vertices), nearest first.
    pub first_crack_chunks: Vec<ChunkKey>,
    /// Where the first (up to 16) cracked rays meet the sphere, and their
    /// pixel.
    pub crack_samples: Vec<(DVec3, (u32, u32))>,
    /// Triangles in the scene.
    pub triangles: usize,
}

/// One triangle in f64, camera-relative, with its chunk.
struct ExactTriangle {
    v: [DVec3; 3],
}

/// Casts a `width` × `height` grid of view rays (through pixel centres,
/// row 0 at the top; the image's aspect, not the camera's, shapes the rays)
/// from `camera` with the view's field of view and counts
/// the rays that leak through the surface to the sphere of minimum surface
/// radius.
#[must_use]
pub fn cast_cracks(view: &PlanetView, camera: &Camera, width: u32, height: u32) -> CrackReport {
    let eye = camera.position;
    let mut exact = Vec::new();
    for mesh in &view.meshes {
        for triangle in mesh.indices().chunks_exact(3) {
            let v = [0, 1, 2].map(|k| mesh.world_position(triangle[k] as usize).unwrap_or_default() - eye);
            exact.push(ExactTriangle { v });
        }
    }
    let tris: Vec<Triangle> = exact
        .iter()
        .map(|t| Triangle { v0: t.v[0].as_vec3a(), v1: t.v[1].as_vec3a(), v2: t.v[2].as_vec3a() })
        .collect();
    let bvh = build_bvh2_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
    let min_radius = view.min_surface_radius;
    let results: Vec<(bool, bool, DVec3, u32)> = (0..width * height)
        .into_par_iter()
        .map(|pixel| {
            let dir = camera.pixel_ray(view.fov_y_degrees, (width, height), (pixel % width, pixel / width));
            let t_sphere = ray_sphere(eye, dir, min_radius);
            let limit = t_sphere.map_or(f32::INFINITY, |t| (t * 1.0001) as f32);
            let ray = Ray::new(dir.as_vec3a() * 0.0, dir.as_vec3a(), 0.0, limit);
            let mut hit = RayHit::none();
            // The nearest front-facing and back-facing hits, tracked apart:
            // a ray through an edge where surfaces meet (a non-manifold
            // chunk corner, say) can touch a back face at the same distance
            // as a front face, which is no crack.
            let (mut front, mut back) = (f64::INFINITY, f64::INFINITY);
            bvh.ray_traverse(ray, &mut hit, |_, id| {
                let t = &exact[bvh.primitive_indices[id] as usize];
                if let Some((t, facing)) = ray_hit(&t.v, dir) {
                    let slot = if facing { &mut front } else { &mut back };
                    *slot = slot.min(t);
                }
                f32::INFINITY
            });
            let nearest = front.min(back);
            let any = nearest.is_finite();
            let first_is_back = any && back < front * (1.0 - 1e-9);
            let point = eye + dir * t_sphere.unwrap_or(nearest);
            let checked = t_sphere.is_some() || any;
            (checked, first_is_back || (t_sphere.is_some() && !any), point, pixel)
        })
        .collect();
    let mut report = CrackReport { rays: results.len(), triangles: exact.len(), ..CrackReport::default() };
    for &(on_planet, crack, point, pixel) in &results {
        report.rays_on_planet += usize::from(on_planet);
        if crack {
            report.cracks += 1;
            if report.crack_samples.len() < 16 {
                report.crack_samples.push((point, (pixel % width, pixel / width)));
            }
            if report.first_crack_chunks.is_empty() {
                report.first_crack_chunks = nearest_chunks(view, point);
            }
        }
    }
    report
}

/// The up to four chunks with a vertex nearest to `point`.
fn nearest_chunks(view: &PlanetView, point: DVec3) -> Vec<ChunkKey> {
    let mut by_distance: Vec<(f64, ChunkKey)> = view
        .meshes
        .iter()
        .map(|mesh| {
            let nearest = (0..mesh.vertex_count())
                .filter_map(|i| mesh.world_position(i))
                .map(|p| p.distance(point))
                .fold(f64::INFINITY, f64::min);
            (nearest, mesh.key())
        })
        .collect();
    by_distance.sort_by(|a, b| a.0.total_cmp(&b.0));
    by_distance.into_iter().take(4).map(|(_, key)| key).collect()
}

/// Möller–Trumbore in f64 from the origin along `dir`, both sides, with a
/// 10⁻⁹ barycentric tolerance: the distance and whether the triangle faces
/// the ray (counter-clockwise seen from it).
fn ray_hit(v: &[DVec3; 3], dir: DVec3) -> Option<(f64, bool)> {
    const EPS: f64 = 1e-9;
    let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let s = -v[0];
    let u = s.dot(p) / det;
    if !(-EPS..=1.0 + EPS).contains(&u) || !u.is_finite() {
        return None;
    }
    let q = s.cross(e1);
    let w = dir.dot(q) / det;
    if w < -EPS || u + w > 1.0 + EPS {
        return None;
    }
    let t = e2.dot(q) / det;
    (t > 0.0).then_some((t, det > 0.0))
}

/// Seams between neighbouring chunks, counted in lattice space.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TopologyReport {
    /// Neighbouring chunk pairs compared.
    pub pairs: usize,
    /// Pairs whose chunks differ in LOD.
    pub lod_boundary_pairs: usize,
    /// Outline edges of same-LOD neighbours that the other side lacks.
    pub unmatched_edges: usize,
    /// Vertices of a finer chunk inside a coarser neighbour's outline edge
    /// (in lattice space) but off that edge in the world by more than 1 µm.
    pub t_junctions: usize,
}

/// Compares the outlines of every pair of neighbouring visible chunks.
#[must_use]
pub fn boundary_topology(view: &PlanetView) -> TopologyReport {
    let by_column: HashMap<ChunkColumn, Vec<&ChunkMesh>> = view.meshes.iter().fold(HashMap::new(), |mut map, m| {
        map.entry(m.key().column()).or_default().push(m);
        map
    });
    let mut report = TopologyReport::default();
    for (&column, meshes) in &by_column {
        let Some(context) = view.contexts.get(&column) else { continue };
        for edge in FaceEdge::ALL {
            let side = FaceDirection::from_face_edge(edge);
            let relation = context.relation(side);
            if relation == NeighborLodRelation::LowerThanNeighbor {
                continue; // compared from the finer side
            }
            let Some((other, back)) = neighbour_leaf(view, column, edge) else { continue };
            let Some(other_meshes) = by_column.get(&other) else { continue };
            if relation == NeighborLodRelation::Same
                && (other.face, other.x, other.y) < (column.face, column.x, column.y)
            {
                continue; // each same-LOD pair once
            }
            report.pairs += 1;
            let ours = outline(meshes, side);
            let theirs = outline(other_meshes, FaceDirection::from_face_edge(back));
            if relation == NeighborLodRelation::Same {
                report.unmatched_edges += ours.edges.symmetric_difference(&theirs.edges).count();
            } else {
                report.lod_boundary_pairs += 1;
                report.t_junctions += leaking_t_junctions(&ours, &theirs);
            }
        }
    }
    report
}

/// The leaf across `edge` of leaf `column` that covers the cell next to it
/// (same LOD or coarser), and the edge of it that faces back.
fn neighbour_leaf(view: &PlanetView, column: ChunkColumn, edge: FaceEdge) -> Option<(ChunkColumn, FaceEdge)> {
    let (di, dj) = edge.step();
    let per_edge = 1i64 << (view.max_lod - column.lod);
    let (face, x, y) = column.face.wrap_cell(i64::from(column.x) + di, i64::from(column.y) + dj, per_edge)?;
    let back = if face == column.face { edge.opposite() } else { column.face.neighbor(edge).edge };
    let mut cell = ChunkColumn { face, lod: column.lod, x: x as u32, y: y as u32 };
    while !view.contexts.contains_key(&cell) {
        if cell.lod >= view.max_lod {
            return None;
        }
        cell = nebula_lod::parent(cell)?;
    }
    Some((cell, back))
}

struct Outline {
    /// Outline edges as lattice point pairs (sorted), without edges on the
    /// radial boundary planes.
    edges: HashSet<(LatticeKey, LatticeKey)>,
    /// World position of each outline vertex.
    points: HashMap<LatticeKey, DVec3>,
}

type LatticeKey = ([i32; 3], i32);

fn lattice_key(p: LatticePoint) -> LatticeKey {
    (p.cube.to_array(), p.layer)
}

fn outline(meshes: &[&ChunkMesh], side: FaceDirection) -> Outline {
    let mut out = Outline { edges: HashSet::new(), points: HashMap::new() };
    for mesh in meshes {
        for edge in mesh.outline(side) {
            if edge.on_radial_boundary {
                continue;
            }
            let (ka, kb) = (lattice_key(edge.lattice[0]), lattice_key(edge.lattice[1]));
            out.points.insert(ka, edge.world[0]);
            out.points.insert(kb, edge.world[1]);
            out.edges.insert(if ka < kb { (ka, kb) } else { (kb, ka) });
        }
    }
    out
}

/// Fine outline vertices strictly inside a coarse outline edge (lattice
/// space: same layer, collinear cube coordinates, between) that are more
/// than 1 µm off the coarse edge in the world.
fn leaking_t_junctions(fine: &Outline, coarse: &Outline) -> usize {
    let mut count = 0;
    for &(a, b) in &coarse.edges {
        if a.1 != b.1 {
            continue;
        }
        let (ca, cb) = (a.0.map(i64::from), b.0.map(i64::from));
        let d = [cb[0] - ca[0], cb[1] - ca[1], cb[2] - ca[2]];
        let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        for (&p, &world) in &fine.points {
            if p.1 != a.1 {
                continue;
            }
            let cp = p.0.map(i64::from);
            let e = [cp[0] - ca[0], cp[1] - ca[1], cp[2] - ca[2]];
            let cross = [e[1] * d[2] - e[2] * d[1], e[2] * d[0] - e[0] * d[2], e[0] * d[1] - e[1] * d[0]];
            let along = e[0] * d[0] + e[1] * d[1] + e[2] * d[2];
            if cross != [0, 0, 0] || along <= 0 || along >= len2 {
                continue;
            }
            let (wa, wb) = (coarse.points[&a], coarse.points[&b]);
            let t = ((world - wa).dot(wb - wa) / (wb - wa).length_squared()).clamp(0.0, 1.0);
            if (wa + (wb - wa) * t).distance(world) > 1e-6 {
                count += 1;
            }
        }
    }
    count
}
