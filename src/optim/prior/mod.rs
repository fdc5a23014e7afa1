//! The priors the gradient passes through before the step: the smoothness prior
//! ([`smoothness`], a term of the loss over observed neighbouring texels) and the multiscale
//! gradient ([`multiscale`], each texel's gradient averaged with its blocks'). Each module
//! holds its pass's driver and the mirror of its uniform; its WGSL lies beside it.
pub mod multiscale;
pub mod smoothness;

/// The priors' WGSL: (name, source) of their passes.
pub(crate) const WGSL: &[(&str, &str)] = &[
    (
        "multiscale_gradient",
        include_str!("multiscale_gradient.wgsl"),
    ),
    ("smoothness", include_str!("smoothness.wgsl")),
];
