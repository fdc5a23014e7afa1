//! `psrestir bench` on one benchmark scene shrunk to 32x32 images and 64x64 textures, with a
//! one-second budget: every field of bench.json is there, finite and in range, and the
//! report, plots and images are written. The benchmark is never a timing test: nothing here
//! asserts that one estimator is faster or better.
mod common;

use psrestir::bench::{bench, resolve_scene, BenchOptions, Contender};
use psrestir::optim::estimator::restir::{
    STATE_BYTES_PER_32_TEXELS, STATE_BYTES_PER_OBSERVED_TEXEL,
};
use serde_json::Value;
use std::path::Path;

fn number(scene: &Value, key: &str) -> f64 {
    let v = scene
        .get(key)
        .unwrap_or_else(|| panic!("bench.json: scene has no `{key}`"));
    let x = v
        .as_f64()
        .unwrap_or_else(|| panic!("bench.json: `{key}` is not a number: {v}"));
    assert!(x.is_finite(), "bench.json: `{key}` is not finite: {x}");
    x
}

fn png(path: &Path) -> (u32, u32) {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (img.width(), img.height())
}

#[test]
fn bench_json_has_every_field_finite_and_in_range() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let task = resolve_scene("sphere").unwrap();
    let opts = BenchOptions {
        budget_s: 1.0,
        scale: 0.25,
        warmup: 4,
        settle: 2,
        repeats: 1,
        reference_spp: 16,
        reference_primal_spp: 64,
        eval_spp: 4,
        curve_points: 3,
        out: dir.path().to_path_buf(),
        progress: false,
        ..Default::default()
    };
    bench(&gpu, &[task], &opts).unwrap();

    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("bench.json")).unwrap())
            .unwrap();
    assert!(!json["adapter"].as_str().unwrap().is_empty());
    assert_eq!(json["budget_s"].as_f64(), Some(1.0));
    let scenes = json["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 1);
    let s = &scenes[0];
    assert_eq!(s["name"].as_str(), Some("sphere"));
    // Sizes scaled: 128 -> 32 pixels, 256 -> 64 texels, two textures.
    assert_eq!((number(s, "width"), number(s, "height")), (32.0, 32.0));
    assert_eq!(number(s, "texels"), 2.0 * 64.0 * 64.0);

    let spp = number(s, "baseline_spp_equal_time");
    assert!((1.0..=1024.0).contains(&spp), "spp {spp}");
    let check_ratio = |b: &str, r: &str, ratio: &str| {
        let (b, r, q) = (number(s, b), number(s, r), number(s, ratio));
        assert!(b > 0.0 && r > 0.0, "{ratio}: {b} {r}");
        assert!((q - r / b).abs() <= 1e-9 * q, "{ratio} {q} vs {r}/{b}");
    };
    // The gradient phase measured ReSTIR (the default) against the baseline.
    assert_eq!(s["gradient_method"].as_str(), Some("restir"));
    assert_eq!(json["gradient_method"].as_str(), Some("restir"));
    check_ratio(
        "gradient_relmse_baseline",
        "gradient_relmse_estimator",
        "gradient_relmse_ratio",
    );
    check_ratio(
        "gradient_relmse_baseline_equal_iterations",
        "gradient_relmse_estimator",
        "gradient_relmse_ratio_equal_iterations",
    );
    check_ratio(
        "gradient_relmse_estimator_only_baseline",
        "gradient_relmse_estimator_only_estimator",
        "gradient_relmse_estimator_only_ratio",
    );
    check_ratio(
        "gradient_relmse_estimator_only_baseline_equal_time",
        "gradient_relmse_estimator_only_estimator",
        "gradient_relmse_estimator_only_ratio_equal_time",
    );
    check_ratio(
        "gradient_relmse_mean_baseline",
        "gradient_relmse_mean_estimator",
        "gradient_relmse_mean_ratio",
    );
    // Per texture (the task has two): each texture's part of the equal-iteration errors, the
    // parts adding up to the scene's figures (up to the rounding of a sum in another order),
    // each part positive (every texture has samples) and its ratio its parts' quotient.
    let parts = s["gradient_relmse_per_texture"].as_array().unwrap();
    assert_eq!(parts.len(), 2);
    assert_ne!(parts[0]["texture"], parts[1]["texture"]);
    for (part, scene) in [
        (
            "estimator_only_baseline",
            "gradient_relmse_estimator_only_baseline",
        ),
        (
            "estimator_only_estimator",
            "gradient_relmse_estimator_only_estimator",
        ),
        (
            "total_baseline_equal_iterations",
            "gradient_relmse_baseline_equal_iterations",
        ),
        ("total_estimator", "gradient_relmse_estimator"),
    ] {
        let sum: f64 = parts.iter().map(|p| number(p, part)).sum();
        let whole = number(s, scene);
        assert!(
            (sum - whole).abs() <= 1e-9 * whole,
            "{part}: parts add up to {sum}, {scene} is {whole}"
        );
    }
    for p in parts {
        for (b, r, q) in [
            (
                "estimator_only_baseline",
                "estimator_only_estimator",
                "estimator_only_ratio",
            ),
            (
                "total_baseline_equal_iterations",
                "total_estimator",
                "total_ratio_equal_iterations",
            ),
        ] {
            let (b, r, q) = (number(p, b), number(p, r), number(p, q));
            assert!(b > 0.0 && r > 0.0, "{q}: {b} {r}");
            assert!((q - r / b).abs() <= 1e-9 * q, "{q} vs {r}/{b}");
        }
    }
    // The mean of 10 independent baseline estimates has a tenth of one estimate's variance;
    // both errors also hold the 16-spp reference's own, 1/16 of one estimate's variance, so
    // the expected ratio is (1/10 + 1/16) / (1 + 1/16) = 0.15. Below half leaves room for
    // the fluctuation of the one estimate. (ReSTIR's successive estimates are correlated,
    // so its mean has no such bound against one of them.)
    assert_eq!(number(s, "successive_estimates"), 10.0);
    assert!(
        number(s, "gradient_relmse_mean_baseline")
            < 0.5 * number(s, "gradient_relmse_estimator_only_baseline"),
        "the mean of independent baseline estimates gains less than 2x over one"
    );
    // Both estimators' costs were timed: an iteration of the estimator is never free, nor 100x a
    // baseline iteration.
    let ms = number(s, "ms_per_iteration_ratio");
    assert!(ms > 0.5 && ms < 100.0, "ms_per_iteration_ratio {ms}");
    // No option given over the tasks': the report says none.
    assert_eq!(s["primal"].as_str(), Some("independent"));
    assert_eq!(json["estimator_options"], serde_json::json!({}));
    for k in [
        "texture_rmse_initial",
        "texture_rmse_observed_initial",
        "observed_fraction",
    ] {
        let x = number(s, k);
        assert!(x > 0.0 && x < 1.0, "{k} {x}");
    }
    // The image error of the start is the same for all and larger than after optimizing
    // would be hard to promise in one second; only its range is checked.
    assert!(number(s, "image_relmse_initial") > 0.0);
    // Every run: the baseline with Adam first (the reference of the ratios), then the
    // default contenders: ReSTIR with Adam, the recursive estimator with Adam and with the
    // variance-scaled step, the baseline with the variance-scaled step unfiltered and
    // filtered, and the default configuration (auto's: at 0.25 gradient samples per texel
    // at depth 1, ReSTIR with Adam).
    let runs = s["runs"].as_array().unwrap();
    let names: Vec<&str> = runs.iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "baseline",
            "restir",
            "recursive",
            "recursive",
            "baseline",
            "baseline",
            "restir"
        ]
    );
    let d = &runs[6];
    assert_eq!(d["key"].as_str(), Some("default"));
    assert_eq!(d["name"].as_str(), Some("default (auto: restir, Adam)"));
    let dr = &s["auto"]["default_run"];
    let want = number(d, "texture_rmse_observed") / number(s, "texture_rmse_observed_initial");
    assert!(
        (number(dr, "over_start") - want).abs() <= 1e-9 * want,
        "{dr}"
    );
    assert!(number(dr, "over_best") > 0.0, "{dr}");
    let (base, restir) = (&runs[0], &runs[1]);
    for r in runs {
        let name = r["name"].as_str().unwrap();
        for k in [
            "texture_rmse",
            "texture_rmse_observed",
            "texture_rmse_observed_third",
        ] {
            let x = number(r, k);
            assert!(x > 0.0 && x < 1.0, "{name}: {k} {x}");
        }
        let ms = number(r, "ms_per_iteration");
        assert!(ms > 0.0 && ms < 60_000.0, "{name}: ms {ms}");
        assert!(number(r, "iterations") >= 1.0, "{name}");
        for (v, over, ratio) in [
            ("image_relmse", "image_relmse", "image_relmse_ratio"),
            (
                "texture_rmse_observed",
                "texture_rmse_observed",
                "texture_rmse_observed_ratio",
            ),
        ] {
            let q = number(r, ratio);
            let want = number(r, v) / number(base, over);
            assert!(
                (q - want).abs() <= 1e-9 * want,
                "{name}: {ratio} {q} vs {want}"
            );
        }
        // Curves start at the initial state and run to the budget.
        let pts = r["curve"].as_array().unwrap();
        assert!(pts.len() >= 2, "{name}");
        assert_eq!(pts[0]["seconds"].as_f64(), Some(0.0));
        let last = pts.last().unwrap();
        assert!(last["seconds"].as_f64().unwrap() >= 1.0);
        assert!(
            last["image_relmse"].as_f64().is_some(),
            "{name}: no final image error"
        );
    }
    // The merge's work, counted between the sampled iterations (2, 10, ...): it evaluates
    // stored paths, at most four per observed texel (the fresh and the kept one of each sign).
    // The other estimators count nothing per iteration.
    let counters = restir["diagnostics_per_iteration"].as_array().unwrap();
    if number(restir, "iterations") >= 10.0 {
        let e = counters
            .iter()
            .find(|c| c[0] == "merge evaluations")
            .map(|c| c[1].as_f64().unwrap())
            .expect("no merge evaluations");
        assert!(
            e > 0.0 && e <= 4.0 * number(s, "observed_texels"),
            "merge evaluations per iteration {e}"
        );
    }
    assert!(base["diagnostics_per_iteration"]
        .as_array()
        .unwrap()
        .is_empty());
    // ReSTIR's extra state per texel is exactly the reservoirs and headers of the observed
    // texels and the compaction map (its own variance, 12 bytes per value, is off by
    // default); buffers that scale with the image, its target adjoints and claim log among
    // them, are not counted per texel.
    let extra = number(restir, "state_bytes_per_texel") - number(base, "state_bytes_per_texel");
    let texels = number(s, "texels");
    let observed = number(s, "observed_texels");
    let expected = (observed * STATE_BYTES_PER_OBSERVED_TEXEL as f64
        + (texels / 32.0).ceil() * STATE_BYTES_PER_32_TEXELS as f64)
        / texels;
    assert!(
        (extra - expected).abs() < 1e-9 * expected,
        "{extra} bytes per texel, expected {expected}"
    );

    // `auto` on this task (2 cameras of 32², 1 gradient spp, 2 x 64² texels: 0.25 samples
    // per texel, a small texture) picks ReSTIR, and its run over the better of the
    // baseline's and ReSTIR's is ReSTIR's own error over that minimum.
    let auto = &s["auto"];
    assert_eq!(auto["method"].as_str(), Some("restir"), "{auto}");
    assert_eq!(number(auto, "samples_per_texel"), 0.25);
    assert!(auto["reason"]
        .as_str()
        .unwrap()
        .contains("0.25 gradient samples"));
    for (k, v) in [
        ("texture_rmse_observed_over_best", "texture_rmse_observed"),
        ("image_relmse_over_best", "image_relmse"),
    ] {
        let want = number(restir, v) / number(base, v).min(number(restir, v));
        let got = number(auto, k);
        assert!(
            got >= 1.0 && (got - want).abs() <= 1e-9 * want,
            "{k} {got} vs {want}"
        );
    }

    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(md.contains("| sphere |"), "{md}");
    assert!(
        md.contains("| sphere | 2 / 1 | 8192 | 0.25 | restir |"),
        "{md}"
    );
    // Per texture (the task has two): each run's observed-texel RMSE per texture, between
    // the smallest and the largest part no more than the whole (an RMSE over the union lies
    // between its parts'), and the report's table of them.
    assert_eq!(s["textures"].as_array().unwrap().len(), 2);
    for r in runs {
        let parts: Vec<f64> = r["texture_rmse_observed_per_texture"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(parts.len(), 2);
        let whole = number(r, "texture_rmse_observed");
        let (lo, hi) = (parts[0].min(parts[1]), parts[0].max(parts[1]));
        assert!(
            lo > 0.0 && lo <= whole * (1.0 + 1e-9) && whole <= hi * (1.0 + 1e-9),
            "{}: parts {parts:?}, whole {whole}",
            r["name"]
        );
    }
    assert!(md.contains("### Per texture"), "{md}");
    // bench.json holds everything the report is written from (`--report-from`): read back,
    // it writes the same report, and the headline has one row for the scene.
    let back: psrestir::bench::BenchReport =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("bench.json")).unwrap())
            .unwrap();
    assert_eq!(psrestir::bench::report::report_markdown(&back), md);
    let headline = psrestir::bench::report::headline_table(&back);
    assert_eq!(
        headline
            .lines()
            .filter(|l| l.starts_with("| sphere |"))
            .count(),
        1
    );
    assert!(
        back.source.is_some(),
        "bench.json names the commit it measured"
    );
    // Every run has its rows.
    for r in runs {
        assert!(md.contains(&format!("| sphere | {} |", r["name"].as_str().unwrap())));
    }
    // Every table row is whole: it starts and ends on its own line.
    for line in md.lines().filter(|l| l.starts_with('|')) {
        assert!(line.trim_end().ends_with('|'), "broken table row: {line}");
    }
    for line in md.lines() {
        assert!(
            !line.starts_with(" ") || !line.contains("|---"),
            "broken table: {line}"
        );
    }
    let scene_dir = dir.path().join("sphere");
    // Three panels: texture RMSE (observed texels), image relMSE, loss.
    use psrestir::job::plot::{PANEL_HEIGHT, PLOT_WIDTH};
    assert_eq!(
        png(&scene_dir.join("error_vs_time.png")),
        (PLOT_WIDTH, 3 * PANEL_HEIGHT)
    );
    let (w, h) = png(&scene_dir.join("gradients.png"));
    assert!(w >= 3 * 192 && h >= 2 * 192, "gradients.png {w}x{h}");
    let (w, h) = png(&scene_dir.join("final.png"));
    assert!(w >= 3 * 32 && h >= 32, "final.png {w}x{h}");
}

