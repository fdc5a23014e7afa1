//! `psrestir bench`: the paper's measurements (docs/method.md, "How results are measured") of
//! the estimators, one after the other on the same device, per scene (the gradient-error
//! phase compares one estimator, `gradient_method`, ReSTIR unless told, with the baseline;
//! the equal-time phase runs the baseline with Adam and then every contender: an estimator
//! with its step, and the default configuration):
//!
//! 1. gradient error: after `warmup` iterations of the estimator, the relMSE of its next
//!    gradient and of baseline gradients at the same parameter state, at equal iterations
//!    (the task's spp) and at equal time (as many spp as fit in the time of one of its
//!    iterations), against a reference from a converged adjoint (a `reference_primal_spp`
//!    primal render) and `reference_spp` gradient samples. Each error is measured twice: *total*, under the
//!    adjoint of a task-spp primal render (what a user gets), the same render for both
//!    estimators and every baseline spp (common random numbers), and
//!    *estimator-only*, both under the converged adjoint (what the reservoirs do), after
//!    `settle` more of its estimates under it at the same textures (ReSTIR's reservoirs
//!    filled for that integrand); and the estimator-only error of the mean of successive
//!    estimates (ReSTIR's share kept samples) against a mean of as many independent
//!    baseline estimates;
//! 2. equal-time optimization: the baseline and each contender optimize from the same start
//!    for the same wall-clock budget; image relMSE (a high-spp render against the target) and
//!    texture RMSE against the ground truth, as curves over time and at the end;
//! 3. cost: milliseconds per iteration, GPU time per pass, bytes of state per texel.
//!
//! The report (`bench.json`, `report.md`, plots and gradient images) is written by
//! [`report`].
mod contender;
mod counters;
mod gradient;
mod options;
pub mod peer;
mod phases;
mod progress;
pub mod report;
mod results;
pub mod seeds;
pub mod throughput;
pub mod tune;

pub use contender::{bare, Contender};
use gradient::gradient_phase;
pub use gradient::{gradient_relmse, gradient_relmse_parts};
use options::settings;
pub use options::{resolve_scene, scaled, scenes_root, BenchOptions, Protocol};
use phases::{optimization_phases, primal_phase, PrimalPhase};
use progress::Progress;
pub use results::*;
use throughput::first_creations;

use crate::gpu::Gpu;

use crate::job::Problem;
use crate::optim::Optimizer;
use crate::task::task_settings;
use crate::task::Task;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

pub use crate::optim::loss::image_relmse;

/// Run the benchmark on the given task files and write the report into `o.out`.
pub fn bench(gpu: &Gpu, tasks: &[PathBuf], o: &BenchOptions) -> Result<BenchReport> {
    check_options(o)?;
    // Load every task first, so that a bad one fails before hours of measuring.
    let loaded = tasks
        .iter()
        .map(|p| load_task(p, o))
        .collect::<Result<Vec<Task>>>()?;
    std::fs::create_dir_all(&o.out).map_err(|e| Error::file(&o.out, e.to_string()))?;
    let seeds = o.seeds.max(1);
    let later_seeds = BenchOptions {
        end_to_end_only: !o.gradient_only,
        ..o.clone()
    };
    let per_scene = steps_per_scene(o) + (seeds as u64 - 1) * steps_per_scene(&later_seeds);
    let progress = Progress::new(o.progress, loaded.len() as u64 * per_scene);
    let mut report = BenchReport {
        version: env!("CARGO_PKG_VERSION").into(),
        adapter: gpu.describe(),
        budget_s: o.budget_s,
        task_budgets: o.task_budgets,
        scale: o.scale,
        gradient_method: o.gradient_method.name().into(),
        warmup: o.warmup,
        settle: o.settle,
        repeats: o.repeats.max(1),
        seeds: o.seeds.max(1),
        over_seeds: Vec::new(),
        reference_spp: o.reference_spp,
        reference_primal_spp: o.reference_primal_spp,
        protocol: o.protocol,
        eval_spp: o.eval_spp,
        image_error: ImageError::Expectation,
        estimator_options: o.estimator_options.clone(),
        no_priors: o.no_priors,
        tuned: o.tune,
        scenes: Vec::new(),
        pipelines: Vec::new(),
        command: o.command.clone(),
        source: Some(report::source_state(std::path::Path::new("."))),
    };
    let pipelines_before = gpu.pipeline_times().len();
    // Every optimizer pass the bench may create compiles on a second device while the first
    // scene's targets render.
    let mut helper = loaded.first().and_then(|task| compile_ahead(gpu, task, o));
    for loaded_task in &loaded {
        let scene = scene_name(loaded_task);
        for k in 0..seeds {
            let (task, name) = seeded(loaded_task, &scene, k, seeds);
            let mut o = o.clone();
            if o.task_budgets {
                o.budget_s = task.optimizer.time_budget_s.unwrap_or(o.budget_s);
            }
            // The primal and gradient phases with the first seed only.
            if k > 0 && !o.gradient_only {
                o.end_to_end_only = true;
            }
            // The search, with --tune, once per scene: every seed's runs take its choice.
            let tune_dir = o.out.join(crate::image_io::file_safe(&scene));
            let result = measure_scene(gpu, &task, name, &o, &tune_dir, &progress, &mut helper)?;
            report.scenes.push(result);
            report.pipelines = first_creations(&gpu.pipeline_times()[pipelines_before..]);
            if k + 1 == seeds && seeds > 1 {
                let of_scene: Vec<&SceneResult> = report.scenes
                    [report.scenes.len() - seeds as usize..]
                    .iter()
                    .collect();
                report.over_seeds.push(seeds::summarize(&scene, &of_scene));
            }
            // Written after every scene, so that an interrupted run keeps what it measured.
            report::write_report(&o.out, &report)?;
        }
    }
    progress.finish();
    Ok(report)
}

