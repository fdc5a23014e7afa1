// Primal render: one invocation per pixel, `spp` jittered camera samples each (box filter),
// direct illumination with MIS, accumulated into accum (rgb sum, sample count in w).
// With two_states set, every sample is also evaluated under the previous iteration's
// textures (the same path: the same hit, light sample, BSDF direction and MIS weights, the
// BRDF of the other textures; no extra ray) and accumulated into accum_prev: the correlated
// render that the control-variate primal (primal_cv.wgsl) needs.
#import shared/rng
#import shared/camera
#import shared/integrator

// Mirrored by GpuRenderParams in src/render/layout.rs.
struct RenderParams {
    camera: CameraInfo,
    seed: u32,
    sample_offset: u32,
    spp: u32,
    techniques: u32,
    stride: u32,
    two_states: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(1) @binding(0) var<uniform> rp: RenderParams;
@group(1) @binding(1) var<storage, read_write> accum: array<vec4f>;
// [0] camera rays, [1] shadow rays, [2] BSDF rays, [3] dropped non-finite samples.
@group(1) @binding(2) var<storage, read_write> stats: array<atomic<u32>, 4>;
// The same samples under the previous textures (rgb sum), when two_states is set.
@group(1) @binding(3) var<storage, read_write> accum_prev: array<vec4f>;

// The hook camera_path names for the derivatives at a path's later vertices: a render never
// replays a path, so it is never called here.
fn differentiate_later_vertex(sf: Surface, wi: vec3f, mat: SurfaceMaterial, mat_prev: SurfaceMaterial, weight: vec3f, weight_prev: vec3f) {}
// The hook for the environment's derivative: a render leaves env_gradients off.
fn differentiate_env(d: vec3f, weight: vec3f) {}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let width = rp.camera.width;
    let n_pixels = width * rp.camera.height;
    let xy_px = tile_pixel(id.x + id.y * rp.stride, width, rp.camera.height);
    if xy_px.x == NONE {
        return;
    }
    let px = xy_px.x;
    let py = xy_px.y;
    let pixel = py * width + px;
    light_base = rp.camera.light_base;
    let xy = vec2f(f32(px), f32(py));
    var sum = vec3f(0.0);
    var sum_prev = vec3f(0.0);
    var dropped = 0u;
    for (var s = 0u; s < rp.spp; s++) {
        // The camera-sample index identifies this sample.
        rng_init(rp.seed, (rp.sample_offset + s) * n_pixels + pixel, 0u);
        let d = camera_direction(rp.camera, xy + rand2());
        var po = path_options();
        po.both = rp.two_states != 0u;
        po.techniques = rp.techniques;
        let l = radiance_states(rp.camera.origin, d, po);
        if all(l[0] == l[0]) && all(abs(l[0]) < vec3f(3.0e38)) && all(l[1] == l[1]) && all(abs(l[1]) < vec3f(3.0e38)) {
            sum += l[0];
            sum_prev += l[1];
        } else {
            dropped += 1u;
        }
    }
    accum[pixel] += vec4f(sum, f32(rp.spp));
    if rp.two_states != 0u {
        accum_prev[pixel] += vec4f(sum_prev, f32(rp.spp));
    }
    atomicAdd(&stats[RENDER_STAT_CAMERA_RAYS], rp.spp);
    atomicAdd(&stats[RENDER_STAT_SHADOW_RAYS], shadow_rays);
    atomicAdd(&stats[RENDER_STAT_BSDF_RAYS], bsdf_rays);
    if dropped > 0u {
        atomicAdd(&stats[RENDER_STAT_DROPPED], dropped);
    }
}
