// ReSTIR's compact path: what a reservoir keeps of a path in res_stride words (layout RES_*
// from abi.rs, gen/restir: RESERVOIR_WORDS, or RESERVOIR_WORDS_MAX with whole paths), in the compact path encoding (shared/path_encoding.wgsl).
// A path is its vertices (triangle and fixed-point barycentrics; the camera ray's hit first,
// up to MAX_PATH_VERTICES), the incident direction at the last one (fixed point, in its
// shading frame), the radiance arriving along it (RGBE: an emitter's, fixed while textures
// change), and its shape: how many vertices and at which one the texel's derivative is taken.
// Geometry does not change during a texture optimization, so the stored vertices are the
// same path under any textures (the shift is the identity in path space, Jacobian 1); the
// directions between vertices are rebuilt from their positions.
#import gen/abi
#import gen/restir
#import shared/path_encoding

// The path's shape word: vertex count n (1 ..= MAX_PATH_VERTICES), derivative vertex k < n.
fn shape_word(n: u32, k: u32) -> u32 {
    return (n - 1u) | (k << 2u);
}

// A path's vertex packed into two words (RES_TRI, RES_BARY or the later vertices' pairs).
fn vertex_words(tri: u32, kb: vec2u) -> vec2u {
    return vec2u(tri | (kb.x << RES_TRI_BITS), (kb.x >> (32u - RES_TRI_BITS)) | (kb.y << (PATH_BARY_BITS + RES_TRI_BITS - 32u)));
}

// The words of a stored path after RES_W, in order (RES_TRI .. RES_SHAPE): its vertices
// (tri, kb; unused ones 0), the incident direction ko at the last vertex, the radiance word,
// the path's target under the previous state q_prev, and its shape.
fn path_words(tri: array<u32, MAX_PATH_VERTICES>, kb: array<vec2u, MAX_PATH_VERTICES>, ko: vec2u, radiance: u32, q_prev: f32, shape: u32) -> array<u32, RES_PATH_WORDS> {
    let q = bf16_pack(q_prev);
    let v0 = vertex_words(tri[0], kb[0]);
    let v1 = vertex_words(tri[1], kb[1]);
    let v2 = vertex_words(tri[2], kb[2]);
    return array<u32, RES_PATH_WORDS>(
        v0.x,
        v0.y,
        ko.x | ((q & 0xffu) << PATH_OCT_BITS),
        ko.y | ((q >> 8u) << PATH_OCT_BITS),
        radiance,
        v1.x,
        v1.y,
        v2.x,
        v2.y,
        shape,
    );
}

// A stored path unpacked: its vertices, the last direction, the radiance, q_prev, and its
// shape (n vertices, derivative at vertex k).
struct PathWords {
    tri: array<u32, MAX_PATH_VERTICES>,
    kb: array<vec2u, MAX_PATH_VERTICES>,
    ko: vec2u,
    radiance: vec3f,
    q_prev: f32,
    n: u32,
    k: u32,
}

fn unpack_vertex(a: u32, b: u32) -> vec3u {
    let tri_mask = (1u << RES_TRI_BITS) - 1u;
    let bary_mask = (1u << PATH_BARY_BITS) - 1u;
    let kb1 = (a >> RES_TRI_BITS) | ((b << (32u - RES_TRI_BITS)) & bary_mask);
    let kb2 = (b >> (PATH_BARY_BITS + RES_TRI_BITS - 32u)) & bary_mask;
    return vec3u(a & tri_mask, kb1, kb2);
}

fn unpack_path(w: array<u32, RES_PATH_WORDS>) -> PathWords {
    let oct_mask = (1u << PATH_OCT_BITS) - 1u;
    let q = (w[2] >> PATH_OCT_BITS) | ((w[3] >> PATH_OCT_BITS) << 8u);
    let v0 = unpack_vertex(w[0], w[1]);
    let v1 = unpack_vertex(w[5], w[6]);
    let v2 = unpack_vertex(w[7], w[8]);
    let shape = w[9];
    let n = min((shape & 3u) + 1u, MAX_PATH_VERTICES);
    return PathWords(
        array<u32, MAX_PATH_VERTICES>(v0.x, v1.x, v2.x),
        array<vec2u, MAX_PATH_VERTICES>(v0.yz, v1.yz, v2.yz),
        vec2u(w[2] & oct_mask, w[3] & oct_mask),
        rgbe_unpack(w[4]),
        bf16_unpack(q),
        n,
        min(shape >> 2u, n - 1u),
    );
}

