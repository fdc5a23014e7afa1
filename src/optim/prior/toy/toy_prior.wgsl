// The toy prior's one pass (the registry's test, src/optim/prior/toy): adds the gradient of
// ½ weight (θ − target)² to every parameter scalar θ's.

struct ToyPriorParams {
    n: u32,
    stride: u32,
    target_value: f32,
    weight: f32,
}

@group(0) @binding(0) var<uniform> tp: ToyPriorParams;
@group(0) @binding(1) var<storage, read_write> grad: array<f32>;
@group(0) @binding(2) var<storage, read> params: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let i = id.x + id.y * tp.stride;
    if i >= tp.n {
        return;
    }
    grad[i] += tp.weight * (params[i] - tp.target_value);
}
