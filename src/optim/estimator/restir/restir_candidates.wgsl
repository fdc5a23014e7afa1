// ReSTIR candidate pass: every camera sample's light-sampled and BSDF-sampled paths are
// candidates for every texel that their hit point touches. A candidate's value v for a texel
// is the path-space integrand adjoint x e, with e = d(BRDF cos L_i)/d(texel) per image
// channel (shared/surface.wgsl, path_factor); its target q is target_of(the target adjoint x
// e) (shared/params.wgsl). The target adjoint is an exponential moving average of
// the adjoints (cp.smoothing; reservoir.wgsl), which this pass forms for every pixel.
// A candidate is offered to the texel's positive reservoir when q > 0, to the negative one
// when q < 0 (or to one reservoir without positivization) with the resampling weight |q| x
// MIS weight / density, and the reservoir keeps the path (compact_path.wgsl; the
// samples are taken at the rounded hit, directions and radiances that it stores). The pass
// runs twice per iteration with the same random numbers (cp.phase, reservoir.wgsl): phase 0
// adds the weights and runs the race for each reservoir, phase 1 writes the winners' paths
// (and adds, counts and forms nothing else). Only
// observed texels have reservoirs (observed_map); a candidate for another texel is dropped
// and counted (CANDIDATE_STAT_UNMAPPED: the observed-texel pass's strata missed it).
// When the merge will reuse, each candidate also carries its target under the previous
// iteration's textures and target adjoint (the merge's MIS weights need it): the same path,
// one more BRDF-with-derivative evaluation per technique here, shared by the path's texels,
// instead of one per texel and reservoir in the merge.
// With indirect light the candidates are the first vertex's samples, the light arriving
// along each (everything the rest of the path brings back) stored as its radiance; the later
// vertices' derivatives are plain Monte Carlo (path replay, shared/integrator.wgsl), added
// into the gradient as the baseline adds them; the merge adds the reservoirs' estimates to the
// observed texels' (texels seen only after a bounce keep the plain Monte Carlo estimate).
#import shared/rng
#import shared/camera
#import shared/adjoint_pixel
#import shared/integrator
#import shared/gradient_scatter
#import shared/env_gradient
#import gen/restir
#import restir/compact_path
#import restir/reservoir
#import restir/target

// Mirrored by CandidateParams in src/optim/estimator/restir/mod.rs.
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
    // Weight of the last target adjoint in this one (0: the iteration's adjoint itself).
    smoothing: f32,
    // Where this iteration's and the last iteration's target adjoints start in `targets`.
    target_cur: u32,
    target_prev: u32,
    // 0: weights and race keys; 1: the winners' paths (reservoir.wgsl).
    phase: u32,
}

@group(1) @binding(0) var<uniform> cp: CandidateParams;
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
// Slot k of every observed texel's reservoirs (reservoir.wgsl) and the texels'
// headers, which say which slots hold the kept reservoirs.
@group(1) @binding(2) var<storage, read_write> slots0: array<atomic<u32>>;
@group(1) @binding(3) var<storage, read_write> slots1: array<atomic<u32>>;
@group(1) @binding(4) var<storage, read_write> slots2: array<atomic<u32>>;
@group(1) @binding(5) var<storage, read_write> slots3: array<atomic<u32>>;
@group(1) @binding(6) var<storage, read> headers: array<u32>;
// CANDIDATE_STAT_* slots (generated from abi.rs).
@group(1) @binding(7) var<storage, read_write> cstats: array<atomic<u32>, 4>;
// The target adjoints (reservoir.wgsl), both parities: the last iteration's, and this
// one's, which this pass forms.
@group(1) @binding(8) var<storage, read_write> targets: array<vec4f>;
// The compaction map: per 32 texels, which are observed (bits) and how many observed texels
// come before them.
@group(1) @binding(9) var<storage, read> observed_map: array<vec2u>;
// The gradient (f32 bits, laid out like params[]): with indirect light the later vertices'
// derivatives are added here (shared/gradient_scatter.wgsl), cleared before this pass; the
// merge adds the rest. Not written at depth 1.
@group(1) @binding(10) var<storage, read_write> grad: array<atomic<u32>>;
// dL/d(environment radiance) and its counters, plain Monte Carlo (shared/env_gradient.wgsl);
// added in phase 0 only.
@group(1) @binding(11) var<storage, read_write> env_grad: array<atomic<u32>>;

// The index of texel t among the observed texels, or UNOBSERVED.
fn observed_index(t: u32) -> u32 {
    let m = observed_map[t >> 5u];
    let bit = 1u << (t & 31u);
    if (m.x & bit) == 0u {
        return UNOBSERVED;
    }
    return m.y + countOneBits(m.x & (bit - 1u));
}

var<private> offered: u32 = 0u;
var<private> lost: u32 = 0u;
var<private> dropped: u32 = 0u;
var<private> unmapped: u32 = 0u;

// The adjoint (over the spp) of the pixel whose sample is being differentiated.
var<private> pixel_adj: vec3f;

