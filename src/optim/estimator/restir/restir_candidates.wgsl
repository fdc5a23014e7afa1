// ReSTIR candidate pass: every camera sample's light-sampled and BSDF-sampled paths are
// candidates for every texel that their hit point touches. A candidate's value v for a texel
// is the path-space integrand e applied to the adjoint, with e = d(BRDF cos L_i)/d(texel)
// per image channel, or for a normal-map texel per image channel and map channel (a 3x3
// factor: shared/params.wgsl, TexelFactor; shared/surface.wgsl, path_factor); its target q
// is target_of(e applied to the target adjoint) (target.wgsl). With an optimized normal map
// a path's last direction is stored in the geometric normal's frame, which the map does not
// move (shared/path_encoding.wgsl, stored_frame), and the previous state's target is taken
// in the previous textures' shading frames. The target adjoint is an exponential moving average of
// the adjoints (cp.smoothing; reservoir.wgsl), which this pass forms for every pixel.
// A candidate is offered to the texel's positive reservoir when q > 0, to the negative one
// when q < 0 (or to one reservoir without positivization) with the resampling weight |q| x
// MIS weight / density, and the reservoir keeps the path (compact_path.wgsl; the
// samples are taken at the rounded hit, directions and radiances that it stores). The pass
// adds the weights and runs the race for each reservoir (cp.phase 0, reservoir.wgsl), and
// appends every offer that led its reservoir's race when it entered to the claim log, with
// its path: the claim pass (restir_claim.wgsl) then writes the winners' paths. Where the log
// is full, the pass runs again over the same samples with the same random numbers (phase 1,
// dispatched only then) and writes the winners' paths itself (and adds, counts and forms
// nothing else). Only
// observed texels have reservoirs (observed_map); a candidate for another texel is dropped
// and counted (CANDIDATE_STAT_UNMAPPED: the observed-texel pass's strata missed it).
// When the merge will reuse, each candidate also carries its target under the previous
// iteration's textures and target adjoint (the merge's MIS weights need it): the same path,
// one more BRDF-with-derivative evaluation per technique here, shared by the path's texels,
// instead of one per texel and reservoir in the merge.
// With indirect light of up to MAX_PATH_VERTICES vertices (whole_paths), a candidate is a
// whole path: every sample that reaches an emitter from a vertex of the camera path (light
// sampling or BSDF sampling at any vertex; shared/integrator.wgsl records them) ends a path of
// n vertices, which is offered to the texels of every vertex k whose material is optimized,
// with value adjoint x radiance x (every other vertex's BRDF cos) x d(vertex k's BRDF cos) and
// resampling weight |q| x MIS weight / (the whole path's density). The reservoir keeps the
// path's vertices, its last direction and radiance and k (compact_path.wgsl), and the merge
// re-evaluates every vertex under the current textures, so a kept sample follows every
// surface's change; texels seen only after a bounce have reservoirs too (every texel is in
// the map). The first vertex need not be optimized. Beyond MAX_PATH_VERTICES the candidates
// are the first vertex's samples, the light arriving along each (everything the rest of the
// path brings back) stored as its radiance; the later vertices' derivatives are then plain
// Monte Carlo (path replay), added into the gradient as the baseline adds them, and the
// merge adds the reservoirs' estimates to them.
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
    // 0: weights, race keys and the claim log; 1: the winners' paths (reservoir.wgsl).
    phase: u32,
    // Entries the claim log holds, and the workgroups of this pass (the retracing claim's
    // dispatch when the log overflows).
    claim_capacity: u32,
    grid_x: u32,
    grid_y: u32,
    _pad0: u32,
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
@group(1) @binding(7) var<storage, read_write> cstats: array<atomic<u32>, CANDIDATE_STAT_SLOTS>;
// The target adjoints (reservoir.wgsl), both parities: the last iteration's, and this
// one's, which this pass forms.
@group(1) @binding(8) var<storage, read_write> targets: array<vec4f>;
// The compaction map: per 32 texels, which are observed (bits) and how many observed texels
// come before them.
@group(1) @binding(9) var<storage, read> observed_map: array<vec2u>;
// The gradient (f32 bits, laid out like params[]): beyond MAX_PATH_VERTICES the later
// vertices' derivatives are added here (shared/gradient_scatter.wgsl), cleared before this
// pass; the merge adds the rest. Not written at depth 1 or with whole paths.
@group(1) @binding(10) var<storage, read_write> grad: array<atomic<u32>>;
// dL/d(environment radiance) and its counters, plain Monte Carlo (shared/env_gradient.wgsl);
// added in phase 0 only.
@group(1) @binding(11) var<storage, read_write> env_grad: array<atomic<u32>>;
// The claim log (abi.rs, claim): its header (count, the claim pass's and the retracing
// claim's indirect dispatches, the entries' stride), then the leading offers.
@group(1) @binding(12) var<storage, read_write> claims: array<atomic<u32>>;

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
var<private> logged: u32 = 0u;
var<private> overflowed: u32 = 0u;

