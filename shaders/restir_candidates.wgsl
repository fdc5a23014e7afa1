// ReSTIR candidate pass: every camera sample's light-sampled and BSDF-sampled contributions
// are candidates for every texel that their hit point touches. A candidate's value v for a
// texel is the adjoint-weighted derivative (as the baseline would add it), its target
// q = luminance(v) (v for scalar textures), and it is offered to the texel's positive
// reservoir with weight q when q > 0, to the negative one with weight -q when q < 0 (or to one
// reservoir with weight |q| without positivization). Because v already carries 1/density,
// the weight is q itself.
#import shared/rng
#import shared/camera
#import shared/adjoint_pixel
#import shared/integrator
#import shared/reservoir

// Keep in sync with GpuCandidateParams in src/render/layout.rs.
struct CandidateParams {
    camera: CameraInfo,
    seed: u32,
    spp: u32,
    stride: u32,
    inv_spp: f32,
    // Index of this camera (stored in the reservoirs for replay) and where its adjoint starts.
    camera_index: u32,
    adjoint_offset: u32,
    positivize: u32,
    _pad0: u32,
}

@group(1) @binding(0) var<uniform> cp: CandidateParams;
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
@group(1) @binding(2) var<storage, read_write> fresh: array<atomic<u32>>;
@group(1) @binding(3) var<storage, read_write> locks: array<atomic<u32>>;
// [0] candidates offered, [1] lost offers (lock bound exhausted), [2] dropped non-finite.
@group(1) @binding(4) var<storage, read_write> cstats: array<atomic<u32>, 4>;

var<private> offered: u32 = 0u;
var<private> lost: u32 = 0u;
var<private> dropped: u32 = 0u;

fn offer_contribution(m: Material, hit: Hit, uv: vec2f, bg: BrdfGrad, weight: vec3f, adj: vec3f, sample: u32, info: u32) {
    if all(weight == vec3f(0.0)) {
        return;
    }
    for (var slot = 0u; slot < 3u; slot++) {
        let pi = material_param(m, slot);
        if pi == NONE {
            continue;
        }
        let p = param_textures[pi];
        let fp = footprint_merged(param_footprint(p, uv));
        let g = slot_derivative(slot, bg, weight, adj);
        for (var k = 0u; k < 4u; k++) {
            if fp.weight[k] == 0.0 {
                continue;
            }
            let v = fp.weight[k] * g;
            var q = v.x;
            if p.channels == 3u {
                q = luminance(v);
            }
            if q == 0.0 {
                continue;
            }
            if !(abs(q) < 3.0e38) || !all(abs(v) < vec3f(3.0e38)) {
                dropped += 1u;
                continue;
            }
            let texel = p.texel_offset + fp.texel[k];
            var r = 2u * texel;
            if cp.positivize != 0u && q < 0.0 {
                r += 1u;
            }
            offered += 1u;
            if !reservoir_offer(r, abs(q), rand(), sample, cp.seed, info, v, hit) {
                lost += 1u;
            }
        }
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let a = adjoint_pixel(id.x + id.y * cp.stride, cp.camera, cp.adjoint_offset, cp.inv_spp);
    if a.pixel == NONE {
        return;
    }
    techniques = TECH_MIS;
    for (var s = 0u; s < cp.spp; s++) {
        let sample = s * a.n_pixels + a.pixel;
        rng_init(cp.seed, sample, 0u);
        let d = camera_direction(cp.camera, a.xy + rand2());
        let g = gradient_sample(cp.camera.origin, d);
        if !g.valid {
            continue;
        }
        let cam_bits = cp.camera_index << 1u;
        offer_contribution(g.m, g.hit, g.sf.uv, g.nee_grad, g.nee.weight, a.adj, sample, cam_bits);
        offer_contribution(g.m, g.hit, g.sf.uv, g.bsdf_grad, g.bsdf.weight, a.adj, sample, cam_bits | 1u);
    }
    atomicAdd(&cstats[0], offered);
    if lost > 0u {
        atomicAdd(&cstats[1], lost);
    }
    if dropped > 0u {
        atomicAdd(&cstats[2], dropped);
    }
}
