//! The fit of the light and the cameras' response: the parameter table's CPU groups and
//! their steps ([`param_table`]), the cameras' exposures and white balances (`gains`), and
//! the environment's radiance (`environment`, with its options and state in
//! [`environment_fit`]). [`Fit`] owns the state and reads it;
//! [`FitMut`] changes it and uploads what the engine's passes read of it (the loss pass's
//! gains, the scene's environment). The optimizer hands out both
//! ([`Optimizer::fit`](crate::optim::Optimizer::fit),
//! [`Optimizer::fit_mut`](crate::optim::Optimizer::fit_mut)).
use crate::gpu::Gpu;
use crate::optim::loss::LossPass;
use crate::optim::Settings;
use crate::render::GpuScene;

mod environment;
pub mod environment_fit;
pub(in crate::optim) mod gains;
pub mod param_table;

/// The fit's state: the parameter table's CPU groups, the gains the last adjoint was
/// written with, and the environment's gradient and fit.
pub struct Fit {
    /// The parameter table's CPU groups (exposures, white balances, the environment when it
    /// is optimized) with their step's state.
    pub(in crate::optim) table: param_table::ParamTable,
    /// The gains the last adjoint was written with.
    pub(in crate::optim) gain_prev: Vec<[f32; 3]>,
    /// The environment's gradient (`environment.rs`), and the environment's fit when it
    /// is optimized, with the gradient updates its passes lost or dropped.
    pub(in crate::optim) env_grad: wgpu::Buffer,
    pub(in crate::optim) env_fit: Option<environment_fit::EnvFit>,
    pub(in crate::optim) env_faults: u32,
}

/// The fit at work: its state and the parts of the engine it writes to, borrowed from the
/// optimizer for one call ([`Optimizer::fit_mut`](crate::optim::Optimizer::fit_mut)).
pub struct FitMut<'a> {
    pub(in crate::optim) fit: &'a mut Fit,
    pub(in crate::optim) gpu: &'a Gpu,
    /// The uploaded scene, whose environment the fit replaces.
    pub(in crate::optim) scene: &'a mut GpuScene,
    /// The loss pass, which multiplies each camera's render by its gain.
    pub(in crate::optim) loss: &'a mut LossPass,
    pub(in crate::optim) settings: &'a Settings,
    /// How many cameras (one gain each).
    pub(in crate::optim) cameras: usize,
}
