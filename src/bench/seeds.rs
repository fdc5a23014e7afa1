//! The bench over seeds (`--seeds S`): every scene's equal-time phase repeated with S seeds
//! (new targets' noise, new sampling), the contenders paired within each seed (same targets,
//! same start). A ratio over seeds is a geometric mean with a 90% interval (Student's t on
//! the logarithms of the per-seed ratios), and a difference counts only where its interval
//! excludes 1: one seed's ratio cannot tell a few percent from the run-to-run spread.
use super::results::{Interval, RunResult, SceneResult, SeededRun, SeededScene};
use std::fmt::Write as _;

/// The 95% quantile of Student's t with `df` degrees of freedom (the two-sided 90%
/// interval's), from the standard table; past 30, the normal's 1.645 with the table's last
/// correction.
fn t95(df: u32) -> f64 {
    const TABLE: [f64; 30] = [
        6.314, 2.920, 2.353, 2.132, 2.015, 1.943, 1.895, 1.860, 1.833, 1.812, 1.796, 1.782, 1.771,
        1.761, 1.753, 1.746, 1.740, 1.734, 1.729, 1.725, 1.721, 1.717, 1.714, 1.711, 1.708, 1.706,
        1.703, 1.701, 1.699, 1.697,
    ];
    match df {
        0 => f64::INFINITY,
        d if d <= 30 => TABLE[d as usize - 1],
        d => 1.645 + 1.56 / d as f64,
    }
}

impl Interval {
    /// Over the finite, positive `ratios` (None without any).
    pub fn of(ratios: &[f64]) -> Option<Interval> {
        let logs: Vec<f64> = ratios
            .iter()
            .filter(|r| r.is_finite() && **r > 0.0)
            .map(|r| r.ln())
            .collect();
        let n = logs.len();
        if n == 0 {
            return None;
        }
        let mean = logs.iter().sum::<f64>() / n as f64;
        let half = if n > 1 {
            let var = logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            t95(n as u32 - 1) * (var / n as f64).sqrt()
        } else {
            0.0
        };
        Some(Interval {
            mean: mean.exp(),
            low: (mean - half).exp(),
            high: (mean + half).exp(),
            n: n as u32,
        })
    }

    /// Whether the difference from 1 counts: more than one seed, and the interval excludes 1.
    pub fn counts(&self) -> bool {
        self.n > 1 && (self.high < 1.0 || self.low > 1.0)
    }

    /// `0.93 [0.88, 0.98]`, bold where it counts; the mean alone over one seed.
    pub fn show(&self) -> String {
        let text = if self.n > 1 {
            format!("{:.2} [{:.2}, {:.2}]", self.mean, self.low, self.high)
        } else {
            format!("{:.2}", self.mean)
        };
        if self.counts() {
            format!("**{text}**")
        } else {
            text
        }
    }
}

