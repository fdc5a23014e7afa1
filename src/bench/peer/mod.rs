//! Peers in the bench's race (`psrestir bench --peers mitsuba`): another renderer's inverse
//! rendering on the same task, at the same budget, scored as psrestir's runs are.
//!
//! psrestir writes the task for the peer ([`exchange`]: its loaded ground-truth scene, the
//! optimized textures' start, truth and observed texels, its targets, budget and schedule);
//! the peer's script (`mitsuba_race.py`, kept here and written beside the exchange when it
//! runs) rebuilds the scene, renders its own targets, optimizes for the budget and writes
//! `result.json`, which becomes runs of the bench's report. A peer that is not installed, or
//! a scene it cannot take, leaves its rows out with a warning that says why; the rest of the
//! bench runs.
pub mod exchange;
pub mod report;

use super::{CurvePoint, PeerForward, RunResult};
use crate::{Error, Result};
use serde::Deserialize;
use std::path::Path;

/// The Mitsuba 3 race script (run with the Python that `--peer-python` names).
pub const MITSUBA_SCRIPT: &str = include_str!("mitsuba_race.py");

/// The `method` of every peer run in the report (psrestir's contenders never take it).
pub const MITSUBA: &str = "mitsuba";

/// The keys of Mitsuba's rows: plain, and with psrestir's smoothness prior.
pub const MITSUBA_KEYS: [&str; 2] = ["mitsuba", "mitsuba_priors"];

/// Whether a run's key is a peer's (peers are never "the best other contender").
pub fn is_peer_key(key: &str) -> bool {
    MITSUBA_KEYS.contains(&key)
}

/// How a user gets Mitsuba 3.
pub const MITSUBA_INSTALL: &str = "`pip install mitsuba` (with the Python that \
    --peer-python names), and LLVM 15 or newer from the system's packages \
    (Debian: `apt-get install libllvm19`)";

/// Whether `python` can import Mitsuba 3 and Dr.Jit; else why not and how to get them.
pub fn check_mitsuba(python: &str) -> std::result::Result<String, String> {
    let out = std::process::Command::new(python)
        .args([
            "-c",
            "import mitsuba as mi, drjit; mi.set_variant('llvm_ad_rgb'); print(mi.__version__)",
        ])
        .output()
        .map_err(|e| {
            format!("cannot run `{python}` ({e}); install Mitsuba 3: {MITSUBA_INSTALL}")
        })?;
    if out.status.success() {
        return Ok(String::from_utf8_lossy(&out.stdout).trim().to_string());
    }
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().last().unwrap_or("").trim();
    Err(format!(
        "`{python}` cannot load Mitsuba 3's LLVM variant ({last}); install it: {MITSUBA_INSTALL}"
    ))
}

/// `result.json` as the script writes it.
#[derive(Deserialize)]
struct RaceResult {
    mitsuba: String,
    threads: u32,
    forward: Vec<Forward>,
    rows: Vec<Row>,
}

/// One camera's forward check.
#[derive(Deserialize)]
struct Forward {
    camera: String,
    #[serde(deserialize_with = "nan_if_null")]
    mean_ratio: f64,
    #[serde(deserialize_with = "nan_if_null")]
    relmse: f64,
}

/// One row: a Mitsuba run.
#[derive(Deserialize)]
struct Row {
    row: String,
    learning_rate_scale: f64,
    spp: u32,
    smoothness: f64,
    iterations: u32,
    ms_per_iteration: f64,
    warmup_s: f64,
    #[serde(deserialize_with = "nan_if_null")]
    texture_rmse_observed: f64,
    #[serde(deserialize_with = "nan_if_null")]
    texture_rmse: f64,
    texture_rmse_observed_per_texture: Vec<Option<f64>>,
    /// The relMSE of its render's expectation: the image error the bench scores (the script
    /// writes its render's relMSE, `image_relmse`, beside it).
    #[serde(deserialize_with = "nan_if_null")]
    image_relmse_expected: f64,
    curve: Vec<PeerPoint>,
}

