//! A whole optimization run from a task file: targets, the iteration loop with progress,
//! metrics and checkpoints, and the outputs.
use super::metrics::{
    log_exposures, log_observed, progress_bar, progress_message, Metrics, PassMean,
};
use super::problem::camera_file_name;
use super::Problem;
use crate::gpu::Gpu;
use crate::image_io::{self, Image};
use crate::optim::checkpoint::{Checkpoint, Header, MetricRow};
use crate::optim::{FaultCounts, Optimizer, PassTimes};
use crate::render::params::ParamSet;
use crate::task::Task;
use crate::task::{named_cameras, task_configuration, task_method, task_settings};
use crate::vocab::Slot;
use crate::{Error, Result};
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
    /// Warnings the run gave (also logged): a loss that did not fall ([`super::watch`]).
    pub warnings: Vec<String>,
    /// Seconds this run spent creating (compiling) GPU pipelines, all before the
    /// optimization's clock started ([`Gpu::pipeline_times`]).
    pub pipeline_s: f64,
    /// The optimized textures' layout, and their final values laid out as it says.
    pub set: ParamSet,
}

/// One optimized texture's observed-texel RMSE at the start and at the end of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureErrors {
    /// `material_slot`.
    pub texture: String,
    /// At the initial values.
    pub initial_rmse_observed: f64,
    /// At the end.
    pub final_rmse_observed: f64,
}

/// A render as it is compared with its target: times the camera's exposure.
fn exposed(mut img: Image, exposure: f32) -> Image {
    for p in &mut img.rgb {
        *p = p.map(|v| v * exposure);
    }
    img
}

/// Log the configuration a run takes, then each choice `auto` made with its reason.
fn log_configuration(
    config: &crate::optim::auto::Configuration,
    settings: &crate::optim::Settings,
    set: &ParamSet,
) {
    let own = settings.estimator_options.describe(settings.method);
    log::info!(
        "gradient estimator: {}{}; step: {}{}; learning rates {}; schedule: {}; smoothness {}",
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
            .map(|t| format!(
                "{} {}",
                t.name(),
                crate::optim::auto::texture_rate(t, settings.step)
            ))
            .collect::<Vec<_>>()
            .join(", "),
        settings.schedule.describe(),
        settings.smoothness,
    );
    for reason in &config.reasons {
        log::info!("auto: {reason}");
    }
}

/// Image relMSE of an `spp`-sample render of every camera of `opt` against its target
/// (mean over cameras), with the same seed at every call, so that differences between calls
/// are the textures', not the noise's; and the renders.
pub fn evaluate(
    opt: &Optimizer,
    targets: &[Image],
    spp: u32,
    seed: u32,
) -> Result<(f64, Vec<Image>)> {
    let mut sum = 0.0;
    let mut images = Vec::new();
    for (k, target) in targets.iter().enumerate() {
        let img = exposed(
            opt.render(
                k,
                spp,
                crate::optim::pass_seed(seed, u32::MAX - 2, k as u32, crate::optim::Seeds::EVAL),
            )?,
            opt.exposure()[k],
        );
        sum += crate::optim::loss::image_relmse(&img, target);
        images.push(img);
    }
    Ok((sum / targets.len().max(1) as f64, images))
}

/// Root-mean-square difference.
pub fn rmse(a: &[f32], b: &[f32]) -> f64 {
    let s: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    (s / a.len().max(1) as f64).sqrt()
}

fn layout_string(set: &ParamSet) -> String {
    set.textures
        .iter()
        .map(|t| format!("{}:{}x{}", t.name(), t.width, t.height))
        .collect::<Vec<_>>()
        .join(",")
}

/// The columns of metrics.csv.
pub const METRICS_HEADER: &str =
    "iteration,elapsed_s,loss,texture_rmse,texture_rmse_observed,image_relmse,learning_rate";

/// Write `texture_errors.csv` atomically: per optimized texture, its observed-texel RMSE at
/// the start and at the end of the run.
pub fn write_texture_errors(path: &Path, errors: &[TextureErrors]) -> Result<()> {
    let mut s = String::from("texture,initial_rmse_observed,final_rmse_observed\n");
    for t in errors {
        s.push_str(&format!(
            "{},{:.6e},{:.6e}\n",
            t.texture, t.initial_rmse_observed, t.final_rmse_observed
        ));
    }
    image_io::write_atomic(path, s.as_bytes())
}

