// Two-phase occlusion culling of the frame's indirect draws.
//
// The draw list is written twice into the indirect buffer: block 1 (the
// first phase) and block 2 (the second), each the surface draws (5 words)
// then the skirt draws (4 words). The first phase draws the chunks that
// were visible the last time they were tested (a bit per mesh in
// `visible`) and lie in the frustum; then the depth they drew is reduced
// into a depth pyramid (`hzb_first`, `hzb_down`: each texel the farthest
// depth it covers); the second phase tests every chunk's box against it
// and draws those the first phase did not and that some pixel may show.
// The test is conservative (a chunk is left out only where every pixel its
// box covers already holds something nearer than the box's nearest point),
// so the picture is the same as drawing everything; only the triangles
// sent to the rasteriser change. Depth is reversed-Z with an infinite far
// plane: nearer is greater, the sky is 0.

struct CullParams {
    // Camera-relative clip from world (the terrain's `view_proj`).
    view_proj: mat4x4<f32>,
    // Width and height of the target, pixels.
    screen: vec2<f32>,
    // The near plane, metres (`NEAR_PLANE`).
    near: f32,
    // Mip levels of the depth pyramid.
    mips: u32,
    // Surface draws, then skirt draws, in each block.
    surface_draws: u32,
    skirt_draws: u32,
    _pad: vec2<u32>,
}

// A chunk's box, camera relative (every position its vertex shaders may
// give, morphed or not, skirts lowered): its centre and three half axes;
// and its mesh's key in `visible`.
struct ChunkBox {
    centre: vec3<f32>,
    key: u32,
    half_axes: array<vec4<f32>, 3>,
}

// The frame's parameters and its chunks' boxes by instance, in one
// storage buffer: on lavapipe a uniform buffer bound to a compute pass
// kept about 0.9 MB of the process's memory a pass.
struct Frame {
    params: CullParams,
    boxes: array<ChunkBox>,
}

@group(0) @binding(1) var<storage, read> frame: Frame;
@group(0) @binding(2) var<storage, read_write> draws: array<u32>;
@group(0) @binding(3) var<storage, read_write> visible: array<atomic<u32>>;
// Triangles and draws of each phase: [phase 1 triangles, phase 2
// triangles, phase 1 draws, phase 2 draws].
@group(0) @binding(4) var<storage, read_write> counts: array<atomic<u32>, 4>;
@group(0) @binding(5) var pyramid: texture_2d<f32>;

// Where draw `i`'s words start in block 1, its instance count's offset
// from there, its first instance's, and its triangles (index or vertex
// count over 3).
struct DrawAt {
    start: u32,
    instance: u32,
    first_instance: u32,
    triangles: u32,
}

fn draw_at(i: u32) -> DrawAt {
    if i < frame.params.surface_draws {
        let start = 5u * i;
        return DrawAt(start, start + 1u, start + 4u, draws[start] / 3u);
    }
    let start = 5u * frame.params.surface_draws + 4u * (i - frame.params.surface_draws);
    return DrawAt(start, start + 1u, start + 3u, draws[start] / 3u);
}

fn block_words() -> u32 {
    return 5u * frame.params.surface_draws + 4u * frame.params.skirt_draws;
}

// The box's eight corners in clip space.
fn corner(b: ChunkBox, k: u32) -> vec4<f32> {
    let p = b.centre
        + select(-1.0, 1.0, (k & 1u) != 0u) * b.half_axes[0].xyz
        + select(-1.0, 1.0, (k & 2u) != 0u) * b.half_axes[1].xyz
        + select(-1.0, 1.0, (k & 4u) != 0u) * b.half_axes[2].xyz;
    return frame.params.view_proj * vec4<f32>(p, 1.0);
}

// Whether the box lies wholly outside one plane of the frustum (sides and
// near plane; the far plane is at infinity).
fn outside_frustum(b: ChunkBox) -> bool {
    var left = true;
    var right = true;
    var below = true;
    var above = true;
    var near = true;
    for (var k = 0u; k < 8u; k++) {
        let c = corner(b, k);
        left = left && c.x < -c.w;
        right = right && c.x > c.w;
        below = below && c.y < -c.w;
        above = above && c.y > c.w;
        // Reversed-Z: depth z/w over 1 is nearer than the near plane.
        near = near && c.z > c.w;
    }
    return left || right || below || above || near;
}

