//! The `psrestir` command line: its commands and their arguments (clap).
use anyhow::Result;
use clap::builder::TypedValueParser as _;
use clap::{Parser, Subcommand};
use psrestir::optim;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "psrestir",
    version,
    about = "Inverse texture optimization with parameter-space ReSTIR gradients, on wgpu"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum TechniqueArg {
    /// Light and BSDF sampling combined by MIS (power heuristic).
    Mis,
    /// Light sampling (next-event estimation) only.
    Nee,
    /// BSDF sampling only (delta lights still use light sampling).
    Bsdf,
}

/// `--step`'s values: the registry's steps by name.
fn step_parser() -> impl clap::builder::TypedValueParser<Value = optim::StepKind> {
    clap::builder::PossibleValuesParser::new(optim::StepKind::names()).map(|name: String| {
        optim::StepKind::by_name(&name).expect("a possible value names a registered step")
    })
}

/// Choice of gradient estimator and its options, shared by the commands that estimate
/// gradients.
#[derive(clap::Args)]
pub(crate) struct EstimatorArgs {
    /// Gradient estimator: auto (chosen by the task's sampling and size; `psrestir
    /// estimators` states the rule), baseline (plain Monte Carlo), restir (parameter-space
    /// ReSTIR) or recursive (a recursive control variate on the gradient). Default: the
    /// task's `optimizer.method`, else auto.
    #[arg(long, value_parser = parse_method)]
    pub(crate) method: Option<optim::MethodChoice>,
    /// An estimator's option over the task's `[optimizer.METHOD]` table, as
    /// METHOD.KEY=VALUE (`restir.m_cap=16`, `restir.confidence=candidates`,
    /// `recursive.min_weight=0.2`); repeat for more. docs/guide.md lists the options.
    #[arg(long = "estimator-option", value_name = "METHOD.KEY=VALUE")]
    pub(crate) options: Vec<String>,
}

fn parse_method(s: &str) -> std::result::Result<optim::MethodChoice, String> {
    s.parse().map_err(|e: psrestir::Error| e.to_string())
}

fn parse_estimator(s: &str) -> std::result::Result<optim::Method, String> {
    s.parse().map_err(|e: psrestir::Error| e.to_string())
}

impl EstimatorArgs {
    /// The estimator (`task_method` unless `--method` is given) and the options given,
    /// refused here (before any scene is loaded) when invalid.
    pub(crate) fn resolve(
        &self,
        task_method: optim::MethodChoice,
    ) -> Result<(optim::MethodChoice, optim::EstimatorOptions)> {
        Ok((
            self.method.unwrap_or(task_method),
            self.estimator_options()?,
        ))
    }

