//! Environment light from an equirectangular image, with the tables for importance sampling.
use crate::{Error, Result};
use std::path::Path;

/// An equirectangular environment map: +Y up, u = 0 towards -Z, u increasing towards +X,
/// v = 0 at the zenith.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Linear RGB radiance, row 0 at the zenith.
    pub rgb: Vec<[f32; 3]>,
    /// Multiplier applied to every texel.
    pub scale: f32,
}

impl EnvMap {
    /// Load an `.exr` or `.hdr` file.
    pub fn load(path: &Path) -> Result<EnvMap> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let (width, height, rgb) = match ext.as_str() {
            "exr" => crate::image_io::decode::decode_exr(path)?,
            "hdr" => {
                let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
                crate::image_io::decode::decode_hdr(&bytes, path)?
            }
            _ => {
                return Err(Error::file(
                    path,
                    "environment maps must be OpenEXR (.exr) or Radiance HDR (.hdr)",
                ))
            }
        };
        if rgb.iter().flatten().any(|v| !v.is_finite()) {
            return Err(Error::file(path, "environment map has non-finite texels"));
        }
        // Lossy EXR compression (B44, PXR24) leaves small negative values near zero.
        let mut rgb = rgb;
        let negative = rgb.iter().flatten().filter(|v| **v < 0.0).count();
        if negative > 0 {
            log::warn!(
                "{}: {negative} negative texel values set to 0 (radiance cannot be negative)",
                path.display()
            );
            rgb.iter_mut().flatten().for_each(|v| *v = v.max(0.0));
        }
        Ok(EnvMap {
            width,
            height,
            rgb,
            scale: 1.0,
        })
    }

    /// A constant environment of radiance `rgb`.
    pub fn constant(rgb: [f32; 3]) -> EnvMap {
        EnvMap {
            width: 8,
            height: 4,
            rgb: vec![rgb; 32],
            scale: 1.0,
        }
    }

    /// The direction of texture coordinates (u, v) (shared/lights.wgsl's env_direction):
    /// +Y up, u the azimuth from -Z towards +X, v the polar angle over pi.
    pub fn direction(u: f32, v: f32) -> glam::Vec3 {
        let (phi, theta) = (2.0 * std::f32::consts::PI * u, std::f32::consts::PI * v);
        glam::Vec3::new(
            theta.sin() * phi.sin(),
            theta.cos(),
            -theta.sin() * phi.cos(),
        )
    }

    /// The direction of the texel of highest luminance (its centre): where the map emits most
    /// strongly.
    pub fn strongest_direction(&self) -> glam::Vec3 {
        let lum = |c: &[f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let k = (0..self.rgb.len())
            .max_by(|&a, &b| lum(&self.rgb[a]).total_cmp(&lum(&self.rgb[b])))
            .unwrap_or(0);
        let (i, j) = (k as u32 % self.width, k as u32 / self.width);
        EnvMap::direction(
            (i as f32 + 0.5) / self.width as f32,
            (j as f32 + 0.5) / self.height as f32,
        )
    }

    /// Sampling density weight of each texel: luminance times sin(theta) (the solid angle of
    /// the texel row), scaled.
    fn weights(&self) -> Vec<f64> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut f = vec![0f64; w * h];
        for j in 0..h {
            let sin_t = (std::f64::consts::PI * (j as f64 + 0.5) / h as f64).sin();
            for i in 0..w {
                let c = self.rgb[j * w + i];
                let lum = 0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64;
                f[j * w + i] = lum.max(0.0) * sin_t;
            }
        }
        f
    }

    /// Power proxy for light selection: pi x mean radiance weighted by solid angle, times the
    /// scene's cross-section. In f64: texels near f32::MAX overflowed it in f32 (found by
    /// fuzzing).
    pub fn power(&self, scene_radius: f32) -> f64 {
        let f = self.weights();
        let n = (self.width as f64) * (self.height as f64);
        let mean = f.iter().sum::<f64>() / n * std::f64::consts::PI / 2.0;
        mean * self.scale as f64 * std::f64::consts::PI * (scene_radius as f64).powi(2)
    }

    /// The GPU table (see `SceneInfo` in shaders/shared/types.wgsl): RGB texels, then the
    /// marginal CDF (height+1), then per row the conditional CDF (width+1). Returns the table
    /// and the offsets of the marginal and conditional parts.
    pub fn gpu_table(&self) -> (Vec<f32>, u32, u32) {
        let (w, h) = (self.width as usize, self.height as usize);
        let f = self.weights();
        let mut table: Vec<f32> = self.rgb.iter().flatten().copied().collect();
        let marginal = table.len();
        let conditional = marginal + h + 1;
        table.resize(conditional + h * (w + 1), 0.0);
        let row_sums: Vec<f64> = (0..h).map(|j| f[j * w..(j + 1) * w].iter().sum()).collect();
        let total: f64 = row_sums.iter().sum();
        let mut acc = 0.0;
        for j in 0..h {
            table[marginal + j] = if total > 0.0 {
                (acc / total) as f32
            } else {
                j as f32 / h as f32
            };
            acc += row_sums[j];
            let row = conditional + j * (w + 1);
            let mut racc = 0.0;
            for i in 0..w {
                table[row + i] = if row_sums[j] > 0.0 {
                    (racc / row_sums[j]) as f32
                } else {
                    i as f32 / w as f32
                };
                racc += f[j * w + i];
            }
            table[row + w] = 1.0;
        }
        table[marginal + h] = 1.0;
        (table, marginal as u32, conditional as u32)
    }
}
