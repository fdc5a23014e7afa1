//! What `psrestir bench` measures, per scene and in all (`bench.json` is their serde form).
use super::Protocol;
use crate::image_io::Image;
use crate::optim::PassTimes;
use serde::Serialize;

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
    /// Total gradient relMSE (under the adjoint of ReSTIR's task-spp primal render of the
    /// same iteration) of the baseline at equal time (mean over seeds).
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
    /// Estimator-only gradient relMSE of the mean of `successive_estimates` independent
    /// baseline estimates (the task's spp).
    pub gradient_relmse_mean_baseline: f64,
    /// Estimator-only gradient relMSE of the mean of ReSTIR's next `successive_estimates`
    /// estimates (successive iterations: they share kept samples).
    pub gradient_relmse_mean_restir: f64,
    /// restir / baseline of the means: what survives of the single-estimate ratio when an
    /// optimizer adds up successive steps.
    pub gradient_relmse_mean_ratio: f64,
    /// How many estimates those means average.
    pub successive_estimates: u32,
    /// Per optimized texture, its parts of the equal-iteration gradient errors above (each
    /// texture's terms over the count of all entries, so that the parts add up to the
    /// scene's figures): which texture the error is in.
    pub gradient_relmse_per_texture: Vec<TextureGradientErrors>,
    /// Mean wall-clock ms of a ReSTIR and a baseline iteration in the gradient phase (at the
    /// task's spp, GPU work finished), and their ratio.
    pub ms_per_iteration_ratio: f64,
    /// The primal estimator of the gradient and optimization phases.
    pub primal: String,
    /// ReSTIR's target smoothing with that primal estimator.
    pub target_smoothing: f32,
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

/// One optimized texture's parts of a scene's gradient errors at equal iterations (mean over
/// seeds).
#[derive(Clone, Debug, Serialize)]
pub struct TextureGradientErrors {
    /// `material_slot`.
    pub texture: String,
    /// Part of `gradient_relmse_estimator_only_baseline`.
    pub estimator_only_baseline: f64,
    /// Part of `gradient_relmse_estimator_only_restir`.
    pub estimator_only_restir: f64,
    /// restir / baseline of the two parts.
    pub estimator_only_ratio: f64,
    /// Part of `gradient_relmse_baseline_equal_iterations`.
    pub total_baseline_equal_iterations: f64,
    /// Part of `gradient_relmse_restir`.
    pub total_restir: f64,
    /// restir / baseline of the two parts.
    pub total_ratio_equal_iterations: f64,
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
    /// Kept paths ReSTIR's merge evaluated per iteration, from the second iteration whose pass
    /// times are sampled to the last (the merge's work; it traces no ray).
    pub merge_evaluations_per_iteration: Option<f64>,
    /// Bytes of GPU state per texel of the ReSTIR optimizer (textures, gradient, Adam, and
    /// the reservoirs and headers of the observed texels with the compaction map).
    pub state_bytes_per_texel: f64,
    /// The same for the baseline optimizer.
    pub state_bytes_per_texel_baseline: f64,
    /// Texels that the cameras observe (those with reservoirs).
    pub observed_texels: u64,
    /// Lowest observed-texel RMSE of the baseline's run (a run that ends well above it
    /// drifted: it has a floor).
    pub texture_rmse_observed_min_baseline: f64,
    /// Lowest observed-texel RMSE of ReSTIR's run.
    pub texture_rmse_observed_min_restir: f64,
    /// The baseline's settings in this run (tuned by `--tune`, else the task's).
    pub settings_baseline: String,
    /// ReSTIR's settings in this run.
    pub settings_restir: String,
    /// The search that chose the baseline's settings (`--tune`).
    pub tuned_baseline: Option<super::tune::Tuned>,
    /// The search that chose ReSTIR's settings.
    pub tuned_restir: Option<super::tune::Tuned>,
    /// Optimization curve of the baseline.
    pub curve_baseline: Vec<CurvePoint>,
    /// Optimization curve of ReSTIR.
    pub curve_restir: Vec<CurvePoint>,
    /// The further estimators and steps of [`super::BenchOptions::contenders`], in order.
    pub contenders: Vec<ContenderResult>,
}

/// The equal-time optimization of one further estimator with its step.
#[derive(Clone, Debug, Serialize)]
pub struct ContenderResult {
    /// The estimator and step, e.g. `recursive, variance-scaled step`.
    pub name: String,
    /// Its key in file names (`recursive_variance`).
    pub key: String,
    /// Image relMSE after its budget.
    pub image_relmse: f64,
    /// Over the baseline's (with Adam).
    pub image_relmse_ratio: f64,
    /// Texture RMSE after its budget.
    pub texture_rmse: f64,
    /// Texture RMSE over the observed texels after its budget.
    pub texture_rmse_observed: f64,
    /// Over the baseline's (with Adam).
    pub texture_rmse_observed_ratio: f64,
    /// ... at a third of the budget.
    pub texture_rmse_observed_third: f64,
    /// Lowest observed-texel RMSE of the run.
    pub texture_rmse_observed_min: f64,
    /// Mean wall-clock milliseconds per iteration (GPU work finished).
    pub ms_per_iteration: f64,
    /// Iterations run within the budget.
    pub iterations: u32,
    /// Mean GPU time per pass, when available.
    pub passes: Option<PassTimes>,
    /// Bytes of GPU state per texel.
    pub state_bytes_per_texel: f64,
    /// Its settings in this run (tuned by `--tune`, else the task's).
    pub settings: String,
    /// The search that chose them (`--tune`).
    pub tuned: Option<super::tune::Tuned>,
    /// Its optimization curve.
    pub curve: Vec<CurvePoint>,
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
    /// ReSTIR estimates under the converged adjoint before the estimator-only error.
    pub settle: u32,
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
    /// ReSTIR's target smoothing as given (the last target adjoint's weight); absent: by the
    /// primal estimator (each scene's `target_smoothing`).
    pub target_smoothing: Option<f32>,
    /// The tasks' priors (multiscale gradient, smoothness) were switched off (`--no-priors`).
    pub no_priors: bool,
    /// Each estimator ran at settings chosen by `--tune`.
    pub tuned: bool,
    /// Per scene.
    pub scenes: Vec<SceneResult>,
    /// Each pass's pipeline the first time this run created it: seconds of creation and
    /// compilation (or a load from the driver's shader cache), outside every clock.
    pub pipelines: Vec<crate::gpu::PipelineTime>,
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
