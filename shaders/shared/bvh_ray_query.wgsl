// Hardware ray tracing: the same functions as shared/bvh (trace_ray, trace_closest), through
// a ray query against the scene's acceleration structure, built by GpuScene::new from the
// triangles in the order the other scene buffers use, so a hit's primitive index is the
// triangle index. The composer substitutes this file for `#import shared/bvh` and adds
// `enable wgpu_ray_query;` when the device traces with ray queries (gpu/shaders.rs).
#import shared/scene
#import shared/triangle

@group(0) @binding(11) var scene_tlas: acceleration_structure;

fn trace_ray_query(o: vec3f, d: vec3f, tmax: f32, flags: u32) -> Hit {
    var rq: ray_query;
    rayQueryInitialize(&rq, scene_tlas, RayDesc(flags | RAY_FLAG_FORCE_OPAQUE, 0xFFu, 0.0, tmax, o, d));
    rayQueryProceed(&rq);
    let h = rayQueryGetCommittedIntersection(&rq);
    if h.kind == RAY_QUERY_INTERSECTION_NONE {
        return Hit(tmax, NONE, 0.0, 0.0);
    }
    return Hit(h.t, h.primitive_index, h.barycentrics.x, h.barycentrics.y);
}

fn trace_ray(o: vec3f, d: vec3f, tmax: f32, any_hit: bool) -> Hit {
    return trace_ray_query(o, d, tmax, select(0u, RAY_FLAG_TERMINATE_ON_FIRST_HIT, any_hit));
}

fn trace_closest(o: vec3f, d: vec3f, tmax: f32) -> Hit {
    return trace_ray_query(o, d, tmax, 0u);
}