// Whether every pixel the box may cover already holds a surface nearer
// than the box's nearest point, by the depth pyramid.
fn occluded(b: ChunkBox) -> bool {
    var low = vec2<f32>(1e30);
    var high = vec2<f32>(-1e30);
    var nearest = 1e30;
    for (var k = 0u; k < 8u; k++) {
        let c = corner(b, k);
        // A corner at or behind the near plane: the box reaches the eye.
        if c.w <= frame.params.near {
            return false;
        }
        let ndc = c.xy / c.w;
        let pixel = vec2<f32>((ndc.x * 0.5 + 0.5) * frame.params.screen.x, (0.5 - ndc.y * 0.5) * frame.params.screen.y);
        low = min(low, pixel);
        high = max(high, pixel);
        nearest = min(nearest, c.w);
    }
    let depth = frame.params.near / nearest;
    // The pixels whose centres the box may cover, a pixel more each way
    // for rounding, clamped to the target.
    // (Clamped as floats: a corner near the near plane can lie past what
    // an i32 holds.)
    let last = vec2<i32>(frame.params.screen) - 1;
    let lastf = vec2<f32>(last);
    if any(floor(high) + 1.0 < vec2<f32>(0.0)) || any(floor(low) - 1.0 > lastf) {
        // Off the target altogether (the frustum test's rounding).
        return true;
    }
    let first_pixel = vec2<i32>(clamp(floor(low) - 1.0, vec2<f32>(0.0), lastf));
    let last_pixel = vec2<i32>(clamp(floor(high) + 1.0, vec2<f32>(0.0), lastf));
    // The finest level where the rectangle is at most 256 texels.
    var level = 0u;
    loop {
        let span = (last_pixel >> vec2<u32>(level)) - (first_pixel >> vec2<u32>(level)) + 1;
        if span.x * span.y <= 256 || level + 1u >= frame.params.mips {
            break;
        }
        level += 1u;
    }
    // (Computed, not `textureDimensions(pyramid, level)`: lavapipe answers
    // that with the wrong level's size.)
    let size = max(vec2<i32>(frame.params.screen) >> vec2<u32>(level), vec2<i32>(1));
    let start = min(first_pixel >> vec2<u32>(level), size - 1);
    let end = min(last_pixel >> vec2<u32>(level), size - 1);
    for (var y = start.y; y <= end.y; y++) {
        for (var x = start.x; x <= end.x; x++) {
            // The farthest depth under this texel is not nearer than the
            // box: the box may show there.
            if textureLoad(pyramid, vec2<i32>(x, y), i32(level)).x <= depth {
                return false;
            }
        }
    }
    return true;
}

// Dispatched with one row of workgroups for the first phase and two for
// the second, whose second row does the work.
@compute @workgroup_size(64)
fn cull(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let phase = groups.y - 1u;
    let i = id.x;
    if id.y != phase || i >= frame.params.surface_draws + frame.params.skirt_draws {
        return;
    }
    let at = draw_at(i);
    let b = frame.boxes[draws[at.first_instance]];
    let word = b.key >> 5u;
    let bit = 1u << (b.key & 31u);
    let second = block_words();
    if phase == 0u {
        let was_visible = (atomicLoad(&visible[word]) & bit) != 0u;
        let drawn = was_visible && !outside_frustum(b);
        draws[at.instance] = select(0u, 1u, drawn);
        draws[second + at.instance] = 0u;
        if drawn {
            atomicAdd(&counts[0], at.triangles);
            atomicAdd(&counts[2], 1u);
        }
        return;
    }
    let shows = !outside_frustum(b) && !occluded(b);
    if shows {
        atomicOr(&visible[word], bit);
    } else {
        atomicAnd(&visible[word], ~bit);
    }
    if shows && draws[at.instance] == 0u {
        draws[second + at.instance] = 1u;
        atomicAdd(&counts[1], at.triangles);
        atomicAdd(&counts[3], 1u);
    }
}