/// `task` with its `k`-th of `seeds` seeds, and its name in the report (`vase`, or
/// `vase, seed 2` over several seeds). Seed 0 is the task's own.
fn seeded(task: &Task, scene: &str, k: u32, seeds: u32) -> (Task, String) {
    let mut t = task.clone();
    t.seed = task.seed.wrapping_add(k.wrapping_mul(1_000_003));
    let name = if seeds > 1 {
        format!("{scene}, seed {k}")
    } else {
        scene.to_string()
    };
    (t, name)
}

/// One scene (at one seed): its targets, its phases and its files.
fn measure_scene(
    gpu: &Gpu,
    task: &Task,
    name: String,
    o: &BenchOptions,
    tune_dir: &Path,
    progress: &Progress,
    helper: &mut Option<std::thread::JoinHandle<()>>,
) -> Result<SceneResult> {
    let dir = o.out.join(crate::image_io::file_safe(&name));
    std::fs::create_dir_all(&dir).map_err(|e| Error::file(&dir, e.to_string()))?;
    if let Some(b) = &progress.bar {
        b.set_prefix(name.clone());
    }
    progress.message(format!("{name}: rendering targets"));
    let prep = Problem::from_task(gpu, task, &dir, false)?;
    if let Some(h) = helper.take() {
        let _ = h.join();
    }
    progress.done();
    let (pp, g) = if o.end_to_end_only {
        (
            PrimalPhase::not_measured(),
            gradient::GradientPhase::not_measured(&prep),
        )
    } else {
        (
            primal_phase(gpu, task, &prep, o, progress)?,
            gradient_phase(gpu, task, &prep, o, progress)?,
        )
    };
    let (optimization, finals) = if o.gradient_only {
        (None, None)
    } else {
        if o.tune {
            std::fs::create_dir_all(tune_dir).map_err(|e| Error::file(tune_dir, e.to_string()))?;
        }
        let tuned = tune_contenders(gpu, task, &prep, o, tune_dir, progress)?;
        let (r, f) = optimization_phases(gpu, task, &prep, o, (&dir, tune_dir), tuned, progress)?;
        (Some(r), Some(f))
    };
    let result = scene_result(name, task, &prep, o, &pp, &g, optimization);
    report::write_scene_files(&dir, &prep, &result, &g.snapshot, finals.as_ref())?;
    Ok(result)
}

