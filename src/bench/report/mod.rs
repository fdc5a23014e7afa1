//! Files of `psrestir bench`: `bench.json`, `report.md`, and per scene the error-against-time
//! plot, the gradients side by side and the final renders side by side.
use super::{BenchReport, CurvePoint, FinalImages, GradientSnapshot, SceneResult};
use crate::image_io::write_atomic;
use crate::job::plot::{captioned_row, plot, save_png, Panel, Series};
use crate::job::run::{false_color, gradient_scalars};
use crate::job::Problem;
use crate::{Error, Result};
use image::{Rgb, RgbImage};
use std::fmt::Write as _;
use std::path::Path;

/// The curves' colours, one per run in order (the baseline's first), repeating.
const COLORS: [[u8; 3]; 6] = [
    [220, 110, 20],
    [30, 90, 200],
    [40, 160, 70],
    [170, 50, 160],
    [200, 40, 40],
    [90, 90, 90],
];

/// Rows stacked vertically.
fn stack(rows: &[RgbImage]) -> RgbImage {
    let w = rows.iter().map(|r| r.width()).max().unwrap_or(1);
    let h = rows.iter().map(|r| r.height()).sum::<u32>().max(1);
    let mut out = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let mut y = 0;
    for r in rows {
        image::imageops::replace(&mut out, r, 0, y as i64);
        y += r.height();
    }
    out
}

fn srgb(img: &crate::image_io::Image) -> RgbImage {
    RgbImage::from_raw(img.width, img.height, img.to_srgb8()).unwrap_or_else(|| RgbImage::new(1, 1))
}

/// Signed false color of one texture's gradient, at a shared scale; small textures are
/// enlarged so that every tile is at least 192 pixels wide.
fn gradient_tile(prep: &Problem, g: &[f32], i: usize, scale: f32) -> RgbImage {
    let t = &prep.set.textures[i];
    let v = gradient_scalars(&prep.set, g, i);
    let bytes: Vec<u8> = v.iter().flat_map(|&x| false_color(x / scale)).collect();
    let img = RgbImage::from_raw(t.width, t.height, bytes).unwrap_or_else(|| RgbImage::new(1, 1));
    let zoom = 192u32.div_ceil(t.width.max(1)).max(1);
    if zoom > 1 {
        image::imageops::resize(
            &img,
            t.width * zoom,
            t.height * zoom,
            image::imageops::FilterType::Nearest,
        )
    } else {
        img
    }
}

/// The per-scene files: `gradients.png`, and with an optimization `error_vs_time.png` and
/// `final.png`.
pub fn write_scene_files(
    dir: &Path,
    prep: &Problem,
    r: &SceneResult,
    g: &GradientSnapshot,
    finals: Option<&FinalImages>,
) -> Result<()> {
    write_gradients(dir, prep, g)?;
    let (Some(opt), Some(finals)) = (&r.optimization, finals) else {
        return Ok(());
    };
    let series =
        |name: &str, color, c: &[CurvePoint], f: &dyn Fn(&CurvePoint) -> Option<f64>| Series {
            name: name.into(),
            color,
            points: c
                .iter()
                .filter_map(|p| f(p).map(|y| (p.seconds, y)))
                .collect(),
        };
    let panel = |title: &str, y: &str, f: &dyn Fn(&CurvePoint) -> Option<f64>| Panel {
        title: title.into(),
        y_label: y.into(),
        log_y: true,
        series: opt
            .runs
            .iter()
            .enumerate()
            .map(|(i, c)| series(&c.name, COLORS[i % COLORS.len()], &c.curve, f))
            .collect(),
        secondary: None,
    };
    let mut texture = panel(
        &format!("{}: texture RMSE over observed texels", r.name),
        "RMSE",
        &|p| Some(p.texture_rmse_observed),
    );
    texture.secondary = Some((
        "learning-rate factor".into(),
        vec![series(
            "schedule",
            [120, 120, 120],
            &opt.baseline().curve,
            &|p| p.learning_rate_factor,
        )],
    ));
    plot(
        &dir.join("error_vs_time.png"),
        "seconds of optimization",
        &[
            texture,
            panel("image relMSE (evaluation renders)", "relMSE", &|p| {
                p.image_relmse
            }),
            panel("loss", "loss", &|p| Some(p.loss)),
        ],
    )?;
    save_png(
        &dir.join("final.png"),
        &captioned_row(
            &std::iter::once(("target".to_string(), srgb(&finals.target)))
                .chain(finals.runs.iter().map(|(n, img)| (n.clone(), srgb(img))))
                .collect::<Vec<_>>(),
        )?,
    )
}

