#import shared/types

// Orthonormal basis around n (Duff et al. 2017).
fn onb(n: vec3f) -> mat3x3f {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t = vec3f(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let bt = vec3f(b, s + n.y * n.y * a, -n.y);
    return mat3x3f(t, bt, n);
}

fn to_world(frame: mat3x3f, v: vec3f) -> vec3f {
    return frame * v;
}

fn to_local(frame: mat3x3f, v: vec3f) -> vec3f {
    return v * frame;
}

fn sample_cosine_hemisphere(u: vec2f) -> vec3f {
    let r = sqrt(u.x);
    let phi = 2.0 * PI * u.y;
    return vec3f(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.x)));
}

// Uniform point on a triangle, returned as barycentrics (b1, b2).
fn sample_triangle(u: vec2f) -> vec2f {
    let su = sqrt(u.x);
    return vec2f(1.0 - su, u.y * su);
}

fn power_heuristic(a: f32, b: f32) -> f32 {
    let a2 = a * a;
    let b2 = b * b;
    if a2 + b2 <= 0.0 {
        return 0.0;
    }
    return a2 / (a2 + b2);
}

fn luminance(c: vec3f) -> f32 {
    return dot(c, vec3f(0.2126, 0.7152, 0.0722));
}
