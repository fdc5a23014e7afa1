//! Rust mirrors of the GPU structs. Keep in sync with shaders/shared/types.wgsl,
//! shaders/shared/camera.wgsl and shaders/render.wgsl.
use bytemuck::{Pod, Zeroable};

/// `TriShading` in types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuTriShading {
    pub n0: [f32; 4],
    pub n1: [f32; 4],
    pub n2: [f32; 4],
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
    pub _pad: [u32; 3],
    pub base_color_tex: GpuTexRef,
    pub mr_tex: GpuTexRef,
    pub emissive_tex: GpuTexRef,
    pub uv_xf: [[f32; 4]; 6],
}

/// Light kinds, as `LIGHT_*` in types.wgsl.
pub const LIGHT_POINT: u32 = 0;
/// Spot light.
pub const LIGHT_SPOT: u32 = 1;
/// Directional light.
pub const LIGHT_DIRECTIONAL: u32 = 2;
/// Emissive triangle.
pub const LIGHT_AREA: u32 = 3;
/// Environment map.
pub const LIGHT_ENV: u32 = 4;

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
    pub _pad: u32,
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
    pub _pad: [u32; 2],
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
    pub _pad: [u32; 2],
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::size_of;

    // Sizes as naga computes them for the WGSL structs.
    fn wgsl_size(pass: &str, name: &str) -> usize {
        let module = crate::gpu::shaders::validate(pass).unwrap();
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).unwrap();
        let (h, _) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no WGSL struct {name} in {pass}"));
        layouter[h].size as usize
    }

    // Sizes as naga lays out the WGSL structs.
    #[test]
    fn sizes_match_wgsl() {
        for (pass, name, size) in [
            ("render", "TriShading", size_of::<GpuTriShading>()),
            ("render", "TexRef", size_of::<GpuTexRef>()),
            ("render", "Material", size_of::<GpuMaterial>()),
            ("render", "Light", size_of::<GpuLight>()),
            ("render", "SceneInfo", size_of::<GpuSceneInfo>()),
            ("render", "CameraInfo", size_of::<GpuCameraInfo>()),
            ("render", "RenderParams", size_of::<GpuRenderParams>()),
            ("render", "ParamTex", size_of::<GpuParamTex>()),
            ("render", "BvhNode", size_of::<crate::scene::bvh::BvhNode>()),
            ("trace_rays", "TraceParams", size_of::<GpuTraceParams>()),
            (
                "gradient",
                "GradientParams",
                size_of::<crate::optim::estimator::baseline::GradientParams>(),
            ),
            (
                "loss",
                "LossParams",
                size_of::<crate::optim::loss::LossParams>(),
            ),
            (
                "adam",
                "AdamParams",
                size_of::<crate::optim::adam::AdamParams>(),
            ),
            (
                "restir_candidates",
                "CandidateParams",
                size_of::<crate::optim::restir::CandidateParams>(),
            ),
            (
                "restir_merge",
                "MergeParams",
                size_of::<crate::optim::restir::MergeParams>(),
            ),
            (
                "primal_cv",
                "PrimalCvParams",
                size_of::<crate::optim::primal::PrimalCvParams>(),
            ),
            (
                "observed_texels",
                "ObservedParams",
                size_of::<crate::optim::observed::ObservedParams>(),
            ),
            (
                "texture_export",
                "ExportParams",
                size_of::<crate::optim::texture_export::ExportParams>(),
            ),
        ] {
            assert_eq!(size, wgsl_size(pass, name), "{name}");
        }
    }
}