/// `gradients.png`: the reference, the baseline's and the studied estimator's gradients
/// under the converged adjoint, side by side.
fn write_gradients(dir: &Path, prep: &Problem, g: &GradientSnapshot) -> Result<()> {
    if g.reference.is_empty() {
        // Not measured (--end-to-end-only).
        return Ok(());
    }
    // Gradients: one row per texture, scaled by the reference's 99th percentile magnitude.
    let mut rows = Vec::new();
    for i in 0..prep.set.textures.len() {
        let mut mags: Vec<f32> = gradient_scalars(&prep.set, &g.reference, i)
            .iter()
            .map(|v| v.abs())
            .filter(|v| v.is_finite())
            .collect();
        mags.sort_by(f32::total_cmp);
        let scale = mags
            .get((mags.len() as f64 * 0.99) as usize)
            .copied()
            .unwrap_or(1.0)
            .max(1e-30);
        let name = prep.set.textures[i].name();
        rows.push(captioned_row(&[
            (
                format!("{name}: reference"),
                gradient_tile(prep, &g.reference, i, scale),
            ),
            (
                format!("baseline {} spp", g.baseline_spp),
                gradient_tile(prep, &g.baseline, i, scale),
            ),
            (
                g.estimator_name.clone(),
                gradient_tile(prep, &g.estimator, i, scale),
            ),
        ])?);
    }
    save_png(&dir.join("gradients.png"), &stack(&rows))
}

mod tables;
pub(crate) use tables::pipeline_markdown;
pub use tables::{
    auto_table, curve_table, default_table, gradient_table, optimization_table, per_texture_table,
    primal_table, settings_table, successive_table, texture_table,
};
use tables::{budget_text, ratio};

/// The reconstruction at equal time, the headline section of `report.md`.
fn reconstruction_markdown(r: &BenchReport) -> String {
    let mut md = String::from("## Reconstruction at equal time\n\n");
    md.push_str(&optimization_table(r));
    let _ = writeln!(
        md,
        "\nEvery estimator optimizes each scene from the same start for {} of step time \
         (evaluation renders not counted); {} of every camera against its target, texture \
         RMSE against the ground truth over the texels a camera sees, both of the state the \
         run hands back: as `psrestir optimize` does (its task's `keep_best`), the lowest \
         evaluation's (by the relMSE of its render's expectation), the start's included \
         (`kept N` in the iterations column; bench.json has the last state's errors beside \
         them, and the curve and the 1/3 column follow the run itself). Ratios are over the \
         baseline with Adam. {} {}\n",
        budget_text(r),
        r.image_error.describe(r.eval_spp),
        if r.no_priors {
            "The tasks' priors (multiscale gradient, smoothness) are off (`--no-priors`)."
        } else {
            "With the tasks' priors (multiscale gradient, smoothness prior)."
        },
        if r.tuned {
            "Each estimator runs at its own settings, chosen by `--tune` on another seed:"
        } else {
            "All run at the tasks' settings:"
        }
    );
    md.push_str(&settings_table(r));
    let relit = tables::relit_table(r);
    if relit.lines().count() > 2 {
        md.push_str(
            "\n### Relighting\n\nScenes whose task names `relight` environments: each run's \
             recovered textures (and light, where the task recovers it) and the ground truth \
             rendered under each held-out environment, compared after a per-channel scale \
             (mean over the environments); the angle between the recovered and the true \
             environment's strongest emission.\n\n",
        );
        md.push_str(&relit);
    }
    let per_texture = per_texture_table(r);
    if !per_texture.is_empty() {
        md.push_str(
            "\n### Per texture\n\nObserved-texel RMSE of each texture where a scene has \
             several: which texture the error is in.\n\n",
        );
        md.push_str(&per_texture);
    }
    let _ = write!(
        md,
        "\n### The automatic choice\n\n`method = \"auto\"` (the default of task files and \
         the command line) takes {}. Its pick's run over the better of the baseline's and \
         ReSTIR's:\n\n",
        crate::optim::estimator::auto_rule()
    );
    md.push_str(&auto_table(r));
    let defaults = default_table(r);
    if defaults.lines().count() > 2 {
        md.push_str(
            "\n### The default configuration\n\nThe contender `default` runs each scene's \
             task stripped to its scene, cameras, targets, textures and sampling, every other \
             choice `auto`'s (estimator, step, moment filter, learning rates, schedule, \
             smoothness prior); its observed-texel RMSE at the end over its start, and over the run of \
             the others that ended lowest:\n\n",
        );
        md.push_str(&defaults);
    }
    md.push_str(&crate::bench::peer::report::markdown(r));
    md.push_str("\n### Observed-texel RMSE along the run\n\n");
    md.push_str(&curve_table(r));
    md.push_str(
        "\nA run that ends well above its lowest value drifted: its steps moved texels the \
         images hardly determine. Curves per scene: `<scene>/error_vs_time.png`.\n\n",
    );
    md
}

