// Copy one optimized texture from the parameter array into an rgba32float texture that an
// application can bind: RGB for base color, the value in R, G and B for scalar textures,
// alpha 1. Texel (x, y) is parameter texel (x, y), row 0 first, as in the saved images.

// Mirrored by ExportParams in src/optim/texture_export.rs.
struct ExportParams {
    offset: u32,
    width: u32,
    height: u32,
    channels: u32,
}

@group(0) @binding(0) var<uniform> ep: ExportParams;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var texture_out: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let i = gid.x + gid.y * groups.x * 64u;
    if i >= ep.width * ep.height {
        return;
    }
    let base = ep.offset + i * ep.channels;
    var c = vec3f(params[base]);
    if ep.channels == 3u {
        c = vec3f(params[base], params[base + 1u], params[base + 2u]);
    }
    textureStore(texture_out, vec2u(i % ep.width, i / ep.width), vec4f(c, 1.0));
}
