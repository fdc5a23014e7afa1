// Direct illumination at the first hit of a camera ray: emission seen directly, next-event
// estimation and BSDF sampling, combined by MIS (power heuristic). Each technique returns the
// sampled direction and a light weight (incident radiance x MIS weight / density), so that the
// contribution is brdf_eval_cos(wo, wi) x weight; the gradient pass reuses this split.
#import shared/bvh
#import shared/lights
#import shared/brdf
#import shared/params

const TECH_NEE: u32 = 1u;
const TECH_BSDF: u32 = 2u;
const TECH_MIS: u32 = 3u;

// Which techniques contribute to area and environment lights (delta lights always use NEE).
var<private> techniques: u32 = TECH_MIS;
var<private> shadow_rays: u32 = 0u;
var<private> bsdf_rays: u32 = 0u;
// Set by ReSTIR's replays of light samples that were unoccluded when drawn: geometry does not
// change during texture optimization, so the shadow ray would find the same answer.
var<private> assume_visible: bool = false;

struct Surface {
    p: vec3f,
    ng: vec3f,
    frame: mat3x3f,
    wo: vec3f,
    uv: vec2f,
    material: u32,
    front: bool,
    valid: bool,
}

struct DirectSample {
    wi: vec3f,
    weight: vec3f,
}

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

// Geometry at a hit, normals turned towards the viewer for double-sided materials.
// valid is false for the back of a single-sided surface (it shades black).
fn surface_at(o: vec3f, d: vec3f, hit: Hit) -> Surface {
    let tri = hit.tri;
    let s = tri_shading[tri];
    let b0 = 1.0 - hit.b1 - hit.b2;
    let p0 = tri_vertex(tri, 0u);
    var ng = normalize(cross(tri_vertex(tri, 1u) - p0, tri_vertex(tri, 2u) - p0));
    var ns = b0 * s.n0.xyz + hit.b1 * s.n1.xyz + hit.b2 * s.n2.xyz;
    let front = dot(ng, d) < 0.0;
    let m = materials[s.material];
    var out: Surface;
    out.p = o + hit.t * d;
    out.uv = b0 * s.uv01.xy + hit.b1 * s.uv01.zw + hit.b2 * s.uv2;
    out.material = s.material;
    out.front = front;
    out.wo = -d;
    out.valid = front || m.double_sided != 0u;
    if !front {
        ng = -ng;
        ns = -ns;
    }
    let len = length(ns);
    if len <= 0.0 || dot(ns / len, out.wo) <= 1e-6 {
        ns = ng;
    } else {
        ns = ns / len;
    }
    out.ng = ng;
    out.frame = onb(ns);
    return out;
}

fn surface_material(sf: Surface) -> SurfaceMaterial {
    let m = materials[sf.material];
    let bc = sample_texture(m.base_color_tex, transform_uv(m, 0u, sf.uv));
    let mr = sample_texture(m.mr_tex, transform_uv(m, 1u, sf.uv));
    var out = SurfaceMaterial(m.base_color.rgb * bc.rgb, clamp(m.metallic * mr.b, 0.0, 1.0), clamp(m.roughness * mr.g, 0.0, 1.0));
    // Optimized textures replace the material's inputs (UV0, repeat wrap).
    if m.param_base_color != NONE {
        let p = param_textures[m.param_base_color];
        out.base_color = param_value(p, param_footprint(p, sf.uv));
    }
    if m.param_metallic != NONE {
        let p = param_textures[m.param_metallic];
        out.metallic = param_value(p, param_footprint(p, sf.uv)).x;
    }
    if m.param_roughness != NONE {
        let p = param_textures[m.param_roughness];
        out.roughness = param_value(p, param_footprint(p, sf.uv)).x;
    }
    return out;
}

// Origin pushed off the surface along the geometric normal, on the side of direction d.
fn offset_origin(sf: Surface, d: vec3f) -> vec3f {
    let scale = 1e-4 * (1.0 + max(max(abs(sf.p.x), abs(sf.p.y)), abs(sf.p.z)));
    return sf.p + sf.ng * select(-scale, scale, dot(sf.ng, d) >= 0.0);
}

