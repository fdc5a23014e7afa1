//! The uniforms and bind groups of ReSTIR's passes (`restir_candidates.wgsl`,
//! `restir_merge.wgsl`), with the tests of their layout against the WGSL.
use crate::render::layout::GpuCameraInfo;
use bytemuck::{Pod, Zeroable};

/// Cameras a ReSTIR optimizer can use (the camera index has three bits in a reservoir).
pub const MAX_CAMERAS: usize = super::abi::MAX_CAMERAS as usize;

/// Group 1 of `restir_candidates.wgsl`.
pub(crate) const CANDIDATES_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "restir_candidates",
    group: 1,
    names: &[
        "cp",
        "adjoint",
        "slots0",
        "slots1",
        "slots2",
        "slots3",
        "headers",
        "cstats",
        "targets",
        "observed_map",
        "grad",
        "env_grad",
        "claims",
    ],
};
/// Group 0 of `restir_claim.wgsl`.
pub(crate) const CLAIM_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "restir_claim",
    group: 0,
    names: &["slots0", "slots1", "slots2", "slots3", "claims"],
};
/// Group 1 of `restir_merge.wgsl`.
pub(crate) const MERGE_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "restir_merge",
    group: 1,
    names: &[
        "mp",
        "adjoint",
        "targets",
        "slots0",
        "slots1",
        "slots2",
        "slots3",
        "headers",
        "grad",
        "mstats",
        "observed_list",
        "fresh_moments",
        "variance",
    ],
};

/// `CandidateParams` in restir_candidates.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct CandidateParams {
    pub camera: GpuCameraInfo,
    pub seed: u32,
    pub spp: u32,
    pub stride: u32,
    pub inv_spp: f32,
    pub camera_index: u32,
    pub adjoint_offset: u32,
    pub positivize: u32,
    pub prev_targets: u32,
    pub smoothing: f32,
    pub target_cur: u32,
    pub target_prev: u32,
    pub phase: u32,
    pub claim_capacity: u32,
    pub grid_x: u32,
    pub grid_y: u32,
    pub _pad0: u32,
}

/// `MergeParams` in restir_merge.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MergeParams {
    pub n_observed: u32,
    pub n_pixels: u32,
    pub seed: u32,
    pub flags: u32,
    pub m_fresh: f32,
    pub m_kept: f32,
    pub inv_spp: f32,
    pub n_textures: u32,
    pub stride: u32,
    pub target_cur: u32,
    pub target_prev: u32,
    pub moment_decay: f32,
    pub moment_bias: f32,
    pub variance_factor: f32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub origins: [[f32; 4]; MAX_CAMERAS],
}

/// Its uniforms and bind groups, for the contract test (`crate::contract_tests`).
#[cfg(test)]
mod contract_tests {
    use crate::contract_tests::mirror;

    // Its uniforms, field by field against naga's layout of its WGSL.
    #[test]
    fn uniform_mirrors_match_wgsl_field_by_field() {
        mirror!(
            "restir_candidates",
            "CandidateParams",
            super::CandidateParams,
            [
                camera,
                seed,
                spp,
                stride,
                inv_spp,
                camera_index,
                adjoint_offset,
                positivize,
                prev_targets,
                smoothing,
                target_cur,
                target_prev,
                phase,
                claim_capacity,
                grid_x,
                grid_y
            ]
        );
        mirror!(
            "restir_merge",
            "MergeParams",
            super::MergeParams,
            [
                n_observed,
                n_pixels,
                seed,
                flags,
                m_fresh,
                m_kept,
                inv_spp,
                n_textures,
                stride,
                target_cur,
                target_prev,
                moment_decay,
                moment_bias,
                variance_factor,
                origins
            ]
        );
    }
}
