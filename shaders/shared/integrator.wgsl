// Camera paths: emission seen directly, then at every vertex next-event estimation and BSDF
// sampling, combined by MIS (power heuristic), to scene.max_depth vertices (1: direct light).
// Each of the first vertex's two techniques returns the sampled direction, the radiance
// arriving along it (with further vertices, everything the BSDF sample's ray brings back) and
// a factor (MIS weight / density, or 1 / density), so that the contribution is
// brdf_eval_cos(wo, wi) x radiance x scale; the gradient passes reuse this split (ReSTIR
// stores the path, direction and radiance, without the factor).
#import shared/bvh
#import shared/surface
#import shared/path_encoding

// Rays traced, counted for the pass's statistics.
var<private> shadow_rays: u32 = 0u;
var<private> bsdf_rays: u32 = 0u;

// The path's first PATH_RECORD_VERTICES vertices and its arrivals, with
// PathOptions.record_paths (see there).
const PATH_RECORD_VERTICES: u32 = 3u;
var<private> rec_tri: array<u32, PATH_RECORD_VERTICES>;
var<private> rec_kb: array<vec2u, PATH_RECORD_VERTICES>;

struct Arrival {
    n: u32,
    wi: vec3f,
    radiance: vec3f,
    scale: f32,
    // Whether the radiance is the environment's along wi (which an environment fit changes).
    env: bool,
}

var<private> arrivals: array<Arrival, 6>;
var<private> n_arrivals: u32 = 0u;

fn record_arrival(opts: PathOptions, n: u32, wi: vec3f, radiance: vec3f, scale: f32, env: bool) {
    if opts.record_paths && n <= PATH_RECORD_VERTICES && n_arrivals < 6u {
        arrivals[n_arrivals] = Arrival(n, wi, radiance, scale, env);
        n_arrivals += 1u;
    }
}

// One technique's sample: direction wi (world space), incident radiance along it (for delta
// lights intensity / distance^2), and scale = MIS weight / density (1 / choice probability for
// delta lights). The contribution is brdf_eval_cos(wo, wi) x radiance x scale; no sample has
// radiance 0.
struct DirectSample {
    wi: vec3f,
    radiance: vec3f,
    scale: f32,
}

const NO_SAMPLE = DirectSample(vec3f(0.0, 0.0, 1.0), vec3f(0.0), 0.0);

fn mis_light(techniques: u32, p_light: f32, p_bsdf: f32) -> f32 {
    switch techniques {
        case 1u: {
            return 1.0;
        }
        case 2u: {
            return 0.0;
        }
        default: {
            return power_heuristic(p_light, p_bsdf);
        }
    }
}

fn mis_bsdf(techniques: u32, p_bsdf: f32, p_light: f32) -> f32 {
    switch techniques {
        case 1u: {
            return 0.0;
        }
        case 2u: {
            return 1.0;
        }
        default: {
            return power_heuristic(p_bsdf, p_light);
        }
    }
}

// A camera path: the first hit and its two direct samples (light sampling, NEE, then BSDF
// sampling), and with scene.max_depth > 1 the path continued from the BSDF sample's hit, with
// both samples at every further vertex combined by MIS, to max_depth vertices (depth 1 is
// direct light only). A CPU device inlines every function call, so each call site of a
// function is compiled anew (measured on lavapipe: about 1.5 s of pipeline creation per
// traversal). So every ray (camera, shadow, BSDF, at every vertex) is traced at one call
// site, in a loop over these stages, what arrives at a shading point (emission at a hit, an
// area light's point, the environment in a direction) is evaluated at one call site, and
// every vertex is shaded at one: STAGE_LIGHT traces nothing and evaluates the sampled light's
// point there.
const STAGE_CAMERA: u32 = 0u;
const STAGE_LIGHT: u32 = 1u;
const STAGE_SHADOW: u32 = 2u;
const STAGE_BSDF: u32 = 3u;
const STAGE_DONE: u32 = 4u;

// Vertices from which Russian roulette may end a path (the first three never end by it).
const RR_VERTEX: u32 = 4u;

