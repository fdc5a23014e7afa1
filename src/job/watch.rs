//! A run that is going wrong says so: [`LossWatch`] follows the loss of each iteration and
//! warns once when, after a fair share of the budget, it has not fallen below its start. A run
//! that has converged ends: [`PlateauWatch`] follows the loss and the evaluation image error
//! and says when both have stayed flat within their noise over a window.
use crate::optim::StepKind;

/// Iterations whose mean loss is the start, and the mean of which the present is compared.
/// The loss is a noisy estimate (the primal's few samples per pixel); 20 iterations' mean
/// has a fifth of one iteration's spread, while a run's first 20 iterations change its
/// textures by at most 20 learning rates.
pub const WINDOW: usize = 20;

/// The share of the budget (iterations or time, whichever is further along) after which the
/// watch judges: an optimization that has not lowered its loss after a quarter of its
/// budget wastes the rest.
pub const SHARE: f64 = 0.25;

/// Follows a run's loss; see the module documentation.
#[derive(Clone, Debug)]
pub struct LossWatch {
    step: StepKind,
    first: Vec<f64>,
    recent: std::collections::VecDeque<f64>,
    seen: usize,
    done: bool,
}

impl LossWatch {
    /// A watch over a run taking `step`.
    pub fn new(step: StepKind) -> LossWatch {
        LossWatch {
            step,
            first: Vec::with_capacity(WINDOW),
            recent: std::collections::VecDeque::with_capacity(WINDOW),
            seen: 0,
            done: false,
        }
    }

    /// The loss of one more iteration (non-finite: ignored), with the share of the budget
    /// done; the warning, once, when the run is going wrong.
    pub fn observe(&mut self, loss: f64, progress: f64) -> Option<String> {
        if !loss.is_finite() || self.done {
            return None;
        }
        self.seen += 1;
        if self.first.len() < WINDOW {
            self.first.push(loss);
        }
        if self.recent.len() == WINDOW {
            self.recent.pop_front();
        }
        self.recent.push_back(loss);
        // Judged once the two windows are disjoint.
        if progress < SHARE || self.seen < 2 * WINDOW {
            return None;
        }
        self.done = true;
        let mean = |v: &mut dyn Iterator<Item = &f64>| v.sum::<f64>() / WINDOW as f64;
        let (start, now) = (mean(&mut self.first.iter()), mean(&mut self.recent.iter()));
        if now < start {
            return None;
        }
        let advice = self.step.kind().if_not_converging;
        Some(format!(
            "the run is not converging: after {:.0}% of its budget the loss (mean of the last \
             {WINDOW} iterations, {now:.4e}) is not below its start ({start:.4e}). {advice}; \
             and check that the targets match the scene (cameras, exposure, lights). A \
             texture that starts at its answer also gives this",
            progress * 100.0
        ))
    }
}

/// Iterations of the window over which [`PlateauWatch`] judges a run at the least; from
/// there, the last half of the run's iterations.
pub const PLATEAU_WINDOW: usize = 60;

/// The share of the budget before which [`PlateauWatch`] never stops a run.
pub const PLATEAU_SHARE: f64 = 0.4;

/// Standard errors by which a series' fall over the window must exceed its noise to count
/// as falling.
pub const PLATEAU_SIGMAS: f64 = 1.0;

/// The share of a series' level that its fall over the rest of the budget, at its pace over
/// the window, may reach and still count as flat.
pub const PLATEAU_LEVEL: f64 = 0.01;

/// Evaluation renders (image error) a window needs before it is judged.
pub const PLATEAU_EVALUATIONS: usize = 4;

/// Follows a run's loss (every iteration) and evaluation image error (every few) and says
/// when both have stopped falling. Each is judged over the window (the last half of the
/// iterations, at least [`PLATEAU_WINDOW`]) by a least-squares line: the series is flat where
/// its fall along the line over the window is less than [`PLATEAU_SIGMAS`] standard errors
/// of that fall (the residuals' spread: the noise of a few samples per pixel), or where that
/// fall, carried on over the iterations the rest of the budget leaves at the run's pace, is
/// less than [`PLATEAU_LEVEL`] of its level (the rest of the budget would change it by less).
/// A series that rises counts as flat. The run is judged from [`PLATEAU_SHARE`] of its budget
/// on, once the window holds [`PLATEAU_EVALUATIONS`] evaluations (without evaluations, on the
/// loss alone). The constants were chosen on the scene family's train split (every stop
/// within 1.03× its run's whole-budget error, with the least budget spent): docs/studies.md,
/// "The plateau stop and the state handed back, on the family".
#[derive(Clone, Debug, Default)]
pub struct PlateauWatch {
    loss: Vec<(f64, f64)>,
    image: Vec<(f64, f64)>,
    evaluations: bool,
}

