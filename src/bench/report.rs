//! Files of `psrestir bench`: `bench.json`, `report.md`, and per scene the error-against-time
//! plot, the gradients side by side and the final renders side by side.
use super::{BenchReport, CurvePoint, FinalImages, GradientSnapshot, SceneResult};
use crate::image_io::{write_atomic, write_atomic_with};
use crate::optim::plot::{plot, text, Panel, Series};
use crate::optim::run::{false_color, gradient_scalars};
use crate::optim::Problem;
use crate::{Error, Result};
use image::{Rgb, RgbImage};
use std::fmt::Write as _;
use std::path::Path;

const BASELINE: [u8; 3] = [220, 110, 20];
const RESTIR: [u8; 3] = [30, 90, 200];

fn save_png(path: &Path, img: &RgbImage) -> Result<()> {
    write_atomic_with(path, |tmp| {
        img.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| Error::file(path, e.to_string()))
}

/// Tiles in a row, each under its caption, on white.
fn captioned_row(tiles: &[(String, RgbImage)]) -> RgbImage {
    let (gap, header) = (6u32, 14u32);
    let col = |t: &(String, RgbImage)| t.1.width().max(8 * t.0.chars().count() as u32);
    let w: u32 = tiles.iter().map(|t| col(t) + gap).sum::<u32>() + gap;
    let h = tiles.iter().map(|t| t.1.height()).max().unwrap_or(0) + header + gap;
    let mut out = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let mut x = gap;
    for t in tiles {
        text(&mut out, x as i64, 3, &t.0, [0, 0, 0]);
        image::imageops::replace(&mut out, &t.1, x as i64, header as i64);
        x += col(t) + gap;
    }
    out
}

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

/// The per-scene files: `error_vs_time.png`, `gradients.png`, `final.png`.
pub fn write_scene_files(
    dir: &Path,
    prep: &Problem,
    r: &SceneResult,
    g: &GradientSnapshot,
    finals: &FinalImages,
) -> Result<()> {
    let series =
        |name: &str, color, c: &[CurvePoint], f: &dyn Fn(&CurvePoint) -> Option<f64>| Series {
            name: name.into(),
            color,
            points: c
                .iter()
                .filter_map(|p| f(p).map(|y| (p.seconds, y)))
                .collect(),
        };
    let panel = |title: &str, f: &dyn Fn(&CurvePoint) -> Option<f64>| Panel {
        title: title.into(),
        series: vec![
            series("baseline", BASELINE, &r.curve_baseline, f),
            series("ReSTIR", RESTIR, &r.curve_restir, f),
        ],
    };
    plot(
        &dir.join("error_vs_time.png"),
        "seconds of optimization",
        &[
            panel(&format!("{}: texture RMSE", r.name), &|p| {
                Some(p.texture_rmse)
            }),
            panel("image relMSE", &|p| p.image_relmse),
            panel("loss", &|p| Some(p.loss)),
        ],
    )?;

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
                format!("baseline {} spp", r.baseline_spp_equal_time),
                gradient_tile(prep, &g.baseline, i, scale),
            ),
            ("ReSTIR".into(), gradient_tile(prep, &g.restir, i, scale)),
        ]));
    }
    save_png(&dir.join("gradients.png"), &stack(&rows))?;
    save_png(
        &dir.join("final.png"),
        &captioned_row(&[
            ("target".into(), srgb(&finals.target)),
            ("baseline".into(), srgb(&finals.baseline)),
            ("ReSTIR".into(), srgb(&finals.restir)),
        ]),
    )
}

fn sci(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        "–".into()
    }
}

fn ratio(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "–".into()
    }
}