struct CameraPath {
    // The camera ray's hit (tri NONE on a miss); with compact_paths, at the barycentrics
    // ReSTIR stores.
    hit: Hit,
    // Whether the hit was shaded and its samples drawn: false on a miss, at the back of a
    // single-sided surface, and (with optimized_only, unless replay or record_paths at depth
    // > 1) on a material without optimized textures. Only e is set otherwise.
    shaded: bool,
    sf: Surface,
    // The inputs that the glTF material gives, and those with the optimized textures.
    gltf: SurfaceMaterial,
    mat: SurfaceMaterial,
    // The inputs with the previous iteration's optimized textures (with `both`).
    mat_prev: SurfaceMaterial,
    // Radiance along the camera ray itself: the environment on a miss, emission at a hit.
    e: vec3f,
    nee: DirectSample,
    // BSDF sampling at the first hit. With max_depth > 1 its radiance is everything that
    // arrives along its direction: the emission it finds, weighted by MIS, plus the path's
    // further vertices (scale is then 1 / density); otherwise the emission alone (scale MIS
    // weight / density).
    bsdf: DirectSample,
    // bsdf.radiance with the further vertices under the previous iteration's textures (with
    // `both`; otherwise bsdf.radiance).
    bsdf_prev: vec3f,
}

// Whether material mi has an optimized texture (fields read one by one: a CPU device loads
// every word of a struct read at a per-invocation index).
fn has_optimized(mi: u32) -> bool {
    return materials[mi].param_base_color != NONE || materials[mi].param_metallic != NONE || materials[mi].param_roughness != NONE || materials[mi].param_normal != NONE;
}

fn max_component(v: vec3f) -> f32 {
    return max(max(v.x, v.y), v.z);
}

// What a camera path computes besides its value, and how, set by name at every call site
// (path_options, then the fields):
// - optimized_only shades the first vertex only where its material has an optimized texture
//   (the gradient passes); both and replay as camera_path says.
// - techniques: which techniques contribute to area and environment lights (TECH_*; delta
//   lights always use NEE).
// - env_gradients: camera_path calls the pass's differentiate_env(direction, factor) for
//   every segment that escapes to the environment (a gradient pass sets it when the
//   environment is optimized): shared/env_gradient.wgsl. The first vertex is then shaded on
//   every material.
// - compact_paths (ReSTIR's candidates): the camera ray's hit (and with record_paths every
//   vertex) is moved to the fixed-point barycentrics ReSTIR stores, and gradient_sample
//   rounds the incident directions and the radiances to the compact path encoding
//   (shared/path_encoding.wgsl) before anything is evaluated, so that a stored path
//   (stored_vertex, path_factor) re-evaluates to the same value.
// - record_paths (ReSTIR's candidates keeping whole paths, restir_candidates.wgsl; the path
//   cache's trace, primal/primal_cache_trace.wgsl): the
//   path's first PATH_RECORD_VERTICES vertices (rec_tri, rec_kb: triangle and fixed-point
//   barycentrics, the camera ray's hit first; with compact_paths every vertex is moved to the
//   barycentrics stored) and every sample that reaches an emitter from one of them (an
//   arrival): the path of `n` vertices that it ends, the direction from its last vertex, the
//   radiance arriving (unweighted) and its factor, MIS weight / density of the whole path (the
//   BSDF samples' densities that led to the last vertex included). Such a path's contribution
//   is its radiance times every vertex's BRDF x cos times the factor. At depth > 1
//   camera_path also shades a first vertex without optimized textures then (a later vertex
//   may be optimized).
struct PathOptions {
    optimized_only: bool,
    both: bool,
    replay: bool,
    techniques: u32,
    env_gradients: bool,
    compact_paths: bool,
    record_paths: bool,
}

// The defaults: the path's value under the current textures, by MIS, nothing else.
fn path_options() -> PathOptions {
    return PathOptions(false, false, false, TECH_MIS, false, false, false);
}

// camera_path's state between its steps: its options, the vertex whose samples are being
// traced, what the path has gathered, and its result so far.
struct PathState {
    out: CameraPath,
    opts: PathOptions,
    max_depth: u32,
    rng_start: u32,
    // Whether the path is being replayed (with `replay`) to differentiate later vertices,
    // knowing what it brought back in all (ind_total, ind_prev_total).
    replaying: bool,
    ind_total: vec3f,
    ind_prev_total: vec3f,
    later_optimized: bool,
    // The ray to trace next and what it is (STAGE_*).
    ray_o: vec3f,
    ray_d: vec3f,
    ray_tmax: f32,
    stage: u32,
    ls: LightSample,
    nee_weight: f32,
    u_bsdf: vec3f,
    bsdf_pdf: f32,
    // The vertex whose samples are being traced (1 = the camera ray's hit, 0 before it is
    // shaded), its surface and material under the current and (with both) the previous
    // textures.
    depth: u32,
    vsf: Surface,
    vmat: SurfaceMaterial,
    vmat_prev: SurfaceMaterial,
    // The surface at the hit of a ray that a vertex is shaded at next.
    next_sf: Surface,
    // From vertex 2 on: the throughput from vertex 2 to this vertex (1 at vertex 2) and to the
    // next one along the BSDF sample, under each state, and the radiance gathered so far,
    // arriving at the first vertex along its BSDF sample (before its BRDF and density).
    beta: vec3f,
    beta_prev: vec3f,
    beta_next: vec3f,
    beta_next_prev: vec3f,
    ind: vec3f,
    ind_prev: vec3f,
    // The first vertex's BRDF x cos / density along its BSDF sample (for Russian roulette and
    // the later vertices' derivatives), under each state.
    first_weight: vec3f,
    first_weight_prev: vec3f,
    // The first vertex's BSDF sample: its direction, density and the MIS-weighted emission
    // it finds.
    first_wi: vec3f,
    first_pdf: f32,
    first_e: vec3f,
    // With env_gradients: the direction of this step's escape to the environment (zero for
    // none) and the MIS weight / density its radiance is multiplied by at its vertex.
    env_dir: vec3f,
    env_factor: f32,
    // With record_paths: 1 / the densities of the BSDF samples that led to this vertex (and
    // to the next one), and the next vertex's triangle and barycentrics.
    path_scale: f32,
    path_scale_next: f32,
    next_tri: u32,
    next_kb: vec2u,
}

