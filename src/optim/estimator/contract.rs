//! The contract between the optimizer and an estimator: what a folder exports ([`Kind`]),
//! what it is built from ([`Setup`]), what one iteration hands it ([`Frame`]) and the
//! [`Estimator`] trait it is driven through.
use super::{EstimatorOptions, EstimatorState, Method, OptionsKind};
use crate::gpu::shaders::Generator;
use crate::gpu::{Gpu, GroupDecl};
use crate::optim::{FaultCounts, PassTimer};
use crate::render::layout::GpuCameraInfo;
use crate::render::{GpuScene, Techniques};
use crate::Result;

/// An estimator as its folder exports it: everything the rest of the crate knows of it.
pub struct Kind {
    /// The name used on the command line, in task files, checkpoints and reports.
    pub name: &'static str,
    /// What it does, in one line.
    pub summary: &'static str,
    /// Its options (the task file's `[optimizer.<name>]` table).
    pub options: OptionsKind,
    /// Its WGSL files: (name, source), a pass named after its file, another module as
    /// `<name>/<file stem>` (what `#import` names).
    pub wgsl: &'static [(&'static str, &'static str)],
    /// The WGSL it generates from its Rust (`gen/<name>`).
    pub generated: &'static [(&'static str, Generator)],
    /// Its bind-group declarations (checked against its WGSL by the contract test).
    pub groups: &'static [GroupDecl],
    /// The passes it creates with its options, the slowest to compile first.
    pub passes: fn(&EstimatorOptions) -> Vec<&'static str>,
    /// The most cameras it can use in one optimization (None: no limit of its own).
    pub max_cameras: Option<usize>,
    /// The buffers it allocates with its options, by label, size in bytes and what the size
    /// scales with.
    pub memory: fn(&Sizes, &EstimatorOptions) -> Vec<(String, u64, Scale)>,
    /// What the user should know before a run with it under `conditions` (logged).
    pub warnings: fn(&Conditions) -> Vec<String>,
    /// Whether, with paths of this many vertices, it keeps state for every texel rather
    /// than the observed ones only (a path can reach any texel after a bounce).
    pub every_texel: fn(u32) -> bool,
    pub(crate) build: fn(&Setup) -> Result<Box<dyn Estimator>>,
}

/// What a buffer's size scales with (in an estimator's memory plan and the optimizer's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// Every texel of the optimized textures.
    Texel,
    /// The texels that a camera observes (ReSTIR's reservoirs).
    ObservedTexel,
    /// Every pixel of every camera.
    Pixel,
}

/// The sizes an estimator's memory plan scales with.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sizes {
    /// Parameter scalars of all optimized textures.
    pub params: u64,
    /// Texels of all optimized textures.
    pub texels: u64,
    /// Of those, the texels a camera observes.
    pub observed: u64,
    /// Pixels of all cameras.
    pub pixels: u64,
    /// Vertices of a camera path.
    pub max_depth: u32,
    /// Gradient samples per iteration (pixels of all cameras times the gradient spp).
    pub gradient_samples: u64,
    /// The most optimized textures one material has.
    pub slots_per_material: u64,
    /// The most texels one lookup of an optimized texture touches (1 nearest, 4 bilinear).
    pub footprint: u64,
}

impl Sizes {
    /// `slots_per_material` and `footprint` of the textures in `set`.
    pub fn lookups(set: &crate::render::params::ParamSet) -> (u64, u64) {
        let t = &set.textures;
        let slots = t
            .iter()
            .map(|a| t.iter().filter(|b| b.material == a.material).count() as u64)
            .max()
            .unwrap_or(1);
        let footprint = if t.iter().any(|a| a.filter == crate::vocab::Filter::Bilinear) {
            4
        } else {
            1
        };
        (slots, footprint)
    }
}

/// What a run's warnings depend on.
#[derive(Clone, Copy, Debug)]
pub struct Conditions {
    /// Vertices of a camera path (1: direct light only).
    pub max_depth: u32,
}

/// No buffers of its own.
pub fn no_memory(_: &Sizes, _: &EstimatorOptions) -> Vec<(String, u64, Scale)> {
    Vec::new()
}

/// Nothing to warn of.
pub fn no_warnings(_: &Conditions) -> Vec<String> {
    Vec::new()
}

/// Named values an estimator counted since it was made (for diagnostics and tests; see
/// [`restir::MergeDiagnostics`](super::restir::MergeDiagnostics)).
pub type Diagnostics = Vec<(&'static str, f64)>;

/// What an estimator is built from: the optimizer's scene, images and shared buffers.
pub(crate) struct Setup<'a> {
    pub gpu: &'a Gpu,
    pub scene: &'a GpuScene,
    pub set: &'a crate::render::params::ParamSet,
    /// The estimator to build, and every estimator's options.
    pub method: Method,
    pub options: &'a EstimatorOptions,
    /// Camera samples per pixel and iteration.
    pub gradient_spp: u32,
    /// Each camera's image size.
    pub width: u32,
    pub height: u32,
    /// How the primal render draws its samples (ReSTIR's target smoothing follows it).
    pub primal: crate::optim::primal::PrimalMode,
    /// Camera constants of the task's cameras, in task order, at the task's image size.
    pub cameras: &'a [GpuCameraInfo],
    /// The adjoint images of all cameras, one after another; iteration t writes buffer t % 2
    /// (the other holds the previous iteration's).
    pub adjoint: &'a [wgpu::Buffer; 2],
    /// The gradient, laid out like the parameters.
    pub grad: &'a wgpu::Buffer,
    /// The environment's gradient and counters (shared/env_gradient.wgsl), which the
    /// gradient passes add to when the scene says the environment is optimized.
    pub env_grad: &'a wgpu::Buffer,
    /// Workgroups of one camera's image in 8x8 tiles.
    pub grid: (u32, u32),
    /// Which texels the cameras observe (one flag per texel of all optimized textures).
    pub observed: &'a [bool],
}

/// What one iteration's encoding needs.
pub(crate) struct Frame<'a> {
    /// The iteration (seeds derive from it and from `seed`).
    pub iteration: u32,
    /// The seed whose streams the gradient samples draw from, mixed with the iteration
    /// ([`pass_seed`](crate::optim::pass_seed)): the settings' seed in an optimization, the
    /// caller's in [`Optimizer::backward`](crate::optim::Optimizer::backward).
    pub seed: u32,
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
pub(crate) trait Estimator: Send {
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
    /// Which of its [`Estimator::diagnostics`] are counters (they rise by the work of each
    /// iteration, so that a rate per iteration means something; 32 bits on the GPU, they may
    /// wrap); the others are levels.
    fn counters(&self) -> &'static [&'static str] {
        &[]
    }
}

/// No estimator state beyond the observed texels, at any depth.
pub(crate) fn observed_only(_max_depth: u32) -> bool {
    false
}
