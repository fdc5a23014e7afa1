//! What a device has made, kept for reuse, and what making each pipeline cost.
use super::shaders::Binding;
use std::collections::HashMap;

/// What a device has made, to be reused: bind group layouts by label and bindings, and
/// pipelines by composed WGSL and layouts.
#[derive(Default)]
pub(super) struct Made {
    pub(super) layouts: HashMap<(String, Vec<Binding>), wgpu::BindGroupLayout>,
    pub(super) pipelines: HashMap<String, Vec<(Vec<wgpu::BindGroupLayout>, wgpu::ComputePipeline)>>,
}

/// Seconds spent creating (and compiling) one pass's pipeline.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PipelineTime {
    /// The pass (its WGSL file).
    pub pass: String,
    /// Wall-clock seconds of creation and compilation.
    pub seconds: f64,
    /// Whether a second device compiled it ahead, beside the first's work
    /// ([`Gpu::compile_elsewhere_in`](super::Gpu::compile_elsewhere_in)); the first device's own creation of the pass follows.
    pub ahead: bool,
}
