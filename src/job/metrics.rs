//! What `psrestir optimize` reports while it runs: the rows of `metrics.csv` (texture and
//! image errors, measured outside the timed optimization), the mean pass times, the progress
//! bar and the log lines about observed texels and exposures; and how they are measured
//! and written (image error, texture RMSE, `metrics.csv`, `texture_errors.csv`).
use super::Problem;
use crate::image_io::{self, Image};
use crate::optim::checkpoint::MetricRow;
use crate::optim::{Optimizer, Seeds};
use crate::Result;
use std::path::Path;

/// What each iteration's row of `metrics.csv` measures, outside the timed optimization.
pub(super) struct Metrics<'a> {
    pub(super) prep: &'a Problem,
    pub(super) observed: &'a [bool],
    pub(super) eval_spp: u32,
    pub(super) eval_every: u32,
    pub(super) rmse_every: u32,
    pub(super) seed: u32,
}

impl Metrics<'_> {
    /// Texture RMSE over all texels and over the observed ones (with a ground truth).
    pub(super) fn texture_errors(&self, values: &[f32]) -> (Option<f64>, Option<f64>) {
        match &self.prep.reference {
            Some(r) => (
                self.prep.texture_rmse(values),
                Some(crate::optim::observed::rmse_observed(
                    &self.prep.set,
                    values,
                    r,
                    self.observed,
                )),
            ),
            None => (None, None),
        }
    }

    /// Image relMSE of an evaluation render against the targets, and that of its
    /// expectation ([`Evaluation`]).
    pub(super) fn eval(&self, opt: &Optimizer) -> Result<(f64, f64)> {
        let e = evaluate(opt, &self.prep.targets, self.eval_spp, self.seed)?;
        Ok((e.relmse, e.expected))
    }

    /// The row of the iteration `opt` just finished, with texture and image errors where
    /// their period falls.
    pub(super) fn row(&self, opt: &Optimizer, loss: f64, elapsed: f64) -> Result<MetricRow> {
        let (texture_rmse, texture_rmse_observed) = if opt.iteration % self.rmse_every == 0 {
            self.texture_errors(&opt.read_params()?)
        } else {
            (None, None)
        };
        let image = if self.eval_every > 0 && opt.iteration % self.eval_every == 0 {
            Some(self.eval(opt)?)
        } else {
            None
        };
        Ok(MetricRow {
            iteration: opt.iteration,
            elapsed_s: elapsed,
            loss: Some(loss),
            texture_rmse,
            texture_rmse_observed,
            image_relmse: image.map(|e| e.0),
            learning_rate: opt.last_learning_rates().first().map(|&l| l as f64),
            image_relmse_expected: image.map(|e| e.1),
        })
    }
    /// The errors of the first row, at the initial textures.
    pub(super) fn start_row(&self, opt: &Optimizer) -> Result<MetricRow> {
        let (texture_rmse, texture_rmse_observed) = self.texture_errors(&self.prep.set.values);
        let image = (self.eval_every > 0).then(|| self.eval(opt)).transpose()?;
        Ok(MetricRow {
            iteration: 0,
            elapsed_s: 0.0,
            loss: None,
            texture_rmse,
            texture_rmse_observed,
            image_relmse: image.map(|e| e.0),
            learning_rate: None,
            image_relmse_expected: image.map(|e| e.1),
        })
    }

    /// The end gets an evaluation and texture errors if its iteration had none.
    pub(super) fn complete_last(&self, rows: &mut [MetricRow], opt: &Optimizer) -> Result<()> {
        if let Some(last) = rows.last_mut() {
            if self.eval_every > 0 && last.image_relmse.is_none() {
                let (e, expected) = self.eval(opt)?;
                (last.image_relmse, last.image_relmse_expected) = (Some(e), Some(expected));
            }
            if last.texture_rmse.is_none() {
                (last.texture_rmse, last.texture_rmse_observed) =
                    self.texture_errors(&opt.read_params()?);
            }
        }
        Ok(())
    }

    /// Texture RMSE of `values` over all texels and over the observed ones, and the observed
    /// texels' initial RMSE (with a ground truth).
    pub(super) fn final_errors(&self, values: &[f32]) -> (Option<f64>, Option<f64>, Option<f64>) {
        let p = self.prep;
        let observed = |v: &[f32], r: &[f32]| {
            crate::optim::observed::rmse_observed(&p.set, v, r, self.observed)
        };
        (
            p.texture_rmse(values),
            p.reference.as_ref().map(|r| observed(values, r)),
            p.reference.as_ref().map(|r| observed(&p.set.values, r)),
        )
    }
}

