//! The primal estimator: how each iteration's image (and so the adjoint) is rendered.
//!
//! - [`PrimalMode::Independent`]: a fresh `primal_spp` render of every camera, with random
//!   numbers of its own.
//! - [`PrimalMode::ControlVariate`]: the recursive control variate of Nicolet et al. 2023 in
//!   path space (src/optim/primal_cv.wgsl): the primal render also evaluates each of its samples
//!   under the previous iteration's textures (the same path; no extra ray), and
//!   `I_t = w (I_{t-1} - H_t) + F_t` carries the last image forward with a per-pixel weight
//!   from running statistics.
//!
//! Either way the image is an unbiased estimate of the current render, with random numbers
//! independent of the gradient samples, so the adjoint of an L2 or relMSE loss (affine in the
//! image) stays unbiased. The loss *value* is biased upwards by the image's variance (its mean
//! is L(E\[I\]) + Var(I) x the loss's weights), as with any noisy render; the control variate
//! lowers that bias with the variance.
pub mod path_cache;
pub(crate) mod path_pool;
pub(crate) use path_cache::PathCache;

use crate::gpu::Gpu;
use crate::optim::{PassKind, PassTimer};
use crate::render::WORKGROUP;
use crate::{Error, Result};
use bytemuck::{Pod, Zeroable};
use serde::Deserialize;

/// Group 0 of `primal_cv.wgsl`.
pub(crate) const PRIMAL_CV_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "primal_cv",
    group: 0,
    names: &["cp", "accum", "accum_prev", "cv_state"],
};

/// How the primal image of each iteration is estimated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PrimalMode {
    /// An independent render at `primal_spp`.
    #[default]
    Independent,
    /// The recursive control variate: the same render, combined with the last image.
    ControlVariate,
}

impl PrimalMode {
    /// The name used in task files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PrimalMode::Independent => "independent",
            PrimalMode::ControlVariate => "control_variate",
        }
    }
}

/// `PrimalCvParams` in src/optim/primal_cv.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct PrimalCvParams {
    pub n_pixels: u32,
    pub pixel_offset: u32,
    pub updates: u32,
    pub use_weight: u32,
    pub have_prev: u32,
    pub beta1: f32,
    pub beta2: f32,
    pub phase: u32,
    pub width: u32,
    pub height: u32,
    pub max_weight: f32,
    pub _pad0: u32,
}

/// Decay of the running means (as Adam's first moment).
pub const BETA1: f32 = 0.9;
/// Decay of the running second moments: a long memory, so that the weight of an iteration
/// hardly depends on the last few samples (which also make up the carried image).
pub const BETA2: f32 = 0.999;
/// The default upper clamp of the weight. With w -> 1 a pixel's image keeps its early noise
/// for many iterations, and an optimizer whose textures follow the images fits that noise
/// (the per-iteration unbiasedness holds for parameters independent of the noise, not for
/// parameters that learned from it). Measured on the default task (ReSTIR, 150 iterations):
/// observed-texel RMSE 0.211 with w <= 1, 0.160 with w <= 0.9 (independent renders: 0.159),
/// while the cap costs little variance: with fully correlated F and H the steady-state
/// variance is (1 - w) / (1 + w) of one render's, 0.05 at w = 0.9.
pub const DEFAULT_MAX_WEIGHT: f32 = 0.9;
/// Iterations before the weight is used (the statistics need one update first).
pub const WARMUP: u32 = 1;
/// vec4s of state per pixel (`CV_VEC4S`).
pub const STATE_VEC4S: u64 = crate::gpu::abi::CV_VEC4S as u64;

/// The control variate's state that carries over to the next iteration (for checkpoints).
#[derive(Clone, Debug, PartialEq)]
pub struct ControlVariateSnapshot {
    /// Per camera and pixel: the last image, running moments, variance and weight
    /// ([`STATE_VEC4S`] RGBA values).
    pub state: Vec<f32>,
    /// Iterations the control variate has run.
    pub iterations: u32,
}

struct Camera {
    /// Per phase (0: form the image, 1: update the statistics): each dispatch of one
    /// submission needs its own uniform.
    uniforms: [wgpu::Buffer; 2],
    params: PrimalCvParams,
    groups: [wgpu::BindGroup; 2],
}

/// The control variate's pass and per-pixel state.
pub(crate) struct ControlVariate {
    pipeline: wgpu::ComputePipeline,
    cameras: Vec<Camera>,
    state: wgpu::Buffer,
    grid: (u32, u32),
    /// Iterations run so far.
    iterations: u32,
    queue: wgpu::Queue,
}