#[derive(Deserialize)]
struct PeerPoint {
    iteration: u32,
    seconds: f64,
    loss: Option<f64>,
    #[serde(deserialize_with = "nan_if_null")]
    texture_rmse: f64,
    #[serde(deserialize_with = "nan_if_null")]
    texture_rmse_observed: f64,
}

/// A number the script wrote as null (JSON has no NaN): NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// What the bench gives a peer's race on one scene at one seed.
pub struct RaceInput<'a> {
    /// The scene's output folder (the race writes `mitsuba/` in it).
    pub dir: &'a Path,
    /// The Python that runs the script.
    pub python: &'a str,
    /// Choose the peer's learning rate and spp by a search on another seed.
    pub tune: bool,
    /// Seconds of each trial of that search.
    pub tune_budget_s: Option<f64>,
    /// Where the search's choice is kept for the scene's other seeds (one search per scene).
    pub tuned_file: Option<&'a Path>,
    /// The baseline's run (the reference of every ratio).
    pub baseline: &'a RunResult,
}

/// Run Mitsuba 3 on the exchange in `input.dir/mitsuba/exchange` (written by
/// [`exchange::write`]) and return its rows as runs of the report.
/// Also its forward check per camera.
pub fn race_mitsuba(input: &RaceInput) -> Result<(Vec<RunResult>, Vec<PeerForward>)> {
    let dir = input.dir.join("mitsuba");
    let script = dir.join("mitsuba_race.py");
    crate::image_io::write_atomic(&script, MITSUBA_SCRIPT.as_bytes())?;
    let mut cmd = std::process::Command::new(input.python);
    cmd.arg(&script).arg(dir.join("exchange")).arg(&dir);
    if input.tune {
        cmd.arg("--tune");
        if let Some(t) = input.tune_budget_s {
            cmd.args(["--tune-budget-s", &t.to_string()]);
        }
        if let Some(f) = input.tuned_file {
            cmd.arg("--tuned").arg(f);
        }
    }
    let log = dir.join("race.log");
    let out = cmd
        .output()
        .map_err(|e| Error::file(&script, format!("cannot run `{}`: {e}", input.python)))?;
    let text = [out.stdout.as_slice(), out.stderr.as_slice()].concat();
    crate::image_io::write_atomic(&log, &text)?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(Error::file(
            &script,
            format!(
                "the Mitsuba race failed ({}): {}",
                out.status,
                err.lines().last().unwrap_or("").trim()
            ),
        ));
    }
    let path = dir.join("result.json");
    let bytes = std::fs::read(&path).map_err(|e| Error::file(&path, e.to_string()))?;
    let r: RaceResult = serde_json::from_slice(&bytes)
        .map_err(|e| Error::file(&path, format!("not a race result: {e}")))?;
    let forward = r
        .forward
        .iter()
        .map(|f| PeerForward {
            peer: MITSUBA.into(),
            camera: f.camera.clone(),
            mean_ratio: f.mean_ratio,
            relmse: f.relmse,
        })
        .collect();
    Ok((
        r.rows.iter().map(|row| run_of(&r, row, input)).collect(),
        forward,
    ))
}

