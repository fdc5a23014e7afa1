// Which optimized texels a camera sample can reach: for every pixel of one camera, strata x
// strata positions spread over the pixel (the gradient passes jitter uniformly over it), the
// camera ray's hit, and the filter footprint of every optimized texture of the hit's material.
// Each texel with a non-zero filter weight is marked. Texels that no sample reaches get no
// gradient and keep their initial values; texture errors are reported over the marked ones.
#import shared/camera
#import shared/bvh
#import shared/surface

// Mirrored by ObservedParams in src/optim/observed.rs.
struct ObservedParams {
    camera: CameraInfo,
    strata: u32,
    stride: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(1) @binding(0) var<uniform> op: ObservedParams;
// One word per texel of all optimized textures (ParamTex.texel_offset order); 1 = observed.
@group(1) @binding(1) var<storage, read_write> observed: array<atomic<u32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let xy = tile_pixel(id.x + id.y * op.stride, op.camera.width, op.camera.height);
    if xy.x == NONE {
        return;
    }
    let n = op.strata;
    for (var s = 0u; s < n * n; s++) {
        let offset = (vec2f(f32(s % n), f32(s / n)) + 0.5) / f32(n);
        let d = camera_direction(op.camera, vec2f(xy) + offset);
        let hit = trace_closest(op.camera.origin, d, 3.0e38);
        if hit.tri == NONE {
            continue;
        }
        let sf = surface_at(op.camera.origin, hit);
        if !sf.valid {
            continue;
        }
        let m = materials[sf.material];
        for (var slot = 0u; slot < SLOTS; slot++) {
            let pi = material_param(m, slot);
            if pi == NONE {
                continue;
            }
            let p = param_textures[pi];
            let fp = param_footprint(p, sf.uv);
            for (var k = 0u; k < 4u; k++) {
                if fp.weight[k] > 0.0 {
                    atomicOr(&observed[p.texel_offset + fp.texel[k]], 1u);
                }
            }
        }
    }
}