/// Write metrics.csv atomically. Empty fields: not measured at that iteration (texture
/// errors without a ground truth, image error between evaluations, the loss of the start).
pub fn write_metrics(path: &Path, rows: &[MetricRow]) -> Result<()> {
    let opt = |v: Option<f64>| {
        v.filter(|v| v.is_finite())
            .map(|v| format!("{v:.6e}"))
            .unwrap_or_default()
    };
    let mut s = format!("{METRICS_HEADER}\n");
    for r in rows {
        s.push_str(&format!(
            "{},{:.4},{},{},{},{},{}\n",
            r.iteration,
            r.elapsed_s,
            opt(r.loss),
            opt(r.texture_rmse),
            opt(r.texture_rmse_observed),
            opt(r.image_relmse),
            opt(r.learning_rate),
        ));
    }
    image_io::write_atomic(path, s.as_bytes())
}

/// Texture `i` of `values` as an image: RGB for base color, gray for scalars.
pub fn texture_image(set: &ParamSet, values: &[f32], i: usize) -> Image {
    let t = &set.textures[i];
    let v = &values[t.offset as usize..t.offset as usize + t.len()];
    let rgb = match t.slot {
        Slot::BaseColor => v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        _ => v.iter().map(|&x| [x; 3]).collect(),
    };
    Image {
        width: t.width,
        height: t.height,
        rgb,
    }
}

