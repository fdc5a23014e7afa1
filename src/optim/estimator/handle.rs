//! What names an estimator outside its folder: its handle ([`Method`]) and the tables of
//! its options, typed by the marker through which the generic registry sees the estimators,
//! and the command line's `--estimator-option` assignments into those tables.
use crate::optim::registry::Handle;
use crate::Result;

/// The estimators as the generic registry sees them.
pub struct EstimatorFamily;

/// The gradient estimator: a handle on its [`Kind`](super::Kind) in the
/// [`REGISTRY`](super::REGISTRY). The library's
/// default is the one that ends lower on the bundled default task at equal time, each at its
/// own best settings (docs/studies.md, "Which estimator is the default"): on the machines
/// measured so far, the baseline. Task files and the command line default to
/// [`MethodChoice::Auto`](super::MethodChoice::Auto), which picks one by the task's regime.
pub type Method = Handle<EstimatorFamily>;

/// What the registry knows of an estimator's options, without their type.
pub type OptionsKind = crate::optim::registry::OptionsKind<EstimatorFamily>;

/// Every estimator's options, one table of TOML values per method name: the task file's
/// `[optimizer.<method>]` tables, with the command line's `--estimator-option
/// METHOD.KEY=VALUE` on top. The optimizer, the job and the bench only pass the tables on;
/// each estimator reads its own ([`Options`](super::Options)) and [`EstimatorOptions::check`]
/// asks each to check its table.
pub type EstimatorOptions = crate::optim::registry::Tables<EstimatorFamily>;

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
