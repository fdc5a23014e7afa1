//! The contract between the optimizer and a prior: what a folder exports ([`Kind`]), the
//! tables of their options ([`Priors`]), what a prior is built from ([`Setup`]) and the
//! [`Prior`] trait it is driven through.
use crate::gpu::{Gpu, GroupDecl};
use crate::optim::registry::{self, Tables};
use crate::optim::timing::PassTimer;
use crate::render::params::ParamSet;
use crate::Result;

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

/// The priors as the generic registry sees them.
pub struct PriorFamily;

/// What the registry knows of a prior's options without their type (its options' defaults
/// leave it off).
pub type OptionsKind = registry::OptionsKind<PriorFamily>;

/// Every prior's options, one table per prior name: the task file's `[optimizer.<name>]`
/// tables (and shorthands). Each prior reads its own ([`Options`](super::Options)).
pub type Priors = Tables<PriorFamily>;

impl Priors {
    /// Whether every prior that acts keeps each entry's variance ([`Kind::keeps_variance`]).
    pub fn keep_variance(&self) -> bool {
        self.active().iter().all(|k| k.keeps_variance)
    }

    /// The priors that act, described for reports (`none` without any).
    pub fn describe_active(&self) -> String {
        let on: Vec<String> = self
            .active()
            .into_iter()
            .map(|k| self.describe(k))
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
