//! The parts the [`Optimizer`](super::Optimizer) holds besides its scene, textures and
//! settings: the buffers one iteration's passes hand each other, the passes it runs itself,
//! the plugins it calls and what it fits the textures to, and how they are made.

use super::cameras::{CameraPasses, Stats};
use super::estimator::Estimator;
use super::{loss, primal, prior, step, PassTimer, Settings};
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::render::params::{ParamBuffers, ParamSet};
use crate::Result;

/// The buffers an iteration's passes hand each other.
pub(in crate::optim) struct IterationBuffers {
    /// The gradient, laid out like the parameters.
    pub(in crate::optim) grad: wgpu::Buffer,
    /// Adjoint images of all cameras; iteration t writes buffer t % 2.
    pub(in crate::optim) adjoint: [wgpu::Buffer; 2],
    /// The step's two per-parameter moments.
    pub(in crate::optim) moments: [wgpu::Buffer; 2],
    /// The primal samples of this iteration, and under the previous textures (control
    /// variate).
    pub(in crate::optim) accum: wgpu::Buffer,
    pub(in crate::optim) accum_prev: wgpu::Buffer,
    pub(in crate::optim) stats: Stats,
}

/// The passes the engine runs itself, and the GPU objects made on first use.
pub(in crate::optim) struct Passes {
    pub(in crate::optim) cams: Vec<CameraPasses>,
    pub(in crate::optim) loss: loss::LossPass,
    pub(in crate::optim) grid: (u32, u32),
    /// The control-variate primal, when `settings.primal` asks for it.
    pub(in crate::optim) control_variate: Option<primal::ControlVariate>,
    /// The path cache the primal is shaded from, when `settings.path_cache` asks for it and
    /// the images allow it.
    pub(in crate::optim) path_cache: Option<primal::PathCache>,
    pub(in crate::optim) timer: PassTimer,
    /// The texture_export pipeline, built on first use.
    pub(in crate::optim) export_pipeline: std::sync::OnceLock<wgpu::ComputePipeline>,
    /// The images [`Optimizer::render_cameras`](super::Optimizer::render_cameras) reads back, made at its first call.
    pub(in crate::optim) camera_images: std::sync::OnceLock<wgpu::Buffer>,
}

/// The plugins an iteration calls: the gradient estimator, the step and the priors.
pub(in crate::optim) struct Plugins {
    pub(in crate::optim) estimator: Box<dyn Estimator>,
    pub(in crate::optim) step: Box<dyn step::Step>,
    /// The priors the settings ask for, in the order they apply, built by
    /// [`Optimizer::prepare`] (the first step's, or the caller's before it).
    pub(in crate::optim) priors: Option<Vec<(&'static prior::Kind, Box<dyn prior::Prior>)>>,
}

/// What the optimizer fits the textures to.
pub(in crate::optim) struct Inputs {
    /// The targets (CPU copies, for re-uploading them with masks).
    pub(in crate::optim) targets: Vec<Image>,
    /// The observed-texel mask, computed when the optimizer is made: its flags, and the GPU
    /// buffer they were read from (one word per texel, nonzero: observed), which the
    /// priors bind.
    pub(in crate::optim) observed: (Vec<bool>, wgpu::Buffer),
}

impl IterationBuffers {
    /// The buffers for `n_cams` cameras of `w` x `h` pixels and `n_params` parameter
    /// scalars: the adjoints of both parities (RGBA per pixel of all cameras), the gradient,
    /// the step's two moments, one camera's primal samples (twice) and the statistics.
    pub(in crate::optim) fn new(
        gpu: &Gpu,
        (w, h): (u32, u32),
        n_cams: u32,
        n_params: u64,
    ) -> IterationBuffers {
        let pixels = (w * h) as u64;
        let adjoint_size = pixels * n_cams as u64 * 16;
        IterationBuffers {
            grad: gpu.storage_zeroed("gradient", n_params * 4),
            adjoint: [
                gpu.storage_zeroed("adjoint even", adjoint_size),
                gpu.storage_zeroed("adjoint odd", adjoint_size),
            ],
            moments: [
                gpu.storage_zeroed("step moment1", n_params * 4),
                gpu.storage_zeroed("step moment2", n_params * 4),
            ],
            accum: gpu.storage_zeroed("primal accum", pixels * 16),
            accum_prev: gpu.storage_zeroed("primal accum_prev", pixels * 16),
            stats: Stats {
                primal: gpu.storage_zeroed("primal stats", 16),
                step: gpu.storage_zeroed("step stats", 16),
            },
        }
    }
}

/// The step the settings choose, bound to the iteration's buffers: the estimator's own
/// variance where it keeps one and the priors keep it.
pub(in crate::optim) fn build_step(
    gpu: &Gpu,
    (set, params): (&ParamSet, &ParamBuffers),
    settings: &Settings,
    observed_map: &wgpu::Buffer,
    bufs: &IterationBuffers,
    estimator: &dyn Estimator,
) -> Result<Box<dyn step::Step>> {
    step::build(
        gpu,
        set,
        &step::StepChoice {
            kind: settings.step,
            steps: &settings.steps,
            sparse: settings.sparse_steps,
            moment_filter: &settings.moment_filter,
        },
        observed_map,
        &step::StepBuffers {
            grad: &bufs.grad,
            params: &params.values,
            moments: &bufs.moments,
            // The estimator's variance is that of its own estimate; a prior that mixes
            // texels (the multiscale gradient) changes it, so the step then tracks the
            // variance of what it is given.
            variance: estimator
                .variance()
                .filter(|_| settings.priors.keep_variance()),
            stats: &bufs.stats.step,
        },
    )
}

/// A timer with a slot for every pass of an iteration: primal, control variate and loss per
/// camera, the estimator's passes (at most three per camera and two more), smoothness,
/// multiscale and the step (two dispatches with the moment filter) per texture, and the
/// filter's levels.
pub(in crate::optim) fn pass_timer(
    gpu: &Gpu,
    n_cams: u32,
    n_textures: usize,
    step: &dyn step::Step,
) -> PassTimer {
    let filter_dispatches = step.filter().map_or(0, |f| f.dispatches());
    let per_texture = 4 * n_textures as u32;
    PassTimer::new(gpu, 6 * n_cams + 4 + per_texture + filter_dispatches)
}

/// The control variate `settings` ask for, over `n_cams` cameras' images in the iteration's
/// accumulators `bufs`; None for the independent primal.
pub(in crate::optim) fn control_variate(
    gpu: &Gpu,
    settings: &Settings,
    n_cams: usize,
    bufs: &IterationBuffers,
) -> Result<Option<primal::ControlVariate>> {
    if settings.primal != primal::PrimalMode::ControlVariate {
        return Ok(None);
    }
    let size = (settings.width, settings.height);
    let (accum, prev) = (&bufs.accum, &bufs.accum_prev);
    primal::ControlVariate::new(gpu, size, n_cams, accum, prev, settings.cv_max_weight).map(Some)
}
