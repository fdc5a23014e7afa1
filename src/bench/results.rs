//! What `psrestir bench` measures, per scene and in all (`bench.json` is their serde form).
use super::Protocol;
use crate::image_io::Image;
use crate::optim::PassTimes;
use serde::{Deserialize, Serialize};

/// A number that `bench.json` may hold as null (serde_json writes NaN so): NaN.
fn f64_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// One point of an optimization curve.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Iterations done.
    pub iteration: u32,
    /// Seconds of optimization (step time).
    #[serde(deserialize_with = "f64_or_nan")]
    pub seconds: f64,
    /// Loss of the iteration's primal render (NaN at the start, written as null).
    #[serde(deserialize_with = "f64_or_nan")]
    pub loss: f64,
    /// Texture RMSE against the ground truth.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse: f64,
    /// Texture RMSE over the observed texels.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_observed: f64,
    /// The learning-rate schedule's factor in this iteration.
    pub learning_rate_factor: Option<f64>,
    /// Image error at evaluation points only ([`BenchReport::image_error`] says which).
    pub image_relmse: Option<f64>,
}

/// The measurements of one scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneResult {
    /// Scene name (`vase`, or `vase, seed 2` with `--seeds`).
    pub name: String,
    /// The seed its targets and runs took (the task's own, or its k-th with `--seeds`).
    #[serde(default)]
    pub seed: u32,
    /// Seconds of optimization per run (the bench's budget, or the task's own).
    #[serde(default)]
    #[serde(deserialize_with = "f64_or_nan")]
    pub budget_s: f64,
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
    /// The estimator whose gradient error is measured against the baseline's
    /// ([`super::BenchOptions::gradient_method`]); "the estimator" below.
    pub gradient_method: String,
    /// Gradient spp the baseline gets in the time of one iteration of the estimator
    /// (fractional: the errors at equal time are interpolated in 1/spp between the two whole
    /// spp around it).
    #[serde(deserialize_with = "f64_or_nan")]
    pub baseline_spp_equal_time: f64,
    /// Total gradient relMSE (under the adjoint of the estimator's task-spp primal render of
    /// the same iteration) of the baseline at equal time (mean over seeds).
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_baseline: f64,
    /// Total gradient relMSE of the estimator after `warmup` iterations (mean over seeds).
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_estimator: f64,
    /// estimator / baseline, total, equal time.
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_ratio: f64,
    /// Total gradient relMSE of the baseline at the task's spp (equal iterations).
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_baseline_equal_iterations: f64,
    /// estimator / baseline, total, equal iterations.
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_ratio_equal_iterations: f64,
    /// Estimator-only gradient relMSE (converged adjoint) of the baseline at the task's spp.
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_estimator_only_baseline: f64,
    /// Estimator-only gradient relMSE of the estimator (its next iteration under the
    /// converged adjoint, from the same state).
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_estimator_only_estimator: f64,
    /// estimator / baseline, estimator-only, equal iterations.
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_estimator_only_ratio: f64,
    /// Estimator-only gradient relMSE of the baseline at equal time.
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_estimator_only_baseline_equal_time: f64,
    /// estimator / baseline, estimator-only, equal time.
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_estimator_only_ratio_equal_time: f64,
    /// Estimator-only gradient relMSE of the mean of `successive_estimates` independent
    /// baseline estimates (the task's spp).
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_mean_baseline: f64,
    /// Estimator-only gradient relMSE of the mean of the estimator's next
    /// `successive_estimates` estimates (successive iterations: they may share samples).
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_mean_estimator: f64,
    /// estimator / baseline of the means: what survives of the single-estimate ratio when an
    /// optimizer adds up successive steps.
    #[serde(deserialize_with = "f64_or_nan")]
    pub gradient_relmse_mean_ratio: f64,
    /// How many estimates those means average.
    pub successive_estimates: u32,
    /// Per optimized texture, its parts of the equal-iteration gradient errors above (each
    /// texture's terms over the count of all entries, so that the parts add up to the
    /// scene's figures): which texture the error is in.
    pub gradient_relmse_per_texture: Vec<TextureGradientErrors>,
    /// Mean wall-clock ms of an iteration of the estimator over one of the baseline in the
    /// gradient phase (at the task's spp, GPU work finished).
    #[serde(deserialize_with = "f64_or_nan")]
    pub ms_per_iteration_ratio: f64,
    /// The primal estimator of the gradient and optimization phases.
    pub primal: String,
    /// relMSE of an independent primal render (the task's primal spp) against a converged
    /// render, at the state after `warmup` iterations (mean over seeds and cameras).
    #[serde(deserialize_with = "f64_or_nan")]
    pub primal_relmse_independent: f64,
    /// relMSE of the control-variate primal image at the same state.
    #[serde(deserialize_with = "f64_or_nan")]
    pub primal_relmse_control_variate: f64,
    /// control variate / independent.
    #[serde(deserialize_with = "f64_or_nan")]
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

