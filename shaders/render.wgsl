// Primal render: one invocation per pixel, `spp` jittered camera samples each (box filter),
// direct illumination with MIS, accumulated into accum (rgb sum, sample count in w).
#import shared/rng
#import shared/camera
#import shared/integrator

// Keep in sync with RenderParams in src/render/layout.rs.
struct RenderParams {
    camera: CameraInfo,
    seed: u32,
    sample_offset: u32,
    spp: u32,
    techniques: u32,
    stride: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(1) @binding(0) var<uniform> rp: RenderParams;
@group(1) @binding(1) var<storage, read_write> accum: array<vec4f>;
// [0] camera rays, [1] shadow rays, [2] BSDF rays, [3] dropped non-finite samples.
@group(1) @binding(2) var<storage, read_write> stats: array<atomic<u32>, 4>;

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
    techniques = rp.techniques;
    let xy = vec2f(f32(px), f32(py));
    var sum = vec3f(0.0);
    var dropped = 0u;
    for (var s = 0u; s < rp.spp; s++) {
        // The camera-sample index identifies this sample for replay.
        rng_init(rp.seed, (rp.sample_offset + s) * n_pixels + pixel, 0u);
        let d = camera_direction(rp.camera, xy + rand2());
        let l = direct_radiance(rp.camera.origin, d);
        if all(l == l) && all(abs(l) < vec3f(3.0e38)) {
            sum += l;
        } else {
            dropped += 1u;
        }
    }
    accum[pixel] += vec4f(sum, f32(rp.spp));
    atomicAdd(&stats[0], rp.spp);
    atomicAdd(&stats[1], shadow_rays);
    atomicAdd(&stats[2], bsdf_rays);
    if dropped > 0u {
        atomicAdd(&stats[3], dropped);
    }
}
