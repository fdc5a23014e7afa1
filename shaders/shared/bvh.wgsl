// Software ray tracing: traversal of the binned-SAH BVH built on the host
// (src/scene/bvh.rs). shared/bvh_ray_query offers the same functions through hardware ray
// queries; the composer picks one of the two for `#import shared/bvh` (gpu/shaders.rs).
#import shared/scene
#import shared/triangle

const BVH_STACK: u32 = 64u;

// Entry distance of the ray into an AABB, or a huge value on a miss.
fn intersect_aabb(o: vec3f, inv_d: vec3f, bmin: vec3f, bmax: vec3f, tmax: f32) -> f32 {
    let t0 = (bmin - o) * inv_d;
    let t1 = (bmax - o) * inv_d;
    let tn = min(t0, t1);
    let tf = max(t0, t1);
    let enter = max(max(tn.x, tn.y), max(tn.z, 0.0));
    let exit = min(min(tf.x, tf.y), min(tf.z, tmax));
    return select(3.0e38, enter, enter <= exit);
}

fn safe_inverse(d: vec3f) -> vec3f {
    let eps = 1e-30;
    return vec3f(
        1.0 / select(d.x, eps, abs(d.x) < eps),
        1.0 / select(d.y, eps, abs(d.y) < eps),
        1.0 / select(d.z, eps, abs(d.z) < eps),
    );
}

// Closest hit with t in (0, tmax), or any hit when any_hit is true. Every node is pushed at
// most once, so the loop is bounded by the node count.
fn traverse(o: vec3f, d: vec3f, tmax: f32, any_hit: bool) -> Hit {
    var hit = Hit(tmax, NONE, 0.0, 0.0);
    if scene.n_nodes == 0u {
        return hit;
    }
    let inv_d = safe_inverse(d);
    var stack: array<u32, BVH_STACK>;
    var sp = 0u;
    var node = 0u;
    if intersect_aabb(o, inv_d, nodes[0].bmin, nodes[0].bmax, hit.t) > 1.0e38 {
        return hit;
    }
    for (var it = 0u; it <= scene.n_nodes; it++) {
        let n = nodes[node];
        if n.count > 0u {
            for (var k = 0u; k < n.count; k++) {
                let tri = n.left_first + k;
                let r = intersect_triangle(o, d, tri);
                if r.x > 0.0 && r.x < hit.t {
                    hit = Hit(r.x, tri, r.y, r.z);
                    if any_hit {
                        return hit;
                    }
                }
            }
            if sp == 0u {
                break;
            }
            sp -= 1u;
            node = stack[sp];
        } else {
            let a = n.left_first;
            let b = a + 1u;
            let ta = intersect_aabb(o, inv_d, nodes[a].bmin, nodes[a].bmax, hit.t);
            let tb = intersect_aabb(o, inv_d, nodes[b].bmin, nodes[b].bmax, hit.t);
            let near = select(b, a, ta <= tb);
            let far = select(a, b, ta <= tb);
            let tnear = min(ta, tb);
            let tfar = max(ta, tb);
            if tnear > 1.0e38 {
                if sp == 0u {
                    break;
                }
                sp -= 1u;
                node = stack[sp];
            } else {
                if tfar <= 1.0e38 && sp < BVH_STACK {
                    stack[sp] = far;
                    sp += 1u;
                }
                node = near;
            }
        }
    }
    return hit;
}

// The closest hit, or with any_hit any hit (which is all an occlusion test needs).
fn trace_ray(o: vec3f, d: vec3f, tmax: f32, any_hit: bool) -> Hit {
    return traverse(o, d, tmax, any_hit);
}

fn trace_closest(o: vec3f, d: vec3f, tmax: f32) -> Hit {
    return traverse(o, d, tmax, false);
}
