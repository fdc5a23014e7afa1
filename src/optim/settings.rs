//! What an optimization samples and how it stops: [`Settings`], [`Stop`], [`Progress`].

use super::{Method, PrimalMode, RestirOptions, Schedule};
use crate::vocab::Loss;

/// How each iteration samples.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Image width of every camera.
    pub width: u32,
    /// Image height of every camera.
    pub height: u32,
    /// Cameras rendered every iteration (indices into the scene's cameras).
    pub cameras: Vec<usize>,
    /// Samples per pixel of the primal render.
    pub primal_spp: u32,
    /// How the primal image is estimated: independently, or with the recursive control
    /// variate.
    pub primal: PrimalMode,
    /// Upper clamp of the control variate's per-pixel weight (in [0, 1]; see
    /// [`PrimalMode::ControlVariate`]).
    pub cv_max_weight: f32,
    /// Samples per pixel of the gradient pass.
    pub gradient_spp: u32,
    /// Image loss.
    pub loss: Loss,
    /// Seed of the whole run; every pass derives its own from it.
    pub seed: u32,
    /// Gradient estimator.
    pub method: Method,
    /// ReSTIR options (used when `method` is ReSTIR).
    pub restir: RestirOptions,
    /// Learning-rate schedule: a factor of every texture's learning rate over the run (see
    /// [`Optimizer::set_progress`]).
    pub schedule: Schedule,
    /// Masked (sparse) Adam: entries whose gradient is exactly zero in an iteration keep
    /// their value and moments, as Mitsuba 3's `mask_updates`.
    pub adam_mask: bool,
    /// Levels of the multiscale gradient (0: off; at most 4; see [`super::multiscale`]): each
    /// observed texel's gradient is averaged with its 2^l x 2^l blocks' before Adam.
    pub multiscale_levels: u32,
    /// Weight of the smoothness prior (0: off; see [`super::smoothness`]): the gradient of
    /// `smoothness * mean squared difference of observed neighbouring texels` is added to
    /// the image loss's before the multiscale gradient and Adam.
    pub smoothness: f32,
    /// Optimize the per-camera exposures (see [`Optimizer::set_exposure`]) with Adam on
    /// their logarithms, at this learning rate; None: exposures stay fixed.
    pub exposure_learning_rate: Option<f32>,
}

impl Settings {
    /// The defaults of a task file (4 primal and 1 gradient samples per pixel, L2 loss,
    /// seed 1, ReSTIR with its default options) for `cameras` at `width` x `height`.
    pub fn new(width: u32, height: u32, cameras: Vec<usize>) -> Settings {
        Settings {
            width,
            height,
            cameras,
            primal_spp: 4,
            primal: PrimalMode::Independent,
            cv_max_weight: super::primal::DEFAULT_MAX_WEIGHT,
            gradient_spp: 1,
            loss: Loss::L2,
            seed: 1,
            method: Method::Restir,
            restir: RestirOptions::default(),
            schedule: Schedule::constant(),
            adam_mask: false,
            multiscale_levels: 0,
            smoothness: 0.0,
            exposure_learning_rate: None,
        }
    }
}

/// When [`Optimizer::run`] returns: after `iterations` more iterations, after `time_budget`,
/// or at whichever comes first. At least one must be given.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stop {
    /// Iterations to run in this call.
    pub iterations: Option<u32>,
    /// Wall-clock time for this call.
    pub time_budget: Option<std::time::Duration>,
}

impl Stop {
    /// Stop after `n` iterations.
    pub fn iterations(n: u32) -> Stop {
        Stop {
            iterations: Some(n),
            time_budget: None,
        }
    }
    /// Stop once `d` has passed (the iteration under way finishes first).
    pub fn time(d: std::time::Duration) -> Stop {
        Stop {
            iterations: None,
            time_budget: Some(d),
        }
    }
}

/// What the callback of [`Optimizer::run`] sees after each iteration.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Iterations done in total ([`Optimizer::iteration`]).
    pub iteration: u32,
    /// Iterations done in this call.
    pub in_this_run: u32,
    /// Loss of the iteration's primal render.
    pub loss: f64,
    /// Time since the call began.
    pub elapsed: std::time::Duration,
}
