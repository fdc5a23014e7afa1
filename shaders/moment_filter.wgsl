// Moment filter: one level of an edge-stopping a-trous filter over a pair of per-texel arrays
// (Adam's first and second moments, or the variance step's estimate and its variance) of one
// optimized texture, before the step uses them. Each observed texel becomes the normalized
// sum over the 5 x 5 taps at spacing `spacing` (2^level) of
//   h(dx) h(dy) exp(-|guide_i - guide_j| / sigma) x value_j,
// with h = (1/16, 1/4, 3/8, 1/4, 1/16) (the cubic B-spline) and guide the texture's current
// values (all channels: the distance is the length of their difference), or their logarithms
// with log_space. Texels no camera observes take no part as neighbours and are copied
// unchanged; the texture does not wrap. src/optim/moment_filter.rs has the CPU twin.

// Mirrored by MomentFilterParams in src/optim/moment_filter.rs.
struct MomentFilterParams {
    // First float of the texture in params (the guide); the pair is indexed from 0.
    offset: u32,
    width: u32,
    height: u32,
    channels: u32,
    // First word of the texture in `observed` (one word per texel).
    texel_offset: u32,
    // Distance between taps, in texels (2^level).
    spacing: u32,
    // Edge-stopping scale of the guide distance.
    sigma: f32,
    // Nonzero: the guide is ln(max(value, 0) + LOG_FLOOR).
    log_space: u32,
}

@group(0) @binding(0) var<uniform> fp: MomentFilterParams;
@group(0) @binding(1) var<storage, read> src_first: array<f32>;
@group(0) @binding(2) var<storage, read> src_second: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst_first: array<f32>;
@group(0) @binding(4) var<storage, read_write> dst_second: array<f32>;
@group(0) @binding(5) var<storage, read> params: array<f32>;
@group(0) @binding(6) var<storage, read> observed: array<u32>;

// Added to a value before its logarithm, so that values at 0 (a metallic texture's common
// value) have a finite guide. Mirrored by LOG_FLOOR in src/optim/moment_filter.rs.
const LOG_FLOOR: f32 = 1e-3;

fn is_observed(x: i32, y: i32) -> bool {
    if x < 0 || y < 0 || x >= i32(fp.width) || y >= i32(fp.height) {
        return false;
    }
    return observed[fp.texel_offset + u32(y) * fp.width + u32(x)] != 0u;
}

fn guide(t: u32) -> vec3f {
    var v = vec3f(0.0);
    for (var c = 0u; c < fp.channels; c++) {
        let p = params[fp.offset + t * fp.channels + c];
        v[c] = select(p, log(max(p, 0.0) + LOG_FLOOR), fp.log_space != 0u);
    }
    return v;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    let x = i32(gid.x);
    let y = i32(gid.y);
    if x >= i32(fp.width) || y >= i32(fp.height) {
        return;
    }
    let t = u32(y) * fp.width + u32(x);
    if !is_observed(x, y) {
        for (var c = 0u; c < fp.channels; c++) {
            dst_first[t * fp.channels + c] = src_first[t * fp.channels + c];
            dst_second[t * fp.channels + c] = src_second[t * fp.channels + c];
        }
        return;
    }
    let h = array<f32, 3>(0.375, 0.25, 0.0625);
    let centre = guide(t);
    var first = vec3f(0.0);
    var second = vec3f(0.0);
    var weights = 0.0;
    for (var dy = -2; dy <= 2; dy++) {
        for (var dx = -2; dx <= 2; dx++) {
            let nx = x + dx * i32(fp.spacing);
            let ny = y + dy * i32(fp.spacing);
            if !is_observed(nx, ny) {
                continue;
            }
            let n = u32(ny) * fp.width + u32(nx);
            let w = h[abs(dx)] * h[abs(dy)] * exp(-length(guide(n) - centre) / fp.sigma);
            for (var c = 0u; c < fp.channels; c++) {
                first[c] += w * src_first[n * fp.channels + c];
                second[c] += w * src_second[n * fp.channels + c];
            }
            weights += w;
        }
    }
    // The centre tap has weight h(0)^2 > 0, so `weights` is never 0.
    for (var c = 0u; c < fp.channels; c++) {
        dst_first[t * fp.channels + c] = first[c] / weights;
        dst_second[t * fp.channels + c] = second[c] / weights;
    }
}