/// One optimized texture's parts of a scene's gradient errors at equal iterations (mean over
/// seeds).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TextureGradientErrors {
    /// `material_slot`.
    pub texture: String,
    /// Part of `gradient_relmse_estimator_only_baseline`.
    #[serde(deserialize_with = "f64_or_nan")]
    pub estimator_only_baseline: f64,
    /// Part of `gradient_relmse_estimator_only_estimator`.
    #[serde(deserialize_with = "f64_or_nan")]
    pub estimator_only_estimator: f64,
    /// estimator / baseline of the two parts.
    #[serde(deserialize_with = "f64_or_nan")]
    pub estimator_only_ratio: f64,
    /// Part of `gradient_relmse_baseline_equal_iterations`.
    #[serde(deserialize_with = "f64_or_nan")]
    pub total_baseline_equal_iterations: f64,
    /// Part of `gradient_relmse_estimator`.
    #[serde(deserialize_with = "f64_or_nan")]
    pub total_estimator: f64,
    /// estimator / baseline of the two parts.
    #[serde(deserialize_with = "f64_or_nan")]
    pub total_ratio_equal_iterations: f64,
}

/// The equal-time optimization of one scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct OptimizationResult {
    /// Image error at the initial textures ([`BenchReport::image_error`] says which).
    #[serde(deserialize_with = "f64_or_nan")]
    pub image_relmse_initial: f64,
    /// Texture RMSE at the initial textures.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_initial: f64,
    /// Texture RMSE over the observed texels (those a camera sample reaches; the others
    /// keep their initial values) at the start.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_observed_initial: f64,
    /// Fraction of the texels that are observed.
    #[serde(deserialize_with = "f64_or_nan")]
    pub observed_fraction: f64,
    /// Texels that the cameras observe.
    pub observed_texels: u64,
    /// The learning-rate schedule every run followed.
    pub schedule: String,
    /// The optimized textures (`material_slot`), in task order.
    pub textures: Vec<String>,
    /// Per texture, its observed-texel RMSE at the start.
    pub texture_rmse_observed_initial_per_texture: Vec<f64>,
    /// Every run, in order: the baseline with Adam first (the reference of every ratio),
    /// then [`super::BenchOptions::contenders`].
    pub runs: Vec<RunResult>,
    /// What `method = "auto"` picks for this scene's sampling, and how the run of its pick
    /// compares with the better of the fixed methods it picks between.
    pub auto: AutoResult,
    /// A peer's forward check, per camera (`--peers`): its targets' mean over psrestir's.
    #[serde(default)]
    pub peer_forward: Vec<PeerForward>,
}

/// One camera's forward check of a peer renderer: the mean of its target (the ground truth
/// rendered at the task's target spp) over the mean of psrestir's.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PeerForward {
    /// The peer (`mitsuba`).
    pub peer: String,
    /// The camera.
    pub camera: String,
    /// Its target's mean over psrestir's (all pixels and channels).
    #[serde(deserialize_with = "f64_or_nan")]
    pub mean_ratio: f64,
    /// Image relMSE of its target against psrestir's (both renderers' noise and their
    /// models' differences).
    #[serde(deserialize_with = "f64_or_nan")]
    pub relmse: f64,
}

/// `method = "auto"` on one scene: its pick among the baseline and ReSTIR (both with Adam,
/// unfiltered), and its run's errors over the lower of the two runs' (1: it picked the
/// better one; 1.05: it ends 5% above it). The ratios are absent unless both ran.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AutoResult {
    /// The estimator it picks.
    pub method: String,
    /// Why.
    pub reason: String,
    /// Gradient samples per optimized texel per iteration (what the rule reads first).
    #[serde(deserialize_with = "f64_or_nan")]
    pub samples_per_texel: f64,
    /// Optimized texels.
    pub texels: u64,
    /// Observed-texel RMSE of its pick's run over the lower of the two.
    pub texture_rmse_observed_over_best: Option<f64>,
    /// Image relMSE of its pick's run over the lower of the two.
    pub image_relmse_over_best: Option<f64>,
    /// The default configuration's run against the others, when it ran.
    pub default_run: Option<DefaultResult>,
}