/// An error naming the option when the bench's options cannot measure anything.
fn check_options(o: &BenchOptions) -> Result<()> {
    let bad = |m: String| Err(Error::Invalid(format!("bench: {m}")));
    if !(o.budget_s > 0.0 && o.budget_s.is_finite()) {
        return bad(format!(
            "the budget must be a positive number of seconds, not {}",
            o.budget_s
        ));
    }
    if !(o.scale > 0.0 && o.scale <= 64.0) {
        return bad(format!("--scale must be in (0, 64], not {}", o.scale));
    }
    if o.eval_spp == 0
        || o.reference_spp == 0
        || o.reference_primal_spp == 0
        || o.eval_spp > 1 << 16
    {
        return bad(format!(
            "--eval-spp ({}), --reference-spp ({}) and --reference-primal-spp ({}) must be at \
             least 1 (eval at most 65536)",
            o.eval_spp, o.reference_spp, o.reference_primal_spp
        ));
    }
    if o.successive == 0 || o.successive > 4096 {
        return bad(format!(
            "--successive must be in [1, 4096], not {}",
            o.successive
        ));
    }
    if o.gradient_only && o.end_to_end_only {
        return bad("--gradient-only and --end-to-end-only leave nothing to measure".into());
    }
    Ok(())
}

/// The task at `path` as the bench runs it: scaled, under the protocol, with the options'
/// priors and depth.
fn load_task(path: &Path, o: &BenchOptions) -> Result<Task> {
    let mut t = o.protocol.apply(&scaled(&Task::load(path)?, o.scale));
    if o.no_priors {
        t.optimizer.priors_off();
    }
    if let Some(d) = o.max_depth {
        crate::scene::MaxDepth::new(d)
            .map_err(|m| Error::Invalid(format!("bench: --max-depth: {m}")))?;
        t.max_depth = d;
    }
    Ok(t)
}

/// Steps of the progress bar per scene: targets, the primal and gradient phases (one per
/// seed and the reference), the search and each run of the equal-time phase (the
/// baseline's and the contenders').
fn steps_per_scene(o: &BenchOptions) -> u64 {
    let contenders = if o.gradient_only {
        0
    } else {
        o.contenders.len() as u64
    };
    let phases = if o.end_to_end_only {
        2
    } else {
        o.repeats.max(1) as u64 + if o.gradient_only { 2 } else { 3 }
    };
    phases + u64::from(o.tune && !o.gradient_only) + contenders
}

/// Compile every optimizer pass the bench may create on `task` on a second device.
fn compile_ahead(gpu: &Gpu, task: &Task, o: &BenchOptions) -> Option<std::thread::JoinHandle<()>> {
    let mut passes: Vec<&str> = Vec::new();
    let all = [Contender::BASELINE, Contender::adam(o.gradient_method)];
    for c in all.iter().chain(&o.contenders) {
        let c = c.on(task, crate::task::named_cameras(task));
        let s = c.settings(task, |t, m| task_settings(t, &[], m, &o.estimator_options));
        for p in Optimizer::passes(&s) {
            if !passes.contains(&p) {
                passes.push(p);
            }
        }
    }
    gpu.compile_elsewhere(&passes, task.optimizes(crate::vocab::Slot::Normal))
}

/// With `--tune`, each run's settings searched on another seed (the baseline's first, then
/// the contenders'; the default configuration untuned); without it, none.
fn tune_contenders(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    dir: &Path,
    progress: &Progress,
) -> Result<Vec<Option<tune::Tuned>>> {
    if !o.tune {
        return Ok(vec![None; 1 + o.contenders.len()]);
    }
    let budget = o.tune_budget_s.unwrap_or(o.budget_s / 3.0);
    let key = format!(
        "{} {}x{} {:?} scale {} priors {} primal {:?} cache {:?} options {:?} tuning {budget} s, \
         psrestir {}",
        task.path.display(),
        task.width,
        task.height,
        o.protocol,
        o.scale,
        !o.no_priors,
        o.primal,
        o.path_cache,
        o.estimator_options,
        env!("CARGO_PKG_VERSION"),
    );
    let mut t = Vec::new();
    for c in std::iter::once(Contender::BASELINE).chain(o.contenders.iter().copied()) {
        // The default configuration is measured as it is, untuned.
        if c.auto {
            t.push(None);
            continue;
        }
        let mut s = settings(prep, task, c.method, o);
        c.apply(&mut s);
        t.push(Some(tune::tune(
            gpu, prep, &s, budget, &key, dir, progress,
        )?));
    }
    progress.done();
    Ok(t)
}

