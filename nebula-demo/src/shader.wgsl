// Nebula planet shader: camera-relative chunks, per-vertex geomorphing from
// the screen-space error (seed 001), sun lighting, debug views.

struct Frame {
    view_proj: mat4x4<f32>,
    // xyz: direction towards the sun (unit), w: ambient light.
    sun: vec4<f32>,
    // x: K (pixels per radian), y: τ (pixels), z: debug view, w: morphing on (1) / off (0).
    params: vec4<f32>,
    // The eye's f64 world position as high + low f32 parts.
    eye_high: vec4<f32>,
    eye_low: vec4<f32>,
};

struct Chunk {
    // x: LOD, y: max LOD, z: chunk id (for colouring), w: error of the LOD
    // the chunk merges into (its parent's voxel edge), metres.
    info: vec4<f32>,
    // Skirt depth per horizontal side (+X, −X, +Z, −Z as in
    // nebula_math::FaceDirection::HORIZONTAL), metres.
    skirt_depths: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
// One entry per chunk drawn this frame, indexed by the instance index.
@group(1) @binding(0) var<storage, read> chunks: array<Chunk>;

// nebula_meshing::RenderVertex.
struct VertexIn {
    @location(0) position_high: vec3<f32>,
    @location(1) position_low: vec3<f32>,
    @location(2) target_low: vec3<f32>,
    @location(3) normal: vec2<f32>,
    // low 16 bits: material, high 16 bits: flags (1 = skirt, 2 = constrained,
    // bits 2–3: the side a skirt hangs on).
    @location(4) packed: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) @interpolate(flat) material: u32,
    @location(2) @interpolate(flat) flags: u32,
    @location(3) morph: f32,
    // x: LOD, y: chunk id (for colouring).
    @location(4) @interpolate(flat) lod_id: vec2<f32>,
};

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

@vertex
fn vs_main(in: VertexIn, @builtin(instance_index) instance: u32) -> VertexOut {
    var out: VertexOut;
    let chunk = chunks[instance];
    // Vertex − eye from the high and low parts: a function of the vertex's
    // canonical world position and the frame only, never of the chunk, so a
    // vertex shared by two chunks lands on the same clip position in both.
    // The high part is the morph target's, shared by every vertex that
    // collapses onto it, so at μ = 0 they all land on the bit-identical
    // target (nebula_meshing::RenderVertex).
    let base = in.position_high - frame.eye_high.xyz;
    let fine = base + (in.position_low - frame.eye_low.xyz);
    var relative = fine;
    var mu = 1.0;
    if (frame.params.w > 0.5) {
        mu = morph_factor(chunk.info.w, fine);
        let morph_target = base + (in.target_low - frame.eye_low.xyz);
        relative = morph_target + mu * (fine - morph_target);
    }
    let flags = in.packed >> 16u;
    if ((flags & 1u) != 0u) {
        // A skirt vertex hangs from the (morphed) surface vertex towards the
        // planet centre, as deep as its side needs this frame.
        let centre = -(frame.eye_high.xyz + frame.eye_low.xyz);
        let depth = chunk.skirt_depths[(flags >> 2u) & 3u];
        relative = relative + normalize(centre - relative) * depth;
    }
    out.clip = frame.view_proj * vec4<f32>(relative, 1.0);
    out.normal = decode_normal(in.normal);
    out.material = in.packed & 0xffffu;
    out.flags = flags;
    out.morph = mu;
    out.lod_id = chunk.info.xz;
    return out;
}

fn material_colour(material: u32) -> vec3<f32> {
    switch material {
        case 1u: { return vec3<f32>(0.42, 0.41, 0.40); } // stone
        case 2u: { return vec3<f32>(0.36, 0.25, 0.16); } // dirt
        case 3u: { return vec3<f32>(0.22, 0.45, 0.16); } // grass
        case 4u: { return vec3<f32>(0.76, 0.70, 0.50); } // sand
        case 5u: { return vec3<f32>(0.92, 0.94, 0.97); } // snow
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

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let light = frame.sun.w + max(dot(n, frame.sun.xyz), 0.0) * (1.0 - frame.sun.w);
    var base = material_colour(in.material);
    let view = u32(frame.params.z + 0.5);
    if (view == 1u) {
        base = lod_colour(in.lod_id.x);
    } else if (view == 2u && (in.flags & 1u) != 0u) {
        base = vec3<f32>(1.0, 0.1, 0.6);
    } else if (view == 3u) {
        base = mix(vec3<f32>(0.1, 0.2, 0.9), vec3<f32>(0.9, 0.3, 0.1), in.morph);
    } else if (view == 4u) {
        base = vec3<f32>(0.95, 0.95, 0.95);
    } else if (view == 5u) {
        base = lod_colour(in.lod_id.y * 0.37 + 0.1);
    }
    return vec4<f32>(encode(base * light), 1.0);
}
