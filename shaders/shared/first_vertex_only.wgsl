// For passes that call camera_path (shared/integrator.wgsl) without `replay`: the hook it
// names for the derivatives at a path's later vertices, never called there.
fn differentiate_later_vertex(mi: u32, uv: vec2f, wo: vec3f, wi: vec3f, mat: SurfaceMaterial, mat_prev: SurfaceMaterial, weight: vec3f, weight_prev: vec3f) {}
