// The baseline gradient from its path pool: one invocation per pixel, which keeps `spp`
// camera paths in `path_cache` (stored by primal_cache_trace.wgsl from the gradient's own
// random numbers, the slots refreshed this iteration traced anew; the layout of
// primal/path_cache.wgsl). Each stored path is shaded under the current textures without a
// ray, and its derivative is scattered as gradient.wgsl scatters a traced sample's.
//
// A stored path's value is a sum over its arrivals (the samples that reached an emitter from
// one of its vertices): C_a = through_j f_j(wi_a) L_a s_a, where through_j is the product of
// the BRDF x cos of the vertices before j along the path (f_k(wo_k, wi_next_k)), L_a the
// radiance and s_a the MIS weight over the densities of the iteration that traced it. Its
// derivative with respect to the inputs at vertex k is
// - for the arrivals at k: through_k df_k(wi_a) L_a s_a;
// - for those beyond k: through_k df_k(wi_next_k) R_k, where R_k sums what the path brings
//   back to k along wi_next_k: for each later arrival the BRDF x cos of the vertices between
//   k and it, times its f_j(wi_a) L_a s_a;
// and with an optimized environment, d C_a / d L_a for the arrivals from it (and 1 for a
// camera ray that escapes). These are the terms path replay computes when the path is traced
// (shared/integrator.wgsl); here they are summed over the stored arrivals. The densities are
// those of the iteration that traced the path, which keeps the estimate unbiased for the
// current textures (primal/primal_cached.wgsl says why).
#import shared/adjoint_pixel
#import shared/gradient_scatter
#import shared/env_gradient
#import primal/path_cache

