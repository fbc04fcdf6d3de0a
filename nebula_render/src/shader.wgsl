// Nebula planet shader: camera-relative chunks, per-vertex geomorphing from
// the screen-space error (seed 001), sun lighting, debug views; and the sky
// pass (sky, sea, haze) drawn over the terrain from its depth.

struct Frame {
    view_proj: mat4x4<f32>,
    // xyz: direction towards the sun (unit), w: ambient light.
    sun: vec4<f32>,
    // x: K (pixels per radian), y: τ (pixels), z: debug view, w: morphing on (1) / off (0).
    params: vec4<f32>,
    // The eye's f64 world position as high + low f32 parts.
    eye_high: vec4<f32>,
    eye_low: vec4<f32>,
    // Camera-relative clip → world (the sky pass's view rays).
    inv_view_proj: mat4x4<f32>,
    // x: planet (sea level) radius, y: eye radius, z: eye altitude, w: metres
    // of water that dim what is under them by a factor e (nebula_render::water_extinction).
    planet: vec4<f32>,
    // x: 1 where the eye is in the sea (nebula_render::FrameParams::eye_in_sea), y:
    // metres of water that hide what lies under them (nebula_render::sea_hiding_depth).
    sea: vec4<f32>,
    // xyz: the eye's world position modulo w (renderer::TINT_PERIOD).
    tint_origin: vec4<f32>,
    // x: LOD-0 voxel edge, y: the planet's relief, metres.
    terrain: vec4<f32>,
};

struct Chunk {
    // x: LOD, y: max LOD, z: chunk id (for colouring), w: error of the LOD
    // the chunk merges into (its parent's voxel edge), metres.
    info: vec4<f32>,
    // Skirt depth per horizontal side (+X, −X, +Z, −Z as in
    // nebula_math::FaceDirection::HORIZONTAL), metres.
    skirt_depths: vec4<f32>,
    // Where the chunk's mesh lies in its page: x its first vertex, y the
    // first word of its skirt edges, z 1 where an edge is two words (the
    // mesh's indices are u32), 0 where it is one (a | b << 16).
    pulls: vec4<u32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
// One entry per chunk drawn this frame, indexed by the instance index.
@group(1) @binding(0) var<storage, read> chunks: array<Chunk>;
// The mesh page drawn from: vertices (nebula_meshing::RenderVertex, 8
// words each), indices and skirt edges (nebula_render's arena).
@group(2) @binding(0) var<storage, read> page: array<u32>;

// nebula_meshing::RenderVertex as the surface pipeline's vertex buffer
// gives it (fixed-function fetch: on lavapipe, reading the page as storage
// took the still land view from 229-231 to 294 ms of GPU time).
struct VertexAttributes {
    @location(0) position_high: vec3<f32>,
    // xyz: (position − morph target) / 2^LOD; w: target_low.x (f16s).
    @location(1) offset_target_x: vec4<f32>,
    // target_low.yz.
    @location(2) target_yz: vec2<f32>,
    @location(3) normal: vec2<f32>,
    @location(4) packed: u32,
};

// nebula_meshing::RenderVertex, unpacked.
struct VertexIn {
    position_high: vec3<f32>,
    // (position − morph target) / 2^LOD.
    offset: vec3<f32>,
    target_low: vec3<f32>,
    normal: vec2<f32>,
    // bits 0–7: material, 8–15: sky light (0–255), 16–23: flags (2 =
    // constrained), 24–31: the LOD whose 2^LOD scales the offset.
    packed: u32,
};

// Vertex `i` of the page: 12 bytes of f32 high part, 12 of f16 offset and
// target low part, 4 of snorm16 normal, 4 packed. The same values as the
// vertex buffer's formats give (f16 and snorm16 convert exactly).
fn load_vertex(i: u32) -> VertexIn {
    let w = i * 8u;
    var v: VertexIn;
    v.position_high = vec3<f32>(bitcast<f32>(page[w]), bitcast<f32>(page[w + 1u]), bitcast<f32>(page[w + 2u]));
    let offset_xy = unpack2x16float(page[w + 3u]);
    let offset_z_target_x = unpack2x16float(page[w + 4u]);
    let target_yz = unpack2x16float(page[w + 5u]);
    v.offset = vec3<f32>(offset_xy, offset_z_target_x.x);
    v.target_low = vec3<f32>(offset_z_target_x.y, target_yz);
    v.normal = unpack2x16snorm(page[w + 6u]);
    v.packed = page[w + 7u];
    return v;
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) @interpolate(flat) material: u32,
    @location(2) @interpolate(flat) flags: u32,
    @location(3) morph: f32,
    // x: LOD, y: chunk id (for colouring).
    @location(4) @interpolate(flat) lod_id: vec2<f32>,
    // Vertex − eye, metres.
    @location(5) relative: vec3<f32>,
    // How much the sky lights the surface: 1 on open ground, 0 deep in a cave.
    @location(6) sky: f32,
};

