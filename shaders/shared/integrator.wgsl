// Direct illumination at the first hit of a camera ray: emission seen directly, next-event
// estimation and BSDF sampling, combined by MIS (power heuristic). Each technique returns the
// sampled direction, the radiance arriving along it and the factor MIS weight / density, so
// that the contribution is brdf_eval_cos(wo, wi) x radiance x scale; the gradient passes
// reuse this split (ReSTIR stores the path, direction and radiance, without the factor).
#import shared/bvh
#import shared/surface
#import shared/path_encoding

// Which techniques contribute to area and environment lights (delta lights always use NEE).
var<private> techniques: u32 = TECH_MIS;
var<private> shadow_rays: u32 = 0u;
var<private> bsdf_rays: u32 = 0u;

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

// The first hit of a camera ray and its two direct samples: light sampling (NEE), then BSDF
// sampling. A CPU device inlines every function call, so each call site of a function is
// compiled anew (measured on lavapipe: about 1.5 s of pipeline creation per traversal). So
// the three rays (camera, shadow, BSDF) are traced at one call site, in a loop over these
// stages, and what arrives at the shading point (emission at a hit, an area light's point,
// the environment in a direction) is evaluated at one call site too: STAGE_LIGHT traces
// nothing and evaluates the sampled light's point there.
const STAGE_CAMERA: u32 = 0u;
const STAGE_LIGHT: u32 = 1u;
const STAGE_SHADOW: u32 = 2u;
const STAGE_BSDF: u32 = 3u;
const STAGE_DONE: u32 = 4u;

struct DirectPath {
    // The camera ray's hit (tri NONE on a miss); with compact_paths, at the barycentrics
    // ReSTIR stores.
    hit: Hit,
    // Whether the hit was shaded and its samples drawn: false on a miss, at the back of a
    // single-sided surface, and (with optimized_only) on a material without optimized
    // textures. Only e is set otherwise.
    shaded: bool,
    sf: Surface,
    // The inputs that the glTF material gives, and those with the optimized textures.
    gltf: SurfaceMaterial,
    mat: SurfaceMaterial,
    // Radiance along the camera ray itself: the environment on a miss, emission at a hit.
    e: vec3f,
    nee: DirectSample,
    bsdf: DirectSample,
}

// Whether material mi has an optimized texture (fields read one by one: a CPU device loads
// every word of a struct read at a per-invocation index).
fn has_optimized(mi: u32) -> bool {
    return materials[mi].param_base_color != NONE || materials[mi].param_metallic != NONE || materials[mi].param_roughness != NONE;
}