#[test]
fn bench_tunes_each_estimator_and_reports_the_reconstruction_first() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let task = resolve_scene("sphere").unwrap();
    let opts = BenchOptions {
        budget_s: 0.6,
        scale: 0.25,
        eval_spp: 4,
        curve_points: 3,
        out: dir.path().to_path_buf(),
        progress: false,
        no_priors: true,
        tune: true,
        tune_budget_s: Some(0.2),
        end_to_end_only: true,
        // The baseline and ReSTIR, whose searches the test reads (each other contender but
        // the default configuration is searched the same way, `tune_contenders`).
        contenders: vec![Contender::parse("restir").unwrap()],
        ..Default::default()
    };
    bench(&gpu, std::slice::from_ref(&task), &opts).unwrap();
    let read = || -> Value {
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("bench.json")).unwrap())
            .unwrap()
    };
    let json = read();
    assert_eq!(json["no_priors"].as_bool(), Some(true));
    assert_eq!(json["tuned"].as_bool(), Some(true));
    let s = &json["scenes"][0];
    // The gradient phase did not run: its figures are absent (NaN is written as null).
    assert!(s["gradient_relmse_estimator"].is_null());
    let runs = s["runs"].as_array().unwrap();
    for (k, method, trials) in [(0, "baseline", 6), (1, "restir", 11)] {
        let run = &runs[k];
        assert_eq!(run["method"].as_str(), Some(method));
        let t = &run["tuned"];
        let scores: Vec<f64> = t["trials"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| number(x, "score"))
            .collect();
        // Every coordinate's candidates were tried (baseline: the start, 2 learning rates,
        // 2 β1, 1 β2; ReSTIR also 2 M caps, the scheduled cap and 2 target smoothings), and
        // at most 3 more learning rates in the direction that improved.
        assert!(
            (trials..=trials + 3).contains(&scores.len()),
            "{method}: {} trials",
            scores.len()
        );
        assert!(
            scores.iter().all(|x| x.is_finite() && *x > 0.0),
            "{method}: {scores:?}"
        );
        // The chosen score is one of the trials', no worse than the start's.
        let best = number(t, "score");
        assert!(
            scores.contains(&best) && best <= scores[0],
            "{method}: {best} {scores:?}"
        );
        assert!(!run["settings"].as_str().unwrap().is_empty());
        let min = number(run, "texture_rmse_observed_min");
        let end = number(run, "texture_rmse_observed");
        assert!(min > 0.0 && min <= end, "{method}: lowest {min}, end {end}");
    }
    // The settings strings name what was chosen.
    let lr = number(&runs[1]["tuned"]["best"], "learning_rate_scale");
    assert!(runs[1]["settings"]
        .as_str()
        .unwrap()
        .contains(&format!("lr ×{lr}")));
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    let recon = md
        .find("## Reconstruction at equal time")
        .expect("no reconstruction section");
    assert!(
        md[..recon].matches("\n## ").count() == 0,
        "the reconstruction is not the report's first section"
    );
    // The phases that did not run have no section.
    assert!(!md.contains("## Primal image error") && !md.contains("## Gradient error"));
    assert!(md.contains("priors (multiscale gradient, smoothness) are off"));
    // A second run with the same options reads the search from its cache.
    let cached = dir.path().join("sphere").join("tune_restir.json");
    let before = std::fs::metadata(&cached).unwrap().modified().unwrap();
    bench(&gpu, &[task], &opts).unwrap();
    assert_eq!(
        std::fs::metadata(&cached).unwrap().modified().unwrap(),
        before
    );
    assert_eq!(read()["scenes"][0]["runs"][1]["tuned"], runs[1]["tuned"]);
}

