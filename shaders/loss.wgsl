// Image loss and its adjoint dL/dI for one camera, from the primal render's accumulated
// samples. The total loss is the mean over all cameras, pixels and channels; partial sums per
// workgroup go to loss_partial[camera_slot * n_groups + group].
#import shared/types

// Keep in sync with GpuLossParams in src/render/layout.rs.
struct LossParams {
    n_pixels: u32,
    // 0: L2, 1: relMSE.
    kind: u32,
    // 1 / (pixels x channels x cameras).
    norm: f32,
    partial_offset: u32,
    // Where this camera's pixels start in adjoint[].
    adjoint_offset: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

const REL_EPS: f32 = 0.01;

@group(0) @binding(0) var<uniform> lp: LossParams;
@group(0) @binding(1) var<storage, read> accum: array<vec4f>;
@group(0) @binding(2) var<storage, read> target_image: array<vec4f>;
@group(0) @binding(3) var<storage, read_write> adjoint: array<vec4f>;
@group(0) @binding(4) var<storage, read_write> loss_partial: array<f32>;
// [0] pixels whose loss or adjoint was not finite (left out of both).
@group(0) @binding(5) var<storage, read_write> loss_stats: array<atomic<u32>, 4>;

var<workgroup> partial: array<f32, 64>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(local_invocation_index) li: u32, @builtin(workgroup_id) wg: vec3u) {
    let i = gid.x;
    var l = 0.0;
    if i < lp.n_pixels {
        let a = accum[i];
        let img = a.xyz / max(a.w, 1.0);
        let g = target_image[i].xyz;
        let diff = img - g;
        var w = vec3f(1.0);
        if lp.kind == 1u {
            w = 1.0 / (g * g + vec3f(REL_EPS));
        }
        var adj = 2.0 * diff * w * lp.norm;
        var term = dot(diff * diff, w) * lp.norm;
        if !(all(abs(adj) < vec3f(3.0e38)) && abs(term) < 3.0e38) {
            adj = vec3f(0.0);
            term = 0.0;
            atomicAdd(&loss_stats[0], 1u);
        }
        adjoint[lp.adjoint_offset + i] = vec4f(adj, 0.0);
        l = term;
    }
    partial[li] = l;
    workgroupBarrier();
    for (var s = 32u; s > 0u; s = s / 2u) {
        if li < s {
            partial[li] += partial[li + s];
        }
        workgroupBarrier();
    }
    if li == 0u {
        loss_partial[lp.partial_offset + wg.x] = partial[0];
    }
}
