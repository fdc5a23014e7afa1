// Recursive control variate for the primal image (Nicolet et al. 2023), one invocation per
// pixel of one camera, after the two-state primal render:
//   I_t = w (I_{t-1} - H_t) + F_t
// F_t: this iteration's render; H_t: the same paths under the previous iteration's textures
// (an unbiased render of them, correlated with F_t); I_{t-1}: the last iteration's image.
// I_t is unbiased for the current textures whenever w is independent of the pixel's own
// samples, past and present: then E[w (I_{t-1} - H_t)] = E[w] (E[I_{t-1}] - E[H_t]) = 0.
// The variance-optimal per-channel weight is w = Cov(F, H) / (Var(I_{t-1}) + Var(H)). Its
// statistics are exponential moving averages over earlier iterations (means with beta1,
// second moments with beta2, bias-corrected), but a pixel's weight takes them from its 3x3
// neighbours, never from itself: a weight estimated from the pixel's own samples correlates
// with the error its image carries and biases it (measured: chi2/dof 4.4 on 48 block means
// against 1.06 for a constant weight). Var(I) follows from the recursion with the pixel's own
// weights, which depend on the neighbours' samples only.
// Phase 0 forms I_t (it replaces the render in accum, for the loss pass); phase 1, a separate
// dispatch, then updates every pixel's statistics with its F_t and H_t, so that phase 0 of the
// next iteration reads the neighbours' statistics of this one.
#import shared/types

// Mirrored by PrimalCvParams in src/optim/primal.rs.
struct PrimalCvParams {
    n_pixels: u32,
    // Where this camera's pixels start in cv_state (in pixels).
    pixel_offset: u32,
    // Statistics updates done so far (bias correction), and whether w is used yet.
    updates: u32,
    use_weight: u32,
    // Whether H_t exists (false in the first iteration: nothing to update the statistics with).
    have_prev: u32,
    beta1: f32,
    beta2: f32,
    // 0: form the image; 1: update the statistics.
    phase: u32,
    width: u32,
    height: u32,
    // Upper clamp of the weight (cv_max_weight): below 1 it bounds how long a pixel's noise
    // persists in the image, which an optimizer would otherwise fit (see src/optim/primal.rs).
    max_weight: f32,
    _pad0: u32,
}

// Words of state per pixel: vec4s, rgb in xyz.
const CV_IMAGE: u32 = 0u;
const CV_MEAN_F: u32 = 1u;
const CV_MEAN_H: u32 = 2u;
const CV_VAR_F: u32 = 3u;
const CV_VAR_H: u32 = 4u;
const CV_COV: u32 = 5u;
const CV_VAR_IMAGE: u32 = 6u;
const CV_WEIGHT: u32 = 7u;

@group(0) @binding(0) var<uniform> cp: PrimalCvParams;
// F_t (rgb sum, sample count in w) in; I_t (rgb, 1) out.
@group(0) @binding(1) var<storage, read_write> accum: array<vec4f>;
// H_t (rgb sum, sample count in w).
@group(0) @binding(2) var<storage, read> accum_prev: array<vec4f>;
@group(0) @binding(3) var<storage, read_write> cv_state: array<vec4f>;

fn finite_or_zero(v: vec3f) -> vec3f {
    return select(vec3f(0.0), v, abs(v) < vec3f(3.0e38));
}

// The bias-corrected statistics of pixel (x, y): Var(F), Var(H), Cov(F, H).
struct Stats {
    v_f: vec3f,
    v_h: vec3f,
    cov: vec3f,
}