/// Save each texture as EXR (linear) and PNG (sRGB for base color, linear gray for scalars).
pub fn save_textures(dir: &Path, set: &ParamSet, values: &[f32]) -> Result<()> {
    for i in 0..set.textures.len() {
        let t = &set.textures[i];
        let img = texture_image(set, values, i);
        img.save(&dir.join(format!("{}.exr", t.name())))?;
        let bytes: Vec<u8> = match t.slot {
            Slot::BaseColor => img.to_srgb8(),
            _ => img
                .rgb
                .iter()
                .flat_map(|p| p.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
                .collect(),
        };
        let png = image::RgbImage::from_raw(img.width, img.height, bytes)
            .ok_or_else(|| Error::Invalid("texture size mismatch".into()))?;
        let path = dir.join(format!("{}.png", t.name()));
        image_io::write_atomic_with(&path, |tmp| {
            png.save_with_format(tmp, image::ImageFormat::Png)
                .map_err(std::io::Error::other)
        })?;
    }
    Ok(())
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
    let helper = gpu.compile_elsewhere(&passes);
    // On an error the helper is left to finish alone (its work is a cache for later runs).
    let prep = Problem::from_task(gpu, task, &out, opts.resume)?;
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
    if settings.method == crate::optim::Method::Restir && task.max_depth > 1 {
        log::warn!(
            "ReSTIR with paths of {} vertices reuses each path's first vertex with the light \
             the rest of the path brought back when it was drawn, which the other surfaces' \
             textures change since: its gradient lags them (the later vertices' derivatives \
             are plain Monte Carlo). The baseline and the recursive estimator draw every \
             vertex afresh",
            task.max_depth
        );
    }
    let initial_rmse = prep.reference.as_ref().map(|r| rmse(&prep.set.values, r));
    let settings_step = settings.step;
    let mut opt = Optimizer::for_problem(gpu, &prep, settings)?;
    opt.prepare()?;
    let (n_pipelines, pipeline_s) = gpu.pipeline_seconds_since(pipelines_before);
    log::info!(
        "{n_pipelines} GPU passes ready after {pipeline_s:.1} s of pipeline creation, before \
         the optimization's clock starts"
    );
    // The model's path depth is part of what a checkpoint continues (said only above 1, so
    // that checkpoints of direct-light runs read as before).
    let mut layout = layout_string(&prep.set);
    if task.max_depth > 1 {
        layout.push_str(&format!(", paths of {} vertices", task.max_depth));
    }
    let (mut rows, elapsed_before) = match checkpoint {
        Some(c) => resume(&mut opt, c, &ckpt_path, &layout, prep.set.values.len())?,
        None => (Vec::new(), 0.0),
    };
    let max_iter = opts.iterations.or(task.optimizer.iterations);
    let budget = opts.time_budget_s.or(task.optimizer.time_budget_s);
    let save_checkpoint = |opt: &Optimizer, rows: &[MetricRow], elapsed: f64| -> Result<()> {
        Checkpoint {
            header: Header {
                elapsed_s: elapsed,
                layout: layout.clone(),
                metrics: rows.to_vec(),
            },
            state: opt.state()?,
        }
        .save(&ckpt_path)?;
        write_metrics(&out.join("metrics.csv"), rows)
    };

    let bar = opts
        .progress
        .then(|| progress_bar(max_iter, budget, opt.iteration, elapsed_before));
    // Texture errors every iteration, or every k-th for textures over 2^20 values.
    let rmse_every = (prep.set.values.len() / (1 << 20)).max(1) as u32;
    let observed = opt.observed_texels()?.to_vec();
    log_observed(&observed);
    save_observed(&out, &prep.set, &observed)?;
    let eval_every = task.optimizer.eval_every;
    let metrics = Metrics {
        prep: &prep,
        observed: &observed,
        eval_spp: task.optimizer.eval_spp,
        eval_every,
        rmse_every,
        seed: task.seed,
    };
    let session_start = Instant::now();
    // Seconds of this session spent on evaluation renders (not counted as optimization).
    let mut excluded = 0.0;
    let start_iter = opt.iteration;
    if rows.is_empty() {
        // The start: texture and image errors of the initial textures.
        let t0 = Instant::now();
        rows.push(metrics.start_row(&opt)?);
        excluded += t0.elapsed().as_secs_f64();
    }
    let mut last_loss = rows.last().and_then(|r| r.loss).unwrap_or(f64::NAN);
    let ckpt_every = task.optimizer.checkpoint_every;
    let ckpt_every_s = task.optimizer.checkpoint_every_s;
    let mut last_ckpt = Instant::now();
    let mut pass_times = PassMean::default();
    let interrupted = || {
        opts.interrupt
            .as_ref()
            .is_some_and(|f| f.load(std::sync::atomic::Ordering::SeqCst))
    };
    let elapsed_now =
        |excluded: f64| elapsed_before + session_start.elapsed().as_secs_f64() - excluded;
    // Only an interrupt that stops the loop early counts (one during the final writes does not).
    let mut was_interrupted = false;
    let mut watch = super::watch::LossWatch::new(settings_step);
    let mut warnings = Vec::new();
    for r in rows.iter().skip(1) {
        // A resumed run's earlier iterations (judged from the next one on).
        watch.observe(r.loss.unwrap_or(f64::NAN), 0.0);
    }
    loop {
        let elapsed = elapsed_now(excluded);
        if max_iter.is_some_and(|n| opt.iteration >= n) || budget.is_some_and(|b| elapsed >= b) {
            break;
        }
        if interrupted() {
            was_interrupted = true;
            break;
        }
        let by_iterations = max_iter.map_or(0.0, |n| opt.iteration as f64 / n.max(1) as f64);
        let by_time = budget.map_or(0.0, |b| elapsed / b);
        let progress = by_iterations.max(by_time);
        opt.set_progress(progress);
        let stats = opt.step()?;
        last_loss = stats.loss;
        if let Some(w) = watch.observe(stats.loss, progress) {
            log::warn!("{w}");
            warnings.push(w);
        }
        // Timestamps are read back on every 8th iteration only: one readback less per
        // iteration, and the mean is as good.
        if (opt.iteration - start_iter) % 8 == 1 {
            pass_times.add(opt.pass_times()?);
        }
        let elapsed = elapsed_now(excluded);
        let t0 = Instant::now();
        let row = metrics.row(&opt, stats.loss, elapsed)?;
        excluded += t0.elapsed().as_secs_f64();
        if let Some(hook) = &opts.on_row {
            (hook.0)(&row);
        }
        rows.push(row);
        if let Some(b) = &bar {
            b.set_position(if max_iter.is_some() {
                opt.iteration as u64
            } else {
                elapsed as u64
            });
            b.set_message(progress_message(&rows));
        }
        let by_iterations = ckpt_every > 0 && opt.iteration % ckpt_every == 0;
        let by_time = ckpt_every_s > 0.0 && last_ckpt.elapsed().as_secs_f64() >= ckpt_every_s;
        if by_iterations || by_time {
            save_checkpoint(&opt, &rows, elapsed)?;
            last_ckpt = Instant::now();
        }
    }
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    // The last row's evaluation render, like every evaluation, is not optimization time.
    let t0 = Instant::now();
    metrics.complete_last(&mut rows, &opt)?;
    excluded += t0.elapsed().as_secs_f64();
    let session_s = session_start.elapsed().as_secs_f64() - excluded;
    let elapsed = elapsed_before + session_s;
    let done = opt.iteration - start_iter;
    save_checkpoint(&opt, &rows, elapsed)?;
    let values = opt.read_params()?;
    let (final_rmse, final_rmse_observed, initial_rmse_observed) = metrics.final_errors(&values);
    let per_texture = metrics.errors_per_texture(&values);
    if !per_texture.is_empty() {
        write_texture_errors(&out.join("texture_errors.csv"), &per_texture)?;
    }
    write_outputs(&out, task, &prep, &opt, &values, &rows)?;
    if task.optimizer.optimize_exposure || task.target.exposure.is_some() {
        log_exposures(&prep, &opt);
    }
    let faults = opt.faults()?;
    if faults != FaultCounts::default() {
        log::warn!("dropped or lost values during the run: {faults:?}");
    }
    Ok(RunSummary {
        iterations: opt.iteration,
        elapsed_s: elapsed,
        final_loss: last_loss,
        initial_rmse,
        final_rmse,
        initial_rmse_observed,
        final_rmse_observed,
        per_texture,
        ms_per_iteration: if done > 0 {
            1000.0 * session_s / done as f64
        } else {
            f64::NAN
        },
        out,
        faults,
        pass_times: pass_times.mean(),
        interrupted: was_interrupted,
        warnings,
        pipeline_s,
        set: ParamSet {
            textures: prep.set.textures.clone(),
            values,
        },
    })
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

/// Restore `opt` from a checkpoint of the same textures and estimator: the metrics so far and
/// the seconds of optimization done.
fn resume(
    opt: &mut Optimizer,
    c: Checkpoint,
    ckpt_path: &Path,
    layout: &str,
    n_params: usize,
) -> Result<(Vec<MetricRow>, f64)> {
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
    Ok((rows, c.header.elapsed_s))
}

fn write_outputs(
    out: &Path,
    task: &Task,
    prep: &Problem,
    opt: &Optimizer,
    values: &[f32],
    rows: &[MetricRow],
) -> Result<()> {
    save_textures(out, &prep.set, values)?;
    write_metrics(&out.join("metrics.csv"), rows)?;
    plot_metrics(&out.join("plot.png"), task, rows, prep.reference.is_some())?;
    for (k, &cam) in prep.cameras.iter().enumerate() {
        let img = opt.render(
            k,
            task.target.spp.min(64),
            crate::optim::pass_seed(task.seed, u32::MAX - 1, k as u32, crate::optim::Seeds::EVAL),
        )?;
        let img = exposed(img, opt.exposure()[k]);
        img.save(&out.join(format!("final_{}.exr", camera_file_name(&prep.scene, cam))))?;
        image_io::side_by_side(&img, &prep.targets[k]).save(&out.join(format!(
            "final_vs_target_{}.png",
            camera_file_name(&prep.scene, cam)
        )))?;
    }
    crate::job::export::write_glb(
        &task.resolve(&task.scene),
        &out.join("optimized.glb"),
        &prep.scene,
        &prep.set,
        values,
    )
}

/// `plot.png`: the loss and the evaluation renders' image relMSE against time (log scale,
/// with the learning-rate schedule on the right axis), and the texture RMSE (all and
/// observed texels) when the ground truth is known.
pub fn plot_metrics(path: &Path, task: &Task, rows: &[MetricRow], truth: bool) -> Result<()> {
    use crate::job::plot::{Panel, Series};
    let series = |name: &str, color, f: &dyn Fn(&MetricRow) -> Option<f64>| Series {
        name: name.into(),
        color,
        points: rows
            .iter()
            .filter_map(|r| f(r).map(|y| (r.elapsed_s, y)))
            .collect(),
    };
    let mut panels = vec![Panel {
        title: format!(
            "loss ({}) and image relMSE of {}-spp evaluation renders",
            format!("{:?}", task.optimizer.loss).to_lowercase(),
            task.optimizer.eval_spp
        ),
        y_label: "error".into(),
        log_y: true,
        series: vec![
            series("loss", [30, 90, 200], &|r| r.loss),
            series("image relMSE", [20, 150, 60], &|r| r.image_relmse),
        ],
        secondary: Some((
            "learning rate".into(),
            vec![series("learning rate", [140, 140, 140], &|r| {
                r.learning_rate
            })],
        )),
    }];
    if truth {
        panels.push(Panel {
            title: "texture RMSE against the ground truth".into(),
            y_label: "RMSE".into(),
            log_y: true,
            series: vec![
                series("observed texels", [200, 50, 40], &|r| {
                    r.texture_rmse_observed
                }),
                series("all texels", [230, 150, 60], &|r| r.texture_rmse),
            ],
            secondary: None,
        });
    }
    crate::job::plot::plot(path, "seconds of optimization", &panels)
}

/// `observed_TEXTURE.png` per texture: white where a camera sample reaches the texel, black
/// where none does (those texels keep their initial values).
pub fn save_observed(dir: &Path, set: &ParamSet, observed: &[bool]) -> Result<()> {
    let mut first = 0usize;
    for t in &set.textures {
        let n = (t.width * t.height) as usize;
        let px: Vec<u8> = observed[first..first + n]
            .iter()
            .map(|&o| if o { 255 } else { 0 })
            .collect();
        first += n;
        let img = image::GrayImage::from_raw(t.width, t.height, px)
            .ok_or_else(|| Error::Invalid("observed mask size".into()))?;
        let path = dir.join(format!("observed_{}.png", t.name()));
        image_io::write_atomic_with(&path, |tmp| {
            img.save_with_format(tmp, image::ImageFormat::Png)
                .map_err(std::io::Error::other)
        })?;
    }
    Ok(())
}

/// One gradient estimate at the task's initial textures, written to `dir` per texture as
/// `<texture>_gradient.exr` (linear, signed) and `<texture>_gradient.png` (signed false color:
/// red positive, blue negative, scaled by the largest magnitude). Returns the files written.
pub fn write_gradient(
    gpu: &Gpu,
    task: &Task,
    dir: &Path,
    method: crate::optim::MethodChoice,
    options: &crate::optim::EstimatorOptions,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let prep = Problem::from_task(gpu, task, dir, false)?;
    let choice = task_method(task, method, prep.cameras.len());
    if choice.automatic {
        log::info!("gradient estimator: {} ({})", choice.method, choice.reason);
    }
    let settings = task_settings(task, &prep.cameras, choice.method, options);
    let mut opt = Optimizer::for_problem(gpu, &prep, settings)?;
    let (grad, _) = opt.estimate_gradient(0)?;
    let mut written = Vec::new();
    for i in 0..prep.set.textures.len() {
        let t = &prep.set.textures[i];
        let img = texture_image(&prep.set, &grad, i);
        let exr = dir.join(format!("{}_gradient.exr", t.name()));
        img.save(&exr)?;
        let v = gradient_scalars(&prep.set, &grad, i);
        let scale = v.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-30);
        let bytes: Vec<u8> = v.iter().flat_map(|&x| false_color(x / scale)).collect();
        let png = dir.join(format!("{}_gradient.png", t.name()));
        let im = image::RgbImage::from_raw(img.width, img.height, bytes)
            .ok_or_else(|| Error::Invalid("size".into()))?;
        image_io::write_atomic_with(&png, |tmp| {
            im.save_with_format(tmp, image::ImageFormat::Png)
                .map_err(std::io::Error::other)
        })?;
        written.push(exr);
        written.push(png);
    }
    Ok(written)
}

/// One signed number per texel of texture `i` of a gradient: the luminance-weighted sum of
/// the channels for base color, the value for scalar textures.
pub fn gradient_scalars(set: &ParamSet, g: &[f32], i: usize) -> Vec<f32> {
    let img = texture_image(set, g, i);
    let slot = set.textures[i].slot;
    img.rgb
        .iter()
        .map(|p| match slot {
            Slot::BaseColor => p[0] * 0.2126 + p[1] * 0.7152 + p[2] * 0.0722,
            _ => p[0],
        })
        .collect()
}

/// Signed value in [-1, 1] to a diverging color: blue (negative), white (0), red (positive).
pub fn false_color(v: f32) -> [u8; 3] {
    let a = v.clamp(-1.0, 1.0).abs().sqrt();
    let fade = ((1.0 - a) * 255.0) as u8;
    if v >= 0.0 {
        [255, fade, fade]
    } else {
        [fade, fade, 255]
    }
}