// Appends an offer that led the race of slot k of observed texel i when it entered (its key
// and its candidate) to the claim log. A full log asks for the retracing claim (its dispatch
// arguments: every camera's grid).
fn log_claim(k: u32, i: u32, key: u32, c: Candidate) {
    let e = atomicAdd(&claims[CLAIM_COUNT], 1u);
    if e >= cp.claim_capacity {
        if e == cp.claim_capacity {
            atomicStore(&claims[CLAIM_FALLBACK_ARGS], cp.grid_x);
            atomicStore(&claims[CLAIM_FALLBACK_ARGS + 1u], cp.grid_y);
            atomicStore(&claims[CLAIM_FALLBACK_ARGS + 2u], 1u);
        }
        overflowed += 1u;
        return;
    }
    if e % CLAIM_WORKGROUP == 0u {
        atomicMax(&claims[CLAIM_ARGS], e / CLAIM_WORKGROUP + 1u);
    }
    logged += 1u;
    let b = CLAIM_HEADER_WORDS + e * (res_stride + 1u);
    atomicStore(&claims[b + CLAIM_ADDR], (i << 2u) | k);
    atomicStore(&claims[b + CLAIM_KEY], key);
    atomicStore(&claims[b + CLAIM_INFO], c.info);
    for (var j = 0u; j < res_stride - RES_TRI; j++) {
        atomicStore(&claims[b + CLAIM_PATH + j], c.words[j]);
    }
}

// The adjoint (over the spp) of the pixel whose sample is being differentiated.
var<private> pixel_adj: vec3f;

// A later vertex of the path (shared/integrator.wgsl, camera_path with replay): its
// derivative added into `grad`, plain Monte Carlo, as the baseline adds it.
fn differentiate_later_vertex(sf: Surface, wi: vec3f, mat: SurfaceMaterial, mat_prev: SurfaceMaterial, weight: vec3f, weight_prev: vec3f) {
    if cp.phase != 0u {
        return;
    }
    scatter(materials[sf.material], sf.uv, surface_brdf_grad(sf, mat, wi, false), weight, pixel_adj);
}

// A path offered to the texels of one vertex's optimized textures: that vertex's material
// index and texture coordinates, its BRDF derivatives and what multiplies them (the path's
// other factors, arriving_at) under the current and (with cp.prev_targets) the previous
// textures, the path's MIS weight / density, and its words (compact_path.wgsl).
struct Offer {
    mi: u32,
    uv: vec2f,
    bg: BrdfGrad,
    bg_prev: BrdfGrad,
    li: vec3f,
    li_prev: vec3f,
    scale: f32,
    words: array<u32, RES_PATH_WORDS>,
    // Whether the first vertex's BSDF sample (the info word's technique bit).
    bsdf: bool,
}

