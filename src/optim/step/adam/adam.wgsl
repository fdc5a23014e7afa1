// Adam step for one optimized texture, then clamping to the valid range. Non-finite
// gradients leave their parameter unchanged and are counted; huge ones are clamped. With
// mask set (sparse Adam, Mitsuba 3's mask_updates), an entry whose gradient is exactly zero
// keeps its value and moments. With the moment filter (src/optim/step/moment_filter.rs) the step
// takes two dispatches around it: phase STEP_PHASE_PAIR updates the moments and writes them to
// the pair the filter smooths (entries from 0 for each texture), phase STEP_PHASE_FILTERED
// steps from own_weight x the entry's own moments + (1 - own_weight) x the filtered ones
// (every entry: a texel with no gradient of its own, masked or not, moves with its
// neighbours' moments), and with write_back keeps that mix as its moments.
#import gen/abi

// Mirrored by AdamParams in src/optim/step/adam/mod.rs.
struct AdamParams {
    offset: u32,
    count: u32,
    lr: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    // 1 - beta1^t and 1 - beta2^t for the step t (from 1).
    bias1: f32,
    bias2: f32,
    lo: f32,
    hi: f32,
    mask: u32,
    // STEP_PHASE_FUSED, STEP_PHASE_PAIR or STEP_PHASE_FILTERED.
    phase: u32,
    // Phase STEP_PHASE_FILTERED: weight of the entry's own moments against the filtered ones.
    own_weight: f32,
    // Phase STEP_PHASE_FILTERED: nonzero: the mix replaces the moments.
    write_back: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> ap: AdamParams;
@group(0) @binding(1) var<storage, read> grad: array<f32>;
@group(0) @binding(2) var<storage, read_write> params: array<f32>;
@group(0) @binding(3) var<storage, read_write> moment1: array<f32>;
@group(0) @binding(4) var<storage, read_write> moment2: array<f32>;
@group(0) @binding(5) var<storage, read_write> step_stats: array<atomic<u32>, 4>;
// The moment filter's pair (a small unused buffer in phase STEP_PHASE_FUSED).
@group(0) @binding(6) var<storage, read_write> pair_first: array<f32>;
@group(0) @binding(7) var<storage, read_write> pair_second: array<f32>;

// Adam's update of entry i by first and second moments m and v.
fn adam_step(i: u32, m: f32, v: f32) {
    let step = ap.lr * (m / ap.bias1) / (sqrt(v / ap.bias2) + ap.eps);
    params[i] = clamp(params[i] - step, ap.lo, ap.hi);
}

// In phase STEP_PHASE_PAIR, hand entry k's moments to the filter.
fn write_pair(k: u32, m: f32, v: f32) {
    if ap.phase == STEP_PHASE_PAIR {
        pair_first[k] = m;
        pair_second[k] = v;
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    // Rows of the grid continue the entry index (src/gpu grid_2d: past the device's
    // workgroups per dimension the grid has several rows).
    let k = gid.x + gid.y * groups.x * 64u;
    if k >= ap.count {
        return;
    }
    let i = ap.offset + k;
    if ap.phase == STEP_PHASE_FILTERED {
        let a = ap.own_weight;
        let m = a * moment1[i] + (1.0 - a) * pair_first[k];
        let v = a * moment2[i] + (1.0 - a) * pair_second[k];
        if ap.write_back != 0u {
            moment1[i] = m;
            moment2[i] = v;
        }
        adam_step(i, m, v);
        return;
    }
    let g_in = grad[i];
    if ap.mask != 0u && g_in == 0.0 {
        write_pair(k, moment1[i], moment2[i]);
        return;
    }
    if !(abs(g_in) < 3.0e38) {
        atomicAdd(&step_stats[STEP_STAT_SKIPPED], 1u);
        write_pair(k, moment1[i], moment2[i]);
        return;
    }
    // Beyond 1e18, g * g would overflow the second moment to infinity (a finite but huge
    // sample does this). Adam's step hardly depends on the gradient's scale, so clamping
    // there keeps the moments finite at no cost to ordinary gradients.
    let g = clamp(g_in, -1.0e18, 1.0e18);
    let m = ap.beta1 * moment1[i] + (1.0 - ap.beta1) * g;
    let v = ap.beta2 * moment2[i] + (1.0 - ap.beta2) * g * g;
    moment1[i] = m;
    moment2[i] = v;
    if ap.phase == STEP_PHASE_PAIR {
        write_pair(k, m, v);
        return;
    }
    adam_step(i, m, v);
}