/// The results table (markdown), as in `report.md` and the README.
pub fn table(r: &BenchReport) -> String {
    let mut s = String::new();
    s.push_str(
        "| scene | gradient relMSE baseline | ReSTIR | ratio | baseline spp (equal time) | \
         image relMSE baseline | ReSTIR | ratio | texture RMSE initial | baseline | ReSTIR | \
         ms/it baseline | ReSTIR | iterations baseline | ReSTIR |\n",
    );
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for x in &r.scenes {
        let _ = writeln!(
            s,
            "| {} | {} | {} | **{}** | {} | {} | {} | **{}** | {:.4} | {:.4} | {:.4} | {:.0} | {:.0} | {} | {} |",
            x.name,
            sci(x.gradient_relmse_baseline),
            sci(x.gradient_relmse_restir),
            ratio(x.gradient_relmse_ratio),
            x.baseline_spp_equal_time,
            sci(x.image_relmse_baseline),
            sci(x.image_relmse_restir),
            ratio(x.image_relmse_ratio),
            x.texture_rmse_initial,
            x.texture_rmse_baseline,
            x.texture_rmse_restir,
            x.ms_per_iteration_baseline,
            x.ms_per_iteration_restir,
            x.iterations_baseline,
            x.iterations_restir,
        );
    }
    s
}

/// The per-pass GPU times (markdown).
pub fn pass_table(r: &BenchReport) -> String {
    let mut s = String::from(
        "| scene | estimator | primal | loss | gradient / candidates | merge | Adam | state B/texel |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for x in &r.scenes {
        for (name, p, bytes) in [
            (
                "baseline",
                &x.passes_baseline,
                x.state_bytes_per_texel_baseline,
            ),
            ("ReSTIR", &x.passes_restir, x.state_bytes_per_texel),
        ] {
            match p {
                Some(p) => {
                    let _ = writeln!(
                        s,
                        "| {} | {name} | {:.1} | {:.1} | {:.1} | {} | {:.1} | {bytes:.0} |",
                        x.name,
                        p.primal_ms,
                        p.loss_ms,
                        p.gradient_ms,
                        if name == "ReSTIR" {
                            format!("{:.1}", p.merge_ms)
                        } else {
                            "–".into()
                        },
                        p.adam_ms
                    );
                }
                None => {
                    let _ = writeln!(
                        s,
                        "| {} | {name} | – | – | – | – | – | {bytes:.0} |",
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
    let mut md = String::new();
    let _ = writeln!(md, "# psrestir benchmark\n");
    let _ = writeln!(
        md,
        "psrestir {} on `{}`; {} s of optimization per estimator and scene; size scale {}; \
         gradient error after {} ReSTIR iterations, mean of {} seeds, against a {}-spp \
         reference; image error from {}-spp renders; ReSTIR M cap {}.\n",
        r.version,
        r.adapter,
        r.budget_s,
        r.scale,
        r.warmup,
        r.repeats,
        r.reference_spp,
        r.eval_spp,
        r.m_cap
    );
    md.push_str("## Equal time\n\n");
    md.push_str(&table(r));
    md.push_str(
        "\nRatios are ReSTIR / baseline (below 1: ReSTIR is better). The paper (RTX 2080 Ti, \
         1400² images, 2048² textures) reports gradient relMSE 0.23–0.32× and final image \
         relMSE 0.18–0.73× at equal time.\n\n",
    );
    md.push_str("## GPU time per pass (ms, timestamp queries) and state\n\n");
    md.push_str(&pass_table(r));
    md.push_str("\n## Per scene\n\n");
    for x in &r.scenes {
        let _ = writeln!(
            md,
            "- **{}** ({}×{}, {} camera(s), {} texels; baseline equal-iteration gradient \
             relMSE {}): `{}/error_vs_time.png`, `{}/gradients.png`, `{}/final.png`",
            x.name,
            x.width,
            x.height,
            x.cameras,
            x.texels,
            sci(x.gradient_relmse_baseline_equal_iterations),
            x.name,
            x.name,
            x.name
        );
    }
    write_atomic(&out.join("report.md"), md.as_bytes())
}
