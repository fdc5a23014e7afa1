// The glTF metallic-roughness BRDF: Lambert diffuse plus GGX specular with height-correlated
// Smith visibility and Schlick Fresnel; alpha = roughness^2. Directions are local (z = normal).
#import shared/sampling

const ALPHA_MIN: f32 = 4e-4;

struct SurfaceMaterial {
    base_color: vec3f,
    metallic: f32,
    roughness: f32,
}

fn material_alpha(m: SurfaceMaterial) -> f32 {
    return max(m.roughness * m.roughness, ALPHA_MIN);
}

// D's denominator root, 1 + nh^2 (a2 - 1), written so that rounding cannot take it below
// nh^2 a2: in the direct form an nh^2 rounded above 1 (h from a normalize), or a compiler that
// fuses it into one multiply-add, can cancel it to about 0 near nh = 1 at low roughness and
// raise D by many orders of magnitude.
fn ggx_t(nh: f32, a2: f32) -> f32 {
    let c = nh * nh;
    return max(1.0 - c, 0.0) + c * a2;
}

fn ggx_d(nh: f32, a2: f32) -> f32 {
    let d = ggx_t(nh, a2);
    return a2 / (PI * d * d);
}

fn smith_g1(nv: f32, a2: f32) -> f32 {
    return 2.0 * nv / (nv + sqrt(a2 + (1.0 - a2) * nv * nv));
}

fn schlick(f0: vec3f, vh: f32) -> vec3f {
    let k = pow(clamp(1.0 - vh, 0.0, 1.0), 5.0);
    return f0 + (vec3f(1.0) - f0) * k;
}

// f(wo, wi) cos(theta_i) and its derivatives with respect to the material inputs: d_base is
// per channel (channel c of the value depends only on channel c of the base color).
// d_normal: with respect to the RGB of an optimized normal map at the point (column c for
// image channel c), which only surface_brdf_grad (shared/surface.wgsl) fills in.
struct BrdfGrad {
    value: vec3f,
    d_base: vec3f,
    d_metallic: vec3f,
    d_roughness: vec3f,
    d_normal: mat3x3f,
}

// Value and analytic derivatives in one code path; passes that need only the value call
// brdf_eval_cos and the compiler drops the derivative terms.
fn brdf_eval_cos_grad(m: SurfaceMaterial, wo: vec3f, wi: vec3f) -> BrdfGrad {
    var out = BrdfGrad(vec3f(0.0), vec3f(0.0), vec3f(0.0), vec3f(0.0), mat3x3f());
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return out;
    }
    let h = normalize(wo + wi);
    let r = m.roughness;
    let a = material_alpha(m);
    let a2 = a * a;
    // d(a2)/dr: a2 = r^4 above the floor.
    let da2 = select(0.0, 4.0 * r * r * r, r * r > ALPHA_MIN);
    let b = m.base_color;
    let met = m.metallic;
    let f0 = mix(vec3f(0.04), b, met);
    let k = pow(clamp(1.0 - dot(wo, h), 0.0, 1.0), 5.0);
    let fresnel = f0 + (vec3f(1.0) - f0) * k;
    // dF/dbase = (1 - k) met, dF/dmet = (1 - k) (base - 0.04).
    let dfb = (1.0 - k) * met;
    let dfm = (1.0 - k) * (b - vec3f(0.04));
    // D and V with their derivatives with respect to a2.
    let nh = h.z;
    let t = ggx_t(nh, a2);
    let d = a2 / (PI * t * t);
    let dd = (t - 2.0 * a2 * nh * nh) / (PI * t * t * t);
    let nl = wi.z;
    let nv = wo.z;
    let sv = sqrt(nv * nv * (1.0 - a2) + a2);
    let sl = sqrt(nl * nl * (1.0 - a2) + a2);
    let g = max(nl * sv + nv * sl, 1e-20);
    let vis = 0.5 / g;
    let dg = nl * (1.0 - nv * nv) / (2.0 * sv) + nv * (1.0 - nl * nl) / (2.0 * sl);
    let dvis = -0.5 * dg / (g * g);
    let kd = (1.0 - met) * INV_PI;
    let diffuse = (vec3f(1.0) - fresnel) * kd * b;
    let dv = d * vis;
    out.value = (diffuse + fresnel * dv) * nl;
    out.d_base = ((vec3f(1.0) - fresnel) * kd - dfb * kd * b + dfb * dv) * nl;
    out.d_metallic = (-dfm * kd * b - (vec3f(1.0) - fresnel) * INV_PI * b + dfm * dv) * nl;
    out.d_roughness = fresnel * (dd * vis + d * dvis) * da2 * nl;
    return out;
}

