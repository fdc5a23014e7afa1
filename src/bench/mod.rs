//! `psrestir bench`: the paper's measurements (DESIGN.md section 6) of the baseline and the
//! ReSTIR estimator, one after the other on the same device, per scene:
//!
//! 1. gradient error: after `warmup` ReSTIR iterations, the relMSE of ReSTIR's next gradient
//!    and of baseline gradients at the same parameter state, at equal iterations (the task's
//!    spp) and at equal time (as many spp as fit in the time of one ReSTIR iteration), against
//!    a reference from a converged adjoint (a `reference_primal_spp` primal render) and
//!    `reference_spp` gradient samples. Each error is measured twice: *total*, each estimator
//!    with the adjoint of its own task-spp primal render (what a user gets), and
//!    *estimator-only*, both under the converged adjoint (what the reservoirs do);
//! 2. equal-time optimization: both estimators optimize from the same start for the same
//!    wall-clock budget; image relMSE (a high-spp render against the target) and texture RMSE
//!    against the ground truth, as curves over time and at the end;
//! 3. cost: milliseconds per iteration, GPU time per pass, bytes of state per texel.
//!
//! The report (`bench.json`, `report.md`, plots and gradient images) is written by
//! [`report`].
pub mod report;

use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::optim::observed::rmse_observed;
use crate::optim::run::{rmse, task_settings};
use crate::optim::Problem;
use crate::optim::{Method, Optimizer, PassTimes, RestirOptions, Settings};
use crate::task::Task;
use crate::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Which sampling settings the benchmark runs the scenes with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Protocol {
    /// Each task's own settings (primal and gradient spp, texture filter).
    #[default]
    Default,
    /// The paper's: a 32-spp primal render, 1 gradient spp, nearest filtering.
    Paper,
}

impl Protocol {
    /// `task` with the protocol's sampling settings.
    pub fn apply(self, task: &Task) -> Task {
        let mut t = task.clone();
        if self == Protocol::Paper {
            t.optimizer.primal_spp = 32;
            t.optimizer.gradient_spp = 1;
            t.optimizer.filter = crate::vocab::Filter::Nearest;
        }
        t
    }
}

/// What to measure and where to write it.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Wall-clock seconds each estimator optimizes each scene (step time only: evaluation
    /// renders and readbacks are not counted).
    pub budget_s: f64,
    /// Multiplier of image and texture sizes.
    pub scale: f64,
    /// ReSTIR iterations before the gradient error is measured.
    pub warmup: u32,
    /// Seeds the gradient error is averaged over.
    pub repeats: u32,
    /// Gradient samples per pixel of the reference gradient.
    pub reference_spp: u32,
    /// Samples per pixel of the primal render of the converged adjoint (under which the
    /// reference and the estimator-only errors are computed).
    pub reference_primal_spp: u32,
    /// Sampling settings of the scenes.
    pub protocol: Protocol,
    /// Measure the gradient error only (no equal-time optimization).
    pub gradient_only: bool,
    /// The primal estimator of every run (None: each task's own).
    pub primal: Option<crate::optim::PrimalMode>,
    /// Samples per pixel of the renders that measure image error.
    pub eval_spp: u32,
    /// Image-error evaluations along each optimization (start and end included).
    pub curve_points: u32,
    /// ReSTIR settings.
    pub restir: RestirOptions,
    /// Output folder.
    pub out: PathBuf,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            budget_s: 60.0,
            scale: 1.0,
            warmup: 20,
            repeats: 3,
            reference_spp: 256,
            reference_primal_spp: 256,
            protocol: Protocol::Default,
            gradient_only: false,
            primal: None,
            eval_spp: 64,
            curve_points: 11,
            restir: RestirOptions::default(),
            out: PathBuf::from("out/bench"),
            progress: true,
        }
    }
}

/// One point of an optimization curve.
#[derive(Clone, Debug, Serialize)]
pub struct CurvePoint {
    /// Iterations done.
    pub iteration: u32,
    /// Seconds of optimization (step time).
    pub seconds: f64,
    /// Loss of the iteration's primal render.
    pub loss: f64,
    /// Texture RMSE against the ground truth.
    pub texture_rmse: f64,
    /// Texture RMSE over the observed texels.
    pub texture_rmse_observed: f64,
    /// The learning-rate schedule's factor in this iteration.
    pub learning_rate_factor: Option<f64>,
    /// Image relMSE of a high-spp render against the target, at evaluation points only.
    pub image_relmse: Option<f64>,
}