/// Both tables, as `psrestir bench` prints them.
pub fn table(r: &BenchReport) -> String {
    let mut s = String::new();
    if !r.over_seeds.is_empty() {
        s.push_str(&crate::bench::seeds::over_seeds_table(&r.over_seeds));
        s.push('\n');
    }
    if r.scenes.iter().any(|x| x.optimization.is_some()) {
        s.push_str(&optimization_table(r));
        s.push('\n');
        s.push_str(&settings_table(r));
        s.push('\n');
        let per_texture = per_texture_table(r);
        if !per_texture.is_empty() {
            s.push_str(&per_texture);
            s.push('\n');
        }
        s.push_str(&curve_table(r));
        s.push('\n');
        s.push_str(&auto_table(r));
        s.push('\n');
        let defaults = default_table(r);
        if defaults.lines().count() > 2 {
            s.push_str(&defaults);
            s.push('\n');
        }
    }
    // Absent with --end-to-end-only.
    if !gradient_measured(r) {
        return s;
    }
    s.push_str(&primal_table(r));
    s.push('\n');
    s.push_str(&gradient_table(r));
    if r.scenes
        .iter()
        .any(|x| x.gradient_relmse_per_texture.len() > 1)
    {
        s.push('\n');
        s.push_str(&texture_table(r));
    }
    s.push('\n');
    s.push_str(&successive_table(r));
    s
}

/// Whether the primal and gradient phases ran (not with `--end-to-end-only`).
fn gradient_measured(r: &BenchReport) -> bool {
    r.scenes
        .iter()
        .any(|x| x.gradient_relmse_estimator.is_finite())
}

/// The per-pass GPU times (markdown), for every run of the equal-time phase.
pub fn pass_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | estimator, step | primal | loss | gradient | combine | priors | step | moment filter | iteration | outside the passes | state B/texel | estimator's counters per iteration |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        let Some(o) = &x.optimization else { continue };
        for c in &o.runs {
            let (name, ms, bytes) = (&c.name, c.ms_per_iteration, c.state_bytes_per_texel);
            let counters = if c.diagnostics_per_iteration.is_empty() {
                "–".to_string()
            } else {
                c.diagnostics_per_iteration
                    .iter()
                    .map(|(n, v)| format!("{n} {v:.0}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let dash_if_zero = |v: f64, digits: usize| {
                if v > 0.0 {
                    format!("{v:.digits$}")
                } else {
                    "–".into()
                }
            };
            match &c.passes {
                Some(p) => {
                    let _ = writeln!(
                        s,
                        "| {} | {name} | {:.1} | {:.1} | {:.1} | {} | {} | {:.1} | {} | {ms:.1} | {:.1} | {bytes:.0} | {counters} |",
                        x.name,
                        p.primal_ms,
                        p.loss_ms,
                        p.gradient_ms,
                        dash_if_zero(p.combine_ms, 1),
                        dash_if_zero(p.prior_ms, 2),
                        p.step_ms,
                        dash_if_zero(p.filter_ms, 2),
                        ms - p.total()
                    );
                }
                None => {
                    let _ = writeln!(
                        s,
                        "| {} | {name} | – | – | – | – | – | – | – | {ms:.1} | – | {bytes:.0} | {counters} |",
                        x.name
                    );
                }
            }
        }
    }
    s
}

