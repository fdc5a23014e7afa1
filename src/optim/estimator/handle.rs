//! What names an estimator outside its folder: its handle ([`Method`]) and the tables of
//! its options, typed by the marker through which the generic registry sees the estimators.
use crate::optim::registry::Handle;

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
