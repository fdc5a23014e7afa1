// The compact path encoding: a path vertex kept in a few words by an estimator that stores
// paths (ReSTIR's reservoirs) and rebuilt from the scene. A vertex is the camera ray's hit
// (triangle, barycentrics in fixed point, PATH_BARY_BITS), the incident direction in the
// hit's shading frame, or the geometric normal's where an optimized normal map moves the
// shading frame (stored_frame; octahedral, fixed point, PATH_OCT_BITS) and the incident radiance
// (RGBE); everything else the BRDF needs (texture coordinates, shading frame, outgoing
// direction, the material inputs that no optimized texture replaces) is rebuilt by the same
// functions that made it (path_vertex). With compact_paths the integrator samples at the
// rounded hit, direction and radiance, so a stored path re-evaluates to exactly what its
// sample was worth. The precision of each encoding is stated and tested on the CPU
// (src/optim/estimator/restir/compact.rs mirrors these functions).
#import gen/abi
#import shared/surface

const BARY_SCALE: f32 = 1048576.0; // 2^PATH_BARY_BITS
const OCT_HALF_SCALE: f32 = 8388608.0; // 2^(PATH_OCT_BITS - 1)

// Barycentric b as fixed point in [0, 1) (nearest step of 2^-20), and back (exact).
fn bary_round(b: f32) -> u32 {
    return min(u32(max(b, 0.0) * BARY_SCALE + 0.5), (1u << PATH_BARY_BITS) - 1u);
}

fn bary_value(k: u32) -> f32 {
    return f32(k) * (1.0 / BARY_SCALE);
}

// Octahedral coordinate x in [-1, 1] as fixed point (nearest step of 2^-23), and back (exact).
fn oct_round(x: f32) -> u32 {
    return min(u32(max(x + 1.0, 0.0) * OCT_HALF_SCALE + 0.5), (1u << PATH_OCT_BITS) - 1u);
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

// Whether a direction stored at sf is kept in a frame of its own (stored_frame): with an
// optimized normal map, whose texels move the shading frame between the iteration a path is
// stored in and those that evaluate it.
fn own_stored_frame(sf: Surface) -> bool {
    return NORMAL_MAPS && materials[sf.material].param_normal != NONE;
}

// The frame a direction stored at sf is kept in: the shading frame, or with an optimized
// normal map the geometric normal's, which depends on the geometry alone.
fn stored_frame(sf: Surface) -> mat3x3f {
    if own_stored_frame(sf) {
        return onb(sf.ng);
    }
    return sf.frame;
}

// The octahedral coordinates in sf's shading frame `frame` (under either iteration's
// textures) of the direction stored at sf as fixed-point ko (in stored_frame): the stored
// values themselves unless the frame is the normal map's.
fn stored_direction(sf: Surface, frame: mat3x3f, ko: vec2u) -> vec2f {
    let e = vec2f(oct_value(ko.x), oct_value(ko.y));
    if !own_stored_frame(sf) {
        return e;
    }
    return oct_encode(to_local(frame, onb(sf.ng) * oct_decode(e)));
}

// The hit of triangle `tri` at fixed-point barycentrics kb.
fn stored_hit(tri: u32, kb: vec2u) -> Hit {
    return Hit(0.0, tri, bary_value(kb.x), bary_value(kb.y));
}

// The path vertex (shared/surface.wgsl, path_factor) of the hit `sf` seen from its camera,
// with the material inputs that the glTF material gives there and incident direction wi
// (octahedral, in the shading frame).
fn path_vertex(sf: Surface, gltf: SurfaceMaterial, wi: vec2f) -> PathVertex {
    return PathVertex(sf.material, sf.uv, oct_encode(to_local(sf.frame, sf.wo)), wi, fixed_pack(sf.material, gltf), gltf.roughness);
}