/// Write `bench.json` and `report.md` into `out` (atomically).
pub fn write_report(out: &Path, r: &BenchReport) -> Result<()> {
    let json =
        serde_json::to_string_pretty(r).map_err(|e| Error::Invalid(format!("bench.json: {e}")))?;
    write_atomic(&out.join("bench.json"), json.as_bytes())?;
    write_atomic(&out.join("report.md"), report_markdown(r).as_bytes())
}

/// The header row of the headline table.
pub const HEADLINE_COLUMNS: &str = "| scene | the default (what `auto` chose) | texture RMSE ÷ baseline | \
                                    image relMSE ÷ baseline | lowest texture RMSE of all runs ÷ baseline |";

/// The headline (markdown), one row per scene: the default configuration's reconstruction
/// at equal time, its observed-texel RMSE and image relMSE over the baseline with Adam's,
/// and the run that ended with the lowest texture error with its ratio; then the adapter
/// and the budget. docs/results.md holds every run.
pub fn headline_table(r: &BenchReport) -> String {
    let mut s = format!("{HEADLINE_COLUMNS}\n|---|---|---|---|---|\n");
    if !r.over_seeds.is_empty() {
        s = crate::bench::seeds::headline_rows(&r.over_seeds);
    }
    for x in r.scenes.iter().filter(|_| r.over_seeds.is_empty()) {
        let Some(o) = &x.optimization else { continue };
        let Some(d) = o.auto.default_run.as_ref() else {
            continue;
        };
        let run = |name: &str| o.runs.iter().find(|c| c.name == name);
        let Some(default) = run(&d.name) else {
            continue;
        };
        let chose = crate::bench::Contender::chosen(&d.name);
        let best = run(&d.best).map_or("–".to_string(), |b| {
            format!("{} (**{}**)", b.name, ratio(b.texture_rmse_observed_ratio))
        });
        let _ = writeln!(
            s,
            "| {} | {chose} | **{}** | **{}** | {best} |",
            x.name,
            ratio(default.texture_rmse_observed_ratio),
            ratio(default.image_relmse_ratio),
        );
    }
    if !r.over_seeds.is_empty() {
        let _ = write!(
            s,
            "\nGeometric means over {} seeds per scene, the contenders paired within a seed \
             (same targets, same start), with 90% intervals; bold where the interval excludes 1.",
            r.seeds
        );
    }
    let _ = write!(
        s,
        "\npsrestir {} on `{}`, {} of optimization per run and scene, {}, protocol `{:?}`, \
         size scale {}, {}, {}.\n",
        r.version,
        r.adapter,
        budget_text(r),
        r.image_error.describe(r.eval_spp),
        r.protocol,
        r.scale,
        if r.no_priors {
            "no priors"
        } else {
            "the tasks' priors"
        },
        if r.tuned {
            "each estimator at its tuned settings"
        } else {
            "the tasks' settings"
        }
    );
    s
}

/// The block of README.md between these markers is the bench's headline table.
pub const HEADLINE_BEGIN: &str = "<!-- bench:headline -->";
/// End of the headline block.
pub const HEADLINE_END: &str = "<!-- /bench:headline -->";

/// `text` with what lies between the headline markers replaced by `table`.
pub fn replace_headline(text: &str, table: &str) -> std::result::Result<String, String> {
    let a = text
        .find(HEADLINE_BEGIN)
        .ok_or_else(|| format!("no `{HEADLINE_BEGIN}` marker"))?;
    let b = text[a..]
        .find(HEADLINE_END)
        .map(|i| a + i)
        .ok_or_else(|| format!("no `{HEADLINE_END}` marker after `{HEADLINE_BEGIN}`"))?;
    Ok(format!(
        "{}{HEADLINE_BEGIN}\n{}{}",
        &text[..a],
        table,
        &text[b..]
    ))
}

