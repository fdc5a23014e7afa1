//! Image losses on the CPU: the reference for shaders/loss.wgsl and for tests.
use crate::vocab::Loss;

/// Epsilon of relMSE: (I - G)^2 / (G^2 + REL_EPS).
pub const REL_EPS: f32 = 0.01;

/// Loss of one image against its target: the mean over pixels and channels.
pub fn loss(kind: Loss, image: &[[f32; 3]], target: &[[f32; 3]]) -> f64 {
    let n = (image.len() * 3) as f64;
    image
        .iter()
        .zip(target)
        .flat_map(|(i, g)| (0..3).map(move |c| (i[c] as f64, g[c] as f64)))
        .map(|(i, g)| {
            let d = i - g;
            match kind {
                Loss::L2 => d * d,
                Loss::Relmse => d * d / (g * g + REL_EPS as f64),
            }
        })
        .sum::<f64>()
        / n
}

/// dL/dI per pixel and channel, for [`loss`].
pub fn adjoint(kind: Loss, image: &[[f32; 3]], target: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let n = (image.len() * 3) as f32;
    image
        .iter()
        .zip(target)
        .map(|(i, g)| {
            let mut a = [0.0; 3];
            for c in 0..3 {
                let w = match kind {
                    Loss::L2 => 1.0,
                    Loss::Relmse => 1.0 / (g[c] * g[c] + REL_EPS),
                };
                a[c] = 2.0 * (i[c] - g[c]) * w / n;
            }
            a
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adjoints_equal_central_finite_differences() {
        let image: Vec<[f32; 3]> = (0..7)
            .map(|k| [0.1 * k as f32, 0.5, 1.0 - 0.1 * k as f32])
            .collect();
        let target: Vec<[f32; 3]> = (0..7).map(|k| [0.3, 0.05 * k as f32, 0.2]).collect();
        for kind in [Loss::L2, Loss::Relmse] {
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
                    // Both losses are quadratic in I, so the central difference is exact up to
                    // rounding: 1e-4 relative is float noise.
                    assert!(
                        (fd - a[p][c] as f64).abs() <= 1e-4 * fd.abs().max(1e-3),
                        "{kind:?} pixel {p} channel {c}: {fd} vs {}",
                        a[p][c]
                    );
                }
            }
        }
    }
}

/// `LossParams` in shaders/loss.wgsl (a test checks the layout).
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
    pub exposure: f32,
    pub _pad: [u32; 2],
}

/// Image relMSE: mean over pixels and channels of (x - t)^2 / (t^2 + 1e-2).
pub fn image_relmse(img: &crate::image_io::Image, target: &crate::image_io::Image) -> f64 {
    let mut s = 0.0;
    for (a, t) in img.rgb.iter().zip(&target.rgb) {
        for c in 0..3 {
            let (a, t) = (a[c] as f64, t[c] as f64);
            s += (a - t).powi(2) / (t * t + REL_EPS as f64);
        }
    }
    s / (3 * target.rgb.len()).max(1) as f64
}