    /// The options given.
    pub(crate) fn estimator_options(&self) -> Result<optim::EstimatorOptions> {
        let mut o = optim::EstimatorOptions::default();
        for a in &self.options {
            o.assign(a)?;
        }
        Ok(o)
    }
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum PrimalArg {
    /// An independent render at the primal spp.
    Independent,
    /// The recursive control variate: the render carried over from the last iteration.
    ControlVariate,
}

impl PrimalArg {
    pub(crate) fn mode(self) -> optim::PrimalMode {
        match self {
            PrimalArg::Independent => optim::PrimalMode::Independent,
            PrimalArg::ControlVariate => optim::PrimalMode::ControlVariate,
        }
    }
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum ProtocolArg {
    /// Each task's own sampling settings.
    Default,
    /// The paper's: primal 32 spp, gradient 1 spp, nearest filtering.
    Paper,
}

/// The bundled default task.
pub(crate) const DEFAULT_TASK: &str = "scenes/default/task.toml";

/// The arguments of `psrestir render`.
#[derive(clap::Args)]
pub(crate) struct RenderArgs {
    /// The scene (.gltf or .glb).
    pub(crate) scene: PathBuf,
    /// Camera, by name or index (default: the first).
    #[arg(long)]
    pub(crate) camera: Option<String>,
    /// Samples per pixel.
    #[arg(long, default_value_t = 64)]
    pub(crate) spp: u32,
    /// Image size WxH (default: 512 wide, height from the camera's aspect ratio).
    #[arg(long, value_parser = parse_size)]
    pub(crate) size: Option<(u32, u32)>,
    /// Environment light: an equirectangular .exr or .hdr image.
    #[arg(long)]
    pub(crate) env: Option<PathBuf>,
    /// Multiplier for the environment light.
    #[arg(long, default_value_t = 1.0)]
    pub(crate) env_scale: f32,
    /// Add no default environment to a scene without punctual lights and environment (one
    /// lit by its emissive surfaces alone).
    #[arg(long)]
    pub(crate) no_default_env: bool,
    /// The punctual lights that are on, by name, comma-separated (default: all): one capture
    /// of a set of photos under different lights. Emissive surfaces and the environment stay.
    #[arg(long, value_delimiter = ',', value_name = "NAME,...")]
    pub(crate) lights: Option<Vec<String>>,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u32,
    /// Sampling techniques for area and environment lights.
    #[arg(long, value_enum, default_value = "mis")]
    pub(crate) technique: TechniqueArg,
    /// Vertices of a camera path: 1 is direct light only, each more one bounce of indirect
    /// light (default 1).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=psrestir::scene::MaxDepth::LIMIT as i64))]
    pub(crate) max_depth: Option<u32>,
    /// Output image: .exr (linear) or .png (sRGB).
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// A camera file from a capture tool (NeRF-style transforms.json, or a COLMAP text
    /// model: its folder, cameras.txt or images.txt); render its frame `--frame`.
    #[arg(long)]
    pub(crate) cameras: Option<PathBuf>,
    /// The frame of `--cameras` to render (index, or the image's name).
    #[arg(long, default_value = "0")]
    pub(crate) frame: String,
}

/// The arguments of `psrestir optimize`.
#[derive(clap::Args)]
pub(crate) struct OptimizeArgs {
    /// The task file (TOML); the bundled default task when absent.
    pub(crate) task: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) estimator: EstimatorArgs,
    /// Iterations (overrides the task).
    #[arg(long)]
    pub(crate) iterations: Option<u32>,
    /// Wall-clock budget in seconds (overrides the task).
    #[arg(long)]
    pub(crate) time_budget: Option<f64>,
    /// Output folder (overrides the task).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Continue from the checkpoint in the output folder.
    #[arg(long)]
    pub(crate) resume: bool,
    /// Set any key of the task file: `--set optimizer.smoothness=0.01`,
    /// `--set textures.0.learning_rate=0.02`, `--set 'target.lights={main=["sun"]}'` (a TOML
    /// value; a bare word is a string). Repeatable; applied after the flags below, which are
    /// shorthands for such keys, and checked as the file is.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub(crate) set: Vec<String>,
    /// Vertices of a camera path: 1 is direct light only, each more one bounce of indirect
    /// light (overrides the task's `max_depth`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=psrestir::scene::MaxDepth::LIMIT as i64))]
    pub(crate) max_depth: Option<u32>,
    /// Primal estimator (overrides the task).
    #[arg(long, value_enum)]
    pub(crate) primal: Option<PrimalArg>,
    /// Levels of the multiscale gradient, 0 (off) to 4 (overrides the task).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=4))]
    pub(crate) multiscale_levels: Option<u32>,
    /// Weight of the smoothness prior, 0 (off) or more (overrides the task).
    #[arg(long)]
    pub(crate) smoothness: Option<f32>,
    /// Multiply every texture's learning rate by this (overrides the task's rates).
    #[arg(long)]
    pub(crate) lr_scale: Option<f32>,
    /// Adam's first-moment decay (overrides the task).
    #[arg(long)]
    pub(crate) adam_beta1: Option<f32>,
    /// Adam's second-moment decay (overrides the task).
    #[arg(long)]
    pub(crate) adam_beta2: Option<f32>,
    /// Adam's epsilon (overrides the task).
    #[arg(long)]
    pub(crate) adam_eps: Option<f32>,
    /// The step taken with each gradient: `adam`, or `variance` for the variance-scaled step
    /// (overrides the task's `optimizer.step`).
    #[arg(long, value_parser = step_parser())]
    pub(crate) step: Option<optim::StepKind>,
    /// The variance-scaled step's largest step, in learning rates (overrides the task).
    #[arg(long)]
    pub(crate) step_clip: Option<f32>,
    /// The variance-scaled step's threshold: standard deviations taken off each estimate's
    /// magnitude (overrides the task).
    #[arg(long)]
    pub(crate) step_threshold: Option<f32>,
    /// Filtered moments: levels of the edge-stopping filter over the step's moments, 0 (off)
    /// to 8 (overrides the task's `optimizer.moment_filter.levels`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=8))]
    pub(crate) moment_filter: Option<u32>,
    /// Taps per side of each level of the moment filter, 3 or 5 (overrides the task).
    #[arg(long, value_parser = clap::value_parser!(u32).range(3..=5))]
    pub(crate) moment_filter_taps: Option<u32>,
    /// The moment filter's edge-stopping scale (overrides the task).
    #[arg(long)]
    pub(crate) moment_filter_sigma: Option<f32>,
    /// Weight of a texel's own moments against the filtered ones, in (0, 1] (overrides the
    /// task).
    #[arg(long)]
    pub(crate) moment_filter_own_weight: Option<f32>,
    /// The moment filter measures the texture's differences between logarithms.
    #[arg(long)]
    pub(crate) moment_filter_log: bool,
    /// The filtered moments replace Adam's.
    #[arg(long)]
    pub(crate) moment_filter_write_back: bool,
}

impl OptimizeArgs {
    /// The task-file keys the flags set, as `--set` assignments: the flags that stand for one
    /// key, then `--set` itself (later ones win).
    pub(crate) fn task_sets(&self) -> Vec<String> {
        let key = |k: &str, v: Option<String>| v.map(|v| format!("{k}={v}"));
        let text = |v: Option<f32>| v.map(|v| v.to_string());
        let quoted = |name: Option<&str>| name.map(|n| format!("{n:?}"));
        [
            key("max_depth", self.max_depth.map(|v| v.to_string())),
            key("optimizer.adam.beta1", text(self.adam_beta1)),
            key("optimizer.adam.beta2", text(self.adam_beta2)),
            key("optimizer.adam.eps", text(self.adam_eps)),
            key("optimizer.step", quoted(self.step.map(|s| s.name()))),
            key("optimizer.variance_step.clip", text(self.step_clip)),
            key(
                "optimizer.variance_step.threshold",
                text(self.step_threshold),
            ),
            key(
                "optimizer.primal",
                quoted(self.primal.map(|p| p.mode().name())),
            ),
            key(
                "optimizer.multiscale_levels",
                self.multiscale_levels.map(|v| v.to_string()),
            ),
            key("optimizer.smoothness", text(self.smoothness)),
        ]
        .into_iter()
        .flatten()
        .chain(self.set.iter().cloned())
        .collect()
    }
}

/// The arguments of `psrestir bench`.
#[derive(clap::Args)]
pub(crate) struct BenchArgs {
    /// Scenes: names of bundled benchmark scenes (vase, lattice, dish, sphere, room,
    /// gallery, atelier, outdoor), task files, or folders holding task.toml (default: every
    /// bundled benchmark scene).
    pub(crate) scenes: Vec<String>,
    /// Seconds of optimization per estimator and scene (default: each task's
    /// `time_budget_s`, 60 where it names none).
    #[arg(long)]
    pub(crate) budget_s: Option<f64>,
    /// Output folder.
    #[arg(long, default_value = "out/bench")]
    pub(crate) out: PathBuf,
    /// Multiply image and texture sizes (e.g. 4 for GPU-size runs, 0.5 for a quick look).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) scale: f64,
    /// Iterations of the estimator the gradient phase measures (`--gradient-method`) before
    /// its gradient error is measured.
    #[arg(long, default_value_t = 20)]
    pub(crate) warmup: u32,
    /// That estimator's estimates under the converged adjoint, at the textures after the
    /// warm-up, before its estimator-only gradient error is measured.
    #[arg(long, default_value_t = 20)]
    pub(crate) settle: u32,
    /// Successive estimates averaged for the error of their mean (estimator-only).
    #[arg(long, default_value_t = 10)]
    pub(crate) successive: u32,
    /// Seeds the gradient error is averaged over.
    #[arg(long, default_value_t = 3)]
    pub(crate) repeats: u32,
    /// Seeds of the equal-time phase per scene: every contender runs with each (new
    /// targets' noise, new sampling), paired within a seed; each ratio is then a geometric
    /// mean with a 90% interval, a difference counting where it excludes 1.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub(crate) seeds: u32,
    /// Gradient samples per pixel of the reference gradient.
    #[arg(long, default_value_t = 256)]
    pub(crate) reference_spp: u32,
    /// Samples per pixel of the primal render of the converged adjoint (the reference and
    /// the estimator-only errors are computed under it).
    #[arg(long, default_value_t = 256)]
    pub(crate) reference_primal_spp: u32,
    /// Sampling settings: the tasks' own, or the paper's (primal 32 spp, gradient 1 spp,
    /// nearest filtering).
    #[arg(long, value_enum, default_value = "default")]
    pub(crate) protocol: ProtocolArg,
    /// The estimator whose gradient error the gradient phase measures against the baseline's.
    #[arg(long, value_parser = parse_estimator, default_value = "restir")]
    pub(crate) gradient_method: optim::Method,
    /// Measure the gradient error only (skip the equal-time optimization).
    #[arg(long)]
    pub(crate) gradient_only: bool,
    /// Measure the equal-time optimization only (skip the primal and gradient-error phases).
    #[arg(long)]
    pub(crate) end_to_end_only: bool,
    /// The estimators optimized at equal time after the baseline with Adam (the reference
    /// of every ratio), as METHOD or METHOD:STEP (steps: adam, variance), either with
    /// `+filtered` for filtered moments (`baseline+filtered`), or `default` (the scene's task
    /// stripped to what `auto` chooses), comma-separated; `none` for none.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "restir,recursive:adam,recursive:variance,baseline:variance,baseline:variance+filtered,default"
    )]
    pub(crate) contenders: Vec<String>,
    /// Switch off the tasks' priors (multiscale gradient, smoothness prior).
    #[arg(long)]
    pub(crate) no_priors: bool,
    /// Other renderers raced on every scene at equal time, scored as psrestir's runs:
    /// `mitsuba` (Mitsuba 3's `prb` with Adam, and with psrestir's smoothness prior; needs
    /// `pip install mitsuba` and LLVM 15 or newer; without them the bench says how to get
    /// them and runs the rest).
    #[arg(long, value_delimiter = ',', value_parser = ["mitsuba"])]
    pub(crate) peers: Vec<String>,
    /// Choose the peers' learning rate (×1/3, ×1, ×3 the task's) and spp (4, 16) by a
    /// search on another seed, once per scene, each trial a third of the budget (also with
    /// --tune).
    #[arg(long)]
    pub(crate) tune_peers: bool,
    /// The Python that runs the peers' scripts.
    #[arg(long, default_value = "python3")]
    pub(crate) peer_python: String,
    /// Vertices of a camera path: 1 is direct light only, each more one bounce of indirect
    /// light (overrides every task's `max_depth`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=psrestir::scene::MaxDepth::LIMIT as i64))]
    pub(crate) max_depth: Option<u32>,
    /// Measure throughput only, on the first scene given (default: the bundled default
    /// task): camera samples per second of a 256², 64-spp render and of each estimator's
    /// passes, and each pass's pipeline creation. Writes throughput.md and throughput.json.
    #[arg(long)]
    pub(crate) throughput: bool,
    /// Choose each estimator's learning rate, Adam decays and (ReSTIR) M cap, its schedule and
    /// the target smoothing by a small search on another seed (cached in the output folder).
    #[arg(long)]
    pub(crate) tune: bool,
    /// Seconds of each tuning trial (default: a third of --budget).
    #[arg(long)]
    pub(crate) tune_budget: Option<f64>,
    /// Primal estimator of every run (default: each task's own).
    #[arg(long, value_enum)]
    pub(crate) primal: Option<PrimalArg>,
    /// Shade every run's primal from the path cache, this many paths per pixel traced anew
    /// each iteration (at most the task's primal spp); default: each task's own
    /// `optimizer.path_cache`.
    #[arg(long)]
    pub(crate) path_cache: Option<u32>,
    /// Samples per pixel of the renders that measure image error.
    #[arg(long, default_value_t = 64)]
    pub(crate) eval_spp: u32,
    /// Also write the report to the checkout in the current folder: docs/results.md,
    /// and the headline table in README.md (between its `bench:headline` markers).
    #[arg(long)]
    pub(crate) report: bool,
    /// Measure nothing: write docs/results.md and README.md's headline (as --report does)
    /// from the bench.json of an earlier run.
    #[arg(long, value_name = "BENCH_JSON")]
    pub(crate) report_from: Option<std::path::PathBuf>,
    /// An estimator's option for every run of that estimator, as METHOD.KEY=VALUE
    /// (`restir.m_cap=16`); repeat for more.
    #[arg(long = "estimator-option", value_name = "METHOD.KEY=VALUE")]
    pub(crate) options: Vec<String>,
}

