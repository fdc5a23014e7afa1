//! The estimator's counters over an equal-time run (`bench.json`'s
//! `diagnostics_per_iteration`).
use crate::optim::Optimizer;
use crate::Result;

/// The estimator's counters over a run, sampled every few iterations: the first sampled
/// iteration, the last, the sums of their differences since the first, and their values at
/// the last. 32 bits on the GPU, they may wrap over a long run, never between two samples,
/// so they are summed as wrapping differences.
#[derive(Default)]
pub(super) struct Counted(
    Option<(
        u32,
        u32,
        Vec<(&'static str, f64)>,
        crate::optim::estimator::Diagnostics,
    )>,
);

impl Counted {
    pub(super) fn sample(&mut self, opt: &Optimizer) -> Result<()> {
        let now = opt.estimator_counters()?;
        match &mut self.0 {
            None => {
                let sums = now.iter().map(|(n, _)| (*n, 0.0)).collect();
                self.0 = Some((opt.iteration, opt.iteration, sums, now));
            }
            Some((_, to, sums, last)) => {
                for ((s, (_, v)), (_, l)) in sums.iter_mut().zip(&now).zip(last.iter()) {
                    s.1 += (*v as u32).wrapping_sub(*l as u32) as f64;
                }
                *last = now;
                *to = opt.iteration;
            }
        }
        Ok(())
    }

    /// Each counter's rise per iteration between the first and the last sample.
    pub(super) fn per_iteration(self) -> Vec<(String, f64)> {
        match self.0 {
            Some((from, to, sums, _)) if to > from => sums
                .into_iter()
                .map(|(n, s)| (n.to_string(), s / (to - from) as f64))
                .collect(),
            _ => Vec::new(),
        }
    }
}
