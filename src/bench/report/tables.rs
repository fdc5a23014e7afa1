//! The markdown tables of `report.md` and of `psrestir bench`'s output, one per measurement.
use crate::bench::BenchReport;
use std::fmt::Write as _;

pub(super) fn sci(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        "–".into()
    }
}

pub(super) fn ratio(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "–".into()
    }
}

/// The gradient-error table (markdown), as in `report.md` and the README.
pub fn gradient_table(r: &BenchReport) -> String {
    let mut s = String::new();
    s.push_str(
        "| scene | estimator | spp primal / gradient | ms/it ratio | baseline spp (equal time) | \
         estimator-only, equal iterations: baseline | estimator | ratio | equal time ratio | \
         total, equal iterations: baseline | estimator | ratio | equal time ratio |\n",
    );
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for x in &r.scenes {
        let _ = writeln!(
            s,
            "| {} | {} | {} / {} | {} | {} | {} | {} | **{}** | **{}** | {} | {} | **{}** | **{}** |",
            x.name,
            x.gradient_method,
            x.primal_spp,
            x.gradient_spp,
            ratio(x.ms_per_iteration_ratio),
            ratio(x.baseline_spp_equal_time),
            sci(x.gradient_relmse_estimator_only_baseline),
            sci(x.gradient_relmse_estimator_only_estimator),
            ratio(x.gradient_relmse_estimator_only_ratio),
            ratio(x.gradient_relmse_estimator_only_ratio_equal_time),
            sci(x.gradient_relmse_baseline_equal_iterations),
            sci(x.gradient_relmse_estimator),
            ratio(x.gradient_relmse_ratio_equal_iterations),
            ratio(x.gradient_relmse_ratio),
        );
    }
    s
}

/// The gradient errors per optimized texture (markdown): each texture's part of the
/// equal-iteration errors of the gradient table.
pub fn texture_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | texture | estimator-only: baseline | estimator | ratio | total: baseline | \
         estimator | ratio |\n|---|---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        for t in &x.gradient_relmse_per_texture {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | **{}** | {} | {} | **{}** |",
                x.name,
                t.texture,
                sci(t.estimator_only_baseline),
                sci(t.estimator_only_estimator),
                ratio(t.estimator_only_ratio),
                sci(t.total_baseline_equal_iterations),
                sci(t.total_estimator),
                ratio(t.total_ratio_equal_iterations),
            );
        }
    }
    s
}

/// The error of the mean of successive estimates (markdown): estimator-only, both
/// estimators under the converged adjoint.
pub fn successive_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | estimator | estimates | one estimate: ratio | mean of them: baseline | \
         estimator | ratio |\n|---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | **{}** |",
            x.name,
            x.gradient_method,
            x.successive_estimates,
            ratio(x.gradient_relmse_estimator_only_ratio),
            sci(x.gradient_relmse_mean_baseline),
            sci(x.gradient_relmse_mean_estimator),
            ratio(x.gradient_relmse_mean_ratio),
        );
    }
    s
}

/// The primal estimators' table (markdown): image error of the primal at the state after the
/// warm-up, and its GPU cost.
pub fn primal_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | primal relMSE independent | control variate | ratio | primal GPU ms independent \
         | control variate | cost ratio |\n|---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        let ms = |v: Option<f64>| v.map(|v| format!("{v:.1}")).unwrap_or_else(|| "–".into());
        let cost = match (x.primal_ms_independent, x.primal_ms_control_variate) {
            (Some(a), Some(b)) => ratio(b / a),
            _ => "–".into(),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | **{}** | {} | {} | {} |",
            x.name,
            sci(x.primal_relmse_independent),
            sci(x.primal_relmse_control_variate),
            ratio(x.primal_relmse_ratio),
            ms(x.primal_ms_independent),
            ms(x.primal_ms_control_variate),
            cost
        );
    }
    s
}

