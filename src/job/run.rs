//! A whole optimization run from a task file: targets, the iteration loop with progress,
//! metrics and checkpoints, and the outputs (written by `outputs.rs`, measured by
//! `metrics.rs`).
use super::keep::{HandedBack, Keeper};
pub use super::metrics::{
    evaluate, rmse, write_metrics, write_texture_errors, Evaluation, TextureErrors, METRICS_HEADER,
};
use super::metrics::{log_exposures, log_observed, progress_bar, progress_message, Metrics};
use super::outputs::write_outputs;
pub use super::outputs::{
    false_color, gradient_scalars, plot_metrics, save_observed, save_textures, texture_image,
    write_gradient,
};
use super::watch::{LossWatch, PlateauWatch};
use super::Problem;
use crate::gpu::Gpu;
use crate::optim::checkpoint::{Checkpoint, Header, Kept, MetricRow};
use crate::optim::run_loop::{run_observed, Clock, Limits, Observer, PassSampler};
use crate::optim::{FaultCounts, Optimizer, PassTimes, StepStats};
use crate::render::params::ParamSet;
use crate::task::Task;
use crate::task::{named_cameras, task_configuration, task_method, task_settings};
use crate::{Error, Result};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Overrides from the command line.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Iterations (overrides the task).
    pub iterations: Option<u32>,
    /// Time budget in seconds (overrides the task).
    pub time_budget_s: Option<f64>,
    /// Output folder (overrides the task).
    pub out: Option<PathBuf>,
    /// Continue from the output folder's checkpoint.
    pub resume: bool,
    /// Show a progress bar.
    pub progress: bool,
    /// Gradient estimator (`auto`, the default: chosen by the task's sampling and sizes).
    pub method: crate::optim::MethodChoice,
    /// Estimators' options over the task's tables (`--estimator-option`).
    pub estimator_options: crate::optim::EstimatorOptions,
    /// Set (e.g. from a Ctrl-C handler) to stop after the iteration under way: the run then
    /// writes its checkpoint and outputs as at a normal end and returns with `interrupted`.
    pub interrupt: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Called with each iteration's metrics row once it is written (the Python package's
    /// progress callback; set `interrupt` from it to stop).
    pub on_row: Option<RowHook>,
}

/// A function [`run`] calls with each iteration's [`MetricRow`].
#[derive(Clone)]
pub struct RowHook(pub std::sync::Arc<dyn Fn(&MetricRow) + Send + Sync>);

impl std::fmt::Debug for RowHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RowHook(..)")
    }
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// Iterations done in total (including before a resume).
    pub iterations: u32,
    /// Optimization seconds in total.
    pub elapsed_s: f64,
    /// Loss of the last iteration.
    pub final_loss: f64,
    /// Texture RMSE of the initial textures, when the ground truth is known.
    pub initial_rmse: Option<f64>,
    /// Texture RMSE at the end.
    pub final_rmse: Option<f64>,
    /// Texture RMSE of the initial textures over the observed texels.
    pub initial_rmse_observed: Option<f64>,
    /// Texture RMSE at the end over the observed texels.
    pub final_rmse_observed: Option<f64>,
    /// Per optimized texture (in task order), its name and its observed-texel RMSE at the
    /// start and at the end, when the ground truth is known: which texture the error is in.
    pub per_texture: Vec<TextureErrors>,
    /// Milliseconds per iteration in this session.
    pub ms_per_iteration: f64,
    /// The output folder.
    pub out: PathBuf,
    /// Dropped or lost values, all zero in a healthy run.
    pub faults: FaultCounts,
    /// Mean GPU time per iteration of each kind of pass in this session (timestamp queries).
    pub pass_times: Option<PassTimes>,
    /// Whether the run stopped early because `RunOptions::interrupt` was set.
    pub interrupted: bool,
    /// Why the run ended before its budget because it had converged
    /// (`optimizer.stop_on_plateau`), if it did.
    pub plateau: Option<String>,
    /// The earlier state the outputs hold, where an evaluation before the last had a lower
    /// image error (`optimizer.keep_best`); None: the last state.
    pub handed_back: Option<HandedBack>,
    /// Warnings the run gave (also logged): a loss that did not fall ([`super::watch`]).
    pub warnings: Vec<String>,
    /// Seconds this run spent creating (compiling) GPU pipelines, all before the
    /// optimization's clock started ([`Gpu::pipeline_times`]).
    pub pipeline_s: f64,
    /// The optimized textures' layout, and their final values laid out as it says.
    pub set: ParamSet,
    /// The relit errors under the task's `relight` environments (relight.csv), if any.
    pub relit: Vec<super::relight::RelitError>,
    /// With the environment recovered and a ground truth's environment known: the angle in
    /// degrees between their directions of strongest emission.
    pub light_direction_error_deg: Option<f64>,
    /// The recovered environment, when the task recovers it.
    pub environment: Option<crate::scene::EnvMap>,
    /// Each camera's final exposure and white balance.
    pub gains: Vec<(f32, [f32; 3])>,
    /// Each texel's standard deviation, laid out like `set.values`
    /// ([`crate::optim::uncertainty::standard_deviations`]; -1: the images tell nothing), as
    /// `uncertainty_*.exr`.
    pub uncertainty: Option<Vec<f32>>,
}

