//! A run that is going wrong says so: [`LossWatch`] follows the loss of each iteration and
//! warns once when, after a fair share of the budget, it has not fallen below its start.
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
        let advice = match self.step {
            StepKind::Adam => {
                "Adam moves every texel by about its learning rate per step however noisy its \
                 gradient: try the variance-scaled step (`--step variance`, or remove `step` \
                 from the task for auto's configuration) or a lower rate (`--lr-scale 0.25`)"
            }
            StepKind::Variance => {
                "try a lower learning rate (`--lr-scale 0.5`) or more gradient samples per \
                 pixel (`gradient_spp`)"
            }
        };
        Some(format!(
            "the run is not converging: after {:.0}% of its budget the loss (mean of the last \
             {WINDOW} iterations, {now:.4e}) is not below its start ({start:.4e}). {advice}; \
             and check that the targets match the scene (cameras, exposure, lights). A \
             texture that starts at its answer also gives this",
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
        let w = run(StepKind::Adam, 400, |i| {
            0.2 + 0.8 * (-(i as f64) / 50.0).exp() + 0.2 * noise(i)
        });
        assert!(w.is_empty(), "{w:?}");
    }

    #[test]
    fn a_loss_that_rises_or_stays_warns_once_after_a_quarter() {
        for (step, hint) in [
            (StepKind::Adam, "--step variance"),
            (StepKind::Variance, "--lr-scale"),
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
        assert!(run(StepKind::Adam, 2 * WINDOW - 1, |_| 1.0).is_empty());
        // Losses not measured (NaN) are skipped, not counted as a flat loss.
        assert!(run(StepKind::Adam, 400, |_| f64::NAN).is_empty());
    }
}
