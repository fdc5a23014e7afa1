//! `psrestir bench --throughput`: camera samples per second of the forward render and of each
//! estimator's passes on one task, and what creating each pass's pipeline took, so that
//! these figures stay measured rather than quoted.
use crate::gpu::{Gpu, PipelineTime};
use crate::job::Problem;
use crate::optim::run_loop::{run_steps, PassSampler};
use crate::optim::{Method, Optimizer};
use crate::render::{RenderSettings, Renderer, Techniques};
use crate::task::{task_settings, Task};
use crate::{Error, Result};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// The forward render's size and samples: the figure the project compares with Mitsuba 3.
pub const FORWARD_SIZE: u32 = 256;
/// Samples per pixel of the forward render.
pub const FORWARD_SPP: u32 = 64;
/// Iterations run before the passes are timed, and iterations timed.
const WARM_ITERATIONS: u32 = 8;
const TIMED_ITERATIONS: u32 = 16;

/// Camera samples of one pass (or group of passes) and the time they took.
#[derive(Clone, Debug, Serialize)]
pub struct Rate {
    /// What was timed.
    pub what: String,
    /// Camera samples per run of it.
    pub samples: u64,
    /// Milliseconds per run of it.
    pub ms: f64,
    /// Millions of camera samples per second.
    pub msamples_per_s: f64,
}

impl Rate {
    fn new(what: impl Into<String>, samples: u64, ms: f64) -> Rate {
        Rate {
            what: what.into(),
            samples,
            ms,
            msamples_per_s: samples as f64 / (ms * 1e3),
        }
    }
}

/// What `psrestir bench --throughput` measured.
#[derive(Clone, Debug, Serialize)]
pub struct ThroughputReport {
    /// psrestir version.
    pub version: String,
    /// The adapter, as `psrestir adapter` prints it.
    pub adapter: String,
    /// The task file.
    pub task: String,
    /// Rates: the forward render, then each estimator's primal and gradient passes.
    pub rates: Vec<Rate>,
    /// Each pass's pipeline the first time this run created it (compilation included).
    pub pipelines: Vec<PipelineTime>,
}

/// Measure on `task` (read from `path`; its targets go to `out`): a 256², 64-spp render of its first camera (wall clock, GPU work
/// finished, best of three), then for each estimator the mean pass times of 16 iterations
/// after 8 (timestamp queries; an error on a device without them).
pub fn throughput(gpu: &Gpu, task: &Task, path: &Path, out: &Path) -> Result<ThroughputReport> {
    if !gpu.timestamps {
        return Err(Error::Unsuitable(format!(
            "bench --throughput times passes with timestamp queries, which {} lacks",
            gpu.info.name
        )));
    }
    let before = gpu.pipeline_times().len();
    let prep = Problem::from_task(gpu, task, out, false)?;
    let renderer = Renderer::new(gpu, &prep.scene)?;
    let settings = RenderSettings {
        width: FORWARD_SIZE,
        height: FORWARD_SIZE,
        spp: FORWARD_SPP,
        seed: task.seed,
        camera: prep.cameras[0],
        techniques: Techniques::Mis,
    };
    let mut best = f64::INFINITY;
    let mut samples = 0;
    for _ in 0..3 {
        let out = renderer.render(&settings, |_| {})?;
        best = best.min(out.seconds);
        samples = out.camera_rays;
    }
    let mut rates = vec![Rate::new(
        format!("render {FORWARD_SIZE}² × {FORWARD_SPP} spp"),
        samples,
        1e3 * best,
    )];
    let pixels: u64 = prep.cameras.len() as u64 * (task.width as u64 * task.height as u64);
    for method in Method::all() {
        let s = task_settings(task, &prep.cameras, method, &Default::default());
        let (primal_spp, gradient_spp) = (s.primal_spp as u64, s.gradient_spp as u64);
        let mut opt = Optimizer::for_problem(gpu, &prep, s)?;
        run_steps(&mut opt, WARM_ITERATIONS, &mut [])?;
        let mut sampler = PassSampler::every(1);
        run_steps(&mut opt, TIMED_ITERATIONS, &mut [&mut sampler])?;
        let t = sampler.mean().unwrap_or_default();
        let name = method.name();
        rates.push(Rate::new(
            format!("{name}: primal"),
            primal_spp * pixels,
            t.primal_ms,
        ));
        rates.push(Rate::new(
            format!("{name}: gradient"),
            gradient_spp * pixels,
            t.gradient_ms,
        ));
        if t.combine_ms > 0.0 {
            rates.push(Rate::new(
                format!("{name}: gradient, all passes"),
                gradient_spp * pixels,
                t.gradient_ms + t.combine_ms,
            ));
        }
    }
    Ok(ThroughputReport {
        version: env!("CARGO_PKG_VERSION").into(),
        adapter: gpu.describe(),
        task: path.display().to_string(),
        rates,
        pipelines: first_creations(&gpu.pipeline_times()[before..]),
    })
}

/// The report as markdown: the rates, then the pipelines, slowest first.
pub fn markdown(r: &ThroughputReport) -> String {
    let mut md = format!(
        "# psrestir throughput\n\npsrestir {} on `{}`, task `{}`.\n\n\
         | what | camera samples | ms | M samples/s |\n|---|---:|---:|---:|\n",
        r.version, r.adapter, r.task
    );
    for x in &r.rates {
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} | {:.2} |",
            x.what, x.samples, x.ms, x.msamples_per_s
        );
    }
    md.push_str(
        "\nThe render: wall clock with the GPU work finished, best of three. The passes: mean \
         GPU time (timestamp queries) of 16 iterations after 8, at the task's settings; the \
         primal with the control variate evaluates each sample under two states; an \
         estimator's gradient is its sampling pass (ReSTIR's candidates), and its other pass \
         (ReSTIR's merge, the recursive combine) is added in the row after.\n",
    );
    md.push_str(&super::report::pipeline_markdown(&r.pipelines));
    md
}

/// The first creation of each pass among `times`, in order (later ones load what the first
/// compiled).
pub(super) fn first_creations(times: &[crate::gpu::PipelineTime]) -> Vec<crate::gpu::PipelineTime> {
    let mut out: Vec<crate::gpu::PipelineTime> = Vec::new();
    for t in times {
        if !out.iter().any(|o| o.pass == t.pass) {
            out.push(t.clone());
        }
    }
    out
}
