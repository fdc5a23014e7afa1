// The toy estimator's one pass (the registry's test, src/optim/estimator/toy): the gradient
// of ½ weight (θ − target)² for every parameter scalar θ, which reads no image.
#import shared/scene

struct ToyParams {
    n: u32,
    stride: u32,
    target_value: f32,
    weight: f32,
}

@group(1) @binding(0) var<uniform> tp: ToyParams;
@group(1) @binding(1) var<storage, read_write> grad: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let i = id.x + id.y * tp.stride;
    if i >= tp.n {
        return;
    }
    grad[i] = tp.weight * (params[i] - tp.target_value);
}
