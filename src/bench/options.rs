//! What a bench run is asked: its options, the protocol of its sampling settings, the scenes
//! it resolves, and the settings each estimator runs a scene with.
use super::contender::Contender;
use crate::job::Problem;
use crate::optim::{EstimatorOptions, Method, Settings};
use crate::task::{task_settings, Task};
use crate::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The settings of `method` on `task` as the bench runs it: the task's, with the bench's
/// estimator options and primal.
pub(super) fn settings(prep: &Problem, task: &Task, method: Method, o: &BenchOptions) -> Settings {
    let mut s = task_settings(task, &prep.cameras, method, &o.estimator_options);
    if let Some(p) = o.primal {
        s.primal = p;
    }
    if let Some(r) = o.path_cache {
        s.path_cache = Some(r.min(s.primal_spp));
    }
    s
}

/// Which sampling settings the benchmark runs the scenes with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
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
    /// Each task's own `time_budget_s` instead of `budget_s` (which stays for a task that
    /// names none): the bench's `--budget-s` left out.
    pub task_budgets: bool,
    /// Multiplier of image and texture sizes.
    pub scale: f64,
    /// The estimator whose gradient error the gradient phase measures against the
    /// baseline's (ReSTIR by default: the method the bench's gradient phase was made for).
    pub gradient_method: Method,
    /// Iterations of that estimator before the gradient error is measured.
    pub warmup: u32,
    /// Its estimates under the converged adjoint, at the textures after the warm-up, before
    /// its estimator-only error is measured.
    pub settle: u32,
    /// Successive estimates (the estimator's) and independent ones (baseline) averaged for the
    /// estimator-only error of their mean: 10, about the window of Adam's first moment
    /// (β1 = 0.9), with the 256-spp reference's own error a small part of the baseline's
    /// mean (about 4%).
    pub successive: u32,
    /// Seeds the gradient error is averaged over.
    pub repeats: u32,
    /// Seeds of the equal-time phase per scene (`--seeds`): each renders the targets and
    /// runs every contender again with another seed ([`seeds`](super::seeds)); the primal and gradient
    /// phases run with the first only.
    pub seeds: u32,
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
    /// The path cache of every run: paths per pixel traced anew each iteration, at most the
    /// task's primal spp (None: each task's own).
    pub path_cache: Option<u32>,
    /// Vertices of a camera path in every task (None: each task's own `max_depth`).
    pub max_depth: Option<u32>,
    /// Samples per pixel of the renders that measure image error.
    pub eval_spp: u32,
    /// Image-error evaluations along each optimization (start and end included).
    pub curve_points: u32,
    /// The estimators' options over the tasks' (`--estimator-option`).
    pub estimator_options: EstimatorOptions,
    /// The command line that runs it, recorded in `bench.json`.
    pub command: Option<String>,
    /// Output folder.
    pub out: PathBuf,
    /// Show a progress bar.
    pub progress: bool,
    /// Switch off the tasks' priors (multiscale gradient, smoothness prior).
    pub no_priors: bool,
    /// Each estimator's settings chosen by a search on another seed ([`tune`](super::tune)).
    pub tune: bool,
    /// Seconds of each tuning trial (None: a third of `budget_s`).
    pub tune_budget_s: Option<f64>,
    /// The equal-time optimization only (no primal or gradient-error phases).
    pub end_to_end_only: bool,
    /// The estimators and steps optimized in the equal-time phase after the baseline with
    /// Adam, each tuned like it with `tune`.
    pub contenders: Vec<Contender>,
    /// Race Mitsuba 3 too (`--peers mitsuba`), with this Python ([`peer`](super::peer)); None: no peer.
    pub mitsuba: Option<String>,
    /// The peers' learning rate and spp chosen by a search on another seed, once per scene
    /// (also with `tune`).
    pub tune_peers: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            budget_s: 60.0,
            task_budgets: false,
            scale: 1.0,
            gradient_method: Method::RESTIR,
            warmup: 20,
            settle: 20,
            successive: 10,
            repeats: 3,
            seeds: 1,
            reference_spp: 256,
            reference_primal_spp: 256,
            protocol: Protocol::Default,
            gradient_only: false,
            primal: None,
            path_cache: None,
            max_depth: None,
            eval_spp: 64,
            curve_points: 11,
            estimator_options: EstimatorOptions::default(),
            command: None,
            out: PathBuf::from("out/bench"),
            progress: true,
            no_priors: false,
            tune: false,
            tune_budget_s: None,
            end_to_end_only: false,
            contenders: Contender::DEFAULT.to_vec(),
            mitsuba: None,
            tune_peers: false,
        }
    }
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
