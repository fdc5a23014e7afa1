//! Image losses: the loss pass on the GPU (`LossPass`, src/optim/loss.wgsl, its uniform
//! [`LossParams`]) and the CPU reference for it and for tests.
use crate::gpu::{encode_timed_pass, grid_2d, Gpu, GroupDecl};
use crate::image_io::Image;
use crate::render::WORKGROUP;
use crate::vocab::Loss;
use crate::Result;

/// Epsilon of relMSE: (I - G)^2 / (G^2 + REL_EPS).
pub const REL_EPS: f32 = 0.01;

/// A photo's channel at or above this linear value was clipped (`CLIPPED` in loss.wgsl).
pub const CLIPPED: f32 = 0.999;

/// The sRGB transfer curve of a linear value, continued above 1.
pub fn srgb_encode(x: f64) -> f64 {
    let v = x.max(0.0);
    if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// One channel's term of `kind` before the mean: (weight, f(i) - f(g), f'(i)), the loss
/// being weight x (f(i) - f(g))^2.
fn channel(kind: Loss, i: f64, g: f64) -> (f64, f64, f64) {
    match kind {
        Loss::L2 => (1.0, i - g, 1.0),
        Loss::Relmse => (1.0 / (g * g + REL_EPS as f64), i - g, 1.0),
        Loss::Srgb => {
            let clipped = g >= CLIPPED as f64 && i >= g;
            let slope = if i <= 0.0031308 {
                12.92
            } else {
                1.055 / 2.4 * i.powf(1.0 / 2.4 - 1.0)
            };
            let w = if clipped { 0.0 } else { 1.0 };
            (w, srgb_encode(i) - srgb_encode(g), slope)
        }
        Loss::Log => {
            let r = i.max(0.0);
            (
                1.0,
                (1.0 + r).ln() - (1.0 + g.max(0.0)).ln(),
                1.0 / (1.0 + r),
            )
        }
    }
}

/// Loss of one image against its target: the mean over pixels and channels.
pub fn loss(kind: Loss, image: &[[f32; 3]], target: &[[f32; 3]]) -> f64 {
    let n = (image.len() * 3) as f64;
    image
        .iter()
        .zip(target)
        .flat_map(|(i, g)| (0..3).map(move |c| (i[c] as f64, g[c] as f64)))
        .map(|(i, g)| {
            let (w, d, _) = channel(kind, i, g);
            w * d * d
        })
        .sum::<f64>()
        / n
}

/// dL/dI per pixel and channel, for [`loss`].
pub fn adjoint(kind: Loss, image: &[[f32; 3]], target: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let n = (image.len() * 3) as f64;
    image
        .iter()
        .zip(target)
        .map(|(i, g)| {
            std::array::from_fn(|c| {
                let (w, d, slope) = channel(kind, i[c] as f64, g[c] as f64);
                (2.0 * w * d * slope / n) as f32
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adjoints_equal_central_finite_differences() {
        let mut image: Vec<[f32; 3]> = (0..7)
            .map(|k| [0.05 + 0.1 * k as f32, 0.5, 1.0 - 0.1 * k as f32])
            .collect();
        // Above a clipped target (no term), and below it (a term).
        image[0][2] = 1.2;
        let target: Vec<[f32; 3]> = (0..7)
            .map(|k| [0.3, 0.05 * k as f32, if k < 3 { 1.0 } else { 0.2 }])
            .collect();
        for kind in [Loss::L2, Loss::Relmse, Loss::Srgb, Loss::Log] {
            let a = adjoint(kind, &image, &target);
            for p in 0..image.len() {
                for c in 0..3 {
                    let h = 1e-3f32;
                    let mut plus = image.clone();
                    let mut minus = image.clone();
                    plus[p][c] += h;
                    minus[p][c] -= h;
                    let fd = (loss(kind, &plus, &target) - loss(kind, &minus, &target))
                        / (2.0 * h as f64);
                    // L2 and relMSE are quadratic in I, so the central difference is exact up
                    // to rounding (1e-4 relative is float noise); the sRGB and log curves
                    // leave an O(h^2) truncation, under 1e-3 relative at h = 1e-3 away from
                    // the curves' kinks, which the values avoid.
                    let tol = match kind {
                        Loss::L2 | Loss::Relmse => 1e-4,
                        Loss::Srgb | Loss::Log => 1e-3,
                    };
                    assert!(
                        (fd - a[p][c] as f64).abs() <= tol * fd.abs().max(1e-3),
                        "{kind:?} pixel {p} channel {c}: {fd} vs {}",
                        a[p][c]
                    );
                }
            }
            if kind == Loss::Srgb {
                assert_eq!(a[0][2], 0.0, "a render above a clipped photo has no term");
                assert!(a[1][2] < 0.0, "a render below a clipped photo is pulled up");
            }
        }
    }
}

/// `LossParams` in src/optim/loss.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LossParams {
    pub n_pixels: u32,
    pub kind: u32,
    pub norm: f32,
    pub partial_offset: u32,
    pub adjoint_offset: u32,
    pub _pad: [u32; 3],
    pub gain: [f32; 3],
    pub _pad1: u32,
    pub gain_prev: [f32; 3],
    pub _pad2: u32,
}

/// Group 0 of `loss.wgsl`.
pub(crate) const LOSS_GROUP: GroupDecl = GroupDecl {
    pass: "loss",
    group: 0,
    names: &[
        "lp",
        "accum",
        "target_image",
        "adjoint",
        "loss_partial",
        "loss_stats",
        "exposure_partial",
        "adjoint_prev",
    ],
};

/// The loss pass of every camera (src/optim/loss.wgsl): the loss of the primal render (times
/// the camera's gain: exposure times white balance) against the target with its mask, the
/// adjoint image dL/dI into the iteration's adjoint buffer, and per workgroup the partial
/// sums of the loss and of dL/d(gain) per channel.
pub(crate) struct LossPass {
    pipeline: wgpu::ComputePipeline,
    grid: (u32, u32),
    /// Workgroups of one camera's pass.
    n_groups: u32,
    /// Per workgroup and camera: the loss's partial sums.
    partial: wgpu::Buffer,
    /// Per workgroup and camera: dL/d(gain)'s partial sums (3 per workgroup).
    exposure_partial: wgpu::Buffer,
    /// LOSS_* counters.
    pub(crate) stats: wgpu::Buffer,
    cams: Vec<LossCamera>,
}

/// One camera's loss pass.
struct LossCamera {
    uniform: wgpu::Buffer,
    params: LossParams,
    /// The target (RGB) with the mask's weight in A.
    target: wgpu::Buffer,
    /// Per parity of the iteration (the adjoint buffers alternate).
    groups: [wgpu::BindGroup; 2],
}

impl LossPass {
    /// The pass of `targets` (one per camera, each `width` x `height`), reading the primal
    /// render from `accum` and writing `adjoint[iteration % 2]`.
    pub(crate) fn new(
        gpu: &Gpu,
        kind: Loss,
        (width, height): (u32, u32),
        targets: &[Image],
        accum: &wgpu::Buffer,
        adjoint: &[wgpu::Buffer; 2],
    ) -> Result<LossPass> {
        let layout = gpu.pass_layout("loss", 0)?;
        let pipeline = gpu.compute_pipeline("loss", &[&layout])?;
        let n_pixels = width * height;
        let n_cams = targets.len() as u32;
        let n_groups = n_pixels.div_ceil(WORKGROUP);
        let partial = gpu.storage_zeroed("loss partial sums", (n_groups * n_cams) as u64 * 4);
        let exposure_partial =
            gpu.storage_zeroed("exposure partial sums", (n_groups * n_cams) as u64 * 12);
        let stats = gpu.storage_zeroed("loss stats", 16);
        let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
        let norm = 1.0 / (n_pixels as f32 * 3.0 * n_cams as f32);
        let cams = targets
            .iter()
            .enumerate()
            .map(|(k, target)| {
                let params = LossParams {
                    n_pixels,
                    kind: match kind {
                        Loss::L2 => 0,
                        Loss::Relmse => 1,
                        Loss::Srgb => 2,
                        Loss::Log => 3,
                    },
                    norm,
                    partial_offset: k as u32 * n_groups,
                    adjoint_offset: k as u32 * n_pixels,
                    gain: [1.0; 3],
                    gain_prev: [1.0; 3],
                    ..Default::default()
                };
                // Mask weight 1 everywhere until set_targets says otherwise.
                let data: Vec<[f32; 4]> =
                    target.rgb.iter().map(|p| [p[0], p[1], p[2], 1.0]).collect();
                let target = gpu.storage(
                    &format!("target {k}"),
                    bytemuck::cast_slice(&data),
                    wgpu::BufferUsages::empty(),
                );
                let uniform = gpu.uniform(&format!("loss params {k}"), bytemuck::bytes_of(&params));
                let groups = [0usize, 1].map(|p| {
                    gpu.bind(
                        &LOSS_GROUP,
                        "loss",
                        &layout,
                        &[
                            ("lp", &uniform),
                            ("accum", accum),
                            ("target_image", &target),
                            ("adjoint", &adjoint[p]),
                            ("loss_partial", &partial),
                            ("loss_stats", &stats),
                            ("exposure_partial", &exposure_partial),
                            ("adjoint_prev", &adjoint[1 - p]),
                        ],
                    )
                });
                LossCamera {
                    uniform,
                    params,
                    target,
                    groups,
                }
            })
            .collect();
        Ok(LossPass {
            pipeline,
            grid: grid_2d(n_pixels, WORKGROUP, max_dim),
            n_groups,
            partial,
            exposure_partial,
            stats,
            cams,
        })
    }

    /// Record camera `k`'s pass for an iteration of adjoint parity `parity`.
    pub(crate) fn encode(
        &self,
        enc: &mut wgpu::CommandEncoder,
        k: usize,
        parity: usize,
        timing: Option<(&wgpu::QuerySet, u32)>,
    ) {
        let groups = [&self.cams[k].groups[parity]];
        encode_timed_pass(enc, "loss", &self.pipeline, &groups, self.grid, timing);
    }

    /// The loss of the last pass of every camera (the sum of its partial sums).
    pub(crate) fn read_loss(&self, gpu: &Gpu) -> Result<f64> {
        let partial: Vec<f32> = gpu.read_pod(&self.partial)?;
        Ok(partial.iter().map(|&v| v as f64).sum())
    }

    /// dL/d(gain) per channel of each camera from the last passes.
    pub(crate) fn read_gain_gradients(&self, gpu: &Gpu) -> Result<Vec<[f64; 3]>> {
        let partial: Vec<f32> = gpu.read_pod(&self.exposure_partial)?;
        let n = self.n_groups as usize;
        Ok((0..self.cams.len())
            .map(|k| {
                let mut g = [0f64; 3];
                for p in partial[3 * k * n..3 * (k + 1) * n].chunks_exact(3) {
                    for c in 0..3 {
                        g[c] += p[c] as f64;
                    }
                }
                g
            })
            .collect())
    }

    /// Upload camera `k`'s target pixels (RGB and the mask's weight in A).
    pub(crate) fn write_target(&self, gpu: &Gpu, k: usize, data: &[[f32; 4]]) {
        let target = &self.cams[k].target;
        gpu.queue
            .write_buffer(target, 0, bytemuck::cast_slice(data));
    }

    /// The normalization: 1 / the sum of the weights of all cameras' channels.
    pub(crate) fn norm(&self) -> f32 {
        self.cams[0].params.norm
    }

    /// Set every camera's normalization (1 / the sum of the weights of all channels).
    pub(crate) fn set_norm(&mut self, gpu: &Gpu, norm: f32) {
        for k in 0..self.cams.len() {
            self.cams[k].params.norm = norm;
            self.upload(gpu, k);
        }
    }

    /// Set each camera's gains (per channel), and those the adjoint of the last pass was
    /// written with.
    pub(crate) fn set_gains(&mut self, gpu: &Gpu, gains: &[[f32; 3]], previous: &[[f32; 3]]) {
        for (k, (&g, &p)) in gains.iter().zip(previous).enumerate().take(self.cams.len()) {
            self.cams[k].params.gain = g;
            self.cams[k].params.gain_prev = p;
            self.upload(gpu, k);
        }
    }

    fn upload(&self, gpu: &Gpu, k: usize) {
        let cam = &self.cams[k];
        gpu.queue
            .write_buffer(&cam.uniform, 0, bytemuck::bytes_of(&cam.params));
    }
}

/// Image relMSE: mean over pixels and channels of (x - t)^2 / (t^2 + 1e-2).
pub fn image_relmse(img: &crate::image_io::Image, target: &crate::image_io::Image) -> f64 {
    image_relmse_cross(img, img, target)
}

/// The relMSE's cross term of two renders: mean over pixels and channels of
/// (a - t)(b - t) / (t^2 + 1e-2). With `a` and `b` independent renders of the same
/// textures, its mean is the relMSE of their expectation, without the renders' own variance
/// (a single render's relMSE adds its variance to it); one estimate may fall below zero
/// where that expectation matches the target closely.
pub fn image_relmse_cross(
    a: &crate::image_io::Image,
    b: &crate::image_io::Image,
    target: &crate::image_io::Image,
) -> f64 {
    let mut s = 0.0;
    for ((a, b), t) in a.rgb.iter().zip(&b.rgb).zip(&target.rgb) {
        for c in 0..3 {
            let (a, b, t) = (a[c] as f64, b[c] as f64, t[c] as f64);
            s += (a - t) * (b - t) / (t * t + REL_EPS as f64);
        }
    }
    s / (3 * target.rgb.len()).max(1) as f64
}
