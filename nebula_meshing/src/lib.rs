//! Watertight greedy meshing of voxel chunks on a cubesphere.
//!
//! One call, [`mesh_chunk`], takes a chunk from any
//! [`VoxelSource`](nebula_voxel::VoxelSource) to a finished [`ChunkMesh`]:
//!
//! 1. voxels with a one-voxel padding read across chunk and cube-face edges;
//! 2. greedy quads on the padded 34³ array (material-aware) from bitmasks
//!    of its solid voxels ([`GreedyQuads`]): block-mesh-bgm's quads (tested
//!    equal), made from our voxel rows; block-mesh's `greedy_quads` is the
//!    reference for the faces they cover;
//! 3. T-junction-free triangulation, decided in integer lattice coordinates
//!    (see [`ChunkMesher`]): every vertex on a quad's edge joins its outline,
//!    and on chunk boundary planes a canonical set of lattice points does
//!    (a function of the voxels on both sides), so neighbours agree on their
//!    shared vertices bit for bit; sides meeting another LOD take every
//!    lattice point unless only draw-time skirts close them;
//!    then the vertices strictly inside flat regions (one plane, material
//!    and light) left out where a fan from a neighbour covers the same
//!    region, before and while morphing (`collapse`: two triangles fewer
//!    each);
//! 4. [`constrain_edge_vertices`] for sides whose neighbour is coarser, by
//!    any LOD difference;
//! 5. [`generate_skirt`] on sides that meet another LOD, [`skirt_depth`] deep,
//!    with normals locked to the surface; or, with
//!    [`MeshOptions::STITCHED`], no skirt: the seam closed by faces in the
//!    shared boundary plane ([`stitch`]);
//! 6. positions from `nebula_math`'s one canonical lattice → world function,
//!    stored f32 relative to the chunk's f64 origin ([`MeshVertex`], 40
//!    bytes).
//!
//! [`mesh_chunks`] does many chunks on rayon's pool. The seam spec's
//! vocabulary, [`ChunkLodContext`] and [`NeighborLodRelation`], comes from
//! `nebula_lod` and is re-exported here.
//!
//! Trade-off: greedy quads are few, but on a sphere each long quad must be
//! split wherever a neighbour's vertex touches its edge; the extra triangles
//! are the price of no cracks (`cargo bench -p nebula_meshing` reports them
//! next to the time, against block-mesh alone).
//!
//! ```
//! use nebula_meshing::{ChunkLodContext, ChunkMeshBuffer, FaceDirection, MeshOptions, NeighborLodRelation, mesh_chunk};
//! use nebula_voxel::{ChunkColumn, CubeFace, PlanetSettings, ProceduralPlanet, VoxelSource};
//!
//! let planet = ProceduralPlanet::new(PlanetSettings::small(3))?;
//! let column = ChunkColumn { face: CubeFace::PosZ, lod: 1, x: 10, y: 12 };
//!
//! // The neighbour on +X is one LOD coarser.
//! let mut context = ChunkLodContext::uniform(1);
//! context.set(FaceDirection::PosX, NeighborLodRelation::HigherThanNeighbor { lod_diff: 1 });
//!
//! // Mesh the column's chunks that may hold the surface: where it crosses
//! // the +X side, a skirt hangs from it.
//! let mut buffer = ChunkMeshBuffer::new();
//! let mut meshes = Vec::new();
//! for layer in planet.surface_chunk_layers(column)? {
//!     meshes.push(mesh_chunk(&planet, column.chunk(layer), &context, MeshOptions::default(), &mut buffer)?);
//! }
//! let mesh = meshes.iter().find(|mesh| mesh.skirt_triangle_count() > 0).expect("a skirt");
//! assert!(!mesh.has_t_junctions());
//! assert_eq!(mesh.triangle_count(), mesh.surface_triangle_count() + mesh.skirt_triangle_count());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod collapse;
mod error;
mod greedy;
mod mesh;
mod mesher;
mod pipeline;
mod render;
mod seams;
pub mod stitch;

pub use error::MeshError;
pub use greedy::GreedyQuads;
pub use mesh::{ChunkMesh, MeshVertex, OutlineEdge};
pub use mesher::ChunkMesher;
pub use nebula_lod::{ChunkLodContext, NeighborLodRelation};
pub use nebula_math::{DVec3, FaceDirection, Vec3};
pub use pipeline::{
    ChunkMeshBuffer, MeshOptions, PLUG_GROUP_LODS, mesh_chunk, mesh_chunks, plug_group, plug_group_across,
    plug_group_key,
};
pub use render::{
    ChunkDraw, FrameDraw, RenderMesh, RenderVertex, SKIRT_CORNERS, SURFACE_PARTS, decode_normal, drawn_ranges,
    encode_normal, lowered, lowered_skirts, side_index, split_high_low, vertex_morph_factor,
};
pub use seams::{constrain_edge_vertices, generate_skirt, skirt_depth};

#[cfg(test)]
mod stitch_tests;
#[cfg(test)]
mod tests;