// What one step of camera_path passes from stage to stage: the traced ray's hit, whether the
// light sample arrived and what comes next (the BSDF sample, shading the hit), and after the
// first vertex the direction in which this vertex's BRDF is evaluated in this step (zero for
// none) with the radiance arriving along it, weighted by MIS and density (from a light
// sample, or the emission a BSDF sample found), and whether that direction is the BSDF
// sample's that leads to the next vertex.
struct PathStep {
    hit: Hit,
    next_bsdf: bool,
    nee_arrives: bool,
    shade: bool,
    eval_wi: vec3f,
    arrives: vec3f,
    to_next: bool,
}

// A camera path, traced in steps (one ray each: the camera ray, a light sample's shadow ray,
// a BSDF sample) through the stages path_arrival, path_light_arrives, path_evaluate,
// path_next_vertex and path_bsdf_sample, which share PathState and PathStep. Uses 6 random
// numbers per vertex in a fixed order (light choice, light sample, BSDF sample; then, from
// vertex RR_VERTEX on, one for Russian roulette before them), so that the primal and
// gradient passes draw the same samples from the same camera-sample index (options:
// PathOptions). With `both`, the vertices after the first are also evaluated under the
// previous iteration's textures (same directions, densities and MIS weights), for bsdf_prev.
//
// With `replay`, the derivatives at the vertices after the first (path replay
// backpropagation): once the path is traced and everything it brings back is known, it is
// traced again from the same random numbers, and at every later vertex with an optimized
// material the pass's differentiate_later_vertex receives the surface, the incident direction
// (world space), the BRDF's inputs under each state and the factor that its derivative
// multiplies: for a light sample, the throughput up to the vertex times the sample's weight;
// for the BSDF sample, what the rest of the path brings back (everything less what the
// vertices before it brought) over the BRDF's value there.
// Both include the first vertex's BRDF x cos / density along its BSDF sample. The memory is
// the same at every depth; the cost is a second tracing of the paths that reach an optimized
// material after the first vertex.
fn camera_path(o: vec3f, d: vec3f, opts: PathOptions) -> CameraPath {
    // (A variable without an initializer is zero: the other fields start at 0.)
    var st: PathState;
    st.out.hit = Hit(3.0e38, NONE, 0.0, 0.0);
    st.out.nee = NO_SAMPLE;
    st.out.bsdf = NO_SAMPLE;
    st.opts = opts;
    st.max_depth = max(scene.max_depth, 1u);
    st.rng_start = rng_state;
    st.ray_o = o;
    st.ray_d = d;
    st.ray_tmax = 3.0e38;
    st.stage = STAGE_CAMERA;
    st.beta = vec3f(1.0);
    st.beta_prev = vec3f(1.0);
    st.beta_next = vec3f(1.0);
    st.beta_next_prev = vec3f(1.0);
    st.first_weight = vec3f(1.0);
    st.first_weight_prev = vec3f(1.0);
    st.first_wi = vec3f(0.0, 0.0, 1.0);
    st.path_scale = 1.0;
    st.path_scale_next = 1.0;
    st.next_tri = NONE;
    n_arrivals = 0u;
    let steps = (1u + 3u * st.max_depth) * select(1u, 2u, st.opts.replay && st.max_depth > 1u);
    for (var step = 0u; step < steps && st.stage != STAGE_DONE; step++) {
        var sp: PathStep;
        sp.hit = Hit(st.ray_tmax, NONE, 0.0, 0.0);
        if st.stage != STAGE_LIGHT {
            sp.hit = trace_ray(st.ray_o, st.ray_d, st.ray_tmax, st.stage == STAGE_SHADOW);
        }
        st.env_dir = vec3f(0.0);
        if st.stage == STAGE_SHADOW {
            sp.nee_arrives = sp.hit.tri == NONE;
            sp.next_bsdf = true;
        } else {
            path_arrival(&st, &sp);
        }
        if sp.nee_arrives {
            path_light_arrives(&st, &sp);
        }
        if any(sp.eval_wi != vec3f(0.0)) {
            path_evaluate(&st, &sp);
        }
        if sp.shade {
            path_next_vertex(&st, &sp);
        }
        if sp.next_bsdf {
            path_bsdf_sample(&st);
        }
        if st.stage == STAGE_DONE && st.opts.replay && !st.replaying && st.later_optimized && (any(st.ind != vec3f(0.0)) || any(st.ind_prev != vec3f(0.0))) {
            path_replay(&st, o, d);
        }
    }
    st.out.bsdf_prev = st.out.bsdf.radiance;
    if any(st.ind != vec3f(0.0)) || any(st.ind_prev != vec3f(0.0)) {
        st.out.bsdf = DirectSample(st.first_wi, st.first_e + st.ind, 1.0 / st.first_pdf);
        st.out.bsdf_prev = st.first_e + st.ind_prev;
    }
    return st.out;
}

