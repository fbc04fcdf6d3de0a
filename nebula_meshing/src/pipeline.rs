//! One call from voxels to a finished chunk mesh, and many in parallel.

use nebula_lod::{ChunkLodContext, NeighborLodRelation};
use nebula_math::FaceDirection;
use nebula_voxel::{ChunkColumn, ChunkKey, ChunkLayout, ChunkVoxels, VoxelSource};
use rayon::prelude::*;

use crate::mesh::ChunkMesh;
use crate::mesher::PlugReach;
use crate::seams::generate_skirts;
use crate::stitch::{StitchedSide, stitch_padding};
use crate::{ChunkMesher, MeshError, constrain_edge_vertices, skirt_depth};

/// Which seam passes run. Constraining and skirts are on by default;
/// switching them off is for measuring what they fix. [`MeshOptions::STITCHED`]
/// closes seams without skirts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshOptions {
    /// Move boundary vertices onto coarser neighbours' edges.
    pub constrain_edges: bool,
    /// Hang skirts on edges that meet another LOD.
    pub skirts: bool,
    /// Hang a skirt on every horizontal side whatever the context, with
    /// depth 0, for the renderer to lower per side at draw time from the
    /// LODs it draws next to the chunk (see [`RenderVertex`](crate::RenderVertex)).
    /// The mesh then does not depend on its neighbours' LODs: a streamer
    /// swaps chunks without re-meshing their neighbours. Overrides `skirts`.
    pub draw_time_skirts: bool,
    /// Close each seam with a coarser neighbour by faces lying in the
    /// shared boundary plane (see [`crate::stitch`]), and leave the faces in
    /// that plane to the finer chunk on sides with a finer neighbour. Both
    /// chunks of a seam must be meshed for it (their meshes depend on the
    /// relation); with `skirts` off no skirt is hung. Implies
    /// `constrain_edges` and every lattice point on those sides a vertex.
    /// Drawn without geomorphing: the two sides of a seam morph towards
    /// different LODs.
    pub stitch: bool,
    /// From this LOD up, cave air the sky does not light is meshed as the
    /// rock around it, its faces towards the open air dark
    /// ([`ChunkMesher::plug_dark_air`]): a streamed view sees caves from
    /// afar only through their mouths, and their walls under the ground
    /// were 43 % of a narrow lens's triangles over land. `None`: every
    /// cave meshed whole.
    pub plug_dark_air_from_lod: Option<u8>,
    /// Plug this chunk's dark air where `plug_dark_air_from_lod` does not
    /// (below it, or at every LOD when it is `None`), one voxel off every
    /// horizontal side: the layers it shares with its horizontal
    /// neighbours stay as the source has them, so neighbours that do not
    /// plug close up against it (a tunnel crossing a side keeps a
    /// voxel-deep stub, capped dark). Radially it plugs its padding too
    /// (with the source's record of what covers a chunk), so the chunks of
    /// one column must be meshed all with it or all without. For a
    /// streamer choosing column by column: a narrow lens draws LOD 0
    /// kilometres away, where a cave shows only through its mouths as it
    /// does from LOD 1 in a wider view.
    pub plug_dark_air_inside: bool,
}

impl Default for MeshOptions {
    fn default() -> Self {
        Self {
            constrain_edges: true,
            skirts: true,
            draw_time_skirts: false,
            stitch: false,
            plug_dark_air_from_lod: None,
            plug_dark_air_inside: false,
        }
    }
}

impl MeshOptions {
    /// No constraining, no skirts: the bare surface, for measuring what the
    /// seam passes fix.
    pub const NO_SEAMS: Self = Self {
        constrain_edges: false,
        skirts: false,
        draw_time_skirts: false,
        stitch: false,
        plug_dark_air_from_lod: None,
        plug_dark_air_inside: false,
    };

    /// Context-free meshes for streaming: no constraining, a skirt on
    /// every side whose depth the renderer chooses per frame; dark cave
    /// air plugged from LOD 1 (LOD 1 begins hundreds of metres from the
    /// eye).
    pub const STREAMING: Self = Self {
        constrain_edges: false,
        skirts: true,
        draw_time_skirts: true,
        stitch: false,
        plug_dark_air_from_lod: Some(1),
        plug_dark_air_inside: false,
    };

    /// Seams closed by stitches in the boundary planes, no skirts: the
    /// edges towards a coarser neighbour constrained onto its lattice, the
    /// faces between the two LODs' voxels in the plane, and the coarse
    /// edges zipped to the fine vertices on them.
    pub const STITCHED: Self = Self {
        constrain_edges: true,
        skirts: false,
        draw_time_skirts: false,
        stitch: true,
        plug_dark_air_from_lod: None,
        plug_dark_air_inside: false,
    };
}