/// Log the configuration a run takes, then each choice `auto` made with its reason.
fn log_configuration(
    config: &crate::auto::Configuration,
    settings: &crate::optim::Settings,
    set: &ParamSet,
) {
    let own = settings.estimator_options.describe(settings.method);
    log::info!(
        "gradient estimator: {}{}; step: {}{}; learning rates {}; schedule: {}; priors: {}",
        settings.method.name(),
        if own.is_empty() {
            String::new()
        } else {
            format!(" ({own})")
        },
        settings.step.name(),
        if settings.moment_filter.enabled() {
            format!(
                " with filtered moments ({} levels)",
                settings.moment_filter.levels
            )
        } else {
            String::new()
        },
        set.textures
            .iter()
            .map(|t| format!("{} {}", t.name(), settings.step.texture_rate(t)))
            .collect::<Vec<_>>()
            .join(", "),
        settings.schedule.describe(),
        settings.priors.describe_active(),
    );
    for reason in &config.reasons {
        log::info!("auto: {reason}");
    }
}

fn layout_string(set: &ParamSet) -> String {
    set.textures
        .iter()
        .map(|t| format!("{}:{}x{}", t.name(), t.width, t.height))
        .collect::<Vec<_>>()
        .join(",")
}

/// Remove temporary files that a killed run left in `dir` (see `image_io::write_atomic`).
fn remove_stale_temporaries(dir: &Path) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with('.') && name.ends_with(".tmp") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Run (or continue) the optimization of `task`.
pub fn run(gpu: &Gpu, task: &Task, opts: &RunOptions) -> Result<RunSummary> {
    let out = opts.out.clone().unwrap_or_else(|| task.output_dir());
    std::fs::create_dir_all(&out).map_err(|e| Error::file(&out, e.to_string()))?;
    remove_stale_temporaries(&out);
    let ckpt_path = out.join("checkpoint.bin");
    let checkpoint = open_checkpoint(&out, &ckpt_path, opts.resume)?;
    let (prep, mut opt, pipeline_s) = prepare(gpu, task, opts, &out)?;
    let initial_rmse = prep.texture_rmse(&prep.set.values);
    // The model's path depth is part of what a checkpoint continues (said only above 1, so
    // that checkpoints of direct-light runs read as before).
    let mut layout = layout_string(&prep.set);
    if task.max_depth > 1 {
        layout.push_str(&format!(", paths of {} vertices", task.max_depth));
    }
    let (rows, elapsed_before, kept) = match checkpoint {
        Some(c) => resume(&mut opt, c, &ckpt_path, &layout, prep.set.values.len())?,
        None => (Vec::new(), 0.0, None),
    };
    let saver = Saver {
        layout,
        checkpoint: ckpt_path,
        metrics: out.join("metrics.csv"),
    };
    let observed = opt.observed_texels()?.to_vec();
    log_observed(&observed);
    save_observed(&out, &prep.set, &observed)?;
    let metrics = Metrics {
        prep: &prep,
        observed: &observed,
        eval_spp: task.optimizer.eval_spp,
        eval_every: task.optimizer.eval_every,
        // Texture errors every iteration, or every k-th for textures over 2^20 values.
        rmse_every: (prep.set.values.len() / (1 << 20)).max(1) as u32,
        seed: task.seed,
    };
    let start = (rows, kept, elapsed_before);
    let mut session = iterate(&mut opt, task, opts, &metrics, &saver, start)?;
    let elapsed = elapsed_before + session.seconds;
    let handed_back = saver.close(&mut opt, &mut session, elapsed)?;
    let values = opt.read_params()?;
    let (final_rmse, final_rmse_observed, initial_rmse_observed) = metrics.final_errors(&values);
    let per_texture = metrics.errors_per_texture(&values);
    if !per_texture.is_empty() {
        write_texture_errors(&out.join("texture_errors.csv"), &per_texture)?;
    }
    write_outputs(&out, task, &prep, &opt, &values, &session.rows)?;
    // What the images could not tell, from the last loss (none before any iteration).
    let uncertainty = if session.last_loss.is_finite() && session.last_loss > 0.0 {
        let sigma = crate::optim::uncertainty::standard_deviations(&opt, session.last_loss)?;
        super::outputs::save_uncertainty(&out, &prep.set, &sigma)?;
        Some(sigma)
    } else {
        None
    };
    let environment = opt.fit().environment();
    let light_direction_error_deg = match &environment {
        Some(env) => save_environment(&out, &prep, env)?,
        None => None,
    };
    let relit = relight_outputs(gpu, task, &prep, &values, &out)?;
    if task.optimizer.optimize_exposure
        || task.optimizer.optimize_white_balance
        || task.target.exposure.is_some()
    {
        log_exposures(&prep, &opt);
    }
    let faults = opt.faults()?;
    if faults != FaultCounts::default() {
        log::warn!("dropped or lost values during the run: {faults:?}");
    }
    Ok(RunSummary {
        iterations: opt.iteration,
        elapsed_s: elapsed,
        final_loss: session.last_loss,
        initial_rmse,
        final_rmse,
        initial_rmse_observed,
        final_rmse_observed,
        per_texture,
        ms_per_iteration: if session.iterations > 0 {
            1000.0 * session.seconds / session.iterations as f64
        } else {
            f64::NAN
        },
        out,
        faults,
        pass_times: session.pass_times,
        interrupted: session.interrupted,
        plateau: session.plateau,
        handed_back,
        warnings: session.warnings,
        pipeline_s,
        set: ParamSet {
            textures: prep.set.textures.clone(),
            values,
        },
        relit,
        light_direction_error_deg,
        environment,
        uncertainty,
        gains: opt
            .fit()
            .exposure()
            .iter()
            .copied()
            .zip(opt.fit().white_balance().iter().copied())
            .collect(),
    })
}

