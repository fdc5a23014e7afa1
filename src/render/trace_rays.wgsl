// Trace a list of rays, through the BVH or against every triangle (the reference for tests).
#import shared/bvh

// Mirrored by GpuTraceParams in src/render/layout.rs.
struct TraceParams {
    n_rays: u32,
    brute_force: u32,
    stride: u32,
    _pad: u32,
}

@group(1) @binding(0) var<uniform> tp: TraceParams;
// Two vec4 per ray: origin + tmax, direction + 0.
@group(1) @binding(1) var<storage, read> rays: array<vec4f>;
// One vec4 per ray: t, triangle index (bits), b1, b2.
@group(1) @binding(2) var<storage, read_write> hits: array<vec4f>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let i = id.x + id.y * tp.stride;
    if i >= tp.n_rays {
        return;
    }
    let o = rays[2u * i];
    let d = rays[2u * i + 1u].xyz;
    var hit: Hit;
    if tp.brute_force != 0u {
        hit = trace_brute_force(o.xyz, d, o.w);
    } else {
        hit = trace_closest(o.xyz, d, o.w);
    }
    hits[i] = vec4f(hit.t, bitcast<f32>(hit.tri), hit.b1, hit.b2);
}
