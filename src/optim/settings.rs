//! What an optimization samples and how it stops: [`Settings`], [`Stop`], [`Progress`].

use super::step::{StepKind, Steps};
use super::{EstimatorOptions, Method, PrimalMode, Schedule};
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
    /// The path cache ([`super::primal::path_cache`]; None: off): the primal image shades
    /// `primal_spp` stored camera paths per pixel, of which this many are traced anew each
    /// iteration.
    pub path_cache: Option<u32>,
    /// Samples per pixel of the gradient pass.
    pub gradient_spp: u32,
    /// Image loss.
    pub loss: Loss,
    /// Seed of the whole run; every pass derives its own from it.
    pub seed: u32,
    /// Gradient estimator.
    pub method: Method,
    /// Each estimator's options, a table per method name (the one of `method` is used).
    pub estimator_options: EstimatorOptions,
    /// The step taken with each gradient estimate ([`super::step`]: Adam, or the
    /// variance-scaled step).
    pub step: StepKind,
    /// Each step's options, a table per step ([`super::step::Kind::table`]: `adam`,
    /// `variance_step`); the chosen step reads its own.
    pub steps: Steps,
    /// Learning-rate schedule: a factor of every texture's learning rate over the run (see
    /// [`Optimizer::set_progress`](super::Optimizer::set_progress)).
    pub schedule: Schedule,
    /// Masked (sparse) steps: entries whose gradient is exactly zero in an iteration keep
    /// their value and moments, as Mitsuba 3's `mask_updates` (either step).
    pub sparse_steps: bool,
    /// The moment filter (off unless `levels` > 0; see [`super::moment_filter`]): the pair the
    /// step divides (Adam's moments, or the variance step's estimate and variance) smoothed
    /// in texture space, across the texture's edges only where they are weak.
    pub moment_filter: super::moment_filter::MomentFilterOptions,
    /// Each prior's options, a table per prior name ([`super::prior`]: the smoothness prior,
    /// the multiscale gradient); the priors they switch on act on the gradient before the
    /// step, in the registry's order.
    pub priors: super::prior::Priors,
    /// Optimize the per-camera exposures (see [`FitMut::set_exposure`](super::FitMut::set_exposure)) with Adam on
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
            path_cache: None,
            gradient_spp: 1,
            loss: Loss::L2,
            seed: 1,
            method: Method::default(),
            estimator_options: EstimatorOptions::default(),
            step: StepKind::default(),
            steps: Steps::default(),
            schedule: Schedule::constant(),
            sparse_steps: false,
            moment_filter: Default::default(),
            priors: Default::default(),
            exposure_learning_rate: None,
        }
    }

    /// Every range check of the settings, in one place: the task loader and
    /// [`Optimizer::new`](super::Optimizer::new) both call it. An error names the task-file
    /// key (`width`, `optimizer.primal_spp`, ...) and what is wrong.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |key: &str, msg: &str| Err((key.to_string(), msg.to_string()));
        let size_ok = |v: u32| (1..=8192).contains(&v);
        let spp_ok = |v: u32| (1..=4096).contains(&v);
        if !size_ok(self.width) {
            return bad("width", "must be between 1 and 8192");
        }
        if !size_ok(self.height) {
            return bad("height", "must be between 1 and 8192");
        }
        if !spp_ok(self.primal_spp) {
            return bad("optimizer.primal_spp", "must be between 1 and 4096");
        }
        if !spp_ok(self.gradient_spp) {
            return bad("optimizer.gradient_spp", "must be between 1 and 4096");
        }
        if let Some(r) = self.path_cache {
            if r == 0 || r > self.primal_spp {
                return bad(
                    "optimizer.path_cache",
                    &format!(
                        "must be between 1 and primal_spp ({}): the paths per pixel traced \
                         anew each iteration",
                        self.primal_spp
                    ),
                );
            }
        }
        if !(0.0..=1.0).contains(&self.cv_max_weight) {
            return bad("optimizer.cv_max_weight", "must be between 0 and 1");
        }
        if let Err((key, msg)) = self.schedule.check() {
            return Err((format!("optimizer.schedule.{key}"), msg));
        }
        self.estimator_options.check()?;
        self.steps.check()?;
        self.priors.check()?;
        if let Err((key, msg)) = self.moment_filter.check() {
            return bad(&format!("optimizer.moment_filter.{key}"), &msg);
        }
        if self.moment_filter.write_back && !self.step.kind().first_moment {
            return bad(
                "optimizer.moment_filter.write_back",
                &format!(
                    "only with a step that keeps a first moment, as Adam (the {} step keeps \
                     none)",
                    self.step
                ),
            );
        }
        if let Some(lr) = self.exposure_learning_rate {
            if !(lr.is_finite() && lr >= 0.0) {
                return bad(
                    "optimizer.exposure_learning_rate",
                    "must be a finite number >= 0",
                );
            }
        }
        Ok(())
    }
}