/// The default configuration (the contender `default`: every choice `auto`'s) on one scene,
/// against its start and, in each error, the run of the others that ended lowest in it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DefaultResult {
    /// Its run's name (what `auto` chose).
    pub name: String,
    /// Its observed-texel RMSE at the end.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_observed: f64,
    /// That over the start's.
    #[serde(deserialize_with = "f64_or_nan")]
    pub over_start: f64,
    /// The run of the others that ended with the lowest observed-texel RMSE.
    pub best: String,
    /// Its observed-texel RMSE over that run's.
    #[serde(deserialize_with = "f64_or_nan")]
    pub over_best: f64,
    /// The run of the others that ended with the lowest image relMSE.
    pub best_image: String,
    /// Its image relMSE over that run's.
    #[serde(deserialize_with = "f64_or_nan")]
    pub image_over_best: f64,
}

impl OptimizationResult {
    /// The reference run: the baseline with Adam.
    pub fn baseline(&self) -> &RunResult {
        &self.runs[0]
    }
}

/// The equal-time optimization of one estimator with its step.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunResult {
    /// The estimator and step, e.g. `recursive, variance-scaled step`.
    pub name: String,
    /// Its key in file names (`recursive_variance`).
    pub key: String,
    /// The gradient estimator's name.
    pub method: String,
    /// Image error after its budget ([`BenchReport::image_error`] says which).
    #[serde(deserialize_with = "f64_or_nan")]
    pub image_relmse: f64,
    /// Over the baseline's (with Adam).
    #[serde(deserialize_with = "f64_or_nan")]
    pub image_relmse_ratio: f64,
    /// Texture RMSE after its budget.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse: f64,
    /// Texture RMSE over the observed texels after its budget.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_observed: f64,
    /// Over the baseline's (with Adam).
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_observed_ratio: f64,
    /// ... at a third of the budget.
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_observed_third: f64,
    /// Lowest observed-texel RMSE of the run (a run that ends well above it drifted).
    #[serde(deserialize_with = "f64_or_nan")]
    pub texture_rmse_observed_min: f64,
    /// Per texture (as [`OptimizationResult::textures`]), its observed-texel RMSE at the end.
    pub texture_rmse_observed_per_texture: Vec<f64>,
    /// The iteration whose state the errors above are of, where the run handed back an
    /// earlier state than its last, as a run of the task does (`optimizer.keep_best`: the
    /// lowest evaluation's relMSE of the render's expectation, the start's included); None:
    /// the last state. The curve, `_third` and `_min` follow the run itself.
    #[serde(default)]
    pub kept_iteration: Option<u32>,
    /// Where an earlier state was handed back: the last state's observed-texel RMSE and
    /// image relMSE.
    #[serde(default)]
    pub last_state_errors: Option<[f64; 2]>,
    /// Mean wall-clock milliseconds per iteration (GPU work finished).
    #[serde(deserialize_with = "f64_or_nan")]
    pub ms_per_iteration: f64,
    /// Iterations run within the budget.
    pub iterations: u32,
    /// Mean GPU time per pass, when available.
    pub passes: Option<PassTimes>,
    /// The estimator's counters ([`crate::optim::estimator::Diagnostics`]) per iteration,
    /// from the second sampled iteration to the last (e.g. ReSTIR's `evaluations`: the kept
    /// paths its merge evaluated).
    pub diagnostics_per_iteration: Vec<(String, f64)>,
    /// Bytes of GPU state per texel (textures, gradient, the step's state, and the
    /// estimator's).
    #[serde(deserialize_with = "f64_or_nan")]
    pub state_bytes_per_texel: f64,
    /// Its settings in this run (tuned by `--tune`, else the task's).
    pub settings: String,
    /// The search that chose them (`--tune`).
    pub tuned: Option<super::tune::Tuned>,
    /// Relit image relMSE under the task's `relight` environments after a per-channel scale
    /// alignment (mean over them; None without them).
    pub relit_relmse: Option<f64>,
    /// Over the baseline's (with Adam).
    pub relit_relmse_ratio: Option<f64>,
    /// PSNR (dB) of the same comparison, both clamped to [0, 1].
    pub relit_psnr: Option<f64>,
    /// With the environment recovered: its strongest emission's angle (degrees) from the
    /// truth's.
    pub light_direction_error_deg: Option<f64>,
    /// Its optimization curve.
    pub curve: Vec<CurvePoint>,
}