// A later vertex of the path (shared/integrator.wgsl, camera_path with replay): its
// derivative added into `grad`, plain Monte Carlo, as the baseline adds it.
fn differentiate_later_vertex(mi: u32, uv: vec2f, wo: vec3f, wi: vec3f, mat: SurfaceMaterial, mat_prev: SurfaceMaterial, weight: vec3f, weight_prev: vec3f) {
    if cp.phase != 0u {
        return;
    }
    scatter(materials[mi], uv, brdf_eval_cos_grad(mat, wo, wi), weight, pixel_adj);
}

// ts: the technique's sample; adj: the pixel's adjoint (for the value), adj_t: its target
// adjoint; bg_prev and adj_t_prev: the path's BRDF derivatives and the pixel's target adjoint
// under the previous iteration's state (unused unless cp.prev_targets).
fn offer_technique(g: GradientSample, ts: TechniqueSample, bg_prev: BrdfGrad, adj: vec3f, adj_t: vec3f, adj_t_prev: vec3f, info: u32) {
    let ds = ts.ds;
    let bg = ts.grad;
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
        let ch = p.channels;
        let d = slot_factor(slot, bg, ds.radiance);
        var d_prev = vec3f(0.0);
        if cp.prev_targets != 0u {
            d_prev = slot_factor(slot, bg_prev, ds.radiance);
        }
        for (var k = 0u; k < 4u; k++) {
            if fp.weight[k] == 0.0 {
                continue;
            }
            let e = fp.weight[k] * d;
            let v = with_adjoint(e, adj, ch);
            let q = target_of(with_adjoint(e, adj_t, ch), ch);
            var q_prev = target_of(with_adjoint(fp.weight[k] * d_prev, adj_t_prev, ch), ch);
            if !(abs(q_prev) < 3.0e38) {
                q_prev = 0.0;
            }
            let w = abs(q) * ds.scale;
            if w == 0.0 {
                continue;
            }
            if !(w < 3.0e38) || !all(abs(v) < vec3f(3.0e38)) || !all(abs(e) < vec3f(3.0e38)) {
                dropped += 1u;
                continue;
            }
            let i = observed_index(p.texel_offset + fp.texel[k]);
            if i == UNOBSERVED {
                unmapped += 1u;
                continue;
            }
            let s = select(0u, 1u, cp.positivize != 0u && q < 0.0);
            let slot = fresh_slot(headers[i], s);
            let u = rand();
            if cp.phase == 0u {
                offered += 1u;
                if !reservoir_enter(slot, i, w, u) {
                    lost += 1u;
                }
            } else {
                reservoir_claim(slot, i, w, u, Candidate(info, path_words(g.tri, g.kb, ts.ko, ts.rgbe, q_prev)));
            }
        }
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let linear = id.x + id.y * cp.stride;
    // This iteration's target adjoint of the pixel, for every pixel (the merge reads it for
    // kept paths from pixels that draw nothing now).
    let xy_px = tile_pixel(linear, cp.camera.width, cp.camera.height);
    if xy_px.x == NONE {
        return;
    }
    let ai = cp.adjoint_offset + xy_px.y * cp.camera.width + xy_px.x;
    let adj = adjoint[ai].xyz;
    // The last target adjoint: smoothed into this one, and the previous state's target.
    var last = vec3f(0.0);
    if cp.smoothing > 0.0 || cp.prev_targets != 0u {
        last = targets[cp.target_prev + ai].xyz;
    }
    var adj_t = adj;
    if cp.smoothing > 0.0 {
        adj_t = mix(adj, last, cp.smoothing);
    }
    if cp.phase == 0u {
        targets[cp.target_cur + ai] = vec4f(adj_t, 0.0);
    }
    adj_t *= cp.inv_spp;
    let a = adjoint_pixel_at(xy_px, cp.camera, adj, cp.inv_spp);
    if a.pixel == NONE {
        return;
    }
    techniques = TECH_MIS;
    compact_paths = true;
    let info = a.pixel | (cp.camera_index << INFO_CAMERA_SHIFT);
    pixel_adj = a.adj;
    env_adj = a.adj;
    env_gradients = scene.env_optimized != 0u && cp.phase == 0u;
    var adj_t_prev = vec3f(0.0);
    if cp.prev_targets != 0u {
        adj_t_prev = last * cp.inv_spp;
    }
    for (var s = 0u; s < cp.spp; s++) {
        rng_init(cp.seed, s * a.n_pixels + a.pixel, 0u);
        let d = camera_direction(cp.camera, a.xy + rand2());
        let g = gradient_sample(cp.camera.origin, d, false, true);
        if !g.valid {
            continue;
        }
        for (var t = 0u; t < 2u; t++) {
            let ts = technique_sample(g, t);
            var grad_prev = ts.grad;
            if cp.prev_targets != 0u {
                // The path's derivatives under the previous textures, from the stored
                // (rounded) directions, as the merge would evaluate them (path_factor).
                grad_prev = vertex_grad_prev(ts.vertex);
            }
            offer_technique(g, ts, grad_prev, a.adj, adj_t, adj_t_prev, info | (t << INFO_TECH_SHIFT));
        }
    }
    if cp.phase != 0u {
        return;
    }
    atomicAdd(&cstats[CANDIDATE_STAT_OFFERED], offered);
    if lost + scatter_lost > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_LOST], lost + scatter_lost);
    }
    if dropped + scatter_dropped > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_DROPPED], dropped + scatter_dropped);
    }
    if unmapped > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_UNMAPPED], unmapped);
    }
}
