// ReSTIR candidate pass: every camera sample's light-sampled and BSDF-sampled paths are
// candidates for every texel that their hit point touches. A candidate's value v for a texel
// is the path-space integrand adjoint x d(BRDF cos L_i)/d(texel) (shared/surface.wgsl,
// path_value), its target q = luminance(v) (v for scalar textures), and it is offered to the
// texel's positive reservoir when q > 0, to the negative one when q < 0 (or to one reservoir
// without positivization) with the resampling weight |q| x MIS weight / density: numerically
// the baseline's contribution of this sample to the texel.
// When the merge will reuse, each candidate also carries its target under the previous
// iteration's textures and adjoint (the merge's MIS weights need it): the same path, one
// more BRDF-with-derivative evaluation per technique here, shared by the path's texels,
// instead of one per texel and reservoir in the merge.
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
    // Whether to compute each candidate's previous-state target (the merge reuses).
    prev_targets: u32,
}

@group(1) @binding(0) var<uniform> cp: CandidateParams;
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
@group(1) @binding(2) var<storage, read_write> fresh: array<atomic<u32>>;
@group(1) @binding(3) var<storage, read_write> locks: array<atomic<u32>>;
// CANDIDATE_STAT_* slots (generated from src/optim/estimator/restir.rs).
@group(1) @binding(4) var<storage, read_write> cstats: array<atomic<u32>, 4>;
@group(1) @binding(5) var<storage, read> adjoint_prev: array<vec4f>;
// Which slots hold each texel's kept reservoirs (shared/reservoir.wgsl).
@group(1) @binding(6) var<storage, read> headers: array<u32>;

var<private> offered: u32 = 0u;
var<private> lost: u32 = 0u;
var<private> dropped: u32 = 0u;

// bg_prev and adj_prev: the path's BRDF derivatives and the pixel's adjoint under the previous
// iteration's state (unused unless cp.prev_targets).
fn offer_technique(g: GradientSample, ds: DirectSample, bg: BrdfGrad, bg_prev: BrdfGrad, vertex: PathVertex, adj: vec3f, adj_prev: vec3f, info: u32) {
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
        var d_prev = vec3f(0.0);
        if cp.prev_targets != 0u && !all(adj_prev == vec3f(0.0)) {
            d_prev = slot_derivative(slot, bg_prev, ds.radiance, adj_prev);
        }
        for (var k = 0u; k < 4u; k++) {
            if fp.weight[k] == 0.0 {
                continue;
            }
            let v = fp.weight[k] * d;
            let q = target_of(v, p.channels);
            var q_prev = target_of(fp.weight[k] * d_prev, p.channels);
            if !(abs(q_prev) < 3.0e38) {
                q_prev = 0.0;
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
            let s = select(0u, 1u, cp.positivize != 0u && q < 0.0);
            let r = RESERVOIR_SLOTS * texel + fresh_slot(headers[texel], s);
            offered += 1u;
            if !reservoir_offer(r, 2u * texel + s, w, rand(), Candidate(info, v, vertex, ds.radiance, q_prev)) {
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
    var adj_prev = vec3f(0.0);
    if cp.prev_targets != 0u {
        adj_prev = adjoint_prev[cp.adjoint_offset + a.pixel].xyz * cp.inv_spp;
    }
    for (var s = 0u; s < cp.spp; s++) {
        rng_init(cp.seed, s * a.n_pixels + a.pixel, 0u);
        let d = camera_direction(cp.camera, a.xy + rand2());
        let g = gradient_sample(cp.camera.origin, d);
        if !g.valid {
            continue;
        }
        var nee_prev = g.nee_grad;
        var bsdf_prev = g.bsdf_grad;
        if cp.prev_targets != 0u {
            // The path's derivatives under the previous textures, from the stored (rounded)
            // directions, as the merge would evaluate them (shared/surface.wgsl, path_value).
            use_prev_params = true;
            let mat_prev = with_optimized(g.sf.material, g.sf.uv, fixed_unpack(g.sf.material, g.nee_vertex.fixed));
            use_prev_params = false;
            let wo = oct_decode(g.nee_vertex.wo);
            nee_prev = brdf_eval_cos_grad(mat_prev, wo, oct_decode(g.nee_vertex.wi));
            bsdf_prev = brdf_eval_cos_grad(mat_prev, wo, oct_decode(g.bsdf_vertex.wi));
        }
        offer_technique(g, g.nee, g.nee_grad, nee_prev, g.nee_vertex, a.adj, adj_prev, info);
        offer_technique(g, g.bsdf, g.bsdf_grad, bsdf_prev, g.bsdf_vertex, a.adj, adj_prev, info | (1u << INFO_TECH_SHIFT));
    }
    atomicAdd(&cstats[CANDIDATE_STAT_OFFERED], offered);
    if lost > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_LOST], lost);
    }
    if dropped > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_DROPPED], dropped);
    }
}