/// Write the recovered environment `env` to `environment.exr` (lat-long, row 0 at the
/// zenith like the inputs); where the truth has one, the angle in degrees between their
/// strongest emissions, logged.
fn save_environment(out: &Path, prep: &Problem, env: &crate::scene::EnvMap) -> Result<Option<f64>> {
    let img = crate::image_io::Image {
        width: env.width,
        height: env.height,
        rgb: env.rgb.clone(),
    };
    img.save(&out.join("environment.exr"))?;
    let Some(truth) = prep.truth.as_ref().and_then(|t| t.env.as_ref()) else {
        return Ok(None);
    };
    let e = super::relight::direction_error_deg(env, truth);
    log::info!("the recovered environment's strongest emission is {e:.1} degrees from the truth's");
    Ok(Some(e))
}

/// The relit errors under the task's `relight` environments, written to `relight.csv` (none
/// without them or without a ground truth).
fn relight_outputs(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    values: &[f32],
    out: &Path,
) -> Result<Vec<super::relight::RelitError>> {
    let seed = crate::optim::pass_seed(task.seed, u32::MAX - 5, 0, crate::optim::Seeds::EVAL);
    let spp = task.target.spp.min(256);
    let errors = super::relight::task_errors(gpu, task, prep, values.to_vec(), spp, seed)?;
    if errors.is_empty() {
        return Ok(errors);
    }
    for e in &errors {
        log::info!(
            "relit under {}: relMSE {:.4e}, PSNR {:.2} dB (per-channel scales {:.3} {:.3} {:.3})",
            e.environment,
            e.relmse,
            e.psnr,
            e.scale[0],
            e.scale[1],
            e.scale[2]
        );
    }
    super::relight::write_relight_csv(&out.join("relight.csv"), &errors)?;
    Ok(errors)
}

