//! The steps the optimizer takes with each gradient estimate. Each one lives in its own
//! folder and exports one value, its [`Kind`]: name, summary, options (its own type, read
//! from the task file's `[optimizer.<table>]` table), default learning rates, WGSL, bind
//! groups and builder. [`REGISTRY`] lists them and is the one line to add for a new step; the
//! optimizer, `auto`, the task file, the command line (`--step NAME`, `--set
//! optimizer.<table>.<key>=<value>`) and reports see a [`StepKind`] and its table in
//! [`Steps`] only. One step is chosen per run (priors, by contrast, are switched on, any of
//! them).
//!
//! - [`adam`]: Adam (first and second moments), with its CPU path, which moves the parameter
//!   table's CPU groups (the environment, the cameras' gains) in every run.
//! - [`variance_step`]: the variance-scaled step (the estimate over its standard deviation,
//!   thresholded and clipped).
//!
//! Either may take filtered moments ([`moment_filter`]): the pair it divides, smoothed in
//! texture space. The per-texture dispatch logic the steps share is `TextureSteps`.
mod contract;
pub mod moment_filter;

pub use crate::optim::registry::{Options, TuningContext, TypedAxis};
pub use contract::{CpuGroup, Kind, OptionsKind, StepFamily, StepKind, Steps};
pub(crate) use contract::{Setup, Step, StepBuffers, StepChoice, TextureSteps};

use crate::gpu::Gpu;
#[cfg(test)]
use crate::gpu::GroupDecl;
use crate::optim::registry::{self, Family, Handle};
use crate::render::params::{ParamSet, ParamTexture};
use crate::vocab::Slot;
use crate::Result;
use moment_filter::MomentFilter;

// A new step: its folder, exporting `KIND`, and its name here. The toy (tests only) is the
// registry's own test: it is nothing but its folder and this entry.
registry::registry!(
    "Every step, in the order reports list them: the one place that names each folder. \
     The first is the library's default.",
    adam,
    variance_step,
    #[cfg(test)]
    toy
);

/// The moment filter's WGSL (the steps' own are in their kinds).
pub(crate) const WGSL: &[(&str, &str)] = &[("moment_filter", include_str!("moment_filter.wgsl"))];

impl Family for StepFamily {
    const WHAT: &'static str = "step";
    type Kind = Kind;
    fn registry() -> &'static [&'static Kind] {
        REGISTRY
    }
    fn name(kind: &'static Kind) -> &'static str {
        kind.name
    }
    fn table(kind: &'static Kind) -> &'static str {
        kind.table
    }
    fn options(kind: &'static Kind) -> OptionsKind {
        kind.options
    }
}

impl StepKind {
    /// Adam (first and second moments).
    pub const ADAM: StepKind = Handle::of(&adam::KIND);
    /// The variance-scaled step: no first moment, the estimate's variance in the denominator.
    pub const VARIANCE: StepKind = Handle::of(&variance_step::KIND);

    /// The learning rate of a texture of `slot` that names none.
    pub fn learning_rate(self, slot: Slot) -> f32 {
        (self.kind().learning_rate)(slot)
    }

    /// The learning rate of texture `tex` under this step: its own, or the step's default
    /// for its slot.
    pub fn texture_rate(self, tex: &ParamTexture) -> f32 {
        tex.learning_rate
            .unwrap_or_else(|| self.learning_rate(tex.slot))
    }
}

/// The step `choice` names, with its moment filter when that is on.
pub(crate) fn build(
    gpu: &Gpu,
    set: &ParamSet,
    choice: &StepChoice,
    observed_map: &wgpu::Buffer,
    b: &StepBuffers,
) -> Result<Box<dyn Step>> {
    let mf = choice.moment_filter;
    let kind = choice.kind.kind();
    let filter = if mf.enabled() {
        let of_mean = kind.divides_by_variance;
        Some(MomentFilter::new(
            gpu,
            set,
            (mf, of_mean),
            b.params,
            observed_map,
        )?)
    } else {
        None
    };
    (kind.build)(Setup {
        gpu,
        set,
        steps: choice.steps,
        mask: choice.sparse,
        filter,
        buffers: b,
    })
}

/// Every step's WGSL files, the moment filter's included.
pub(crate) fn wgsl() -> impl Iterator<Item = &'static [(&'static str, &'static str)]> {
    REGISTRY.iter().map(|k| k.wgsl).chain([WGSL])
}

/// Every step's bind-group declarations, the moment filter's included (for the contract
/// test).
#[cfg(test)]
pub(crate) fn groups() -> Vec<GroupDecl> {
    REGISTRY
        .iter()
        .flat_map(|k| k.groups.iter().copied())
        .chain([moment_filter::MOMENT_FILTER_GROUP])
        .collect()
}