fn nee_sample(sf: Surface, mat: SurfaceMaterial, u_pick: f32, u: vec2f) -> DirectSample {
    var out = DirectSample(vec3f(0.0, 0.0, 1.0), vec3f(0.0));
    let ls = sample_light(sf.p, u_pick, u);
    if ls.pdf <= 0.0 || all(ls.radiance == vec3f(0.0)) || dot(ls.wi, sf.ng) <= 0.0 {
        return out;
    }
    var w = 1.0;
    if !ls.is_delta {
        let p_bsdf = brdf_pdf(mat, to_local(sf.frame, sf.wo), to_local(sf.frame, ls.wi));
        w = mis_light(ls.pdf, p_bsdf);
        if w <= 0.0 {
            return out;
        }
    }
    shadow_rays += 1u;
    let o = offset_origin(sf, ls.wi);
    let tmax = select(ls.dist * (1.0 - 1e-4), 3.0e38, ls.dist >= 3.0e38);
    if !assume_visible && occluded(o, ls.wi, tmax) {
        return out;
    }
    out.wi = ls.wi;
    out.weight = ls.radiance * (w / ls.pdf);
    return out;
}

fn bsdf_direct_sample(sf: Surface, mat: SurfaceMaterial, u: vec3f) -> DirectSample {
    var out = DirectSample(vec3f(0.0, 0.0, 1.0), vec3f(0.0));
    let wo = to_local(sf.frame, sf.wo);
    let wi_local = brdf_sample(mat, wo, u);
    if wi_local.z <= 0.0 {
        return out;
    }
    let wi = to_world(sf.frame, wi_local);
    if dot(wi, sf.ng) <= 0.0 {
        return out;
    }
    let pdf = brdf_pdf(mat, wo, wi_local);
    if pdf <= 0.0 {
        return out;
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
        p_light = area_light_pdf(hit.tri, o, o + hit.t * wi);
    }
    if all(le == vec3f(0.0)) {
        return out;
    }
    out.wi = wi;
    out.weight = le * (mis_bsdf(pdf, p_light) / pdf);
    return out;
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

// Radiance along a camera ray (origin o, unit direction d) with direct illumination only.
fn direct_radiance(o: vec3f, d: vec3f) -> vec3f {
    let hit = trace_closest(o, d, 3.0e38);
    if hit.tri == NONE {
        return env_radiance(d);
    }
    let sf = surface_at(o, d, hit);
    if !sf.valid {
        return vec3f(0.0);
    }
    var l = emitted(hit.tri, hit.b1, hit.b2, sf.front);
    let mat = surface_material(sf);
    let wo = to_local(sf.frame, sf.wo);
    let s = sample_direct(sf, mat);
    l += brdf_eval_cos(mat, wo, to_local(sf.frame, s.nee.wi)) * s.nee.weight;
    l += brdf_eval_cos(mat, wo, to_local(sf.frame, s.bsdf.wi)) * s.bsdf.weight;
    return l;
}

// A camera sample as the gradient passes see it: the surface it hits and its two direct
// samples with their BRDF derivatives. valid is false when the ray misses, hits the back of a
// single-sided surface, or hits a material without optimized textures.
struct GradientSample {
    valid: bool,
    // The camera ray's hit (stored by ReSTIR so that replays need not trace it again).
    hit: Hit,
    sf: Surface,
    m: Material,
    nee: DirectSample,
    nee_grad: BrdfGrad,
    bsdf: DirectSample,
    bsdf_grad: BrdfGrad,
}

fn gradient_sample(o: vec3f, d: vec3f) -> GradientSample {
    var out: GradientSample;
    out.valid = false;
    let hit = trace_closest(o, d, 3.0e38);
    if hit.tri == NONE {
        return out;
    }
    out.hit = hit;
    out.sf = surface_at(o, d, hit);
    out.m = materials[out.sf.material];
    let m = out.m;
    if !out.sf.valid || (m.param_base_color == NONE && m.param_metallic == NONE && m.param_roughness == NONE) {
        return out;
    }
    let mat = surface_material(out.sf);
    let wo = to_local(out.sf.frame, out.sf.wo);
    let s = sample_direct(out.sf, mat);
    out.nee = s.nee;
    out.bsdf = s.bsdf;
    out.nee_grad = brdf_eval_cos_grad(mat, wo, to_local(out.sf.frame, s.nee.wi));
    out.bsdf_grad = brdf_eval_cos_grad(mat, wo, to_local(out.sf.frame, s.bsdf.wi));
    out.valid = true;
    return out;
}
