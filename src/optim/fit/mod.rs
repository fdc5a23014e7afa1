//! The fit of the light and the cameras' response: the parameter table's CPU groups and
//! their steps ([`param_table`]), the cameras' exposures and white balances (`gains`), and
//! the environment's radiance ([`environment_fit`]).

pub mod environment_fit;
pub(in crate::optim) mod gains;
pub mod param_table;
