//! The variance-scaled step (after Bálint et al. 2023): the pass of
//! variance_step.wgsl (`VarianceStepPass`, one dispatch per optimized texture), its
//! options and its CPU reference. With z = d / (√Var(d) + eps), where d is the gradient
//! estimate and Var(d) its variance (the estimator's own where it tracks one, the recursive
//! estimator's, otherwise a moving variance of the gradient), each scalar moves by
//! −lr · clamp(sign(z) · max(|z| − threshold, 0), −clip, clip). Unlike Adam, whose per-scalar
//! normalization gives any estimator about the same step, a lower-variance estimate takes a
//! larger step; the threshold keeps only the part of the estimate that exceeds its noise, so
//! that scalars the images hardly determine do not drift, and a lower-variance estimate gets
//! closer to the optimum before its steps stop. Where successive estimates share samples
//! (ReSTIR's kept paths), the moving variance can be scaled to one estimate's
//! ([`variance_scale`], `correlation`; off by default: measured, it did not help).
use super::moment_filter::MomentFilter;
use super::{Kind, Options, OptionsKind, Setup, StepKind, TextureSteps};
use crate::gpu::Gpu;
use crate::optim::PassTimer;
use crate::render::params::{ParamSet, ParamTexture};
use crate::vocab::Slot;
use crate::Result;

/// The variance-scaled step as the registry knows it.
pub const KIND: Kind = Kind {
    name: "variance",
    summary: "the variance-scaled step: the estimate over its standard deviation, \
              thresholded and clipped",
    table: "variance_step",
    options: OptionsKind::of::<VarianceStepOptions>(),
    pass: "variance_step",
    wgsl: &[("variance_step", include_str!("variance_step.wgsl"))],
    groups: &[VARIANCE_STEP_GROUP],
    learning_rate,
    first_moment: false,
    divides_by_variance: true,
    tuned_before_filter: true,
    second_moment_decay: |steps| Some(steps.of::<VarianceStepOptions>().beta),
    if_not_converging: "try a lower learning rate (`--lr-scale 0.5`) or more gradient \
        samples per pixel (`gradient_spp`)",
    // It divides by the estimator's variance of each value, which the CPU groups lack.
    cpu: None,
    build: |s| Ok(Box::new(VarianceStepPass::new(s)?)),
};

/// The variance-scaled step's learning rate of a texture that names none. The step moves a
/// texel by at most its clip (one learning rate by default) per step, so its rate is a
/// distance in the slot's units: 0.01, which ended lower than 0.02 on the default task
/// (dense samples, 500 iterations). A normal map takes 0.003: on the `wall` scene under a
/// single sun (scenes/bench/wall, lavapipe, 20 s) it took the normal map's mean angle error
/// from 16.0 to 15.4 degrees (at 0.01: 18.0), where Adam at 0.005 reached 17.9.
pub fn learning_rate(slot: Slot) -> f32 {
    match slot {
        Slot::Normal => 0.003,
        _ => 0.01,
    }
}

/// The variance-scaled step's options (the task file's `[optimizer.variance_step]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct VarianceStepOptions {
    /// The largest step, in learning rates (> 0).
    pub clip: f32,
    /// Decay of the moving variance kept for estimators without their own, in [0, 1).
    pub beta: f32,
    /// Added to the standard deviation (> 0).
    pub eps: f32,
    /// How many standard deviations of the estimate are taken off its magnitude before the
    /// step (>= 0; 0: none).
    pub threshold: f32,
    /// The correlation of successive gradient estimates that the moving variance is corrected
    /// for, in [0, 1) (0: none, the default). ReSTIR's kept samples outweigh a fresh
    /// candidate by up to m_cap to 1, so successive estimates share one about
    /// m_cap / (m_cap + 1) of the time (0.89 at the default cap); see [`variance_scale`].
    pub correlation: f32,
}

impl Default for VarianceStepOptions {
    fn default() -> Self {
        VarianceStepOptions {
            clip: 1.0,
            beta: 0.9,
            eps: 1e-12,
            threshold: 1.0,
            correlation: 0.0,
        }
    }
}

impl Options<super::StepFamily> for VarianceStepOptions {
    const KIND: &'static Kind = &KIND;

    fn describe(&self) -> String {
        format!("clip {}, threshold {}", self.clip, self.threshold)
    }