// What lights a cave far from its mouth: a dim glow, so that its rock
// still reads.
const CAVE_LIGHT: vec3<f32> = vec3<f32>(0.07, 0.068, 0.08);

// μ = smoothstep(clamp((ρ_p/τ − 1) / (1.4 − 1), 0, 1)), ρ_p = δ_parent·K / D:
// the twin of nebula_math::morph_factor (and RenderVertex::drawn_relative).
// δ_parent is the error of the LOD the chunk merges into: μ = 1 where this
// LOD is needed, 0 where the parent would do. Every input is global, per LOD
// or a function of the vertex position, so vertices shared by neighbouring
// chunks morph identically.
fn morph_factor(parent_error: f32, relative: vec3<f32>) -> f32 {
    let distance = max(length(relative), 1e-3);
    let rho = parent_error * frame.params.x / distance;
    let x = clamp((rho / frame.params.y - 1.0) / 0.4, 0.0, 1.0);
    return x * x * (3.0 - 2.0 * x);
}

// Octahedral normal (nebula_meshing::decode_normal).
fn decode_normal(e: vec2<f32>) -> vec3<f32> {
    var n = vec3<f32>(e.x, e.y, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-n.z, 0.0);
    n.x = n.x + select(t, -t, n.x >= 0.0);
    n.y = n.y + select(t, -t, n.y >= 0.0);
    return normalize(n);
}

// A surface vertex placed for the frame: the vertex shaders' common part.
fn place(in: VertexIn, chunk: Chunk) -> VertexOut {
    var out: VertexOut;
    // Vertex − eye from the high and low parts: a function of the vertex's
    // canonical world position, morph target and LOD and of the frame only,
    // never of the chunk, so a vertex shared by two chunks lands on the same
    // clip position in both. The morph target is formed from its own parts,
    // shared by every vertex that collapses onto it, and the vertex is the
    // target plus its offset, so at μ = 0 they all land on the bit-identical
    // target (nebula_meshing::RenderVertex). ldexp by the LOD is exact.
    let base = in.position_high - frame.eye_high.xyz;
    let morph_target = base + (in.target_low - frame.eye_low.xyz);
    let offset = ldexp(in.offset, vec3<i32>(i32(in.packed >> 24u)));
    var relative = morph_target + offset;
    var mu = 1.0;
    if (frame.params.w > 0.5) {
        mu = morph_factor(chunk.info.w, relative);
        relative = morph_target + mu * offset;
    }
    out.clip = frame.view_proj * vec4<f32>(relative, 1.0);
    out.normal = decode_normal(in.normal);
    out.material = in.packed & 0xffu;
    out.sky = f32((in.packed >> 8u) & 0xffu) / 255.0;
    out.flags = (in.packed >> 16u) & 0xffu;
    out.morph = mu;
    out.lod_id = chunk.info.xz;
    out.relative = relative;
    return out;
}

// A surface: indexed draws from the page as vertex buffer.
@vertex
fn vs_main(in: VertexAttributes, @builtin(instance_index) instance: u32) -> VertexOut {
    var v: VertexIn;
    v.position_high = in.position_high;
    v.offset = in.offset_target_x.xyz;
    v.target_low = vec3<f32>(in.offset_target_x.w, in.target_yz);
    v.normal = in.normal;
    v.packed = in.packed;
    return place(v, chunks[instance]);
}