/// The measurements of one scene.
#[derive(Clone, Debug, Serialize)]
pub struct SceneResult {
    /// Scene name.
    pub name: String,
    /// Task file.
    pub task: String,
    /// Image size (per camera) and number of cameras.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Cameras rendered per iteration.
    pub cameras: usize,
    /// Optimized texels (all textures).
    pub texels: u32,
    /// Primal and gradient spp of an iteration (after the protocol).
    pub primal_spp: u32,
    /// Gradient spp of an iteration.
    pub gradient_spp: u32,
    /// Gradient spp the baseline gets in the time of one ReSTIR iteration (fractional: the
    /// errors at equal time are interpolated in 1/spp between the two whole spp around it).
    pub baseline_spp_equal_time: f64,
    /// Total gradient relMSE (each estimator with its own primal) of the baseline at equal
    /// time (mean over seeds).
    pub gradient_relmse_baseline: f64,
    /// Total gradient relMSE of ReSTIR after `warmup` iterations (mean over seeds).
    pub gradient_relmse_restir: f64,
    /// restir / baseline, total, equal time.
    pub gradient_relmse_ratio: f64,
    /// Total gradient relMSE of the baseline at the task's spp (equal iterations).
    pub gradient_relmse_baseline_equal_iterations: f64,
    /// restir / baseline, total, equal iterations.
    pub gradient_relmse_ratio_equal_iterations: f64,
    /// Estimator-only gradient relMSE (converged adjoint) of the baseline at the task's spp.
    pub gradient_relmse_estimator_only_baseline: f64,
    /// Estimator-only gradient relMSE of ReSTIR (its next iteration under the converged
    /// adjoint, from the same reservoirs).
    pub gradient_relmse_estimator_only_restir: f64,
    /// restir / baseline, estimator-only, equal iterations.
    pub gradient_relmse_estimator_only_ratio: f64,
    /// Estimator-only gradient relMSE of the baseline at equal time.
    pub gradient_relmse_estimator_only_baseline_equal_time: f64,
    /// restir / baseline, estimator-only, equal time.
    pub gradient_relmse_estimator_only_ratio_equal_time: f64,
    /// Mean wall-clock ms of a ReSTIR and a baseline iteration in the gradient phase (at the
    /// task's spp, GPU work finished), and their ratio.
    pub ms_per_iteration_ratio: f64,
    /// The primal estimator of the gradient and optimization phases.
    pub primal: String,
    /// relMSE of an independent primal render (the task's primal spp) against a converged
    /// render, at the state after `warmup` iterations (mean over seeds and cameras).
    pub primal_relmse_independent: f64,
    /// relMSE of the control-variate primal image at the same state.
    pub primal_relmse_control_variate: f64,
    /// control variate / independent.
    pub primal_relmse_ratio: f64,
    /// GPU ms of the primal passes per iteration: independent, control variate (render with
    /// both states plus the combination pass), when timestamps exist.
    pub primal_ms_independent: Option<f64>,
    /// See `primal_ms_independent`.
    pub primal_ms_control_variate: Option<f64>,
    /// The equal-time optimization (absent with `--gradient-only`).
    #[serde(flatten)]
    pub optimization: Option<OptimizationResult>,
}

/// The equal-time optimization of one scene.
#[derive(Clone, Debug, Serialize)]
pub struct OptimizationResult {
    /// Image relMSE at the initial textures.
    pub image_relmse_initial: f64,
    /// Image relMSE after the baseline's budget.
    pub image_relmse_baseline: f64,
    /// Image relMSE after ReSTIR's budget.
    pub image_relmse_restir: f64,
    /// restir / baseline.
    pub image_relmse_ratio: f64,
    /// Texture RMSE at the initial textures.
    pub texture_rmse_initial: f64,
    /// Texture RMSE after the baseline's budget.
    pub texture_rmse_baseline: f64,
    /// Texture RMSE after ReSTIR's budget.
    pub texture_rmse_restir: f64,
    /// Texture RMSE over the observed texels (those a camera sample reaches; the others
    /// keep their initial values) at the start.
    pub texture_rmse_observed_initial: f64,
    /// ... after the baseline's budget.
    pub texture_rmse_observed_baseline: f64,
    /// ... after ReSTIR's budget.
    pub texture_rmse_observed_restir: f64,
    /// ... of the baseline at a third of the budget.
    pub texture_rmse_observed_third_baseline: f64,
    /// ... of ReSTIR at a third of the budget.
    pub texture_rmse_observed_third_restir: f64,
    /// Fraction of the texels that are observed.
    pub observed_fraction: f64,
    /// The learning-rate schedule both estimators followed.
    pub schedule: String,
    /// Mean wall-clock milliseconds per baseline iteration (GPU work finished).
    pub ms_per_iteration_baseline: f64,
    /// Mean wall-clock milliseconds per ReSTIR iteration.
    pub ms_per_iteration_restir: f64,
    /// Iterations the baseline ran within the budget.
    pub iterations_baseline: u32,
    /// Iterations ReSTIR ran within the budget.
    pub iterations_restir: u32,
    /// Mean GPU time per pass of a baseline iteration (timestamp queries), when available.
    pub passes_baseline: Option<PassTimes>,
    /// Mean GPU time per pass of a ReSTIR iteration, when available.
    pub passes_restir: Option<PassTimes>,
    /// Bytes of GPU state per texel of the ReSTIR optimizer (textures, gradient, Adam,
    /// reservoirs, locks).
    pub state_bytes_per_texel: f64,
    /// The same for the baseline optimizer.
    pub state_bytes_per_texel_baseline: f64,
    /// Optimization curve of the baseline.
    pub curve_baseline: Vec<CurvePoint>,
    /// Optimization curve of ReSTIR.
    pub curve_restir: Vec<CurvePoint>,
}

