//! Relighting as the judge of a recovery: the recovered model (its textures in the fitted
//! scene) and the ground truth rendered under environments that lit neither the targets nor
//! the fit, compared after a per-channel scale alignment (albedo and light share a scale that
//! images do not fix), as the real-capture benchmarks score relit images.
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::render::params::ParamSet;
use crate::render::{RenderSettings, Renderer, Techniques};
use crate::scene::{EnvMap, Scene};
use crate::{Error, Result};
use std::path::Path;

/// The relit error under one environment, over every camera's pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct RelitError {
    /// The environment's name (its file stem).
    pub environment: String,
    /// Mean over pixels and channels of (s r - t)^2 / (t^2 + 0.01), r the recovery's relit
    /// render, t the truth's, s the channel's alignment.
    pub relmse: f64,
    /// PSNR (dB) of the aligned render against the truth, both clamped to [0, 1].
    pub psnr: f64,
    /// The per-channel scales s (least squares over all pixels).
    pub scale: [f64; 3],
}

/// `renders` against `truths` (the same cameras in the same order) after the per-channel
/// least-squares scale.
pub fn aligned_error(environment: &str, renders: &[Image], truths: &[Image]) -> RelitError {
    let mut rt = [0f64; 3];
    let mut rr = [0f64; 3];
    for (r, t) in renders.iter().zip(truths) {
        for (a, b) in r.rgb.iter().zip(&t.rgb) {
            for c in 0..3 {
                rt[c] += a[c] as f64 * b[c] as f64;
                rr[c] += a[c] as f64 * a[c] as f64;
            }
        }
    }
    let scale: [f64; 3] = std::array::from_fn(|c| if rr[c] > 0.0 { rt[c] / rr[c] } else { 1.0 });
    let (mut rel, mut se, mut n) = (0f64, 0f64, 0f64);
    for (r, t) in renders.iter().zip(truths) {
        for (a, b) in r.rgb.iter().zip(&t.rgb) {
            for c in 0..3 {
                let (x, y) = (scale[c] * a[c] as f64, b[c] as f64);
                rel += (x - y).powi(2) / (y * y + 0.01);
                se += (x.clamp(0.0, 1.0) - y.clamp(0.0, 1.0)).powi(2);
                n += 1.0;
            }
        }
    }
    let mse = se / n.max(1.0);
    RelitError {
        environment: environment.to_string(),
        relmse: rel / n.max(1.0),
        psnr: if mse > 0.0 {
            -10.0 * mse.log10()
        } else {
            f64::INFINITY
        },
        scale,
    }
}

/// What a relit evaluation renders: the fitted scene with the recovered textures, the ground
/// truth, the cameras, the image size, samples and seed.
pub struct Relight<'a> {
    /// The fitted scene (its environment is replaced by each evaluation environment).
    pub scene: &'a Scene,
    /// The recovered textures.
    pub set: &'a ParamSet,
    /// The ground truth.
    pub truth: &'a Scene,
    /// The cameras (indices into both scenes').
    pub cameras: &'a [usize],
    /// Image size.
    pub size: (u32, u32),
    /// Samples per pixel of every render.
    pub spp: u32,
    /// Seed of the renders (the same for the recovery and the truth).
    pub seed: u32,
}

impl Relight<'_> {
    /// The recovery's and the truth's renders under `env`, one per camera.
    pub fn render(&self, gpu: &Gpu, env: &EnvMap) -> Result<(Vec<Image>, Vec<Image>)> {
        // Both looked up as the truth is (the held-out map is the truth's kind of light).
        let lit = |s: &Scene| {
            let mut s = s.clone();
            s.env = Some(env.clone());
            s.env_bilinear = self.truth.env_bilinear;
            s
        };
        let recovered = Renderer::with_params(gpu, &lit(self.scene), self.set)?;
        let truth = Renderer::new(gpu, &lit(self.truth))?;
        let mut out = (Vec::new(), Vec::new());
        for (k, &camera) in self.cameras.iter().enumerate() {
            let settings = RenderSettings {
                width: self.size.0,
                height: self.size.1,
                spp: self.spp,
                seed: self.seed.wrapping_add(k as u32),
                camera,
                techniques: Techniques::Mis,
            };
            out.0.push(recovered.render(&settings, |_| {})?.image);
            out.1.push(truth.render(&settings, |_| {})?.image);
        }
        Ok(out)
    }

    /// The relit error under each of `envs` (name, map).
    pub fn errors(&self, gpu: &Gpu, envs: &[(String, EnvMap)]) -> Result<Vec<RelitError>> {
        envs.iter()
            .map(|(name, env)| {
                let (r, t) = self.render(gpu, env)?;
                Ok(aligned_error(name, &r, &t))
            })
            .collect()
    }
}

