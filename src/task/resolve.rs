//! What a task resolves to: its estimator, its regime, its whole configuration and the
//! optimizer's settings.
use super::Task;
use crate::auto::Configuration;
use crate::optim::estimator::Regime;
use crate::optim::smoothness::SmoothnessOptions;
use crate::optim::{Choice, EstimatorOptions, Method, MethodChoice};

/// The estimator `choice` resolves to for `task` seen by `cameras` cameras (`auto`: by the
/// task's sampling and sizes, [`MethodChoice::resolve`]).
pub fn task_method(task: &Task, choice: MethodChoice, cameras: usize) -> Choice {
    choice.resolve(&task_regime(task, cameras))
}

/// The whole configuration of `task` seen by `cameras` cameras with the estimator `choice`:
/// what the task sets, and `auto`'s choice for the rest ([`Configuration::choose`]).
pub fn task_configuration(task: &Task, choice: MethodChoice, cameras: usize) -> Configuration {
    let textures: Vec<(crate::vocab::Slot, bool)> = task
        .textures
        .iter()
        .map(|t| (t.slot, t.learning_rate.is_some()))
        .collect();
    Configuration::choose(
        &task_regime(task, cameras),
        choice,
        task.optimizer.step,
        task.optimizer.moment_filter,
        task.optimizer.schedule.clone(),
        task.optimizer.smoothness(),
        &textures,
    )
}

/// The sampling and sizes of `task` seen by `cameras` cameras, as `auto` reads them.
pub fn task_regime(task: &Task, cameras: usize) -> Regime {
    Regime {
        primal_spp: task.optimizer.primal_spp,
        gradient_spp: task.optimizer.gradient_spp,
        pixels: task.width as u64 * task.height as u64 * cameras.max(1) as u64,
        texels: task
            .textures
            .iter()
            .map(|t| t.resolution[0] as u64 * t.resolution[1] as u64)
            .sum(),
        max_depth: task.max_depth,
        recovers_light: task.environment.as_ref().is_some_and(|e| e.optimize),
        normal_maps: task.optimizes(crate::vocab::Slot::Normal),
    }
}

/// The cameras `task` names, or 1 where it leaves them to its scene or camera file: the
/// count [`task_method`] assumes before the scene is loaded.
pub fn named_cameras(task: &Task) -> usize {
    task.cameras
        .as_ref()
        .map_or(task.camera_defs.len(), |c| c.len())
        .max(1)
}

/// The optimizer settings a task asks for, with the given estimator and the estimators'
/// options `extra` over the task's (option by option). A task whose tables are not
/// estimators' (refused when it loads) contributes none.
pub fn task_settings(
    task: &Task,
    cameras: &[usize],
    method: Method,
    extra: &EstimatorOptions,
) -> crate::optim::Settings {
    let seen = if cameras.is_empty() {
        named_cameras(task)
    } else {
        cameras.len()
    };
    let config = task_configuration(task, MethodChoice::Fixed(method), seen);
    crate::optim::Settings {
        width: task.width,
        height: task.height,
        cameras: cameras.to_vec(),
        primal_spp: task.optimizer.primal_spp,
        primal: task.optimizer.primal,
        cv_max_weight: task.optimizer.cv_max_weight,
        path_cache: task.optimizer.path_cache,
        gradient_spp: task.optimizer.gradient_spp,
        loss: task.optimizer.loss,
        seed: task.seed,
        method,
        estimator_options: task
            .optimizer
            .estimator_options()
            .unwrap_or_default()
            .merged(extra),
        step: config.step,
        steps: task.optimizer.step_options().unwrap_or_default(),
        schedule: config.schedule,
        sparse_steps: task.optimizer.sparse_steps,
        priors: {
            let mut priors = task.optimizer.prior_options().unwrap_or_default();
            priors.put(&SmoothnessOptions {
                weight: config.smoothness,
            });
            priors
        },
        moment_filter: config.moment_filter,
        exposure_learning_rate: task
            .optimizer
            .optimize_exposure
            .then_some(task.optimizer.exposure_learning_rate),
    }
}