/// The whole benchmark (`bench.json`).
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// psrestir version.
    pub version: String,
    /// The adapter, as `psrestir adapter` prints it.
    pub adapter: String,
    /// Seconds of optimization per estimator and scene.
    pub budget_s: f64,
    /// Size multiplier.
    pub scale: f64,
    /// ReSTIR iterations before the gradient error is measured.
    pub warmup: u32,
    /// Seeds the gradient error is averaged over.
    pub repeats: u32,
    /// Gradient spp of the reference gradient.
    pub reference_spp: u32,
    /// spp of the primal render of the converged adjoint.
    pub reference_primal_spp: u32,
    /// Sampling settings of the scenes.
    pub protocol: Protocol,
    /// ReSTIR's confidence convention for the fresh candidates.
    pub confidence: String,
    /// spp of the image-error renders.
    pub eval_spp: u32,
    /// ReSTIR's confidence cap.
    pub m_cap: f32,
    /// Per scene.
    pub scenes: Vec<SceneResult>,
}

/// What the gradient images show (one gradient of each estimator at one state).
pub struct GradientSnapshot {
    /// The reference gradient.
    pub reference: Vec<f32>,
    /// The baseline's gradient at the task's spp, under the converged adjoint.
    pub baseline: Vec<f32>,
    /// ReSTIR's gradient under the converged adjoint.
    pub restir: Vec<f32>,
    /// The baseline's spp.
    pub baseline_spp: u32,
}

/// Final renders of the first camera: target, baseline and ReSTIR.
pub struct FinalImages {
    /// The target.
    pub target: Image,
    /// Baseline after its budget.
    pub baseline: Image,
    /// ReSTIR after its budget.
    pub restir: Image,
}

/// Folder of the bundled scenes: `scenes/` in the working directory, else the one beside
/// the crate's sources.
pub fn scenes_root() -> PathBuf {
    let here = PathBuf::from("scenes");
    if here.join("bench").is_dir() {
        here
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes")
    }
}

/// The task file of a scene argument: a bundled benchmark scene's name, a task file, or a
/// folder holding `task.toml`.
pub fn resolve_scene(arg: &str) -> Result<PathBuf> {
    let p = PathBuf::from(arg);
    if p.is_file() {
        return Ok(p);
    }
    if p.join("task.toml").is_file() {
        return Ok(p.join("task.toml"));
    }
    let bundled = scenes_root().join("bench").join(arg).join("task.toml");
    if bundled.is_file() {
        return Ok(bundled);
    }
    Err(Error::Invalid(format!(
        "bench: `{arg}` is neither a benchmark scene ({}) nor a task file nor a folder with \
         task.toml",
        crate::assets::bench_scenes::BENCH_SCENES.join(", ")
    )))
}

/// `task` with image and texture sizes multiplied by `scale` (at least 8 pixels, 4 texels).
pub fn scaled(task: &Task, scale: f64) -> Task {
    let mut t = task.clone();
    let s = |v: u32, min: u32| ((v as f64 * scale).round() as u32).max(min);
    t.width = s(task.width, 8);
    t.height = s(task.height, 8);
    for tex in &mut t.textures {
        tex.resolution = [s(tex.resolution[0], 4), s(tex.resolution[1], 4)];
    }
    t
}

/// relMSE over entries with a non-zero reference: mean of (g - r)^2 / (r^2 + 1e-2).
pub fn gradient_relmse(g: &[f32], reference: &[f64]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (a, r) in g.iter().zip(reference) {
        if *r != 0.0 {
            s += (*a as f64 - r).powi(2) / (r * r + 1e-2);
            n += 1;
        }
    }
    s / n.max(1) as f64
}

pub use crate::optim::loss::image_relmse;