impl RunResult {
    /// When the curve first reaches `target` observed-texel RMSE (seconds, linear between
    /// points), if it does.
    pub fn time_to(&self, target: f64) -> Option<f64> {
        let mut prev: Option<(f64, f64)> = None;
        for p in &self.curve {
            let (t, e) = (p.seconds, p.texture_rmse_observed);
            if !e.is_finite() {
                continue;
            }
            if e <= target {
                return Some(match prev {
                    Some((t0, e0)) if e0 > e => t0 + (t - t0) * (e0 - target) / (e0 - e),
                    _ => t,
                });
            }
            prev = Some((t, e));
        }
        None
    }
}

fn one() -> u32 {
    1
}

/// What a bench's image errors measure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ImageError {
    /// The relMSE of one `eval_spp` render against the target: the render's own noise
    /// included (on the default task most of it), which pulls every ratio towards 1 (what the
    /// bench measured before it measured [`ImageError::Expectation`]).
    #[default]
    Render,
    /// The relMSE of the render's expectation against the target, from two independent
    /// halves of `eval_spp` samples (`crate::job::run::Evaluation::expected`).
    Expectation,
}

impl ImageError {
    /// How reports name it, with the evaluation's spp.
    pub fn describe(self, eval_spp: u32) -> String {
        match self {
            ImageError::Render => format!("image relMSE of {eval_spp}-spp renders"),
            ImageError::Expectation => format!(
                "image relMSE of the render's expectation (from two independent halves of \
                 {eval_spp}-spp renders, without the render's own noise)"
            ),
        }
    }
}

/// The whole benchmark (`bench.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BenchReport {
    /// psrestir version.
    pub version: String,
    /// The adapter, as `psrestir adapter` prints it.
    pub adapter: String,
    /// Seconds of optimization per estimator and scene (where `task_budgets`, those of a
    /// task that names none: each scene's is its `budget_s`).
    #[serde(deserialize_with = "f64_or_nan")]
    pub budget_s: f64,
    /// Each task ran for its own `time_budget_s`.
    #[serde(default)]
    pub task_budgets: bool,
    /// Size multiplier.
    #[serde(deserialize_with = "f64_or_nan")]
    pub scale: f64,
    /// The estimator whose gradient error is measured against the baseline's.
    pub gradient_method: String,
    /// Iterations of that estimator before the gradient error is measured.
    pub warmup: u32,
    /// Its estimates under the converged adjoint before the estimator-only error.
    pub settle: u32,
    /// Seeds the gradient error is averaged over.
    pub repeats: u32,
    /// Seeds of the equal-time phase per scene (`--seeds`).
    #[serde(default = "one")]
    pub seeds: u32,
    /// Each scene over its seeds, with `--seeds` above 1.
    #[serde(default)]
    pub over_seeds: Vec<SeededScene>,
    /// Gradient spp of the reference gradient.
    pub reference_spp: u32,
    /// spp of the primal render of the converged adjoint.
    pub reference_primal_spp: u32,
    /// Sampling settings of the scenes.
    pub protocol: Protocol,
    /// spp of the image-error renders.
    pub eval_spp: u32,
    /// What the image errors measure (`render` in a `bench.json` of an older psrestir).
    #[serde(default)]
    pub image_error: ImageError,
    /// The estimators' options given over the tasks' (`--estimator-option`).
    pub estimator_options: crate::optim::EstimatorOptions,
    /// The tasks' priors (multiscale gradient, smoothness) were switched off (`--no-priors`).
    pub no_priors: bool,
    /// Each estimator ran at settings chosen by `--tune`.
    pub tuned: bool,
    /// Per scene.
    pub scenes: Vec<SceneResult>,
    /// Each pass's pipeline the first time this run created it: seconds of creation and
    /// compilation (or a load from the driver's shader cache), outside every clock.
    pub pipelines: Vec<crate::gpu::PipelineTime>,
    /// The command that ran it (`psrestir bench ...`), and the checkout's state it measured
    /// (`commit <hash>`, with whether `src/` or `shaders/` differed): what the docs written
    /// from it name (absent in a `bench.json` of an older psrestir).
    #[serde(default)]
    pub command: Option<String>,
    /// See `command`.
    #[serde(default)]
    pub source: Option<String>,
}

