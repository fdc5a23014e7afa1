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

// Which techniques contribute to area and environment lights (delta lights always use NEE).
var<private> techniques: u32 = TECH_MIS;
var<private> shadow_rays: u32 = 0u;
var<private> bsdf_rays: u32 = 0u;
// Whether camera_path calls the pass's differentiate_env(direction, factor) for every segment
// that escapes to the environment (a gradient pass sets it when the environment is
// optimized): shared/env_gradient.wgsl. The first vertex is then shaded on every material.
var<private> env_gradients: bool = false;
// With compact_paths (ReSTIR's candidates) the camera ray's hit (and with record_paths every
// vertex) is moved to the fixed-point barycentrics ReSTIR stores, and gradient_sample rounds
// the incident directions and the radiances to the compact path encoding
// (shared/path_encoding.wgsl) before anything is evaluated, so that a stored path
// (stored_vertex, path_factor) re-evaluates to the same value.
var<private> compact_paths: bool = false;

// With record_paths (ReSTIR's candidates keeping whole paths, restir_candidates.wgsl), the
// path's first PATH_RECORD_VERTICES vertices (triangle and fixed-point barycentrics, the
// camera ray's hit first; with compact_paths every vertex is moved to the barycentrics stored)
// and every sample that reaches an emitter from one of them (an arrival): the path of `n`
// vertices that it ends, the direction from its last vertex, the radiance arriving (unweighted)
// and its factor, MIS weight / density of the whole path (the BSDF samples' densities that led
// to the last vertex included). Such a path's contribution is its radiance times every
// vertex's BRDF x cos times the factor. camera_path also shades a first vertex without
// optimized textures then.
const PATH_RECORD_VERTICES: u32 = 3u;
var<private> record_paths: bool = false;
var<private> rec_tri: array<u32, PATH_RECORD_VERTICES>;
var<private> rec_kb: array<vec2u, PATH_RECORD_VERTICES>;

struct Arrival {
    n: u32,
    wi: vec3f,
    radiance: vec3f,
    scale: f32,
}

var<private> arrivals: array<Arrival, 6>;
var<private> n_arrivals: u32 = 0u;

