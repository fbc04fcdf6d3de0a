// Nebula planet shader: camera-relative chunks, per-vertex geomorphing from
// the screen-space error (seed 001), sun lighting, debug views.

struct Frame {
    view_proj: mat4x4<f32>,
    // xyz: direction towards the sun (unit), w: ambient light.
    sun: vec4<f32>,
    // x: K (pixels per radian), y: τ (pixels), z: debug view, w: morphing on (1) / off (0).
    params: vec4<f32>,
};

struct Chunk {
    // xyz: chunk origin − camera (computed in f64 on the CPU), w: δ of the parent LOD in metres.
    offset: vec4<f32>,
    // x: LOD, y: max LOD, z: chunk id (for colouring).
    info: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(0) var<uniform> chunk: Chunk;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) morph_target: vec3<f32>,
    // low 16 bits: material, high 16 bits: flags (1 = skirt, 2 = constrained).
    @location(3) packed: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) @interpolate(flat) material: u32,
    @location(2) @interpolate(flat) flags: u32,
    @location(3) morph: f32,
};

// μ = smoothstep(clamp((ρ_p/τ − 1) / (1.4 − 1), 0, 1)), ρ_p = δ_parent·K / D:
// the twin of nebula_math::morph_factor. δ_parent is the error of the LOD the
// chunk merges into: 1 where this LOD is needed, 0 where the parent would do.
// Every input is global or a function of the vertex position, so vertices
// shared by neighbouring chunks morph identically.
fn morph_factor(relative: vec3<f32>) -> f32 {
    let distance = max(length(relative), 1e-3);
    let rho = chunk.offset.w * frame.params.x / distance;
    let x = clamp((rho / frame.params.y - 1.0) / 0.4, 0.0, 1.0);
    return x * x * (3.0 - 2.0 * x);
}

@vertex
fn vs_main(in: VertexIn) -> VertexOut {
    var out: VertexOut;
    var mu = 1.0;
    if (frame.params.w > 0.5) {
        mu = morph_factor(chunk.offset.xyz + in.position);
    }
    let local = mix(in.morph_target, in.position, mu);
    out.clip = frame.view_proj * vec4<f32>(chunk.offset.xyz + local, 1.0);
    out.normal = in.normal;
    out.material = in.packed & 0xffffu;
    out.flags = in.packed >> 16u;
    out.morph = mu;
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
        base = lod_colour(chunk.info.x);
    } else if (view == 2u && (in.flags & 1u) != 0u) {
        base = vec3<f32>(1.0, 0.1, 0.6);
    } else if (view == 3u) {
        base = mix(vec3<f32>(0.1, 0.2, 0.9), vec3<f32>(0.9, 0.3, 0.1), in.morph);
    } else if (view == 4u) {
        base = vec3<f32>(0.95, 0.95, 0.95);
    } else if (view == 5u) {
        base = lod_colour(chunk.info.z * 0.37 + 0.1);
    }
    return vec4<f32>(encode(base * light), 1.0);
}
