// The environment's derivative, for the gradient passes that declare
// `env_grad: array<atomic<u32>>` (f32 bits: dL/d(radiance) per texel and channel, laid out
// like the environment's texels, then two counters: updates lost to the compare-and-swap
// bound, values dropped as not finite). camera_path calls differentiate_env for every path
// segment that escapes to the environment (the camera ray, a BSDF sample, a light sample of
// the environment) with the factor its radiance is multiplied by on the way to the pixel
// (throughput x MIS weight / density); the pass sets env_adj to the pixel's adjoint. The
// derivative goes to the texels the lookup read, with its weights (env_footprint in
// shared/lights.wgsl: the nearest texel, or four bilinearly). Plain Monte Carlo in every
// estimator: no reservoir holds the environment's texels.

var<private> env_adj: vec3f;

fn env_grad_add(i: u32, v: f32) {
    if v == 0.0 {
        return;
    }
    let counters = 3u * scene.env_width * scene.env_height;
    if !(abs(v) < 3.0e38) {
        atomicAdd(&env_grad[counters + 1u], 1u);
        return;
    }
    var old = atomicLoad(&env_grad[i]);
    for (var k = 0u; k < 256u; k++) {
        let r = atomicCompareExchangeWeak(&env_grad[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            return;
        }
        old = r.old_value;
    }
    atomicAdd(&env_grad[counters], 1u);
}

fn differentiate_env(d: vec3f, weight: vec3f) {
    let fp = env_footprint(d);
    let g = env_adj * weight * scene.env_scale;
    for (var j = 0u; j < 4u; j++) {
        if fp.weight[j] != 0.0 {
            let k = 3u * fp.texel[j];
            for (var c = 0u; c < 3u; c++) {
                env_grad_add(k + c, fp.weight[j] * g[c]);
            }
        }
    }
}