/// The scene `name` over its seeds' results `seeded` (one [`SceneResult`] per seed, with
/// the same contenders).
pub fn summarize(name: &str, seeded: &[&SceneResult]) -> SeededScene {
    let optimized: Vec<_> = seeded
        .iter()
        .filter_map(|s| s.optimization.as_ref())
        .collect();
    let keys: Vec<(String, String)> = optimized
        .first()
        .map(|o| {
            o.runs
                .iter()
                .skip(1)
                .map(|r| (r.key.clone(), r.name.clone()))
                .collect()
        })
        .unwrap_or_default();
    let per_seed = |key: &str, f: &dyn Fn(&RunResult, &RunResult) -> Option<f64>| {
        optimized
            .iter()
            .filter_map(|o| {
                let run = o.runs.iter().find(|r| r.key == key)?;
                f(run, o.baseline())
            })
            .collect::<Vec<f64>>()
    };
    let runs: Vec<SeededRun> = keys
        .iter()
        .map(|(key, name)| {
            let sooner = per_seed(key, &|r, b| {
                let budget = b.curve.last().map(|p| p.seconds)?;
                let t = r.time_to(b.texture_rmse_observed)?;
                Some(budget / t.max(1e-3))
            });
            SeededRun {
                name: name.clone(),
                key: key.clone(),
                texture: Interval::of(&per_seed(key, &|r, _| Some(r.texture_rmse_observed_ratio))),
                image: Interval::of(&per_seed(key, &|r, _| Some(r.image_relmse_ratio))),
                reached: sooner.len() as u32,
                sooner: Interval::of(&sooner),
            }
        })
        .collect();
    let default_key = optimized.first().and_then(|o| {
        let d = o.auto.default_run.as_ref()?;
        o.runs
            .iter()
            .find(|r| r.name == d.name)
            .map(|r| r.key.clone())
    });
    // The baseline (ratio 1) is a candidate too.
    let baseline_key = optimized.first().map(|o| o.baseline().key.clone());
    let best = runs
        .iter()
        .filter(|r| Some(&r.key) != default_key.as_ref() && !super::peer::is_peer_key(&r.key))
        .filter_map(|r| Some((r.texture?.mean, r.key.clone())))
        .chain(baseline_key.map(|k| (1.0, k)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k)| k);
    let paired = |f: &dyn Fn(&RunResult) -> f64| -> Option<Interval> {
        let (d, b) = (default_key.as_ref()?, best.as_ref()?);
        let ratios: Vec<f64> = optimized
            .iter()
            .filter_map(|o| {
                let find = |k: &str| o.runs.iter().find(|r| r.key == k);
                Some(f(find(d)?) / f(find(b)?))
            })
            .collect();
        Interval::of(&ratios)
    };
    SeededScene {
        name: name.to_string(),
        seeds: seeded.len() as u32,
        default_over_best_texture: paired(&|r| r.texture_rmse_observed),
        default_over_best_image: paired(&|r| r.image_relmse),
        mitsuba: default_key
            .as_deref()
            .and_then(|d| super::peer::report::over_seeds(&optimized, d)),
        runs,
        default_key,
        best,
    }
}

/// Every contender of every scene over its seeds (markdown).
pub fn over_seeds_table(scenes: &[SeededScene]) -> String {
    let mut s = String::from(
        "| scene | contender | texture RMSE ÷ baseline | image relMSE ÷ baseline | \
         reaches the baseline's final texture RMSE (× sooner; seeds) |\n|---|---|---|---|---|\n",
    );
    let show = |i: &Option<Interval>| i.map_or("–".to_string(), |i| i.show());
    for x in scenes {
        for r in &x.runs {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} ({}/{}) |",
                x.name,
                r.name,
                show(&r.texture),
                show(&r.image),
                show(&r.sooner),
                r.reached,
                x.seeds
            );
        }
    }
    s
}

/// The header row of the headline table over seeds.
pub const HEADLINE_COLUMNS: &str = "| scene | the default (what `auto` chose) | texture RMSE ÷ \
                                    baseline | image relMSE ÷ baseline | texture RMSE ÷ the \
                                    best other contender's | image relMSE ÷ its | × sooner to \
                                    the baseline's final texture RMSE |";

/// The columns the headline gains where Mitsuba 3 raced.
pub const HEADLINE_MITSUBA_COLUMNS: &str = " texture RMSE ÷ Mitsuba 3's best | image relMSE \
                                            ÷ its | × sooner to its final texture RMSE |";