// Uses 6 random numbers in a fixed order (light choice, light sample, BSDF sample), so that
// the primal and gradient passes draw the same samples from the same camera-sample index.
fn direct_path(o: vec3f, d: vec3f, optimized_only: bool) -> DirectPath {
    var out: DirectPath;
    out.hit = Hit(3.0e38, NONE, 0.0, 0.0);
    out.shaded = false;
    out.e = vec3f(0.0);
    out.nee = NO_SAMPLE;
    out.bsdf = NO_SAMPLE;
    var ray_o = o;
    var ray_d = d;
    var ray_tmax = 3.0e38;
    var stage = STAGE_CAMERA;
    var ls: LightSample;
    var nee_weight = 0.0;
    var u_bsdf = vec3f(0.0);
    var bsdf_pdf = 0.0;
    for (var step = 0u; step < 4u && stage != STAGE_DONE; step++) {
        var hit = Hit(ray_tmax, NONE, 0.0, 0.0);
        if stage != STAGE_LIGHT {
            hit = trace_ray(ray_o, ray_d, ray_tmax, stage == STAGE_SHADOW);
        }
        var next_bsdf = false;
        if stage == STAGE_SHADOW {
            if hit.tri == NONE {
                out.nee = DirectSample(ls.wi, ls.radiance, nee_weight / ls.pdf);
            }
            next_bsdf = true;
        } else {
            // What arrives: from the emitter point (tri, b) seen from its front or back, or
            // from the environment along dir when tri is NONE.
            var tri = hit.tri;
            var dir = ray_d;
            var front = false;
            if stage == STAGE_LIGHT {
                tri = ls.tri;
                hit.b1 = ls.b.x;
                hit.b2 = ls.b.y;
                dir = ls.wi;
                front = ls.front;
            } else if stage == STAGE_CAMERA && hit.tri != NONE {
                if compact_paths {
                    hit = stored_hit(hit.tri, vec2u(bary_round(hit.b1), bary_round(hit.b2)));
                }
                out.hit = hit;
                out.sf = surface_at(o, hit);
                front = out.sf.front;
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
                    p_light = area_light_pdf(hit.tri, out.sf.p, ray_o + hit.t * ray_d);
                }
                let w = mis_bsdf(bsdf_pdf, p_light);
                if !(all(le == vec3f(0.0)) || w <= 0.0) {
                    out.bsdf = DirectSample(ray_d, le, w / bsdf_pdf);
                }
                stage = STAGE_DONE;
            } else if stage == STAGE_LIGHT {
                if ls.env {
                    ls.radiance = le;
                    ls.pdf = p_env;
                } else if !ls.is_delta {
                    ls.radiance = le;
                }
                let sf = out.sf;
                stage = STAGE_DONE;
                next_bsdf = true;
                if !(ls.pdf <= 0.0 || all(ls.radiance == vec3f(0.0)) || dot(ls.wi, sf.ng) <= 0.0) {
                    nee_weight = 1.0;
                    if !ls.is_delta {
                        let p_bsdf = brdf_pdf(out.mat, to_local(sf.frame, sf.wo), to_local(sf.frame, ls.wi));
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
                                out.nee = DirectSample(ls.wi, ls.radiance, nee_weight / ls.pdf);
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
                stage = STAGE_DONE;
                if hit.tri != NONE && out.sf.valid && (!optimized_only || has_optimized(out.sf.material)) {
                    out.shaded = true;
                    let sf = out.sf;
                    out.gltf = gltf_inputs(sf.material, sf.uv);
                    out.mat = with_optimized(sf.material, sf.uv, out.gltf);
                    let u_pick = rand();
                    let u_light = rand2();
                    u_bsdf = vec3f(rand(), rand2());
                    ls = sample_light(sf.p, u_pick, u_light);
                    stage = STAGE_LIGHT;
                }
            }
        }
        if next_bsdf {
            stage = STAGE_DONE;
            let wo = to_local(out.sf.frame, out.sf.wo);
            let wi_local = brdf_sample(out.mat, wo, u_bsdf);
            let wi = to_world(out.sf.frame, wi_local);
            if !(wi_local.z <= 0.0 || dot(wi, out.sf.ng) <= 0.0) {
                bsdf_pdf = brdf_pdf(out.mat, wo, wi_local);
                if !(bsdf_pdf <= 0.0) {
                    bsdf_rays += 1u;
                    ray_o = offset_origin(out.sf, wi);
                    ray_d = wi;
                    ray_tmax = 3.0e38;
                    stage = STAGE_BSDF;
                }
            }
        }
    }
    return out;
}

fn contribution(mat: SurfaceMaterial, sf: Surface, s: DirectSample) -> vec3f {
    if s.scale == 0.0 {
        return vec3f(0.0);
    }
    let wo = to_local(sf.frame, sf.wo);
    return brdf_eval_cos(mat, wo, to_local(sf.frame, s.wi)) * s.radiance * s.scale;
}

// Radiance along a camera ray (origin o, unit direction d) with direct illumination only:
// [0] under the current textures and, when `both`, [1] the same path (same hit, samples and
// MIS weights) under the previous iteration's textures (otherwise [1] = [0]). The two
// techniques' contributions under each state are added in one loop, for the reason
// direct_path traces in one.
fn direct_radiance_states(o: vec3f, d: vec3f, both: bool) -> array<vec3f, 2> {
    let p = direct_path(o, d, false);
    var l = array<vec3f, 2>(p.e, p.e);
    if !p.shaded {
        return l;
    }
    var mat = p.mat;
    let terms = select(2u, 4u, both);
    for (var j = 0u; j < terms; j++) {
        if j == 2u {
            use_prev_params = true;
            mat = with_optimized(p.sf.material, p.sf.uv, p.gltf);
            use_prev_params = false;
        }
        var s = p.nee;
        if (j & 1u) == 1u {
            s = p.bsdf;
        }
        l[j / 2u] += contribution(mat, p.sf, s);
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
// octahedral encoding (about 1e-7), and the derivatives are taken there. With compact_paths
// (ReSTIR's candidates) the hit's barycentrics, the incident directions and the radiances are
// rounded to the compact path encoding (shared/path_encoding.wgsl) before anything is evaluated, so
// that a stored path (stored_vertex, path_factor) re-evaluates to the same value.
var<private> compact_paths: bool = false;

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
    // rather than naming each, so that their code is compiled once (see direct_path).
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

// The octahedral coordinates of wi (world space) in sf's frame, rounded to the fixed point
// ReSTIR stores when compact_paths (ko: the fixed-point values).
struct RoundedDirection {
    oct: vec2f,
    ko: vec2u,
}

fn rounded_direction(sf: Surface, wi: vec3f) -> RoundedDirection {
    let e = oct_encode(to_local(sf.frame, wi));
    if !compact_paths {
        return RoundedDirection(e, vec2u(0u));
    }
    let ko = vec2u(oct_round(e.x), oct_round(e.y));
    return RoundedDirection(vec2f(oct_value(ko.x), oct_value(ko.y)), ko);
}

fn gradient_sample(o: vec3f, d: vec3f) -> GradientSample {
    var out: GradientSample;
    let p = direct_path(o, d, true);
    out.valid = p.shaded;
    if !p.shaded {
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
        if t == SAMPLE_BSDF {
            ts.ds = p.bsdf;
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
        ts.grad = brdf_eval_cos_grad(p.mat, wo_l, oct_decode(wi.oct));
        if t == SAMPLE_BSDF {
            out.bsdf = ts;
        } else {
            out.nee = ts;
        }
    }
    return out;
}