// Replay: the same path from the same random numbers (from camera ray o, d), now knowing
// what it brought back in all.
fn path_replay(st: ptr<function, PathState>, o: vec3f, d: vec3f) {
    st.replaying = true;
    st.ind_total = st.ind;
    st.ind_prev_total = st.ind_prev;
    st.ind = vec3f(0.0);
    st.ind_prev = vec3f(0.0);
    rng_state = st.rng_start;
    st.ray_o = o;
    st.ray_d = d;
    st.ray_tmax = 3.0e38;
    st.stage = STAGE_CAMERA;
    st.depth = 0u;
    st.beta_next = vec3f(1.0);
    st.beta_next_prev = vec3f(1.0);
}

// A step of camera_path other than a shadow ray: what arrives along the ray (an emitter's
// or the environment's radiance) and what the stage makes of it: the camera ray's hit, a
// BSDF sample's arrival (and its hit, the next vertex below the maximum depth), or a light
// sample's shadow ray to trace.
fn path_arrival(st: ptr<function, PathState>, sp: ptr<function, PathStep>) {
    // What arrives: from the emitter point (tri, b) seen from its front or back, or
    // from the environment along dir when tri is NONE.
    var tri = sp.hit.tri;
    var dir = st.ray_d;
    var front = false;
    // A hit that becomes the next vertex: the camera ray's, or a BSDF sample's below
    // the maximum depth.
    let continues = st.stage == STAGE_CAMERA || (st.stage == STAGE_BSDF && st.depth < st.max_depth);
    if st.stage == STAGE_LIGHT {
        tri = st.ls.tri;
        sp.hit.b1 = st.ls.b.x;
        sp.hit.b2 = st.ls.b.y;
        dir = st.ls.wi;
        front = st.ls.front;
    } else if continues && sp.hit.tri != NONE {
        if st.opts.compact_paths && (st.stage == STAGE_CAMERA || st.opts.record_paths) {
            // (The distance is kept: a BSDF sample's hit on an emitter reads it.)
            st.next_kb = vec2u(bary_round(sp.hit.b1), bary_round(sp.hit.b2));
            let t = sp.hit.t;
            sp.hit = stored_hit(sp.hit.tri, st.next_kb);
            sp.hit.t = t;
        }
        st.next_tri = sp.hit.tri;
        st.next_sf = surface_at(st.ray_o, sp.hit);
        if st.stage == STAGE_CAMERA {
            st.out.hit = sp.hit;
            st.out.sf = st.next_sf;
        }
        front = st.next_sf.front;
    } else if sp.hit.tri != NONE {
        let p0 = tri_vertex(sp.hit.tri, 0u);
        let ng = cross(tri_vertex(sp.hit.tri, 1u) - p0, tri_vertex(sp.hit.tri, 2u) - p0);
        front = dot(ng, st.ray_d) < 0.0;
    }
    var le = vec3f(0.0);
    // The environment's density in direction dir, light choice included.
    var p_env = 0.0;
    if !(st.stage == STAGE_LIGHT && st.ls.is_delta) {
        if tri == NONE {
            le = env_radiance(dir);
            if st.stage != STAGE_CAMERA {
                p_env = env_light_pdf(dir);
            }
        } else {
            // Zero at the back of a single-sided surface (which shades black).
            le = emitted(tri, sp.hit.b1, sp.hit.b2, front);
        }
    }
    if st.stage == STAGE_BSDF {
        var p_light = p_env;
        if sp.hit.tri != NONE {
            p_light = area_light_pdf(sp.hit.tri, st.vsf.p, st.ray_o + sp.hit.t * st.ray_d);
        }
        let w = mis_bsdf(st.opts.techniques, st.bsdf_pdf, p_light);
        if !(all(le == vec3f(0.0)) || w <= 0.0) {
            record_arrival(st.opts, st.depth, st.ray_d, le, st.path_scale * w / st.bsdf_pdf, sp.hit.tri == NONE);
            if st.depth == 1u {
                st.out.bsdf = DirectSample(st.ray_d, le, w / st.bsdf_pdf);
                st.first_e = le * w;
            } else {
                sp.arrives = le * w;
            }
            if st.opts.env_gradients && sp.hit.tri == NONE {
                st.env_dir = st.ray_d;
                st.env_factor = w / st.bsdf_pdf;
            }
        }
        if st.max_depth > 1u || any(st.env_dir != vec3f(0.0)) {
            sp.eval_wi = st.ray_d;
            sp.to_next = true;
        }
        st.stage = STAGE_DONE;
        sp.shade = continues && sp.hit.tri != NONE && st.next_sf.valid;
    } else if st.stage == STAGE_LIGHT {
        if st.ls.env {
            st.ls.radiance = le;
            st.ls.pdf = p_env;
        } else if !st.ls.is_delta {
            st.ls.radiance = le;
        }
        let sf = st.vsf;
        st.stage = STAGE_DONE;
        sp.next_bsdf = true;
        if !(st.ls.pdf <= 0.0 || all(st.ls.radiance == vec3f(0.0)) || dot(st.ls.wi, sf.ng) <= 0.0) {
            st.nee_weight = 1.0;
            if !st.ls.is_delta {
                let p_bsdf = brdf_pdf(st.vmat, to_local(sf.frame, sf.wo), to_local(sf.frame, st.ls.wi));
                st.nee_weight = mis_light(st.opts.techniques, st.ls.pdf, p_bsdf);
            }
            if !(st.nee_weight <= 0.0) {
                shadow_rays += 1u;
                // The shadow segment runs from the offset origin to the light point
                // itself, moved off an emitter's surface towards the shading point by
                // the same relative offset, so that neither end hits its own surface.
                // (A ray of length `dist` along wi from the offset origin would end
                // past an emitter's plane wherever the origin's offset exceeds its
                // margin along the plane's normal, and find the emitter itself in the
                // way; tests/techniques.rs and tests/analytic.rs catch that.)
                let so = offset_origin(sf, st.ls.wi);
                if st.ls.dist >= 3.0e38 {
                    st.ray_o = so;
                    st.ray_d = st.ls.wi;
                    st.ray_tmax = 3.0e38;
                    st.stage = STAGE_SHADOW;
                } else {
                    var q = sf.p + st.ls.dist * st.ls.wi;
                    if any(st.ls.n != vec3f(0.0)) {
                        let scale = 1e-4 * (1.0 + max(max(abs(q.x), abs(q.y)), abs(q.z)));
                        q += st.ls.n * select(-scale, scale, dot(st.ls.n, -st.ls.wi) >= 0.0);
                    }
                    let to = q - so;
                    let len = length(to);
                    if len <= 0.0 {
                        sp.nee_arrives = true;
                    } else {
                        st.ray_o = so;
                        st.ray_d = to / len;
                        st.ray_tmax = len * (1.0 - 1e-4);
                        st.stage = STAGE_SHADOW;
                    }
                }
                if st.stage == STAGE_SHADOW {
                    sp.next_bsdf = false;
                }
            }
        }
    } else {
        st.out.e = le;
        if st.opts.env_gradients && tri == NONE && !st.replaying {
            differentiate_env(dir, vec3f(1.0));
        }
        st.stage = STAGE_DONE;
        // (With replay, a path whose first vertex is not optimized may still reach one.)
        sp.shade = sp.hit.tri != NONE && st.next_sf.valid && (!st.opts.optimized_only || has_optimized(st.next_sf.material) || (st.opts.replay && st.max_depth > 1u) || st.opts.env_gradients || (st.opts.record_paths && st.max_depth > 1u));
        st.out.shaded = sp.shade;
    }
}