// adj: the pixel's adjoint (for the value), adj_t: its target adjoint; adj_t_prev: the
// pixel's target adjoint under the previous iteration's state (unused unless
// cp.prev_targets).
fn offer_path(o: Offer, adj: vec3f, adj_t: vec3f, adj_t_prev: vec3f, info: u32) {
    if o.scale == 0.0 {
        return;
    }
    let m = materials[o.mi];
    for (var slot = 0u; slot < SLOTS; slot++) {
        let pi = material_param(m, slot);
        if pi == NONE {
            continue;
        }
        let p = param_textures[pi];
        let fp = footprint_merged(param_footprint(p, o.uv));
        let d = texel_factor(slot, o.bg, o.li);
        var d_prev = TexelFactor(vec3f(0.0), mat3x3f());
        if cp.prev_targets != 0u {
            d_prev = texel_factor(slot, o.bg_prev, o.li_prev);
        }
        for (var k = 0u; k < 4u; k++) {
            if fp.weight[k] == 0.0 {
                continue;
            }
            let e = factor_scaled(d, fp.weight[k]);
            let v = texel_value(e, adj, p);
            let q = target_of(texel_value(e, adj_t, p), p);
            var q_prev = target_of(texel_value(factor_scaled(d_prev, fp.weight[k]), adj_t_prev, p), p);
            if !(abs(q_prev) < 3.0e38) {
                q_prev = 0.0;
            }
            let w = abs(q) * o.scale;
            if w == 0.0 {
                continue;
            }
            if !(w < 3.0e38) || !all(abs(v) < vec3f(3.0e38)) || !factor_finite(e) {
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
            let c = Candidate(info | select(0u, 1u << INFO_TECH_SHIFT, o.bsdf), with_q_prev(o.words, q_prev));
            if cp.phase == 0u {
                offered += 1u;
                let entered = reservoir_enter(slot, i, w, u);
                if entered == ENTER_LOST {
                    lost += 1u;
                } else if entered == ENTER_LEADING {
                    log_claim(slot, i, race_key(w, u), c);
                }
            } else {
                reservoir_claim(slot, i, w, u, c);
            }
        }
    }
}

// Technique t of the first vertex (beyond MAX_PATH_VERTICES or at depth 1): the radiance
// arriving along its direction stored as drawn.
fn technique_offer(g: GradientSample, t: u32) -> Offer {
    let ts = technique_sample(g, t);
    var o: Offer;
    o.mi = g.sf.material;
    o.uv = g.sf.uv;
    o.bg = ts.grad;
    o.bg_prev = ts.grad;
    if cp.prev_targets != 0u {
        // The path's derivatives under the previous textures, from the stored (rounded)
        // directions, as the merge would evaluate them (path_factor), in the shading frame
        // of those textures.
        var sf = g.sf;
        var pv = ts.vertex;
        if NORMAL_MAPS && g.m.param_normal != NONE {
            sf.frame = frame_of(sf, true);
            pv.wo = oct_encode(to_local(sf.frame, sf.wo));
            pv.wi = stored_direction(sf, sf.frame, ts.ko);
        }
        use_prev_params = true;
        o.bg_prev = vertex_grad(sf, pv, true);
        use_prev_params = false;
    }
    o.li = ts.ds.radiance;
    o.li_prev = ts.ds.radiance;
    o.scale = ts.ds.scale;
    o.bsdf = t == SAMPLE_BSDF;
    o.words = path_words(array<u32, MAX_PATH_VERTICES>(g.tri, 0u, 0u), array<vec2u, MAX_PATH_VERTICES>(g.kb, vec2u(0u), vec2u(0u)), ts.ko, ts.rgbe, 0.0, 0u);
    return o;
}

// The camera path's vertices (record_paths, shared/integrator.wgsl) rebuilt as the merge
// rebuilds a stored path (compact_path.wgsl), once per camera sample; with optimized normal
// maps and cp.prev_targets, in the previous textures' frames too.
var<private> recorded: DecodedPath;
var<private> recorded_prev: DecodedPath;

// Whole paths: arrival a (a path that reaches an emitter from its last vertex), differentiated
// at its vertex k, evaluated from the words the reservoir will keep exactly as the merge
// evaluates them (the direction at the last vertex and the radiance rounded to their stored
// forms). o.scale is 0 where vertex k's material has no optimized texture.
fn arrival_offer(a: u32, k: u32) -> Offer {
    var o: Offer;
    o.scale = 0.0;
    let ar = arrivals[a];
    let n = ar.n;
    if k >= n || n > recorded.n_valid || !has_optimized(recorded.pv[k].material) {
        return o;
    }
    if !all(ar.radiance < vec3f(3.0e38)) {
        dropped += 1u;
        return o;
    }
    var dp = recorded;
    dp.n = n;
    dp.k = k;
    let last = dp.sf[n - 1u];
    let e = oct_encode(to_local(stored_frame(last), ar.wi));
    let ko = vec2u(oct_round(e.x), oct_round(e.y));
    dp.pv[n - 1u].wi = stored_direction(last, last.frame, ko);
    let rgbe = rgbe_pack(ar.radiance);
    dp.radiance = rgbe_unpack(rgbe);
    o.mi = dp.pv[k].material;
    o.uv = dp.pv[k].uv;
    o.bg = vertex_grad(dp.sf[k], dp.pv[k], true);
    o.li = arriving_at(dp, k);
    o.bg_prev = o.bg;
    o.li_prev = o.li;
    if cp.prev_targets != 0u {
        if NORMAL_MAPS {
            let radiance = dp.radiance;
            dp = recorded_prev;
            dp.n = n;
            dp.k = k;
            let last_prev = dp.sf[n - 1u];
            dp.pv[n - 1u].wi = stored_direction(last_prev, last_prev.frame, ko);
            dp.radiance = radiance;
        }
        use_prev_params = true;
        o.bg_prev = vertex_grad(dp.sf[k], dp.pv[k], true);
        o.li_prev = arriving_at(dp, k);
        use_prev_params = false;
    }
    o.scale = ar.scale;
    o.bsdf = false;
    o.words = path_words(rec_tri, rec_kb, ko, rgbe, 0.0, shape_word(n, k));
    return o;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u, @builtin(local_invocation_index) lid: u32) {
    // The environment's derivative is added in phase 0 only.
    env_local_begin(lid, cp.phase == 0u);
    offer_pixel(id);
    env_local_flush(lid, cp.phase == 0u);
}

// Invocation id's pixel: its target adjoint, and its samples offered to the reservoirs.
fn offer_pixel(id: vec3u) {
    res_stride = reservoir_stride();
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
    light_base = cp.camera.light_base;
    let info = a.pixel | (cp.camera_index << INFO_CAMERA_SHIFT);
    pixel_adj = a.adj;
    env_adj = a.adj;
    var adj_t_prev = vec3f(0.0);
    if cp.prev_targets != 0u {
        adj_t_prev = last * cp.inv_spp;
    }
    let whole = whole_paths();
    for (var s = 0u; s < cp.spp; s++) {
        rng_init(cp.seed, s * a.n_pixels + a.pixel, 0u);
        let d = camera_direction(cp.camera, a.xy + rand2());
        var po = path_options();
        po.replay = !whole;
        po.env_gradients = scene.env_optimized != 0u && cp.phase == 0u;
        po.compact_paths = true;
        po.record_paths = whole;
        let g = gradient_sample(cp.camera.origin, d, po);
        // Offers: the first vertex's two techniques, or with whole paths every arrival at
        // every vertex (at most 6 arrivals of up to MAX_PATH_VERTICES vertices).
        var n_offers = 2u;
        if whole {
            n_offers = n_arrivals * MAX_PATH_VERTICES;
            var n = 0u;
            for (var j = 0u; j < n_arrivals; j++) {
                n = max(n, arrivals[j].n);
            }
            if n > 0u {
                let pw = PathWords(rec_tri, rec_kb, vec2u(0u), vec3f(0.0), 0.0, n, 0u);
                recorded = decode_path(cp.camera.origin, pw, false);
                if NORMAL_MAPS && cp.prev_targets != 0u {
                    recorded_prev = decode_path(cp.camera.origin, pw, true);
                }
            }
        } else if !g.valid {
            continue;
        }
        for (var j = 0u; j < n_offers; j++) {
            var o: Offer;
            if whole {
                o = arrival_offer(j / MAX_PATH_VERTICES, j % MAX_PATH_VERTICES);
            } else {
                o = technique_offer(g, j);
            }
            offer_path(o, a.adj, adj_t, adj_t_prev, info);
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
    if logged > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_LOGGED], logged);
    }
    if overflowed > 0u {
        atomicAdd(&cstats[CANDIDATE_STAT_OVERFLOWED], overflowed);
    }
}