// The skirt draws' vertex index: the side in the bits from SIDE_SHIFT up
// (nebula_render's SKIRT_SIDE_SHIFT), below them 6 per edge of the chunk's
// skirt edges and the corner.
const SIDE_SHIFT: u32 = 28u;
// Corner c of an edge's quad is end (SKIRT_ENDS >> c) & 1 (0 = a, 1 = b)
// of the edge, lowered where (SKIRT_LOWERED >> c) & 1: the triangles
// (a low, b, a) and (b low, b, a low), nebula_meshing::SKIRT_CORNERS.
const SKIRT_ENDS: u32 = 0x1au;
const SKIRT_LOWERED: u32 = 0x29u;

// A skirt: the quad under each outline edge of a side (a → b along the
// surface), its top corners the surface vertices themselves, read from the
// page and placed by the same code as the surface's, its lower ones moved towards the planet centre as deep as the
// side needs this frame.
@vertex
fn vs_skirt(@builtin(vertex_index) i: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    let chunk = chunks[instance];
    let side = i >> SIDE_SHIFT;
    let local = i & ((1u << SIDE_SHIFT) - 1u);
    let edge = local / 6u;
    let corner = local % 6u;
    let end = (SKIRT_ENDS >> corner) & 1u;
    var vertex: u32;
    if (chunk.pulls.z == 0u) {
        vertex = (page[chunk.pulls.y + edge] >> (16u * end)) & 0xffffu;
    } else {
        vertex = page[chunk.pulls.y + 2u * edge + end];
    }
    var out = place(load_vertex(chunk.pulls.x + vertex), chunk);
    if (((SKIRT_LOWERED >> corner) & 1u) != 0u) {
        let centre = -(frame.eye_high.xyz + frame.eye_low.xyz);
        out.relative = out.relative + normalize(centre - out.relative) * chunk.skirt_depths[side];
        out.clip = frame.view_proj * vec4<f32>(out.relative, 1.0);
    }
    // Every corner marks the triangle as skirt (flags flat, from any).
    out.flags = 1u | (side << 2u);
    return out;
}

fn material_colour(material: u32) -> vec3<f32> {
    switch material {
        case 1u: { return vec3<f32>(0.42, 0.41, 0.40); } // stone
        case 2u: { return vec3<f32>(0.36, 0.25, 0.16); } // dirt
        case 3u: { return vec3<f32>(0.22, 0.45, 0.16); } // grass
        case 4u: { return vec3<f32>(0.76, 0.70, 0.50); } // sand
        case 5u: { return vec3<f32>(0.92, 0.94, 0.97); } // snow
        case 6u: { return vec3<f32>(0.55, 0.50, 0.38); } // sea bed
        case 7u: { return vec3<f32>(0.09, 0.25, 0.08); } // forest
        default: { return vec3<f32>(0.6, 0.3, 0.6); }
    }
}

fn lod_colour(lod: f32) -> vec3<f32> {
    let t = lod * 0.61803;
    return 0.5 + 0.5 * cos(6.2831 * (vec3<f32>(t, t, t) + vec3<f32>(0.0, 0.33, 0.67)));
}

// Linear → sRGB encoding: the targets are plain UNORM so that the clear colour
// (a crack sentinel) is stored exactly as given.
fn encode(linear: vec3<f32>) -> vec3<f32> {
    let c = clamp(linear, vec3<f32>(0.0), vec3<f32>(1.0));
    let low = c * 12.92;
    let high = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(high, low, c <= vec3<f32>(0.0031308));
}

// The terrain pass's outputs: the colour, and 1 where the sky pass is to
// draw the sea (sea bed, material 6).
struct TerrainOut {
    @location(0) colour: vec4<f32>,
    @location(1) sea: f32,
};

// The colour of deep water under the sky, before its light.
const DEEP_WATER: vec3<f32> = vec3<f32>(0.01, 0.05, 0.09);

// A hash of an integer lattice point to [0, 1).
fn hash(c: vec3<i32>) -> f32 {
    var h = (u32(c.x) * 0x8da6b343u) ^ (u32(c.y) * 0xd8163841u) ^ (u32(c.z) * 0xcb1ab31fu);
    h = (h ^ (h >> 15u)) * 0x2c1b3c6du;
    h = (h ^ (h >> 12u)) * 0x297a2d39u;
    return f32(h ^ (h >> 15u)) / 4294967296.0;
}