// A light sample that reached its light (its shadow ray unblocked): its arrival recorded,
// and the first vertex's light sample, or the direction a later vertex is evaluated in.
fn path_light_arrives(st: ptr<function, PathState>, sp: ptr<function, PathStep>) {
    record_arrival(st.opts, st.depth, st.ls.wi, st.ls.radiance, st.path_scale * st.nee_weight / st.ls.pdf, st.ls.env);
    if st.opts.env_gradients && st.ls.env {
        st.env_dir = st.ls.wi;
        st.env_factor = st.nee_weight / st.ls.pdf;
    }
    if st.depth == 1u {
        st.out.nee = DirectSample(st.ls.wi, st.ls.radiance, st.nee_weight / st.ls.pdf);
        if any(st.env_dir != vec3f(0.0)) {
            sp.eval_wi = st.ls.wi;
        }
    } else {
        sp.eval_wi = st.ls.wi;
        sp.arrives = st.ls.radiance * (st.nee_weight / st.ls.pdf);
    }
}

// The vertex's BRDF x cos towards sp.eval_wi under each state: the throughput and the
// radiance gathered, the environment's derivative, and with replay the vertex's own.
fn path_evaluate(st: ptr<function, PathState>, sp: ptr<function, PathStep>) {
    // The vertex's BRDF x cos towards eval_wi under each state, at one call site (the
    // light sample's and the BSDF sample's; see above). A BSDF sample's carries the
    // path on to the next vertex (beta_next); at the first vertex it only weighs
    // Russian roulette.
    let wo = to_local(st.vsf.frame, st.vsf.wo);
    let wi = to_local(st.vsf.frame, sp.eval_wi);
    // What the rest of the path brings back from here (replay only).
    let rest = st.ind_total - st.ind;
    let rest_prev = st.ind_prev_total - st.ind_prev;
    var fc = vec3f(0.0);
    var fc_prev = vec3f(0.0);
    for (var state = 0u; state < select(1u, 2u, st.opts.both); state++) {
        var m = st.vmat;
        var b = st.beta;
        var wo_s = wo;
        var wi_s = wi;
        if state == 1u {
            m = st.vmat_prev;
            b = st.beta_prev;
            if materials[st.vsf.material].param_normal != NONE {
                // (The previous normal map's frame; the directions are the same.)
                let frame_prev = frame_of(st.vsf, true);
                wo_s = to_local(frame_prev, st.vsf.wo);
                wi_s = to_local(frame_prev, sp.eval_wi);
            }
        }
        var f = brdf_eval_cos(m, wo_s, wi_s);
        if state == 0u {
            fc = f;
        } else {
            fc_prev = f;
        }
        if sp.to_next {
            f /= st.bsdf_pdf;
        }
        if st.depth == 1u {
            // (At the first vertex a light sample is evaluated here only for the
            // environment's derivative.)
            if sp.to_next && state == 0u {
                st.first_weight = f;
            } else if sp.to_next {
                st.first_weight_prev = f;
            }
        } else if sp.to_next {
            if state == 0u {
                st.beta_next = b * f;
                st.ind += st.beta_next * sp.arrives;
            } else {
                st.beta_next_prev = b * f;
                st.ind_prev += st.beta_next_prev * sp.arrives;
            }
        } else if state == 0u {
            st.ind += b * f * sp.arrives;
        } else {
            st.ind_prev += b * f * sp.arrives;
        }
    }
    if any(st.env_dir != vec3f(0.0)) && !st.replaying {
        // The escape's factor on the way to the pixel: the throughput to this vertex
        // (1 at the first), its BRDF x cos, the MIS weight / density.
        var through = vec3f(1.0);
        if st.depth > 1u {
            through = st.first_weight * st.beta;
        }
        differentiate_env(st.env_dir, through * fc * st.env_factor);
    }
    if st.replaying && st.depth > 1u && has_optimized(st.vsf.material) {
        var w = st.first_weight * st.beta * sp.arrives;
        var w_prev = st.first_weight_prev * st.beta_prev * sp.arrives;
        if sp.to_next {
            w = st.first_weight * select(vec3f(0.0), rest / fc, fc > vec3f(0.0));
            w_prev = st.first_weight_prev * select(vec3f(0.0), rest_prev / fc_prev, fc_prev > vec3f(0.0));
        }
        differentiate_later_vertex(st.vsf, sp.eval_wi, st.vmat, st.vmat_prev, w, w_prev);
    }
}

