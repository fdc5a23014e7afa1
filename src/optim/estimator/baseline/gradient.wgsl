// Baseline gradient pass: every camera sample differentiates its light-sampled and
// BSDF-sampled contributions with respect to the material inputs at its hit point (and, with
// indirect light, at every later vertex of its path: path replay, shared/integrator.wgsl),
// weights them by the adjoint of its pixel, and adds the result into the texels that the
// filter touches (the parameter-space estimator of docs/method.md), by
// shared/gradient_scatter.wgsl. Float additions use a bounded compare-and-swap loop on
// 32-bit atomics; an update that exhausts the bound is
// counted (GRADIENT_STAT_LOST), never silently lost.
#import shared/rng
#import shared/camera
#import shared/adjoint_pixel
#import shared/integrator
#import shared/gradient_scatter
#import shared/env_gradient

// Mirrored by GradientParams in src/optim/estimator/baseline/mod.rs.
struct GradientParams {
    camera: CameraInfo,
    seed: u32,
    sample_offset: u32,
    spp: u32,
    techniques: u32,
    stride: u32,
    // 1 / (gradient samples per pixel of the whole estimate).
    inv_spp: f32,
    // Where this camera's pixels start in adjoint[].
    adjoint_offset: u32,
    _pad1: u32,
}

@group(1) @binding(0) var<uniform> gp: GradientParams;
// dL/dI per pixel (rgb), all cameras.
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
// Gradient per parameter scalar (f32 bits), laid out like params[].
@group(1) @binding(2) var<storage, read_write> grad: array<atomic<u32>>;
// [0] samples, [1] lost updates (CAS bound exhausted), [2] dropped non-finite values.
@group(1) @binding(3) var<storage, read_write> gstats: array<atomic<u32>, 4>;
// dL/d(environment radiance) and its counters (shared/env_gradient.wgsl).
@group(1) @binding(4) var<storage, read_write> env_grad: array<atomic<u32>>;

// The adjoint of the pixel whose sample is being differentiated.
var<private> pixel_adj: vec3f;

// A later vertex of the path (shared/integrator.wgsl, camera_path with replay).
fn differentiate_later_vertex(sf: Surface, wi: vec3f, mat: SurfaceMaterial, mat_prev: SurfaceMaterial, weight: vec3f, weight_prev: vec3f) {
    scatter(materials[sf.material], sf.uv, surface_brdf_grad(sf, mat, wi, false), weight, pixel_adj);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u, @builtin(local_invocation_index) lid: u32) {
    env_local_begin(lid, true);
    differentiate_pixel(id);
    env_local_flush(lid, true);
}

// The gradient samples of invocation id's pixel.
fn differentiate_pixel(id: vec3u) {
    let a = adjoint_pixel(id.x + id.y * gp.stride, gp.camera, gp.adjoint_offset, gp.inv_spp);
    if a.pixel == NONE {
        return;
    }
    light_base = gp.camera.light_base;
    pixel_adj = a.adj;
    env_adj = a.adj;
    for (var s = 0u; s < gp.spp; s++) {
        rng_init(gp.seed, (gp.sample_offset + s) * a.n_pixels + a.pixel, 0u);
        let d = camera_direction(gp.camera, a.xy + rand2());
        var po = path_options();
        po.replay = true;
        po.techniques = gp.techniques;
        po.env_gradients = scene.env_optimized != 0u;
        let g = gradient_sample(gp.camera.origin, d, po);
        if !g.valid {
            continue;
        }
        for (var t = 0u; t < 2u; t++) {
            let ts = technique_sample(g, t);
            scatter(g.m, g.sf.uv, ts.grad, ts.ds.radiance * ts.ds.scale, a.adj);
        }
    }
    atomicAdd(&gstats[GRADIENT_STAT_SAMPLES], gp.spp);
    if scatter_lost > 0u {
        atomicAdd(&gstats[GRADIENT_STAT_LOST], scatter_lost);
    }
    if scatter_dropped > 0u {
        atomicAdd(&gstats[GRADIENT_STAT_DROPPED], scatter_dropped);
    }
}