// Value noise in [−1, 1] at `p` (in cells), repeating every `period` cells.
// The corners are wrapped once per axis and hashed one by one: a loop over
// a local array of corners, each wrapped with two integer remainders per
// axis, cost a GPU's fragment shader most of its time (an NVIDIA H200 drew
// a 1920×1080 land view in 77 ms shaded, 19 ms in the LOD colours).
fn value_noise(p: vec3<f32>, period: i32) -> f32 {
    let cell = floor(p);
    let f = p - cell;
    let u = f * f * (3.0 - 2.0 * f);
    let a = (vec3<i32>(cell) % period + period) % period;
    let b = select(a + 1, vec3<i32>(0), a + 1 >= vec3<i32>(period));
    let x0 = mix(
        mix(hash(a), hash(vec3<i32>(b.x, a.y, a.z)), u.x),
        mix(hash(vec3<i32>(a.x, b.y, a.z)), hash(vec3<i32>(b.x, b.y, a.z)), u.x),
        u.y,
    );
    let x1 = mix(
        mix(hash(vec3<i32>(a.x, a.y, b.z)), hash(vec3<i32>(b.x, a.y, b.z)), u.x),
        mix(hash(vec3<i32>(a.x, b.y, b.z)), hash(b), u.x),
        u.y,
    );
    return mix(x0, x1, u.z) * 2.0 - 1.0;
}

// Patches of lighter and darker ground, 16 m and 128 m across, fixed to the
// world (renderer::TINT_PERIOD is a multiple of both) and faded out where they
// would be smaller than a few pixels: what breaks up a field of one
// material. x: brightness, y: the large patches alone.
fn tint(relative: vec3<f32>) -> vec2<f32> {
    let p = relative + frame.tint_origin.xyz;
    let period = frame.tint_origin.w;
    let pixels_per_metre = frame.params.x / max(length(relative), 1.0);
    // Most of a view is far ground where both fade to nothing: no noise there.
    let fine_weight = smoothstep(2.0, 8.0, 16.0 * pixels_per_metre);
    let coarse_weight = smoothstep(2.0, 8.0, 128.0 * pixels_per_metre);
    var fine = 0.0;
    if (fine_weight > 0.0) {
        fine = value_noise(p / 16.0, i32(period / 16.0)) * fine_weight;
    }
    var coarse = 0.0;
    if (coarse_weight > 0.0) {
        coarse = value_noise(p / 128.0, i32(period / 128.0)) * coarse_weight;
    }
    return vec2<f32>(0.07 * fine + 0.1 * coarse, coarse);
}

// Sunlight and skylight on a surface of normal `n` where up is `up`: the
// sun warms and dims towards the horizon and is gone below it; the sky
// lights what faces up more than what faces sideways or down.
fn lighting(n: vec3<f32>, up: vec3<f32>) -> vec3<f32> {
    let sun_height = dot(frame.sun.xyz, up);
    let sun_colour = mix(vec3<f32>(1.0, 0.55, 0.32), vec3<f32>(1.0, 0.96, 0.9), smoothstep(0.0, 0.35, sun_height));
    let sun = sun_colour * max(dot(n, frame.sun.xyz), 0.0) * smoothstep(-0.03, 0.05, sun_height) * 0.85;
    let facing = dot(n, up) * 0.5 + 0.5;
    let sky = mix(vec3<f32>(0.13, 0.12, 0.11), vec3<f32>(0.30, 0.35, 0.44), facing);
    return sun + sky * (0.2 + 0.8 * smoothstep(-0.15, 0.1, sun_height));
}

