// Combine pass of the recursive estimator, one invocation per parameter scalar: the running
// estimate d_t = a g_t(θ_t) + (1 - a) (d_{t-1} + g_t(θ_t) - g_t(θ_{t-1})), where g_t(θ) are
// this iteration's samples evaluated at the current and at the previous state
// (recursive_gradient.wgsl). The weight a of the fresh term is fixed (`fixed_weight` >= 0), or
// chosen per scalar by inverse variance from moving variances of the fresh term and of the
// difference tracked up to the previous iteration (so that a does not depend on this
// iteration's samples), with the running estimate's own variance carried along:
//   Var[fresh] = vf, Var[d_{t-1} + difference] = vd + vdl, a = (vd + vdl) / (vf + vd + vdl),
//   Var[d_t] = a^2 vf + (1 - a)^2 (vd + vdl).
// d_t replaces the gradient (`grad`) that the rest of the iteration (priors, step) reads, and
// Var[d_t] is written to `variance` for the variance-scaled step.
#import gen/recursive

// Mirrored by RecursiveCombineParams in src/optim/estimator/recursive/mod.rs.
struct RecursiveCombineParams {
    count: u32,
    // 0: no previous state (d = g, the first iteration or a restart).
    have_prev: u32,
    // a in [0, 1], or negative: by inverse variance.
    fixed_weight: f32,
    // Lower bound of the adaptive a.
    min_weight: f32,
    // Decay of the moving moments.
    beta: f32,
    // 1 - beta^n for the moments of the fresh term and of the difference as they stand
    // (n updates so far; 0 before the first).
    bias_f: f32,
    bias_dl: f32,
    // Updates of the fresh term's moments so far (the adaptive a waits for WARMUP).
    n_f: u32,
}

@group(0) @binding(0) var<uniform> cp: RecursiveCombineParams;
// In: this iteration's samples at θ_t. Out: the running estimate d_t.
@group(0) @binding(1) var<storage, read_write> grad: array<f32>;
// This iteration's samples at θ_{t-1}.
@group(0) @binding(2) var<storage, read> grad_prev: array<f32>;
// The running estimate d, kept across iterations.
@group(0) @binding(3) var<storage, read_write> running: array<f32>;
// Moving first and second moments of the fresh term and of the difference.
@group(0) @binding(4) var<storage, read_write> fresh_mean: array<f32>;
@group(0) @binding(5) var<storage, read_write> fresh_sq: array<f32>;
@group(0) @binding(6) var<storage, read_write> diff_mean: array<f32>;
@group(0) @binding(7) var<storage, read_write> diff_sq: array<f32>;
// Var[d] (the running estimate's tracked variance).
@group(0) @binding(8) var<storage, read_write> variance: array<f32>;

// A variance from moving moments with bias correction b (0: none yet).
fn moving_variance(mean: f32, sq: f32, b: f32) -> f32 {
    if b <= 0.0 {
        return 0.0;
    }
    let m = mean / b;
    return max(sq / b - m * m, 0.0);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let i = gid.x + gid.y * groups.x * 64u;
    if i >= cp.count {
        return;
    }
    let g = clamp(grad[i], -1.0e18, 1.0e18);
    let vf = moving_variance(fresh_mean[i], fresh_sq[i], cp.bias_f);
    var d = g;
    var vd = vf;
    if cp.have_prev != 0u {
        let dl = g - clamp(grad_prev[i], -1.0e18, 1.0e18);
        let vy = variance[i] + moving_variance(diff_mean[i], diff_sq[i], cp.bias_dl);
        var a = cp.fixed_weight;
        if a < 0.0 {
            a = 1.0;
            if cp.n_f >= RECURSIVE_WARMUP && cp.bias_dl > 0.0 && vf + vy > 0.0 {
                a = max(vy / (vf + vy), cp.min_weight);
            }
        }
        d = a * g + (1.0 - a) * (running[i] + dl);
        vd = a * a * vf + (1.0 - a) * (1.0 - a) * vy;
        diff_mean[i] = cp.beta * diff_mean[i] + (1.0 - cp.beta) * dl;
        diff_sq[i] = cp.beta * diff_sq[i] + (1.0 - cp.beta) * dl * dl;
    }
    fresh_mean[i] = cp.beta * fresh_mean[i] + (1.0 - cp.beta) * g;
    fresh_sq[i] = cp.beta * fresh_sq[i] + (1.0 - cp.beta) * g * g;
    running[i] = d;
    variance[i] = vd;
    grad[i] = d;
}
