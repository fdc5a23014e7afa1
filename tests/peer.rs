//! The bench's peers (`--peers mitsuba`) without Mitsuba: the exchange folder carries the
//! task as the bench scores it (a stand-in for the race, in plain Python, finds psrestir's
//! starting error from its start, truth and observed texels alone), the race's rows become
//! runs of the report with their ratios and the headline's columns, and a peer that is
//! missing or fails says so and leaves the bench's own runs alone. The race itself, with
//! Mitsuba, is tested in tests/python/test_mitsuba_race.py where Mitsuba is installed.
mod common;

use psrestir::bench::peer::{self, RaceInput};
use psrestir::bench::{bench, BenchOptions, Contender};
use serde_json::Value;
use std::path::Path;

/// A stand-in for `mitsuba_race.py`, run as `FAKE script exchange out`: it reads the
/// exchange's optimized textures (raw f32 start and truth, u8 observed texels), computes the
/// observed-texel RMSE of the start, and writes two rows that halve it, with a 1-s curve.
const FAKE_RACE: &str = r#"
import json, math, os, struct, sys
ex, out = sys.argv[2], sys.argv[3]
j = json.load(open(os.path.join(ex, "scene.json")))
def arr(a):
    raw = open(os.path.join(ex, a["file"]), "rb").read()
    n = len(raw) // (4 if a["dtype"] == "f32" else 1)
    assert n == math.prod(a["shape"]), (a, n)
    return struct.unpack("<%d%s" % (n, "f" if a["dtype"] == "f32" else "B"), raw)
s = n = 0
for o in j["optimized"]:
    init, truth, seen = arr(o["init"]), arr(o["truth"]), arr(o["observed"])
    c = o["init"]["shape"][2]
    for t, flag in enumerate(seen):
        if flag:
            s += sum((init[t * c + k] - truth[t * c + k]) ** 2 for k in range(c))
            n += c
start = math.sqrt(s / n)
for k, m in enumerate(j["meshes"]):
    head = open(os.path.join(ex, m["file"]), "rb").read(400).decode("latin-1")
    assert ("element face %d\n" % m["triangles"]) in head, head
assert len(j["targets"]) == len(j["cameras"]) and j["budget_s"] > 0
curve = [{"iteration": 0, "seconds": 0.0, "loss": None, "texture_rmse": start,
          "texture_rmse_observed": start},
         {"iteration": 10, "seconds": 1.0, "loss": 0.1, "texture_rmse": start / 2,
          "texture_rmse_observed": start / 2}]
row = {"learning_rate_scale": 1.0, "spp": 4, "smoothness": 0.0, "iterations": 10,
       "ms_per_iteration": 100.0, "warmup_s": 2.0, "texture_rmse_observed": start / 2,
       "texture_rmse": start / 2, "texture_rmse_observed_per_texture": [None],
       "image_relmse": 0.011, "image_relmse_expected": 0.01, "curve": curve}
rows = [dict(row, row="plain"), dict(row, row="priors", smoothness=j["smoothness"])]
fwd = [{"camera": c["name"], "mean_ratio": 1.05, "relmse": 0.002} for c in j["cameras"]]
json.dump({"mitsuba": "fake", "threads": 2, "forward": fwd, "rows": rows},
          open(os.path.join(out, "result.json"), "w"))
"#;

/// An executable that runs [`FAKE_RACE`] with the system's Python in place of the peer's
/// Python (the script path it is given is the real race's, which it ignores).
fn fake_python(dir: &Path) -> String {
    let race = dir.join("fake_race.py");
    std::fs::write(&race, FAKE_RACE).unwrap();
    let exe = dir.join("fake_python");
    std::fs::write(
        &exe,
        format!("#!/bin/sh\nexec python3 {} \"$@\"\n", race.display()),
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).unwrap();
    exe.display().to_string()
}