/// `psrestir bench --report`: the checkout's `docs/results.md` (the whole report, with the
/// command that wrote it) and the headline table in its `README.md`, under `root`.
pub fn write_docs(root: &Path, r: &BenchReport, command: &str) -> Result<()> {
    let readme = root.join("README.md");
    let text = std::fs::read_to_string(&readme).map_err(|e| Error::file(&readme, e.to_string()))?;
    // The state it measured, as the report recorded it (a bench.json of an older psrestir
    // records none: then the checkout's now).
    let at = r.source.clone().unwrap_or_else(|| source_state(root));
    let headline = format!("{}Measured at {at}.\n", headline_table(r));
    let new = replace_headline(&text, &headline).map_err(|m| Error::file(&readme, m))?;
    let docs = root.join("docs");
    if !docs.is_dir() {
        return Err(Error::file(
            &docs,
            "no such folder (run --report in the checkout)".to_string(),
        ));
    }
    let md = report_markdown(r).replacen(
        "# psrestir benchmark\n\n",
        &format!(
            "# Results\n\nWritten by `{command}` at {at}; do not edit by hand (run it again). The \
             measurements are described in [method.md](method.md#how-results-are-measured), \
             the studies behind the defaults in [studies.md](studies.md). The per-scene \
             images are in the bench's output folder.\n\n"
        ),
        1,
    );
    write_atomic(&docs.join("results.md"), md.as_bytes())?;
    write_atomic(&readme, new.as_bytes())
}

/// The checkout's commit, as the report names it: `commit <hash>`, and whether `src/` or
/// `shaders/` differ from it (what the numbers depend on).
pub fn source_state(root: &Path) -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .arg("-C")
            .arg(root)
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(hash) => match git(&["status", "--porcelain", "--", "src", "shaders"]) {
            Some(changes) if changes.is_empty() => format!("commit {hash}"),
            _ => format!("commit {hash} with uncommitted changes to src/ or shaders/"),
        },
        None => "a commit git could not name".to_string(),
    }
}

