// Smoothness prior: adds to each observed texel's gradient the derivative of
//   R = lambda x (mean over the observed 4-neighbour pairs and channels of (x_i - x_j)^2),
//   dR/dx_i = scale x sum over the observed neighbours j of (x_i - x_j),
// with scale = 2 lambda / (channels x pairs) set by src/optim/prior/smoothness.rs. Texels the
// cameras do not observe take no part (they keep a zero gradient and their initial values).
// The texture does not wrap: texels on opposite edges are not neighbours.

// Mirrored by SmoothnessParams in src/optim/prior/smoothness.rs.
struct SmoothnessParams {
    // First float of the texture in the parameters and the gradient.
    offset: u32,
    width: u32,
    height: u32,
    channels: u32,
    // First word of the texture in `observed` (one word per texel).
    texel_offset: u32,
    scale: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> sp: SmoothnessParams;
@group(0) @binding(1) var<storage, read_write> grad: array<f32>;
@group(0) @binding(2) var<storage, read> params: array<f32>;
@group(0) @binding(3) var<storage, read> observed: array<u32>;

fn is_observed(x: i32, y: i32) -> bool {
    if x < 0 || y < 0 || x >= i32(sp.width) || y >= i32(sp.height) {
        return false;
    }
    return observed[sp.texel_offset + u32(y) * sp.width + u32(x)] != 0u;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    let x = i32(gid.x);
    let y = i32(gid.y);
    if !is_observed(x, y) {
        return;
    }
    let base = sp.offset + (u32(y) * sp.width + u32(x)) * sp.channels;
    let offsets = array<vec2i, 4>(vec2i(-1, 0), vec2i(1, 0), vec2i(0, -1), vec2i(0, 1));
    for (var c = 0u; c < sp.channels; c++) {
        let v = params[base + c];
        var sum = 0.0;
        for (var k = 0; k < 4; k++) {
            let n = vec2i(x, y) + offsets[k];
            if is_observed(n.x, n.y) {
                sum += v - params[sp.offset + (u32(n.y) * sp.width + u32(n.x)) * sp.channels + c];
            }
        }
        grad[base + c] += sp.scale * sum;
    }
}