/// The problem of `task` with its targets and the optimizer ready to step (every pipeline
/// created), with the seconds of pipeline creation.
fn prepare(
    gpu: &Gpu,
    task: &Task,
    opts: &RunOptions,
    out: &Path,
) -> Result<(Problem, Optimizer, f64)> {
    let pipelines_before = gpu.pipeline_times().len();
    log::info!(
        "preparing the targets and the GPU passes (a driver's first run on a machine compiles \
         their shaders; later runs load them from its cache)"
    );
    // The optimizer's passes compile on a second device while this one renders the targets
    // (for `auto`, those of its choice with the cameras the task names).
    let passes = Optimizer::passes(&task_settings(
        task,
        &[],
        task_method(task, opts.method, named_cameras(task)).method,
        &opts.estimator_options,
    ));
    let helper = gpu.compile_elsewhere(&passes, task.optimizes(crate::vocab::Slot::Normal));
    // On an error the helper is left to finish alone (its work is a cache for later runs).
    let prep = Problem::from_task(gpu, task, out, opts.resume)?;
    if let Some(h) = helper {
        let _ = h.join();
    }
    let config = task_configuration(task, opts.method, prep.cameras.len());
    let settings = task_settings(
        task,
        &prep.cameras,
        config.estimator.method,
        &opts.estimator_options,
    );
    log_configuration(&config, &settings, &prep.set);
    let conditions = crate::optim::estimator::Conditions {
        max_depth: task.max_depth,
    };
    for warning in (settings.method.kind().warnings)(&conditions) {
        log::warn!("{warning}");
    }
    let mut opt = Optimizer::for_problem(gpu, &prep, settings)?;
    opt.prepare()?;
    let (n_pipelines, pipeline_s) = gpu.pipeline_seconds_since(pipelines_before);
    log::info!(
        "{n_pipelines} GPU passes ready after {pipeline_s:.1} s of pipeline creation, before \
         the optimization's clock starts"
    );
    Ok((prep, opt, pipeline_s))
}

/// Where a run's checkpoint and metrics go, and the layout its checkpoints carry.
struct Saver {
    layout: String,
    checkpoint: PathBuf,
    metrics: PathBuf,
}

impl Saver {
    /// At a run's end: the checkpoint with the last state (what --resume continues) and the
    /// kept one beside it, then the kept state put into `opt` for the outputs, where it is not
    /// the last ([`Keeper::hand_back`]).
    fn close(
        &self,
        opt: &mut Optimizer,
        session: &mut Session,
        elapsed: f64,
    ) -> Result<Option<HandedBack>> {
        self.save(opt, &session.rows, elapsed, session.keeper.kept())?;
        let last = session.rows.last().and_then(|r| r.image_relmse_expected);
        let handed_back = session.keeper.hand_back(opt, last)?;
        if let Some(h) = &handed_back {
            h.log(opt.iteration, &mut session.warnings);
        }
        Ok(handed_back)
    }

    /// Write the checkpoint (with the kept state) and `metrics.csv` (both atomically).
    fn save(
        &self,
        opt: &Optimizer,
        rows: &[MetricRow],
        elapsed: f64,
        kept: Option<&Kept>,
    ) -> Result<()> {
        Checkpoint {
            header: Header {
                elapsed_s: elapsed,
                layout: self.layout.clone(),
                metrics: rows.to_vec(),
            },
            state: opt.state()?,
            kept: kept.cloned(),
        }
        .save(&self.checkpoint)?;
        write_metrics(&self.metrics, rows)
    }
}

/// What the iterations of one session (a run, or the part after a resume) left.
struct Session {
    /// Every row of metrics.csv, the earlier sessions' included.
    rows: Vec<MetricRow>,
    /// Seconds of optimization in this session (evaluation renders not counted).
    seconds: f64,
    /// Iterations in this session.
    iterations: u32,
    last_loss: f64,
    pass_times: Option<PassTimes>,
    /// Whether an interrupt stopped the loop early (one during the final writes does not
    /// count).
    interrupted: bool,
    /// Why it ended on a plateau, if it did.
    plateau: Option<String>,
    warnings: Vec<String>,
    /// The state with the lowest evaluation error so far.
    keeper: Keeper,
}