/// `report.md`: every table of the run, with what they measure.
pub fn report_markdown(r: &BenchReport) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# psrestir benchmark\n");
    let _ = writeln!(
        md,
        "psrestir {} on `{}`; protocol `{:?}`; size scale {}; gradient error of {} after {} \
         iterations (estimator-only: {} more estimates under the converged adjoint), mean of \
         {} seeds, against a reference of {} gradient spp under a {}-spp converged adjoint; \
         estimators' options over the tasks': {}; {} of optimization per estimator and \
         scene; {}.\n",
        r.version,
        r.adapter,
        r.protocol,
        r.scale,
        r.gradient_method,
        r.warmup,
        r.settle,
        r.repeats,
        r.reference_spp,
        r.reference_primal_spp,
        r.estimator_options.summary(),
        budget_text(r),
        r.image_error.describe(r.eval_spp),
    );
    if !r.over_seeds.is_empty() {
        let _ = writeln!(
            md,
            "## Over {} seeds\n\nEvery contender ran each scene with {} seeds (new targets' \
             noise, new sampling), paired within a seed; each ratio is the geometric mean of \
             the per-seed ratios with its 90% interval (Student's t on their logarithms), bold \
             where the interval excludes 1. × sooner: the baseline's budget over the time at \
             which the contender's curve first reaches the baseline's final observed-texel \
             RMSE, over the seeds where it does.\n",
            r.seeds, r.seeds
        );
        md.push_str(&crate::bench::seeds::over_seeds_table(&r.over_seeds));
        md.push_str(&crate::bench::peer::report::over_seeds_markdown(
            &r.over_seeds,
        ));
        md.push('\n');
    }
    if r.scenes.iter().any(|x| x.optimization.is_some()) {
        md.push_str(&reconstruction_markdown(r));
    }
    if gradient_measured(r) {
        md.push_str("## Primal image error\n\n");
        md.push_str(&primal_table(r));
        md.push_str(
            "\nThe primal image after the warm-up against a converged render of the same textures; \
             the control variate carries the last image forward (primal_cv.wgsl).\n\n",
        );
        md.push_str("## Gradient error\n\n");
        md.push_str(&gradient_table(r));
        md.push_str(
            "\nRatios are the estimator's over the baseline's (below 1: the estimator is better). \
             Estimator-only: both under the converged adjoint, the estimator after the \
             estimates under it named above; total: both under the adjoint of one primal render at the protocol's spp, the same \
             render for both (common random numbers: both see the same render's noise). The paper (RTX 2080 Ti, 1400² images, 2048² textures) reports gradient relMSE \
             0.23–0.32× and final image relMSE 0.18–0.73× at equal time.\n\n",
        );
        md.push_str("### Per texture\n\n");
        md.push_str(&texture_table(r));
        md.push_str(
            "\nEach texture's part of the equal-iteration errors above: the sum of its entries' \
             terms over the count of all entries, so that a scene's parts add up to its figure.\n\n",
        );
        md.push_str("### Successive estimates\n\n");
        md.push_str(&successive_table(r));
        md.push_str(
            "\nAn optimizer adds up its successive steps. The baseline's estimates are \
             independent, so the error of their mean falls as 1/n; successive estimates of an \
             estimator with reuse share samples (ReSTIR's kept ones, the recursive estimator's \
             running sum), so theirs falls more slowly. The mean of n successive \
             estimates, both under the converged adjoint at the same textures, against the mean \
             of n independent baseline estimates.\n\n",
        );
    }
    if r.scenes.iter().any(|x| x.optimization.is_some()) {
        md.push_str(
            "## GPU time per pass (ms, timestamp queries), state and the estimators' counters\n\n",
        );
        md.push_str(&pass_table(r));
        md.push_str(
            "\nIteration: the wall-clock mean of a timed step (GPU work finished); outside the \
             passes: what of it no timed pass covers (copies and clears, submission, the loss \
             readback, host work).\n",
        );
    }
    if !r.pipelines.is_empty() {
        md.push_str(&pipeline_markdown(&r.pipelines));
    }
    md.push_str("\n## Per scene\n\n");
    for x in &r.scenes {
        // The scene's folder (`vase, seed 2` is in `vase__seed_2/`).
        let dir = crate::image_io::file_safe(&x.name);
        let _ = writeln!(
            md,
            "- **{}** ({}×{}, {} camera(s), {} texels): `{dir}/gradients.png`{}",
            x.name,
            x.width,
            x.height,
            x.cameras,
            x.texels,
            if x.optimization.is_some() {
                format!(", `{dir}/error_vs_time.png`, `{dir}/final.png`")
            } else {
                String::new()
            }
        );
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_headline_block_is_replaced_between_its_markers_only() {
        let text = format!("intro\n{HEADLINE_BEGIN}\nold table\n{HEADLINE_END}\nafter\n");
        let new = replace_headline(&text, "| new |\n").unwrap();
        assert_eq!(
            new,
            format!("intro\n{HEADLINE_BEGIN}\n| new |\n{HEADLINE_END}\nafter\n")
        );
        // Again: the same result (the block does not grow).
        assert_eq!(replace_headline(&new, "| new |\n").unwrap(), new);
        assert!(replace_headline("no markers", "x").is_err());
        assert!(replace_headline(&format!("{HEADLINE_END} {HEADLINE_BEGIN}"), "x").is_err());
    }

    #[test]
    fn the_readme_has_the_headline_markers() {
        let readme =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
        replace_headline(&readme, "x").unwrap();
    }

    /// The README's headline and docs/results.md have the columns the report writes today
    /// (a table measured by an older bench would not), and name the commit they were
    /// measured at.
    #[test]
    fn the_readme_and_results_have_todays_columns() {
        let root = env!("CARGO_MANIFEST_DIR");
        let readme = std::fs::read_to_string(format!("{root}/README.md")).unwrap();
        let block = &readme[readme.find(HEADLINE_BEGIN).unwrap() + HEADLINE_BEGIN.len()..];
        let block = &block[..block.find(HEADLINE_END).unwrap()];
        let header = block.trim_start().lines().next();
        assert!(
            [
                HEADLINE_COLUMNS.to_string(),
                crate::bench::seeds::HEADLINE_COLUMNS.to_string(),
                format!(
                    "{}{}",
                    crate::bench::seeds::HEADLINE_COLUMNS,
                    crate::bench::seeds::HEADLINE_MITSUBA_COLUMNS
                ),
            ]
            .iter()
            .any(|h| header == Some(h.as_str())),
            "{header:?}"
        );
        // One row per scene, not one per run.
        assert!(
            block.lines().filter(|l| l.starts_with("| ")).count() <= 12,
            "{block}"
        );
        assert!(block.contains("Measured at commit "), "{block}");
        let results = std::fs::read_to_string(format!("{root}/docs/results.md")).unwrap();
        assert!(results.contains(" at commit "));
        let empty = |t: fn(&BenchReport) -> String| {
            let r: BenchReport = BenchReport::empty();
            t(&r).lines().next().unwrap().to_string()
        };
        for header in [
            empty(tables::optimization_table),
            empty(tables::settings_table),
            empty(pass_table),
        ] {
            assert!(results.contains(&header), "docs/results.md lacks {header}");
        }
    }
}