/// When [`Optimizer::run`](super::Optimizer::run) returns: after `iterations` more iterations, after `time_budget`,
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

/// What the callback of [`Optimizer::run`](super::Optimizer::run) sees after each iteration.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Iterations done in total ([`Optimizer::iteration`](super::Optimizer::iteration)).
    pub iteration: u32,
    /// Iterations done in this call.
    pub in_this_run: u32,
    /// Loss of the iteration's primal render.
    pub loss: f64,
    /// Time since the call began.
    pub elapsed: std::time::Duration,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_names_the_key_of_every_bad_setting() {
        let ok = Settings::new(64, 64, vec![0]);
        assert_eq!(ok.validate(), Ok(()));
        type Spoil = Box<dyn Fn(&mut Settings)>;
        let cases: Vec<(&str, Spoil)> = vec![
            ("width", Box::new(|s| s.width = 0)),
            ("height", Box::new(|s| s.height = 9000)),
            ("optimizer.primal_spp", Box::new(|s| s.primal_spp = 0)),
            ("optimizer.gradient_spp", Box::new(|s| s.gradient_spp = 0)),
            (
                "optimizer.gradient_spp",
                Box::new(|s| s.gradient_spp = 5000),
            ),
            (
                "optimizer.cv_max_weight",
                Box::new(|s| s.cv_max_weight = 1.5),
            ),
            (
                "optimizer.multiscale.levels",
                Box::new(|s| s.priors.set("multiscale", "levels", 9.into())),
            ),
            (
                "optimizer.smoothness.weight",
                Box::new(|s| s.priors.set("smoothness", "weight", f64::NAN.into())),
            ),
            (
                "optimizer.smoothness",
                Box::new(|s| s.priors.set("smoothness", "wieght", 0.1.into())),
            ),
            (
                "optimizer.smooth",
                Box::new(|s| s.priors.set("smooth", "weight", 0.1.into())),
            ),
            (
                "optimizer.moment_filter.levels",
                Box::new(|s| s.moment_filter.levels = 9),
            ),
            (
                "optimizer.moment_filter.sigma",
                Box::new(|s| s.moment_filter.sigma = 0.0),
            ),
            (
                "optimizer.moment_filter.own_weight",
                Box::new(|s| s.moment_filter.own_weight = 0.0),
            ),
            (
                "optimizer.moment_filter.write_back",
                Box::new(|s| {
                    s.moment_filter.write_back = true;
                    s.step = StepKind::VARIANCE;
                }),
            ),
            (
                "optimizer.exposure_learning_rate",
                Box::new(|s| s.exposure_learning_rate = Some(-1.0)),
            ),
            (
                "optimizer.schedule.final",
                Box::new(|s| s.schedule.final_factor = 0.0),
            ),
            (
                "optimizer.restir.m_cap",
                Box::new(|s| {
                    s.estimator_options
                        .set(Method::RESTIR.table(), "m_cap", 0.0.into())
                }),
            ),
            (
                "optimizer.restir",
                Box::new(|s| {
                    s.estimator_options
                        .set(Method::RESTIR, "m_capp", 8.0.into())
                }),
            ),
            (
                "optimizer.recursive.weight",
                Box::new(|s| {
                    s.estimator_options
                        .set(Method::RECURSIVE, "weight", 0.0.into())
                }),
            ),
            (
                "optimizer.recursive.min_weight",
                Box::new(|s| {
                    s.estimator_options
                        .set(Method::RECURSIVE, "min_weight", 2.0.into())
                }),
            ),
            (
                "optimizer.baseline.cache",
                Box::new(|s| {
                    s.estimator_options
                        .set(Method::BASELINE.table(), "cache", 0.into())
                }),
            ),
            (
                "optimizer.variance_step.clip",
                Box::new(|s| s.steps.set("variance_step", "clip", (-1.0).into())),
            ),
            (
                "optimizer.adam.beta1",
                Box::new(|s| s.steps.set("adam", "beta1", 1.0.into())),
            ),
            (
                "optimizer.adam",
                Box::new(|s| s.steps.set("adam", "beta3", 0.5.into())),
            ),
        ];
        for (key, spoil) in cases {
            let mut s = ok.clone();
            spoil(&mut s);
            let (k, msg) = s.validate().unwrap_err();
            assert_eq!(k, key, "{msg}");
            assert!(!msg.is_empty());
        }
    }
}
