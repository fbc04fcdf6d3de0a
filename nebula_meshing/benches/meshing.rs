//! Meshing speed and output size against block-mesh alone, in one run.
//!
//! For the same padded chunks (surface chunks of the Earth-sized planet at
//! LOD 0 and at LOD 5, under the mountain flight's start at LOD 0 and 4
//! (the sea bed, it turned out), in high mountains (1.5 km up or more) at
//! LOD 0 and 4, and a worst case of random 50 % voxels):
//! - `greedy_quads`: block-mesh's greedy meshing alone (the baseline);
//! - `binary_greedy_quads`: block-mesh-bgm's bitmask greedy meshing alone,
//!   the same faces as block-mesh, and `greedy_quads_from_rows`: the same
//!   quads from the chunk's solid rows ([`GreedyQuads`], what `surface`
//!   runs);
//! - `bgm_fast_mesh`: the binary-greedy-meshing crate's `fast_mesh` alone,
//!   with its opacity masks built outside the timing (it expects a game to
//!   keep them up to date), and `bgm_mask_and_fast_mesh`: with its voxels
//!   and masks made from our padded chunk each time;
//! - `surface`: greedy quads → T-junction-free triangles on the sphere,
//!   sky light included (`sky_floors`: its fixed part);
//! - `copy_and_plug_dark_air` against `copy`: what plugging a chunk's dark
//!   cave air costs (`ChunkMesher::plug_dark_air`, streaming from LOD 1);
//! - `pipeline`: `mesh_chunk` with a coarser neighbour on +X (constraining
//!   and a skirt there) from the already generated voxels, `streaming`:
//!   with `MeshOptions::STREAMING` (draw-time skirts on every side), and
//!   `streaming_plugged_inside`: plugged inside too, its stubs set apart
//!   (LOD 0 where only a narrow lens draws it).
//!
//! Each id names its output: quads for block-mesh, triangles for ours, with
//! `visible_block_faces` (no merging) for scale; the first lines printed
//! give each case's vertex count and a fingerprint of its surface mesh
//! (what a change meant to keep the meshes is checked by). Then 64 chunks sequentially
//! vs. `mesh_chunks` on rayon. Run: `cargo bench -p nebula_meshing`.
//!
//! 2026-11-29: the high mountains' LOD-0 chunk (582 greedy quads → 1,682
//! triangles, 2,363 vertices) meshes in 105.7 µs against 35.7 µs for
//! `bgm_mask_and_fast_mesh` (2.96×), its LOD-4 one 120.0 against 35.1 µs
//! (3.4×): the "mountain" chunks of the notes before (0.68× / 0.89×) were
//! the sea bed under the flight's start, 98 and 118 quads. Evening: the
//! surface 85.2 µs against 38.0 µs (2.24×), `render_mesh` 31.4 µs (48.4
//! before its lowest radius became a least dot product).
//! 2026-12-02 (night): 96.7 µs against 65.2 µs (1.48×; 108.4 against
//! 64.7 µs at that session's start: boundary strips scanned only in layers
//! with a quad clipped, the same meshes), the LOD-4 one 121 against 68 µs.

use std::collections::HashMap;

use binary_greedy_meshing as bgm;
use block_mesh::{GreedyQuadsBuffer, RIGHT_HANDED_Y_UP_CONFIG, UnitQuadBuffer, greedy_quads, visible_block_faces};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nebula_meshing::{
    ChunkLodContext, ChunkMesh, ChunkMeshBuffer, ChunkMesher, FaceDirection, GreedyQuads, MeshOptions,
    NeighborLodRelation, RenderMesh, mesh_chunk, mesh_chunks,
};
use nebula_voxel::{
    ChunkColumn, ChunkKey, ChunkLayout, ChunkVoxels, CubeFace, PADDED_CHUNK_VOLUME, PaddedChunkShape, PlanetSettings,
    ProceduralPlanet, SurfaceBounds, Voxel, VoxelCoord, VoxelError, VoxelSource,
};

/// Serves chunks generated beforehand, so the benches time meshing, not
/// noise.
struct Prepared<'a> {
    planet: &'a ProceduralPlanet,
    chunks: HashMap<ChunkKey, ChunkVoxels>,
}