// Mirrored by GradientCachedParams in src/optim/estimator/baseline/pool.rs.
struct GradientCachedParams {
    // Where this camera's pixels start in adjoint[].
    adjoint_offset: u32,
    // 1 / (paths shaded per pixel).
    inv_spp: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(1) @binding(0) var<uniform> cp: PrimalCachedParams;
@group(1) @binding(1) var<uniform> gcp: GradientCachedParams;
// As gradient.wgsl's.
@group(1) @binding(2) var<storage, read> adjoint: array<vec4f>;
@group(1) @binding(3) var<storage, read_write> grad: array<atomic<u32>>;
@group(1) @binding(4) var<storage, read_write> gstats: array<atomic<u32>, 4>;
@group(1) @binding(5) var<storage, read_write> env_grad: array<atomic<u32>>;
@group(1) @binding(6) var<storage, read_write> path_cache: array<u32>;

// Vertex j of the stored path at `base`, rebuilt from its triangle, seen from `seen_from`
// (for a vertex whose frame moves with an optimized normal map).
fn stored_surface(base: u32, j: u32, seen_from: vec3f) -> Surface {
    let w = base + CACHE_HEADER_WORDS + j * CACHE_VERTEX_WORDS;
    return surface_at(seen_from, stored_hit(path_cache[w + VX_TRI], vec2u(path_cache[w + VX_TRI + 1u], path_cache[w + VX_TRI + 2u])));
}

// The derivative of BRDF x cos at vertex j of the stored path at `base` towards wi (in its
// shading frame), with the normal map's where its frame moves (the vertex seen from
// `seen_from`).
fn stored_vertex_grad(mat: SurfaceMaterial, wo: vec3f, wi: vec3f, moves: bool, base: u32, j: u32, seen_from: vec3f) -> BrdfGrad {
    var bg = brdf_eval_cos_grad(mat, wo, wi);
    if moves {
        bg.d_normal = normal_rgb_grad(stored_surface(base, j, seen_from), false, mat, wo, wi);
    }
    return bg;
}

// Differentiate the stored path at `base` (seen from `origin`) with the pixel's adjoint.
fn differentiate_path(base: u32, origin: vec3f, adj: vec3f) {
    let header = path_cache[base];
    if (header & CACHED_ENV_E) != 0u && scene.env_optimized != 0u {
        differentiate_env(get_vec3(base + 1u), vec3f(1.0));
    }
    let n_arr = header & 0xfu;
    let n_vertices = min((header >> 4u) & 0xfu, CACHE_MAX_VERTICES);
    if n_vertices == 0u {
        return;
    }
    // Per vertex: its material and uv, inputs, directions (outgoing, to the next vertex) in
    // its frame, where it is seen from, whether its frame moves and that frame, through[j],
    // and R[j] (above).
    var mi: array<u32, CACHE_MAX_VERTICES>;
    var uv: array<vec2f, CACHE_MAX_VERTICES>;
    var mat: array<SurfaceMaterial, CACHE_MAX_VERTICES>;
    var wo: array<vec3f, CACHE_MAX_VERTICES>;
    var wi_next: array<vec3f, CACHE_MAX_VERTICES>;
    var viewer: array<vec3f, CACHE_MAX_VERTICES>;
    var moves: array<bool, CACHE_MAX_VERTICES>;
    var frame: array<mat3x3f, CACHE_MAX_VERTICES>;
    var through: array<vec3f, CACHE_MAX_VERTICES>;
    var rest: array<vec3f, CACHE_MAX_VERTICES>;
    var seen_from = origin;
    for (var j = 0u; j < n_vertices; j++) {
        let w = base + CACHE_HEADER_WORDS + j * CACHE_VERTEX_WORDS;
        mi[j] = path_cache[w + VX_MATERIAL];
        uv[j] = vec2f(get_f32(w + VX_UV), get_f32(w + VX_UV + 1u));
        let gltf = SurfaceMaterial(get_vec3(w + VX_GLTF), get_f32(w + VX_GLTF + 3u), get_f32(w + VX_GLTF + 4u));
        mat[j] = with_optimized(mi[j], uv[j], gltf);
        wo[j] = get_vec3(w + VX_WO);
        wi_next[j] = get_vec3(w + VX_WI_NEXT);
        moves[j] = frame_moves(mi[j]);
        viewer[j] = seen_from;
        let p = get_vec3(w + VX_P);
        if moves[j] {
            let sf = stored_surface(base, j, seen_from);
            frame[j] = sf.frame;
            wo[j] = to_local(sf.frame, sf.wo);
        }
        if j > 0u && moves[j - 1u] {
            wi_next[j - 1u] = to_local(frame[j - 1u], normalize(p - seen_from));
        }
        rest[j] = vec3f(0.0);
        seen_from = p;
    }
    through[0] = vec3f(1.0);
    for (var j = 1u; j < n_vertices; j++) {
        through[j] = through[j - 1u] * brdf_eval_cos(mat[j - 1u], wo[j - 1u], wi_next[j - 1u]);
    }
    for (var a = 0u; a < n_arr; a++) {
        let ar = stored_arrival(base, n_vertices, a);
        let j = ar.vertex;
        var wi = ar.wi_local;
        if moves[j] {
            wi = to_local(frame[j], ar.wi);
        }
        let bg = stored_vertex_grad(mat[j], wo[j], wi, moves[j], base, j, viewer[j]);
        if ar.env {
            differentiate_env(ar.wi, through[j] * bg.value * ar.scale);
        }
        scatter(materials[mi[j]], uv[j], bg, through[j] * ar.radiance * ar.scale, adj);
        // What it brings back to every vertex before j, along that vertex's way on.
        var after = bg.value * ar.radiance * ar.scale;
        for (var k = j; k > 0u; k--) {
            rest[k - 1u] += after;
            after *= brdf_eval_cos(mat[k - 1u], wo[k - 1u], wi_next[k - 1u]);
        }
    }
    for (var k = 0u; k + 1u < n_vertices; k++) {
        if any(rest[k] != vec3f(0.0)) {
            let bg = stored_vertex_grad(mat[k], wo[k], wi_next[k], moves[k], base, k, viewer[k]);
            scatter(materials[mi[k]], uv[k], bg, through[k] * rest[k], adj);
        }
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u, @builtin(local_invocation_index) lid: u32) {
    env_local_begin(lid, true);
    let a = adjoint_pixel(id.x + id.y * cp.stride, cp.camera, gcp.adjoint_offset, gcp.inv_spp);
    if a.pixel != NONE {
        env_adj = a.adj;
        let words = cache_words();
        for (var s = 0u; s < cp.spp; s++) {
            differentiate_path((a.pixel * cp.spp + s) * words, cp.camera.origin, a.adj);
        }
        atomicAdd(&gstats[GRADIENT_STAT_SAMPLES], cp.spp);
        if scatter_lost > 0u {
            atomicAdd(&gstats[GRADIENT_STAT_LOST], scatter_lost);
        }
        if scatter_dropped > 0u {
            atomicAdd(&gstats[GRADIENT_STAT_DROPPED], scatter_dropped);
        }
    }
    env_local_flush(lid, true);
}