/// Progress reporting: a bar over the phases of all scenes.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    fn new(enabled: bool, phases: u64) -> Progress {
        let bar = enabled.then(|| {
            let b = indicatif::ProgressBar::new(phases);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "bench [{bar:30}] {pos}/{len} {msg} ({elapsed})",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            b
        });
        Progress { bar }
    }
    fn message(&self, m: String) {
        match &self.bar {
            Some(b) => b.set_message(m),
            None => log::info!("{m}"),
        }
    }
    fn done(&self) {
        if let Some(b) = &self.bar {
            b.inc(1);
        }
    }
    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

fn settings(prep: &Problem, task: &Task, method: Method, o: &BenchOptions) -> Settings {
    let mut s = task_settings(task, &prep.cameras, method, o.restir);
    if let Some(p) = o.primal {
        s.primal = p;
    }
    s
}

/// The primal estimators' image error and cost (issue: recursive control variates): per
/// seed, an optimizer with each primal mode runs `warmup` iterations, then one more estimate
/// with the textures held; its primal image is compared with a converged render of the same
/// textures.
struct PrimalPhase {
    relmse_independent: f64,
    relmse_control_variate: f64,
    ms_independent: Option<f64>,
    ms_control_variate: Option<f64>,
}

fn primal_phase(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    progress: &Progress,
) -> Result<PrimalPhase> {
    use crate::optim::PrimalMode;
    let repeats = o.repeats.max(1);
    let mut out = PrimalPhase {
        relmse_independent: 0.0,
        relmse_control_variate: 0.0,
        ms_independent: None,
        ms_control_variate: None,
    };
    let n = (repeats as usize * prep.targets.len()) as f64;
    for rep in 0..repeats {
        progress.message(format!("primal error, seed {}/{repeats}", rep + 1));
        let seed = task.seed.wrapping_add(2000 * (rep + 1));
        for mode in [PrimalMode::Independent, PrimalMode::ControlVariate] {
            let mut opt = Optimizer::for_problem(
                gpu,
                prep,
                Settings {
                    seed,
                    primal: mode,
                    ..settings(prep, task, Method::Baseline, o)
                },
            )?;
            let mut times = PassTimes::default();
            let mut timed = 0;
            for i in 0..o.warmup {
                opt.step()?;
                if i >= o.warmup / 2 {
                    if let Some(t) = opt.pass_times()? {
                        times.add(&t);
                        timed += 1;
                    }
                }
            }
            // One more estimate at fixed textures: its primal image is at `read_params`.
            opt.estimate_gradient(opt.iteration)?;
            let ms = (timed > 0).then(|| times.primal_ms / timed as f64);
            for k in 0..prep.targets.len() {
                let converged = opt.render(
                    k,
                    o.reference_primal_spp,
                    crate::optim::pass_seed(
                        seed,
                        u32::MAX - 5,
                        k as u32,
                        crate::optim::Seeds::EVAL,
                    ),
                )?;
                let img = match opt.control_variate_image(k)? {
                    Some(img) => img,
                    None => opt.render(
                        k,
                        task.optimizer.primal_spp,
                        crate::optim::pass_seed(
                            seed,
                            u32::MAX - 6,
                            k as u32,
                            crate::optim::Seeds::PRIMAL,
                        ),
                    )?,
                };
                let e = image_relmse(&img, &converged) / n;
                match mode {
                    PrimalMode::Independent => out.relmse_independent += e,
                    PrimalMode::ControlVariate => out.relmse_control_variate += e,
                }
            }
            match mode {
                PrimalMode::Independent => out.ms_independent = ms,
                PrimalMode::ControlVariate => out.ms_control_variate = ms,
            }
        }
    }
    progress.done();
    Ok(out)
}

/// Mean milliseconds of `n` steps after one untimed step.
fn time_steps(opt: &mut Optimizer, n: u32) -> Result<f64> {
    opt.step()?;
    let t0 = Instant::now();
    for _ in 0..n {
        opt.step()?;
    }
    Ok(1000.0 * t0.elapsed().as_secs_f64() / n.max(1) as f64)
}

/// Gradient error (phase 1): the scene's gradient fields and the gradients of the first seed
/// for the images.
struct GradientPhase {
    baseline_spp_equal_time: f64,
    total_baseline: f64,
    total_restir: f64,
    total_baseline_equal_iterations: f64,
    only_baseline: f64,
    only_restir: f64,
    only_baseline_equal_time: f64,
    ms_ratio: f64,
    snapshot: GradientSnapshot,
}

/// The baseline's error at `k` spp (fractional) from its errors at whole spp `s0` and
/// `s0 + 1` around it, linear in 1/spp (Monte Carlo variance falls as 1/spp).
fn interpolate_in_inverse_spp(k: f64, s0: u32, e0: f64, e1: f64) -> f64 {
    let s0 = s0 as f64;
    if k <= s0 {
        return e0;
    }
    let a = (1.0 / s0 - 1.0 / k) / (1.0 / s0 - 1.0 / (s0 + 1.0));
    e0 + a * (e1 - e0)
}