fn record_arrival(n: u32, wi: vec3f, radiance: vec3f, scale: f32) {
    if record_paths && n <= PATH_RECORD_VERTICES && n_arrivals < 6u {
        arrivals[n_arrivals] = Arrival(n, wi, radiance, scale);
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

fn mis_light(p_light: f32, p_bsdf: f32) -> f32 {
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

fn mis_bsdf(p_bsdf: f32, p_light: f32) -> f32 {
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
    // single-sided surface, and (with optimized_only, unless replay at depth > 1) on a
    // material without optimized textures. Only e is set otherwise.
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

// Uses 6 random numbers per vertex in a fixed order (light choice, light sample, BSDF sample;
// then, from vertex RR_VERTEX on, one for Russian roulette before them), so that the primal
// and gradient passes draw the same samples from the same camera-sample index (options:
// PathOptions, below). With `both`, the vertices after the first are also evaluated under the previous iteration's textures
// (same directions, densities and MIS weights), for bsdf_prev.
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
// What a camera path computes besides its value, set by name at every call site
// (path_options, then the fields): optimized_only shades the first vertex only where its
// material has an optimized texture (the gradient passes); both and replay as above.
struct PathOptions {
    optimized_only: bool,
    both: bool,
    replay: bool,
}

// No option set: the path's value under the current textures.
fn path_options() -> PathOptions {
    return PathOptions(false, false, false);
}

fn camera_path(o: vec3f, d: vec3f, opts: PathOptions) -> CameraPath {
    let optimized_only = opts.optimized_only;
    let both = opts.both;
    let replay = opts.replay;
    var out: CameraPath;
    out.hit = Hit(3.0e38, NONE, 0.0, 0.0);
    out.shaded = false;
    out.e = vec3f(0.0);
    out.nee = NO_SAMPLE;
    out.bsdf = NO_SAMPLE;
    out.bsdf_prev = vec3f(0.0);
    let max_depth = max(scene.max_depth, 1u);
    let rng_start = rng_state;
    // Whether the path is being replayed (with `replay`) to differentiate later vertices,
    // knowing what it brought back in all (ind_total, ind_prev_total).
    var replaying = false;
    var ind_total = vec3f(0.0);
    var ind_prev_total = vec3f(0.0);
    var later_optimized = false;
    var ray_o = o;
    var ray_d = d;
    var ray_tmax = 3.0e38;
    var stage = STAGE_CAMERA;
    var ls: LightSample;
    var nee_weight = 0.0;
    var u_bsdf = vec3f(0.0);
    var bsdf_pdf = 0.0;
    // The vertex whose samples are being traced (1 = the camera ray's hit, 0 before it is
    // shaded), its surface and material under the current and (with both) the previous
    // textures.
    var depth = 0u;
    var vsf: Surface;
    var vmat: SurfaceMaterial;
    var vmat_prev: SurfaceMaterial;
    // The surface at the hit of a ray that a vertex is shaded at next.
    var next_sf: Surface;
    // From vertex 2 on: the throughput from vertex 2 to this vertex (1 at vertex 2) and to the
    // next one along the BSDF sample, under each state, and the radiance gathered so far,
    // arriving at the first vertex along its BSDF sample (before its BRDF and density).
    var beta = vec3f(1.0);
    var beta_prev = vec3f(1.0);
    var beta_next = vec3f(1.0);
    var beta_next_prev = vec3f(1.0);
    var ind = vec3f(0.0);
    var ind_prev = vec3f(0.0);
    // The first vertex's BRDF x cos / density along its BSDF sample (for Russian roulette and
    // the later vertices' derivatives), under each state.
    var first_weight = vec3f(1.0);
    var first_weight_prev = vec3f(1.0);
    // The first vertex's BSDF sample: its direction, density and the MIS-weighted emission
    // it finds.
    var first_wi = vec3f(0.0, 0.0, 1.0);
    var first_pdf = 0.0;
    var first_e = vec3f(0.0);
    // With env_gradients: the direction of this step's escape to the environment (zero for
    // none) and the MIS weight / density its radiance is multiplied by at its vertex.
    var env_dir = vec3f(0.0);
    var env_factor = 0.0;
    // With record_paths: 1 / the densities of the BSDF samples that led to this vertex (and
    // to the next one), and the next vertex's triangle and barycentrics.
    var path_scale = 1.0;
    var path_scale_next = 1.0;
    var next_tri = NONE;
    var next_kb = vec2u(0u);
    n_arrivals = 0u;
    let steps = (1u + 3u * max_depth) * select(1u, 2u, replay && max_depth > 1u);
    for (var step = 0u; step < steps && stage != STAGE_DONE; step++) {
        var hit = Hit(ray_tmax, NONE, 0.0, 0.0);
        if stage != STAGE_LIGHT {
            hit = trace_ray(ray_o, ray_d, ray_tmax, stage == STAGE_SHADOW);
        }
        var next_bsdf = false;
        var nee_arrives = false;
        var shade = false;
        // After the first vertex: the direction in which this vertex's BRDF is evaluated in
        // this step (zero for none), and the radiance arriving along it, weighted by MIS
        // and density (from a light sample, or the emission a BSDF sample found).
        var eval_wi = vec3f(0.0);
        var arrives = vec3f(0.0);
        // Whether eval_wi is the direction of the BSDF sample that leads to the next vertex.
        var to_next = false;
        env_dir = vec3f(0.0);
        if stage == STAGE_SHADOW {
            nee_arrives = hit.tri == NONE;
            next_bsdf = true;
        } else {
            // What arrives: from the emitter point (tri, b) seen from its front or back, or
            // from the environment along dir when tri is NONE.
            var tri = hit.tri;
            var dir = ray_d;
            var front = false;
            // A hit that becomes the next vertex: the camera ray's, or a BSDF sample's below
            // the maximum depth.
            let continues = stage == STAGE_CAMERA || (stage == STAGE_BSDF && depth < max_depth);
            if stage == STAGE_LIGHT {
                tri = ls.tri;
                hit.b1 = ls.b.x;
                hit.b2 = ls.b.y;
                dir = ls.wi;
                front = ls.front;
            } else if continues && hit.tri != NONE {
                if compact_paths && (stage == STAGE_CAMERA || record_paths) {
                    // (The distance is kept: a BSDF sample's hit on an emitter reads it.)
                    next_kb = vec2u(bary_round(hit.b1), bary_round(hit.b2));
                    let t = hit.t;
                    hit = stored_hit(hit.tri, next_kb);
                    hit.t = t;
                }
                next_tri = hit.tri;
                next_sf = surface_at(ray_o, hit);
                if stage == STAGE_CAMERA {
                    out.hit = hit;
                    out.sf = next_sf;
                }
                front = next_sf.front;
            } else if hit.tri != NONE {
                let p0 = tri_vertex(hit.tri, 0u);
                let ng = cross(tri_vertex(hit.tri, 1u) - p0, tri_vertex(hit.tri, 2u) - p0);
                front = dot(ng, ray_d) < 0.0;
            }
            var le = vec3f(0.0);
            // The environment's density in direction dir, light choice included.
            var p_env = 0.0;
            if !(stage == STAGE_LIGHT && ls.is_delta) {
                if tri == NONE {
                    le = env_radiance(dir);
                    if stage != STAGE_CAMERA {
                        p_env = env_light_pdf(dir);
                    }
                } else {
                    // Zero at the back of a single-sided surface (which shades black).
                    le = emitted(tri, hit.b1, hit.b2, front);
                }
            }
            if stage == STAGE_BSDF {
                var p_light = p_env;
                if hit.tri != NONE {
                    p_light = area_light_pdf(hit.tri, vsf.p, ray_o + hit.t * ray_d);
                }
                let w = mis_bsdf(bsdf_pdf, p_light);
                if !(all(le == vec3f(0.0)) || w <= 0.0) {
                    record_arrival(depth, ray_d, le, path_scale * w / bsdf_pdf);
                    if depth == 1u {
                        out.bsdf = DirectSample(ray_d, le, w / bsdf_pdf);
                        first_e = le * w;
                    } else {
                        arrives = le * w;
                    }
                    if env_gradients && hit.tri == NONE {
                        env_dir = ray_d;
                        env_factor = w / bsdf_pdf;
                    }
                }
                if max_depth > 1u || any(env_dir != vec3f(0.0)) {
                    eval_wi = ray_d;
                    to_next = true;
                }
                stage = STAGE_DONE;
                shade = continues && hit.tri != NONE && next_sf.valid;
            } else if stage == STAGE_LIGHT {
                if ls.env {
                    ls.radiance = le;
                    ls.pdf = p_env;
                } else if !ls.is_delta {
                    ls.radiance = le;
                }
                let sf = vsf;
                stage = STAGE_DONE;
                next_bsdf = true;
                if !(ls.pdf <= 0.0 || all(ls.radiance == vec3f(0.0)) || dot(ls.wi, sf.ng) <= 0.0) {
                    nee_weight = 1.0;
                    if !ls.is_delta {
                        let p_bsdf = brdf_pdf(vmat, to_local(sf.frame, sf.wo), to_local(sf.frame, ls.wi));
                        nee_weight = mis_light(ls.pdf, p_bsdf);
                    }
                    if !(nee_weight <= 0.0) {
                        shadow_rays += 1u;
                        // The shadow segment runs from the offset origin to the light point
                        // itself, moved off an emitter's surface towards the shading point by
                        // the same relative offset, so that neither end hits its own surface.
                        // (A ray of length `dist` along wi from the offset origin would end
                        // past an emitter's plane wherever the origin's offset exceeds its
                        // margin along the plane's normal, and find the emitter itself in the
                        // way; tests/techniques.rs and tests/analytic.rs catch that.)
                        let so = offset_origin(sf, ls.wi);
                        if ls.dist >= 3.0e38 {
                            ray_o = so;
                            ray_d = ls.wi;
                            ray_tmax = 3.0e38;
                            stage = STAGE_SHADOW;
                        } else {
                            var q = sf.p + ls.dist * ls.wi;
                            if any(ls.n != vec3f(0.0)) {
                                let scale = 1e-4 * (1.0 + max(max(abs(q.x), abs(q.y)), abs(q.z)));
                                q += ls.n * select(-scale, scale, dot(ls.n, -ls.wi) >= 0.0);
                            }
                            let to = q - so;
                            let len = length(to);
                            if len <= 0.0 {
                                nee_arrives = true;
                            } else {
                                ray_o = so;
                                ray_d = to / len;
                                ray_tmax = len * (1.0 - 1e-4);
                                stage = STAGE_SHADOW;
                            }
                        }
                        if stage == STAGE_SHADOW {
                            next_bsdf = false;
                        }
                    }
                }
            } else {
                out.e = le;
                if env_gradients && tri == NONE && !replaying {
                    differentiate_env(dir, vec3f(1.0));
                }
                stage = STAGE_DONE;
                // (With replay, a path whose first vertex is not optimized may still reach one.)
                shade = hit.tri != NONE && next_sf.valid && (!optimized_only || has_optimized(next_sf.material) || (replay && max_depth > 1u) || env_gradients || record_paths);
                out.shaded = shade;
            }
        }
        if nee_arrives {
            record_arrival(depth, ls.wi, ls.radiance, path_scale * nee_weight / ls.pdf);
            if env_gradients && ls.env {
                env_dir = ls.wi;
                env_factor = nee_weight / ls.pdf;
            }
            if depth == 1u {
                out.nee = DirectSample(ls.wi, ls.radiance, nee_weight / ls.pdf);
                if any(env_dir != vec3f(0.0)) {
                    eval_wi = ls.wi;
                }
            } else {
                eval_wi = ls.wi;
                arrives = ls.radiance * (nee_weight / ls.pdf);
            }
        }
        if any(eval_wi != vec3f(0.0)) {
            // The vertex's BRDF x cos towards eval_wi under each state, at one call site (the
            // light sample's and the BSDF sample's; see above). A BSDF sample's carries the
            // path on to the next vertex (beta_next); at the first vertex it only weighs
            // Russian roulette.
            let wo = to_local(vsf.frame, vsf.wo);
            let wi = to_local(vsf.frame, eval_wi);
            // What the rest of the path brings back from here (replay only).
            let rest = ind_total - ind;
            let rest_prev = ind_prev_total - ind_prev;
            var fc = vec3f(0.0);
            var fc_prev = vec3f(0.0);
            for (var state = 0u; state < select(1u, 2u, both); state++) {
                var m = vmat;
                var b = beta;
                var wo_s = wo;
                var wi_s = wi;
                if state == 1u {
                    m = vmat_prev;
                    b = beta_prev;
                    if materials[vsf.material].param_normal != NONE {
                        // (The previous normal map's frame; the directions are the same.)
                        let frame_prev = frame_of(vsf, true);
                        wo_s = to_local(frame_prev, vsf.wo);
                        wi_s = to_local(frame_prev, eval_wi);
                    }
                }
                var f = brdf_eval_cos(m, wo_s, wi_s);
                if state == 0u {
                    fc = f;
                } else {
                    fc_prev = f;
                }
                if to_next {
                    f /= bsdf_pdf;
                }
                if depth == 1u {
                    // (At the first vertex a light sample is evaluated here only for the
                    // environment's derivative.)
                    if to_next && state == 0u {
                        first_weight = f;
                    } else if to_next {
                        first_weight_prev = f;
                    }
                } else if to_next {
                    if state == 0u {
                        beta_next = b * f;
                        ind += beta_next * arrives;
                    } else {
                        beta_next_prev = b * f;
                        ind_prev += beta_next_prev * arrives;
                    }
                } else if state == 0u {
                    ind += b * f * arrives;
                } else {
                    ind_prev += b * f * arrives;
                }
            }
            if any(env_dir != vec3f(0.0)) && !replaying {
                // The escape's factor on the way to the pixel: the throughput to this vertex
                // (1 at the first), its BRDF x cos, the MIS weight / density.
                var through = vec3f(1.0);
                if depth > 1u {
                    through = first_weight * beta;
                }
                differentiate_env(env_dir, through * fc * env_factor);
            }
            if replaying && depth > 1u && has_optimized(vsf.material) {
                var w = first_weight * beta * arrives;
                var w_prev = first_weight_prev * beta_prev * arrives;
                if to_next {
                    w = first_weight * select(vec3f(0.0), rest / fc, fc > vec3f(0.0));
                    w_prev = first_weight_prev * select(vec3f(0.0), rest_prev / fc_prev, fc_prev > vec3f(0.0));
                }
                differentiate_later_vertex(vsf, eval_wi, vmat, vmat_prev, w, w_prev);
            }
        }
        if shade {
            // The hit becomes the next vertex: the first at the camera ray's hit.
            depth += 1u;
            vsf = next_sf;
            if record_paths && depth <= PATH_RECORD_VERTICES {
                rec_tri[depth - 1u] = next_tri;
                rec_kb[depth - 1u] = next_kb;
            }
            let gltf = gltf_inputs(vsf.material, vsf.uv);
            // The optimized inputs under each state, at one call site.
            for (var state = 0u; state < select(1u, 2u, both); state++) {
                use_prev_params = state == 1u;
                let m = with_optimized(vsf.material, vsf.uv, gltf);
                if state == 0u {
                    vmat = m;
                } else {
                    vmat_prev = m;
                }
            }
            use_prev_params = false;
            if depth == 1u {
                out.gltf = gltf;
                out.mat = vmat;
                out.mat_prev = vmat_prev;
            } else {
                later_optimized = later_optimized || has_optimized(vsf.material);
                beta = beta_next;
                beta_prev = beta_next_prev;
                path_scale = path_scale_next;
                if depth >= RR_VERTEX {
                    let q = min(max_component(beta * first_weight), 0.95);
                    if rand() < q {
                        beta /= q;
                        beta_prev /= q;
                        path_scale /= q;
                    } else {
                        shade = false;
                    }
                }
            }
            if shade {
                let u_pick = rand();
                let u_light = rand2();
                u_bsdf = vec3f(rand(), rand2());
                ls = sample_light(vsf.p, u_pick, u_light);
                stage = STAGE_LIGHT;
            }
        }
        if next_bsdf {
            stage = STAGE_DONE;
            let wo = to_local(vsf.frame, vsf.wo);
            let wi_local = brdf_sample(vmat, wo, u_bsdf);
            let wi = to_world(vsf.frame, wi_local);
            if !(wi_local.z <= 0.0 || dot(wi, vsf.ng) <= 0.0) {
                bsdf_pdf = brdf_pdf(vmat, wo, wi_local);
                if !(bsdf_pdf <= 0.0) {
                    bsdf_rays += 1u;
                    ray_o = offset_origin(vsf, wi);
                    ray_d = wi;
                    ray_tmax = 3.0e38;
                    stage = STAGE_BSDF;
                    path_scale_next = path_scale / bsdf_pdf;
                    if depth == 1u {
                        first_wi = wi;
                        first_pdf = bsdf_pdf;
                    }
                }
            }
        }
        if stage == STAGE_DONE && replay && !replaying && later_optimized && (any(ind != vec3f(0.0)) || any(ind_prev != vec3f(0.0))) {
            // Replay: the same path from the same random numbers, now knowing its total.
            replaying = true;
            ind_total = ind;
            ind_prev_total = ind_prev;
            ind = vec3f(0.0);
            ind_prev = vec3f(0.0);
            rng_state = rng_start;
            ray_o = o;
            ray_d = d;
            ray_tmax = 3.0e38;
            stage = STAGE_CAMERA;
            depth = 0u;
            beta_next = vec3f(1.0);
            beta_next_prev = vec3f(1.0);
        }
    }
    out.bsdf_prev = out.bsdf.radiance;
    if any(ind != vec3f(0.0)) || any(ind_prev != vec3f(0.0)) {
        out.bsdf = DirectSample(first_wi, first_e + ind, 1.0 / first_pdf);
        out.bsdf_prev = first_e + ind_prev;
    }
    return out;
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
// [0] under the current textures and, when `both`, [1] the same path (same hits, samples and
// MIS weights) under the previous iteration's textures (otherwise [1] = [0]). The first
// vertex's two techniques' contributions under each state are added in one loop, for the
// reason camera_path traces in one.
fn radiance_states(o: vec3f, d: vec3f, both: bool) -> array<vec3f, 2> {
    var po = path_options();
    po.both = both;
    let p = camera_path(o, d, po);
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

fn rounded_direction(sf: Surface, wi: vec3f) -> RoundedDirection {
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
    if compact_paths {
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
        if compact_paths {
            // A radiance too large for any format is left as it is, so that the candidate
            // pass finds its value not finite and drops and counts it.
            ts.rgbe = rgbe_pack(ts.ds.radiance);
            if all(ts.ds.radiance < vec3f(3.0e38)) {
                ts.ds.radiance = rgbe_unpack(ts.rgbe);
            }
        }
        let wi = rounded_direction(out.sf, ts.ds.wi);
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