/// The headline over seeds: per scene the default configuration's ratios over the baseline
/// and over the contender with the lowest geometric-mean texture error, each with its 90%
/// interval (bold where it excludes 1).
///
/// Where Mitsuba 3 raced (`--peers mitsuba`), three columns more
/// ([`HEADLINE_MITSUBA_COLUMNS`]): the default's errors over Mitsuba's best row and how much
/// sooner it reaches that row's final texture error.
pub fn headline_rows(scenes: &[SeededScene]) -> String {
    let peer = scenes.iter().any(|x| x.mitsuba.is_some());
    let mut s = if peer {
        format!("{HEADLINE_COLUMNS}{HEADLINE_MITSUBA_COLUMNS}\n|---|---|---|---|---|---|---|---|---|---|\n")
    } else {
        format!("{HEADLINE_COLUMNS}\n|---|---|---|---|---|---|---|\n")
    };
    let show = |i: &Option<Interval>| i.map_or("–".to_string(), |i| i.show());
    for x in scenes {
        let Some(d) = x
            .runs
            .iter()
            .find(|r| Some(&r.key) == x.default_key.as_ref())
        else {
            continue;
        };
        let chose = super::Contender::chosen(&d.name);
        // The best is a run of the table, or else the baseline with Adam (ratio 1).
        let best = match &x.best {
            Some(k) => {
                (x.runs.iter().find(|r| &r.key == k)).map_or("baseline, Adam", |r| r.name.as_str())
            }
            None => "–",
        };
        let _ = write!(
            s,
            "| {} | {chose} | {} | {} | {} ({best}) | {} | {} ({}/{}) |",
            x.name,
            show(&d.texture),
            show(&d.image),
            show(&x.default_over_best_texture),
            show(&x.default_over_best_image),
            show(&d.sooner),
            d.reached,
            x.seeds,
        );
        match (&x.mitsuba, peer) {
            (Some(m), _) => {
                let _ = write!(
                    s,
                    " {} ({}) | {} | {} ({}/{}) |",
                    show(&m.texture),
                    m.best,
                    show(&m.image),
                    show(&m.sooner),
                    m.reached,
                    x.seeds
                );
            }
            (None, true) => s.push_str(" – | – | – |"),
            (None, false) => {}
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The interval of known logarithms: mean ± t(0.95, n − 1) · s / √n, exponentiated.
    #[test]
    fn interval_on_the_logarithms() {
        let r = [0.9f64, 1.0, 1.1];
        let i = Interval::of(&r).unwrap();
        let logs: Vec<f64> = r.iter().map(|x| x.ln()).collect();
        let m = logs.iter().sum::<f64>() / 3.0;
        let s = (logs.iter().map(|l| (l - m).powi(2)).sum::<f64>() / 2.0).sqrt();
        assert!((i.mean - m.exp()).abs() < 1e-12);
        assert!((i.high - (m + 2.920 * s / 3f64.sqrt()).exp()).abs() < 1e-12);
        assert!((i.low * i.high - i.mean * i.mean).abs() < 1e-12);
        assert!(!i.counts(), "{i:?} contains 1");
        // Five seeds all about 10% lower: the interval excludes 1.
        let i = Interval::of(&[0.88, 0.9, 0.91, 0.89, 0.92]).unwrap();
        assert!(i.counts() && i.high < 1.0, "{i:?}");
        assert!(i.show().starts_with("**0.90 ["), "{}", i.show());
        // One seed never counts; non-finite ratios are left out.
        let one = Interval::of(&[0.5, f64::NAN]).unwrap();
        assert_eq!((one.n, one.counts(), one.show()), (1, false, "0.50".into()));
        assert!(Interval::of(&[]).is_none());
    }

    /// The time to a level is read off the curve, linear between points; never reached:
    /// None.
    #[test]
    fn time_to_a_level() {
        let mut run: RunResult = serde_json::from_value(serde_json::json!({
            "name": "x", "key": "x", "method": "baseline", "image_relmse": 1.0,
            "image_relmse_ratio": 1.0, "texture_rmse": 1.0, "texture_rmse_observed": 1.0,
            "texture_rmse_observed_ratio": 1.0, "texture_rmse_observed_third": 1.0,
            "texture_rmse_observed_min": 1.0, "texture_rmse_observed_per_texture": [],
            "ms_per_iteration": 1.0, "iterations": 1, "passes": null,
            "diagnostics_per_iteration": [], "state_bytes_per_texel": 0.0, "settings": "",
            "tuned": null, "relit_relmse": null, "relit_relmse_ratio": null,
            "relit_psnr": null, "light_direction_error_deg": null, "curve": []
        }))
        .unwrap();
        for (s, e) in [(0.0, 0.4), (10.0, 0.2), (20.0, 0.1)] {
            run.curve.push(super::super::results::CurvePoint {
                iteration: 0,
                seconds: s,
                loss: 0.0,
                texture_rmse: e,
                texture_rmse_observed: e,
                learning_rate_factor: None,
                image_relmse: None,
            });
        }
        assert!((run.time_to(0.3).unwrap() - 5.0).abs() < 1e-9);
        assert_eq!(run.time_to(0.1), Some(20.0));
        assert_eq!(run.time_to(0.05), None);
    }
}