fn gradient_phase(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    progress: &Progress,
) -> Result<GradientPhase> {
    let spp = task.optimizer.gradient_spp.max(1);
    let new = |method: Method, gradient_spp: u32, seed: u32| -> Result<Optimizer> {
        Optimizer::for_problem(
            gpu,
            prep,
            Settings {
                gradient_spp,
                seed,
                ..settings(prep, task, method, o)
            },
        )
    };
    let repeats = o.repeats.max(1);
    let n = repeats as f64;
    let mut out = GradientPhase {
        baseline_spp_equal_time: spp as f64,
        total_baseline: 0.0,
        total_restir: 0.0,
        total_baseline_equal_iterations: 0.0,
        only_baseline: 0.0,
        only_restir: 0.0,
        only_baseline_equal_time: 0.0,
        ms_ratio: f64::NAN,
        snapshot: GradientSnapshot {
            reference: Vec::new(),
            baseline: Vec::new(),
            restir: Vec::new(),
            baseline_spp: spp,
        },
    };
    let mut eq_spp = None;
    for rep in 0..repeats {
        progress.message(format!("gradient error, seed {}/{repeats}", rep + 1));
        let seed = task.seed.wrapping_add(1000 * (rep + 1));
        // ReSTIR from the initial textures; the later warm-up steps time an iteration.
        let mut re = new(Method::Restir, spp, seed)?;
        let untimed = (o.warmup / 4).max(1).min(o.warmup);
        for _ in 0..untimed {
            re.step()?;
        }
        let t0 = Instant::now();
        for _ in untimed..o.warmup {
            re.step()?;
        }
        let timed = o.warmup - untimed;
        let ms_restir = if timed > 0 {
            Some(1000.0 * t0.elapsed().as_secs_f64() / timed as f64)
        } else {
            None
        };
        let state = re.read_params()?;
        let kept = re.state()?;

        // The baseline's cost per gradient spp, measured once: iterations at spp and 4 spp.
        let k = match eq_spp {
            Some(k) => k,
            None => {
                let ms_restir = match ms_restir {
                    Some(ms) => ms,
                    None => {
                        let mut r = new(Method::Restir, spp, seed)?;
                        time_steps(&mut r, 3)?
                    }
                };
                let mut b1 = new(Method::Baseline, spp, seed ^ 0x71)?;
                let t1 = time_steps(&mut b1, 3)?;
                drop(b1);
                let mut b4 = new(Method::Baseline, 4 * spp, seed ^ 0x72)?;
                let t4 = time_steps(&mut b4, 3)?;
                drop(b4);
                let per_spp = ((t4 - t1) / (3 * spp) as f64).max(1e-3);
                let k = (spp as f64 + (ms_restir - t1) / per_spp).clamp(1.0, 1024.0);
                log::info!(
                    "{}: ReSTIR {ms_restir:.1} ms/it, baseline {t1:.1} ms/it at {spp} spp \
                     (+{per_spp:.1} ms per spp): {k:.2} spp at equal time",
                    task.path.display()
                );
                out.ms_ratio = ms_restir / t1;
                eq_spp = Some(k);
                k
            }
        };
        let s0 = (k.floor() as u32).max(1);

        // The converged adjoint at the state, and the reference gradient under it.
        progress.message(format!(
            "gradient error, seed {}/{repeats}: reference",
            rep + 1
        ));
        let ref_spp = o.reference_spp.clamp(1, 64);
        let estimates = o.reference_spp.div_ceil(ref_spp).max(1);
        let mut r = new(Method::Baseline, ref_spp, seed ^ 0x5eed)?;
        r.write_params(&state)?;
        let (converged, _) = r.converged_adjoint(o.reference_primal_spp, seed ^ 0xad)?;
        let mut reference = vec![0f64; state.len()];
        for it in 0..estimates {
            let g = r.estimate_gradient_with_adjoint(it, &converged)?;
            for (acc, v) in reference.iter_mut().zip(&g) {
                *acc += *v as f64 / estimates as f64;
            }
        }
        drop(r);
        let relmse = |g: &[f32]| gradient_relmse(g, &reference);

        // ReSTIR's next gradient: with its own primal render, then again from the same
        // reservoirs under the converged adjoint.
        let it = re.iteration;
        let (g_restir_total, _) = re.estimate_gradient(it)?;
        re.restore(&kept)?;
        let g_restir_only = re.estimate_gradient_with_adjoint(it, &converged)?;
        drop(re);

        // The baseline at the task's spp and around the equal-time spp, both ways.
        let baseline = |spp: u32, salt: u32| -> Result<(Vec<f32>, Vec<f32>)> {
            let mut b = new(Method::Baseline, spp, seed ^ salt)?;
            b.write_params(&state)?;
            let (total, _) = b.estimate_gradient(0)?;
            let only = b.estimate_gradient_with_adjoint(1, &converged)?;
            Ok((total, only))
        };
        let (b_total, b_only) = baseline(spp, 0xea)?;
        let (b0_total, b0_only) = baseline(s0, 0xe9)?;
        let (b1_total, b1_only) = baseline(s0 + 1, 0xeb)?;

        out.total_restir += relmse(&g_restir_total) / n;
        out.only_restir += relmse(&g_restir_only) / n;
        out.total_baseline_equal_iterations += relmse(&b_total) / n;
        out.only_baseline += relmse(&b_only) / n;
        out.total_baseline +=
            interpolate_in_inverse_spp(k, s0, relmse(&b0_total), relmse(&b1_total)) / n;
        out.only_baseline_equal_time +=
            interpolate_in_inverse_spp(k, s0, relmse(&b0_only), relmse(&b1_only)) / n;
        out.baseline_spp_equal_time = k;
        if rep == 0 {
            out.snapshot = GradientSnapshot {
                reference: reference.iter().map(|&v| v as f32).collect(),
                baseline: b_only,
                restir: g_restir_only,
                baseline_spp: spp,
            };
        }
        progress.done();
    }
    Ok(out)
}

