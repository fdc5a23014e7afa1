// Light selection and sampling for next-event estimation, and the densities that MIS needs
// when a BSDF-sampled ray finds an emitter.
#import shared/texture
#import shared/sampling

// A sampled light as seen from a shading point. radiance: incident radiance for area and
// environment lights, irradiance-like intensity/d^2 for delta lights. pdf: solid-angle density
// including the light choice; for delta lights the choice probability alone. dist: distance to
// the sampled point (3e38 for directions at infinity). n: the emitter's unit geometric normal at
// the sampled point for area lights (zero for the others), so that the shadow ray can end just
// off the emitter's surface. sample_light leaves the radiance of area lights and the radiance
// and density of the environment to its caller (light_arrival), which evaluates them where it
// evaluates what a ray finds: tri, b and front say which emitter point, env whether the
// environment.
struct LightSample {
    wi: vec3f,
    dist: f32,
    radiance: vec3f,
    pdf: f32,
    n: vec3f,
    is_delta: bool,
    tri: u32,
    b: vec2f,
    front: bool,
    env: bool,
}

// The lights of the capture being traced: lights[] holds the scene's n_lights lights once
// for every set of them that a capture sees (src/render/gpu_lights.rs, light_tables; the
// first copy has them all), in the same order, each copy with its own choice probabilities
// (0 for a punctual light that is off). Every pass that traces sets this from its camera
// (CameraInfo.light_base) before it traces; light indices (TriShading.light,
// scene.env_light, pick_light's) count from it.
var<private> light_base: u32;