#[derive(Subcommand)]
pub(crate) enum Command {
    /// Render a glTF scene: direct light, and with --max-depth indirect light.
    Render(RenderArgs),
    /// Recover textures from target images by gradient descent.
    Optimize(OptimizeArgs),
    /// Write one gradient estimate at the task's initial textures, as images in texel space.
    Gradient {
        /// The task file (TOML).
        task: PathBuf,
        #[command(flatten)]
        estimator: EstimatorArgs,
        /// Output folder.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Print what a scene holds: triangles, materials, textures, cameras, lights.
    Info {
        /// The scene (.gltf or .glb).
        scene: PathBuf,
    },
    /// Benchmark the estimators and the default configuration against the baseline
    /// (gradient error, equal-time optimization, cost) on the bundled benchmark scenes or
    /// given tasks; writes bench.json, report.md and plots.
    Bench(BenchArgs),
    /// Print the GPU adapter psrestir would use, its features and limits.
    Adapter,
    /// List the gradient estimators, the steps and the priors: what each does and its options
    /// with their defaults (the TOML of its task-file table `[optimizer.<name>]`; `--set`
    /// sets one).
    Estimators,
    /// Regenerate the bundled scenes (scenes/default and scenes/bench/*), or with
    /// `--family` write members of the scene family (DIR/<split>/<member>/task.toml).
    #[command(hide = true)]
    MakeScenes {
        /// Output folder.
        #[arg(default_value = "scenes")]
        dir: PathBuf,
        /// Write the family's `train` split (seeds for choosing rules and constants) or its
        /// `test` split (seeds only reported) instead of the bundled scenes.
        #[arg(long, value_parser = psrestir::assets::family::Split::parse)]
        family: Option<psrestir::assets::family::Split>,
        /// Members of the split to write (its first seeds).
        #[arg(long, default_value_t = 6)]
        count: u32,
    },
}

pub(crate) fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WxH, e.g. 256x256"))?;
    let w: u32 = w
        .trim()
        .parse()
        .map_err(|_| format!("bad width in `{s}`"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|_| format!("bad height in `{s}`"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("size `{s}` out of range (1..16384)"));
    }
    Ok((w, h))
}
