//! The smoothness prior (smoothness.wgsl): before the multiscale gradient and Adam,
//! each observed texel's gradient gains the derivative of
//! `R = lambda * mean over observed 4-neighbour pairs and channels of (x_i - x_j)^2`.
//!
//! Why: the cameras often see fewer pixels than the texture has texels, so the image does not
//! determine every texel. Monte Carlo gradient noise then random-walks the texture in the
//! directions the image leaves free (the speckle of the bundled tasks), and nothing pulls it
//! back. The prior does. It is a mean, like the image loss, so `lambda` weighs the two terms
//! about alike on textures and images of any size. [`reference()`] is the CPU twin that the
//! tests compare against.

use bytemuck::{Pod, Zeroable};

use super::{Kind, Options, OptionsKind};
use crate::error::Result;
use crate::gpu::{encode_timed_pass, Gpu, GroupDecl};
use crate::render::params::ParamSet;

/// The smoothness prior as the registry knows it.
pub const KIND: Kind = Kind {
    name: "smoothness",
    summary: "the mean squared difference of observed neighbouring texels, added to the loss",
    options: OptionsKind::of::<SmoothnessOptions>(),
    shorthand: Some(("smoothness", "weight")),
    pass: "smoothness",
    keeps_variance: true,
    wgsl: &[("smoothness", include_str!("smoothness.wgsl"))],
    groups: &[SMOOTHNESS_GROUP],
    build: |s, priors| {
        let o = priors.of::<SmoothnessOptions>();
        let pass = Smoothness::new(s.gpu, s.set, s.grad, s.params, s.observed, o.weight)?;
        Ok(Box::new(pass))
    },
};

/// The prior's options (`[optimizer.smoothness]`, or `smoothness = <weight>` for short).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SmoothnessOptions {
    /// The prior's weight λ (0: off).
    pub weight: f32,
}

impl Options<super::PriorFamily> for SmoothnessOptions {
    const KIND: &'static Kind = &KIND;

    fn check(&self) -> std::result::Result<(), (String, String)> {
        if !(self.weight.is_finite() && (0.0..=1.0e6).contains(&self.weight)) {
            return Err((
                "weight".into(),
                "must be a number between 0 (off) and 1e6".into(),
            ));
        }
        Ok(())
    }

    fn on(&self) -> bool {
        self.weight > 0.0
    }

    fn describe(&self) -> String {
        format!("smoothness {}", self.weight)
    }
}

/// Group 0 of `smoothness.wgsl`.
pub(crate) const SMOOTHNESS_GROUP: GroupDecl = GroupDecl {
    pass: "smoothness",
    group: 0,
    names: &["sp", "grad", "params", "observed"],
};

/// Workgroup side of the pass (8 x 8 texels).
const WORKGROUP_SIDE: u32 = 8;

/// `SmoothnessParams` in smoothness.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SmoothnessParams {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub texel_offset: u32,
    pub scale: f32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// Observed 4-neighbour pairs of a `width` x `height` texture (no wrap).
pub fn observed_pairs(width: u32, height: u32, observed: &[bool]) -> u64 {
    let (w, h) = (width as usize, height as usize);
    let mut n = 0;
    for y in 0..h {
        for x in 0..w {
            let t = y * w + x;
            if !observed[t] {
                continue;
            }
            n += (x + 1 < w && observed[t + 1]) as u64 + (y + 1 < h && observed[t + w]) as u64;
        }
    }
    n
}

/// The pass's parameters for each texture of `set` with weight `lambda`.
pub fn params(set: &ParamSet, observed: &[bool], lambda: f32) -> Vec<SmoothnessParams> {
    let mut out = Vec::new();
    let mut texel_offset = 0u32;
    for t in &set.textures {
        let n = (t.width * t.height) as usize;
        let mask = &observed[texel_offset as usize..texel_offset as usize + n];
        let pairs = observed_pairs(t.width, t.height, mask);
        out.push(SmoothnessParams {
            offset: t.offset,
            width: t.width,
            height: t.height,
            channels: t.channels(),
            texel_offset,
            scale: 2.0 * lambda / (t.channels() as f32 * pairs.max(1) as f32),
            _pad0: 0,
            _pad1: 0,
        });
        texel_offset += t.width * t.height;
    }
    out
}

/// The prior's value `R` on one texture (`values` holds its `width * height * channels`
/// floats, `observed` one flag per texel), for tests.
pub fn penalty(p: &SmoothnessParams, lambda: f32, values: &[f32], observed: &[bool]) -> f64 {
    let (w, h, ch) = (p.width as usize, p.height as usize, p.channels as usize);
    let (mut sum, mut pairs) = (0.0f64, 0u64);
    for y in 0..h {
        for x in 0..w {
            let t = y * w + x;
            if !observed[t] {
                continue;
            }
            for n in [(x + 1 < w).then_some(t + 1), (y + 1 < h).then_some(t + w)]
                .into_iter()
                .flatten()
            {
                if observed[n] {
                    pairs += 1;
                    for c in 0..ch {
                        sum += (values[t * ch + c] as f64 - values[n * ch + c] as f64).powi(2);
                    }
                }
            }
        }
    }
    lambda as f64 * sum / (ch as f64 * pairs.max(1) as f64)
}