impl Metrics<'_> {
    /// Per texture, its observed-texel RMSE at the initial values and at `values` (empty
    /// without a ground truth).
    pub(super) fn errors_per_texture(&self, values: &[f32]) -> Vec<TextureErrors> {
        let p = self.prep;
        let Some(r) = p.reference.as_ref() else {
            return Vec::new();
        };
        let per = |v: &[f32]| {
            crate::optim::observed::rmse_observed_per_texture(&p.set, v, r, self.observed)
        };
        let angles = |v: &[f32]| {
            crate::optim::observed::mean_angle_observed_per_texture(&p.set, v, r, self.observed)
        };
        let (a0, a1) = (angles(&p.set.values), angles(values));
        p.set
            .textures
            .iter()
            .zip(per(&p.set.values).into_iter().zip(per(values)))
            .enumerate()
            .map(|(i, (t, (a, b)))| TextureErrors {
                texture: t.name(),
                initial_rmse_observed: a,
                final_rmse_observed: b,
                angle_deg_observed: a0[i].zip(a1[i]),
            })
            .collect()
    }
}

/// Say how many texels the cameras observe.
pub(super) fn log_observed(observed: &[bool]) {
    let (n_observed, n_texels) = crate::optim::observed::observed_count(observed);
    log::info!(
        "{n_observed} of {n_texels} texels are observed by the cameras ({:.1}%); the others get \
         no gradient and keep their initial values (observed_*.png)",
        100.0 * n_observed as f64 / n_texels.max(1) as f64
    );
}

/// A progress bar over the iterations, or over the seconds of the budget when there is no
/// iteration count, at `iteration` / `elapsed` already done.
pub(super) fn progress_bar(
    max_iter: Option<u32>,
    budget: Option<f64>,
    iteration: u32,
    elapsed: f64,
) -> indicatif::ProgressBar {
    let b = match max_iter {
        Some(n) => indicatif::ProgressBar::new(n as u64),
        None => indicatif::ProgressBar::new(budget.map(|b| b.ceil() as u64).unwrap_or(0)),
    };
    b.set_style(
        indicatif::ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} {msg} ETA {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    b.set_prefix(if max_iter.is_some() {
        "iteration"
    } else {
        "seconds"
    });
    b.set_position(if max_iter.is_some() {
        iteration as u64
    } else {
        elapsed as u64
    });
    b
}

/// The progress bar's message: the last loss, texture RMSE and image relMSE.
pub(super) fn progress_message(rows: &[MetricRow]) -> String {
    let last = rows.last();
    let mut msg = format!("loss {:.3e}", last.and_then(|r| r.loss).unwrap_or(f64::NAN));
    if let Some(r) = last.and_then(|r| r.texture_rmse_observed) {
        msg.push_str(&format!(" texture RMSE {r:.4}"));
    }
    if let Some(e) = rows.iter().rev().find_map(|r| r.image_relmse) {
        msg.push_str(&format!(" image relMSE {e:.3e}"));
    }
    msg
}

/// Log the cameras' exposures and white balances.
pub(super) fn log_exposures(prep: &Problem, opt: &Optimizer) {
    let list: Vec<String> = prep
        .cameras
        .iter()
        .zip(opt.fit().exposure())
        .zip(opt.fit().white_balance())
        .map(|((&c, e), wb)| {
            format!(
                "{} {e:.4} (white balance {:.3} {:.3} {:.3})",
                prep.scene.cameras[c].name, wb[0], wb[1], wb[2]
            )
        })
        .collect();
    log::info!("exposures: {}", list.join(", "));
}

/// One optimized texture's observed-texel RMSE at the start and at the end of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureErrors {
    /// `material_slot`.
    pub texture: String,
    /// At the initial values.
    pub initial_rmse_observed: f64,
    /// At the end.
    pub final_rmse_observed: f64,
    /// A normal map's mean angle error (degrees) over its observed texels, at the start and
    /// at the end.
    pub angle_deg_observed: Option<(f64, f64)>,
}

/// A render as it is compared with its target: times the camera's gain per channel.
pub(super) fn exposed(mut img: Image, gain: [f32; 3]) -> Image {
    for p in &mut img.rgb {
        *p = std::array::from_fn(|c| p[c] * gain[c]);
    }
    img
}

/// An evaluation of the current textures on every camera: see [`evaluate`].
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// The image relMSE of the `spp`-sample renders (mean over cameras): what a user's own
    /// render at that sample count shows, its noise included.
    pub relmse: f64,
    /// The relMSE of the renders' expectation, estimated without their noise (mean over
    /// cameras): the cross term of the two halves' residuals,
    /// [`crate::optim::loss::image_relmse_cross`]. What `optimizer.keep_best` ranks states by.
    pub expected: f64,
    /// The renders, times the cameras' gains.
    pub images: Vec<Image>,
}