impl VoxelSource for Prepared<'_> {
    fn layout(&self) -> &ChunkLayout {
        self.planet.layout()
    }
    fn voxel(&self, at: VoxelCoord) -> Result<Voxel, VoxelError> {
        self.planet.voxel(at)
    }
    fn fill_chunk(&self, key: ChunkKey, out: &mut ChunkVoxels) -> Result<(), VoxelError> {
        match self.chunks.get(&key) {
            Some(voxels) => {
                out.as_mut_slice().copy_from_slice(voxels.as_slice());
                out.set_key(key);
                Ok(())
            }
            None => self.planet.fill_chunk(key, out),
        }
    }
    fn surface_bounds(&self, column: ChunkColumn) -> Result<SurfaceBounds, VoxelError> {
        self.planet.surface_bounds(column)
    }
    fn geometric_error(&self, lod: u8) -> f64 {
        self.planet.geometric_error(lod)
    }
}

/// The LOD-`lod` column with the most faces in its surface chunks of the
/// 8 × 8 around the start of the 1 km/s mountain flight
/// (`docs/flight-1kms-mountains.json`, Earth seed 1): the steepest ground
/// there. It is the sea bed, about 470 m down (the flight starts over the
/// sea and reaches the range later); [`high_mountain_column`] is on land.
fn mountain_column(planet: &ProceduralPlanet, lod: u8) -> ChunkColumn {
    let eye = nebula_math::DVec3::new(-2_852_441.14, 5_696_193.33, -144_566.46);
    steepest_column_around(planet, eye, lod)
}

/// The same choice around the first of a fixed sequence of random places
/// whose ground is 1,500 m up or more (as the generate bench's mountains).
fn high_mountain_column(planet: &ProceduralPlanet, lod: u8) -> ChunkColumn {
    let mut state = 0x0A1_u64;
    loop {
        let mut unit = || nebula_math::unit_random(&mut state) * 2.0 - 1.0;
        let Some(direction) = nebula_math::DVec3::new(unit(), unit(), unit()).try_normalize() else { continue };
        if planet.height_at(direction) >= 1_500.0 {
            return steepest_column_around(planet, direction * 6.4e6, lod);
        }
    }
}

/// Of the 8 × 8 LOD-`lod` columns around the one over `eye`, the one
/// with the most faces in its surface chunks.
fn steepest_column_around(planet: &ProceduralPlanet, eye: nebula_math::DVec3, lod: u8) -> ChunkColumn {
    let at = planet.layout().voxel_at(eye).expect("the eye is over the planet");
    let cells = 32 << lod;
    let (x, y) = (at.i / cells, at.j / cells);
    let columns = (0..64).map(|n| ChunkColumn { face: at.face, lod, x: x + n % 8 - 4, y: y + n / 8 - 4 });
    columns.max_by_key(|&column| faces(&surface_chunk(planet, column))).expect("64 columns")
}

/// Solid voxels' faces open to air in `voxels`.
fn faces(voxels: &ChunkVoxels) -> usize {
    let mut quads = UnitQuadBuffer::new();
    let faces = &RIGHT_HANDED_Y_UP_CONFIG.faces;
    visible_block_faces(voxels.as_slice(), &PaddedChunkShape {}, [0; 3], [33; 3], faces, &mut quads);
    quads.num_quads()
}

/// The surface chunk of a column with the most solid voxels' faces.
fn surface_chunk(planet: &ProceduralPlanet, column: ChunkColumn) -> ChunkVoxels {
    let mut best = ChunkVoxels::new(column.chunk(0));
    let mut best_faces = 0;
    for layer in planet.surface_chunk_layers(column).expect("on the planet") {
        let mut voxels = ChunkVoxels::new(column.chunk(layer));
        planet.fill_chunk(column.chunk(layer), &mut voxels).expect("valid key");
        let faces = faces(&voxels);
        if faces > best_faces {
            best_faces = faces;
            best = voxels;
        }
    }
    best
}

