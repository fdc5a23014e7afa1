//! The run: the loop that steps the engine for a number of iterations or a time budget
//! ([`run_loop`]), the learning-rate schedule ([`schedule`]), the seeds each pass draws from,
//! what an iteration reports and the state a checkpoint saves ([`checkpoint`]).

pub mod checkpoint;
pub mod run_loop;
pub mod schedule;
pub(in crate::optim) mod seeds;
pub(in crate::optim) mod snapshot;

/// Where a run stands, for the schedule and the log.
#[derive(Default)]
pub(in crate::optim) struct RunState {
    /// Fraction of the run done, for the learning-rate schedule.
    pub(in crate::optim) progress: f64,
    /// Learning rate of each texture in the last step.
    pub(in crate::optim) last_learning_rates: Vec<f32>,
}