// A stored path rebuilt from the scene, seen from the camera at `origin`: every vertex's
// surface (shared/surface.wgsl) and path vertex with the glTF material's inputs there, the
// radiance at the last one, and its shape. valid is false where a vertex shades black (the
// back of a single-sided surface).
struct DecodedPath {
    valid: bool,
    // How many of the vertices from the first on are valid, and their surfaces, each with
    // the shading frame that its path vertex's directions are in.
    n_valid: u32,
    sf: array<Surface, MAX_PATH_VERTICES>,
    n: u32,
    k: u32,
    pv: array<PathVertex, MAX_PATH_VERTICES>,
    gltf: array<SurfaceMaterial, MAX_PATH_VERTICES>,
    radiance: vec3f,
}

// The path in p rebuilt, its shading frames those of the current or (prev) the previous
// iteration's textures (they differ only where an optimized normal map changed): a path is
// evaluated under the previous textures in their frames.
fn decode_path(origin: vec3f, p: PathWords, prev: bool) -> DecodedPath {
    var out: DecodedPath;
    out.n_valid = 0u;
    out.n = p.n;
    out.k = p.k;
    out.radiance = p.radiance;
    var seen_from = origin;
    for (var j = 0u; j < p.n; j++) {
        out.sf[j] = surface_at(seen_from, stored_hit(p.tri[j], p.kb[j]));
        if NORMAL_MAPS && prev {
            out.sf[j].frame = frame_of(out.sf[j], true);
        }
        if out.sf[j].valid && out.n_valid == j {
            out.n_valid = j + 1u;
        }
        seen_from = out.sf[j].p;
    }
    out.valid = out.n_valid >= p.n;
    for (var j = 0u; j < p.n; j++) {
        // The direction to the next vertex, or the stored one at the last.
        let sf = out.sf[j];
        var wi = vec2f(0.0);
        if j + 1u < p.n {
            wi = oct_encode(to_local(sf.frame, normalize(out.sf[j + 1u].p - sf.p)));
        } else {
            wi = stored_direction(sf, sf.frame, p.ko);
        }
        let gltf = gltf_inputs(sf.material, sf.uv);
        out.gltf[j] = gltf;
        out.pv[j] = path_vertex(sf, gltf, wi);
    }
    return out;
}

// BRDF x cos of vertex j of a decoded path, under the textures use_prev_params selects.
fn decoded_brdf(dp: DecodedPath, j: u32) -> vec3f {
    let pv = dp.pv[j];
    let m = with_optimized(pv.material, pv.uv, dp.gltf[j]);
    return brdf_eval_cos(m, oct_decode(pv.wo), oct_decode(pv.wi));
}

// What multiplies the derivative of vertex k's BRDF x cos in the path's contribution: the
// radiance at the last vertex times every other vertex's BRDF x cos (the path-space integrand
// before any density), under the textures use_prev_params selects.
fn arriving_at(dp: DecodedPath, k: u32) -> vec3f {
    var li = dp.radiance;
    for (var j = 0u; j < dp.n; j++) {
        if j != k {
            li *= decoded_brdf(dp, j);
        }
    }
    return li;
}

// Words w with q as the target under the previous state (the high bytes of the direction's).
fn with_q_prev(w: array<u32, RES_PATH_WORDS>, q: f32) -> array<u32, RES_PATH_WORDS> {
    let h = bf16_pack(q);
    let low = (1u << PATH_OCT_BITS) - 1u;
    var out = w;
    out[2] = (w[2] & low) | ((h & 0xffu) << PATH_OCT_BITS);
    out[3] = (w[3] & low) | ((h >> 8u) << PATH_OCT_BITS);
    return out;
}

// Whether a reservoir keeps whole paths (every vertex stored) at the scene's depth: from two
// vertices to MAX_PATH_VERTICES (abi.rs, reservoir::whole_paths).
fn whole_paths() -> bool {
    return scene.max_depth > 1u && scene.max_depth <= MAX_PATH_VERTICES;
}

// Words per reservoir at the scene's depth (abi.rs, reservoir::words).
fn reservoir_stride() -> u32 {
    return select(RESERVOIR_WORDS, RESERVOIR_WORDS_MAX, whole_paths());
}