/// `outdoor` (its task recovers the environment and names held-out skies), shrunk: every run
/// reports a relit error, its ratio, a PSNR and the recovered light's direction error, and
/// report.md has the relighting table.
#[test]
fn bench_reports_the_relit_error_of_a_scene_under_unknown_light() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let task = resolve_scene("outdoor").unwrap();
    let opts = BenchOptions {
        budget_s: 1.0,
        scale: 0.25,
        end_to_end_only: true,
        eval_spp: 4,
        curve_points: 2,
        contenders: Vec::new(),
        out: dir.path().to_path_buf(),
        progress: false,
        ..Default::default()
    };
    bench(&gpu, &[task], &opts).unwrap();
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("bench.json")).unwrap())
            .unwrap();
    let runs = json["scenes"][0]["runs"].as_array().unwrap();
    assert!(!runs.is_empty());
    for r in runs {
        let relit = number(r, "relit_relmse");
        assert!(relit > 0.0 && relit < 1.0, "relit relMSE {relit}");
        assert_eq!(number(r, "relit_relmse_ratio"), 1.0);
        assert!(number(r, "relit_psnr") > 10.0);
        let angle = number(r, "light_direction_error_deg");
        assert!((0.0..=180.0).contains(&angle), "{angle}");
    }
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(
        md.contains("### Relighting") && md.contains("| outdoor | baseline, Adam |"),
        "{md}"
    );
}

