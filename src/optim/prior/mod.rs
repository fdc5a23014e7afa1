//! The priors the gradient passes through before the step. Each one lives in its own folder
//! and exports one value, its [`Kind`]: name, summary, options (its own type, read from the
//! task file's `[optimizer.<name>]` table), WGSL, bind groups and builder. [`REGISTRY`] lists
//! them in the order they apply, and is the one line to add for a new prior; the optimizer,
//! the task file, the command line (`--set optimizer.<name>.<key>=<value>`) and reports see a
//! kind and its table in [`Priors`] only.
//!
//! - [`smoothness`]: a term of the loss over observed neighbouring texels, whose derivative
//!   it adds to the gradient (`smoothness.wgsl`).
//! - [`multiscale`]: each texel's gradient averaged with its blocks'
//!   (`multiscale_gradient.wgsl`).
//!
//! The optimizer drives a prior through the `Prior` trait once per iteration, after the
//! estimator and before the step.
mod contract;

pub use super::registry::Options;
pub use contract::{Kind, OptionsKind, PriorFamily, Priors};
pub(crate) use contract::{Prior, Setup};

use super::registry::{self, Family};
#[cfg(test)]
use crate::gpu::GroupDecl;
use crate::Result;

// A new prior: its folder, exporting `KIND`, and its name here, where it is to apply. The
// toy (tests only) is the registry's own test: it is nothing but its folder and this entry.
registry::registry!(
    "Every prior, in the order they apply: the one place that names each folder.",
    smoothness,
    multiscale,
    #[cfg(test)]
    toy
);

impl Kind {
    /// The prior called `name`.
    pub fn by_name(name: &str) -> Option<&'static Kind> {
        REGISTRY.iter().copied().find(|k| k.name == name)
    }

    /// Every prior's name.
    pub fn names() -> Vec<&'static str> {
        REGISTRY.iter().map(|k| k.name).collect()
    }
}

impl Family for PriorFamily {
    const WHAT: &'static str = "prior";
    type Kind = Kind;
    fn registry() -> &'static [&'static Kind] {
        REGISTRY
    }
    fn name(kind: &'static Kind) -> &'static str {
        kind.name
    }
    fn options(kind: &'static Kind) -> OptionsKind {
        kind.options
    }
}

/// The priors that `priors` switch on, in the order they apply, each with its kind.
pub(crate) fn build(s: &Setup, priors: &Priors) -> Result<Vec<(&'static Kind, Box<dyn Prior>)>> {
    priors
        .active()
        .into_iter()
        .map(|k| Ok((k, (k.build)(s, priors)?)))
        .collect()
}

/// The passes the priors of `priors` create.
pub(crate) fn passes(priors: &Priors) -> Vec<&'static str> {
    priors.active().iter().map(|k| k.pass).collect()
}

/// Every prior's WGSL files.
pub(crate) fn wgsl() -> impl Iterator<Item = &'static [(&'static str, &'static str)]> {
    REGISTRY.iter().map(|k| k.wgsl)
}

/// Every prior's bind-group declarations (for the contract test).
#[cfg(test)]
pub(crate) fn groups() -> Vec<GroupDecl> {
    REGISTRY
        .iter()
        .flat_map(|k| k.groups.iter().copied())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A prior's table shares `[optimizer]` with the estimators' and the steps' tables and
    /// the priors' shorthands: no name may stand for two things, and every prior is off at its defaults.
    #[test]
    fn prior_names_are_their_own_and_every_prior_is_off_by_default() {
        let mut names: Vec<&str> = crate::optim::Method::names();
        names.extend(<crate::optim::step::StepFamily as Family>::tables());
        for k in REGISTRY {
            names.push(k.name);
            // A shorthand may be its prior's own name (`smoothness = 0.03`).
            names.extend(k.shorthand.map(|s| s.0).filter(|s| *s != k.name));
            let mut p = Priors::default();
            p.set_table(k.name, k.options.defaults());
            assert!(p.active().is_empty(), "{} is on at its defaults", k.name);
            assert_eq!(p.check(), Ok(()));
            assert_eq!(Kind::by_name(k.name).unwrap().pass, k.pass);
        }
        let n = names.len();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), n, "a name stands for two things: {names:?}");
    }
}
