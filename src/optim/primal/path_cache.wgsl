// The path cache's layout, shared by its passes: primal_cache_trace.wgsl stores paths
// (src/optim/primal/path_pool.rs drives it), primal_cached.wgsl shades the primal's pool
// (path_cache.rs) and the baseline's gradient_cached.wgsl differentiates the gradient's
// (estimator/baseline/pool.rs). An importing pass declares `cp` (PrimalCachedParams) and
// `path_cache` (array<u32>).
#import shared/camera
#import shared/path_encoding

// Mirrored by PrimalCachedParams in src/optim/primal/path_cache.rs (both passes bind one).
struct PrimalCachedParams {
    camera: CameraInfo,
    seed: u32,
    // Paths kept per pixel; all of them are shaded every iteration.
    spp: u32,
    techniques: u32,
    stride: u32,
    two_states: u32,
    // The slots traced anew: refresh_count of them from refresh_first on (modulo spp).
    refresh_first: u32,
    refresh_count: u32,
    // Vertices kept per path (the scene's depth, at most PATH_RECORD_VERTICES); the words
    // per path are CACHE_HEADER_WORDS + its vertices' and two arrivals per vertex.
    vertices: u32,
    // Whether the trace pass shades a first vertex without optimized textures only where a
    // later vertex or the environment's derivative may need it (the gradient's pool: such a
    // path adds nothing else to a gradient); the primal's stores every path whole.
    optimized_only: u32,
}

// A stored path: the header (arrival count in bits 0-3, vertex count in bits 4-7,
// CACHED_ENV_E), the radiance along the camera ray itself (emission at the hit, or with
// CACHED_ENV_E the camera ray's direction, the environment's radiance along it read when
// shaded), then per vertex CACHE_VERTEX_WORDS, then per arrival CACHE_ARRIVAL_WORDS; floats
// as their bits. A vertex: its triangle and fixed-point barycentrics, material, texture
// coordinates, position, the outgoing direction and the direction to the next vertex in its
// shading frame, and the material inputs the glTF material gives there (VX_*): shading it
// reads no geometry, unless an optimized normal map moves its frame (then the surface is
// rebuilt from the triangle). An arrival: its vertex count with CACHED_ENV_ARRIVAL, the
// direction (world space, then in its vertex's shading frame), the radiance, the factor (AR_*).
// The sizes (CACHE_*_WORDS, CACHE_MAX_VERTICES) come from src/gpu/abi.rs.
const VX_TRI: u32 = 0u;
const VX_MATERIAL: u32 = 3u;
const VX_UV: u32 = 4u;
const VX_P: u32 = 6u;
const VX_WO: u32 = 9u;
const VX_WI_NEXT: u32 = 12u;
const VX_GLTF: u32 = 15u;
const AR_WI: u32 = 1u;
const AR_WI_LOCAL: u32 = 4u;
const AR_RADIANCE: u32 = 7u;
const AR_SCALE: u32 = 10u;
const CACHED_ENV_E: u32 = 0x100u;
const CACHED_ENV_ARRIVAL: u32 = 0x100u;

fn cache_words() -> u32 {
    return CACHE_HEADER_WORDS + cp.vertices * (CACHE_VERTEX_WORDS + 2u * CACHE_ARRIVAL_WORDS);
}

fn put_vec3(w: u32, v: vec3f) {
    path_cache[w] = bitcast<u32>(v.x);
    path_cache[w + 1u] = bitcast<u32>(v.y);
    path_cache[w + 2u] = bitcast<u32>(v.z);
}

fn get_vec3(w: u32) -> vec3f {
    return vec3f(bitcast<f32>(path_cache[w]), bitcast<f32>(path_cache[w + 1u]), bitcast<f32>(path_cache[w + 2u]));
}

fn get_f32(w: u32) -> f32 {
    return bitcast<f32>(path_cache[w]);
}

// Arrival `a` of the stored path at `base` with `n_vertices` vertices, as its shading reads
// it: the vertex it arrives at (0-based), its direction in world space and in that vertex's
// frame as stored, its radiance (the environment's read anew along it) and its factor.
struct StoredArrival {
    vertex: u32,
    wi: vec3f,
    wi_local: vec3f,
    radiance: vec3f,
    scale: f32,
    env: bool,
}

fn stored_arrival(base: u32, n_vertices: u32, a: u32) -> StoredArrival {
    let w = base + CACHE_HEADER_WORDS + cp.vertices * CACHE_VERTEX_WORDS + a * CACHE_ARRIVAL_WORDS;
    let tag = path_cache[w];
    var out = StoredArrival(clamp(tag & 0xffu, 1u, n_vertices) - 1u, get_vec3(w + AR_WI), get_vec3(w + AR_WI_LOCAL), get_vec3(w + AR_RADIANCE), get_f32(w + AR_SCALE), (tag & CACHED_ENV_ARRIVAL) != 0u);
    if out.env {
        out.radiance = env_radiance(out.wi);
    }
    return out;
}

// Whether vertex material mi's shading frame moves with the textures (an optimized normal
// map).
fn frame_moves(mi: u32) -> bool {
    return NORMAL_MAPS && materials[mi].param_normal != NONE;
}

