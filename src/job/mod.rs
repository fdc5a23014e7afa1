//! Running a task: the [`Problem`] a task file describes (scene, textures, cameras, targets),
//! and [`run::run`], the optimization with progress, metrics, checkpoints and outputs. It sits
//! above [`crate::optim`] (the optimizer knows nothing of task files) and [`crate::task`].
pub mod export;
pub mod keep;
mod metrics;
mod outputs;
pub mod plot;
pub mod problem;
pub mod relight;
pub mod run;
pub mod watch;

pub use problem::Problem;
