// Test pass for shared/wrap: wrapped[i] = wrap_coord(coords[i], n, mode). The test compares
// it with the integer modulo on the CPU (src/render/gpu_scene.rs, wrap_trial).
#import shared/wrap

// Mirrored by TextureWrapTestParams in src/render/gpu_scene.rs.
struct TextureWrapTestParams {
    n: i32,
    mode: u32,
    count: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> tw: TextureWrapTestParams;
@group(0) @binding(1) var<storage, read> coords: array<i32>;
@group(0) @binding(2) var<storage, read_write> wrapped: array<i32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    if id.x >= tw.count {
        return;
    }
    wrapped[id.x] = wrap_coord(coords[id.x], tw.n, tw.mode);
}
