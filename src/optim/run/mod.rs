//! The run: the loop that steps the engine for a number of iterations or a time budget
//! ([`run_loop`]), the learning-rate schedule ([`schedule`]), the seeds each pass draws from,
//! what an iteration reports and the state a checkpoint saves ([`checkpoint`]).

pub mod checkpoint;
pub mod run_loop;
pub mod schedule;
pub(in crate::optim) mod seeds;
pub(in crate::optim) mod snapshot;

use crate::render::params::ParamSet;

/// Where a run stands, for the schedule and the log.
#[derive(Default)]
pub(in crate::optim) struct RunState {
    /// Fraction of the run done, for the learning-rate schedule.
    pub(in crate::optim) progress: f64,
    /// Learning rate of each texture in the last step.
    pub(in crate::optim) last_learning_rates: Vec<f32>,
    /// The iterations the run holds, once told ([`RunState::read_length`]).
    pub(in crate::optim) length: Option<f64>,
}

impl RunState {
    /// Take the run's length (iterations) the first time it is told, and switch each
    /// texture of `set` that has a rate for long runs to it when the run holds at least
    /// its `from_iterations`; later calls change nothing (a run's rate does not flip with
    /// its pace). Returns a line for the log per texture switched.
    pub(in crate::optim) fn read_length(
        &mut self,
        iterations: f64,
        set: &mut ParamSet,
    ) -> Vec<String> {
        if self.length.is_some() || !iterations.is_finite() {
            return Vec::new();
        }
        self.length = Some(iterations);
        let mut switched = Vec::new();
        for t in &mut set.textures {
            let Some(long) = t.long_run else { continue };
            if iterations >= long.from_iterations as f64 {
                switched.push(format!(
                    "learning rate of {} {}: {} (the run holds about {iterations:.0} iterations, \
                     at least {})",
                    t.material_name,
                    t.slot.name(),
                    long.learning_rate,
                    long.from_iterations
                ));
                t.learning_rate = Some(long.learning_rate);
            }
        }
        switched
    }
}
