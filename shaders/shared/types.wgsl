// GPU structs shared by every pass, mirrored in src/render/layout.rs (Gpu* types).
#import gen/abi

const PI: f32 = 3.14159265358979;
const INV_PI: f32 = 0.318309886183791;
const NONE: u32 = 0xffffffffu;

// BVH node: a leaf when count > 0 (triangles left_first .. left_first+count), otherwise an
// inner node whose children are left_first and left_first + 1.
struct BvhNode {
    bmin: vec3f,
    left_first: u32,
    bmax: vec3f,
    count: u32,
}

// Shading data of one triangle (BVH order). light: index into lights[] when emissive, else NONE.
// t0..t2: the vertex tangents for normal maps, packed (shared/surface.wgsl, tangent_at; 0: none).
struct TriShading {
    n0: vec3f,
    t0: u32,
    n1: vec3f,
    t1: u32,
    n2: vec3f,
    t2: u32,
    uv01: vec4f,
    uv2: vec2f,
    material: u32,
    light: u32,
}

// A texture as used by one material slot. offset: first texel in texels[], NONE when absent.
// flags: bits 0-1 wrap s, bits 2-3 wrap t (0 repeat, 1 clamp, 2 mirror), bit 4 sRGB, bit 5 nearest.
struct TexRef {
    offset: u32,
    width: u32,
    height: u32,
    flags: u32,
}

struct Material {
    base_color: vec4f,
    emissive: vec3f,
    metallic: f32,
    roughness: f32,
    double_sided: u32,
    // Optimized textures replacing base color, metallic, roughness: indices into
    // param_textures[], NONE when the slot is not optimized (param_normal below).
    param_base_color: u32,
    param_metallic: u32,
    param_roughness: u32,
    // normalTexture's scale of the tangent-space normal's X and Y.
    normal_scale: f32,
    // The optimized tangent-space normal map replacing normal_tex (NONE when not optimized).
    param_normal: u32,
    _pad1: u32,
    base_color_tex: TexRef,
    mr_tex: TexRef,
    emissive_tex: TexRef,
    // Tangent-space normal map (linear).
    normal_tex: TexRef,
    // Per slot (base color, metallic-roughness, emissive, normal) a 2x3 UV transform, two
    // rows each.
    uv_xf: array<vec4f, 8>,
}

// intensity: color x intensity (cd for point/spot, lux for directional). direction: where the
// light points (spot, directional). tri: the emissive triangle of an area light.
// pmf / cdf: probability of choosing this light for NEE, and the running sum up to it.
struct Light {
    position: vec3f,
    kind: u32,
    direction: vec3f,
    tri: u32,
    intensity: vec3f,
    range: f32,
    spot_scale: f32,
    spot_offset: f32,
    pmf: f32,
    cdf: f32,
}

// Scene-wide constants. env[] holds RGB radiance (3 floats per texel), then the marginal CDF
// over rows (height+1 floats), then one conditional CDF per row (width+1 floats each).
struct SceneInfo {
    n_nodes: u32,
    n_tris: u32,
    n_lights: u32,
    env_light: u32,
    env_width: u32,
    env_height: u32,
    env_marginal: u32,
    env_conditional: u32,
    env_scale: f32,
    env_total: f32,
    scene_radius: f32,
    // Vertices of a camera path (1: direct light only; see shared/integrator.wgsl).
    max_depth: u32,
    // 1 when the environment is optimized: the gradient passes differentiate it
    // (shared/env_gradient.wgsl).
    env_optimized: u32,
    // 1: the environment is looked up bilinearly (shared/lights.wgsl, env_footprint).
    env_bilinear: u32,
    _pad1: u32,
    _pad2: u32,
}

// An optimized texture: linear values, `channels` floats per texel from params[offset], row 0
// at v = 0, repeat wrap. filtering: 0 nearest, 1 bilinear. Mirrored by GpuParamTex in
// src/render/layout.rs.
// texel_offset: index of the texture's first texel among the texels of all optimized textures
// (reservoirs are per texel).
struct ParamTex {
    offset: u32,
    width: u32,
    height: u32,
    channels: u32,
    filtering: u32,
    texel_offset: u32,
    // The material input it replaces (shared/params.wgsl, material_param's slot).
    slot: u32,
    _pad0: u32,
}

struct Hit {
    t: f32,
    tri: u32,
    b1: f32,
    b2: f32,
}

// What the value of a direct-lighting path depends on besides the incident radiance, once
// geometry is fixed: the hit's material, texture coordinates and fixed material inputs
// (shared/surface.wgsl, fixed_pack), and the outgoing and incident directions in its
// shading frame (octahedral, shared/surface.wgsl). ReSTIR stores it; the
// gradient passes evaluate every sample at the decoded directions, so a stored path
// re-evaluates to the same value (shared/surface.wgsl, path_factor).
struct PathVertex {
    material: u32,
    uv: vec2f,
    wo: vec2f,
    wi: vec2f,
    fixed: vec4f,
    // The glTF roughness: with base color, metallic and roughness all from the glTF
    // material (only a normal map optimized), five inputs that `fixed` cannot hold.
    fixed_roughness: f32,
}
