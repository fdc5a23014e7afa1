//! The peers' part of the bench report: the default configuration against each peer row,
//! per scene and seed and over seeds, and the peers' forward checks.
use crate::bench::{
    BenchReport, Interval, OptimizationResult, PeerOverSeeds, RunResult, SeededScene,
};
use std::fmt::Write as _;

/// How much sooner `d` reaches `peer`'s final observed-texel RMSE than the budget: the
/// budget over the time `d`'s curve first gets there; None where it does not.
fn sooner(d: &RunResult, peer: &RunResult) -> Option<f64> {
    let budget = d.curve.last().map(|p| p.seconds)?;
    let t = d.time_to(peer.texture_rmse_observed)?;
    Some(budget / t.max(1e-3))
}

fn find<'a>(o: &'a OptimizationResult, key: &str) -> Option<&'a RunResult> {
    o.runs.iter().find(|r| r.key == key)
}

/// The default (run `default_key`) against the peer row with the lowest geometric-mean
/// observed-texel RMSE over the seeds of `optimized`; None where no peer ran.
pub fn over_seeds(optimized: &[&OptimizationResult], default_key: &str) -> Option<PeerOverSeeds> {
    let mean_log = |key: &str| -> Option<f64> {
        let logs: Vec<f64> = optimized
            .iter()
            .filter_map(|o| find(o, key).map(|r| r.texture_rmse_observed.ln()))
            .collect();
        (!logs.is_empty()).then(|| logs.iter().sum::<f64>() / logs.len() as f64)
    };
    let best = super::MITSUBA_KEYS
        .iter()
        .filter_map(|k| Some((mean_log(k)?, *k)))
        .min_by(|a, b| a.0.total_cmp(&b.0))?
        .1;
    let pairs: Vec<(&RunResult, &RunResult)> = optimized
        .iter()
        .filter_map(|o| Some((find(o, default_key)?, find(o, best)?)))
        .collect();
    let ratio = |f: fn(&RunResult) -> f64| {
        Interval::of(&pairs.iter().map(|(d, p)| f(d) / f(p)).collect::<Vec<_>>())
    };
    let reached: Vec<f64> = pairs.iter().filter_map(|(d, p)| sooner(d, p)).collect();
    Some(PeerOverSeeds {
        best: pairs.first()?.1.name.clone(),
        texture: ratio(|r| r.texture_rmse_observed),
        image: ratio(|r| r.image_relmse),
        sooner: Interval::of(&reached),
        reached: reached.len() as u32,
    })
}

/// Over seeds, per scene where Mitsuba raced: the default against Mitsuba's best row
/// (markdown; empty where it did not race).
pub fn over_seeds_markdown(scenes: &[SeededScene]) -> String {
    let show = |i: &Option<Interval>| i.map_or("–".to_string(), |i| i.show());
    let mut rows = String::new();
    for x in scenes {
        let Some(m) = &x.mitsuba else { continue };
        let _ = writeln!(
            rows,
            "| {} | {} | {} | {} | {} ({}/{}) |",
            x.name,
            m.best,
            show(&m.texture),
            show(&m.image),
            show(&m.sooner),
            m.reached,
            x.seeds
        );
    }
    if rows.is_empty() {
        return rows;
    }
    format!(
        "\nThe default against Mitsuba 3's best row (the lower geometric-mean texture error of \
         its two), paired per seed:\n\n| scene | Mitsuba's best row | the default's texture \
         RMSE ÷ its | image relMSE ÷ its | × sooner to its final texture RMSE (seeds) |\n\
         |---|---|---|---|---|\n{rows}"
    )
}

/// The section of `report.md` on the peers; empty where none raced.
pub fn markdown(r: &BenchReport) -> String {
    let mut rows = String::new();
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        let d = o
            .auto
            .default_run
            .as_ref()
            .and_then(|d| o.runs.iter().find(|r| r.name == d.name));
        let forward: Vec<String> = o
            .peer_forward
            .iter()
            .map(|f| format!("{} {:.3} ({:.3})", f.camera, f.mean_ratio, f.relmse))
            .collect();
        for p in o.runs.iter().filter(|r| super::is_peer_key(&r.key)) {
            let vs = |f: fn(&RunResult) -> f64| {
                d.map_or("–".into(), |d| format!("{:.2}", f(d) / f(p)))
            };
            let soon = d
                .and_then(|d| sooner(d, p))
                .map_or("– (not reached)".into(), |s| format!("{s:.2}"));
            let _ = writeln!(
                rows,
                "| {} | {} | {} ({:.0} ms) | {:.4} | {:.2} | {} | {} | {soon} | {} |",
                x.name,
                p.name,
                p.iterations,
                p.ms_per_iteration,
                p.texture_rmse_observed,
                p.texture_rmse_observed_ratio,
                vs(|r| r.texture_rmse_observed),
                vs(|r| r.image_relmse),
                forward.join(", "),
            );
        }
    }
    if rows.is_empty() {
        return String::new();
    }
    let mut md = String::from(
        "\n### Against Mitsuba 3\n\nMitsuba 3 (`--peers mitsuba`) on each scene as psrestir \
         loaded it: its own targets of the ground truth at the task's target spp, `prb` at \
         the task's depth, Adam from psrestir's start for the same step time with the task's \
         schedule, alone and with psrestir's smoothness prior; its JIT compilation outside the \
         clock. Scored as psrestir's runs: RMSE over the texels psrestir's cameras observe, \
         image relMSE against its own targets. The default's errors over each row's, and how \
         much sooner the default reaches the row's final texture error (its budget over the \
         time it gets there); forward: the mean of Mitsuba's target over psrestir's, per \
         camera, and in brackets the image relMSE between the two (Mitsuba's diffuse is Disney's, psrestir's Lambert × (1 − F)).\n\n\
         | scene | Mitsuba's row | iterations (ms each) | observed-texel RMSE | ÷ baseline | \
         default's texture RMSE ÷ its | default's image relMSE ÷ its | default × sooner to \
         its final texture RMSE | forward: its target mean ÷ psrestir's (relMSE) |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    md.push_str(&rows);
    if let Some(x) = r
        .scenes
        .iter()
        .filter_map(|x| x.optimization.as_ref())
        .next()
    {
        for p in x.runs.iter().filter(|r| super::is_peer_key(&r.key)) {
            let _ = writeln!(md, "\n{} on the first scene: {}.", p.name, p.settings);
        }
    }
    md
}
