//! The baseline estimator (gradient.wgsl): plain Monte Carlo. Every camera sample
//! differentiates its light-sampled and BSDF-sampled contributions with respect to the
//! material at its hit point and adds them, weighted by its pixel's adjoint, into the texels
//! that the texture filter touches. Float additions are bounded compare-and-swap loops on
//! 32-bit atomics; an exhausted bound is counted, never silently lost.
use super::{Estimator, EstimatorState, Frame, Kind, Method, OptionsKind, Setup};
use crate::gpu::encode_timed_pass;
use crate::gpu::Gpu;
use crate::optim::{pass_seed, FaultCounts, PassKind, PassTimer, Seeds};
use crate::render::layout::GpuCameraInfo;
use crate::render::{Techniques, WORKGROUP};
use crate::Result;
use bytemuck::{Pod, Zeroable};

/// The baseline as the registry knows it.
pub const KIND: Kind = Kind {
    name: "baseline",
    summary: "plain Monte Carlo: every sample adds its derivative to the texels it touches",
    options: OptionsKind::NONE,
    wgsl: &[("gradient", include_str!("gradient.wgsl"))],
    generated: &[],
    groups: &[GRADIENT_GROUP],
    passes: &["gradient"],
    max_cameras: None,
    memory: super::no_memory,
    warnings: super::no_warnings,
    every_texel: super::observed_only,
    build: |setup| Ok(Box::new(Baseline::new(setup)?)),
};

/// Group 1 of `gradient.wgsl`.
pub(crate) const GRADIENT_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "gradient",
    group: 1,
    names: &["gp", "adjoint", "grad", "gstats", "env_grad"],
};

/// `GradientParams` in gradient.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GradientParams {
    pub camera: GpuCameraInfo,
    pub seed: u32,
    pub sample_offset: u32,
    pub spp: u32,
    pub techniques: u32,
    pub stride: u32,
    pub inv_spp: f32,
    pub adjoint_offset: u32,
    pub _pad: u32,
}

/// `gstats` slots of gradient.wgsl.
const STAT_LOST: usize = crate::gpu::abi::stat::GRADIENT_LOST as usize;
const STAT_DROPPED: usize = crate::gpu::abi::stat::GRADIENT_DROPPED as usize;

struct Camera {
    uniform: wgpu::Buffer,
    params: GradientParams,
    /// Per parity of the iteration (the adjoint buffers alternate).
    groups: [wgpu::BindGroup; 2],
}

/// The baseline estimator's passes and buffers.
pub(crate) struct Baseline {
    pipeline: wgpu::ComputePipeline,
    cameras: Vec<Camera>,
    grad: wgpu::Buffer,
    stats: wgpu::Buffer,
    grid: (u32, u32),
    queue: wgpu::Queue,
}

impl Baseline {
    pub(crate) fn new(s: &Setup) -> Result<Baseline> {
        let gpu = s.gpu;
        let layout = gpu.pass_layout("gradient", 1)?;
        let pipeline = s.scene.pipeline(gpu, "gradient", &[&s.scene.layout, &layout])?;
        let stats = gpu.storage_zeroed("gradient stats", 16);
        let n_pixels = s.width * s.height;
        let cameras = s
            .cameras
            .iter()
            .enumerate()
            .map(|(k, &camera)| {
                let params = GradientParams {
                    camera,
                    spp: s.gradient_spp,
                    techniques: Techniques::Mis.bits(),
                    stride: s.grid.0 * WORKGROUP,
                    inv_spp: 1.0 / s.gradient_spp as f32,
                    adjoint_offset: k as u32 * n_pixels,
                    ..Default::default()
                };
                let uniform =
                    gpu.uniform(&format!("gradient params {k}"), bytemuck::bytes_of(&params));
                let groups = [0usize, 1].map(|p| {
                    gpu.bind(
                        &GRADIENT_GROUP,
                        "gradient",
                        &layout,
                        &[
                            ("gp", &uniform),
                            ("adjoint", &s.adjoint[p]),
                            ("grad", s.grad),
                            ("gstats", &stats),
                            ("env_grad", s.env_grad),
                        ],
                    )
                });
                Camera {
                    uniform,
                    params,
                    groups,
                }
            })
            .collect();
        Ok(Baseline {
            pipeline,
            cameras,
            grad: s.grad.clone(),
            stats,
            grid: s.grid,
            queue: gpu.queue.clone(),
        })
    }
}

impl Estimator for Baseline {
    fn encode(&mut self, enc: &mut wgpu::CommandEncoder, frame: &Frame, timer: &mut PassTimer) {
        enc.clear_buffer(&self.grad, 0, None);
        for (k, cam) in self.cameras.iter_mut().enumerate() {
            cam.params.seed = pass_seed(frame.seed, frame.iteration, k as u32, Seeds::GRADIENT);
            self.queue
                .write_buffer(&cam.uniform, 0, bytemuck::bytes_of(&cam.params));
            encode_timed_pass(
                enc,
                "gradient",
                &self.pipeline,
                &[frame.scene_group, &cam.groups[frame.parity()]],
                self.grid,
                timer.next(PassKind::Gradient),
            );
        }
    }

    fn uses_previous_state(&self) -> bool {
        false
    }

    fn faults(&self, gpu: &Gpu, f: &mut FaultCounts) -> Result<()> {
        let g: Vec<u32> = gpu.read_pod(&self.stats)?;
        f.lost_updates += g[STAT_LOST];
        f.dropped_gradient += g[STAT_DROPPED];
        Ok(())
    }

    fn snapshot(&self, _gpu: &Gpu, _iteration: u32) -> Result<EstimatorState> {
        Ok(EstimatorState::new(Method::BASELINE))
    }

    fn restore(&mut self, _: &Gpu, _: Option<&EstimatorState>, _: u32) -> Result<()> {
        Ok(())
    }

    fn state_bytes(&self) -> u64 {
        0
    }

    fn set_techniques(&mut self, techniques: Techniques) -> Result<()> {
        for cam in &mut self.cameras {
            cam.params.techniques = techniques.bits();
        }
        Ok(())
    }
}

#[cfg(test)]
mod contract_tests {
    use crate::contract_tests::mirror;

    // Its uniforms, field by field against naga's layout of its WGSL.
    #[test]
    fn uniform_mirrors_match_wgsl_field_by_field() {
        mirror!(
            "gradient",
            "GradientParams",
            super::GradientParams,
            [
                camera,
                seed,
                sample_offset,
                spp,
                techniques,
                stride,
                inv_spp,
                adjoint_offset
            ]
        );
    }
}
