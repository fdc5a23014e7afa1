// Adam step for one optimized texture, then clamping to the valid range. Non-finite
// gradients leave their parameter unchanged and are counted; huge ones are clamped. With
// mask set (sparse Adam, Mitsuba 3's mask_updates), an entry whose gradient is exactly zero
// keeps its value and moments.
#import gen/abi

// Mirrored by AdamParams in src/optim/adam.rs.
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
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> ap: AdamParams;
@group(0) @binding(1) var<storage, read> grad: array<f32>;
@group(0) @binding(2) var<storage, read_write> params: array<f32>;
@group(0) @binding(3) var<storage, read_write> moment1: array<f32>;
@group(0) @binding(4) var<storage, read_write> moment2: array<f32>;
@group(0) @binding(5) var<storage, read_write> adam_stats: array<atomic<u32>, 4>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    // Rows of the grid continue the entry index (src/gpu grid_2d: past the device's
    // workgroups per dimension the grid has several rows).
    let k = gid.x + gid.y * groups.x * 64u;
    if k >= ap.count {
        return;
    }
    let i = ap.offset + k;
    let g_in = grad[i];
    if ap.mask != 0u && g_in == 0.0 {
        return;
    }
    if !(abs(g_in) < 3.0e38) {
        atomicAdd(&adam_stats[ADAM_STAT_SKIPPED], 1u);
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
    let step = ap.lr * (m / ap.bias1) / (sqrt(v / ap.bias2) + ap.eps);
    params[i] = clamp(params[i] - step, ap.lo, ap.hi);
}