impl BenchReport {
    /// A report of no scene (for the tests of its tables' columns).
    #[cfg(test)]
    pub(crate) fn empty() -> BenchReport {
        BenchReport {
            version: String::new(),
            adapter: String::new(),
            budget_s: 0.0,
            task_budgets: false,
            scale: 1.0,
            gradient_method: String::new(),
            warmup: 0,
            settle: 0,
            repeats: 0,
            seeds: 1,
            over_seeds: Vec::new(),
            reference_spp: 0,
            reference_primal_spp: 0,
            protocol: Protocol::Default,
            eval_spp: 0,
            image_error: ImageError::Expectation,
            estimator_options: Default::default(),
            no_priors: false,
            tuned: false,
            scenes: Vec::new(),
            pipelines: Vec::new(),
            command: None,
            source: None,
        }
    }
}

/// What the gradient images show (one gradient of each estimator at one state).
pub struct GradientSnapshot {
    /// The reference gradient.
    pub reference: Vec<f32>,
    /// The baseline's gradient at the task's spp, under the converged adjoint.
    pub baseline: Vec<f32>,
    /// The estimator's gradient under the converged adjoint.
    pub estimator: Vec<f32>,
    /// The estimator's name.
    pub estimator_name: String,
    /// The baseline's spp.
    pub baseline_spp: u32,
}

/// Final renders of the first camera: the target and each run's.
pub struct FinalImages {
    /// The target.
    pub target: Image,
    /// Each run's after its budget, as (name, image), in the order of the runs.
    pub runs: Vec<(String, Image)>,
}

/// A geometric mean of per-seed ratios with its 90% interval (`bench --seeds`; see
/// [`super::seeds`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    /// The geometric mean.
    #[serde(deserialize_with = "f64_or_nan")]
    pub mean: f64,
    /// The interval's lower end (equal to `mean` with one seed).
    #[serde(deserialize_with = "f64_or_nan")]
    pub low: f64,
    /// Its upper end.
    #[serde(deserialize_with = "f64_or_nan")]
    pub high: f64,
    /// Seeds it is over.
    pub n: u32,
}

/// One contender over the seeds of a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeededRun {
    /// Its name in the runs' tables.
    pub name: String,
    /// Its key.
    pub key: String,
    /// Observed-texel RMSE at the end over the baseline's (with Adam).
    pub texture: Option<Interval>,
    /// Image relMSE at the end over the baseline's.
    pub image: Option<Interval>,
    /// How much sooner it reaches the baseline's final observed-texel RMSE: the baseline's
    /// budget over the time at which this run's curve first gets there (linear between the
    /// curve's points); over the seeds where it does.
    pub sooner: Option<Interval>,
    /// Seeds in which it reaches the baseline's final error at all.
    pub reached: u32,
}

/// A scene over its seeds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeededScene {
    /// The scene's name.
    pub name: String,
    /// Seeds run.
    pub seeds: u32,
    /// Every contender but the baseline with Adam (the reference of the ratios).
    pub runs: Vec<SeededRun>,
    /// The default configuration's key, when it ran.
    pub default_key: Option<String>,
    /// The contender other than the default with the lowest geometric-mean texture error.
    pub best: Option<String>,
    /// The default's observed-texel RMSE over that contender's, paired per seed.
    pub default_over_best_texture: Option<Interval>,
    /// The default's image relMSE over that contender's, paired per seed.
    pub default_over_best_image: Option<Interval>,
    /// The default against Mitsuba 3's best row, where it raced (`--peers mitsuba`).
    #[serde(default)]
    pub mitsuba: Option<PeerOverSeeds>,
}

/// The default configuration against a peer's best row (the one with the lowest
/// geometric-mean texture error over the seeds), paired per seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PeerOverSeeds {
    /// The peer's row.
    pub best: String,
    /// The default's observed-texel RMSE over that row's.
    pub texture: Option<Interval>,
    /// The default's image relMSE (against psrestir's targets) over that row's (against its
    /// own targets).
    pub image: Option<Interval>,
    /// How much sooner the default reaches that row's final observed-texel RMSE: the budget
    /// over the time its curve first gets there, over the seeds where it does.
    pub sooner: Option<Interval>,
    /// Seeds in which the default reaches it at all.
    pub reached: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `bench.json` written before the bench measured the render's expectation has no
    /// `image_error`: it reads as the render's relMSE, and its report says so.
    #[test]
    fn an_older_bench_json_reads_as_the_renders_relmse() {
        let mut r = BenchReport::empty();
        r.eval_spp = 64;
        let mut v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["image_error"], "expectation");
        v.as_object_mut().unwrap().remove("image_error");
        let old: BenchReport = serde_json::from_value(v).unwrap();
        assert_eq!(old.image_error, ImageError::Render);
        let md = super::super::report::report_markdown(&old);
        assert!(md.contains("image relMSE of 64-spp renders"), "{md}");
    }
}
