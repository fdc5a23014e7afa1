// The path cache's trace pass: one invocation per pixel and refreshed slot (refresh_count
// of them from refresh_first on, modulo spp, per pixel): the slot's camera sample is traced
// as render.wgsl traces one (the same camera-sample index), with camera_path keeping the
// whole path (record_paths), and stored (primal/path_cache.wgsl) for primal_cached.wgsl to
// shade. Paths of at most PATH_RECORD_VERTICES vertices (the depths whose arrivals
// camera_path records).
#import shared/rng
#import shared/camera
#import shared/integrator
#import primal/path_cache

@group(1) @binding(0) var<uniform> cp: PrimalCachedParams;
// As render.wgsl's: the rays traced.
@group(1) @binding(1) var<storage, read_write> stats: array<atomic<u32>, 4>;
@group(1) @binding(2) var<storage, read_write> path_cache: array<u32>;

// The hooks camera_path names for derivatives: a render takes none.
fn differentiate_later_vertex(sf: Surface, wi: vec3f, mat: SurfaceMaterial, mat_prev: SurfaceMaterial, weight: vec3f, weight_prev: vec3f) {}
fn differentiate_env(d: vec3f, weight: vec3f) {}

// Store the path camera_path (with record_paths) just traced along camera direction d: its
// vertices rebuilt from their triangles and barycentrics, as a stored path is.
fn store_path(base: u32, p: CameraPath, d: vec3f) {
    var n_vertices = 0u;
    let n_arr = min(n_arrivals, 2u * cp.vertices);
    for (var a = 0u; a < n_arr; a++) {
        n_vertices = max(n_vertices, arrivals[a].n);
    }
    var header = n_arr | (n_vertices << 4u);
    if p.hit.tri == NONE {
        header |= CACHED_ENV_E;
        put_vec3(base + 1u, d);
    } else {
        put_vec3(base + 1u, p.e);
    }
    path_cache[base] = header;
    var frames: array<mat3x3f, PATH_RECORD_VERTICES>;
    var seen_from = cp.camera.origin;
    for (var j = 0u; j < n_vertices; j++) {
        let w = base + CACHE_HEADER_WORDS + j * CACHE_VERTEX_WORDS;
        let sf = surface_at(seen_from, stored_hit(rec_tri[j], rec_kb[j]));
        frames[j] = sf.frame;
        path_cache[w + VX_TRI] = rec_tri[j];
        path_cache[w + VX_TRI + 1u] = rec_kb[j].x;
        path_cache[w + VX_TRI + 2u] = rec_kb[j].y;
        path_cache[w + VX_MATERIAL] = sf.material;
        path_cache[w + VX_UV] = bitcast<u32>(sf.uv.x);
        path_cache[w + VX_UV + 1u] = bitcast<u32>(sf.uv.y);
        put_vec3(w + VX_P, sf.p);
        put_vec3(w + VX_WO, to_local(sf.frame, sf.wo));
        put_vec3(w + VX_WI_NEXT, vec3f(0.0, 0.0, 1.0));
        if j > 0u {
            let prev = w - CACHE_VERTEX_WORDS;
            put_vec3(prev + VX_WI_NEXT, to_local(frames[j - 1u], normalize(sf.p - seen_from)));
        }
        let gltf = gltf_inputs(sf.material, sf.uv);
        put_vec3(w + VX_GLTF, gltf.base_color);
        path_cache[w + VX_GLTF + 3u] = bitcast<u32>(gltf.metallic);
        path_cache[w + VX_GLTF + 4u] = bitcast<u32>(gltf.roughness);
        seen_from = sf.p;
    }
    let first_arrival = base + CACHE_HEADER_WORDS + cp.vertices * CACHE_VERTEX_WORDS;
    for (var a = 0u; a < n_arr; a++) {
        let w = first_arrival + a * CACHE_ARRIVAL_WORDS;
        let ar = arrivals[a];
        let env = ar.env && scene.env_optimized != 0u;
        path_cache[w] = ar.n | select(0u, CACHED_ENV_ARRIVAL, env);
        put_vec3(w + AR_WI, ar.wi);
        put_vec3(w + AR_WI_LOCAL, to_local(frames[max(ar.n, 1u) - 1u], ar.wi));
        put_vec3(w + AR_RADIANCE, ar.radiance);
        path_cache[w + AR_SCALE] = bitcast<u32>(ar.scale);
    }
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let width = cp.camera.width;
    let n_pixels = width * cp.camera.height;
    let linear = id.x + id.y * cp.stride;
    // Invocations walk the image in tiles (tile_pixel), one image per refreshed slot.
    let tiled = ((width + 7u) / 8u) * ((cp.camera.height + 7u) / 8u) * 64u;
    let r = linear / tiled;
    if r >= cp.refresh_count {
        return;
    }
    let xy_px = tile_pixel(linear % tiled, width, cp.camera.height);
    if xy_px.x == NONE {
        return;
    }
    let pixel = xy_px.y * width + xy_px.x;
    light_base = cp.camera.light_base;
    let s = (cp.refresh_first + r) % cp.spp;
    // The slot's camera-sample index identifies its sample, as in render.wgsl.
    rng_init(cp.seed, s * n_pixels + pixel, 0u);
    let d = camera_direction(cp.camera, vec2f(f32(xy_px.x), f32(xy_px.y)) + rand2());
    var po = path_options();
    po.techniques = cp.techniques;
    po.compact_paths = true;
    po.record_paths = true;
    po.optimized_only = cp.optimized_only != 0u && scene.env_optimized == 0u;
    store_path((pixel * cp.spp + s) * cache_words(), camera_path(cp.camera.origin, d, po), d);
    atomicAdd(&stats[RENDER_STAT_CAMERA_RAYS], 1u);
    atomicAdd(&stats[RENDER_STAT_SHADOW_RAYS], shadow_rays);
    atomicAdd(&stats[RENDER_STAT_BSDF_RAYS], bsdf_rays);
}