/// Image errors of an `spp`-sample render of every camera of `opt` against its target, with
/// the same seeds at every call, so that differences between calls are the textures', not
/// the noise's. Each camera is rendered as two independent halves (`spp - spp / 2` and
/// `spp / 2` samples, at least one each); their weighted mean is the render and gives
/// [`Evaluation::relmse`], their residuals' product [`Evaluation::expected`].
///
/// Why both: a render's relMSE is its expectation's plus its variance's share, and that
/// share can be most of it (at 16 samples, 85% on a roughness task of the scene family and
/// 97% on the bundled default task after 500 iterations) and change with the textures, so
/// that the relMSE can rise while the textures approach the truth. A state kept by it is
/// the quietest, not the closest.
pub fn evaluate(opt: &Optimizer, targets: &[Image], spp: u32, seed: u32) -> Result<Evaluation> {
    let halves = [(spp - spp / 2).max(1), (spp / 2).max(1)];
    let (mut relmse, mut expected) = (0.0, 0.0);
    let mut images = Vec::new();
    for (k, target) in targets.iter().enumerate() {
        let render = |h: u32| -> Result<Image> {
            let s = crate::optim::pass_seed(seed, u32::MAX - 2 - h, k as u32, Seeds::EVAL);
            Ok(exposed(
                opt.render(k, halves[h as usize], s)?,
                opt.fit().gains()[k],
            ))
        };
        let (a, b) = (render(0)?, render(1)?);
        let wa = halves[0] as f32 / (halves[0] + halves[1]) as f32;
        let img = Image {
            width: a.width,
            height: a.height,
            rgb: (a.rgb.iter().zip(&b.rgb))
                .map(|(x, y)| std::array::from_fn(|c| wa * x[c] + (1.0 - wa) * y[c]))
                .collect(),
        };
        relmse += crate::optim::loss::image_relmse(&img, target);
        expected += crate::optim::loss::image_relmse_cross(&a, &b, target);
        images.push(img);
    }
    let n = targets.len().max(1) as f64;
    Ok(Evaluation {
        relmse: relmse / n,
        expected: expected / n,
        images,
    })
}

/// Root-mean-square difference.
pub fn rmse(a: &[f32], b: &[f32]) -> f64 {
    let s: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    (s / a.len().max(1) as f64).sqrt()
}

/// The columns of metrics.csv.
pub const METRICS_HEADER: &str = "iteration,elapsed_s,loss,texture_rmse,texture_rmse_observed,\
     image_relmse,learning_rate,image_relmse_expected";

/// Write `texture_errors.csv` atomically: per optimized texture, its observed-texel RMSE at
/// the start and at the end of the run; where a normal map is optimized, two more columns
/// with its mean angle error in degrees (empty for the other textures).
pub fn write_texture_errors(path: &Path, errors: &[TextureErrors]) -> Result<()> {
    let angles = errors.iter().any(|t| t.angle_deg_observed.is_some());
    let mut s = String::from("texture,initial_rmse_observed,final_rmse_observed");
    s.push_str(if angles {
        ",initial_angle_deg_observed,final_angle_deg_observed\n"
    } else {
        "\n"
    });
    for t in errors {
        s.push_str(&format!(
            "{},{:.6e},{:.6e}",
            t.texture, t.initial_rmse_observed, t.final_rmse_observed
        ));
        if angles {
            match t.angle_deg_observed {
                Some((a, b)) => s.push_str(&format!(",{a:.4},{b:.4}")),
                None => s.push(','),
            }
        }
        s.push('\n');
    }
    image_io::write_atomic(path, s.as_bytes())
}

/// Write metrics.csv atomically. Empty fields: not measured at that iteration (texture
/// errors without a ground truth, image error between evaluations, the loss of the start).
pub fn write_metrics(path: &Path, rows: &[MetricRow]) -> Result<()> {
    let opt = |v: Option<f64>| {
        v.filter(|v| v.is_finite())
            .map(|v| format!("{v:.6e}"))
            .unwrap_or_default()
    };
    let mut s = format!("{METRICS_HEADER}\n");
    for r in rows {
        s.push_str(&format!(
            "{},{:.4},{},{},{},{},{},{}\n",
            r.iteration,
            r.elapsed_s,
            opt(r.loss),
            opt(r.texture_rmse),
            opt(r.texture_rmse_observed),
            opt(r.image_relmse),
            opt(r.learning_rate),
            opt(r.image_relmse_expected),
        ));
    }
    image_io::write_atomic(path, s.as_bytes())
}