// The mean of the 3x3 neighbours' statistics, the pixel itself excluded.
fn neighbour_stats(x: i32, y: i32) -> Stats {
    var out = Stats(vec3f(0.0), vec3f(0.0), vec3f(0.0));
    var n = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let nx = x + dx;
            let ny = y + dy;
            if (dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= i32(cp.width) || ny >= i32(cp.height) {
                continue;
            }
            let b = (cp.pixel_offset + u32(ny) * cp.width + u32(nx)) * CV_VEC4S;
            out.v_f += cv_state[b + CV_VAR_F].xyz;
            out.v_h += cv_state[b + CV_VAR_H].xyz;
            out.cov += cv_state[b + CV_COV].xyz;
            n += 1.0;
        }
    }
    let c = 1.0 / (max(n, 1.0) * (1.0 - pow(cp.beta2, f32(cp.updates))));
    return Stats(out.v_f * c, out.v_h * c, out.cov * c);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    // Rows of the grid continue the pixel index (src/gpu grid_2d).
    let i = gid.x + gid.y * groups.x * 64u;
    if i >= cp.n_pixels {
        return;
    }
    let a = accum[i];
    let n = max(a.w, 1.0);
    let f = a.xyz / n;
    let h = accum_prev[i].xyz / n;
    let base = (cp.pixel_offset + i) * CV_VEC4S;
    if cp.phase == 0u {
        var image = cv_state[base + CV_IMAGE].xyz;
        var v_image = cv_state[base + CV_VAR_IMAGE].xyz;
        var w = cv_state[base + CV_WEIGHT].xyz;
        if cp.use_weight != 0u {
            let st = neighbour_stats(i32(i % cp.width), i32(i / cp.width));
            // Var(I_{t-1}) from Var(I_{t-2}) and the weight used then.
            v_image = finite_or_zero(w * w * (v_image + st.v_h) + st.v_f - 2.0 * w * st.cov);
            w = clamp(finite_or_zero(st.cov / (st.v_h + v_image)), vec3f(0.0), vec3f(cp.max_weight));
        } else {
            w = vec3f(0.0);
        }
        if cp.have_prev == 0u {
            image = vec3f(0.0);
        }
        image = w * (image - h) + f;
        // The loss pass reads the image as one sample; F and H stay for phase 1.
        cv_state[base + CV_IMAGE] = vec4f(image, 0.0);
        cv_state[base + CV_VAR_IMAGE] = vec4f(v_image, 0.0);
        cv_state[base + CV_WEIGHT] = vec4f(w, 0.0);
        return;
    }
    // Phase 1: Welford-style update of exponential moving moments of (F, H), then the image
    // replaces the render for the loss pass.
    accum[i] = vec4f(cv_state[base + CV_IMAGE].xyz, 1.0);
    if cp.have_prev == 0u {
        return;
    }
    let b1 = cp.beta1;
    let b2 = cp.beta2;
    let k = f32(cp.updates);
    var mean_f = cv_state[base + CV_MEAN_F].xyz;
    var mean_h = cv_state[base + CV_MEAN_H].xyz;
    var df1 = f;
    var dh1 = h;
    if cp.updates > 0u {
        df1 = f - mean_f / (1.0 - pow(b1, k));
        dh1 = h - mean_h / (1.0 - pow(b1, k));
    }
    mean_f = b1 * mean_f + (1.0 - b1) * f;
    mean_h = b1 * mean_h + (1.0 - b1) * h;
    let df2 = f - mean_f / (1.0 - pow(b1, k + 1.0));
    let dh2 = h - mean_h / (1.0 - pow(b1, k + 1.0));
    cv_state[base + CV_MEAN_F] = vec4f(mean_f, 0.0);
    cv_state[base + CV_MEAN_H] = vec4f(mean_h, 0.0);
    cv_state[base + CV_VAR_F] = vec4f(finite_or_zero(b2 * cv_state[base + CV_VAR_F].xyz + (1.0 - b2) * df1 * df2), 0.0);
    cv_state[base + CV_VAR_H] = vec4f(finite_or_zero(b2 * cv_state[base + CV_VAR_H].xyz + (1.0 - b2) * dh1 * dh2), 0.0);
    cv_state[base + CV_COV] = vec4f(finite_or_zero(b2 * cv_state[base + CV_COV].xyz + (1.0 - b2) * df1 * dh2), 0.0);
}
