//! A task that names only its scene, targets and texture runs with `auto`'s whole
//! configuration and ends below its start; a run whose loss does not fall says so.
mod common;

use psrestir::assets::authoring::{png_bytes, GltfBuilder};
use psrestir::job::run::{run, RunOptions};
use psrestir::task::Task;
use serde_json::json;
use std::path::Path;

/// A lit plane seen from above, gray, or with a 4x4 base color texture (the truth).
fn write_scene(path: &Path, textured: bool) {
    let mut b = GltfBuilder::new();
    let mut pbr = json!({"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6});
    if textured {
        let px: Vec<[u8; 4]> = (0..16u8)
            .map(|k| [30 + 14 * k, 220 - 12 * k, 50 + 40 * (k % 5), 255])
            .collect();
        let img = b.add_image_embedded("truth", &png_bytes(4, 4, &px).unwrap(), "image/png");
        let tex = b.add_texture(img, None);
        pbr = json!({"baseColorTexture": {"index": tex}, "metallicFactor": 0.0, "roughnessFactor": 0.6});
    }
    let mat = b.add_material(json!({"name": "plane", "pbrMetallicRoughness": pbr}));
    let mesh = b.add_mesh(
        "plane",
        &[
            [-1.0, 0.0, -1.0],
            [1.0, 0.0, -1.0],
            [1.0, 0.0, 1.0],
            [-1.0, 0.0, 1.0],
        ],
        Some(&[[0.0, 1.0, 0.0]; 4]),
        Some(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
        Some(&[0, 2, 1, 0, 3, 2]),
        Some(mat),
    );
    let cam = b.add_camera("top", 0.8, Some(1.0));
    let light = b.add_light(json!({"type": "point", "intensity": 6.0}));
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let n = vec![
        b.add_node(json!({"mesh": mesh})),
        b.add_node(json!({"camera": cam, "translation": [0.0, 2.6, 0.0], "rotation": [-h, 0.0, 0.0, h]})),
        b.add_node(json!({"translation": [0.3, 2.0, 0.4], "extensions": {"KHR_lights_punctual": {"light": light}}})),
    ];
    b.set_scene(&n);
    b.write_glb(path).unwrap();
}

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
    assert_eq!(c.step, psrestir::optim::StepKind::Variance);
    assert!(c.moment_filter.enabled());
    assert_eq!(c.schedule, psrestir::optim::auto::schedule());
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
        last < 0.01 * 0.1 && last >= 0.01 * 0.05 - 1e-6,
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
    assert_eq!(s.warnings.len(), 1, "{:?}\n{text}", s.warnings);
    let w = &s.warnings[0];
    assert!(
        w.contains("not converging") && w.contains("--step variance"),
        "{w}"
    );
}