// The gradient of brdf_eval_cos's value with respect to the shading normal (local z), the
// directions held fixed, in the shading frame: column c for image channel c. The value
// depends on the normal only through nl = n.wi, nv = n.wo and nh = n.h (the Fresnel term
// reads wo.h, the rest are fixed), so its gradient is d/dnl wi + d/dnv wo + d/dnh h.
fn brdf_normal_grad(m: SurfaceMaterial, wo: vec3f, wi: vec3f) -> mat3x3f {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return mat3x3f();
    }
    let h = normalize(wo + wi);
    let a = material_alpha(m);
    let a2 = a * a;
    let b = m.base_color;
    let met = m.metallic;
    let fresnel = schlick(mix(vec3f(0.04), b, met), dot(wo, h));
    let diffuse = (vec3f(1.0) - fresnel) * (1.0 - met) * INV_PI * b;
    let nh = h.z;
    let nl = wi.z;
    let nv = wo.z;
    // D = a2 / (pi t^2), t = ggx_t: dt/dnh = 2 nh (a2 - 1) below nh = 1.
    let t = ggx_t(nh, a2);
    let d = a2 / (PI * t * t);
    let dt = select(2.0 * nh * a2, 2.0 * nh * (a2 - 1.0), nh * nh < 1.0);
    let dd = -2.0 * a2 * dt / (PI * t * t * t);
    // Vis = 1 / (2 g), g = nl sv + nv sl.
    let sv = sqrt(nv * nv * (1.0 - a2) + a2);
    let sl = sqrt(nl * nl * (1.0 - a2) + a2);
    let g = max(nl * sv + nv * sl, 1e-20);
    let vis = 0.5 / g;
    let dvis_nl = -0.5 * (sv + nv * nl * (1.0 - a2) / sl) / (g * g);
    let dvis_nv = -0.5 * (nl * nv * (1.0 - a2) / sv + sl) / (g * g);
    let d_nl = diffuse + fresnel * d * (vis + nl * dvis_nl);
    let d_nv = fresnel * d * nl * dvis_nv;
    let d_nh = fresnel * nl * vis * dd;
    return mat3x3f(d_nl.x * wi + d_nv.x * wo + d_nh.x * h, d_nl.y * wi + d_nv.y * wo + d_nh.y * h, d_nl.z * wi + d_nv.z * wo + d_nh.z * h);
}

fn brdf_eval_cos(m: SurfaceMaterial, wo: vec3f, wi: vec3f) -> vec3f {
    return brdf_eval_cos_grad(m, wo, wi).value;
}

// Probability of sampling the specular lobe.
fn specular_probability(m: SurfaceMaterial, wo: vec3f) -> f32 {
    let f0 = mix(vec3f(0.04), m.base_color, m.metallic);
    let fs = luminance(schlick(f0, wo.z));
    let fd = luminance(m.base_color) * (1.0 - m.metallic) * (1.0 - fs);
    if fs + fd <= 0.0 {
        return 0.5;
    }
    return clamp(fs / (fs + fd), 0.1, 0.9);
}

// Visible-normal sampling of GGX (Heitz 2018).
fn sample_ggx_vndf(wo: vec3f, a: f32, u: vec2f) -> vec3f {
    let vh = normalize(vec3f(a * wo.x, a * wo.y, wo.z));
    let lensq = vh.x * vh.x + vh.y * vh.y;
    let t1 = select(vec3f(1.0, 0.0, 0.0), vec3f(-vh.y, vh.x, 0.0) * inverseSqrt(lensq), lensq > 1e-12);
    let t2 = cross(vh, t1);
    let r = sqrt(u.x);
    let phi = 2.0 * PI * u.y;
    let p1 = r * cos(phi);
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * sqrt(max(0.0, 1.0 - p1 * p1)) + s * r * sin(phi);
    let nh = p1 * t1 + p2 * t2 + sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh;
    return normalize(vec3f(a * nh.x, a * nh.y, max(1e-6, nh.z)));
}

fn brdf_pdf(m: SurfaceMaterial, wo: vec3f, wi: vec3f) -> f32 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    let ps = specular_probability(m, wo);
    let h = normalize(wo + wi);
    let a = material_alpha(m);
    let a2 = a * a;
    let spec = smith_g1(wo.z, a2) * ggx_d(h.z, a2) / (4.0 * wo.z);
    return ps * spec + (1.0 - ps) * wi.z * INV_PI;
}

// A direction from the mixture of the two lobes; z <= 0 means no valid sample.
fn brdf_sample(m: SurfaceMaterial, wo: vec3f, u: vec3f) -> vec3f {
    let ps = specular_probability(m, wo);
    if u.x < ps {
        let h = sample_ggx_vndf(wo, material_alpha(m), u.yz);
        return reflect(-wo, h);
    }
    return sample_cosine_hemisphere(u.yz);
}
