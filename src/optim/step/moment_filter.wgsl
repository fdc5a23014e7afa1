// Moment filter: one level of an edge-stopping a-trous filter over a pair of per-texel arrays
// (Adam's first and second moments, or the variance step's estimate and its variance) of one
// optimized texture, before the step uses them. Each observed texel's first value becomes the
// normalized sum over the 5 x 5 taps (radius 2) or 3 x 3 taps (radius 1) at spacing `spacing`
// (2^level) of
//   w_j x value_j,  w_j = h(dx) h(dy) exp(-|guide_i - guide_j| / sigma),
// with h = (1/16, 1/4, 3/8, 1/4, 1/16) (the cubic B-spline) or (1/4, 1/2, 1/4) (the linear
// one) and guide the texture's current values (all channels: the distance is the length of
// their difference), or their logarithms with log_space. Its second value becomes the same
// weighted mean (Adam's second moment), or with variance_of_mean the variance of that mean,
// sum w_j^2 x value_j / (sum w_j)^2, for estimates taken as independent (the variance step's
// variance). A neighbour whose edge factor is below exp(-MAX_EXPONENT) (about 1e-7) is left
// out: it would change nothing, and its loads are saved. Texels no camera observes take no
// part as neighbours and are copied unchanged; the texture does not wrap.
// src/optim/step/moment_filter.rs has the CPU twin.

// Mirrored by MomentFilterParams in src/optim/step/moment_filter.rs.
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
    // 2: 5 x 5 taps, 1: 3 x 3.
    radius: i32,
    // Nonzero: the second value is a variance, filtered as the variance of the weighted mean.
    variance_of_mean: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> fp: MomentFilterParams;
@group(0) @binding(1) var<storage, read> src_first: array<f32>;
@group(0) @binding(2) var<storage, read> src_second: array<f32>;
@group(0) @binding(3) var<storage, read_write> dst_first: array<f32>;
@group(0) @binding(4) var<storage, read_write> dst_second: array<f32>;
@group(0) @binding(5) var<storage, read> params: array<f32>;
@group(0) @binding(6) var<storage, read> observed: array<u32>;

// Added to a value before its logarithm, so that values at 0 (a metallic texture's common
// value) have a finite guide. Mirrored by LOG_FLOOR in src/optim/step/moment_filter.rs.
const LOG_FLOOR: f32 = 1e-3;
// Neighbours with exp(-distance / sigma) below exp(-MAX_EXPONENT) are left out. Mirrored by
// MAX_EXPONENT in src/optim/step/moment_filter.rs.
const MAX_EXPONENT: f32 = 16.0;

fn is_observed(x: i32, y: i32) -> bool {
    if x < 0 || y < 0 || x >= i32(fp.width) || y >= i32(fp.height) {
        return false;
    }
    return observed[fp.texel_offset + u32(y) * fp.width + u32(x)] != 0u;
}

// Texel t's channels (unused ones 0) of the guide and of the source pair.
fn guide(t: u32) -> vec3f {
    let b = fp.offset + t * fp.channels;
    var v = vec3f(params[b], 0.0, 0.0);
    if fp.channels == 3u {
        v = vec3f(params[b], params[b + 1u], params[b + 2u]);
    }
    if fp.log_space != 0u {
        return log(max(v, vec3f(0.0)) + LOG_FLOOR);
    }
    return v;
}

fn first_at(t: u32) -> vec3f {
    let b = t * fp.channels;
    if fp.channels == 3u {
        return vec3f(src_first[b], src_first[b + 1u], src_first[b + 2u]);
    }
    return vec3f(src_first[b], 0.0, 0.0);
}

fn second_at(t: u32) -> vec3f {
    let b = t * fp.channels;
    if fp.channels == 3u {
        return vec3f(src_second[b], src_second[b + 1u], src_second[b + 2u]);
    }
    return vec3f(src_second[b], 0.0, 0.0);
}

fn write(t: u32, first: vec3f, second: vec3f) {
    let b = t * fp.channels;
    dst_first[b] = first.x;
    dst_second[b] = second.x;
    if fp.channels == 3u {
        dst_first[b + 1u] = first.y;
        dst_first[b + 2u] = first.z;
        dst_second[b + 1u] = second.y;
        dst_second[b + 2u] = second.z;
    }
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
        write(t, first_at(t), second_at(t));
        return;
    }
    // The kernel's taps at offsets 0, 1, 2.
    var h = vec3f(0.375, 0.25, 0.0625);
    if fp.radius == 1 {
        h = vec3f(0.5, 0.25, 0.0);
    }
    let r = fp.radius;
    let centre = guide(t);
    var first = vec3f(0.0);
    var second = vec3f(0.0);
    var weights = 0.0;
    for (var dy = -r; dy <= r; dy++) {
        for (var dx = -r; dx <= r; dx++) {
            let nx = x + dx * i32(fp.spacing);
            let ny = y + dy * i32(fp.spacing);
            if !is_observed(nx, ny) {
                continue;
            }
            let n = u32(ny) * fp.width + u32(nx);
            let e = length(guide(n) - centre) / fp.sigma;
            if e > MAX_EXPONENT {
                continue;
            }
            let w = h[abs(dx)] * h[abs(dy)] * exp(-e);
            first += w * first_at(n);
            second += select(w, w * w, fp.variance_of_mean != 0u) * second_at(n);
            weights += w;
        }
    }
    // The centre tap has weight h(0)^2 > 0, so `weights` is never 0.
    let norm = select(weights, weights * weights, fp.variance_of_mean != 0u);
    write(t, first / weights, second / norm);
}