/// The chunk in binary-greedy-meshing's layout (34³, z fastest, then x,
/// then y) and its opacity mask (one u64 per (y, x) column, bit z), made
/// from our padded voxels (x fastest, then y, then z) in one pass over
/// them: what a game keeping its voxels as we do pays to mesh with it.
fn bgm_input_into(voxels: &ChunkVoxels, out: &mut [u16], opaque: &mut [u64]) {
    const P: usize = 34;
    opaque.fill(0);
    for (z, slab) in voxels.as_slice().chunks_exact(P * P).enumerate() {
        for (y, row) in slab.chunks_exact(P).enumerate() {
            for (x, voxel) in row.iter().enumerate() {
                out[z + x * P + y * P * P] = u16::from(voxel.material());
                opaque[x + y * P] |= u64::from(voxel.is_solid()) << z;
            }
        }
    }
}

/// [`bgm_input_into`] into new buffers.
fn bgm_input(voxels: &ChunkVoxels) -> (Vec<u16>, Vec<u64>) {
    let (mut out, mut opaque) = (vec![0u16; PADDED_CHUNK_VOLUME], vec![0u64; 34 * 34]);
    bgm_input_into(voxels, &mut out, &mut opaque);
    (out, opaque)
}

/// A hash of a mesh's vertices and indices: what a change that should not
/// alter the meshes is checked by.
fn mesh_fingerprint(mesh: &ChunkMesh) -> u64 {
    let mut hasher = std::hash::DefaultHasher::new();
    std::hash::Hash::hash(&format!("{:?}{:?}", mesh.vertices(), mesh.indices()), &mut hasher);
    std::hash::Hasher::finish(&hasher)
}

/// The same for a mesh in GPU form: its vertices' bytes, indices, skirt
/// edges and lowest radius.
fn render_fingerprint(render: &RenderMesh) -> u64 {
    let mut hasher = std::hash::DefaultHasher::new();
    let text = format!("{:?}{:?}{:?}", render.indices, render.skirt_edges, render.lowest_radius.to_bits());
    std::hash::Hash::hash(&(text, bytemuck::cast_slice::<_, u8>(&render.vertices)), &mut hasher);
    std::hash::Hasher::finish(&hasher)
}

fn noisy_chunk(key: ChunkKey) -> ChunkVoxels {
    let mut state = 0x2545_F491_4F6C_DD1D_u64;
    let voxels = (0..PADDED_CHUNK_VOLUME)
        .map(|_| if nebula_math::unit_random(&mut state) < 0.5 { Voxel::STONE } else { Voxel::AIR })
        .collect();
    ChunkVoxels::from_voxels(key, voxels).expect("right size")
}

