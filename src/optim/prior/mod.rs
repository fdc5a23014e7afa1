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
use super::timing::PassTimer;
use crate::gpu::{Gpu, GroupDecl};
use crate::render::params::ParamSet;
use crate::Result;
use std::collections::BTreeMap;

// A new prior: its folder, exporting `KIND`, and its name here, where it is to apply. The
// toy (tests only) is the registry's own test: it is nothing but its folder and this entry.
super::registry!(
    "Every prior, in the order they apply: the one place that names each folder.",
    smoothness,
    multiscale,
    #[cfg(test)]
    toy
);

/// A prior as its folder exports it: everything the rest of the crate knows of it.
pub struct Kind {
    /// Its name: the task file's `[optimizer.<name>]` table.
    pub name: &'static str,
    /// What it does, in one line.
    pub summary: &'static str,
    /// Its options.
    pub options: OptionsKind,
    /// A task-file key under `[optimizer]` that sets one of its options by a bare value,
    /// and that option (`smoothness = 0.03` for `[optimizer.smoothness] weight = 0.03`).
    pub shorthand: Option<(&'static str, &'static str)>,
    /// Its pass (WGSL file), which names it in timings and tests.
    pub pass: &'static str,
    /// Whether each entry's variance is the same after it as before (it adds a term that
    /// does not depend on the samples), so that an estimator's own variance still describes
    /// the gradient the step is given.
    pub keeps_variance: bool,
    /// Its WGSL files: (name, source).
    pub wgsl: &'static [(&'static str, &'static str)],
    /// Its bind-group declarations (checked against its WGSL by the contract test).
    pub groups: &'static [GroupDecl],
    pub(crate) build: fn(&Setup, &Priors) -> Result<Box<dyn Prior>>,
}

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

/// A prior's options as its folder defines them: read from and written to its table in
/// [`Priors`] (missing keys take their defaults, which leave the prior off).
pub trait Options:
    Clone + Default + serde::Serialize + serde::de::DeserializeOwned + std::fmt::Debug
{
    /// The prior they belong to.
    const KIND: &'static Kind;
    /// An error naming the option (its key in the table) and what is wrong.
    fn check(&self) -> std::result::Result<(), (String, String)>;
    /// Whether the prior acts at all with these options.
    fn on(&self) -> bool;
    /// A short description for reports, e.g. `smoothness 0.03`.
    fn describe(&self) -> String;
}

/// What the registry knows of a prior's options without their type: functions of the
/// tables in [`Priors`], made from an [`Options`] type by [`OptionsKind::of`].
#[derive(Clone, Copy)]
pub struct OptionsKind {
    check: fn(&Priors) -> std::result::Result<(), (String, String)>,
    on: fn(&Priors) -> bool,
    describe: fn(&Priors) -> String,
    /// The options at their defaults, as a table (which leaves the prior off).
    pub defaults: fn() -> toml::Table,
}

impl OptionsKind {
    /// The options `T` defines.
    pub const fn of<T: Options + 'static>() -> OptionsKind {
        OptionsKind {
            check: |p| p.get::<T>().map(|_| ()),
            on: |p| p.get::<T>().is_ok_and(|t| t.on()),
            describe: |p| p.get::<T>().map(|t| t.describe()).unwrap_or_default(),
            defaults: || super::as_table(&T::default()),
        }
    }
}

/// Every prior's options, one table of TOML values per prior name: the task file's
/// `[optimizer.<name>]` tables (and shorthands). Each prior reads its own ([`Options`]).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(transparent)]
pub struct Priors {
    tables: BTreeMap<String, toml::Table>,
}

impl Priors {
    /// These priors with `options` in place of their prior's table:
    /// `Priors::default().with(&SmoothnessOptions { weight: 0.01 })`.
    pub fn with<T: Options>(mut self, options: &T) -> Priors {
        self.put(options);
        self
    }

    /// The options of `T`'s prior, parsed from its table and checked: an error names the
    /// task-file key and what is wrong.
    pub fn get<T: Options>(&self) -> std::result::Result<T, (String, String)> {
        let name = T::KIND.name;
        let o: T = super::parse_table(name, self.tables.get(name))?;
        o.check()
            .map_err(|(k, m)| (format!("optimizer.{name}.{k}"), m))?;
        Ok(o)
    }

    /// The options of `T`'s prior, at their defaults where the table is not valid (settings
    /// are checked before an optimizer reads them).
    pub fn of<T: Options>(&self) -> T {
        self.get().unwrap_or_default()
    }

    /// Replace the table of `T`'s prior by `options`.
    pub fn put<T: Options>(&mut self, options: &T) {
        self.tables
            .insert(T::KIND.name.to_string(), super::as_table(options));
    }

    /// `name`'s table (empty: every option at its default).
    pub fn table(&self, name: &str) -> toml::Table {
        self.tables.get(name).cloned().unwrap_or_default()
    }

    /// Set one option of the prior `name` (checked by [`Priors::check`]).
    pub fn set(&mut self, name: &str, key: &str, value: toml::Value) {
        self.tables
            .entry(name.to_string())
            .or_default()
            .insert(key.to_string(), value);
    }

    /// Check every table: an error names the task-file key and what is wrong.
    pub fn check(&self) -> std::result::Result<(), (String, String)> {
        for name in self.tables.keys() {
            let kind = Kind::by_name(name).ok_or_else(|| {
                (
                    format!("optimizer.{name}"),
                    format!("is no prior ({})", Kind::names().join(", ")),
                )
            })?;
            (kind.options.check)(self)?;
        }
        Ok(())
    }

    /// The priors that act, in the order they apply.
    pub fn active(&self) -> Vec<&'static Kind> {
        REGISTRY
            .iter()
            .copied()
            .filter(|k| (k.options.on)(self))
            .collect()
    }

    /// Whether every prior that acts keeps each entry's variance ([`Kind::keeps_variance`]).
    pub fn keep_variance(&self) -> bool {
        self.active().iter().all(|k| k.keeps_variance)
    }

    /// The priors that act, described for reports (`none` without any).
    pub fn describe(&self) -> String {
        let on: Vec<String> = self
            .active()
            .iter()
            .map(|k| (k.options.describe)(self))
            .collect();
        if on.is_empty() {
            "none".into()
        } else {
            on.join(", ")
        }
    }
}

/// A prior as the optimizer drives it: passes that turn the gradient in place after the
/// estimator and before the step.
pub(crate) trait Prior: Send {
    /// Record its passes for `iteration` (of the run seeded `seed`).
    fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        seed: u32,
        iteration: u32,
        timer: &mut PassTimer,
    );
}

/// What the priors are built from: the optimizer's textures and buffers.
pub(crate) struct Setup<'a> {
    pub gpu: &'a Gpu,
    pub set: &'a ParamSet,
    /// The gradient, laid out like the parameters.
    pub grad: &'a wgpu::Buffer,
    /// The parameters.
    pub params: &'a wgpu::Buffer,
    /// Which texels the cameras observe (one flag per texel) and its GPU buffer.
    pub observed: &'a (Vec<bool>, wgpu::Buffer),
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
        names.extend(crate::optim::step::Kind::tables());
        for k in REGISTRY {
            names.push(k.name);
            // A shorthand may be its prior's own name (`smoothness = 0.03`).
            names.extend(k.shorthand.map(|s| s.0).filter(|s| *s != k.name));
            let mut p = Priors::default();
            p.tables.insert(k.name.into(), (k.options.defaults)());
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
