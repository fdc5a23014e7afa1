// Gradient pass of the recursive estimator: every camera sample is drawn once, at the current
// textures and adjoint, and differentiated twice: under the current state (textures[t],
// adjoint[t]) into `grad`, and under the previous one (textures[t-1], adjoint[t-1]) into
// `grad_prev`. Both use the same hit, light and BSDF samples and the same MIS weight over
// density (the current state's), so the two sums are unbiased estimates of the gradient at
// each state and their difference is small where the states are close. No ray is traced for
// the previous state. recursive_combine.wgsl turns the two sums into the running estimate.
// Float additions are bounded compare-and-swap loops; an exhausted bound is counted.
#import shared/rng
#import shared/camera
#import shared/integrator
#import shared/env_gradient
#import gen/recursive

// Mirrored by RecursiveGradientParams in src/optim/estimator/recursive/mod.rs.
struct RecursiveGradientParams {
    camera: CameraInfo,
    seed: u32,
    spp: u32,
    stride: u32,
    // 1 / (gradient samples per pixel).
    inv_spp: f32,
    // Where this camera's pixels start in adjoint[] and adjoint_prev[].
    adjoint_offset: u32,
    // 0: the previous state is not known (the first iteration): grad_prev is left alone.
    have_prev: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(1) @binding(0) var<uniform> rp: RecursiveGradientParams;
// dL/dI per pixel (rgb) of this iteration and of the previous one, all cameras.
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
@group(1) @binding(2) var<storage, read> adjoint_prev: array<vec4f>;
// Sums per parameter scalar (f32 bits), laid out like params[].
@group(1) @binding(3) var<storage, read_write> grad: array<atomic<u32>>;
@group(1) @binding(4) var<storage, read_write> grad_prev: array<atomic<u32>>;
@group(1) @binding(5) var<storage, read_write> rstats: array<atomic<u32>, 4>;
// dL/d(environment radiance) under the current state, plain Monte Carlo
// (shared/env_gradient.wgsl): the environment has no running estimate here.
@group(1) @binding(6) var<storage, read_write> env_grad: array<atomic<u32>>;

const CAS_BOUND: u32 = 256u;

var<private> lost_updates: u32 = 0u;
var<private> dropped_values: u32 = 0u;

// The value to add, or 0 (counted) when it is not finite.
fn finite_or_dropped(v: f32) -> f32 {
    if abs(v) < 3.0e38 {
        return v;
    }
    dropped_values += 1u;
    return 0.0;
}

fn add_grad(i: u32, v: f32) {
    if v == 0.0 {
        return;
    }
    var old = atomicLoad(&grad[i]);
    for (var k = 0u; k < CAS_BOUND; k++) {
        let r = atomicCompareExchangeWeak(&grad[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            return;
        }
        old = r.old_value;
    }
    lost_updates += 1u;
}

fn add_grad_prev(i: u32, v: f32) {
    if v == 0.0 {
        return;
    }
    var old = atomicLoad(&grad_prev[i]);
    for (var k = 0u; k < CAS_BOUND; k++) {
        let r = atomicCompareExchangeWeak(&grad_prev[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            return;
        }
        old = r.old_value;
    }
    lost_updates += 1u;
}

// Scatter one technique's contribution (radiance x MIS weight / density = weight) under both
// states: its BRDF derivative at the current material `bg` with the current adjoint, and at
// the previous material `bg_prev` with the previous adjoint and `weight_prev` (the radiance
// that the path's further vertices bring back under the previous textures; weight at depth 1).
fn scatter2(m: Material, uv: vec2f, bg: BrdfGrad, bg_prev: BrdfGrad, weight: vec3f, weight_prev: vec3f, adj: vec3f, adj_prev: vec3f) {
    if all(weight == vec3f(0.0)) && all(weight_prev == vec3f(0.0)) {
        return;
    }
    for (var slot = 0u; slot < SLOTS; slot++) {
        let pi = material_param(m, slot);
        if pi == NONE {
            continue;
        }
        let p = param_textures[pi];
        let fp = param_footprint(p, uv);
        let g = slot_derivative(slot, bg, weight, adj);
        let gp = slot_derivative(slot, bg_prev, weight_prev, adj_prev);
        for (var k = 0u; k < 4u; k++) {
            if fp.weight[k] != 0.0 {
                let base = p.offset + fp.texel[k] * p.channels;
                for (var c = 0u; c < p.channels; c++) {
                    add_grad(base + c, finite_or_dropped(fp.weight[k] * g[c]));
                    if rp.have_prev != 0u {
                        add_grad_prev(base + c, finite_or_dropped(fp.weight[k] * gp[c]));
                    }
                }
            }
        }
    }
}

// The current and previous adjoints of the pixel whose sample is being differentiated.
var<private> pixel_adj: vec3f;
var<private> pixel_adj_prev: vec3f;

// A later vertex of the path (shared/integrator.wgsl, camera_path with replay), under both
// states.
fn differentiate_later_vertex(sf: Surface, wi: vec3f, mat: SurfaceMaterial, mat_prev: SurfaceMaterial, weight: vec3f, weight_prev: vec3f) {
    let bg = surface_brdf_grad(sf, mat, wi, false);
    var bg_prev = bg;
    if rp.have_prev != 0u {
        bg_prev = surface_brdf_grad(sf, mat_prev, wi, true);
    }
    scatter2(materials[sf.material], sf.uv, bg, bg_prev, weight, weight_prev, pixel_adj, pixel_adj_prev);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u, @builtin(local_invocation_index) lid: u32) {
    env_local_begin(lid, true);
    differentiate_pixel(id);
    env_local_flush(lid, true);
}

// The gradient samples of invocation id's pixel, under both states.
fn differentiate_pixel(id: vec3u) {
    let xy = tile_pixel(id.x + id.y * rp.stride, rp.camera.width, rp.camera.height);
    if xy.x == NONE {
        return;
    }
    let n_pixels = rp.camera.width * rp.camera.height;
    let pixel = xy.y * rp.camera.width + xy.x;
    let adj = adjoint[rp.adjoint_offset + pixel].xyz * rp.inv_spp;
    var adj_prev = vec3f(0.0);
    if rp.have_prev != 0u {
        adj_prev = adjoint_prev[rp.adjoint_offset + pixel].xyz * rp.inv_spp;
    }
    if all(adj == vec3f(0.0)) && all(adj_prev == vec3f(0.0)) {
        return;
    }
    light_base = rp.camera.light_base;
    pixel_adj = adj;
    pixel_adj_prev = adj_prev;
    env_adj = adj;
    for (var s = 0u; s < rp.spp; s++) {
        // The same random numbers as the baseline's sample s of this pixel.
        rng_init(rp.seed, s * n_pixels + pixel, 0u);
        let d = camera_direction(rp.camera, vec2f(xy) + rand2());
        var po = path_options();
        po.both = rp.have_prev != 0u;
        po.replay = true;
        po.env_gradients = scene.env_optimized != 0u;
        let g = gradient_sample(rp.camera.origin, d, po);
        if !g.valid {
            continue;
        }
        for (var t = 0u; t < 2u; t++) {
            let ts = technique_sample(g, t);
            var grad_prev = ts.grad;
            if rp.have_prev != 0u {
                // The same path under the previous textures, with the glTF inputs it kept
                // (and, with an optimized normal map, the previous normal's frame).
                use_prev_params = true;
                grad_prev = vertex_grad(g.sf, ts.vertex, false);
                use_prev_params = false;
                if g.m.param_normal != NONE {
                    grad_prev = surface_brdf_grad(g.sf, material_at(g.sf, true), ts.ds.wi, true);
                }
            }
            scatter2(g.m, g.sf.uv, ts.grad, grad_prev, ts.ds.radiance * ts.ds.scale, ts.radiance_prev * ts.ds.scale, adj, adj_prev);
        }
    }
    atomicAdd(&rstats[RECURSIVE_STAT_SAMPLES], rp.spp);
    if lost_updates > 0u {
        atomicAdd(&rstats[RECURSIVE_STAT_LOST], lost_updates);
    }
    if dropped_values > 0u {
        atomicAdd(&rstats[RECURSIVE_STAT_DROPPED], dropped_values);
    }
}
