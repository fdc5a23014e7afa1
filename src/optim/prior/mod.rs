//! The priors the gradient passes through before the step: the smoothness prior
//! ([`smoothness`], a term of the loss over observed neighbouring texels) and the multiscale
//! gradient ([`multiscale`], each texel's gradient averaged with its blocks'). Each module
//! holds its pass's driver and the mirror of its uniform; its WGSL lies beside it. The
//! optimizer sees them through the `Prior` trait, built by `build` as its settings ask.
pub mod multiscale;
pub mod smoothness;

use super::timing::PassTimer;
use super::Settings;
use crate::gpu::Gpu;
use crate::render::params::ParamSet;
use crate::Result;

/// A prior as the optimizer drives it: passes that turn the gradient in place after the
/// estimator and before the step.
pub(crate) trait Prior: Send {
    /// Its pass (WGSL file), which names it.
    fn pass(&self) -> &'static str;
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
    pub settings: &'a Settings,
    /// The gradient, laid out like the parameters.
    pub grad: &'a wgpu::Buffer,
    /// The parameters.
    pub params: &'a wgpu::Buffer,
    /// Which texels the cameras observe (one flag per texel) and its GPU buffer.
    pub observed: &'a (Vec<bool>, wgpu::Buffer),
}

/// The priors `setup.settings` ask for, in the order they apply: the smoothness prior adds
/// its derivative at the current textures, then the multiscale gradient averages the sum.
pub(crate) fn build(s: &Setup) -> Result<Vec<Box<dyn Prior>>> {
    let mut priors: Vec<Box<dyn Prior>> = Vec::new();
    if s.settings.smoothness > 0.0 {
        priors.push(Box::new(smoothness::Smoothness::new(
            s.gpu,
            s.set,
            s.grad,
            s.params,
            s.observed,
            s.settings.smoothness,
        )?));
    }
    let levels = s.settings.multiscale_levels;
    if levels > 0 {
        priors.push(Box::new(multiscale::Multiscale::new(
            s.gpu,
            s.set,
            s.grad,
            &s.observed.1,
            levels,
        )?));
    }
    Ok(priors)
}

/// The passes the priors of `settings` create.
pub(crate) fn passes(settings: &Settings) -> Vec<&'static str> {
    let mut p = Vec::new();
    if settings.smoothness > 0.0 {
        p.push("smoothness");
    }
    if settings.multiscale_levels > 0 {
        p.push("multiscale_gradient");
    }
    p
}

/// The priors' WGSL: (name, source) of their passes.
pub(crate) const WGSL: &[(&str, &str)] = &[
    (
        "multiscale_gradient",
        include_str!("multiscale_gradient.wgsl"),
    ),
    ("smoothness", include_str!("smoothness.wgsl")),
];
