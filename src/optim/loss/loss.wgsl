// Image loss and its adjoint dL/dI for one camera, from the primal render's accumulated
// samples. The compared image is gain x render, per channel (the camera's exposure times its
// white balance); each pixel's terms are weighted by the target's mask (its w; 0 leaves the
// pixel out of the loss and the gradient). The total loss is the mean over all cameras'
// masked pixels and channels; partial sums per workgroup go to
// loss_partial[partial_offset + group], and those of dL/d(gain) per channel to
// exposure_partial[3 (partial_offset + group) + channel].
//
// dL/d(gain_c) = sum 2 w (k r - g)_c r_c uses the render r twice; with one noisy render the
// product's mean carries r's variance and pulls the gain low (measured: 1.10 for a true 1.4 at
// 4 spp). So it pairs this render with the previous iteration's image-space derivative
// 2 w (k' r' - g), made from independent samples (adjoint_prev holds it times that
// iteration's gain, lp.gain_prev; its w is 1 once written). The one-step lag in the textures
// is the price.
#import shared/types

// Mirrored by LossParams in src/optim/loss.rs.
struct LossParams {
    n_pixels: u32,
    // 0: L2, 1: relMSE, 2: sRGB, 3: log.
    kind: u32,
    // 1 / (3 x the mask's sum over all cameras' pixels).
    norm: f32,
    partial_offset: u32,
    // Where this camera's pixels start in adjoint[].
    adjoint_offset: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // The factors the render is multiplied by before the comparison, per channel, and those
    // of the iteration that wrote adjoint_prev.
    gain: vec3f,
    gain_prev: vec3f,
}

const REL_EPS: f32 = 0.01;
// A photo's channel at or above this linear value was clipped (8-bit 255 decodes to 1).
const CLIPPED: f32 = 0.999;

// The sRGB transfer curve of a linear value, continued above 1 (1.055 x^(1/2.4) - 0.055),
// and its slope.
fn srgb_encode(x: vec3f) -> vec3f {
    let v = max(x, vec3f(0.0));
    return select(1.055 * pow(v, vec3f(1.0 / 2.4)) - 0.055, 12.92 * v, v <= vec3f(0.0031308));
}

fn srgb_slope(x: vec3f) -> vec3f {
    let v = max(x, vec3f(0.0031308));
    return select(1.055 / 2.4 * pow(v, vec3f(1.0 / 2.4 - 1.0)), vec3f(12.92), x <= vec3f(0.0031308));
}

@group(0) @binding(0) var<uniform> lp: LossParams;
@group(0) @binding(1) var<storage, read> accum: array<vec4f>;
// rgb, and the pixel's mask weight in w.
@group(0) @binding(2) var<storage, read> target_image: array<vec4f>;
@group(0) @binding(3) var<storage, read_write> adjoint: array<vec4f>;
@group(0) @binding(4) var<storage, read_write> loss_partial: array<f32>;
// [0] pixels whose loss or adjoint was not finite (left out of both).
@group(0) @binding(5) var<storage, read_write> loss_stats: array<atomic<u32>, 4>;
@group(0) @binding(6) var<storage, read_write> exposure_partial: array<f32>;
// The previous iteration's adjoint (the other parity's buffer); w: 1 once written, 0 if none.
@group(0) @binding(7) var<storage, read> adjoint_prev: array<vec4f>;

var<workgroup> partial: array<vec4f, 64>;

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) li: u32, @builtin(workgroup_id) wg: vec3u, @builtin(num_workgroups) groups: vec3u) {
    // Workgroup `group` takes pixels 64 group to 64 group + 63, whichever row of the grid it
    // is in (src/gpu grid_2d).
    let group = wg.x + wg.y * groups.x;
    let i = group * 64u + li;
    var l = vec4f(0.0);
    if i < lp.n_pixels {
        let a = accum[i];
        let rendered = a.xyz / max(a.w, 1.0);
        let img = lp.gain * rendered;
        let t = target_image[i];
        let g = t.xyz;
        let mask = t.w;
        // Each loss is a weighted square of diff = f(img) - f(g), f the space it compares
        // in; d_f = f'(img) (src/optim/loss.rs holds the CPU twin).
        var diff = img - g;
        var w = vec3f(1.0);
        var d_f = vec3f(1.0);
        if lp.kind == 1u {
            w = 1.0 / (g * g + vec3f(REL_EPS));
        } else if lp.kind == 2u {
            diff = srgb_encode(img) - srgb_encode(g);
            d_f = srgb_slope(img);
            // A channel the photo clipped counts only where the render is below it.
            w = select(vec3f(1.0), vec3f(0.0), g >= vec3f(CLIPPED) & img >= g);
        } else if lp.kind == 3u {
            let r = max(img, vec3f(0.0));
            diff = log(vec3f(1.0) + r) - log(vec3f(1.0) + max(g, vec3f(0.0)));
            d_f = 1.0 / (vec3f(1.0) + r);
        }
        // dL / d(gain x render), then by the chain rule the adjoint of the render and the
        // derivative with respect to the gain.
        let d_img = 2.0 * diff * w * d_f * lp.norm * mask;
        var adj = d_img * lp.gain;
        var term = dot(diff * diff, w) * lp.norm * mask;
        let prev = adjoint_prev[lp.adjoint_offset + i];
        var d_gain = vec3f(0.0);
        if prev.w > 0.0 {
            d_gain = select(vec3f(0.0), prev.xyz / lp.gain_prev, lp.gain_prev > vec3f(0.0)) * rendered;
        }
        if !(all(abs(adj) < vec3f(3.0e38)) && abs(term) < 3.0e38 && all(abs(d_gain) < vec3f(3.0e38))) {
            adj = vec3f(0.0);
            term = 0.0;
            d_gain = vec3f(0.0);
            atomicAdd(&loss_stats[LOSS_STAT_DROPPED], 1u);
        }
        adjoint[lp.adjoint_offset + i] = vec4f(adj, 1.0);
        l = vec4f(term, d_gain);
    }
    partial[li] = l;
    workgroupBarrier();
    for (var s = 32u; s > 0u; s = s / 2u) {
        if li < s {
            partial[li] += partial[li + s];
        }
        workgroupBarrier();
    }
    // A grid of several rows may end with groups past the last pixel: the partial sums
    // hold one entry per group of 64 pixels.
    if li == 0u && group * 64u < lp.n_pixels {
        loss_partial[lp.partial_offset + group] = partial[0].x;
        let e = 3u * (lp.partial_offset + group);
        exposure_partial[e] = partial[0].y;
        exposure_partial[e + 1u] = partial[0].z;
        exposure_partial[e + 2u] = partial[0].w;
    }
}