/// What watches a run's rows: the loss that does not fall (a warning) and, where asked, the
/// plateau that ends the run.
struct Watches {
    loss: LossWatch,
    plateau: Option<PlateauWatch>,
}

impl Watches {
    /// The watches of `opt`'s run of `task`, primed with a resumed run's `earlier` rows (its
    /// iterations before this session, judged from the next one on).
    fn new(opt: &Optimizer, task: &Task, stop_on_plateau: bool, earlier: &[MetricRow]) -> Self {
        let mut w = Watches {
            loss: LossWatch::new(opt.settings().step),
            plateau: stop_on_plateau.then(|| PlateauWatch::new(task.optimizer.eval_every > 0)),
        };
        for r in earlier {
            let loss = r.loss.unwrap_or(f64::NAN);
            w.loss.observe(loss, 0.0);
            if let Some(p) = &mut w.plateau {
                p.observe(r.iteration, loss, r.image_relmse, 0.0);
            }
        }
        w
    }
}

/// Step `opt` until the task's (or the options') budget is spent or an interrupt comes,
/// with a metrics row per iteration, the progress bar, the loss watch and checkpoints: the
/// optimizer's loop ([`run_observed`](crate::optim::run_loop::run_observed)) with a [`JobWatch`] and the passes'
/// sampler.
fn iterate(
    opt: &mut Optimizer,
    task: &Task,
    opts: &RunOptions,
    metrics: &Metrics,
    saver: &Saver,
    (mut rows, kept, elapsed_before): (Vec<MetricRow>, Option<Kept>, f64),
) -> Result<Session> {
    let mut keeper = Keeper::new(task.optimizer.keep_best, kept);
    let limits = Limits {
        first: 0,
        iterations: opts.iterations.or(task.optimizer.iterations),
        seconds: opts.time_budget_s.or(task.optimizer.time_budget_s),
    };
    let bar = opts.progress.then(|| {
        progress_bar(
            limits.iterations,
            limits.seconds,
            opt.iteration,
            elapsed_before,
        )
    });
    let mut clock = Clock::start(elapsed_before);
    let start_iter = opt.iteration;
    if rows.is_empty() {
        // The start: texture and image errors of the initial textures.
        let start = clock.aside(|| metrics.start_row(opt))?;
        clock.aside(|| keeper.offer(opt, start.image_relmse_expected))?;
        rows.push(start);
    }
    let stop_on_plateau = task
        .optimizer
        .stop_on_plateau
        .unwrap_or(limits.seconds.is_some() && limits.iterations.is_none());
    let earlier = rows.get(1..).unwrap_or_default();
    let watches = Watches::new(opt, task, stop_on_plateau, earlier);
    let mut watch = JobWatch {
        session: Session {
            last_loss: rows.last().and_then(|r| r.loss).unwrap_or(f64::NAN),
            rows,
            seconds: 0.0,
            iterations: 0,
            pass_times: None,
            interrupted: false,
            plateau: None,
            warnings: Vec::new(),
            keeper,
        },
        watches,
        opts,
        metrics,
        saver,
        bar,
        limits,
        checkpoint_every: (
            task.optimizer.checkpoint_every,
            task.optimizer.checkpoint_every_s,
        ),
        last_checkpoint: Instant::now(),
    };
    let mut sampler = PassSampler::default();
    run_observed(opt, limits, &mut clock, &mut [&mut sampler, &mut watch])?;
    let mut session = watch.session;
    if let Some(b) = &watch.bar {
        b.finish_and_clear();
    }
    // The last row's evaluation render, like every evaluation, is not optimization time.
    clock.aside(|| metrics.complete_last(&mut session.rows, opt))?;
    if let Some(last) = session.rows.last() {
        clock.aside(|| session.keeper.offer(opt, last.image_relmse_expected))?;
    }
    session.seconds = clock.session_seconds();
    session.iterations = opt.iteration - start_iter;
    session.pass_times = sampler.mean();
    Ok(session)
}

/// The job's observer of its loop: the interrupt, a metrics row per iteration (its
/// measurements set aside on the clock), the loss and plateau watches, the progress bar, the
/// row hook and the checkpoints.
struct JobWatch<'a> {
    session: Session,
    watches: Watches,
    opts: &'a RunOptions,
    metrics: &'a Metrics<'a>,
    saver: &'a Saver,
    bar: Option<indicatif::ProgressBar>,
    limits: Limits,
    /// Iterations and seconds between checkpoints (0: never by that measure).
    checkpoint_every: (u32, f64),
    last_checkpoint: Instant,
}

