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

fn ggx_d(nh: f32, a2: f32) -> f32 {
    let d = nh * nh * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

fn smith_visibility(nl: f32, nv: f32, a2: f32) -> f32 {
    let gv = nl * sqrt(nv * nv * (1.0 - a2) + a2);
    let gl = nv * sqrt(nl * nl * (1.0 - a2) + a2);
    return 0.5 / max(gv + gl, 1e-20);
}

fn smith_g1(nv: f32, a2: f32) -> f32 {
    return 2.0 * nv / (nv + sqrt(a2 + (1.0 - a2) * nv * nv));
}

fn schlick(f0: vec3f, vh: f32) -> vec3f {
    let k = pow(clamp(1.0 - vh, 0.0, 1.0), 5.0);
    return f0 + (vec3f(1.0) - f0) * k;
}

// f(wo, wi) * cos(theta_i).
fn brdf_eval_cos(m: SurfaceMaterial, wo: vec3f, wi: vec3f) -> vec3f {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return vec3f(0.0);
    }
    let h = normalize(wo + wi);
    let a = material_alpha(m);
    let a2 = a * a;
    let f0 = mix(vec3f(0.04), m.base_color, m.metallic);
    let fresnel = schlick(f0, dot(wo, h));
    let diffuse = (vec3f(1.0) - fresnel) * (1.0 - m.metallic) * m.base_color * INV_PI;
    let specular = fresnel * ggx_d(h.z, a2) * smith_visibility(wi.z, wo.z, a2);
    return (diffuse + specular) * wi.z;
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