// The ray's hit becomes the next vertex (the first at the camera ray's hit): its inputs under
// each state, Russian roulette from RR_VERTEX on, and its light sample drawn.
fn path_next_vertex(st: ptr<function, PathState>, sp: ptr<function, PathStep>) {
    // The hit becomes the next vertex: the first at the camera ray's hit.
    st.depth += 1u;
    st.vsf = st.next_sf;
    if st.opts.record_paths && st.depth <= PATH_RECORD_VERTICES {
        rec_tri[st.depth - 1u] = st.next_tri;
        rec_kb[st.depth - 1u] = st.next_kb;
    }
    let gltf = gltf_inputs(st.vsf.material, st.vsf.uv);
    // The optimized inputs under each state, at one call site.
    for (var state = 0u; state < select(1u, 2u, st.opts.both); state++) {
        use_prev_params = state == 1u;
        let m = with_optimized(st.vsf.material, st.vsf.uv, gltf);
        if state == 0u {
            st.vmat = m;
        } else {
            st.vmat_prev = m;
        }
    }
    use_prev_params = false;
    if st.depth == 1u {
        st.out.gltf = gltf;
        st.out.mat = st.vmat;
        st.out.mat_prev = st.vmat_prev;
    } else {
        st.later_optimized = st.later_optimized || has_optimized(st.vsf.material);
        st.beta = st.beta_next;
        st.beta_prev = st.beta_next_prev;
        st.path_scale = st.path_scale_next;
        if st.depth >= RR_VERTEX {
            let q = min(max_component(st.beta * st.first_weight), 0.95);
            if rand() < q {
                st.beta /= q;
                st.beta_prev /= q;
                st.path_scale /= q;
            } else {
                sp.shade = false;
            }
        }
    }
    if sp.shade {
        let u_pick = rand();
        let u_light = rand2();
        st.u_bsdf = vec3f(rand(), rand2());
        st.ls = sample_light(st.vsf.p, u_pick, u_light);
        st.stage = STAGE_LIGHT;
    }
}