/// How many LODs above a column its plug group lies: a chunk plugged inside
/// ([`MeshOptions::plug_dark_air_inside`]) plugs the layers it shares with
/// the chunks of the columns under the same ancestor this many LODs up (4 ×
/// 4 columns, [`plug_group`]) as the LODs plugged by themselves do, padding
/// included, and keeps off only those it shares with other groups; a
/// streamer meshes a group's chunks all plugged inside or all not. Why
/// groups: towards a neighbour that may choose otherwise a tunnel crossing
/// the side keeps a stub on both chunks, and leaving out the stubs where
/// both are plugged does not take back what the margin costs: on seed
/// 71's third lens LOD 0 drew 328 k triangles with every horizontal side
/// kept off, 200 k with groups of 4 × 4, 161 k with every side plugged
/// (which no streamer could keep consistent: one group for the planet).
pub const PLUG_GROUP_LODS: u8 = 2;

/// The columns of `column`'s plug group ([`PLUG_GROUP_LODS`]), its own
/// among them, on its face and LOD (a group at a face's edge may name
/// columns past it, which hold no chunk).
pub fn plug_group(column: ChunkColumn) -> impl Iterator<Item = ChunkColumn> {
    let side = 1_u32 << PLUG_GROUP_LODS;
    let first = plug_group_key(column);
    (0..side * side).map(move |n| ChunkColumn { x: first.x + n % side, y: first.y + n / side, ..first })
}

/// What names `column`'s plug group ([`plug_group`]): its first column,
/// the same for every column of the group.
#[must_use]
pub fn plug_group_key(column: ChunkColumn) -> ChunkColumn {
    let mask = !((1_u32 << PLUG_GROUP_LODS) - 1);
    ChunkColumn { x: column.x & mask, y: column.y & mask, ..column }
}

/// Whether the column across horizontal side `side` of `column` (on a
/// planet of `layout`) is of its plug group ([`plug_group`]): on the same
/// face, under the same ancestor.
#[must_use]
pub fn plug_group_across(layout: &ChunkLayout, column: ChunkColumn, side: FaceDirection) -> bool {
    let last = (1_u32 << PLUG_GROUP_LODS) - 1;
    let on_face = |c: u32| c + 1 < layout.chunks_per_edge(column.lod);
    match side {
        FaceDirection::PosX => column.x & last != last && on_face(column.x),
        FaceDirection::NegX => column.x & last != 0,
        FaceDirection::PosZ => column.y & last != last && on_face(column.y),
        FaceDirection::NegZ => column.y & last != 0,
        FaceDirection::PosY | FaceDirection::NegY => false,
    }
}

/// Reusable memory for meshing chunk after chunk on one thread: the padded
/// voxel array and the mesher's scratch.
pub struct ChunkMeshBuffer {
    voxels: Option<ChunkVoxels>,
    pub(crate) mesher: ChunkMesher,
}

impl Default for ChunkMeshBuffer {
    fn default() -> Self {
        Self::new()
    }
}

impl ChunkMeshBuffer {
    /// Fresh buffers.
    #[must_use]
    pub fn new() -> Self {
        Self { voxels: None, mesher: ChunkMesher::new() }
    }

    /// The voxels of the last chunk meshed.
    #[must_use]
    pub fn voxels(&self) -> Option<&ChunkVoxels> {
        self.voxels.as_ref()
    }
}

