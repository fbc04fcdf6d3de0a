// The depth pyramid the second phase of occlusion culling (`cull.wgsl`)
// tests against: each texel the farthest depth (reversed-Z: the least)
// of the pixels under it.

// The depth pyramid's finest level: the depth drawn (each sample's
// farthest where the depth is multisampled: `cull.rs` replaces the
// declarations of the samples and the depth).
const DEPTH_SAMPLES: i32 = 1;
@group(0) @binding(0) var terrain_depth: texture_depth_2d;
@group(0) @binding(1) var level_out: texture_storage_2d<r32float, write>;

@compute @workgroup_size(8, 8)
fn hzb_first(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(level_out);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    var farthest = 1e30;
    for (var s = 0; s < DEPTH_SAMPLES; s++) {
        farthest = min(farthest, textureLoad(terrain_depth, vec2<i32>(id.xy), s));
    }
    textureStore(level_out, vec2<i32>(id.xy), vec4<f32>(farthest, 0.0, 0.0, 0.0));
}

// A coarser level: each texel the farthest of the 2×2 under it, and of a
// third column (row) where it is the last of an odd-sized level, so that
// every pixel lies under the texel `pixel >> level` (clamped).
@group(0) @binding(2) var level_in: texture_2d<f32>;

@compute @workgroup_size(8, 8)
fn hzb_down(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(level_out);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let below = textureDimensions(level_in);
    let extra = vec2<u32>(
        select(1u, 2u, id.x == size.x - 1u && (below.x & 1u) == 1u),
        select(1u, 2u, id.y == size.y - 1u && (below.y & 1u) == 1u),
    );
    var farthest = 1e30;
    for (var dy = 0u; dy <= extra.y; dy++) {
        for (var dx = 0u; dx <= extra.x; dx++) {
            let at = min(2u * id.xy + vec2<u32>(dx, dy), below - 1u);
            farthest = min(farthest, textureLoad(level_in, vec2<i32>(at), 0).x);
        }
    }
    textureStore(level_out, vec2<i32>(id.xy), vec4<f32>(farthest, 0.0, 0.0, 0.0));
}
