//! Gradient estimators. Each one lives in its own module and owns its pipelines, bind groups,
//! buffers, GPU struct mirrors, memory plan, checkpoint state and fault counters; the
//! optimizer calls it through the `Estimator` trait once per iteration, after the primal render and
//! the loss have written every camera's adjoint.
//!
//! - [`baseline`]: plain Monte Carlo, every sample adds its derivative to the texels it
//!   touches (`gradient.wgsl`).
//! - [`restir`]: parameter-space ReSTIR, two reservoirs per texel reused across iterations
//!   (`restir_candidates.wgsl`, `restir_merge.wgsl`).
//! - [`recursive`]: a recursive control variate on the gradient: fresh samples evaluated at
//!   the current and the previous state correct the running estimate
//!   (`recursive_gradient.wgsl`, `recursive_combine.wgsl`).
//!
//! Each lives in its own folder with its Rust and its passes' WGSL (shared WGSL stays in
//! `shaders/shared/`).
pub mod baseline;
pub mod recursive;
pub mod restir;
pub use restir::compact;

use super::{FaultCounts, PassTimer, Settings};
use crate::gpu::Gpu;
use crate::render::layout::GpuCameraInfo;
use crate::render::{GpuScene, Techniques};
use crate::Result;
pub use recursive::RecursiveOptions;
pub use restir::{Confidence, RestirOptions};

/// The gradient estimator. The default is the one that ends lower on the bundled default task
/// at equal time, each at its own best settings (docs/studies.md, "Which estimator is the
/// default"): on the machines measured so far, the baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Plain Monte Carlo: every candidate adds its value to the texels it touches.
    #[default]
    Baseline,
    /// Parameter-space ReSTIR.
    Restir,
    /// The recursive control variate on the gradient.
    Recursive,
}

impl Method {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Baseline => "baseline",
            Method::Restir => "restir",
            Method::Recursive => "recursive",
        }
    }
}

/// The part of an estimator's state that carries over to the next iteration, as the optimizer
/// and its checkpoints hold it without knowing the estimator: the method that wrote it (its
/// [`Method::name`]), named counters and named arrays of 32-bit words. Each estimator says
/// what its names mean and checks them when it restores.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EstimatorState {
    /// The [`Method::name`] of the estimator that wrote it.
    pub method: String,
    /// Named counters.
    pub counters: Vec<(String, u32)>,
    /// Named arrays of 32-bit words (floats are stored as their bits).
    pub arrays: Vec<(String, Vec<u32>)>,
}

impl EstimatorState {
    /// An empty state written by `method`.
    pub fn new(method: Method) -> EstimatorState {
        EstimatorState {
            method: method.name().to_string(),
            ..Default::default()
        }
    }

    /// The counter `name`, if the state has it.
    pub fn counter(&self, name: &str) -> Option<u32> {
        self.counters.iter().find(|(n, _)| n == name).map(|c| c.1)
    }

    /// The array `name`, if the state has it.
    pub fn array(&self, name: &str) -> Option<&[u32]> {
        self.arrays
            .iter()
            .find(|(n, _)| n == name)
            .map(|a| a.1.as_slice())
    }

    /// An error unless the state was written by `method`.
    pub fn check_method(&self, method: Method) -> Result<()> {
        if self.method == method.name() {
            return Ok(());
        }
        Err(crate::Error::Invalid(format!(
            "the saved state was written by the {} gradient estimator, not by {}; resume with \
             the same --method",
            self.method,
            method.name()
        )))
    }
}

/// Named values an estimator counted since it was made (for diagnostics and tests; see
/// [`restir::MergeDiagnostics`]).
pub type Diagnostics = Vec<(&'static str, f64)>;

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
    /// Which texels the cameras observe (one flag per texel of all optimized textures).
    pub observed: &'a [bool],
}

/// What one iteration's encoding needs.
pub(crate) struct Frame<'a> {
    /// The iteration (seeds derive from it).
    pub iteration: u32,
    /// The scene bind group (group 0).
    pub scene_group: &'a wgpu::BindGroup,
    /// The learning-rate schedule's factor at this iteration (1 without a schedule).
    pub schedule_factor: f32,
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
    fn snapshot(&self, gpu: &Gpu, iteration: u32) -> Result<EstimatorState>;
    /// Restore a snapshot taken after `iteration` iterations (None, or a state without
    /// arrays: start afresh). The optimizer has checked that this estimator wrote it; an
    /// error when it was written for other textures or images.
    fn restore(&mut self, gpu: &Gpu, state: Option<&EstimatorState>, iteration: u32) -> Result<()>;
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
    /// The variance of each gradient scalar it wrote, laid out like the gradient, when the
    /// estimator tracks it (the variance-scaled step divides by its square root; without it
    /// the step tracks a moving variance of the gradient itself).
    fn variance(&self) -> Option<&wgpu::Buffer> {
        None
    }
    /// What the estimator counted since it was made (empty unless it counts something).
    fn diagnostics(&self, _gpu: &Gpu) -> Result<Diagnostics> {
        Ok(Vec::new())
    }
}

/// The estimator of `settings.method`.
pub(crate) fn build(setup: &Setup) -> Result<Box<dyn Estimator>> {
    Ok(match setup.settings.method {
        Method::Baseline => Box::new(baseline::Baseline::new(setup)?),
        Method::Restir => Box::new(restir::Restir::new(setup)?),
        Method::Recursive => Box::new(recursive::Recursive::new(setup)?),
    })
}

/// The most cameras `method` can use in one optimization (None: no limit of its own).
pub(crate) fn max_cameras(method: Method) -> Option<usize> {
    match method {
        Method::Baseline | Method::Recursive => None,
        Method::Restir => Some(restir::MAX_CAMERAS),
    }
}

/// The buffers `method` allocates for `n_params` parameter scalars in `n_texels` texels of
/// which `n_observed` are observed, and `n_pixels` pixels (all cameras'), by label, size in
/// bytes and what the size scales with.
pub(crate) fn memory(
    method: Method,
    n_params: u64,
    n_texels: u64,
    n_observed: u64,
    n_pixels: u64,
) -> Vec<(String, u64, crate::optim::Scale)> {
    match method {
        Method::Baseline => Vec::new(),
        Method::Restir => restir::memory(n_texels, n_observed, n_pixels),
        Method::Recursive => recursive::memory(n_params),
    }
}
