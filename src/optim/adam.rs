//! Adam: the constants, the pass of shaders/adam.wgsl (`AdamPass`, one dispatch per
//! optimized texture), and its CPU reference.
use crate::gpu::{encode_timed_pass, grid_2d, Gpu};
use crate::optim::{PassKind, PassTimer};
use crate::render::params::ParamSet;
use crate::render::WORKGROUP;
use crate::Result;

/// First-moment decay.
pub const BETA1: f32 = 0.9;
/// Second-moment decay.
pub const BETA2: f32 = 0.999;
/// Denominator epsilon.
pub const EPS: f32 = 1e-8;

/// Adam's decays and epsilon (the task file's `[optimizer.adam]`; `bench --tune` searches
/// them per estimator).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdamOptions {
    /// First-moment decay, in [0, 1).
    pub beta1: f32,
    /// Second-moment decay, in [0, 1).
    pub beta2: f32,
    /// Denominator epsilon, > 0.
    pub eps: f32,
}

impl Default for AdamOptions {
    fn default() -> Self {
        AdamOptions {
            beta1: BETA1,
            beta2: BETA2,
            eps: EPS,
        }
    }
}

impl AdamOptions {
    /// An error naming the field (`beta1`, `beta2`, `eps`) that is out of range.
    pub fn check(&self) -> std::result::Result<(), (&'static str, &'static str)> {
        if !(0.0..1.0).contains(&self.beta1) {
            return Err(("beta1", "must be in [0, 1)"));
        }
        if !(0.0..1.0).contains(&self.beta2) {
            return Err(("beta2", "must be in [0, 1)"));
        }
        if !(self.eps.is_finite() && self.eps > 0.0) {
            return Err(("eps", "must be a positive number"));
        }
        Ok(())
    }
}

/// One Adam step at step number `t` (from 1) with clamping to `[lo, hi]`, on the CPU.
#[allow(clippy::too_many_arguments)]
pub fn step(
    params: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    grad: &[f32],
    lr: f32,
    t: u32,
    lo: f32,
    hi: f32,
) {
    step_masked(params, m, v, grad, lr, t, lo, hi, false)
}

/// [`step`], where with `mask` an entry whose gradient is exactly zero keeps its value and
/// moments (sparse Adam).
#[allow(clippy::too_many_arguments)]
pub fn step_masked(
    params: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    grad: &[f32],
    lr: f32,
    t: u32,
    lo: f32,
    hi: f32,
    mask: bool,
) {
    let o = AdamOptions::default();
    step_with(&o, params, m, v, grad, lr, t, (lo, hi), mask)
}

/// [`step_masked`] with the decays and epsilon of `o`.
#[allow(clippy::too_many_arguments)]
pub fn step_with(
    o: &AdamOptions,
    params: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    grad: &[f32],
    lr: f32,
    t: u32,
    (lo, hi): (f32, f32),
    mask: bool,
) {
    let bias1 = 1.0 - o.beta1.powi(t as i32);
    let bias2 = 1.0 - o.beta2.powi(t as i32);
    for i in 0..params.len() {
        let g = grad[i];
        if !g.is_finite() || (mask && g == 0.0) {
            continue;
        }
        m[i] = o.beta1 * m[i] + (1.0 - o.beta1) * g;
        v[i] = o.beta2 * v[i] + (1.0 - o.beta2) * g * g;
        let s = lr * (m[i] / bias1) / ((v[i] / bias2).sqrt() + o.eps);
        params[i] = (params[i] - s).clamp(lo, hi);
    }
}

/// `AdamParams` in shaders/adam.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AdamParams {
    pub offset: u32,
    pub count: u32,
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    pub bias1: f32,
    pub bias2: f32,
    pub lo: f32,
    pub hi: f32,
    pub mask: u32,
    pub _pad: u32,
}

/// Group 0 of `adam.wgsl`.
pub(crate) const ADAM_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "adam",
    group: 0,
    names: &["ap", "grad", "params", "moment1", "moment2", "adam_stats"],
};

