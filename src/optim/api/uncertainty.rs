//! What the images could not tell: each texel's uncertainty, from the gradient's second
//! moment that the step tracks anyway.
//!
//! The loss is the mean over n pixel channels of squared residuals r_p = I_p - T_p, so a
//! texel's gradient is g = (2/n) sum_p r_p J_p with J_p = dI_p/dθ. Near convergence the
//! residuals are the images' noise and misfit, of variance σ² ≈ L (the loss), and the mean
//! gradient is near 0: the second moment v ≈ Var\[g\] = (4/n²) σ² sum_p J_p². The likelihood
//! of Gaussian residuals, exp(-sum r_p² / 2σ²), has the (Gauss-Newton) curvature
//! sum_p J_p² / σ² = n² v / (4 σ⁴) in θ, so the Laplace approximation gives θ the standard
//! deviation
//!
//!   σ_θ = 2 σ² / (n sqrt(v)) ≈ 2 L / (n sqrt(v)).
//!
//! A texel few pixels see, at grazing angles or in shadow, has small J, a small v and a large
//! σ_θ. The estimator's own Monte Carlo noise adds to v, so σ_θ is low where that noise
//! dominates: a ranking and a scale, not a calibrated interval. Computed once, from the moments
//! the step keeps (Adam's second moment, the variance-scaled step's moving second moment, or
//! the estimator's own variance where the step uses it): no pass and no memory per iteration.
use crate::optim::Optimizer;
use crate::{Error, Result};

/// The value [`standard_deviations`] gives a texel the images tell nothing of: one no
/// camera observes, or one that never received a gradient.
pub const UNOBSERVED: f32 = -1.0;

/// Each parameter scalar's standard deviation (laid out like the values) under the
/// Laplace approximation above, for a run whose last loss was `loss`:
/// [`UNOBSERVED`] for the texels no camera sample reaches and for those whose gradient
/// was always 0 (the output files stay finite, as every image psrestir reads must be).
pub fn standard_deviations(opt: &Optimizer, loss: f64) -> Result<Vec<f32>> {
    let n_values = opt.set.values.len();
    let own = opt
        .plugins
        .estimator
        .variance()
        .filter(|_| opt.settings.step.kind().divides_by_variance)
        .filter(|_| opt.settings.priors.keep_variance());
    let v: Vec<f32> = match own {
        Some(buf) => {
            let mut v: Vec<f32> = opt.gpu.read_pod(buf)?;
            v.truncate(n_values);
            v
        }
        None => {
            let kind = opt.settings.step.kind();
            let beta = (kind.second_moment_decay)(&opt.settings.steps).ok_or_else(|| {
                Error::Invalid(format!(
                    "the {} step keeps no second moment to tell the uncertainty from",
                    kind.name
                ))
            })?;
            // The moving moment's bias correction after the steps taken.
            let bias = 1.0 - (beta as f64).powi(opt.iteration.max(1) as i32);
            let mut m2: Vec<f32> = opt.gpu.read_pod(&opt.bufs.moments[1])?;
            m2.truncate(n_values);
            m2.iter().map(|&m| (m as f64 / bias) as f32).collect()
        }
    };
    let pixel_channels = 1.0 / opt.passes.loss.norm() as f64;
    let observed = &opt.inputs.observed.0;
    let mut out = vec![UNOBSERVED; n_values];
    let mut texel = 0;
    for t in &opt.set.textures {
        let ch = t.channels() as usize;
        for k in 0..(t.width * t.height) as usize {
            if observed[texel + k] {
                for c in 0..ch {
                    let i = t.offset as usize + k * ch + c;
                    let sigma = 2.0 * loss / (pixel_channels * (v[i] as f64).sqrt());
                    out[i] = if v[i] > 0.0 && sigma.is_finite() {
                        sigma as f32
                    } else {
                        // Never a gradient: nothing to tell from, as if unobserved.
                        UNOBSERVED
                    };
                }
            }
        }
        texel += (t.width * t.height) as usize;
    }
    Ok(out)
}
