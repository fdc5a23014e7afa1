// Direct illumination at the first hit of a camera ray: emission seen directly, next-event
// estimation and BSDF sampling, combined by MIS (power heuristic). Each technique returns the
// sampled direction, the radiance arriving along it and the factor MIS weight / density, so
// that the contribution is brdf_eval_cos(wo, wi) x radiance x scale; the gradient passes
// reuse this split (ReSTIR stores the path, direction and radiance, without the factor).
#import shared/bvh
#import shared/surface
#import shared/compact_path

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
// sampling. The three rays (camera, shadow, BSDF) are traced at one call site, in a loop over
// these stages: a CPU device inlines every function call, so each call site of the traversal
// would be compiled anew (measured on lavapipe: about 1.5 s of pipeline creation each).
const STAGE_CAMERA: u32 = 0u;
const STAGE_SHADOW: u32 = 1u;
const STAGE_BSDF: u32 = 2u;
const STAGE_DONE: u32 = 3u;

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

fn has_optimized(mi: u32) -> bool {
    let m = materials[mi];
    return m.param_base_color != NONE || m.param_metallic != NONE || m.param_roughness != NONE;
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
    for (var ray = 0u; ray < 3u && stage != STAGE_DONE; ray++) {
        var hit = trace_ray(ray_o, ray_d, ray_tmax, stage == STAGE_SHADOW);
        var next_bsdf = false;
        if stage == STAGE_SHADOW {
            if hit.tri == NONE {
                out.nee = DirectSample(ls.wi, ls.radiance, nee_weight / ls.pdf);
            }
            next_bsdf = true;
        } else {
            // The camera ray or the BSDF ray: what arrives along it.
            var front = false;
            if stage == STAGE_CAMERA && hit.tri != NONE {
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
            var p_light = 0.0;
            if hit.tri == NONE {
                le = env_radiance(ray_d);
                if stage == STAGE_BSDF {
                    p_light = env_light_pdf(ray_d);
                }
            } else {
                // Zero at the back of a single-sided surface (which shades black).
                le = emitted(hit.tri, hit.b1, hit.b2, front);
                if stage == STAGE_BSDF {
                    p_light = area_light_pdf(hit.tri, out.sf.p, ray_o + hit.t * ray_d);
                }
            }
            if stage == STAGE_BSDF {
                let w = mis_bsdf(bsdf_pdf, p_light);
                if !(all(le == vec3f(0.0)) || w <= 0.0) {
                    out.bsdf = DirectSample(ray_d, le, w / bsdf_pdf);
                }
                stage = STAGE_DONE;
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
                    next_bsdf = true;
                    ls = sample_light(sf.p, u_pick, u_light);
                    if !(ls.pdf <= 0.0 || all(ls.radiance == vec3f(0.0)) || dot(ls.wi, sf.ng) <= 0.0) {
                        nee_weight = 1.0;
                        if !ls.is_delta {
                            let p_bsdf = brdf_pdf(out.mat, to_local(sf.frame, sf.wo), to_local(sf.frame, ls.wi));
                            nee_weight = mis_light(ls.pdf, p_bsdf);
                        }
                        if !(nee_weight <= 0.0) {
                            shadow_rays += 1u;
                            // The shadow segment runs from the offset origin to the light
                            // point itself, moved off an emitter's surface towards the shading
                            // point by the same relative offset, so that neither end hits its
                            // own surface. (A ray of length `dist` along wi from the offset
                            // origin would end past an emitter's plane wherever the origin's
                            // offset exceeds its margin along the plane's normal, and find the
                            // emitter itself in the way; tests/techniques.rs and
                            // tests/analytic.rs catch that.)
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
// rounded as ReSTIR stores them (shared/compact_path.wgsl) before anything is evaluated, so
// that a stored path (stored_vertex, path_factor) re-evaluates to the same value.
var<private> compact_paths: bool = false;

struct GradientSample {
    valid: bool,
    sf: Surface,
    m: Material,
    nee: DirectSample,
    nee_grad: BrdfGrad,
    // The path of each technique as the BRDF sees it.
    nee_vertex: PathVertex,
    bsdf: DirectSample,
    bsdf_grad: BrdfGrad,
    bsdf_vertex: PathVertex,
    // With compact_paths: the hit's triangle and fixed-point barycentrics, and each
    // technique's fixed-point direction and RGBE radiance (shared/compact_path.wgsl).
    tri: u32,
    kb: vec2u,
    nee_ko: vec2u,
    nee_rgbe: u32,
    bsdf_ko: vec2u,
    bsdf_rgbe: u32,
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
    let gltf = p.gltf;
    let mat = p.mat;
    let s = p;
    out.nee = s.nee;
    out.bsdf = s.bsdf;
    if compact_paths {
        // A radiance too large for any format is left as it is, so that the candidate pass
        // finds its value not finite and drops and counts it.
        out.nee_rgbe = rgbe_pack(s.nee.radiance);
        if all(s.nee.radiance < vec3f(3.0e38)) {
            out.nee.radiance = rgbe_unpack(out.nee_rgbe);
        }
        out.bsdf_rgbe = rgbe_pack(s.bsdf.radiance);
        if all(s.bsdf.radiance < vec3f(3.0e38)) {
            out.bsdf.radiance = rgbe_unpack(out.bsdf_rgbe);
        }
    }
    let nee_wi = rounded_direction(out.sf, s.nee.wi);
    let bsdf_wi = rounded_direction(out.sf, s.bsdf.wi);
    out.nee_ko = nee_wi.ko;
    out.bsdf_ko = bsdf_wi.ko;
    out.nee_vertex = path_vertex(out.sf, gltf, nee_wi.oct);
    out.bsdf_vertex = path_vertex(out.sf, gltf, bsdf_wi.oct);
    let wo_l = oct_decode(out.nee_vertex.wo);
    out.nee_grad = brdf_eval_cos_grad(mat, wo_l, oct_decode(nee_wi.oct));
    out.bsdf_grad = brdf_eval_cos_grad(mat, wo_l, oct_decode(bsdf_wi.oct));
    out.valid = true;
    return out;
}