/// The equal-time optimization table (markdown): every run of every scene, the baseline with
/// Adam first, with ratios over it.
pub fn optimization_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | estimator, step | image relMSE | ÷ baseline | texture RMSE (observed) | \
         ÷ baseline | at 1/3 | end / lowest | texture RMSE (all) | ms/it | iterations |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        let _ = writeln!(
            s,
            "| {} | initial | {} | | {:.4} | | | | {:.4} | | |",
            x.name,
            sci(o.image_relmse_initial),
            o.texture_rmse_observed_initial,
            o.texture_rmse_initial,
        );
        for c in &o.runs {
            let _ = writeln!(
                s,
                "| {} | {} | {} | **{}** | {:.4} | **{}** | {:.4} | {} | {:.4} | {:.0} | {} |",
                x.name,
                c.name,
                sci(c.image_relmse),
                ratio(c.image_relmse_ratio),
                c.texture_rmse_observed,
                ratio(c.texture_rmse_observed_ratio),
                c.texture_rmse_observed_third,
                ratio(c.texture_rmse_observed / c.texture_rmse_observed_min),
                c.texture_rmse,
                c.ms_per_iteration,
                match c.kept_iteration {
                    Some(k) => format!("{} (kept {k})", c.iterations),
                    None => c.iterations.to_string(),
                },
            );
        }
    }
    s
}

/// The relit errors of the scenes whose tasks name `relight` environments (markdown; a
/// header alone when none does).
pub fn relit_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | estimator, step | relit relMSE | ÷ baseline | relit PSNR (dB) | light \
         direction error (°) | texture RMSE (observed) |\n|---|---|---|---|---|---|---|\n",
    );
    let opt = |v: Option<f64>, f: fn(f64) -> String| v.map_or("–".to_string(), f);
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        for c in o.runs.iter().filter(|c| c.relit_relmse.is_some()) {
            let _ = writeln!(
                s,
                "| {} | {} | {} | **{}** | {} | {} | {:.4} |",
                x.name,
                c.name,
                opt(c.relit_relmse, sci),
                opt(c.relit_relmse_ratio, ratio),
                opt(c.relit_psnr, |v| format!("{v:.2}")),
                opt(c.light_direction_error_deg, |v| format!("{v:.1}")),
                c.texture_rmse_observed,
            );
        }
    }
    s
}

/// Per texture of the scenes with several, each run's observed-texel RMSE at the end with its
/// ratio over the baseline's (empty when no scene has several textures).
pub fn per_texture_table(r: &BenchReport) -> String {
    let mut s = String::new();
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        if o.textures.len() < 2 {
            continue;
        }
        if s.is_empty() {
            s.push_str(
                "| scene | texture | initial | estimator, step | end | ÷ baseline |\n\
                 |---|---|---|---|---|---|\n",
            );
        }
        for (k, name) in o.textures.iter().enumerate() {
            let base = o.baseline().texture_rmse_observed_per_texture[k];
            for c in &o.runs {
                let end = c.texture_rmse_observed_per_texture[k];
                let _ = writeln!(
                    s,
                    "| {} | {name} | {:.4} | {} | {:.4} | **{}** |",
                    x.name,
                    o.texture_rmse_observed_initial_per_texture[k],
                    c.name,
                    end,
                    ratio(end / base)
                );
            }
        }
    }
    s
}

/// What `method = "auto"` picks per scene and its run's errors over the better of the
/// baseline's and ReSTIR's (both with Adam; "–" unless both ran).
pub fn auto_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | spp primal / gradient | texels | gradient samples per texel | auto picks | \
         texture ÷ best | image ÷ best |\n|---|---|---|---|---|---|---|\n",
    );
    let or_dash = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("**{}**", ratio(v)));
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        let _ = writeln!(
            s,
            "| {} | {} / {} | {} | {:.2} | {} | {} | {} |",
            x.name,
            x.primal_spp,
            x.gradient_spp,
            o.auto.texels,
            o.auto.samples_per_texel,
            o.auto.method,
            or_dash(o.auto.texture_rmse_observed_over_best),
            or_dash(o.auto.image_relmse_over_best),
        );
    }
    s
}

