// The toy step's one pass (the registry's test, src/optim/step/toy): plain gradient descent,
// each parameter scalar of one optimized texture moved by -lr x its gradient, then clamped
// to the slot's range.

// Mirrored by ToyStepParams in src/optim/step/toy/mod.rs.
struct ToyStepParams {
    offset: u32,
    count: u32,
    lr: f32,
    lo: f32,
    hi: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> tsp: ToyStepParams;
@group(0) @binding(1) var<storage, read> grad: array<f32>;
@group(0) @binding(2) var<storage, read_write> params: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let k = gid.x + gid.y * groups.x * 64u;
    if k >= tsp.count {
        return;
    }
    let i = tsp.offset + k;
    params[i] = clamp(params[i] - tsp.lr * grad[i], tsp.lo, tsp.hi);
}