/// CPU twin of the pass on one texture: adds dR/dx to `grad`.
pub fn reference(p: &SmoothnessParams, grad: &mut [f32], values: &[f32], observed: &[bool]) {
    let (w, h, ch) = (p.width as i64, p.height as i64, p.channels as usize);
    let seen =
        |x: i64, y: i64| x >= 0 && y >= 0 && x < w && y < h && observed[(y * w + x) as usize];
    for y in 0..h {
        for x in 0..w {
            if !seen(x, y) {
                continue;
            }
            let t = (y * w + x) as usize;
            for c in 0..ch {
                let mut sum = 0.0f32;
                for (dx, dy) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
                    if seen(x + dx, y + dy) {
                        let n = ((y + dy) * w + x + dx) as usize;
                        sum += values[t * ch + c] - values[n * ch + c];
                    }
                }
                grad[t * ch + c] += p.scale * sum;
            }
        }
    }
}

/// The pass over every optimized texture.
pub(crate) struct Smoothness {
    pipeline: wgpu::ComputePipeline,
    /// Per texture: its bind group and parameters (the uniform is kept alive by the group).
    textures: Vec<(wgpu::BindGroup, SmoothnessParams)>,
}

impl Smoothness {
    /// The pass adding the prior's derivative with weight `lambda` to `grad`, from the
    /// parameters in `params`, over the texels marked in `observed` (one flag per texel)
    /// and, on the GPU, in `mask` (the observed-texel buffer).
    pub fn new(
        gpu: &Gpu,
        set: &ParamSet,
        grad: &wgpu::Buffer,
        params_buf: &wgpu::Buffer,
        (observed, mask): &(Vec<bool>, wgpu::Buffer),
        lambda: f32,
    ) -> Result<Smoothness> {
        let layout = gpu.pass_layout("smoothness", 0)?;
        let pipeline = gpu.compute_pipeline("smoothness", &[&layout])?;
        let mut textures = Vec::new();
        for (t, p) in set.textures.iter().zip(params(set, observed, lambda)) {
            let u = gpu.uniform(
                &format!("smoothness params {}", t.name()),
                bytemuck::bytes_of(&p),
            );
            let g = gpu.bind(
                &SMOOTHNESS_GROUP,
                "smoothness",
                &layout,
                &[
                    ("sp", &u),
                    ("grad", grad),
                    ("params", params_buf),
                    ("observed", mask),
                ],
            );
            textures.push((g, p));
        }
        Ok(Smoothness { pipeline, textures })
    }
}

impl super::Prior for Smoothness {
    fn encode(
        &mut self,
        _gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        _seed: u32,
        _iteration: u32,
        timer: &mut crate::optim::timing::PassTimer,
    ) {
        for (g, p) in &self.textures {
            let grid = (
                p.width.div_ceil(WORKGROUP_SIDE),
                p.height.div_ceil(WORKGROUP_SIDE),
            );
            let timing = timer.next(crate::optim::timing::PassKind::Prior);
            encode_timed_pass(enc, "smoothness", &self.pipeline, &[g], grid, timing);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6 x 5 texture, 3 channels, with unobserved texels inside and on the edges.
    fn case() -> (SmoothnessParams, Vec<f32>, Vec<bool>, f32) {
        let (w, h) = (6u32, 5u32);
        let observed: Vec<bool> = (0..w * h).map(|t| t % 7 != 3 && t != 0).collect();
        let values: Vec<f32> = (0..w * h * 3)
            .map(|i| ((i * 37) % 101) as f32 / 101.0)
            .collect();
        let lambda = 0.7;
        let pairs = observed_pairs(w, h, &observed);
        let p = SmoothnessParams {
            offset: 0,
            width: w,
            height: h,
            channels: 3,
            texel_offset: 0,
            scale: 2.0 * lambda / (3.0 * pairs as f32),
            _pad0: 0,
            _pad1: 0,
        };
        (p, values, observed, lambda)
    }

    #[test]
    fn the_pass_adds_the_derivative_of_the_penalty() {
        let (p, values, observed, lambda) = case();
        let mut grad = vec![0.0f32; values.len()];
        reference(&p, &mut grad, &values, &observed);
        // The penalty is quadratic: a central difference is exact up to rounding.
        let h = 1.0 / 64.0;
        for i in 0..values.len() {
            let (mut up, mut down) = (values.clone(), values.clone());
            up[i] += h;
            down[i] -= h;
            let fd = (penalty(&p, lambda, &up, &observed) - penalty(&p, lambda, &down, &observed))
                / (2.0 * h as f64);
            if !observed[i / 3] {
                // Unobserved texels are not in the penalty and get nothing.
                assert_eq!(fd, 0.0, "entry {i}");
                assert_eq!(grad[i], 0.0, "entry {i}");
            } else {
                assert!(
                    (grad[i] as f64 - fd).abs() < 1e-6,
                    "entry {i}: {} vs {fd}",
                    grad[i]
                );
            }
        }
        assert!(grad.iter().any(|&g| g.abs() > 1e-3));
    }

    #[test]
    fn pairs_count_observed_neighbours_only() {
        // 3 x 2, all observed: 2 x 2 horizontal + 3 vertical pairs.
        assert_eq!(observed_pairs(3, 2, &[true; 6]), 7);
        // The middle of the top row unseen: it takes 3 pairs with it.
        assert_eq!(
            observed_pairs(3, 2, &[true, false, true, true, true, true]),
            4
        );
    }
}