/// The relit errors of `values` (the textures of `prep`'s layout) under `task`'s `relight`
/// environments, at `spp` samples per pixel from `seed`: none without them or without a
/// ground truth. The run's outputs and the bench both measure with it.
pub fn task_errors(
    gpu: &Gpu,
    task: &crate::task::Task,
    prep: &crate::job::Problem,
    values: Vec<f32>,
    spp: u32,
    seed: u32,
) -> Result<Vec<RelitError>> {
    let Some(truth) = prep.truth.as_ref().filter(|_| !task.relight.is_empty()) else {
        return Ok(Vec::new());
    };
    let paths: Vec<_> = task.relight.iter().map(|p| task.resolve(p)).collect();
    let envs = load_environments(&paths)?;
    let set = ParamSet {
        textures: prep.set.textures.clone(),
        values,
    };
    let first = prep
        .targets
        .first()
        .ok_or_else(|| Error::Invalid("relighting: the problem has no targets".into()))?;
    Relight {
        scene: &prep.scene,
        set: &set,
        truth,
        cameras: &prep.cameras,
        size: (first.width, first.height),
        spp,
        seed,
    }
    .errors(gpu, &envs)
}

/// The angle (degrees) between two environments' directions of strongest emission.
pub fn direction_error_deg(a: &EnvMap, b: &EnvMap) -> f64 {
    let d = a.strongest_direction().dot(b.strongest_direction());
    (d.clamp(-1.0, 1.0) as f64).acos().to_degrees()
}

/// Load the evaluation environments, each named by its file stem.
pub fn load_environments(paths: &[std::path::PathBuf]) -> Result<Vec<(String, EnvMap)>> {
    paths
        .iter()
        .map(|p| {
            let name = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .ok_or_else(|| Error::file(p, "an environment file needs a name"))?;
            Ok((name, EnvMap::load(p)?))
        })
        .collect()
}

/// `relight.csv`: one row per environment (written atomically).
pub fn write_relight_csv(path: &Path, rows: &[RelitError]) -> Result<()> {
    let mut s = String::from("environment,relit_relmse,relit_psnr_db,scale_r,scale_g,scale_b\n");
    for r in rows {
        s.push_str(&format!(
            "{},{:.6e},{:.3},{:.5},{:.5},{:.5}\n",
            r.environment, r.relmse, r.psnr, r.scale[0], r.scale[1], r.scale[2]
        ));
    }
    crate::image_io::write_atomic(path, s.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(v: &[[f32; 3]]) -> Image {
        Image {
            width: v.len() as u32,
            height: 1,
            rgb: v.to_vec(),
        }
    }

    /// A render off by a per-channel factor aligns to zero error; a wrong shape does not.
    #[test]
    fn a_per_channel_scale_is_aligned_away_and_a_wrong_shape_is_not() {
        let t = image(&[[0.2, 0.4, 0.1], [0.6, 0.3, 0.05], [0.1, 0.1, 0.9]]);
        let r = image(
            &t.rgb
                .iter()
                .map(|p| [p[0] * 2.0, p[1] * 0.5, p[2] * 3.0])
                .collect::<Vec<_>>(),
        );
        let e = aligned_error("x", &[r], std::slice::from_ref(&t));
        assert!(e.relmse < 1e-12, "{e:?}");
        assert!((e.scale[0] - 0.5).abs() < 1e-6 && (e.scale[1] - 2.0).abs() < 1e-6);
        let wrong = image(&[[0.6, 0.3, 0.05], [0.2, 0.4, 0.1], [0.1, 0.1, 0.9]]);
        let e = aligned_error("x", &[wrong], &[t]);
        assert!(e.relmse > 0.1 && e.psnr < 20.0, "{e:?}");
    }
}
