//! Rust mirrors of the renderer's GPU structs (shaders/shared/types.wgsl,
//! shaders/shared/camera.wgsl, src/render/render.wgsl, src/render/trace_rays.wgsl). The test below
//! checks every mirror in the crate, field by field, against naga's layout of its WGSL twin.
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// Invocations per workgroup of every pass.
pub const WORKGROUP: u32 = 64;

/// Camera constants for a pinhole camera at the given image size: the camera's intrinsics
/// scaled to it, or, without intrinsics, square pixels with the vertical field of view and
/// the principal point at the center. Its `light_base` is 0, every light of the scene; a
/// camera whose capture sees some of them takes [`GpuScene::camera_info`](super::GpuScene::camera_info)'s.
pub fn camera_info(cam: &crate::scene::Camera, width: u32, height: u32) -> GpuCameraInfo {
    let m = cam.world;
    let right = m.transform_vector3(Vec3::X).normalize_or(Vec3::X);
    let up = m.transform_vector3(Vec3::Y).normalize_or(Vec3::Y);
    let forward = m.transform_vector3(Vec3::NEG_Z).normalize_or(Vec3::NEG_Z);
    let [fx, fy, cx, cy] = cam.pixel_intrinsics(width, height);
    GpuCameraInfo {
        origin: m.transform_point3(Vec3::ZERO).to_array(),
        fx,
        right: right.to_array(),
        fy,
        up: up.to_array(),
        width,
        forward: forward.to_array(),
        height,
        cx,
        cy,
        light_base: 0,
        _pad: 0,
    }
}

/// `TriShading` in types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuTriShading {
    pub n0: [f32; 3],
    pub t0: u32,
    pub n1: [f32; 3],
    pub t1: u32,
    pub n2: [f32; 3],
    pub t2: u32,
    pub uv01: [f32; 4],
    pub uv2: [f32; 2],
    pub material: u32,
    pub light: u32,
}

/// `TexRef` in types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuTexRef {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
    pub flags: u32,
}

impl GpuTexRef {
    /// No texture (lookups return white).
    pub const NONE: GpuTexRef = GpuTexRef {
        offset: u32::MAX,
        width: 1,
        height: 1,
        flags: 0,
    };
}

/// `Material` in types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuMaterial {
    pub base_color: [f32; 4],
    pub emissive: [f32; 3],
    pub metallic: f32,
    pub roughness: f32,
    pub double_sided: u32,
    pub param_base_color: u32,
    pub param_metallic: u32,
    pub param_roughness: u32,
    pub normal_scale: f32,
    pub param_normal: u32,
    pub _pad: u32,
    pub base_color_tex: GpuTexRef,
    pub mr_tex: GpuTexRef,
    pub emissive_tex: GpuTexRef,
    pub normal_tex: GpuTexRef,
    pub uv_xf: [[f32; 4]; 8],
}

/// Unit direction to octahedral coordinates in [-1, 1]² (WGSL `oct_encode`,
/// shaders/shared/surface.wgsl); the zero vector gives NaN.
pub fn oct_encode(d: [f32; 3]) -> [f32; 2] {
    let l1 = d[0].abs() + d[1].abs() + d[2].abs();
    let n = [d[0] / l1, d[1] / l1, d[2] / l1];
    if n[2] >= 0.0 {
        return [n[0], n[1]];
    }
    let sign = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
    [
        (1.0 - n[1].abs()) * sign(n[0]),
        (1.0 - n[0].abs()) * sign(n[1]),
    ]
}

/// A vertex tangent (xyz, w = ±1) in one word for `TriShading`: 0 for none, else bit 31
/// set, bit 30 for w < 0, and the direction's octahedral coordinates in 15 bits each (about
/// 1e-4 rad; shaders/shared/surface.wgsl, tangent_at).
pub fn pack_tangent(t: glam::Vec4) -> u32 {
    let d = t.truncate();
    let l1 = d.x.abs() + d.y.abs() + d.z.abs();
    if !(l1 > 0.0) || !l1.is_finite() {
        return 0;
    }
    let e = oct_encode(d.to_array());
    let q = |x: f32| (((x + 1.0) * 0.5 * 32767.0).round() as u32).min(32767);
    (1 << 31) | if t.w < 0.0 { 1 << 30 } else { 0 } | q(e[0]) | (q(e[1]) << 15)
}

/// Light kinds (`crate::gpu::abi::light`, WGSL `LIGHT_*`).
pub const LIGHT_POINT: u32 = crate::gpu::abi::light::POINT;
/// Spot light.
pub const LIGHT_SPOT: u32 = crate::gpu::abi::light::SPOT;
/// Directional light.
pub const LIGHT_DIRECTIONAL: u32 = crate::gpu::abi::light::DIRECTIONAL;
/// Emissive triangle.
pub const LIGHT_AREA: u32 = crate::gpu::abi::light::AREA;
/// Environment map.
pub const LIGHT_ENV: u32 = crate::gpu::abi::light::ENV;

/// `Light` in types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuLight {
    pub position: [f32; 3],
    pub kind: u32,
    pub direction: [f32; 3],
    pub tri: u32,
    pub intensity: [f32; 3],
    pub range: f32,
    pub spot_scale: f32,
    pub spot_offset: f32,
    pub pmf: f32,
    pub cdf: f32,
}

/// `SceneInfo` in types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuSceneInfo {
    pub n_nodes: u32,
    pub n_tris: u32,
    pub n_lights: u32,
    pub env_light: u32,
    pub env_width: u32,
    pub env_height: u32,
    pub env_marginal: u32,
    pub env_conditional: u32,
    pub env_scale: f32,
    pub env_total: f32,
    pub scene_radius: f32,
    pub max_depth: u32,
    pub env_optimized: u32,
    pub env_bilinear: u32,
    pub _pad: [u32; 2],
}

/// `CameraInfo` in camera.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuCameraInfo {
    pub origin: [f32; 3],
    pub fx: f32,
    pub right: [f32; 3],
    pub fy: f32,
    pub up: [f32; 3],
    pub width: u32,
    pub forward: [f32; 3],
    pub height: u32,
    pub cx: f32,
    pub cy: f32,
    /// The first entry of the camera's capture's lights in the lights buffer
    /// ([`GpuScene::camera_info`](super::GpuScene::camera_info)).
    pub light_base: u32,
    pub _pad: u32,
}

/// `RenderParams` in render.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuRenderParams {
    pub camera: GpuCameraInfo,
    pub seed: u32,
    pub sample_offset: u32,
    pub spp: u32,
    pub techniques: u32,
    pub stride: u32,
    pub two_states: u32,
    pub _pad: [u32; 2],
}

/// `ParamTex` in types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuParamTex {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub filtering: u32,
    pub texel_offset: u32,
    /// The material input it replaces: 0 base color, 1 metallic, 2 roughness, 3 normal map
    /// (`material_param` in params.wgsl).
    pub slot: u32,
    pub _pad: u32,
}

/// `TraceParams` in trace_rays.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuTraceParams {
    pub n_rays: u32,
    pub brute_force: u32,
    pub stride: u32,
    pub _pad: u32,
}