/// The Adam pass: per optimized texture a uniform, its bind group and its parameters.
pub(crate) struct AdamPass {
    pipeline: wgpu::ComputePipeline,
    textures: Vec<(wgpu::Buffer, wgpu::BindGroup, AdamParams)>,
}

/// What the Adam pass binds.
pub(crate) struct AdamBuffers<'a> {
    pub grad: &'a wgpu::Buffer,
    pub params: &'a wgpu::Buffer,
    pub moments: &'a [wgpu::Buffer; 2],
    pub stats: &'a wgpu::Buffer,
}

impl AdamPass {
    pub(crate) fn new(
        gpu: &Gpu,
        set: &ParamSet,
        options: AdamOptions,
        mask: bool,
        b: AdamBuffers,
    ) -> Result<AdamPass> {
        let layout = gpu.pass_layout("adam", 0)?;
        let pipeline = gpu.compute_pipeline("adam", &[&layout])?;
        let textures = set
            .textures
            .iter()
            .map(|t| {
                let (lo, hi) = t.slot.range();
                let p = AdamParams {
                    offset: t.offset,
                    count: t.len() as u32,
                    lr: t.learning_rate,
                    beta1: options.beta1,
                    beta2: options.beta2,
                    eps: options.eps,
                    bias1: 1.0,
                    bias2: 1.0,
                    lo,
                    hi,
                    mask: mask as u32,
                    _pad: 0,
                };
                let u = gpu.uniform(&format!("adam params {}", t.name()), bytemuck::bytes_of(&p));
                let g = gpu.bind(
                    &ADAM_GROUP,
                    "adam",
                    &layout,
                    &[
                        ("ap", &u),
                        ("grad", b.grad),
                        ("params", b.params),
                        ("moment1", &b.moments[0]),
                        ("moment2", &b.moments[1]),
                        ("adam_stats", b.stats),
                    ],
                );
                (u, g, p)
            })
            .collect();
        Ok(AdamPass { pipeline, textures })
    }

    /// Record step `t` (from 1) of every texture at its learning rate times `factor`;
    /// returns the learning rates used, one per texture.
    pub(crate) fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        set: &ParamSet,
        factor: f32,
        t: u32,
        timer: &mut PassTimer,
    ) -> Vec<f32> {
        let pass = ("adam", &self.pipeline);
        encode_texture_steps(
            gpu,
            enc,
            pass,
            &mut self.textures,
            set,
            factor,
            timer,
            |p, lr| {
                p.lr = lr;
                p.bias1 = 1.0 - p.beta1.powi(t as i32);
                p.bias2 = 1.0 - p.beta2.powi(t as i32);
                p.count
            },
        )
    }
}

/// Record a step pass (`pass`: its name and pipeline) once per optimized texture, each with
/// its uniform and bind group in `textures`: `prepare` sets a texture's uniform for the
/// learning rate it is given (the texture's rate times `factor`) and returns its number of
/// entries. Returns the learning rates used, one per texture. Shared by Adam and the
/// variance-scaled step.
#[allow(clippy::too_many_arguments)]
pub(crate) fn encode_texture_steps<P: bytemuck::Pod>(
    gpu: &Gpu,
    enc: &mut wgpu::CommandEncoder,
    (label, pipeline): (&str, &wgpu::ComputePipeline),
    textures: &mut [(wgpu::Buffer, wgpu::BindGroup, P)],
    set: &ParamSet,
    factor: f32,
    timer: &mut PassTimer,
    mut prepare: impl FnMut(&mut P, f32) -> u32,
) -> Vec<f32> {
    let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
    let mut rates = Vec::with_capacity(textures.len());
    for ((u, g, p), tex) in textures.iter_mut().zip(&set.textures) {
        let lr = tex.learning_rate * factor;
        rates.push(lr);
        let count = prepare(p, lr);
        gpu.queue.write_buffer(u, 0, bytemuck::bytes_of(p));
        let grid = grid_2d(count, WORKGROUP, max_dim);
        encode_timed_pass(enc, label, pipeline, &[g], grid, timer.next(PassKind::Adam));
    }
    rates
}
