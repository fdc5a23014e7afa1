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

fn nee_sample(sf: Surface, mat: SurfaceMaterial, u_pick: f32, u: vec2f) -> DirectSample {
    let ls = sample_light(sf.p, u_pick, u);
    if ls.pdf <= 0.0 || all(ls.radiance == vec3f(0.0)) || dot(ls.wi, sf.ng) <= 0.0 {
        return NO_SAMPLE;
    }
    var w = 1.0;
    if !ls.is_delta {
        let p_bsdf = brdf_pdf(mat, to_local(sf.frame, sf.wo), to_local(sf.frame, ls.wi));
        w = mis_light(ls.pdf, p_bsdf);
        if w <= 0.0 {
            return NO_SAMPLE;
        }
    }
    shadow_rays += 1u;
    if !unoccluded(sf, ls) {
        return NO_SAMPLE;
    }
    return DirectSample(ls.wi, ls.radiance, w / ls.pdf);
}

// Whether nothing lies between the shading point and the sampled light point. The segment runs
// from the offset origin to the light point itself, moved off an emitter's surface towards the
// shading point by the same relative offset, so that neither end hits its own surface. (A ray
// of length `dist` along wi from the offset origin would end past an emitter's plane wherever
// the origin's offset exceeds its margin along the plane's normal, and find the emitter itself
// in the way; tests/techniques.rs and tests/analytic.rs catch that.)
fn unoccluded(sf: Surface, ls: LightSample) -> bool {
    let o = offset_origin(sf, ls.wi);
    if ls.dist >= 3.0e38 {
        return !occluded(o, ls.wi, 3.0e38);
    }
    var q = sf.p + ls.dist * ls.wi;
    if any(ls.n != vec3f(0.0)) {
        let scale = 1e-4 * (1.0 + max(max(abs(q.x), abs(q.y)), abs(q.z)));
        q += ls.n * select(-scale, scale, dot(ls.n, -ls.wi) >= 0.0);
    }
    let to = q - o;
    let len = length(to);
    if len <= 0.0 {
        return true;
    }
    return !occluded(o, to / len, len * (1.0 - 1e-4));
}

fn bsdf_direct_sample(sf: Surface, mat: SurfaceMaterial, u: vec3f) -> DirectSample {
    let wo = to_local(sf.frame, sf.wo);
    let wi_local = brdf_sample(mat, wo, u);
    if wi_local.z <= 0.0 {
        return NO_SAMPLE;
    }
    let wi = to_world(sf.frame, wi_local);
    if dot(wi, sf.ng) <= 0.0 {
        return NO_SAMPLE;
    }
    let pdf = brdf_pdf(mat, wo, wi_local);
    if pdf <= 0.0 {
        return NO_SAMPLE;
    }
    bsdf_rays += 1u;
    let o = offset_origin(sf, wi);
    let hit = trace_closest(o, wi, 3.0e38);
    var le = vec3f(0.0);
    var p_light = 0.0;
    if hit.tri == NONE {
        le = env_radiance(wi);
        p_light = env_light_pdf(wi);
    } else {
        let p0 = tri_vertex(hit.tri, 0u);
        let ng = cross(tri_vertex(hit.tri, 1u) - p0, tri_vertex(hit.tri, 2u) - p0);
        le = emitted(hit.tri, hit.b1, hit.b2, dot(ng, wi) < 0.0);
        p_light = area_light_pdf(hit.tri, sf.p, o + hit.t * wi);
    }
    let w = mis_bsdf(pdf, p_light);
    if all(le == vec3f(0.0)) || w <= 0.0 {
        return NO_SAMPLE;
    }
    return DirectSample(wi, le, w / pdf);
}

// The two direct-lighting samples at a surface: light sampling, then BSDF sampling. Uses 6
// random numbers in a fixed order, so the primal and gradient passes draw the same samples
// from the same camera-sample index.
struct DirectSamples {
    nee: DirectSample,
    bsdf: DirectSample,
}

fn sample_direct(sf: Surface, mat: SurfaceMaterial) -> DirectSamples {
    let u_pick = rand();
    let u_light = rand2();
    let nee = nee_sample(sf, mat, u_pick, u_light);
    let u_bsdf = vec3f(rand(), rand2());
    let bsdf = bsdf_direct_sample(sf, mat, u_bsdf);
    return DirectSamples(nee, bsdf);
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
// MIS weights) under the previous iteration's textures (otherwise [1] = [0]).
fn direct_radiance_states(o: vec3f, d: vec3f, both: bool) -> array<vec3f, 2> {
    let hit = trace_closest(o, d, 3.0e38);
    if hit.tri == NONE {
        let e = env_radiance(d);
        return array<vec3f, 2>(e, e);
    }
    let sf = surface_at(o, hit);
    if !sf.valid {
        return array<vec3f, 2>(vec3f(0.0), vec3f(0.0));
    }
    let e = emitted(hit.tri, hit.b1, hit.b2, sf.front);
    let gltf = gltf_inputs(sf.material, sf.uv);
    let mat = with_optimized(sf.material, sf.uv, gltf);
    let s = sample_direct(sf, mat);
    let l = e + contribution(mat, sf, s.nee) + contribution(mat, sf, s.bsdf);
    if !both {
        return array<vec3f, 2>(l, l);
    }
    use_prev_params = true;
    let mat_prev = with_optimized(sf.material, sf.uv, gltf);
    use_prev_params = false;
    let l_prev = e + contribution(mat_prev, sf, s.nee) + contribution(mat_prev, sf, s.bsdf);
    return array<vec3f, 2>(l, l_prev);
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
    out.valid = false;
    var hit = trace_closest(o, d, 3.0e38);
    if hit.tri == NONE {
        return out;
    }
    if compact_paths {
        out.tri = hit.tri;
        out.kb = vec2u(bary_round(hit.b1), bary_round(hit.b2));
        hit = stored_hit(hit.tri, out.kb);
    }
    out.sf = surface_at(o, hit);
    out.m = materials[out.sf.material];
    let m = out.m;
    if !out.sf.valid || (m.param_base_color == NONE && m.param_metallic == NONE && m.param_roughness == NONE) {
        return out;
    }
    let gltf = gltf_inputs(out.sf.material, out.sf.uv);
    let mat = with_optimized(out.sf.material, out.sf.uv, gltf);
    let s = sample_direct(out.sf, mat);
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