/// Whether the points (x, y) fall along their least-squares line by less than their noise,
/// or, carried on for `ahead` times the points' span, by less than [`PLATEAU_LEVEL`] of
/// their level; with the fall over the span and its standard error.
fn flat(points: &[(f64, f64)], ahead: f64) -> (bool, f64, f64) {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if n < 3.0 || sxx <= 0.0 {
        return (false, 0.0, 0.0);
    }
    let slope = sxy / sxx;
    let resid: f64 = points
        .iter()
        .map(|p| (p.1 - my - slope * (p.0 - mx)).powi(2))
        .sum();
    let se_slope = (resid / (n - 2.0) / sxx).sqrt();
    let span = points[points.len() - 1].0 - points[0].0;
    let (fall, se) = (-slope * span, se_slope * span);
    (
        fall < PLATEAU_SIGMAS * se || fall * ahead < PLATEAU_LEVEL * my.abs(),
        fall,
        se,
    )
}

impl PlateauWatch {
    /// A watch; `evaluations`: whether the run renders evaluations (image error) to judge.
    pub fn new(evaluations: bool) -> PlateauWatch {
        PlateauWatch {
            evaluations,
            ..Default::default()
        }
    }

    /// One more iteration's loss (non-finite: ignored) and image error (on the iterations
    /// that have one), with the share of the budget done; the reason to stop, once both
    /// series are flat.
    pub fn observe(
        &mut self,
        iteration: u32,
        loss: f64,
        image: Option<f64>,
        progress: f64,
    ) -> Option<String> {
        let x = f64::from(iteration);
        if loss.is_finite() {
            self.loss.push((x, loss));
        }
        if let Some(e) = image.filter(|e| e.is_finite()) {
            self.image.push((x, e));
        }
        let window = PLATEAU_WINDOW.max(self.loss.len() / 2);
        if progress < PLATEAU_SHARE || self.loss.len() < window {
            return None;
        }
        let from = self.loss[self.loss.len() - window].0;
        // The iterations the rest of the budget leaves at the run's pace, in windows.
        let left = x * (1.0 - progress) / progress.max(1e-9);
        let ahead = (left / (x - from).max(1.0)).max(0.0);
        let (loss_flat, fall, se) = flat(&self.loss[self.loss.len() - window..], ahead);
        if !loss_flat {
            return None;
        }
        let recent: Vec<(f64, f64)> = self.image.iter().copied().filter(|p| p.0 >= from).collect();
        let image_note = if self.evaluations {
            if recent.len() < PLATEAU_EVALUATIONS {
                return None;
            }
            let (image_flat, ifall, ise) = flat(&recent, ahead);
            if !image_flat {
                return None;
            }
            format!(
                " and the image error by {ifall:.3e} (noise {ise:.3e}, {} evaluations)",
                recent.len()
            )
        } else {
            String::new()
        };
        Some(format!(
            "converged: over its last {window} iterations the loss fell by {fall:.3e} (noise \
             {se:.3e}){image_note}: within their noise, or at that pace less than 1% of \
             their level over the rest of the budget; stopping at {:.0}% of the budget \
             (stop_on_plateau = false runs it all)",
            progress * 100.0
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feed `n` iterations of `loss(i)` spread evenly over the budget; the warnings.
    fn run(step: StepKind, n: usize, loss: impl Fn(usize) -> f64) -> Vec<String> {
        let mut w = LossWatch::new(step);
        (0..n)
            .filter_map(|i| w.observe(loss(i), i as f64 / n as f64))
            .collect()
    }

    /// A deterministic noise in [-0.5, 0.5).
    fn noise(i: usize) -> f64 {
        ((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as f64 / (1u64 << 24) as f64 - 0.5
    }

    #[test]
    fn a_falling_loss_gives_no_warning() {
        // Falls to a fifth, with noise of 20% of the start on each iteration.
        let w = run(StepKind::ADAM, 400, |i| {
            0.2 + 0.8 * (-(i as f64) / 50.0).exp() + 0.2 * noise(i)
        });
        assert!(w.is_empty(), "{w:?}");
    }

    #[test]
    fn a_loss_that_rises_or_stays_warns_once_after_a_quarter() {
        for (step, hint) in [
            (StepKind::ADAM, "--step variance"),
            (StepKind::VARIANCE, "--lr-scale"),
        ] {
            let mut w = LossWatch::new(step);
            let mut warned = Vec::new();
            for i in 0..400 {
                // Rises by 10% over the run, with noise.
                let loss = 1.0 + 0.1 * i as f64 / 400.0 + 0.05 * noise(i);
                if let Some(m) = w.observe(loss, i as f64 / 400.0) {
                    warned.push((i, m));
                }
            }
            assert_eq!(warned.len(), 1, "{warned:?}");
            assert_eq!(warned[0].0, 100, "judged at a quarter of the budget");
            assert!(
                warned[0].1.contains(hint) && warned[0].1.contains("25%"),
                "{warned:?}"
            );
        }
    }

    #[test]
    fn short_runs_and_missing_losses_are_not_judged() {
        // Fewer than two disjoint windows of losses: nothing to compare.
        assert!(run(StepKind::ADAM, 2 * WINDOW - 1, |_| 1.0).is_empty());
        // Losses not measured (NaN) are skipped, not counted as a flat loss.
        assert!(run(StepKind::ADAM, 400, |_| f64::NAN).is_empty());
    }

    /// Feed a plateau watch `n` iterations of `loss(i)`, an evaluation every 10 at
    /// `image(i)`, spread over the budget; the iteration it stopped at.
    fn plateau(n: u32, loss: impl Fn(f64) -> f64, image: impl Fn(f64) -> f64) -> Option<u32> {
        let mut w = PlateauWatch::new(true);
        (1..=n).find(|&i| {
            let x = f64::from(i);
            let e = (i % 10 == 0).then(|| image(x));
            w.observe(i, loss(x), e, x / f64::from(n)).is_some()
        })
    }

    #[test]
    fn a_falling_run_goes_on_and_a_flat_one_stops() {
        // Falls by a factor 5 with a time constant of 300 iterations, noise 5% of its end.
        let fall = |x: f64| 0.2 + 0.8 * (-x / 300.0).exp();
        let noisy = |x: f64| fall(x) + 0.01 * noise(x as usize);
        let stop = plateau(4000, noisy, fall).expect("the run flattens");
        // It stops once its fall at the window's pace (the last half of the run), carried
        // on over the rest of the budget, is within 1% of its level: about 10 time
        // constants (3080 here; 0.01% above the end), not at 1800, where the window's fall
        // is still 6%.
        assert!(stop > 1800, "stopped at {stop}, while still falling");
        assert!(stop < 3200, "went on to {stop}, long after it flattened");
        // A flat run stops at 40% of the budget, the earliest it may.
        let stop = plateau(1000, |x| 1.0 + 0.05 * noise(x as usize), |_| 0.3).unwrap();
        assert_eq!(stop, 400, "{stop}");
    }

    #[test]
    fn a_flat_loss_with_a_falling_image_error_goes_on() {
        // The loss's noise hides a slow fall that the evaluations (low noise) show: the run
        // goes on until the few iterations left would take less than 1% off the image
        // error (993 of 1000 here).
        let stop = plateau(
            1000,
            |x| 1.0 + 0.5 * noise(x as usize),
            |x| 0.3 - 0.2 * x / 1000.0,
        );
        assert!(stop.is_none_or(|s| s >= 990), "{stop:?}");
        // Without evaluations the loss alone decides.
        let mut w = PlateauWatch::new(false);
        let stop = (1..=1000u32).find(|&i| {
            w.observe(
                i,
                1.0 + 0.5 * noise(i as usize),
                None,
                f64::from(i) / 1000.0,
            )
            .is_some()
        });
        assert_eq!(stop, Some(400));
    }
}
