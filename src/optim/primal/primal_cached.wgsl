// The primal render from the path cache: one invocation per pixel, which keeps `spp` camera
// paths (its pool) in `path_cache`, stored by primal_cache_trace.wgsl (the slots it refreshed
// this iteration traced anew): the camera ray's hit and the later vertices, and every sample
// that reaches an emitter from one of them (an arrival: how many vertices, the direction from
// the last, the radiance, and the factor MIS weight / density of the whole path, all taken
// when it was traced). Every slot of the pool is shaded under the current textures, and with
// two_states under the previous ones, without a ray: the radiance times every vertex's BRDF x
// cos times the factor, as in the path's own iteration.
//
// Geometry, cameras and lights do not change, so a stored path is a sample of the same path
// space under any textures. Its densities (the BSDF sample's, which roughness and a normal map
// move, and the MIS weights) are those of the iteration that traced it: the sample is still
// unbiased for the current integrand, as long as every direction where the current integrand
// is nonzero could be drawn by some technique then (light sampling covers every emitter). The
// radiance of an arrival from the environment is read anew (an environment fit changes it).
// Accumulates as render.wgsl does (rgb sum, sample count in w).
#import primal/path_cache

@group(1) @binding(0) var<uniform> cp: PrimalCachedParams;
@group(1) @binding(1) var<storage, read_write> accum: array<vec4f>;
// As render.wgsl's (the samples dropped as not finite).
@group(1) @binding(2) var<storage, read_write> stats: array<atomic<u32>, 4>;
@group(1) @binding(3) var<storage, read_write> accum_prev: array<vec4f>;
@group(1) @binding(4) var<storage, read_write> path_cache: array<u32>;

// The value of the stored path at `base` seen from the camera at `origin`, under the current
// or (prev) the previous iteration's textures (and their normal maps' frames).
fn shade_path(base: u32, origin: vec3f, prev: bool) -> vec3f {
    let header = path_cache[base];
    var l = get_vec3(base + 1u);
    if (header & CACHED_ENV_E) != 0u {
        l = env_radiance(l);
    }
    let n_arr = header & 0xfu;
    let n_vertices = min((header >> 4u) & 0xfu, CACHE_MAX_VERTICES);
    if n_vertices == 0u {
        return l;
    }
    // Per vertex: its inputs, the outgoing direction and the one to the next vertex in its
    // frame, the frame where it moves (zero otherwise), and through[j], the BRDF x cos of the
    // vertices before it along the path.
    var mat: array<SurfaceMaterial, CACHE_MAX_VERTICES>;
    var wo: array<vec3f, CACHE_MAX_VERTICES>;
    var frame: array<mat3x3f, CACHE_MAX_VERTICES>;
    var through: array<vec3f, CACHE_MAX_VERTICES>;
    var seen_from = origin;
    use_prev_params = prev;
    for (var j = 0u; j < n_vertices; j++) {
        let w = base + CACHE_HEADER_WORDS + j * CACHE_VERTEX_WORDS;
        let mi = path_cache[w + VX_MATERIAL];
        let uv = vec2f(get_f32(w + VX_UV), get_f32(w + VX_UV + 1u));
        let gltf = SurfaceMaterial(get_vec3(w + VX_GLTF), get_f32(w + VX_GLTF + 3u), get_f32(w + VX_GLTF + 4u));
        mat[j] = with_optimized(mi, uv, gltf);
        wo[j] = get_vec3(w + VX_WO);
        var wi_next = get_vec3(w + VX_WI_NEXT);
        frame[j] = mat3x3f();
        let p = get_vec3(w + VX_P);
        if frame_moves(mi) {
            var sf = surface_at(seen_from, stored_hit(path_cache[w + VX_TRI], vec2u(path_cache[w + VX_TRI + 1u], path_cache[w + VX_TRI + 2u])));
            frame[j] = frame_of(sf, prev);
            wo[j] = to_local(frame[j], sf.wo);
        }
        through[j] = vec3f(1.0);
        if j > 0u {
            var wi_prev = get_vec3(w - CACHE_VERTEX_WORDS + VX_WI_NEXT);
            if frame_moves(path_cache[w - CACHE_VERTEX_WORDS + VX_MATERIAL]) {
                wi_prev = to_local(frame[j - 1u], normalize(p - seen_from));
            }
            through[j] = through[j - 1u] * brdf_eval_cos(mat[j - 1u], wo[j - 1u], wi_prev);
        }
        seen_from = p;
    }
    use_prev_params = false;
    for (var a = 0u; a < n_arr; a++) {
        let ar = stored_arrival(base, n_vertices, a);
        let j = ar.vertex;
        var wi = ar.wi_local;
        if any(frame[j][2] != vec3f(0.0)) {
            wi = to_local(frame[j], ar.wi);
        }
        l += through[j] * brdf_eval_cos(mat[j], wo[j], wi) * ar.radiance * ar.scale;
    }
    return l;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let width = cp.camera.width;
    let xy_px = tile_pixel(id.x + id.y * cp.stride, width, cp.camera.height);
    if xy_px.x == NONE {
        return;
    }
    let pixel = xy_px.y * width + xy_px.x;
    let words = cache_words();
    var sum = vec3f(0.0);
    var sum_prev = vec3f(0.0);
    var dropped = 0u;
    for (var s = 0u; s < cp.spp; s++) {
        let base = (pixel * cp.spp + s) * words;
        var l = array<vec3f, 2>(vec3f(0.0), vec3f(0.0));
        for (var state = 0u; state < select(1u, 2u, cp.two_states != 0u); state++) {
            l[state] = shade_path(base, cp.camera.origin, state == 1u);
        }
        if all(l[0] == l[0]) && all(abs(l[0]) < vec3f(3.0e38)) && all(l[1] == l[1]) && all(abs(l[1]) < vec3f(3.0e38)) {
            sum += l[0];
            sum_prev += l[1];
        } else {
            dropped += 1u;
        }
    }
    accum[pixel] += vec4f(sum, f32(cp.spp));
    if cp.two_states != 0u {
        accum_prev[pixel] += vec4f(sum_prev, f32(cp.spp));
    }
    if dropped > 0u {
        atomicAdd(&stats[RENDER_STAT_DROPPED], dropped);
    }
}