/// Meshes chunk `key` of `source` with its neighbours' LODs in `context`:
/// voxels (with padding) → greedy quads → T-junction-free triangles on the
/// sphere → edges constrained for coarser neighbours → skirts on every edge
/// that meets another LOD.
///
/// # Errors
/// [`MeshError`] for a key the source refuses, a context whose LOD is not
/// the key's or that has a radial neighbour of another LOD, or a `lod_diff`
/// past the planet's coarsest LOD.
pub fn mesh_chunk<S: VoxelSource + ?Sized>(
    source: &S,
    key: ChunkKey,
    context: &ChunkLodContext,
    options: MeshOptions,
    buffer: &mut ChunkMeshBuffer,
) -> Result<ChunkMesh, MeshError> {
    check_context(key, context)?;
    let voxels = buffer.voxels.get_or_insert_with(|| ChunkVoxels::new(key));
    source.fill_chunk(key, voxels)?;
    let mut plugged = false;
    let plugged_by_lod = options.plug_dark_air_from_lod.is_some_and(|lod| key.lod >= lod);
    let reach = (plugged_by_lod || options.plug_dark_air_inside).then_some(match (plugged_by_lod, options.stitch) {
        // Every chunk of the LOD plugs alike.
        (true, false) => PlugReach::Padding,
        // Stitched seams read a neighbour's boundary layer from the
        // source: the plugs keep off it.
        (true, true) => PlugReach::OffSides,
        // Neighbours may not plug.
        (false, _) => PlugReach::Interior,
    });
    if let Some(reach) = reach {
        buffer.mesher.plug_reach = reach;
        // (A stitched side towards another LOD takes its padding from the
        // coarser neighbour's voxels: not plugged.)
        let layout = source.layout();
        buffer.mesher.padded_sides = FaceDirection::HORIZONTAL.map(|side| {
            plug_group_across(layout, key.column(), side)
                && (!options.stitch || context.relation(side) == NeighborLodRelation::Same)
        });
        plugged = buffer.mesher.plug_dark_air(voxels) > 0;
    }
    let layout = source.layout();
    let stitched: Vec<StitchedSide> = if options.stitch {
        FaceDirection::HORIZONTAL
            .into_iter()
            .map(|side| stitch_padding(source, voxels, side, context.relation(side)))
            .collect::<Result<Vec<_>, _>>()?
            .into_iter()
            .flatten()
            .collect()
    } else {
        Vec::new()
    };
    let stitch_faces = stitched.iter().any(|side| side.has_faces(voxels));
    let mut mesh = if voxels.has_no_surface() && !stitch_faces {
        ChunkMesh::empty(key, *layout, layout.chunk_origin(key)?)
    } else {
        // Sides to another LOD are closed by constraining or by skirts
        // made for that LOD: both need every lattice point there. Meshes
        // for draw-time skirts alone must not depend on the neighbours'
        // LODs.
        let dense_sides: Vec<FaceDirection> = if options.draw_time_skirts && !options.constrain_edges && !options.stitch
        {
            Vec::new()
        } else {
            FaceDirection::HORIZONTAL
                .into_iter()
                .filter(|&side| context.relation(side) != NeighborLodRelation::Same)
                .collect()
        };
        buffer.mesher.mesh_stitched(voxels, layout, &dense_sides, &stitched)?
    };
    for side in FaceDirection::HORIZONTAL {
        if let (true, Some(lod_diff)) = (options.constrain_edges || options.stitch, context.coarser_neighbor_diff(side))
        {
            constrain_edge_vertices(&mut mesh, side, lod_diff)?;
        }
    }
    mesh.dark_air_plugged = plugged;
    if reach == Some(PlugReach::Interior) {
        if options.stitch {
            // Stitched seams zip faces in the side planes from the coarser
            // neighbour's voxels: no stubs are told apart there (but the
            // mesh plugs what its group shares, and says so).
            mesh.plugged_inside = true;
        } else {
            buffer.mesher.set_aside_stubs(&mut mesh);
        }
    }
    mesh.order_flattening_walls();
    let center = mesh.planet_center();
    if options.draw_time_skirts {
        generate_skirts(&mut mesh, [Some(0.0); 4], &center)?;
    } else if options.skirts {
        let depths = FaceDirection::HORIZONTAL.map(|side| {
            let coarse_lod = match context.relation(side) {
                NeighborLodRelation::Same => return None,
                NeighborLodRelation::HigherThanNeighbor { lod_diff } => key.lod + lod_diff,
                // The finer neighbour is at most as coarse as this chunk.
                NeighborLodRelation::LowerThanNeighbor => key.lod,
            };
            Some(skirt_depth(source, key.lod, coarse_lod) as f32)
        });
        generate_skirts(&mut mesh, depths, &center)?;
    }
    Ok(mesh)
}

thread_local! {
    /// Each thread's [`ChunkMeshBuffer`] for [`mesh_chunks`], kept between
    /// calls: one takes megabytes to set up, and rayon's `map_init` made
    /// one per split of the jobs (a third of meshing 64 chunks on two
    /// threads).
    static BUFFER: std::cell::RefCell<ChunkMeshBuffer> = std::cell::RefCell::new(ChunkMeshBuffer::new());
}

/// Meshes many chunks in parallel with rayon, with one [`ChunkMeshBuffer`]
/// per worker thread, kept for the next call (a few megabytes a thread).
/// Results come back in the order of `jobs`.
pub fn mesh_chunks<S: VoxelSource + ?Sized>(
    source: &S,
    jobs: &[(ChunkKey, ChunkLodContext)],
    options: MeshOptions,
) -> Vec<Result<ChunkMesh, MeshError>> {
    jobs.par_iter()
        .map(|(key, context)| {
            BUFFER.with(|buffer| match buffer.try_borrow_mut() {
                Ok(mut buffer) => mesh_chunk(source, *key, context, options, &mut buffer),
                // This thread is meshing already: a source's `fill_chunk`
                // waited on rayon and was handed this job meanwhile.
                Err(_) => mesh_chunk(source, *key, context, options, &mut ChunkMeshBuffer::new()),
            })
        })
        .collect()
}

fn check_context(key: ChunkKey, context: &ChunkLodContext) -> Result<(), MeshError> {
    let mismatch = |reason: String| Err(MeshError::ContextMismatch { chunk_lod: key.lod, reason });
    if context.lod != key.lod {
        return mismatch(format!("context is for LOD {}", context.lod));
    }
    for side in [FaceDirection::PosY, FaceDirection::NegY] {
        if context.relation(side) != NeighborLodRelation::Same {
            return mismatch(format!("radial side {side:?} has relation {:?}", context.relation(side)));
        }
    }
    Ok(())
}
