//! Gradient estimators. Each one lives in its own folder with everything of its own: its
//! Rust, its WGSL, its part of the GPU contract (generated as `gen/<name>`), its uniforms'
//! mirrors and their tests, its options ([`Options`]) and its pipelines, bind groups,
//! buffers, memory plan, checkpoint state and fault counters. A folder exports one value, its
//! [`Kind`]: name, summary, options, WGSL, bind groups, passes, limits, memory, builder and
//! warnings. [`REGISTRY`] lists them, and is the one line to add for a new estimator; the
//! optimizer, the CLI, task files, checkpoints and the bench see a [`Method`] (a handle on a
//! kind) and its options table only (the seam test in `tests.rs` holds it). The optimizer
//! calls an estimator through the `Estimator` trait once per iteration, after the primal
//! render and the loss have written every camera's adjoint.
//!
//! - [`baseline`]: plain Monte Carlo, every sample adds its derivative to the texels it
//!   touches (`gradient.wgsl`).
//! - [`restir`]: parameter-space ReSTIR, two reservoirs per texel reused across iterations
//!   (`restir_candidates.wgsl`, `restir_merge.wgsl`).
//! - [`recursive`]: a recursive control variate on the gradient: fresh samples evaluated at
//!   the current and the previous state correct the running estimate
//!   (`recursive_gradient.wgsl`, `recursive_combine.wgsl`).
mod choice;
mod contract;
mod handle;
mod state;

pub use super::registry::{Options, TuningAxis, TuningContext, TypedAxis};
pub use choice::{
    rule as auto_rule, Choice, MethodChoice, Regime, DENSE_SAMPLES_PER_TEXEL,
    RESTIR_MAX_TEXELS_CHEAP_PRIMAL, RESTIR_PRIMAL_RATIO,
};
pub use contract::{no_memory, no_warnings, Conditions, Diagnostics, Kind, Scale, Sizes};
pub(crate) use contract::{observed_only, Estimator, Frame, Setup};
pub use handle::{EstimatorFamily, EstimatorOptions, Method, OptionsKind};
pub use state::EstimatorState;

use super::registry::{self, Family, Handle};
use crate::gpu::shaders::Generator;
#[cfg(test)]
use crate::gpu::GroupDecl;
use crate::Result;

// A new estimator: its folder, exporting `KIND`, and its name here. The toy (tests only)
// is the registry's own test: it is nothing but its folder and this entry.
registry::registry!(
    "Every estimator, in the order reports list them: the one place that names each \
     folder. The first is the baseline, the reference of every comparison.",
    baseline,
    restir,
    recursive,
    #[cfg(test)]
    toy
);

impl Family for EstimatorFamily {
    const WHAT: &'static str = "gradient estimator";
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

impl Method {
    /// Plain Monte Carlo: every candidate adds its value to the texels it touches.
    pub const BASELINE: Method = Handle::of(&baseline::KIND);
    /// Parameter-space ReSTIR.
    pub const RESTIR: Method = Handle::of(&restir::KIND);
    /// The recursive control variate on the gradient.
    pub const RECURSIVE: Method = Handle::of(&recursive::KIND);

    /// What it does, in one line.
    pub fn summary(self) -> &'static str {
        self.kind().summary
    }
}

/// The estimator of `settings.method`.
pub(crate) fn build(setup: &Setup) -> Result<Box<dyn Estimator>> {
    (setup.method.kind().build)(setup)
}

/// Every estimator's WGSL files (for the shader library).
pub(crate) fn wgsl() -> impl Iterator<Item = &'static [(&'static str, &'static str)]> {
    REGISTRY.iter().map(|k| k.wgsl)
}

/// The WGSL the estimators generate from their Rust (`gen/<method>`).
pub(crate) fn generated() -> impl Iterator<Item = &'static [(&'static str, Generator)]> {
    REGISTRY.iter().map(|k| k.generated)
}

/// Every estimator's bind-group declarations (for the contract test).
#[cfg(test)]
pub(crate) fn groups() -> Vec<GroupDecl> {
    REGISTRY
        .iter()
        .flat_map(|k| k.groups.iter().copied())
        .collect()
}

/// The passes (WGSL files) `method` creates with `options`, the slowest to compile first.
pub(crate) fn passes(method: Method, options: &EstimatorOptions) -> Vec<&'static str> {
    (method.kind().passes)(options)
}

/// Whether `method` keeps state for every texel at paths of `max_depth` vertices
/// ([`Kind::every_texel`]).
pub(crate) fn every_texel(method: Method, max_depth: u32) -> bool {
    (method.kind().every_texel)(max_depth)
}

/// The most cameras `method` can use in one optimization (None: no limit of its own).
pub(crate) fn max_cameras(method: Method) -> Option<usize> {
    method.kind().max_cameras
}

/// The buffers `method` allocates with `options` for the textures of `set` (`n_texels`
/// texels of which `n_observed` are observed), `n_pixels` pixels (all cameras') and
/// `gradient_spp` gradient samples per pixel, by label, size in bytes and what the size
/// scales with.
#[allow(clippy::too_many_arguments)]
pub(crate) fn memory(
    method: Method,
    options: &EstimatorOptions,
    set: &crate::render::params::ParamSet,
    n_texels: u64,
    n_observed: u64,
    n_pixels: u64,
    gradient_spp: u32,
    max_depth: u32,
) -> Vec<(String, u64, Scale)> {
    let (slots_per_material, footprint) = Sizes::lookups(set);
    let sizes = Sizes {
        params: set.values.len() as u64,
        texels: n_texels,
        observed: n_observed,
        pixels: n_pixels,
        max_depth,
        gradient_samples: n_pixels * u64::from(gradient_spp),
        slots_per_material,
        footprint,
    };
    (method.kind().memory)(&sizes, options)
}

#[cfg(test)]
mod tests;