/// A Mitsuba row as a run of the report (its ratios over psrestir's baseline).
fn run_of(r: &RaceResult, row: &Row, input: &RaceInput) -> RunResult {
    let b = input.baseline;
    let curve: Vec<CurvePoint> = row
        .curve
        .iter()
        .map(|p| CurvePoint {
            iteration: p.iteration,
            seconds: p.seconds,
            loss: p.loss.unwrap_or(f64::NAN),
            texture_rmse: p.texture_rmse,
            texture_rmse_observed: p.texture_rmse_observed,
            learning_rate_factor: None,
            image_relmse: None,
        })
        .collect();
    let budget = curve.last().map_or(0.0, |p| p.seconds);
    let third = curve
        .iter()
        .take_while(|p| p.seconds <= budget / 3.0)
        .last()
        .map_or(f64::NAN, |p| p.texture_rmse_observed);
    let min = curve
        .iter()
        .map(|p| p.texture_rmse_observed)
        .fold(f64::INFINITY, f64::min);
    let (name, key) = if row.row == "priors" {
        ("Mitsuba 3, prb, Adam, smoothness prior", MITSUBA_KEYS[1])
    } else {
        ("Mitsuba 3, prb, Adam", MITSUBA_KEYS[0])
    };
    let forward: Vec<String> = r
        .forward
        .iter()
        .map(|f| format!("{} {:.3}", f.camera, f.mean_ratio))
        .collect();
    RunResult {
        name: name.into(),
        key: key.into(),
        method: MITSUBA.into(),
        image_relmse: row.image_relmse_expected,
        image_relmse_ratio: row.image_relmse_expected / b.image_relmse,
        texture_rmse: row.texture_rmse,
        texture_rmse_observed: row.texture_rmse_observed,
        texture_rmse_observed_ratio: row.texture_rmse_observed / b.texture_rmse_observed,
        texture_rmse_observed_third: third,
        texture_rmse_observed_min: min,
        texture_rmse_observed_per_texture: row
            .texture_rmse_observed_per_texture
            .iter()
            .map(|v| v.unwrap_or(f64::NAN))
            .collect(),
        // Mitsuba's loop hands back its last state: it has no keeper.
        kept_iteration: None,
        last_state_errors: None,
        ms_per_iteration: row.ms_per_iteration,
        iterations: row.iterations,
        passes: None,
        diagnostics_per_iteration: Vec::new(),
        state_bytes_per_texel: f64::NAN,
        settings: format!(
            "Mitsuba {} llvm_ad_rgb ({} threads), {} spp, Adam at {}x the task's rate, \
             smoothness {}; JIT warm-up {:.1} s outside the clock; its target means over \
             psrestir's: {}",
            r.mitsuba,
            r.threads,
            row.spp,
            row.learning_rate_scale,
            row.smoothness,
            row.warmup_s,
            forward.join(", ")
        ),
        tuned: None,
        relit_relmse: None,
        relit_relmse_ratio: None,
        relit_psnr: None,
        light_direction_error_deg: None,
        curve,
    }
}

/// The peers' rows on this scene and seed, added to `runs` (the baseline first), and their
/// forward checks: Mitsuba 3's where `o.mitsuba` names its Python; none, with a warning that
/// says why, where the scene does not convert or the race fails.
pub(super) fn race(
    (dir, tune_dir): (&Path, &Path),
    task: &crate::task::Task,
    prep: &crate::job::Problem,
    o: &super::BenchOptions,
    observed: &[bool],
    runs: &mut Vec<RunResult>,
) -> Vec<PeerForward> {
    let Some(python) = &o.mitsuba else {
        return Vec::new();
    };
    let exchange = dir.join("mitsuba").join("exchange");
    let s = super::settings(prep, task, crate::optim::Method::BASELINE, o);
    let tuned_file = tune_dir.join("mitsuba_tuned.json");
    let raced = exchange::write(&exchange, task, prep, &s, observed, o.budget_s, o.eval_spp)
        .and_then(|()| {
            race_mitsuba(&RaceInput {
                dir,
                python,
                tune: o.tune || o.tune_peers,
                tune_budget_s: o.tune_budget_s,
                tuned_file: Some(&tuned_file),
                baseline: &runs[0],
            })
        });
    match raced {
        Ok((rows, forward)) => {
            runs.extend(rows);
            forward
        }
        Err(e) => {
            eprintln!("warning: no Mitsuba 3 rows for {}: {e}", dir.display());
            Vec::new()
        }
    }
}