impl Observer for JobWatch<'_> {
    fn before(&mut self, _: &mut Optimizer, _: &mut Clock, last: bool) -> Result<ControlFlow<()>> {
        let interrupted = self
            .opts
            .interrupt
            .as_ref()
            .is_some_and(|f| f.load(std::sync::atomic::Ordering::SeqCst));
        if interrupted && !last {
            self.session.interrupted = true;
            return Ok(ControlFlow::Break(()));
        }
        Ok(ControlFlow::Continue(()))
    }

    fn after(
        &mut self,
        opt: &mut Optimizer,
        stats: &StepStats,
        progress: f64,
        clock: &mut Clock,
    ) -> Result<ControlFlow<()>> {
        let session = &mut self.session;
        session.last_loss = stats.loss;
        if let Some(w) = self.watches.loss.observe(stats.loss, progress) {
            log::warn!("{w}");
            session.warnings.push(w);
        }
        let elapsed = clock.seconds();
        let row = clock.aside(|| self.metrics.row(opt, stats.loss, elapsed))?;
        if let Some(hook) = &self.opts.on_row {
            (hook.0)(&row);
        }
        let converged = self
            .watches
            .plateau
            .as_mut()
            .and_then(|p| p.observe(row.iteration, stats.loss, row.image_relmse, progress));
        clock.aside(|| session.keeper.offer(opt, row.image_relmse_expected))?;
        session.rows.push(row);
        if let Some(b) = &self.bar {
            b.set_position(if self.limits.iterations.is_some() {
                opt.iteration as u64
            } else {
                elapsed as u64
            });
            b.set_message(progress_message(&session.rows));
        }
        let (every, every_s) = self.checkpoint_every;
        let by_iterations = every > 0 && opt.iteration % every == 0;
        let by_time = every_s > 0.0 && self.last_checkpoint.elapsed().as_secs_f64() >= every_s;
        if by_iterations || by_time {
            self.saver
                .save(opt, &session.rows, elapsed, session.keeper.kept())?;
            self.last_checkpoint = Instant::now();
        }
        if let Some(why) = converged {
            log::info!("{why}");
            session.plateau = Some(why);
            return Ok(ControlFlow::Break(()));
        }
        Ok(ControlFlow::Continue(()))
    }
}

/// The checkpoint to resume from: with `resume` and one in the output folder. `--resume`
/// without a checkpoint starts from the beginning, so that one command both starts and
/// restarts a job.
fn open_checkpoint(out: &Path, ckpt_path: &Path, resume: bool) -> Result<Option<Checkpoint>> {
    if resume && ckpt_path.exists() {
        return Ok(Some(Checkpoint::load(ckpt_path)?));
    }
    if resume {
        log::warn!(
            "--resume: no checkpoint in {} yet: starting from the beginning",
            out.display()
        );
    }
    Ok(None)
}

/// Restore `opt` from a checkpoint of the same textures and estimator: the metrics so far,
/// the seconds of optimization done and the kept state.
fn resume(
    opt: &mut Optimizer,
    c: Checkpoint,
    ckpt_path: &Path,
    layout: &str,
    n_params: usize,
) -> Result<(Vec<MetricRow>, f64, Option<Kept>)> {
    if c.header.layout != layout || c.state.params.len() != n_params {
        return Err(Error::file(
            ckpt_path,
            format!(
                "checkpoint holds textures {} but the task has {layout}",
                c.header.layout
            ),
        ));
    }
    // Refused before anything is written when another estimator or other images wrote it.
    opt.restore(&c.state)
        .map_err(|e| Error::file(ckpt_path, e.to_string()))?;
    let mut rows = c.header.metrics;
    rows.retain(|r| r.iteration <= opt.iteration);
    log::info!(
        "resuming at iteration {} ({:.1} s done)",
        opt.iteration,
        c.header.elapsed_s
    );
    let kept = c.kept.filter(|k| k.values.iteration <= opt.iteration);
    Ok((rows, c.header.elapsed_s, kept))
}