    /// The clip (× 0.5, × 2), then the threshold (0, and twice the current one, at least 1).
    fn tuning(_: &super::TuningContext) -> Vec<super::TypedAxis<Self>> {
        vec![
            |b| {
                [0.5, 2.0]
                    .map(|f| VarianceStepOptions {
                        clip: b.clip * f,
                        ..*b
                    })
                    .to_vec()
            },
            |b| {
                [0.0, 2.0 * b.threshold.max(0.5)]
                    .map(|threshold| VarianceStepOptions { threshold, ..*b })
                    .to_vec()
            },
        ]
    }

    /// An error naming the field that is out of range.
    fn check(&self) -> std::result::Result<(), (String, String)> {
        let bad = |key: &str, msg: &str| Err((key.to_string(), msg.to_string()));
        if !(self.clip.is_finite() && self.clip > 0.0) {
            return bad("clip", "must be a positive number");
        }
        if !(0.0..1.0).contains(&self.beta) {
            return bad("beta", "must be in [0, 1)");
        }
        if !(self.eps.is_finite() && self.eps > 0.0) {
            return bad("eps", "must be a positive number");
        }
        if !(self.threshold.is_finite() && self.threshold >= 0.0) {
            return bad("threshold", "must be a number >= 0");
        }
        if !(0.0..1.0).contains(&self.correlation) {
            return bad("correlation", "must be in [0, 1)");
        }
        Ok(())
    }
}

/// The factor that turns the moving variance of a gradient whose successive estimates have
/// correlation `rho` (lag 1, decaying geometrically: rho^k at lag k) into the variance of one
/// estimate, for moments of decay `beta`. The moving moments give `E[v - m^2] = s^2 - Var[m]`,
/// and the moving mean `m` of such a series has
/// `Var[m] = s^2 (1 - beta) (1 + beta rho) / ((1 + beta) (1 - beta rho))`: close to `s^2`
/// itself when rho is near 1, so that the spread the moments see is a fraction of the
/// estimate's. The step divides by s, the spread of the estimate it takes. 1 at rho = 0 would ignore the (1 - beta) / (1 + beta) that the mean
/// takes off even for independent estimates; that part is left as it was (the step's
/// threshold was chosen with it), so the factor is the ratio of the two.
pub fn variance_scale(rho: f32, beta: f32) -> f32 {
    let kept = |r: f32| 1.0 - (1.0 - beta) * (1.0 + beta * r) / ((1.0 + beta) * (1.0 - beta * r));
    let rho = rho.clamp(0.0, 0.99);
    (kept(0.0) / kept(rho).max(1e-3)).max(1.0)
}

/// One variance-scaled step at step number `t` (from 1) with clamping to `[lo, hi]`, on the
/// CPU: with `variance`, the estimator's own; otherwise the moving moments `m`, `v`
/// (updated here) give it.
#[allow(clippy::too_many_arguments)]
pub fn step(
    o: &VarianceStepOptions,
    params: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    grad: &[f32],
    variance: Option<&[f32]>,
    lr: f32,
    t: u32,
    (lo, hi): (f32, f32),
    mask: bool,
) {
    let bias = 1.0 - o.beta.powi(t as i32);
    let scale = variance_scale(o.correlation, o.beta);
    for i in 0..params.len() {
        let g = grad[i];
        if !g.is_finite() || (mask && g == 0.0) {
            continue;
        }
        let var = match variance {
            Some(var) => var[i],
            None => {
                m[i] = o.beta * m[i] + (1.0 - o.beta) * g;
                v[i] = o.beta * v[i] + (1.0 - o.beta) * g * g;
                let mean = m[i] / bias;
                (v[i] / bias - mean * mean).max(0.0) * scale
            }
        };
        let z = g / (var.sqrt() + o.eps);
        let shrunk = z.signum() * (z.abs() - o.threshold).max(0.0);
        params[i] = (params[i] - lr * shrunk.clamp(-o.clip, o.clip)).clamp(lo, hi);
    }
}

/// `VarianceStepParams` in variance_step.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VarianceStepParams {
    pub offset: u32,
    pub count: u32,
    pub lr: f32,
    pub clip: f32,
    pub beta: f32,
    pub eps: f32,
    pub bias: f32,
    pub own_variance: u32,
    pub lo: f32,
    pub hi: f32,
    pub mask: u32,
    pub threshold: f32,
    pub phase: u32,
    pub own_weight: f32,
    pub variance_scale: f32,
    pub _pad: u32,
}

