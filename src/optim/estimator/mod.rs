//! Gradient estimators. Each one lives in its own module and owns its pipelines, bind groups,
//! buffers, GPU struct mirrors, memory plan, checkpoint state and fault counters; the
//! optimizer calls it through the `Estimator` trait once per iteration, after the primal render and
//! the loss have written every camera's adjoint.
//!
//! - [`baseline`]: plain Monte Carlo, every sample adds its derivative to the texels it
//!   touches (shaders/gradient.wgsl).
//! - [`restir`]: parameter-space ReSTIR, two reservoirs per texel reused across iterations
//!   (shaders/restir_candidates.wgsl, shaders/restir_merge.wgsl).
pub mod baseline;
mod reservoir_test;
pub mod restir;

use super::{FaultCounts, PassTimer, Settings};
use crate::gpu::Gpu;
use crate::render::layout::GpuCameraInfo;
use crate::render::{GpuScene, Techniques};
use crate::Result;
pub use restir::{Confidence, RestirOptions, RestirSnapshot};

/// The gradient estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Method {
    /// Plain Monte Carlo: every candidate adds its value to the texels it touches.
    Baseline,
    /// Parameter-space ReSTIR.
    #[default]
    Restir,
}

impl Method {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Baseline => "baseline",
            Method::Restir => "restir",
        }
    }
}

/// What an estimator is built from: the optimizer's scene, images and shared buffers.
pub(crate) struct Setup<'a> {
    pub gpu: &'a Gpu,
    pub scene: &'a GpuScene,
    pub set: &'a crate::render::params::ParamSet,
    pub settings: &'a Settings,
    /// Camera constants of the task's cameras, in task order, at the task's image size.
    pub cameras: &'a [GpuCameraInfo],
    /// The adjoint images of all cameras, one after another; iteration t writes buffer t % 2
    /// (the other holds the previous iteration's).
    pub adjoint: &'a [wgpu::Buffer; 2],
    /// The gradient, laid out like the parameters.
    pub grad: &'a wgpu::Buffer,
    /// Workgroups of one camera's image in 8x8 tiles.
    pub grid: (u32, u32),
}

/// What one iteration's encoding needs.
pub(crate) struct Frame<'a> {
    /// The iteration (seeds derive from it).
    pub iteration: u32,
    /// The scene bind group (group 0).
    pub scene_group: &'a wgpu::BindGroup,
}

impl Frame<'_> {
    /// Which of the double-buffered adjoints this iteration writes.
    pub fn parity(&self) -> usize {
        (self.iteration % 2) as usize
    }
}

/// A gradient estimator as the optimizer drives it.
pub(crate) trait Estimator {
    /// Record the passes that turn the adjoint of every camera (in `adjoint[parity]`) into the
    /// gradient of iteration `frame.iteration`, in `grad`.
    fn encode(&mut self, enc: &mut wgpu::CommandEncoder, frame: &Frame, timer: &mut PassTimer);
    /// Called once the iteration's work is submitted.
    fn finish_iteration(&mut self) {}
    /// Whether the estimator reads the previous iteration's textures and adjoint (the
    /// optimizer then copies the textures before each Adam step).
    fn uses_previous_state(&self) -> bool;
    /// Add the estimator's counters of dropped or lost values to `f`.
    fn faults(&self, gpu: &Gpu, f: &mut FaultCounts) -> Result<()>;
    /// The state that carries over to the next iteration (for checkpoints), taken after
    /// `iteration` iterations.
    fn snapshot(&self, gpu: &Gpu, iteration: u32) -> Result<Option<RestirSnapshot>>;
    /// Restore a snapshot taken after `iteration` iterations (None: start afresh).
    fn restore(
        &mut self,
        gpu: &Gpu,
        snapshot: Option<&RestirSnapshot>,
        iteration: u32,
    ) -> Result<()>;
    /// Bytes of GPU state the estimator keeps besides the optimizer's.
    fn state_bytes(&self) -> u64;
    /// Which techniques the gradient samples use for area and environment lights (MIS unless
    /// set): a diagnostic, so that the tests can check that light-sampled and BSDF-sampled
    /// gradients agree. Estimators that cannot restrict their samples refuse.
    fn set_techniques(&mut self, techniques: Techniques) -> Result<()> {
        Err(crate::Error::Invalid(format!(
            "this estimator samples with MIS only; {techniques:?} is for the baseline"
        )))
    }
    /// What ReSTIR's merge counted (None for other estimators).
    fn restir_diagnostics(&self, _gpu: &Gpu) -> Result<Option<restir::MergeDiagnostics>> {
        Ok(None)
    }
}

/// The estimator of `settings.method`.
pub(crate) fn build(setup: &Setup) -> Result<Box<dyn Estimator>> {
    Ok(match setup.settings.method {
        Method::Baseline => Box::new(baseline::Baseline::new(setup)?),
        Method::Restir => Box::new(restir::Restir::new(setup)?),
    })
}

/// The buffers `method` allocates for `n_texels` texels and `n_pixels` pixels (all
/// cameras'), by label and size in bytes.
pub(crate) fn memory(method: Method, n_texels: u64, n_pixels: u64) -> Vec<(String, u64)> {
    match method {
        Method::Baseline => Vec::new(),
        Method::Restir => restir::memory(n_texels, n_pixels),
    }
}
