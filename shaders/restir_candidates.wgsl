// ReSTIR candidate pass: every camera sample's light-sampled and BSDF-sampled paths are
// candidates for every texel that their hit point touches. A candidate's value v for a texel
// is the path-space integrand adjoint x d(BRDF cos L_i)/d(texel) (shared/surface.wgsl,
// path_value), its target q = luminance(v) (v for scalar textures), and it is offered to the
// texel's positive reservoir when q > 0, to the negative one when q < 0 (or to one reservoir
// without positivization) with the resampling weight |q| x MIS weight / density: numerically
// the baseline's contribution of this sample to the texel.
#import shared/rng
#import shared/camera
#import shared/adjoint_pixel
#import shared/integrator
#import shared/reservoir

// Mirrored by CandidateParams in src/optim/estimator/restir.rs.
struct CandidateParams {
    camera: CameraInfo,
    seed: u32,
    spp: u32,
    stride: u32,
    inv_spp: f32,
    // Index of this camera (stored in the reservoirs) and where its adjoint starts.
    camera_index: u32,
    adjoint_offset: u32,
    positivize: u32,
    _pad0: u32,
}

@group(1) @binding(0) var<uniform> cp: CandidateParams;
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
@group(1) @binding(2) var<storage, read_write> fresh: array<atomic<u32>>;
@group(1) @binding(3) var<storage, read_write> locks: array<atomic<u32>>;
// CANDIDATE_STAT_* slots (generated from src/optim/estimator/restir.rs).
@group(1) @binding(4) var<storage, read_write> cstats: array<atomic<u32>, 4>;

var<private> offered: u32 = 0u;
var<private> lost: u32 = 0u;
var<private> dropped: u32 = 0u;

fn offer_technique(g: GradientSample, ds: DirectSample, bg: BrdfGrad, vertex: PathVertex, adj: vec3f, info: u32) {
    if ds.scale == 0.0 {
        return;
    }
    for (var slot = 0u; slot < 3u; slot++) {
        let pi = material_param(g.m, slot);
        if pi == NONE {
            continue;
        }
        let p = param_textures[pi];
        let fp = footprint_merged(param_footprint(p, g.sf.uv));
        let d = slot_derivative(slot, bg, ds.radiance, adj);
        for (var k = 0u; k < 4u; k++) {
            if fp.weight[k] == 0.0 {
                continue;
            }
            let v = fp.weight[k] * d;
            var q = v.x;
            if p.channels == 3u {
                q = luminance(v);
            }
            let w = abs(q) * ds.scale;
            if w == 0.0 {
                continue;
            }
            if !(w < 3.0e38) || !all(abs(v) < vec3f(3.0e38)) {
                dropped += 1u;
                continue;
            }
            let texel = p.texel_offset + fp.texel[k];
            var r = 2u * texel;
            if cp.positivize != 0u && q < 0.0 {
                r += 1u;
            }
            offered += 1u;
            if !reservoir_offer(r, w, rand(), Candidate(info, v, vertex, ds.radiance)) {
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
    let info = a.pixel | (cp.camera_index << INFO_CAMERA_SHIFT);
    for (var s = 0u; s < cp.spp; s++) {
        rng_init(cp.seed, s * a.n_pixels + a.pixel, 0u);
        let d = camera_direction(cp.camera, a.xy + rand2());
        let g = gradient_sample(cp.camera.origin, d);
        if !g.valid {
            continue;
        }
        offer_technique(g, g.nee, g.nee_grad, g.nee_vertex, a.adj, info);
        offer_technique(g, g.bsdf, g.bsdf_grad, g.bsdf_vertex, a.adj, info | (1u << INFO_TECH_SHIFT));
    }
    atomicAdd(&cstats[CANDIDATE_STAT_OFFERED], offered);
    if lost > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_LOST], lost);
    }
    if dropped > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_DROPPED], dropped);
    }
}