/// The default configuration per scene (the contender `default`): what `auto` chose, its
/// end over its start, and in each error over the run of the others that ended lowest in it
/// (a ratio above 1 is a miss of the rule's).
pub fn default_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | default (auto's choice) | texture ÷ start | lowest texture error of the others \
         | texture ÷ it | lowest image error of the others | image ÷ it |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        let Some(d) = x
            .optimization
            .as_ref()
            .and_then(|o| o.auto.default_run.as_ref())
        else {
            continue;
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | **{}** | {} | **{}** |",
            x.name,
            d.name,
            ratio(d.over_start),
            d.best,
            ratio(d.over_best),
            d.best_image,
            ratio(d.image_over_best),
        );
    }
    s
}

/// Each run's settings (tuned or the task's) and, with `--tune`, the search's score on its
/// own seed.
pub fn settings_table(r: &BenchReport) -> String {
    let mut s =
        String::from("| scene | estimator, step | settings | tuning score |\n|---|---|---|---|\n");
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        for c in &o.runs {
            let score = c.tuned.as_ref().map_or("–".to_string(), |t| {
                format!("{:.4} ({} trials)", t.score, t.trials.len())
            });
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} |",
                x.name, c.name, c.settings, score
            );
        }
    }
    s
}

/// Observed-texel RMSE along each run (at a quarter, half, three quarters and the end of
/// the budget), its lowest value and how far the end lies above it.
pub fn curve_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | estimator | ¼ | ½ | ¾ | end | lowest | end / lowest |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        // The scene's own budget (bench.json of an older psrestir: the report's).
        let budget = if x.budget_s > 0.0 {
            x.budget_s
        } else {
            r.budget_s
        };
        let runs = o
            .runs
            .iter()
            .map(|c| (c.name.clone(), &c.curve, c.texture_rmse_observed_min));
        for (name, curve, min) in runs {
            let at = |f: f64| {
                curve
                    .iter()
                    .take_while(|p| p.seconds <= f * budget)
                    .last()
                    .map_or(f64::NAN, |p| p.texture_rmse_observed)
            };
            let end = curve.last().map_or(f64::NAN, |p| p.texture_rmse_observed);
            let _ = writeln!(
                s,
                "| {} | {name} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {} |",
                x.name,
                at(0.25),
                at(0.5),
                at(0.75),
                end,
                min,
                ratio(end / min)
            );
        }
    }
    s
}

/// The seconds of optimization per run: the bench's, or the range of the tasks' own.
pub(super) fn budget_text(r: &BenchReport) -> String {
    let own = r.scenes.iter().map(|x| x.budget_s).filter(|b| *b > 0.0);
    let (lo, hi) = own.fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
    if !r.task_budgets || lo > hi {
        format!("{} s", r.budget_s)
    } else if lo == hi {
        format!("{lo} s (the tasks' own budget)")
    } else {
        format!("{lo}–{hi} s (each task's own budget)")
    }
}

/// The pipeline-creation section: each pass's first creation in the run, slowest first.
pub(crate) fn pipeline_markdown(pipelines: &[crate::gpu::PipelineTime]) -> String {
    let mut rows = pipelines.to_vec();
    rows.sort_by(|a, b| b.seconds.total_cmp(&a.seconds));
    let total: f64 = rows.iter().map(|p| p.seconds).sum();
    let mut md =
        String::from("\n## Pipeline creation\n\n| pass | seconds | where |\n|---|---:|---|\n");
    for p in &rows {
        let place = if p.ahead {
            "second device, ahead"
        } else {
            "this device"
        };
        let _ = writeln!(md, "| {} | {:.2} | {place} |", p.pass, p.seconds);
    }
    let _ = writeln!(
        md,
        "| total | {total:.2} | |\n\nEach pass the first time this run created it, shader \
         compilation included (a load instead where the driver's shader cache held it); passes \
         compiled ahead on a second device ran beside the first device's work, so the total \
         is work, not waiting. All of it happens before the clocks above start."
    );
    md
}