@fragment
fn fs_main(in: VertexOut) -> TerrainOut {
    let n = normalize(in.normal);
    let up = normalize(in.relative + frame.eye_high.xyz + frame.eye_low.xyz);
    // A voxel's top (bottom) is the sphere shell above (below) it: lit by
    // the radial up, not by its flat quad's normal, which tilts by the
    // quad's angular size (a greedy quad can span a chunk), so that no
    // quad shows as a facet. Sides are lit by their normal, fading to
    // the ground's light where voxels are taller than the relief (their
    // sides are steps of quantisation, not landforms).
    let facing = dot(n, up);
    let voxel = frame.terrain.x * exp2(in.lod_id.x);
    let landform = 1.0 - smoothstep(0.25 * frame.terrain.y, frame.terrain.y, voxel);
    var shading_normal = normalize(mix(up, n, landform));
    if (abs(facing) > 0.7) {
        shading_normal = sign(facing) * up;
    }
    var light = lighting(shading_normal, up);
    var base = material_colour(in.material);
    let view = u32(frame.params.z + 0.5);
    if (view == 0u) {
        // Grass and forest show earth on their sides (steps and cliffs),
        // and every material varies in patches.
        let side = (1.0 - smoothstep(0.3, 0.7, abs(facing))) * landform;
        if (in.material == 3u || in.material == 7u) {
            base = mix(base, vec3<f32>(0.33, 0.26, 0.17), 0.55 * side);
        }
        let t = tint(in.relative);
        base = base * (1.0 + t.x);
        if (in.material == 3u) {
            base = mix(base, vec3<f32>(0.36, 0.42, 0.16), 0.35 * clamp(t.y, 0.0, 1.0));
        }
        // Caves and the ground under overhangs: the sky and the sun reach
        // them only through their openings (exactly the open light where
        // the sky light is 1).
        light = mix(CAVE_LIGHT * (0.6 + 0.4 * facing), light, in.sky);
    } else {
        light = vec3<f32>(frame.sun.w + max(dot(n, frame.sun.xyz), 0.0) * (1.0 - frame.sun.w));
    }
    if (view == 1u) {
        base = lod_colour(in.lod_id.x);
    } else if (view == 2u && (in.flags & 1u) != 0u) {
        base = vec3<f32>(1.0, 0.1, 0.6);
    } else if (view == 3u) {
        base = mix(vec3<f32>(0.1, 0.2, 0.9), vec3<f32>(0.9, 0.3, 0.1), in.morph);
    } else if (view == 4u) {
        base = vec3<f32>(0.95, 0.95, 0.95);
    } else if (view == 5u) {
        base = lod_colour(f32(u32(in.lod_id.y) % 4096u) * 0.37 + 0.1);
    }
    var out: TerrainOut;
    out.colour = vec4<f32>(encode(base * light), 1.0);
    // Sea bed deeper than the sea lets light through (nebula_render::sea_hiding_depth:
    // twelve extinction lengths) is never seen, and the streamer may draw
    // it coarse (nebula_world::stream::OpaqueSea). It gets one deep-water
    // colour, so that a pixel only partly over it (an edge, multisampled)
    // comes out the same whichever sea bed is drawn.
    let depth_under_sea = frame.planet.x - length(in.relative + frame.eye_high.xyz + frame.eye_low.xyz);
    if (in.material == 6u && frame.planet.x > 1.0 && frame.sea.x < 0.5 && depth_under_sea > frame.sea.y) {
        out.colour = vec4<f32>(encode(DEEP_WATER), 1.0);
    }
    // The sea goes over sea bed; and over the sides of voxels taller than
    // the relief where they are below sea level: at a coarse LOD a coast
    // is a wall one voxel tall (kilometres) from the sea bed up to the
    // land, and what of it is under the sea is under water.
    let below_sea = length(in.relative + frame.eye_high.xyz + frame.eye_low.xyz) < frame.planet.x;
    let drowned_side = abs(facing) <= 0.7 && landform < 0.5 && below_sea;
    out.sea = select(0.0, 1.0, in.material == 6u || drowned_side);
    if (view == 6u) {
        // The chunk's number and LOD as bytes (DebugView::Ids).
        let id = u32(in.lod_id.y);
        let bytes = vec4<u32>(id & 255u, (id >> 8u) & 255u, (id >> 16u) & 255u, u32(in.lod_id.x));
        out.colour = vec4<f32>(bytes) / 255.0;
    }
    return out;
}

// ---- Sky pass -------------------------------------------------------------
//
// One full-screen triangle after the terrain, reading its depth. Per pixel:
// the view ray, the sea (the sphere at sea level, hit analytically: no
// mesh, no seams), and haze from the optical depth of an exponential
// atmosphere along the ray (8 samples). A cheap model, not Rayleigh/Mie
// scattering: the sky colour is a gradient from horizon to zenith, tinted by
// the sun's height, and the haze blends towards it. Output is premultiplied:
// rgb the light added, alpha how much of the terrain behind is hidden.