/// Image relMSE of the current textures, mean over the task's cameras, and the render of
/// the first camera (the same seed every time: differences are the textures', not the
/// noise's).
fn evaluate(opt: &Optimizer, prep: &Problem, task: &Task, spp: u32) -> Result<(f64, Image)> {
    let (e, mut images) = crate::optim::run::evaluate(opt, &prep.targets, spp, task.seed)?;
    if images.is_empty() {
        return Err(Error::Invalid("the task has no camera".into()));
    }
    Ok((e, images.swap_remove(0)))
}

/// One estimator's equal-time optimization (phase 2).
struct OptimizationRun {
    curve: Vec<CurvePoint>,
    iterations: u32,
    ms_per_iteration: f64,
    passes: Option<PassTimes>,
    state_bytes_per_texel: f64,
    final_image: Image,
}

fn optimization_phase(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    method: Method,
    progress: &Progress,
) -> Result<OptimizationRun> {
    let mut opt = Optimizer::for_problem(gpu, prep, settings(prep, task, method, o))?;
    let truth = prep.reference.as_deref();
    let texture_rmse = |v: &[f32]| truth.map(|r| rmse(v, r)).unwrap_or(f64::NAN);
    let observed = opt.observed_texels()?.to_vec();
    let texture_rmse_observed = |v: &[f32]| {
        truth
            .map(|r| rmse_observed(&prep.set, v, r, &observed))
            .unwrap_or(f64::NAN)
    };
    let points = o.curve_points.max(2);
    let mut next_eval = 1u32;
    let mut curve = Vec::new();
    let mut seconds = 0.0;
    let mut passes: Option<(PassTimes, u32)> = None;
    let mut last_image = None;
    let name = match method {
        Method::Baseline => "baseline",
        Method::Restir => "ReSTIR",
    };
    loop {
        let eval_due = seconds >= o.budget_s * next_eval as f64 / (points - 1) as f64;
        if seconds >= o.budget_s || eval_due {
            let (e, img) = evaluate(&opt, prep, task, o.eval_spp)?;
            last_image = Some(img);
            if let Some(p) = curve.last_mut() {
                let p: &mut CurvePoint = p;
                p.image_relmse = Some(e);
            }
            next_eval += 1;
            progress.message(format!(
                "{name}: {seconds:.0}/{:.0} s, image relMSE {e:.3e}",
                o.budget_s
            ));
        }
        if seconds >= o.budget_s {
            break;
        }
        // Both estimators follow the task's schedule over the same budget.
        opt.set_progress(seconds / o.budget_s);
        let t0 = Instant::now();
        let stats = opt.step()?;
        seconds += t0.elapsed().as_secs_f64();
        if opt.iteration % 8 == 2 {
            if let Some(t) = opt.pass_times()? {
                let (s, n) = passes.get_or_insert((PassTimes::default(), 0));
                s.add(&t);
                *n += 1;
            }
        }
        let values = opt.read_params()?;
        let factor = match (opt.last_learning_rates().first(), prep.set.textures.first()) {
            (Some(&l), Some(t)) if t.learning_rate > 0.0 => Some(l as f64 / t.learning_rate as f64),
            _ => None,
        };
        curve.push(CurvePoint {
            iteration: opt.iteration,
            seconds,
            loss: stats.loss,
            texture_rmse: texture_rmse(&values),
            texture_rmse_observed: texture_rmse_observed(&values),
            learning_rate_factor: factor,
            image_relmse: None,
        });
    }
    // The loop ends with an evaluation at the end of the budget.
    let final_image = match last_image {
        Some(img) => img,
        None => evaluate(&opt, prep, task, o.eval_spp)?.1,
    };
    let iterations = opt.iteration;
    progress.done();
    Ok(OptimizationRun {
        ms_per_iteration: 1000.0 * seconds / iterations.max(1) as f64,
        iterations,
        passes: passes.map(|(s, n)| s.divided(n as f64)),
        state_bytes_per_texel: opt.state_bytes_per_texel(),
        curve,
        final_image,
    })
}