#[test]
fn bench_rejects_unknown_scenes_and_bad_options_clearly() {
    let e = resolve_scene("no_such_scene").unwrap_err().to_string();
    assert!(
        e.contains("no_such_scene") && e.contains("vase"),
        "unclear error: {e}"
    );
    let Some(gpu) = common::gpu() else { return };
    let task = resolve_scene("dish").unwrap();
    for (budget_s, scale, eval_spp, successive, what) in [
        (0.0, 1.0, 64, 10, "budget"),
        (1.0, -2.0, 64, 10, "--scale"),
        (1.0, 1.0, 0, 10, "--eval-spp"),
        (1.0, 1.0, 64, 0, "--successive"),
    ] {
        let opts = BenchOptions {
            budget_s,
            scale,
            eval_spp,
            successive,
            progress: false,
            out: std::env::temp_dir().join("psrestir-bench-never-written"),
            ..Default::default()
        };
        let e = bench(&gpu, std::slice::from_ref(&task), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains(what), "unclear error: {e}");
    }
}

#[test]
fn committed_bench_scenes_are_what_the_generator_writes() {
    let dir = tempfile::tempdir().unwrap();
    psrestir::assets::bench_scenes::write_bench_scenes(dir.path()).unwrap();
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let bench = psrestir::assets::bench_scenes::BENCH_SCENES;
    for name in bench
        .iter()
        .chain(&psrestir::assets::bench_scenes::STUDY_SCENES)
    {
        let fresh_dir = dir.path().join(name);
        let mut files: Vec<_> = std::fs::read_dir(&fresh_dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        files.sort();
        assert!(files.len() >= 3, "{name}: {files:?}");
        for f in files {
            let a = std::fs::read(fresh_dir.join(&f)).unwrap();
            let b = std::fs::read(committed.join(name).join(&f))
                .unwrap_or_else(|e| panic!("scenes/bench/{name}/{f:?}: {e}"));
            assert!(
                a == b,
                "scenes/bench/{name}/{f:?} differs from the generator: run `psrestir make-scenes`"
            );
        }
        // Every bundled task file loads.
        for e in std::fs::read_dir(committed.join(name)).unwrap() {
            let f = e.unwrap().file_name().to_string_lossy().to_string();
            if f.starts_with("task") && f.ends_with(".toml") {
                psrestir::task::Task::load(&committed.join(name).join(f)).unwrap();
            }
        }
    }
}

/// `bench --throughput` on the sphere scene shrunk to 32x32 images: the forward render counts
/// its 256² × 64 camera samples, every estimator's primal and gradient rates are positive and
/// finite, and the pipelines it created are listed once each. Nothing asserts a speed.
#[test]
fn throughput_reports_every_rate_and_pipeline() {
    let Some(gpu) = common::gpu() else { return };
    if !gpu.timestamps {
        eprintln!("skipped: no timestamp queries");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = resolve_scene("sphere").unwrap();
    let task = psrestir::bench::scaled(&psrestir::Task::load(&path).unwrap(), 0.25);
    let r = psrestir::bench::throughput::throughput(&gpu, &task, &path, dir.path()).unwrap();
    assert_eq!(r.rates[0].samples, 256 * 256 * 64);
    for method in ["baseline", "restir", "recursive"] {
        for part in ["primal", "gradient"] {
            let what = format!("{method}: {part}");
            let rate = r
                .rates
                .iter()
                .find(|x| x.what == what)
                .unwrap_or_else(|| panic!("no rate `{what}` in {:?}", r.rates));
            assert!(rate.samples > 0, "{what}: {rate:?}");
            assert!(
                rate.ms > 0.0 && rate.msamples_per_s.is_finite() && rate.msamples_per_s > 0.0,
                "{what}: {rate:?}"
            );
        }
    }
    for pass in [
        "render",
        "gradient",
        "restir_candidates",
        "recursive_gradient",
    ] {
        assert_eq!(
            r.pipelines.iter().filter(|p| p.pass == pass).count(),
            1,
            "{pass} in {:?}",
            r.pipelines
        );
    }
    let md = psrestir::bench::throughput::markdown(&r);
    assert!(md.contains("| baseline: gradient |") && md.contains("## Pipeline creation"));
}

/// A member of the scene family, benched over two seeds: each seed is a scene of its own
/// (its seed in bench.json), and `over_seeds` pairs them into intervals over two seeds that
/// report.md prints.
#[test]
fn bench_over_seeds_of_a_family_member_gives_intervals() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let split = psrestir::assets::family::Split::Train;
    let tasks =
        psrestir::assets::family::write_split(&dir.path().join("family"), split, 1).unwrap();
    let opts = BenchOptions {
        budget_s: 1.0,
        scale: 0.25,
        end_to_end_only: true,
        seeds: 2,
        eval_spp: 4,
        curve_points: 3,
        contenders: vec![Contender::AUTO],
        out: dir.path().join("bench"),
        progress: false,
        ..Default::default()
    };
    let report = bench(&gpu, &tasks, &opts).unwrap();
    assert_eq!(report.scenes.len(), 2);
    let (a, b) = (&report.scenes[0], &report.scenes[1]);
    assert_ne!(a.seed, b.seed);
    assert!(
        a.name.ends_with(", seed 0") && b.name.ends_with(", seed 1"),
        "{}",
        a.name
    );
    assert_eq!(report.over_seeds.len(), 1);
    let s = &report.over_seeds[0];
    assert_eq!(s.seeds, 2);
    assert_eq!(s.runs.len(), 1, "{s:?}");
    let t = s.runs[0].texture.expect("a texture interval");
    assert_eq!(t.n, 2);
    assert!(t.low <= t.mean && t.mean <= t.high && t.low > 0.0, "{t:?}");
    // The geometric mean of the two seeds' ratios.
    let ratio = |x: &psrestir::bench::SceneResult| {
        x.optimization.as_ref().unwrap().runs[1].texture_rmse_observed_ratio
    };
    assert!((t.mean - (ratio(a) * ratio(b)).sqrt()).abs() < 1e-9 * t.mean);
    let md = std::fs::read_to_string(dir.path().join("bench/report.md")).unwrap();
    assert!(md.contains("## Over 2 seeds"), "{md}");
}

/// The bench scores what a run of the task hands back (`optimizer.keep_best`), not its last
/// state: a plane that starts 0.02 from its gray truth under Adam without momentum at a
/// constant rate of 0.3 (every texel moves by about 0.3 per step on the gradient's noise)
/// ends far from its start, and the bench reports the start's errors, says so, and keeps the
/// last state's beside them; with `keep_best = false` it reports the last state.
#[test]
fn bench_scores_the_state_a_run_hands_back() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    common::write_plane_scene(&dir.path().join("scene.glb"), false);
    let task = |keep_best: bool| {
        let text = format!(
            "scene = \"scene.glb\"\nwidth = 32\nheight = 32\nseed = 3\n[target]\n\
             scene = \"scene.glb\"\nspp = 64\n[optimizer]\ntime_budget_s = 1\nstep = \"adam\"\n\
             keep_best = {keep_best}\nschedule = {{ kind = \"constant\" }}\n\
             adam = {{ beta1 = 0.0 }}\n[[textures]]\nmaterial = \"plane\"\n\
             slot = \"base_color\"\nresolution = [4, 4]\ninit = [0.52, 0.52, 0.52]\n\
             learning_rate = 0.3\n"
        );
        let path = dir.path().join(format!("walk_{keep_best}.toml"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let opts = BenchOptions {
        budget_s: 1.0,
        end_to_end_only: true,
        eval_spp: 4,
        curve_points: 4,
        contenders: Vec::new(),
        out: dir.path().join("bench"),
        progress: false,
        ..Default::default()
    };
    let report = bench(&gpu, &[task(true), task(false)], &opts).unwrap();
    let result = |k: usize| report.scenes[k].optimization.as_ref().unwrap();
    let (kept, last) = (result(0), result(1));
    let start = kept.texture_rmse_observed_initial;
    assert!((start - 0.02).abs() < 1e-4, "start {start}");
    let r = &kept.runs[0];
    assert_eq!(r.kept_iteration, Some(0), "{r:?}");
    assert_eq!(r.texture_rmse_observed, start);
    assert_eq!(r.image_relmse, kept.image_relmse_initial);
    let [walked, walked_image] = r.last_state_errors.expect("the last state's errors");
    assert!(walked > 3.0 * start, "last state {walked}, start {start}");
    assert!(walked_image > r.image_relmse, "{walked_image}");
    let r = &last.runs[0];
    assert_eq!((r.kept_iteration, r.last_state_errors), (None, None));
    assert!(r.texture_rmse_observed > 3.0 * start, "{r:?}");
}