fn meshing(c: &mut Criterion) {
    let planet = ProceduralPlanet::new(PlanetSettings::earth(1)).expect("valid planet");
    let cases = [
        ("terrain_lod0", surface_chunk(&planet, ChunkColumn { face: CubeFace::PosZ, lod: 0, x: 100_000, y: 70_001 })),
        ("terrain_lod5", surface_chunk(&planet, ChunkColumn { face: CubeFace::NegY, lod: 5, x: 3_000, y: 4_100 })),
        ("mountains_lod0", surface_chunk(&planet, mountain_column(&planet, 0))),
        ("mountains_lod4", surface_chunk(&planet, mountain_column(&planet, 4))),
        ("high_mountains_lod0", surface_chunk(&planet, high_mountain_column(&planet, 0))),
        ("high_mountains_lod4", surface_chunk(&planet, high_mountain_column(&planet, 4))),
        ("noise50", noisy_chunk(ChunkKey { face: CubeFace::PosX, lod: 0, x: 9, y: 9, layer: 0 })),
    ];
    let source = Prepared { planet: &planet, chunks: cases.iter().map(|(_, v)| (v.key(), v.clone())).collect() };
    let mut group = c.benchmark_group("mesh_chunk");
    for (name, voxels) in &cases {
        let key = voxels.key();
        let mut greedy = GreedyQuadsBuffer::new(PADDED_CHUNK_VOLUME);
        let faces = &RIGHT_HANDED_Y_UP_CONFIG.faces;
        greedy_quads(voxels.as_slice(), &PaddedChunkShape {}, [0; 3], [33; 3], faces, &mut greedy);
        let quads = greedy.quads.num_quads();
        let mut unit = UnitQuadBuffer::new();
        visible_block_faces(voxels.as_slice(), &PaddedChunkShape {}, [0; 3], [33; 3], faces, &mut unit);
        let unit_tris = 2 * unit.num_quads();
        let mut mesher = ChunkMesher::new();
        let surface = mesher.mesh(voxels, planet.layout()).expect("valid chunk");
        let surface_tris = surface.triangle_count();
        // What a change that should not alter the meshes can be checked by.
        let fingerprint = mesh_fingerprint(&surface);
        let mut context = ChunkLodContext::uniform(key.lod);
        context.set(FaceDirection::PosX, NeighborLodRelation::HigherThanNeighbor { lod_diff: 1 });
        let mut buffer = ChunkMeshBuffer::new();
        let full = mesh_chunk(&source, key, &context, MeshOptions::default(), &mut buffer).expect("valid chunk");
        eprintln!(
            "{name}: greedy quads {quads} (= {} tris), ours {surface_tris} surface + {} skirt tris ({} vertices), \
             visible_block_faces {unit_tris} tris; T-junction repair +{} tris; surface mesh {fingerprint:016x}",
            2 * quads,
            full.skirt_triangle_count(),
            surface.vertex_count(),
            surface_tris as i64 - 2 * quads as i64
        );
        group.bench_function(BenchmarkId::new(format!("{name}/greedy_quads"), format!("quads={quads}")), |b| {
            b.iter(|| greedy_quads(voxels.as_slice(), &PaddedChunkShape {}, [0; 3], [33; 3], faces, &mut greedy));
        });
        let mut binary = block_mesh_bgm::BinaryGreedyQuadsBuffer::new();
        let binary_greedy = |out: &mut block_mesh_bgm::BinaryGreedyQuadsBuffer| {
            block_mesh_bgm::binary_greedy_quads(voxels.as_slice(), &PaddedChunkShape {}, [0; 3], [33; 3], faces, out);
        };
        binary_greedy(&mut binary);
        let binary_quads = binary.quads.num_quads();
        group.bench_function(
            BenchmarkId::new(format!("{name}/binary_greedy_quads"), format!("quads={binary_quads}")),
            |b| b.iter(|| binary_greedy(&mut binary)),
        );
        // The same quads from the chunk's solid rows: what `surface` runs.
        let mut ours = GreedyQuads::new();
        group.bench_function(
            BenchmarkId::new(format!("{name}/greedy_quads_from_rows"), format!("quads={binary_quads}")),
            |b| {
                b.iter(|| ours.mesh(voxels));
            },
        );
        let (bgm_voxels, bgm_opaque) = bgm_input(voxels);
        let bgm_transparent = vec![0u64; bgm_opaque.len()];
        let mut bgm = bgm::Mesher::<32>::new();
        bgm.fast_mesh(&bgm_voxels, &bgm_opaque, &bgm_transparent);
        let bgm_quads: usize = bgm.quads.iter().map(Vec::len).sum();
        group.bench_function(BenchmarkId::new(format!("{name}/bgm_fast_mesh"), format!("quads={bgm_quads}")), |b| {
            b.iter(|| {
                bgm.clear();
                bgm.fast_mesh(&bgm_voxels, &bgm_opaque, &bgm_transparent);
            });
        });
        // The same with its input made from our voxels each time (the
        // baseline issue 25 names: "its opaque mask and fast_mesh").
        let (mut bgm_scratch, mut bgm_masks) = (bgm_voxels.clone(), bgm_opaque.clone());
        group.bench_function(
            BenchmarkId::new(format!("{name}/bgm_mask_and_fast_mesh"), format!("quads={bgm_quads}")),
            |b| {
                b.iter(|| {
                    bgm_input_into(voxels, &mut bgm_scratch, &mut bgm_masks);
                    bgm.clear();
                    bgm.fast_mesh(&bgm_scratch, &bgm_masks, &bgm_transparent);
                });
            },
        );
        group.bench_function(BenchmarkId::new(format!("{name}/surface"), format!("tris={surface_tris}")), |b| {
            b.iter(|| mesher.mesh(voxels, planet.layout()).expect("valid chunk"));
        });
        // The fixed part of what the sky light costs `surface` (the rest is
        // four voxel reads per vertex and one per face of a quad).
        group.bench_function(BenchmarkId::new(format!("{name}/sky_floors"), "columns=1156"), |b| {
            b.iter(|| voxels.sky_floors());
        });
        // Plugging dark cave air (streaming does it from LOD 1 up), on a
        // copy of the chunk each time: against `copy` alone.
        let mut copy = voxels.clone();
        group.bench_function(BenchmarkId::new(format!("{name}/copy"), "voxels=39304"), |b| {
            b.iter(|| copy.as_mut_slice().copy_from_slice(voxels.as_slice()));
        });
        group.bench_function(BenchmarkId::new(format!("{name}/copy_and_plug_dark_air"), "voxels=39304"), |b| {
            b.iter(|| {
                copy.as_mut_slice().copy_from_slice(voxels.as_slice());
                mesher.plug_dark_air(&mut copy)
            });
        });
        let tris = full.triangle_count();
        group.bench_function(BenchmarkId::new(format!("{name}/pipeline"), format!("tris={tris}")), |b| {
            b.iter(|| mesh_chunk(&source, key, &context, MeshOptions::default(), &mut buffer).expect("valid chunk"));
        });
        // What the streamer runs (draw-time skirts on every side, dark air
        // plugged from LOD 1), generation aside.
        let uniform = ChunkLodContext::uniform(key.lod);
        let streamed = mesh_chunk(&source, key, &uniform, MeshOptions::STREAMING, &mut buffer).expect("valid chunk");
        let tris = streamed.triangle_count();
        eprintln!(
            "{name}: streamed mesh {:016x}, render mesh {:016x}",
            mesh_fingerprint(&streamed),
            render_fingerprint(&streamed.render_mesh())
        );
        group.bench_function(BenchmarkId::new(format!("{name}/streaming"), format!("tris={tris}")), |b| {
            b.iter(|| mesh_chunk(&source, key, &uniform, MeshOptions::STREAMING, &mut buffer).expect("valid chunk"));
        });
        // Where only a narrow lens draws it (LOD 0 kilometres away): plugged
        // inside, its stubs found and set apart.
        let inside = MeshOptions { plug_dark_air_inside: true, ..MeshOptions::STREAMING };
        let tris = mesh_chunk(&source, key, &uniform, inside, &mut buffer).expect("valid chunk").triangle_count();
        group.bench_function(
            BenchmarkId::new(format!("{name}/streaming_plugged_inside"), format!("tris={tris}")),
            |b| {
                b.iter(|| mesh_chunk(&source, key, &uniform, inside, &mut buffer).expect("valid chunk"));
            },
        );
        // What a streaming worker hands the renderer: the mesh in GPU form.
        group.bench_function(BenchmarkId::new(format!("{name}/render_mesh"), format!("tris={tris}")), |b| {
            b.iter(|| streamed.render_mesh());
        });
    }
    group.finish();

    // 64 LOD-2 surface chunks, voxels prepared.
    let mut many = Prepared { planet: &planet, chunks: HashMap::new() };
    let jobs: Vec<(ChunkKey, ChunkLodContext)> = (0..64)
        .map(|n| {
            let voxels =
                surface_chunk(&planet, ChunkColumn { face: CubeFace::PosX, lod: 2, x: 500 + n % 8, y: 900 + n / 8 });
            let key = voxels.key();
            many.chunks.insert(key, voxels);
            (key, ChunkLodContext::uniform(2))
        })
        .collect();
    let mut group = c.benchmark_group("mesh_many_chunks");
    group.sample_size(20);
    group.bench_function("sequential_64", |b| {
        let mut buffer = ChunkMeshBuffer::new();
        b.iter(|| {
            for (key, context) in &jobs {
                mesh_chunk(&many, *key, context, MeshOptions::default(), &mut buffer).expect("valid chunk");
            }
        });
    });
    group.bench_function("rayon_64", |b| b.iter(|| mesh_chunks(&many, &jobs, MeshOptions::default())));
    group.finish();
}

criterion_group!(benches, meshing);
criterion_main!(benches);
