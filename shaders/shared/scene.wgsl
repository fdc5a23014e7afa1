// Scene bindings, group 0, shared by every pass that traces rays.
// The layout is reflected from here (Gpu::pass_layout); GpuScene::new binds the buffers.
// With ray queries, shared/bvh_ray_query adds the acceleration structure as binding 11.
#import shared/types

@group(0) @binding(0) var<storage, read> nodes: array<BvhNode>;
@group(0) @binding(1) var<storage, read> tri_positions: array<vec4f>;
@group(0) @binding(2) var<storage, read> tri_shading: array<TriShading>;
@group(0) @binding(3) var<storage, read> materials: array<Material>;
@group(0) @binding(4) var<storage, read> texels: array<u32>;
@group(0) @binding(5) var<storage, read> lights: array<Light>;
@group(0) @binding(6) var<storage, read> env: array<f32>;
@group(0) @binding(7) var<uniform> scene: SceneInfo;
@group(0) @binding(8) var<storage, read> param_textures: array<ParamTex>;
@group(0) @binding(9) var<storage, read> params: array<f32>;
// The optimized textures of the previous iteration (ReSTIR evaluates kept samples under both).
@group(0) @binding(10) var<storage, read> params_prev: array<f32>;
