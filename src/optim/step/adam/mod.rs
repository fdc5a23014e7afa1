//! Adam: its kind, its options, the pass of adam.wgsl (`AdamPass`, one or two dispatches
//! per optimized texture) and its CPU path (which moves the parameter table's CPU groups: the
//! environment, the cameras' gains).
use super::moment_filter::MomentFilter;
use super::{Kind, Options, OptionsKind, Setup, StepKind, TextureSteps};
use crate::gpu::Gpu;
use crate::optim::PassTimer;
use crate::render::params::{ParamSet, ParamTexture};
use crate::vocab::Slot;
use crate::Result;

/// Adam as the registry knows it.
pub const KIND: Kind = Kind {
    name: "adam",
    summary: "Adam: the first moment over the root of the second, per parameter scalar",
    table: "adam",
    options: OptionsKind::of::<AdamOptions>(),
    pass: "adam",
    wgsl: &[("adam", include_str!("adam.wgsl"))],
    groups: &[ADAM_GROUP],
    learning_rate,
    first_moment: true,
    divides_by_variance: false,
    tuned_before_filter: false,
    second_moment_decay: |steps| Some(steps.of::<AdamOptions>().beta2),
    if_not_converging: "Adam moves every texel by about its learning rate per step however \
        noisy its gradient: try the variance-scaled step (`--step variance`, or remove `step` \
        from the task for auto's configuration) or a lower rate (`--lr-scale 0.25`)",
    cpu: Some(|steps, g| {
        let o = steps.of::<AdamOptions>();
        step_with(&o, g.values, g.m1, g.m2, g.grad, g.lr, g.t, g.range, false)
    }),
    build: |s| Ok(Box::new(AdamPass::new(s)?)),
};

/// Adam's learning rate of a texture that names none: the rates the bundled bench tasks
/// chose for it, 0.03 for base color and metallic, 0.02 for roughness (whose derivative is
/// the steepest). Adam moves every texel by about its rate per step.
///
/// A normal map takes a smaller rate: on the `wall` scene under a single sun
/// (scenes/bench/wall, base color and normal map together, lavapipe) Adam at 0.03 drove the
/// normal map away from its flat start (mean angle error 16.0 -> 44.7 degrees in 60 s); in
/// 20 s, at 0.01 to 22.4 and at 0.005 to 17.9. Under its three suns, one per capture, Adam at
/// 0.005 with filtered moments recovers it (16.0 -> 6.5 degrees in 60 s; docs/guide.md,
/// "Normal maps").
pub fn learning_rate(slot: Slot) -> f32 {
    match slot {
        Slot::Normal => 0.005,
        Slot::Roughness => 0.02,
        _ => 0.03,
    }
}

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

impl Options<super::StepFamily> for AdamOptions {
    const KIND: &'static Kind = &KIND;

    fn describe(&self) -> String {
        format!("β1 {}, β2 {}", self.beta1, self.beta2)
    }

    /// β1 (0.5, 0, and 0.2 as well with the filter, which averages in space what β1
    /// averages in time), then β2 (0.99). ε is not searched: it matters only where it is
    /// comparable to the gradients' size, which differs by orders of magnitude between scenes.
    fn tuning(context: &super::TuningContext) -> Vec<super::TypedAxis<Self>> {
        let beta1: super::TypedAxis<Self> = if context.filtered {
            |b| [0.5, 0.2, 0.0].map(|beta1| AdamOptions { beta1, ..*b }).to_vec()
        } else {
            |b| [0.5, 0.0].map(|beta1| AdamOptions { beta1, ..*b }).to_vec()
        };
        vec![beta1, |b| vec![AdamOptions { beta2: 0.99, ..*b }]]
    }

    /// An error naming the field (`beta1`, `beta2`, `eps`) that is out of range.
    fn check(&self) -> std::result::Result<(), (String, String)> {
        let bad = |key: &str, msg: &str| Err((key.to_string(), msg.to_string()));
        if !(0.0..1.0).contains(&self.beta1) {
            return bad("beta1", "must be in [0, 1)");
        }
        if !(0.0..1.0).contains(&self.beta2) {
            return bad("beta2", "must be in [0, 1)");
        }
        if !(self.eps.is_finite() && self.eps > 0.0) {
            return bad("eps", "must be a positive number");
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

/// `AdamParams` in adam.wgsl (a test checks the layout).
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
    pub phase: u32,
    pub own_weight: f32,
    pub write_back: u32,
    pub _pad: [u32; 2],
}

/// Group 0 of `adam.wgsl`.
pub(crate) const ADAM_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "adam",
    group: 0,
    names: &[
        "ap",
        "grad",
        "params",
        "moment1",
        "moment2",
        "step_stats",
        "pair_first",
        "pair_second",
    ],
};

/// The Adam pass: one or two dispatches per optimized texture (see [`TextureSteps`]).
pub(crate) struct AdamPass(TextureSteps<AdamParams>);

impl AdamPass {
    fn new(s: Setup) -> Result<AdamPass> {
        let (gpu, set, b, filter) = (s.gpu, s.set, s.buffers, s.filter);
        let (options, mask) = (s.steps.of::<AdamOptions>(), s.mask);
        let layout = gpu.pass_layout("adam", 0)?;
        let pipeline = gpu.compute_pipeline("adam", &[&layout])?;
        let f = filter.as_ref().map(|f| f.options).unwrap_or_default();
        let make = |t: &ParamTexture, phase: u32| {
            let (lo, hi) = t.slot.range();
            AdamParams {
                offset: t.offset,
                count: t.len() as u32,
                lr: StepKind::ADAM.texture_rate(t),
                beta1: options.beta1,
                beta2: options.beta2,
                eps: options.eps,
                bias1: 1.0,
                bias2: 1.0,
                lo,
                hi,
                mask: mask as u32,
                phase,
                own_weight: f.own_weight,
                write_back: f.write_back as u32,
                _pad: [0; 2],
            }
        };
        let bind = |label: &str, u: &wgpu::Buffer, pair: &[wgpu::Buffer; 2]| {
            gpu.bind(
                &ADAM_GROUP,
                label,
                &layout,
                &[
                    ("ap", u),
                    ("grad", b.grad),
                    ("params", b.params),
                    ("moment1", &b.moments[0]),
                    ("moment2", &b.moments[1]),
                    ("step_stats", b.stats),
                    ("pair_first", &pair[0]),
                    ("pair_second", &pair[1]),
                ],
            )
        };
        Ok(AdamPass(TextureSteps::new(
            gpu,
            StepKind::ADAM,
            pipeline,
            set,
            filter,
            make,
            bind,
        )))
    }
}

impl super::Step for AdamPass {
    fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        set: &ParamSet,
        factor: f32,
        t: u32,
        timer: &mut PassTimer,
    ) -> Vec<f32> {
        self.0.encode(gpu, enc, set, factor, timer, |p, lr| {
            p.lr = lr;
            p.bias1 = 1.0 - p.beta1.powi(t as i32);
            p.bias2 = 1.0 - p.beta2.powi(t as i32);
            p.count
        })
    }

    fn filter(&self) -> Option<&MomentFilter> {
        self.0.filter.as_ref()
    }
}
