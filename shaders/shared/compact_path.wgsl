// ReSTIR's compact path: what a reservoir keeps of a path in RESERVOIR_WORDS words (layout
// RES_* from src/gpu/abi.rs; each encoding's precision is stated and tested in
// src/optim/estimator/restir/compact.rs, which mirrors these functions). A path is the camera ray's
// hit (triangle, barycentrics in fixed point), the incident direction in the hit's shading
// frame (octahedral, fixed point) and the incident radiance (RGBE). Everything else the BRDF
// needs (texture coordinates, shading frame, outgoing direction, the material inputs that no
// optimized texture replaces) is rebuilt from the scene by the same functions that made it
// (stored_vertex), and ReSTIR's gradient samples are taken at the rounded hit, direction and
// radiance (gradient_sample with compact_paths), so a stored path re-evaluates to exactly what
// its candidate was worth.
#import gen/abi
#import shared/surface

const BARY_SCALE: f32 = 1048576.0; // 2^RES_BARY_BITS
const OCT_HALF_SCALE: f32 = 8388608.0; // 2^(RES_OCT_BITS - 1)

// Barycentric b as fixed point in [0, 1) (nearest step of 2^-20), and back (exact).
fn bary_round(b: f32) -> u32 {
    return min(u32(max(b, 0.0) * BARY_SCALE + 0.5), (1u << RES_BARY_BITS) - 1u);
}

fn bary_value(k: u32) -> f32 {
    return f32(k) * (1.0 / BARY_SCALE);
}

// Octahedral coordinate x in [-1, 1] as fixed point (nearest step of 2^-23), and back (exact).
fn oct_round(x: f32) -> u32 {
    return min(u32(max(x + 1.0, 0.0) * OCT_HALF_SCALE + 0.5), (1u << RES_OCT_BITS) - 1u);
}

fn oct_value(k: u32) -> f32 {
    return f32(k) * (1.0 / OCT_HALF_SCALE) - 1.0;
}

// 2^e for e in [-126, 127], exactly.
fn pow2(e: i32) -> f32 {
    return bitcast<f32>(u32(e + 127) << 23u);
}

// Non-negative RGB as RGBE: three 8-bit mantissas and a shared exponent (biased by 128) in
// the high byte; 0 for a largest channel below 2^-100 or not finite.
fn rgbe_pack(c: vec3f) -> u32 {
    let m = max(max(c.x, c.y), c.z);
    if !(m >= 7.9e-31) || !(m < 3.0e38) {
        return 0u;
    }
    // m in [2^(e-1), 2^e).
    var e = i32((bitcast<u32>(m) >> 23u) & 0xffu) - 126;
    var s = pow2(8 - e);
    if floor(m * s + 0.5) >= 256.0 {
        e += 1;
        s *= 0.5;
    }
    let k = vec3u(min(floor(max(c, vec3f(0.0)) * s + 0.5), vec3f(255.0)));
    return k.x | (k.y << 8u) | (k.z << 16u) | (u32(e + 128) << 24u);
}

fn rgbe_unpack(w: u32) -> vec3f {
    if w == 0u {
        return vec3f(0.0);
    }
    let e = i32(w >> 24u) - 128;
    let k = vec3f(f32(w & 0xffu), f32((w >> 8u) & 0xffu), f32((w >> 16u) & 0xffu));
    return k * pow2(e - 8);
}

// A finite f32 as bfloat16 (the high 16 bits, rounded to nearest even), and back (exact).
fn bf16_pack(x: f32) -> u32 {
    let b = bitcast<u32>(x);
    return (b + 0x7fffu + ((b >> 16u) & 1u)) >> 16u;
}

fn bf16_unpack(h: u32) -> f32 {
    return bitcast<f32>(h << 16u);
}

// The words of a stored path after RES_W, in order (RES_TRI .. RES_RADIANCE): hit triangle
// `tri` and barycentrics kb (fixed point), incident direction ko (fixed point), radiance
// word, and the path's target under the previous state, q_prev.
fn path_words(tri: u32, kb: vec2u, ko: vec2u, radiance: u32, q_prev: f32) -> array<u32, 5> {
    let q = bf16_pack(q_prev);
    return array<u32, 5>(
        tri | (kb.x << RES_TRI_BITS),
        (kb.x >> (32u - RES_TRI_BITS)) | (kb.y << (RES_BARY_BITS + RES_TRI_BITS - 32u)),
        ko.x | ((q & 0xffu) << RES_OCT_BITS),
        ko.y | ((q >> 8u) << RES_OCT_BITS),
        radiance,
    );
}

// A stored path unpacked: the hit, the direction, the radiance, and q_prev.
struct PathWords {
    tri: u32,
    kb: vec2u,
    ko: vec2u,
    radiance: vec3f,
    q_prev: f32,
}

fn unpack_path(w: array<u32, 5>) -> PathWords {
    let tri_mask = (1u << RES_TRI_BITS) - 1u;
    let bary_mask = (1u << RES_BARY_BITS) - 1u;
    let oct_mask = (1u << RES_OCT_BITS) - 1u;
    let kb1 = (w[0] >> RES_TRI_BITS) | ((w[1] << (32u - RES_TRI_BITS)) & bary_mask);
    let kb2 = (w[1] >> (RES_BARY_BITS + RES_TRI_BITS - 32u)) & bary_mask;
    let q = (w[2] >> RES_OCT_BITS) | ((w[3] >> RES_OCT_BITS) << 8u);
    return PathWords(w[0] & tri_mask, vec2u(kb1, kb2), vec2u(w[2] & oct_mask, w[3] & oct_mask), rgbe_unpack(w[4]), bf16_unpack(q));
}

// The hit of triangle `tri` at fixed-point barycentrics kb.
fn stored_hit(tri: u32, kb: vec2u) -> Hit {
    return Hit(0.0, tri, bary_value(kb.x), bary_value(kb.y));
}

// The path vertex (shared/surface.wgsl, path_factor) of the hit `sf` seen from its camera,
// with the material inputs that the glTF material gives there and incident direction wi
// (octahedral, in the shading frame).
fn path_vertex(sf: Surface, gltf: SurfaceMaterial, wi: vec2f) -> PathVertex {
    return PathVertex(sf.material, sf.uv, oct_encode(to_local(sf.frame, sf.wo)), wi, fixed_pack(sf.material, gltf));
}

// A stored path rebuilt from the scene: the camera at `origin`, the hit and direction of p.
// valid is false where the hit shades black (the back of a single-sided surface).
struct StoredVertex {
    valid: bool,
    vertex: PathVertex,
}

fn stored_vertex(origin: vec3f, p: PathWords) -> StoredVertex {
    let sf = surface_at(origin, stored_hit(p.tri, p.kb));
    let gltf = gltf_inputs(sf.material, sf.uv);
    return StoredVertex(sf.valid, path_vertex(sf, gltf, vec2f(oct_value(p.ko.x), oct_value(p.ko.y))));
}