/// One scene's results from its phases.
fn scene_result(
    name: String,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    pp: &PrimalPhase,
    g: &gradient::GradientPhase,
    optimization: Option<OptimizationResult>,
) -> SceneResult {
    // The primal estimator of both phases (the task's, or the bench's --primal).
    let primal = settings(prep, task, o.gradient_method, o).primal;
    SceneResult {
        name,
        seed: task.seed,
        budget_s: o.budget_s,
        task: task.path.display().to_string(),
        width: task.width,
        height: task.height,
        cameras: prep.cameras.len(),
        texels: prep.set.textures.iter().map(|t| t.width * t.height).sum(),
        primal_spp: task.optimizer.primal_spp,
        gradient_spp: task.optimizer.gradient_spp,
        gradient_method: o.gradient_method.name().into(),
        baseline_spp_equal_time: g.baseline_spp_equal_time,
        gradient_relmse_baseline: g.total_baseline,
        gradient_relmse_estimator: g.total_estimator,
        gradient_relmse_ratio: g.total_estimator / g.total_baseline,
        gradient_relmse_baseline_equal_iterations: g.total_baseline_equal_iterations,
        gradient_relmse_ratio_equal_iterations: g.total_estimator
            / g.total_baseline_equal_iterations,
        gradient_relmse_estimator_only_baseline: g.only_baseline,
        gradient_relmse_estimator_only_estimator: g.only_estimator,
        gradient_relmse_estimator_only_ratio: g.only_estimator / g.only_baseline,
        gradient_relmse_estimator_only_baseline_equal_time: g.only_baseline_equal_time,
        gradient_relmse_estimator_only_ratio_equal_time: g.only_estimator
            / g.only_baseline_equal_time,
        gradient_relmse_mean_baseline: g.mean_baseline,
        gradient_relmse_mean_estimator: g.mean_estimator,
        gradient_relmse_mean_ratio: g.mean_estimator / g.mean_baseline,
        successive_estimates: o.successive,
        gradient_relmse_per_texture: prep
            .set
            .textures
            .iter()
            .zip(&g.per_texture)
            .map(|(t, p)| TextureGradientErrors {
                texture: t.name(),
                estimator_only_baseline: p.only_baseline,
                estimator_only_estimator: p.only_estimator,
                estimator_only_ratio: p.only_estimator / p.only_baseline,
                total_baseline_equal_iterations: p.total_baseline_equal_iterations,
                total_estimator: p.total_estimator,
                total_ratio_equal_iterations: p.total_estimator / p.total_baseline_equal_iterations,
            })
            .collect(),
        ms_per_iteration_ratio: g.ms_ratio,
        primal: primal.name().into(),
        primal_relmse_independent: pp.relmse_independent,
        primal_relmse_control_variate: pp.relmse_control_variate,
        primal_relmse_ratio: pp.relmse_control_variate / pp.relmse_independent,
        primal_ms_independent: pp.ms_independent,
        primal_ms_control_variate: pp.ms_control_variate,
        optimization,
    }
}

/// The scene's name: its folder's name (the bundled scenes' folders are their names).
fn scene_name(task: &Task) -> String {
    task.base
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .filter(|n| !n.is_empty())
        .unwrap_or_else(|| task.path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::{Method, StepKind};

    #[test]
    fn contenders_parse_with_their_step_and_filter() {
        let c = Contender::parse("recursive:variance+filtered").unwrap();
        assert_eq!(
            (c.method, c.step, c.filtered),
            (Method::RECURSIVE, StepKind::VARIANCE, true)
        );
        assert_eq!(c.key(), "recursive_variance_filtered");
        let c = Contender::parse("baseline").unwrap();
        assert_eq!(c, Contender::adam(Method::BASELINE));
        assert_eq!(c.key(), "baseline");
        assert_eq!(
            Contender::parse("baseline+filtered").unwrap().name(),
            "baseline, Adam, filtered moments"
        );
        for bad in ["filtered", "baseline:sgd", "restir+blur"] {
            assert!(Contender::parse(bad).is_err(), "{bad} accepted");
        }
        // The filter's levels come from the task, or the suggested ones.
        let mut s = crate::optim::Settings::new(8, 8, vec![0]);
        Contender::parse("baseline+filtered").unwrap().apply(&mut s);
        assert_eq!(
            s.moment_filter.levels,
            crate::optim::moment_filter::SUGGESTED_LEVELS
        );
        Contender::adam(Method::BASELINE).apply(&mut s);
        assert!(!s.moment_filter.enabled());
    }
}
