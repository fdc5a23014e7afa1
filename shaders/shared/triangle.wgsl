// Ray-triangle intersection, and the brute-force reference that tests compare both tracers
// (shared/bvh and shared/bvh_ray_query) with.
#import shared/scene

// Moeller-Trumbore. Returns t (or -1 on a miss) and the barycentrics of vertices 1 and 2.
fn intersect_triangle(o: vec3f, d: vec3f, tri: u32) -> vec3f {
    let p0 = tri_positions[3u * tri].xyz;
    let e1 = tri_positions[3u * tri + 1u].xyz - p0;
    let e2 = tri_positions[3u * tri + 2u].xyz - p0;
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    if abs(det) < 1e-20 {
        return vec3f(-1.0, 0.0, 0.0);
    }
    let inv = 1.0 / det;
    let tv = o - p0;
    let u = dot(tv, pv) * inv;
    if u < 0.0 || u > 1.0 {
        return vec3f(-1.0, 0.0, 0.0);
    }
    let qv = cross(tv, e1);
    let v = dot(d, qv) * inv;
    if v < 0.0 || u + v > 1.0 {
        return vec3f(-1.0, 0.0, 0.0);
    }
    return vec3f(dot(e2, qv) * inv, u, v);
}

// Reference for tests: every triangle, no BVH. Bounded by the triangle count.
fn trace_brute_force(o: vec3f, d: vec3f, tmax: f32) -> Hit {
    var hit = Hit(tmax, NONE, 0.0, 0.0);
    for (var tri = 0u; tri < scene.n_tris; tri++) {
        let r = intersect_triangle(o, d, tri);
        if r.x > 0.0 && r.x < hit.t {
            hit = Hit(r.x, tri, r.y, r.z);
        }
    }
    return hit;
}