/// Group 0 of `variance_step.wgsl`.
pub(crate) const VARIANCE_STEP_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "variance_step",
    group: 0,
    names: &[
        "vp",
        "grad",
        "params",
        "moment1",
        "moment2",
        "variance",
        "step_stats",
        "pair_first",
        "pair_second",
    ],
};

/// The variance-scaled step's pass: one or two dispatches per optimized texture (see
/// [`TextureSteps`]).
pub(crate) struct VarianceStepPass(TextureSteps<VarianceStepParams>);

impl VarianceStepPass {
    fn new(s: Setup) -> Result<VarianceStepPass> {
        let (gpu, set, b, filter) = (s.gpu, s.set, s.buffers, s.filter);
        let (options, mask) = (s.steps.of::<VarianceStepOptions>(), s.mask);
        let layout = gpu.pass_layout("variance_step", 0)?;
        let pipeline = gpu.compute_pipeline("variance_step", &[&layout])?;
        let unused = gpu.storage_zeroed("variance step unused variance", 16);
        let variance = b.variance.unwrap_or(&unused);
        let f = filter.as_ref().map(|f| f.options).unwrap_or_default();
        let make = |t: &ParamTexture, phase: u32| {
            let (lo, hi) = t.slot.range();
            VarianceStepParams {
                offset: t.offset,
                count: t.len() as u32,
                lr: StepKind::VARIANCE.texture_rate(t),
                clip: options.clip,
                beta: options.beta,
                eps: options.eps,
                bias: 1.0,
                own_variance: b.variance.is_some() as u32,
                lo,
                hi,
                mask: mask as u32,
                threshold: options.threshold,
                phase,
                own_weight: f.own_weight,
                variance_scale: variance_scale(options.correlation, options.beta),
                _pad: 0,
            }
        };
        let bind = |label: &str, u: &wgpu::Buffer, pair: &[wgpu::Buffer; 2]| {
            gpu.bind(
                &VARIANCE_STEP_GROUP,
                label,
                &layout,
                &[
                    ("vp", u),
                    ("grad", b.grad),
                    ("params", b.params),
                    ("moment1", &b.moments[0]),
                    ("moment2", &b.moments[1]),
                    ("variance", variance),
                    ("step_stats", b.stats),
                    ("pair_first", &pair[0]),
                    ("pair_second", &pair[1]),
                ],
            )
        };
        Ok(VarianceStepPass(TextureSteps::new(
            gpu,
            StepKind::VARIANCE,
            pipeline,
            set,
            filter,
            make,
            bind,
        )))
    }
}

impl super::Step for VarianceStepPass {
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
            p.bias = 1.0 - p.beta.powi(t as i32);
            p.count
        })
    }

    fn filter(&self) -> Option<&MomentFilter> {
        self.0.filter.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::variance_scale;

    /// A stationary series whose successive values have correlation rho (AR(1), unit
    /// variance), through the step's moving moments: the moving variance times
    /// variance_scale(rho) matches what it gives for independent values (the scale corrects
    /// exactly the part correlation takes away), within 3% over 200 000 steps.
    #[test]
    fn the_scaled_moving_variance_of_a_correlated_series_is_that_of_an_independent_one() {
        let beta = 0.9f32;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut normal = move || {
            // Box-Muller from two uniforms of a 64-bit xorshift.
            let mut u = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let mut mean_var = |rho: f64| {
            let (mut x, mut m, mut v, mut sum) = (0.0f64, 0.0, 0.0, 0.0);
            let n = 200_000;
            for t in 0..n + 100 {
                x = rho * x + (1.0 - rho * rho).sqrt() * normal();
                m = beta as f64 * m + (1.0 - beta as f64) * x;
                v = beta as f64 * v + (1.0 - beta as f64) * x * x;
                if t >= 100 {
                    sum += v - m * m;
                }
            }
            sum / n as f64
        };
        assert_eq!(variance_scale(0.0, beta), 1.0);
        let independent = mean_var(0.0);
        for rho in [0.5f32, 0.8, 0.9] {
            let scaled = mean_var(rho as f64) * variance_scale(rho, beta) as f64;
            let r = scaled / independent;
            assert!(
                (r - 1.0).abs() < 0.03,
                "rho {rho}: {scaled} vs {independent} ({r})"
            );
        }
    }
}