@group(1) @binding(0) var terrain_depth: texture_depth_2d;
@group(1) @binding(1) var sea_mask: texture_2d<f32>;
// Samples a pixel of `terrain_depth` has (4 in the multisampled shader,
// where `textureLoad`'s last argument is the sample; here it is the mip level).
const DEPTH_SAMPLES: i32 = 1;

// Whether the terrain drawn at `pixel` is mostly sea bed: the resolved sea
// mask is the share of all its samples that are sea bed, and this is that
// share among the samples something was drawn at. A pixel where sea bed
// meets nothing drawn (ground left out behind the horizon, under the sea
// that covers both) is sea, as either half is on its own.
fn sea_bed_at(pixel: vec2<i32>) -> bool {
    var drawn = 0.0;
    for (var s = 0; s < DEPTH_SAMPLES; s = s + 1) {
        drawn = drawn + select(0.0, 1.0, textureLoad(terrain_depth, pixel, s) > 0.0);
    }
    return textureLoad(sea_mask, pixel, 0).r * f32(DEPTH_SAMPLES) > 0.5 * drawn && drawn > 0.0;
}

@vertex
fn vs_sky(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

// Scale height and sea-level visibility as shares of the planet radius (8.3
// km and 51 km on Earth); the atmosphere ends 12 scale heights up.
const SCALE_HEIGHT: f32 = 0.0013;
const VISIBILITY: f32 = 0.008;
const TOP: f32 = 12.0;
// Under water, light falls by e over this many of the water's extinction
// lengths (planet.w): 24 m on Earth.
const UNDERWATER_CLARITY: f32 = 8.0;

fn sky_colour(dir: vec3<f32>, up: vec3<f32>) -> vec3<f32> {
    let sun = frame.sun.xyz;
    let elevation = clamp(dot(dir, up), 0.0, 1.0);
    let sun_height = dot(sun, up);
    let day = smoothstep(-0.15, 0.1, sun_height);
    let zenith = vec3<f32>(0.10, 0.28, 0.70);
    let horizon = mix(vec3<f32>(0.85, 0.45, 0.20), vec3<f32>(0.60, 0.72, 0.88), smoothstep(0.0, 0.35, sun_height));
    var colour = mix(horizon, zenith, pow(elevation, 0.45));
    colour = colour + vec3<f32>(1.0, 0.75, 0.45) * pow(max(dot(dir, sun), 0.0), 24.0) * 0.35;
    return colour * (0.08 + 0.92 * day);
}

// Height above sea level of the point `t` along the ray, from
// r² − R² = c + 2tb + t² (no cancellation against R²).
fn altitude(t: f32, b: f32, c: f32, radius: f32) -> f32 {
    let excess = c + 2.0 * t * b + t * t;
    return excess / (sqrt(radius * radius + excess) + radius);
}

@fragment
fn fs_sky(@builtin(position) pixel: vec4<f32>) -> @location(0) vec4<f32> {
    let size = vec2<f32>(textureDimensions(terrain_depth));
    let depth = textureLoad(terrain_depth, vec2<i32>(pixel.xy), 0);
    let ndc = vec2<f32>(pixel.x / size.x * 2.0 - 1.0, 1.0 - pixel.y / size.y * 2.0);
    let near = frame.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let dir = normalize(near.xyz / near.w);
    let radius = frame.planet.x;
    let eye_radius = frame.planet.y;
    let height = frame.planet.z;
    let up = normalize(frame.eye_high.xyz + frame.eye_low.xyz);
    let b = dot(dir, up) * eye_radius;
    let c = height * (eye_radius + radius);
    // Terrain (reverse Z: 0 is nothing drawn).
    var terrain = 3.0e38;
    if (depth > 0.0) {
        let p = frame.inv_view_proj * vec4<f32>(ndc, depth, 1.0);
        terrain = length(p.xyz / p.w);
    }
    // Under the sea: the ray runs through water until it meets the
    // terrain or leaves through the surface (the sea sphere's far root),
    // and the water dims and tints what lies at its end: murk from the
    // water's extinction (`UNDERWATER_CLARITY` times longer than the
    // shallows' from above, so a diver sees tens of metres), lit by the
    // sun's height; up through the surface, the sky.
    if (height < 0.0 && frame.sea.x > 0.5) {
        let exit = -b + sqrt(max(b * b - c, 0.0));
        let path = min(terrain, exit);
        let murk = 1.0 - exp(-path / (UNDERWATER_CLARITY * frame.planet.w));
        let lit = 0.12 + 0.88 * smoothstep(-0.1, 0.4, dot(frame.sun.xyz, up));
        let water = vec3<f32>(0.015, 0.11, 0.15) * lit;
        if (terrain < exit) {
            return vec4<f32>(encode(water) * murk, murk);
        }
        let window = sky_colour(dir, up) * 0.7;
        return vec4<f32>(encode(mix(window, water, murk)), 1.0);
    }
    // The sea: over sea bed, where the ray meets the sea-level sphere (or
    // at the sea bed itself, where a coarse LOD drew it above); and where
    // the ray meets that sphere with no terrain drawn (the terrain pass also
    // marks the sides of voxels taller than the relief under sea level:
    // coasts at coarse LODs). Never over land, even
    // land a coarse LOD rounded down below sea level.
    var sea = -1.0;
    let sea_bed = sea_bed_at(vec2<i32>(pixel.xy));
    let sea_disc = b * b - c;
    var sphere = 3.0e38;
    if (height > 0.0 && sea_disc > 0.0 && -b - sqrt(sea_disc) > 0.0) {
        sphere = -b - sqrt(sea_disc);
    }
    if (sea_bed && height > 0.0) {
        sea = min(sphere, terrain);
    } else if (depth == 0.0 && sphere < 1.0e38) {
        sea = sphere;
    }
    var hit = terrain;
    if (sea > 0.0) {
        hit = sea;
    }
    // Optical depth through the atmosphere, up to whatever the ray hits,
    // or the sea-level sphere if that comes first: ground drawn below sea
    // level over land is mostly the sag of a coarse chunk's flat quads
    // (7.7 km at the middle of a LOD-14 chunk on an Earth), and hazing
    // it deeper drew each chunk as a brighter bowl from orbit.
    let scale_height = SCALE_HEIGHT * radius;
    let top = radius + TOP * scale_height;
    let top_c = (height - TOP * scale_height) * (eye_radius + top);
    let top_disc = b * b - top_c;
    var tau = 0.0;
    if (top_disc > 0.0) {
        let start = max(-b - sqrt(top_disc), 0.0);
        let end = min(-b + sqrt(top_disc), min(hit, sphere));
        if (end > start) {
            let step = (end - start) / 8.0;
            for (var k = 0; k < 8; k = k + 1) {
                let t = start + (f32(k) + 0.5) * step;
                tau = tau + exp(-max(altitude(t, b, c, radius), 0.0) / scale_height) * step;
            }
            tau = tau / (VISIBILITY * radius);
        }
    }
    let transmit = exp(-tau);
    let sky = sky_colour(dir, up);
    if (hit > 1.0e38) {
        // Sky: opaque inside the atmosphere, a glow along the limb from
        // space, and the sun's disc.
        let glow = 1.0 - exp(-6.0 * tau);
        let disc = smoothstep(0.99985, 0.99995, dot(dir, frame.sun.xyz)) * transmit;
        let light = encode(sky) * glow + vec3<f32>(1.0, 0.95, 0.85) * disc;
        return vec4<f32>(min(light, vec3<f32>(1.0)), clamp(max(glow, disc), 0.0, 1.0));
    }
    let haze = 1.0 - transmit;
    if (sea > 0.0) {
        let normal = normalize(up * eye_radius + dir * sea);
        let reflected = reflect(dir, normal);
        let facing = max(dot(-dir, normal), 0.0);
        let fresnel = 0.02 + 0.98 * pow(1.0 - facing, 5.0);
        let lit = max(dot(normal, frame.sun.xyz), 0.0);
        let water = DEEP_WATER * (0.3 + 0.7 * lit);
        let glint = vec3<f32>(1.0, 0.9, 0.7) * pow(max(dot(reflected, frame.sun.xyz), 0.0), 300.0) * 2.0 * lit;
        let surface = mix(water, sky_colour(reflected, normal), fresnel) + glint;
        // Shallow water shows the sea floor.
        var opacity = 1.0 - exp(-(terrain - sea) / frame.planet.w);
        if (sea >= terrain) {
            opacity = 1.0;
        }
        let light = encode(surface) * opacity * transmit + encode(sky) * haze;
        return vec4<f32>(light, 1.0 - transmit * (1.0 - opacity));
    }
    let relief = relief_shade(vec2<i32>(pixel.xy), terrain, up);
    return vec4<f32>(encode(sky) * haze, 1.0 - relief * (1.0 - haze));
}

// The terrain's camera-relative position at `pixel` (w: 1 where terrain
// was drawn there, else 0).
fn terrain_point(pixel: vec2<i32>) -> vec4<f32> {
    let size = vec2<i32>(textureDimensions(terrain_depth));
    let p = clamp(pixel, vec2<i32>(0), size - 1);
    let depth = textureLoad(terrain_depth, p, 0);
    let ndc = vec2<f32>((f32(p.x) + 0.5) / f32(size.x) * 2.0 - 1.0, 1.0 - (f32(p.y) + 0.5) / f32(size.y) * 2.0);
    let world = frame.inv_view_proj * vec4<f32>(ndc, depth, 1.0);
    return vec4<f32>(world.xyz / world.w, select(0.0, 1.0, depth > 0.0));
}

// Relief shading of distant terrain, 1 (none) down to 0.4: how much
// less light the ground gets than flat ground would, with its normal
// taken from the depth two pixels either side. Beyond the first few
// hundred metres every voxel drawn is about a pixel (the LOD rule), so
// each one's own normal, up or sideways, says nothing of the slope it is
// part of; across four pixels the staircase averages out into it. Faded
// in from where LOD-0 voxels shrink below a pixel to a quarter of one,
// and out where the voxels drawn (about a pixel) grow past a tenth of the
// relief: there the ground is flat greedy quads up to a chunk wide, whose
// tilt against the sphere is no landform. Left out across silhouettes.
// It can only darken (the pass blends over the terrain): slopes away from
// the sun.
fn relief_shade(pixel: vec2<i32>, distance: f32, up: vec3<f32>) -> f32 {
    let voxel_pixels = frame.terrain.x * frame.params.x / max(distance, 1.0);
    let pixel_metres = distance / frame.params.x;
    let fade = (1.0 - smoothstep(0.25, 1.0, voxel_pixels))
        * (1.0 - smoothstep(0.04 * frame.terrain.y, 0.1 * frame.terrain.y, pixel_metres));
    if (fade <= 0.0) {
        return 1.0;
    }
    let left = terrain_point(pixel - vec2<i32>(2, 0));
    let right = terrain_point(pixel + vec2<i32>(2, 0));
    let above = terrain_point(pixel - vec2<i32>(0, 2));
    let below = terrain_point(pixel + vec2<i32>(0, 2));
    let across = right.xyz - left.xyz;
    let down = below.xyz - above.xyz;
    // A silhouette: a neighbour missing or far behind the others; or a
    // neighbour under the sea (its sea bed is hidden, and may be drawn
    // coarse: it must not shade the land beside it).
    let spread = max(length(across), length(down));
    let eye = frame.eye_high.xyz + frame.eye_low.xyz;
    let lowest = min(min(length(left.xyz + eye), length(right.xyz + eye)), min(length(above.xyz + eye), length(below.xyz + eye)));
    if (left.w * right.w * above.w * below.w < 0.5 || spread > 0.05 * distance || lowest < frame.planet.x) {
        return 1.0;
    }
    var n = normalize(cross(down, across));
    if (dot(n, up) < 0.0) {
        n = -n;
    }
    // Slopes steepened 2.5 times, as hill shading does: a 15° flank
    // seen from kilometres away should read as one.
    let tilt = n - up * dot(n, up);
    n = normalize(up * dot(n, up) + tilt * 2.5);
    let shade = dot(lighting(n, up), vec3<f32>(0.3, 0.5, 0.2)) / max(dot(lighting(up, up), vec3<f32>(0.3, 0.5, 0.2)), 1e-3);
    return mix(1.0, clamp(shade, 0.4, 1.0), fade);
}
