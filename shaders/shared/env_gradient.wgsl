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
// Every pixel may add to the same few texels, so a workgroup first sums its invocations'
// derivatives in workgroup memory (env_local: an environment of up to ENV_LOCAL_TEXELS
// texels), then adds each non-zero sum to env_grad once (env_local_flush): the additions
// that meet on one word of env_grad are one per workgroup, however large the image. Each
// float addition is a compare-and-swap loop; an attempt fails only when another addition to
// the same word succeeded in between, so a bound above the additions that can meet on one
// word (the workgroup's invocations' in workgroup memory, the workgroups' in env_grad) loses
// none. A larger environment adds to env_grad directly, with the same bound.

var<private> env_adj: vec3f;

// Texels of the largest environment that a workgroup sums in workgroup memory (6 KiB: the
// default 32 x 16 map; a GPU keeps as many workgroups resident as without it).
const ENV_LOCAL_TEXELS: u32 = 512u;
const ENV_LOCAL_WORDS: u32 = 3u * ENV_LOCAL_TEXELS;
// Tries of an addition's compare-and-swap loop: more than the additions that can meet on one
// word in one dispatch (65535 x 65535 workgroups could not run at once on any device).
const ENV_CAS_BOUND: u32 = 1048576u;

var<workgroup> env_local: array<atomic<u32>, ENV_LOCAL_WORDS>;
// Whether this dispatch sums the environment's derivatives in workgroup memory (set by
// env_local_begin; the same in every invocation).
var<private> env_local_on: bool = false;

// Add v to word i of the workgroup's sums (f32 bits in atomics); false when the bound ran
// out. env_cas_add_global is the same on env_grad: WGSL takes no pointer to workgroup or
// storage memory as an argument, so each array has its own.
fn env_cas_add_local(i: u32, v: f32) -> bool {
    var old = atomicLoad(&env_local[i]);
    for (var k = 0u; k < ENV_CAS_BOUND; k++) {
        let r = atomicCompareExchangeWeak(&env_local[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            return true;
        }
        old = r.old_value;
    }
    return false;
}

fn env_cas_add_global(i: u32, v: f32) -> bool {
    var old = atomicLoad(&env_grad[i]);
    for (var k = 0u; k < ENV_CAS_BOUND; k++) {
        let r = atomicCompareExchangeWeak(&env_grad[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            return true;
        }
        old = r.old_value;
    }
    return false;
}

fn env_words() -> u32 {
    return 3u * scene.env_width * scene.env_height;
}

// Whether a dispatch whose pass adds to the environment's derivative (`on`, from uniforms
// only) sums it in workgroup memory: the environment is optimized and fits.
fn env_local_use(on: bool) -> bool {
    return on && scene.env_optimized != 0u && env_words() <= ENV_LOCAL_WORDS;
}

// Called first by every invocation of a pass that differentiates the environment, with the
// pass's condition for adding to it in this dispatch (from uniforms only, so that every
// invocation of the workgroup meets the barrier): clears the workgroup's sums.
fn env_local_begin(lid: u32, on: bool) {
    env_local_on = env_local_use(on);
    if env_local_use(on) {
        for (var w = lid; w < ENV_LOCAL_WORDS; w += 64u) {
            atomicStore(&env_local[w], 0u);
        }
        workgroupBarrier();
    }
}

// Called last by every invocation (no early return before it), with the same condition:
// adds the workgroup's sums into env_grad.
fn env_local_flush(lid: u32, on: bool) {
    if env_local_use(on) {
        workgroupBarrier();
        let n = env_words();
        var lost = 0u;
        for (var w = lid; w < n; w += 64u) {
            let v = bitcast<f32>(atomicLoad(&env_local[w]));
            if v != 0.0 && !env_cas_add_global(w, v) {
                lost += 1u;
            }
        }
        if lost > 0u {
            atomicAdd(&env_grad[n], lost);
        }
    }
}

fn env_grad_add(i: u32, v: f32) {
    if v == 0.0 {
        return;
    }
    let counters = env_words();
    if !(abs(v) < 3.0e38) {
        atomicAdd(&env_grad[counters + 1u], 1u);
        return;
    }
    var added = false;
    if env_local_on {
        added = env_cas_add_local(i, v);
    } else {
        added = env_cas_add_global(i, v);
    }
    if !added {
        atomicAdd(&env_grad[counters], 1u);
    }
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