// The vertex's BSDF sample: the ray to trace next, or the end of the path.
fn path_bsdf_sample(st: ptr<function, PathState>) {
    st.stage = STAGE_DONE;
    let wo = to_local(st.vsf.frame, st.vsf.wo);
    let wi_local = brdf_sample(st.vmat, wo, st.u_bsdf);
    let wi = to_world(st.vsf.frame, wi_local);
    if !(wi_local.z <= 0.0 || dot(wi, st.vsf.ng) <= 0.0) {
        st.bsdf_pdf = brdf_pdf(st.vmat, wo, wi_local);
        if !(st.bsdf_pdf <= 0.0) {
            bsdf_rays += 1u;
            st.ray_o = offset_origin(st.vsf, wi);
            st.ray_d = wi;
            st.ray_tmax = 3.0e38;
            st.stage = STAGE_BSDF;
            st.path_scale_next = st.path_scale / st.bsdf_pdf;
            if st.depth == 1u {
                st.first_wi = wi;
                st.first_pdf = st.bsdf_pdf;
            }
        }
    }
}

// Sample s's contribution at sf with inputs mat, in sf's frame under the current or (prev)
// the previous textures.
fn contribution(mat: SurfaceMaterial, sf: Surface, s: DirectSample, prev: bool) -> vec3f {
    if s.scale == 0.0 {
        return vec3f(0.0);
    }
    let frame = frame_of(sf, prev);
    let wo = to_local(frame, sf.wo);
    return brdf_eval_cos(mat, wo, to_local(frame, s.wi)) * s.radiance * s.scale;
}

// Radiance along a camera ray (origin o, unit direction d), paths of scene.max_depth vertices:
// [0] under the current textures and, with opts.both, [1] the same path (same hits, samples and
// MIS weights) under the previous iteration's textures (otherwise [1] = [0]). The first
// vertex's two techniques' contributions under each state are added in one loop, for the
// reason camera_path traces in one.
fn radiance_states(o: vec3f, d: vec3f, opts: PathOptions) -> array<vec3f, 2> {
    let both = opts.both;
    let p = camera_path(o, d, opts);
    var l = array<vec3f, 2>(p.e, p.e);
    if !p.shaded {
        return l;
    }
    var mat = p.mat;
    let terms = select(2u, 4u, both);
    for (var j = 0u; j < terms; j++) {
        if j == 2u {
            mat = p.mat_prev;
        }
        var s = p.nee;
        if (j & 1u) == 1u {
            s = p.bsdf;
        }
        if j == 3u {
            s.radiance = p.bsdf_prev;
        }
        l[j / 2u] += contribution(mat, p.sf, s, j >= 2u);
    }
    if !both {
        l[1] = l[0];
    }
    return l;
}

// A camera sample as the gradient passes see it: the surface it hits and its two direct
// samples with their BRDF derivatives. valid is false when the ray misses, hits the back of a
// single-sided surface, or hits a material without optimized textures. The outgoing and each
// sample's incident direction are taken to the shading frame and rounded through the
// octahedral encoding (about 1e-7), and the derivatives are taken there (with compact_paths,
// as the top of this file says).