#[test]
fn a_peers_rows_join_the_report_scored_from_the_same_start() {
    let Some(gpu) = common::gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let split = psrestir::assets::family::Split::Train;
    // One task with a base color, direct light and a spot (train 2; the room before it has
    // paths of 3 vertices, three times the time).
    let tasks = psrestir::assets::family::write_split(&dir.path().join("family"), split, 3)
        .unwrap()
        .into_iter()
        .filter(|t| t.to_string_lossy().contains("rounded_box-base_color"))
        .collect::<Vec<_>>();
    assert_eq!(tasks.len(), 1, "{tasks:?}");
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
        mitsuba: Some(fake_python(dir.path())),
        ..Default::default()
    };
    let report = bench(&gpu, &tasks, &opts).unwrap();
    for x in &report.scenes {
        let o = x.optimization.as_ref().unwrap();
        let keys: Vec<&str> = o.runs.iter().map(|r| r.key.as_str()).collect();
        assert_eq!(&keys[2..], ["mitsuba", "mitsuba_priors"], "{keys:?}");
        let m = &o.runs[2];
        // The exchange carries the start, truth and observed texels the bench scores on.
        let start = m.curve[0].texture_rmse_observed;
        assert!(
            (start / o.texture_rmse_observed_initial - 1.0).abs() < 1e-5,
            "{start} against {}",
            o.texture_rmse_observed_initial
        );
        let ratio = m.texture_rmse_observed / o.baseline().texture_rmse_observed;
        assert!((m.texture_rmse_observed_ratio - ratio).abs() < 1e-12);
        // Scored by its render's expectation, as psrestir's own runs are, not by the
        // render's relMSE (0.011 in the fake race's rows).
        assert_eq!(m.image_relmse, 0.01);
        assert_eq!(report.image_error, psrestir::bench::ImageError::Expectation);
        assert_eq!(o.peer_forward.len(), x.cameras);
        // The default is compared with psrestir's contenders only, never with a peer.
        let d = o.auto.default_run.as_ref().unwrap();
        assert!(!d.best.contains("Mitsuba"), "{}", d.best);
    }
    let s = &report.over_seeds[0];
    let m = s
        .mitsuba
        .as_ref()
        .expect("the default against Mitsuba over seeds");
    let t = m.texture.expect("an interval");
    assert_eq!(t.n, 2);
    // The geometric mean of default / Mitsuba's row per seed.
    let per_seed = |x: &psrestir::bench::SceneResult| {
        let o = x.optimization.as_ref().unwrap();
        o.runs[1].texture_rmse_observed / o.runs[2].texture_rmse_observed
    };
    let want = (per_seed(&report.scenes[0]) * per_seed(&report.scenes[1])).sqrt();
    assert!(
        (t.mean - want).abs() < 1e-9 * want,
        "{} against {want}",
        t.mean
    );
    assert!(s.best.as_deref().is_some_and(|b| !b.starts_with("mitsuba")));
    let headline = psrestir::bench::seeds::headline_rows(&report.over_seeds);
    assert!(
        headline.starts_with(&format!(
            "{}{}",
            psrestir::bench::seeds::HEADLINE_COLUMNS,
            psrestir::bench::seeds::HEADLINE_MITSUBA_COLUMNS
        )),
        "{headline}"
    );
    let md = std::fs::read_to_string(dir.path().join("bench/report.md")).unwrap();
    assert!(md.contains("### Against Mitsuba 3"), "{md}");
    assert!(
        md.contains("The default against Mitsuba 3's best row"),
        "{md}"
    );
    let json: Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("bench/bench.json")).unwrap())
            .unwrap();
    assert!(json["over_seeds"][0]["mitsuba"]["texture"]["mean"].is_number());
}

#[test]
fn a_missing_or_failing_peer_says_what_to_do() {
    let why = peer::check_mitsuba("/nonexistent/python3").unwrap_err();
    assert!(why.contains("pip install mitsuba"), "{why}");
    // A Python without Mitsuba (the check imports it; `false` stands for a failed import).
    let why = peer::check_mitsuba("false").unwrap_err();
    assert!(why.contains("pip install mitsuba"), "{why}");
    // A race that fails is an error naming the script, which the bench turns into a warning.
    let dir = tempfile::tempdir().unwrap();
    let baseline: psrestir::bench::RunResult = serde_json::from_value(serde_json::json!({
        "name": "baseline, Adam", "key": "baseline", "method": "baseline",
        "image_relmse": 0.1, "image_relmse_ratio": 1.0, "texture_rmse": 0.2,
        "texture_rmse_observed": 0.2, "texture_rmse_observed_ratio": 1.0,
        "texture_rmse_observed_third": 0.2, "texture_rmse_observed_min": 0.2,
        "texture_rmse_observed_per_texture": [0.2], "ms_per_iteration": 10.0, "iterations": 1,
        "passes": null, "diagnostics_per_iteration": [], "state_bytes_per_texel": 16.0,
        "settings": "", "tuned": null, "relit_relmse": null, "relit_relmse_ratio": null,
        "relit_psnr": null, "light_direction_error_deg": null, "curve": []
    }))
    .unwrap();
    let input = RaceInput {
        dir: dir.path(),
        python: "false",
        tune: false,
        tune_budget_s: None,
        tuned_file: None,
        baseline: &baseline,
    };
    let err = peer::race_mitsuba(&input).unwrap_err().to_string();
    assert!(
        err.contains("mitsuba_race.py") && err.contains("failed"),
        "{err}"
    );
    // The race's output is kept beside it.
    assert!(dir.path().join("mitsuba/race.log").exists());
}
