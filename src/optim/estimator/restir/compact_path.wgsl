// ReSTIR's compact path: what a reservoir keeps of a path in RESERVOIR_WORDS words (layout
// RES_* from abi.rs, gen/restir), in the compact path encoding (shared/path_encoding.wgsl).
#import gen/abi
#import gen/restir
#import shared/path_encoding

// The words of a stored path after RES_W, in order (RES_TRI .. RES_RADIANCE): hit triangle
// `tri` and barycentrics kb (fixed point), incident direction ko (fixed point), radiance
// word, and the path's target under the previous state, q_prev.
fn path_words(tri: u32, kb: vec2u, ko: vec2u, radiance: u32, q_prev: f32) -> array<u32, 5> {
    let q = bf16_pack(q_prev);
    return array<u32, 5>(
        tri | (kb.x << RES_TRI_BITS),
        (kb.x >> (32u - RES_TRI_BITS)) | (kb.y << (PATH_BARY_BITS + RES_TRI_BITS - 32u)),
        ko.x | ((q & 0xffu) << PATH_OCT_BITS),
        ko.y | ((q >> 8u) << PATH_OCT_BITS),
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
    let bary_mask = (1u << PATH_BARY_BITS) - 1u;
    let oct_mask = (1u << PATH_OCT_BITS) - 1u;
    let kb1 = (w[0] >> RES_TRI_BITS) | ((w[1] << (32u - RES_TRI_BITS)) & bary_mask);
    let kb2 = (w[1] >> (PATH_BARY_BITS + RES_TRI_BITS - 32u)) & bary_mask;
    let q = (w[2] >> PATH_OCT_BITS) | ((w[3] >> PATH_OCT_BITS) << 8u);
    return PathWords(w[0] & tri_mask, vec2u(kb1, kb2), vec2u(w[2] & oct_mask, w[3] & oct_mask), rgbe_unpack(w[4]), bf16_unpack(q));
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