// One technique's sample as the gradient passes use it.
struct TechniqueSample {
    // Direction, radiance (rounded with compact_paths) and MIS weight / density.
    ds: DirectSample,
    grad: BrdfGrad,
    // The path as the BRDF sees it.
    vertex: PathVertex,
    // With compact_paths: the fixed-point direction and the RGBE radiance
    // (shared/path_encoding.wgsl).
    ko: vec2u,
    rgbe: u32,
    // ds.radiance with the path's further vertices under the previous iteration's textures
    // (gradient_sample with `both`; otherwise ds.radiance).
    radiance_prev: vec3f,
}

// The two samples of a GradientSample, in the order in which every pass adds them.
const SAMPLE_NEE: u32 = 0u;
const SAMPLE_BSDF: u32 = 1u;

struct GradientSample {
    valid: bool,
    sf: Surface,
    m: Material,
    // With compact_paths: the hit's triangle and fixed-point barycentrics.
    tri: u32,
    kb: vec2u,
    // Light sampling and BSDF sampling. The passes loop over the two (technique_sample)
    // rather than naming each, so that their code is compiled once (see camera_path).
    nee: TechniqueSample,
    bsdf: TechniqueSample,
}

// Sample t (SAMPLE_NEE or SAMPLE_BSDF) of g. (A struct copy by branch: an array of the two
// indexed by t compiled slower on lavapipe.)
fn technique_sample(g: GradientSample, t: u32) -> TechniqueSample {
    if t == SAMPLE_BSDF {
        return g.bsdf;
    }
    return g.nee;
}

// The octahedral coordinates of wi (world space) in sf's frame; when compact_paths, of wi
// as ReSTIR stores it (ko: the fixed-point values in the frame it is stored in,
// shared/path_encoding.wgsl, stored_frame).
struct RoundedDirection {
    oct: vec2f,
    ko: vec2u,
}

fn rounded_direction(sf: Surface, wi: vec3f, compact_paths: bool) -> RoundedDirection {
    if !compact_paths {
        return RoundedDirection(oct_encode(to_local(sf.frame, wi)), vec2u(0u));
    }
    let e = oct_encode(to_local(stored_frame(sf), wi));
    let ko = vec2u(oct_round(e.x), oct_round(e.y));
    return RoundedDirection(stored_direction(sf, sf.frame, ko), ko);
}

// With opts.both, the BSDF sample's radiance_prev holds what its further vertices bring
// back under the previous iteration's textures (the recursive estimator's second state).
// With opts.replay, the path's later vertices are differentiated on the way (camera_path):
// the pass defines differentiate_later_vertex. The first vertex is shaded only where its
// material has an optimized texture (opts.optimized_only is set here).
fn gradient_sample(o: vec3f, d: vec3f, opts: PathOptions) -> GradientSample {
    var out: GradientSample;
    var po = opts;
    po.optimized_only = true;
    let p = camera_path(o, d, po);
    out.valid = p.shaded && has_optimized(p.sf.material);
    if !out.valid {
        return out;
    }
    out.sf = p.sf;
    out.m = materials[p.sf.material];
    if opts.compact_paths {
        out.tri = p.hit.tri;
        out.kb = vec2u(bary_round(p.hit.b1), bary_round(p.hit.b2));
    }
    let wo_l = oct_decode(oct_encode(to_local(out.sf.frame, out.sf.wo)));
    for (var t = 0u; t < 2u; t++) {
        var ts: TechniqueSample;
        ts.ds = p.nee;
        ts.radiance_prev = p.nee.radiance;
        if t == SAMPLE_BSDF {
            ts.ds = p.bsdf;
            ts.radiance_prev = p.bsdf_prev;
        }
        ts.rgbe = 0u;
        if opts.compact_paths {
            // A radiance too large for any format is left as it is, so that the candidate
            // pass finds its value not finite and drops and counts it.
            ts.rgbe = rgbe_pack(ts.ds.radiance);
            if all(ts.ds.radiance < vec3f(3.0e38)) {
                ts.ds.radiance = rgbe_unpack(ts.rgbe);
            }
        }
        let wi = rounded_direction(out.sf, ts.ds.wi, opts.compact_paths);
        ts.ko = wi.ko;
        ts.vertex = path_vertex(out.sf, p.gltf, wi.oct);
        let wi_l = oct_decode(wi.oct);
        ts.grad = brdf_eval_cos_grad(p.mat, wo_l, wi_l);
        if out.m.param_normal != NONE {
            ts.grad.d_normal = normal_rgb_grad(out.sf, false, p.mat, wo_l, wi_l);
        }
        if t == SAMPLE_BSDF {
            out.bsdf = ts;
        } else {
            out.nee = ts;
        }
    }
    return out;
}