/// Bytes of control-variate state for `n_cams` images of `pixels` pixels.
pub(crate) fn memory(pixels: u64, n_cams: u64) -> Vec<(String, u64)> {
    vec![(
        "primal_cv state".to_string(),
        16 * STATE_VEC4S * pixels * n_cams,
    )]
}

impl ControlVariate {
    /// The pass for `n_cams` cameras of `n_pixels` pixels, reading `accum` (F) and
    /// `accum_prev` (H).
    pub(crate) fn new(
        gpu: &Gpu,
        (width, height): (u32, u32),
        n_cams: usize,
        accum: &wgpu::Buffer,
        accum_prev: &wgpu::Buffer,
        max_weight: f32,
    ) -> Result<ControlVariate> {
        let n_pixels = width * height;
        let layout = gpu.pass_layout("primal_cv", 0)?;
        let pipeline = gpu.compute_pipeline("primal_cv", &[&layout])?;
        let sizes = memory(n_pixels as u64, n_cams as u64);
        let state = gpu.storage_zeroed(&sizes[0].0, sizes[0].1);
        let cameras = (0..n_cams)
            .map(|k| {
                let params = PrimalCvParams {
                    n_pixels,
                    pixel_offset: k as u32 * n_pixels,
                    beta1: BETA1,
                    beta2: BETA2,
                    width,
                    height,
                    max_weight,
                    ..Default::default()
                };
                let uniforms = [0, 1].map(|phase| {
                    gpu.uniform(
                        &format!("primal_cv params {k} phase {phase}"),
                        bytemuck::bytes_of(&params),
                    )
                });
                let groups = [0, 1].map(|phase| {
                    gpu.bind(
                        &PRIMAL_CV_GROUP,
                        "primal_cv",
                        &layout,
                        &[
                            ("cp", &uniforms[phase]),
                            ("accum", accum),
                            ("accum_prev", accum_prev),
                            ("cv_state", &state),
                        ],
                    )
                });
                Camera {
                    uniforms,
                    params,
                    groups,
                }
            })
            .collect();
        let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
        Ok(ControlVariate {
            pipeline,
            cameras,
            state,
            grid: crate::gpu::grid_2d(n_pixels, WORKGROUP, max_dim),
            iterations: 0,
            queue: gpu.queue.clone(),
        })
    }

    /// Record the combination for camera `k`, after its two-state render into the
    /// accumulators and before its loss pass.
    pub(crate) fn encode(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        k: usize,
        timer: &mut PassTimer,
    ) {
        let it = self.iterations;
        let cam = &mut self.cameras[k];
        cam.params.have_prev = (it > 0) as u32;
        cam.params.updates = it.saturating_sub(1);
        cam.params.use_weight = (it > WARMUP) as u32;
        for phase in 0..2 {
            cam.params.phase = phase as u32;
            self.queue
                .write_buffer(&cam.uniforms[phase], 0, bytemuck::bytes_of(&cam.params));
            crate::gpu::encode_timed_pass(
                enc,
                "primal_cv",
                &self.pipeline,
                &[&cam.groups[phase]],
                self.grid,
                timer.next(PassKind::Primal),
            );
        }
    }

    /// Called once an iteration's work is submitted.
    pub(crate) fn finish_iteration(&mut self) {
        self.iterations = self.iterations.saturating_add(1);
    }

    pub(crate) fn snapshot(&self, gpu: &Gpu) -> Result<ControlVariateSnapshot> {
        Ok(ControlVariateSnapshot {
            state: gpu.read_pod(&self.state)?,
            iterations: self.iterations,
        })
    }

    pub(crate) fn restore(&mut self, gpu: &Gpu, s: Option<&ControlVariateSnapshot>) -> Result<()> {
        match s {
            Some(s) => {
                if s.state.len() as u64 * 4 != self.state.size() {
                    return Err(Error::Invalid(
                        "the saved control-variate state does not match this optimizer's images"
                            .into(),
                    ));
                }
                gpu.queue
                    .write_buffer(&self.state, 0, bytemuck::cast_slice(&s.state));
                self.iterations = s.iterations;
            }
            None => {
                // Start afresh: the first iteration ignores the (stale) state.
                self.iterations = 0;
            }
        }
        Ok(())
    }

    /// The current image of camera `k` (the last iteration's I_t), RGB per pixel.
    pub(crate) fn image(&self, gpu: &Gpu, k: usize, n_pixels: usize) -> Result<Vec<[f32; 3]>> {
        let all: Vec<[f32; 4]> = gpu.read_pod(&self.state)?;
        let per = STATE_VEC4S as usize;
        Ok((0..n_pixels)
            .map(|i| {
                let v = all[(k * n_pixels + i) * per];
                [v[0], v[1], v[2]]
            })
            .collect())
    }
}
