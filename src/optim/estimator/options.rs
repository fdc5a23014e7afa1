//! Estimator options: each estimator's own type ([`Options`](super::Options)) in its folder,
//! read from its table of [`EstimatorOptions`] (the task file's `[optimizer.<method>]` tables
//! and the command line's `--estimator-option`).
use super::{EstimatorOptions, Method};
use crate::Result;

impl EstimatorOptions {
    /// Apply `METHOD.KEY=VALUE` (the value as TOML, or else as a string: `restir.m_cap=16`,
    /// `restir.confidence=candidates`).
    pub fn assign(&mut self, assignment: &str) -> Result<()> {
        let bad = |why: String| {
            crate::Error::Invalid(format!("--estimator-option `{assignment}`: {why}"))
        };
        let (path, value) = assignment
            .split_once('=')
            .ok_or_else(|| bad("expected METHOD.KEY=VALUE".into()))?;
        let (method, key) = path
            .trim()
            .split_once('.')
            .ok_or_else(|| bad("expected METHOD.KEY=VALUE".into()))?;
        let method = method.parse::<Method>().map_err(|e| bad(e.to_string()))?;
        let value = value.trim();
        let value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        self.set(method.table(), key.trim(), value);
        self.check_one(method)
            .map_err(|(key, msg)| bad(format!("{key} {msg}")))
    }
}
