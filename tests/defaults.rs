//! A task that names only its scene, targets and texture runs with `auto`'s whole
//! configuration and ends below its start; a run whose loss does not fall says so.
mod common;

use common::write_plane_scene as write_scene;
use psrestir::job::run::{run, RunOptions};
use psrestir::task::Task;
use std::path::Path;

/// A 64² task in `dir` with `optimizer` as its `[optimizer]` keys and `rate` as its
/// texture's `learning_rate` line (empty: none); its targets are renders of `truth` (the
/// textured plane, or the gray one the texture starts as).
fn task(dir: &Path, optimizer: &str, rate: &str, truth: &str) -> Task {
    write_scene(&dir.join("scene.glb"), false);
    write_scene(&dir.join("truth.glb"), true);
    let text = format!(
        "scene = \"scene.glb\"\nwidth = 64\nheight = 64\nseed = 3\n[target]\nscene = \
         \"{truth}\"\nspp = 128\n[optimizer]\n{optimizer}\n[[textures]]\nmaterial = \
         \"plane\"\nslot = \"base_color\"\nresolution = [4, 4]\ninit = [0.5, 0.5, 0.5]\n{rate}\n"
    );
    std::fs::write(dir.join("task.toml"), text).unwrap();
    Task::load(&dir.join("task.toml")).unwrap()
}

/// The learning-rate column of metrics.csv, iteration by iteration.
fn rates(dir: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    text.lines()
        .skip(2)
        .map(|l| l.split(',').nth(6).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn a_bare_task_takes_autos_configuration_and_ends_below_its_start() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let t = task(dir.path(), "iterations = 60", "", "truth.glb");
    // The rule's choices, before any pass runs.
    let c = psrestir::task::task_configuration(&t, t.optimizer.method, 1);
    assert_eq!(c.step, psrestir::optim::StepKind::VARIANCE);
    assert!(c.moment_filter.enabled());
    assert_eq!(c.schedule, psrestir::auto::schedule());
    assert!(
        c.reasons.iter().any(|r| r.contains("learning rate 0.01")),
        "{:?}",
        c.reasons
    );
    let out = dir.path().join("out");
    let s = run(
        &gpu,
        &t,
        &RunOptions {
            out: Some(out.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(s.iterations, 60);
    // The variance step's rate for base color, decaying as a cosine to 5% over the run.
    let r = rates(&out);
    assert!((r[0] - 0.01).abs() < 1e-4, "first rate {}", r[0]);
    let last = *r.last().unwrap();
    assert!(
        (0.01 * 0.05 - 1e-6..0.01 * 0.1).contains(&last),
        "last rate {last}"
    );
    let (start, end) = (
        s.initial_rmse_observed.unwrap(),
        s.final_rmse_observed.unwrap(),
    );
    assert!(end < 0.8 * start, "observed-texel RMSE {start} -> {end}");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

#[test]
fn a_run_whose_loss_does_not_fall_warns_and_says_what_to_try() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    // The texture starts at its answer (the targets are renders of the gray plane), and Adam
    // without momentum (β1 0) at a constant rate of 0.3 moves every texel by about 0.3 per
    // step on the gradient's noise alone: the loss can only rise from its start.
    let t = task(
        dir.path(),
        "iterations = 80\nstep = \"adam\"\nschedule = { kind = \"constant\" }\nadam = { beta1 = 0.0 }",
        "learning_rate = 0.3",
        "scene.glb",
    );
    let s = run(
        &gpu,
        &t,
        &RunOptions {
            out: Some(dir.path().join("out")),
            ..Default::default()
        },
    )
    .unwrap();
    let text = std::fs::read_to_string(dir.path().join("out/metrics.csv")).unwrap();
    assert_eq!(s.warnings.len(), 2, "{:?}\n{text}", s.warnings);
    let w = &s.warnings[0];
    assert!(
        w.contains("not converging") && w.contains("--step variance"),
        "{w}"
    );
    // Every evaluation after the start is worse than the start's: the run hands back the
    // start, bit for bit, and says so.
    assert!(
        s.warnings[1].contains("did not improve on its start"),
        "{:?}",
        s.warnings
    );
    let h = s.handed_back.as_ref().expect("the start is handed back");
    assert_eq!(h.iteration, 0);
    assert!(h.image_relmse < h.last_image_relmse, "{h:?}");
    assert!(s.set.values.iter().all(|&v| v == 0.5), "{:?}", s.set.values);
    assert_eq!(s.final_rmse_observed, s.initial_rmse_observed);
    // With keep_best off the same run writes its last, walked-away state.
    let t = Task {
        optimizer: psrestir::task::OptimizerSpec {
            keep_best: false,
            ..t.optimizer.clone()
        },
        ..t
    };
    let s = run(
        &gpu,
        &t,
        &RunOptions {
            out: Some(dir.path().join("out_last")),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(s.handed_back.is_none());
    assert!(
        s.final_rmse_observed.unwrap() > s.initial_rmse_observed.unwrap() + 0.01,
        "{:?} -> {:?}",
        s.initial_rmse_observed,
        s.final_rmse_observed
    );
}

/// The keeper ranks every state, the start's and the last's included, by the error of the
/// evaluation render's expectation (`image_relmse_expected`). Here the texture starts at its
/// answer and drifts on the gradient's noise by less than one evaluation render's own noise
/// (2 spp): each later state is worse than the start in expectation while its expected error
/// lies below the start's render relMSE. Ranking the start by that noisier measure would
/// hand back a drifted state; the run must hand back the start.
#[test]
fn a_drift_smaller_than_the_evaluation_noise_still_hands_back_the_start() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let t = task(
        dir.path(),
        "iterations = 40\nstep = \"adam\"\nschedule = { kind = \"constant\" }\n\
         adam = { beta1 = 0.0 }\neval_spp = 2\nstop_on_plateau = false",
        "learning_rate = 0.04",
        "scene.glb",
    );
    let out = dir.path().join("out");
    let s = run(
        &gpu,
        &t,
        &RunOptions {
            out: Some(out.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    let text = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    // (iteration, image_relmse, image_relmse_expected) of the evaluated rows.
    let evaluated: Vec<(u32, f64, f64)> = text
        .lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some((f[0].parse().ok()?, f[5].parse().ok()?, f[7].parse().ok()?))
        })
        .collect();
    assert!(evaluated.len() >= 5, "{text}");
    let (start, later) = (evaluated[0], &evaluated[1..]);
    assert_eq!(start.0, 0, "{text}");
    // The case this test is about: every later state worse than the start in expectation,
    // and better than the start's render relMSE.
    assert!(
        later.iter().all(|r| start.2 < r.2 && r.2 < start.1),
        "the drift is not in the regime the test needs:\n{text}"
    );
    let h = s.handed_back.as_ref().expect("the start is handed back");
    assert_eq!(h.iteration, 0, "{h:?}\n{text}");
    assert!(
        (h.image_relmse - start.2).abs() <= 1e-5 * start.2.abs(),
        "{h:?}"
    );
    assert!(s.set.values.iter().all(|&v| v == 0.5), "{:?}", s.set.values);
}
