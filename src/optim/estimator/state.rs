//! The part of an estimator's state that carries over to the next iteration, as the
//! optimizer and its checkpoints hold it.
use super::Method;
use crate::Result;

/// The part of an estimator's state that carries over to the next iteration, as the optimizer
/// and its checkpoints hold it without knowing the estimator: the method that wrote it (its
/// [`Method::name`]), named counters and named arrays of 32-bit words. Each estimator says
/// what its names mean and checks them when it restores.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EstimatorState {
    /// The [`Method::name`] of the estimator that wrote it.
    pub method: String,
    /// Named counters.
    pub counters: Vec<(String, u32)>,
    /// Named arrays of 32-bit words (floats are stored as their bits).
    pub arrays: Vec<(String, Vec<u32>)>,
}

impl EstimatorState {
    /// An empty state written by `method`.
    pub fn new(method: Method) -> EstimatorState {
        EstimatorState {
            method: method.name().to_string(),
            ..Default::default()
        }
    }

    /// The counter `name`, if the state has it.
    pub fn counter(&self, name: &str) -> Option<u32> {
        self.counters.iter().find(|(n, _)| n == name).map(|c| c.1)
    }

    /// The array `name`, if the state has it.
    pub fn array(&self, name: &str) -> Option<&[u32]> {
        self.arrays
            .iter()
            .find(|(n, _)| n == name)
            .map(|a| a.1.as_slice())
    }

    /// An error unless the state was written by `method`.
    pub fn check_method(&self, method: Method) -> Result<()> {
        if self.method == method.name() {
            return Ok(());
        }
        Err(crate::Error::Invalid(format!(
            "the saved state was written by the {} gradient estimator, not by {}; resume with \
             the same --method",
            self.method,
            method.name()
        )))
    }
}
