// Variance-scaled step for one optimized texture, then clamping to the valid range: with
// z = d / (sqrt(Var[d]) + eps), each scalar moves by -lr * clamp(shrink(z), -clip, clip),
// where shrink(z) = sign(z) max(|z| - threshold, 0) keeps only the part of the estimate that
// exceeds its noise (threshold 0: -lr d / sqrt(Var[d]), clipped); no first moment.
// Var[d] is the estimator's own tracked variance of its estimate d where it has one
// (own_variance, the recursive estimator's), otherwise a moving variance of the gradient
// kept in the moment buffers (moment1: mean, moment2: second moment, decay beta), times
// variance_scale where successive estimates share samples (ReSTIR's kept paths): the moving
// moments of a correlated series see a fraction of one estimate's spread. A surer
// estimate (higher d / sqrt(Var[d])) takes a larger step, up to clip x lr; a pure-noise one
// moves by lr times a standard normal shrunk by the threshold, so that a texel the images
// hardly determine does not drift with errors that a running estimate repeats. Non-finite gradients leave their parameter
// unchanged and are counted; with mask, an entry whose gradient is exactly zero keeps its
// value and moments. With the moment filter (src/optim/step/moment_filter.rs) the step takes two
// dispatches around it: phase STEP_PHASE_PAIR writes (d, Var[d]) to the pair the filter
// smooths (entries from 0 for each texture; an entry without a gradient of its own gives d =
// 0 and its variance as it stands), phase STEP_PHASE_FILTERED steps with
// d = a x own d + (1 - a) x filtered d, a = own_weight, of variance a^2 x own Var[d] +
// (1 - a)^2 x the filtered mean's variance (the filter propagates the variance of its
// weighted mean; both as if independent, which the levels of the filter are not, so this is
// a lower bound and the steps are somewhat bold).
#import gen/abi

// Mirrored by VarianceStepParams in src/optim/step/variance_step/mod.rs.
struct VarianceStepParams {
    offset: u32,
    count: u32,
    lr: f32,
    clip: f32,
    beta: f32,
    eps: f32,
    // 1 - beta^t for the step t (from 1).
    bias: f32,
    own_variance: u32,
    lo: f32,
    hi: f32,
    mask: u32,
    threshold: f32,
    // STEP_PHASE_FUSED, STEP_PHASE_PAIR or STEP_PHASE_FILTERED.
    phase: u32,
    // Phase STEP_PHASE_FILTERED: weight of the entry's own pair against the filtered one.
    own_weight: f32,
    // The moving variance's factor for correlated successive estimates (variance_scale in
    // variance_step.rs; 1 for independent ones).
    variance_scale: f32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> vp: VarianceStepParams;
@group(0) @binding(1) var<storage, read> grad: array<f32>;
@group(0) @binding(2) var<storage, read_write> params: array<f32>;
@group(0) @binding(3) var<storage, read_write> moment1: array<f32>;
@group(0) @binding(4) var<storage, read_write> moment2: array<f32>;
@group(0) @binding(5) var<storage, read> variance: array<f32>;
@group(0) @binding(6) var<storage, read_write> step_stats: array<atomic<u32>, 4>;
// The moment filter's pair (a small unused buffer in phase STEP_PHASE_FUSED).
@group(0) @binding(7) var<storage, read_write> pair_first: array<f32>;
@group(0) @binding(8) var<storage, read_write> pair_second: array<f32>;

// Move entry i by estimate d of variance var_d.
fn variance_step(i: u32, d: f32, var_d: f32) {
    let z = d / (sqrt(var_d) + vp.eps);
    let shrunk = sign(z) * max(abs(z) - vp.threshold, 0.0);
    let step = clamp(shrunk, -vp.clip, vp.clip);
    params[i] = clamp(params[i] - vp.lr * step, vp.lo, vp.hi);
}

// Entry i's variance as it stands (no gradient this iteration), for the filter's pair.
fn standing_variance(i: u32) -> f32 {
    if vp.own_variance != 0u {
        return variance[i];
    }
    let mean = moment1[i] / vp.bias;
    return max(moment2[i] / vp.bias - mean * mean, 0.0) * vp.variance_scale;
}

// In phase STEP_PHASE_PAIR, hand entry k's estimate and variance to the filter.
fn write_pair(k: u32, d: f32, var_d: f32) {
    if vp.phase == STEP_PHASE_PAIR {
        pair_first[k] = d;
        pair_second[k] = var_d;
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let k = gid.x + gid.y * groups.x * 64u;
    if k >= vp.count {
        return;
    }
    let i = vp.offset + k;
    let g_in = grad[i];
    if vp.phase == STEP_PHASE_FILTERED {
        // The pair phase updated the moving moments already: the variance as it stands is
        // this iteration's; an entry without a gradient of its own has d = 0.
        let skipped = !(abs(g_in) < 3.0e38) || (vp.mask != 0u && g_in == 0.0);
        let own_d = select(clamp(g_in, -1.0e18, 1.0e18), 0.0, skipped);
        let a = vp.own_weight;
        let d = a * own_d + (1.0 - a) * pair_first[k];
        let var_d = a * a * standing_variance(i) + (1.0 - a) * (1.0 - a) * pair_second[k];
        variance_step(i, d, var_d);
        return;
    }
    if vp.mask != 0u && g_in == 0.0 {
        write_pair(k, 0.0, standing_variance(i));
        return;
    }
    if !(abs(g_in) < 3.0e38) {
        atomicAdd(&step_stats[STEP_STAT_SKIPPED], 1u);
        write_pair(k, 0.0, standing_variance(i));
        return;
    }
    let g = clamp(g_in, -1.0e18, 1.0e18);
    var var_d = 0.0;
    if vp.own_variance != 0u {
        var_d = variance[i];
    } else {
        let m = vp.beta * moment1[i] + (1.0 - vp.beta) * g;
        let v = vp.beta * moment2[i] + (1.0 - vp.beta) * g * g;
        moment1[i] = m;
        moment2[i] = v;
        let mean = m / vp.bias;
        var_d = max(v / vp.bias - mean * mean, 0.0) * vp.variance_scale;
    }
    if vp.phase == STEP_PHASE_PAIR {
        write_pair(k, g, var_d);
        return;
    }
    variance_step(i, g, var_d);
}