/// Run the benchmark on the given task files and write the report into `o.out`.
pub fn bench(gpu: &Gpu, tasks: &[PathBuf], o: &BenchOptions) -> Result<BenchReport> {
    if !(o.budget_s > 0.0 && o.budget_s.is_finite()) {
        return Err(Error::Invalid(format!(
            "bench: the budget must be a positive number of seconds, not {}",
            o.budget_s
        )));
    }
    if !(o.scale > 0.0 && o.scale <= 64.0) {
        return Err(Error::Invalid(format!(
            "bench: --scale must be in (0, 64], not {}",
            o.scale
        )));
    }
    if o.eval_spp == 0
        || o.reference_spp == 0
        || o.reference_primal_spp == 0
        || o.eval_spp > 1 << 16
    {
        return Err(Error::Invalid(format!(
            "bench: --eval-spp ({}), --reference-spp ({}) and --reference-primal-spp ({}) must be \
             at least 1 (eval at most 65536)",
            o.eval_spp, o.reference_spp, o.reference_primal_spp
        )));
    }
    // Load every task first, so that a bad one fails before hours of measuring.
    let mut loaded = Vec::new();
    for p in tasks {
        loaded.push(o.protocol.apply(&scaled(&Task::load(p)?, o.scale)));
    }
    std::fs::create_dir_all(&o.out).map_err(|e| Error::file(&o.out, e.to_string()))?;
    let per_scene = o.repeats.max(1) as u64 + if o.gradient_only { 2 } else { 4 };
    let progress = Progress::new(o.progress, loaded.len() as u64 * per_scene);
    let mut report = BenchReport {
        version: env!("CARGO_PKG_VERSION").into(),
        adapter: gpu.describe(),
        budget_s: o.budget_s,
        scale: o.scale,
        warmup: o.warmup,
        repeats: o.repeats.max(1),
        reference_spp: o.reference_spp,
        reference_primal_spp: o.reference_primal_spp,
        protocol: o.protocol,
        confidence: o.restir.confidence.name().into(),
        eval_spp: o.eval_spp,
        m_cap: o.restir.m_cap,
        scenes: Vec::new(),
    };
    for task in &loaded {
        let name = scene_name(task);
        let dir = o.out.join(crate::image_io::file_safe(&name));
        std::fs::create_dir_all(&dir).map_err(|e| Error::file(&dir, e.to_string()))?;
        if let Some(b) = &progress.bar {
            b.set_prefix(name.clone());
        }
        progress.message(format!("{name}: rendering targets"));
        let prep = Problem::from_task(gpu, task, &dir, false)?;
        progress.done();
        let pp = primal_phase(gpu, task, &prep, o, &progress)?;
        let g = gradient_phase(gpu, task, &prep, o, &progress)?;
        let (optimization, finals) = if o.gradient_only {
            (None, None)
        } else {
            let (r, f) = optimization_phases(gpu, task, &prep, o, &progress)?;
            (Some(r), Some(f))
        };
        let result = SceneResult {
            name: name.clone(),
            task: task.path.display().to_string(),
            width: task.width,
            height: task.height,
            cameras: prep.cameras.len(),
            texels: prep.set.textures.iter().map(|t| t.width * t.height).sum(),
            primal_spp: task.optimizer.primal_spp,
            gradient_spp: task.optimizer.gradient_spp,
            baseline_spp_equal_time: g.baseline_spp_equal_time,
            gradient_relmse_baseline: g.total_baseline,
            gradient_relmse_restir: g.total_restir,
            gradient_relmse_ratio: g.total_restir / g.total_baseline,
            gradient_relmse_baseline_equal_iterations: g.total_baseline_equal_iterations,
            gradient_relmse_ratio_equal_iterations: g.total_restir
                / g.total_baseline_equal_iterations,
            gradient_relmse_estimator_only_baseline: g.only_baseline,
            gradient_relmse_estimator_only_restir: g.only_restir,
            gradient_relmse_estimator_only_ratio: g.only_restir / g.only_baseline,
            gradient_relmse_estimator_only_baseline_equal_time: g.only_baseline_equal_time,
            gradient_relmse_estimator_only_ratio_equal_time: g.only_restir
                / g.only_baseline_equal_time,
            ms_per_iteration_ratio: g.ms_ratio,
            primal: settings(&prep, task, Method::Restir, o)
                .primal
                .name()
                .into(),
            primal_relmse_independent: pp.relmse_independent,
            primal_relmse_control_variate: pp.relmse_control_variate,
            primal_relmse_ratio: pp.relmse_control_variate / pp.relmse_independent,
            primal_ms_independent: pp.ms_independent,
            primal_ms_control_variate: pp.ms_control_variate,
            optimization,
        };
        report::write_scene_files(&dir, &prep, &result, &g.snapshot, finals.as_ref())?;
        report.scenes.push(result);
        // Written after every scene, so that an interrupted run keeps what it measured.
        report::write_report(&o.out, &report)?;
    }
    progress.finish();
    Ok(report)
}

