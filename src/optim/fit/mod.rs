//! The fit of the light and the cameras' response: the parameter table's CPU groups and
//! their steps ([`param_table`]), the cameras' exposures and white balances (`gains`), and
//! the environment's radiance ([`environment_fit`]).

pub mod environment_fit;
pub(in crate::optim) mod gains;
pub mod param_table;

/// The fit's state: the parameter table's CPU groups, the gains the last adjoint was
/// written with, and the environment's gradient and fit.
pub(in crate::optim) struct Fit {
    /// The parameter table's CPU groups (exposures, white balances, the environment when it
    /// is optimized) with their step's state.
    pub(in crate::optim) table: param_table::ParamTable,
    /// The gains the last adjoint was written with.
    pub(in crate::optim) gain_prev: Vec<[f32; 3]>,
    /// The environment's gradient (`environment_fit.rs`), and the environment's fit when it
    /// is optimized, with the gradient updates its passes lost or dropped.
    pub(in crate::optim) env_grad: wgpu::Buffer,
    pub(in crate::optim) env_fit: Option<environment_fit::EnvFit>,
    pub(in crate::optim) env_faults: u32,
}