// Index of the light whose CDF interval holds u. Bounded binary search.
fn pick_light(u: f32) -> u32 {
    var lo = 0u;
    var hi = scene.n_lights;
    for (var it = 0u; it < 32u && lo < hi; it++) {
        let mid = (lo + hi) / 2u;
        if lights[light_base + mid].cdf <= u {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return min(lo, scene.n_lights - 1u);
}

fn tri_vertex(tri: u32, k: u32) -> vec3f {
    return tri_positions[3u * tri + k].xyz;
}

fn tri_uv(tri: u32, b1: f32, b2: f32) -> vec2f {
    let s = tri_shading[tri];
    return (1.0 - b1 - b2) * s.uv01.xy + b1 * s.uv01.zw + b2 * s.uv2;
}

// Emitted radiance of a triangle at barycentrics (b1, b2), seen from its front or back.
fn emitted(tri: u32, b1: f32, b2: f32, front: bool) -> vec3f {
    let m = materials[tri_shading[tri].material];
    if !front && m.double_sided == 0u {
        return vec3f(0.0);
    }
    if all(m.emissive == vec3f(0.0)) {
        return vec3f(0.0);
    }
    let uv = transform_uv(m, 2u, tri_uv(tri, b1, b2));
    return m.emissive * sample_texture(m.emissive_tex, uv).rgb;
}

// Equirectangular mapping: +y up, u = azimuth from -z towards +x, v = polar angle / pi.
fn env_direction(uv: vec2f) -> vec3f {
    let phi = 2.0 * PI * uv.x;
    let theta = PI * uv.y;
    let st = sin(theta);
    return vec3f(st * sin(phi), cos(theta), -st * cos(phi));
}

fn env_uv(d: vec3f) -> vec2f {
    var u = atan2(d.x, -d.z) * (0.5 * INV_PI);
    u = select(u, u + 1.0, u < 0.0);
    let v = acos(clamp(d.y, -1.0, 1.0)) * INV_PI;
    return vec2f(u, v);
}

fn env_texel(uv: vec2f) -> vec2u {
    let w = scene.env_width;
    let h = scene.env_height;
    let i = min(u32(max(uv.x, 0.0) * f32(w)), w - 1u);
    let j = min(u32(max(uv.y, 0.0) * f32(h)), h - 1u);
    return vec2u(i, j);
}

// The texels a lookup in direction d reads and their weights: the nearest one (weight 1), or
// with scene.env_bilinear the four around d's coordinates, texel centres apart, wrapping in
// azimuth and clamped at the poles. The environment's derivative goes to the same texels
// with the same weights (shared/env_gradient.wgsl).
struct EnvFootprint {
    texel: vec4u,
    weight: vec4f,
}

fn env_footprint(d: vec3f) -> EnvFootprint {
    let uv = env_uv(d);
    let w = scene.env_width;
    let h = scene.env_height;
    if scene.env_bilinear == 0u {
        let ij = env_texel(uv);
        return EnvFootprint(vec4u(ij.y * w + ij.x, 0u, 0u, 0u), vec4f(1.0, 0.0, 0.0, 0.0));
    }
    let q = uv * vec2f(f32(w), f32(h)) - 0.5;
    let f = floor(q);
    let t = q - f;
    let wi = i32(w);
    let x0 = u32(((i32(f.x) % wi) + wi) % wi);
    let x1 = (x0 + 1u) % w;
    let y0 = u32(clamp(i32(f.y), 0, i32(h) - 1));
    let y1 = u32(clamp(i32(f.y) + 1, 0, i32(h) - 1));
    return EnvFootprint(
        vec4u(y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1),
        vec4f((1.0 - t.x) * (1.0 - t.y), t.x * (1.0 - t.y), (1.0 - t.x) * t.y, t.x * t.y),
    );
}

fn env_radiance(d: vec3f) -> vec3f {
    if scene.env_width == 0u {
        return vec3f(0.0);
    }
    let fp = env_footprint(d);
    var c = vec3f(0.0);
    for (var j = 0u; j < 4u; j++) {
        let k = 3u * fp.texel[j];
        c += fp.weight[j] * vec3f(env[k], env[k + 1u], env[k + 2u]);
    }
    return c * scene.env_scale;
}

// Solid-angle density of sampling direction d from the environment distribution (without the
// light choice).
fn env_pdf(d: vec3f) -> f32 {
    if scene.env_light == NONE {
        return 0.0;
    }
    let uv = env_uv(d);
    let ij = env_texel(uv);
    let w = scene.env_width;
    let h = scene.env_height;
    let p_row = env[scene.env_marginal + ij.y + 1u] - env[scene.env_marginal + ij.y];
    let row = scene.env_conditional + ij.y * (w + 1u);
    let p_col = env[row + ij.x + 1u] - env[row + ij.x];
    let sin_theta = sin(PI * uv.y);
    if sin_theta <= 0.0 {
        return 0.0;
    }
    return p_row * p_col * f32(w * h) / (2.0 * PI * PI * sin_theta);
}

// Index i in [0, count) with cdf[first+i] <= u < cdf[first+i+1]. Bounded binary search.
fn search_env_cdf(first: u32, count: u32, u: f32) -> u32 {
    var lo = 0u;
    var hi = count;
    for (var it = 0u; it < 32u && lo + 1u < hi; it++) {
        let mid = (lo + hi) / 2u;
        if env[first + mid] <= u {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

fn sample_env(u: vec2f) -> vec3f {
    let w = scene.env_width;
    let h = scene.env_height;
    let j = search_env_cdf(scene.env_marginal, h, u.y);
    let row = scene.env_conditional + j * (w + 1u);
    let i = search_env_cdf(row, w, u.x);
    // Uniform position inside the chosen texel, reusing the leftover of u.
    let r0 = env[scene.env_marginal + j];
    let r1 = env[scene.env_marginal + j + 1u];
    let c0 = env[row + i];
    let c1 = env[row + i + 1u];
    let fv = clamp((u.y - r0) / max(r1 - r0, 1e-30), 0.0, 1.0);
    let fu = clamp((u.x - c0) / max(c1 - c0, 1e-30), 0.0, 1.0);
    return env_direction(vec2f((f32(i) + fu) / f32(w), (f32(j) + fv) / f32(h)));
}

// glTF's recommended range window: smooth fall-off to zero at `range` (0 = infinite).
fn range_window(dist: f32, range: f32) -> f32 {
    if range <= 0.0 {
        return 1.0;
    }
    let r = dist / range;
    let x = clamp(1.0 - r * r * r * r, 0.0, 1.0);
    return x * x;
}

// The radiance of an area light and the radiance and density of the environment are left to
// the caller (LightSample).
fn sample_light(p: vec3f, u_pick: f32, u: vec2f) -> LightSample {
    var s = LightSample(vec3f(0.0, 0.0, 1.0), 0.0, vec3f(0.0), 0.0, vec3f(0.0), true, NONE, vec2f(0.0), false, false);
    if scene.n_lights == 0u {
        return s;
    }
    let li = pick_light(u_pick);
    let light = lights[light_base + li];
    switch light.kind {
        case 0u, 1u: {
            let to = light.position - p;
            let d2 = max(dot(to, to), 1e-12);
            let dist = sqrt(d2);
            s.wi = to / dist;
            s.dist = dist;
            var att = range_window(dist, light.range) / d2;
            if light.kind == LIGHT_SPOT {
                let cd = dot(light.direction, -s.wi);
                let t = clamp(cd * light.spot_scale + light.spot_offset, 0.0, 1.0);
                att *= t * t;
            }
            s.radiance = light.intensity * att;
            s.pdf = light.pmf;
        }
        case 2u: {
            s.wi = -light.direction;
            s.dist = 3.0e38;
            s.radiance = light.intensity;
            s.pdf = light.pmf;
        }
        case 3u: {
            let b = sample_triangle(u);
            let p0 = tri_vertex(light.tri, 0u);
            let e1 = tri_vertex(light.tri, 1u) - p0;
            let e2 = tri_vertex(light.tri, 2u) - p0;
            let q = p0 + b.x * e1 + b.y * e2;
            let c = cross(e1, e2);
            let area2 = length(c);
            let to = q - p;
            let d2 = dot(to, to);
            if area2 <= 0.0 || d2 <= 0.0 {
                return s;
            }
            let dist = sqrt(d2);
            s.wi = to / dist;
            s.dist = dist;
            s.n = c / area2;
            let cos_l = dot(s.n, -s.wi);
            s.tri = light.tri;
            s.b = b;
            s.front = cos_l > 0.0;
            s.pdf = light.pmf * d2 / (0.5 * area2 * max(abs(cos_l), 1e-12));
            s.is_delta = false;
        }
        default: {
            s.wi = sample_env(u);
            s.dist = 3.0e38;
            s.env = true;
            s.is_delta = false;
        }
    }
    return s;
}

// Density with which NEE would have sampled the point where a ray from p hit triangle `tri`.
fn area_light_pdf(tri: u32, p: vec3f, q: vec3f) -> f32 {
    let li = tri_shading[tri].light;
    if li == NONE {
        return 0.0;
    }
    let p0 = tri_vertex(tri, 0u);
    let c = cross(tri_vertex(tri, 1u) - p0, tri_vertex(tri, 2u) - p0);
    let area2 = length(c);
    let to = q - p;
    let d2 = dot(to, to);
    let cos_l = abs(dot(c / area2, to / sqrt(d2)));
    return lights[light_base + li].pmf * d2 / (0.5 * area2 * max(cos_l, 1e-12));
}

fn env_light_pdf(d: vec3f) -> f32 {
    if scene.env_light == NONE {
        return 0.0;
    }
    return lights[light_base + scene.env_light].pmf * env_pdf(d);
}