/// The equal-time optimization of both estimators (phase 2) and the cost (phase 3).
fn optimization_phases(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    progress: &Progress,
) -> Result<(OptimizationResult, FinalImages)> {
    let init = Optimizer::for_problem(gpu, prep, settings(prep, task, Method::Baseline, o))?;
    let (image_initial, _) = evaluate(&init, prep, task, o.eval_spp)?;
    let texture_initial = prep
        .reference
        .as_deref()
        .map(|r| rmse(&prep.set.values, r))
        .unwrap_or(f64::NAN);
    let observed = init.observed_texels()?.to_vec();
    let texture_observed_initial = prep
        .reference
        .as_deref()
        .map(|r| rmse_observed(&prep.set, &prep.set.values, r, &observed))
        .unwrap_or(f64::NAN);
    drop(init);
    let start = CurvePoint {
        iteration: 0,
        seconds: 0.0,
        loss: f64::NAN,
        texture_rmse: texture_initial,
        texture_rmse_observed: texture_observed_initial,
        learning_rate_factor: None,
        image_relmse: Some(image_initial),
    };
    let base = optimization_phase(gpu, task, prep, o, Method::Baseline, progress)?;
    let re = optimization_phase(gpu, task, prep, o, Method::Restir, progress)?;
    let last = |r: &OptimizationRun| -> (f64, f64, f64) {
        let t = r
            .curve
            .last()
            .map(|p| (p.texture_rmse, p.texture_rmse_observed))
            .unwrap_or((texture_initial, texture_observed_initial));
        let i = r
            .curve
            .iter()
            .rev()
            .find_map(|p| p.image_relmse)
            .unwrap_or(image_initial);
        (t.0, t.1, i)
    };
    // The observed-texel RMSE at a third of the budget (the last point before it).
    let third = |r: &OptimizationRun| -> f64 {
        r.curve
            .iter()
            .take_while(|p| p.seconds <= o.budget_s / 3.0)
            .last()
            .map(|p| p.texture_rmse_observed)
            .unwrap_or(texture_observed_initial)
    };
    let (tb, tob, ib) = last(&base);
    let (tr, tor, ir) = last(&re);
    let with_start = |c: &[CurvePoint]| {
        let mut v = vec![start.clone()];
        v.extend_from_slice(c);
        v
    };
    let result = OptimizationResult {
        image_relmse_initial: image_initial,
        image_relmse_baseline: ib,
        image_relmse_restir: ir,
        image_relmse_ratio: ir / ib,
        texture_rmse_initial: texture_initial,
        texture_rmse_baseline: tb,
        texture_rmse_restir: tr,
        texture_rmse_observed_initial: texture_observed_initial,
        texture_rmse_observed_baseline: tob,
        texture_rmse_observed_restir: tor,
        texture_rmse_observed_third_baseline: third(&base),
        texture_rmse_observed_third_restir: third(&re),
        observed_fraction: observed.iter().filter(|&&b| b).count() as f64
            / observed.len().max(1) as f64,
        schedule: task.optimizer.schedule.describe(),
        ms_per_iteration_baseline: base.ms_per_iteration,
        ms_per_iteration_restir: re.ms_per_iteration,
        iterations_baseline: base.iterations,
        iterations_restir: re.iterations,
        passes_baseline: base.passes,
        passes_restir: re.passes,
        state_bytes_per_texel: re.state_bytes_per_texel,
        state_bytes_per_texel_baseline: base.state_bytes_per_texel,
        curve_baseline: with_start(&base.curve),
        curve_restir: with_start(&re.curve),
    };
    let finals = FinalImages {
        target: prep.targets[0].clone(),
        baseline: base.final_image,
        restir: re.final_image,
    };
    Ok((result, finals))
}

/// The scene's name: its folder's name (the bundled scenes' folders are their names).
fn scene_name(task: &Task) -> String {
    task.base
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .filter(|n| !n.is_empty())
        .unwrap_or_else(|| task.path.display().to_string())
}
