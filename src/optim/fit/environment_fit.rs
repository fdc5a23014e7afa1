//! The environment as a parameter: a lat-long RGB map recovered with the textures.
//!
//! Each texel's radiance is `exp(θ)` (positive by construction); θ is the parameter table's
//! `environment` group, moved by the run's step on the CPU (Adam's where the step has no CPU
//! path) at its own learning rate from dL/d(radiance), which every gradient pass scatters
//! from the path segments that escape to the environment (shared/env_gradient.wgsl). The
//! sampling tables (the environment's importance sampling and its share of the light choice)
//! are rebuilt from the current estimate every `rebuild_every` iterations; between rebuilds
//! the texels change and the tables stay, which every density reads too, so the estimates
//! stay unbiased. Optional priors act on θ: smoothness (squared differences of neighbouring
//! texels' logarithms) and gray world (the logarithms of the three channels' solid-angle
//! means pulled together). Albedo and light share a scale that images do not fix: the
//! gauge `mean` holds the environment's mean luminance at its start after every step;
//! `none` leaves the scale free (docs/guide.md, "Unknown light").
use crate::scene::EnvMap;

use serde::{Deserialize, Serialize};

/// Which scale of the environment is held fixed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Gauge {
    /// Nothing: albedo and light share their scale freely (judge with an aligned relit error).
    #[default]
    None,
    /// The solid-angle mean luminance of the environment stays at its starting value.
    Mean,
}

/// How the environment is recovered.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvFitOptions {
    /// Learning rate of the texels' logarithms.
    #[serde(default = "default_lr")]
    pub learning_rate: f32,
    /// Iterations between rebuilds of the sampling tables (1: every iteration).
    #[serde(default = "default_rebuild")]
    pub rebuild_every: u32,
    /// Weight of the smoothness prior on the logarithms (0: off).
    #[serde(default)]
    pub smoothness: f32,
    /// Weight of the gray-world prior on the channels' means (0: off).
    #[serde(default)]
    pub gray_world: f32,
    /// The scale held fixed.
    #[serde(default)]
    pub gauge: Gauge,
    /// Iterations at the start in which only the environment steps and the textures hold,
    /// so that they do not absorb the starting light's error first.
    #[serde(default)]
    pub warmup_iterations: u32,
}

fn default_lr() -> f32 {
    0.05
}
fn default_rebuild() -> u32 {
    4
}

impl Default for EnvFitOptions {
    fn default() -> EnvFitOptions {
        EnvFitOptions {
            learning_rate: default_lr(),
            rebuild_every: default_rebuild(),
            smoothness: 0.0,
            gray_world: 0.0,
            gauge: Gauge::None,
            warmup_iterations: 0,
        }
    }
}

impl EnvFitOptions {
    /// Range checks; an error names the key (under `[environment]`) and what is wrong.
    pub fn check(&self) -> std::result::Result<(), (String, String)> {
        let bad = |k: &str, m: &str| Err((k.to_string(), m.to_string()));
        if !(self.learning_rate.is_finite()
            && self.learning_rate > 0.0
            && self.learning_rate <= 10.0)
        {
            return bad("learning_rate", "must be a number in (0, 10]");
        }
        if !(1..=100_000).contains(&self.rebuild_every) {
            return bad("rebuild_every", "must be between 1 and 100000 iterations");
        }
        for (k, v) in [
            ("smoothness", self.smoothness),
            ("gray_world", self.gray_world),
        ] {
            if !(v.is_finite() && (0.0..=1.0e6).contains(&v)) {
                return bad(k, "must be a number between 0 (off) and 1e6");
            }
        }
        Ok(())
    }
}

/// What the environment's fit keeps besides its texels' logarithms and their step's state
/// (the parameter table's `environment` group).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvFitState {
    /// Width and height in texels.
    pub size: [u32; 2],
    /// The solid-angle mean luminance the `mean` gauge holds.
    pub mean_luminance: f64,
}

pub(in crate::optim) struct EnvFit {
    pub opts: EnvFitOptions,
    pub state: EnvFitState,
}

/// The pairs of neighbouring texels of a `w` x `h` lat-long map: each with the next in its
/// row (wrapping in azimuth) and the one below it.
fn neighbour_pairs(w: usize, h: usize) -> Vec<(usize, usize)> {
    let mut pairs = Vec::with_capacity(2 * w * h);
    for j in 0..h {
        for i in 0..w {
            pairs.push((j * w + i, j * w + (i + 1) % w));
            if j + 1 < h {
                pairs.push((j * w + i, (j + 1) * w + i));
            }
        }
    }
    pairs
}

/// Solid angle of each row's texels (sin θ dθ dφ).
fn row_weights(w: usize, h: usize) -> Vec<f64> {
    use std::f64::consts::PI;
    (0..h)
        .map(|j| {
            let t0 = PI * j as f64 / h as f64;
            let t1 = PI * (j + 1) as f64 / h as f64;
            (t0.cos() - t1.cos()) * 2.0 * PI / w as f64
        })
        .collect()
}

/// Solid-angle mean of each channel of an environment.
pub fn channel_means(env: &EnvMap) -> [f64; 3] {
    let (w, h) = (env.width as usize, env.height as usize);
    let rw = row_weights(w, h);
    let mut m = [0f64; 3];
    for j in 0..h {
        for i in 0..w {
            for (c, mc) in m.iter_mut().enumerate() {
                *mc += rw[j] * env.rgb[j * w + i][c] as f64;
            }
        }
    }
    m.map(|v| v * env.scale as f64 / (4.0 * std::f64::consts::PI))
}

pub(super) fn luminance(m: [f64; 3]) -> f64 {
    0.2126 * m[0] + 0.7152 * m[1] + 0.0722 * m[2]
}

/// ln(radiance) per texel and channel of `env`, and what its fit keeps.
pub(super) fn logarithms(env: &EnvMap) -> (Vec<f32>, EnvFitState) {
    let log = (env.rgb.iter().flatten())
        .map(|&v| (v * env.scale).max(1e-6).ln())
        .collect();
    let state = EnvFitState {
        size: [env.width, env.height],
        mean_luminance: luminance(channel_means(env)),
    };
    (log, state)
}

impl EnvFitState {
    /// The environment the logarithms `log` describe (scale 1).
    pub fn env(&self, log: &[f32]) -> EnvMap {
        EnvMap {
            width: self.size[0],
            height: self.size[1],
            rgb: log
                .chunks(3)
                .map(|c| [c[0].exp(), c[1].exp(), c[2].exp()])
                .collect(),
            scale: 1.0,
        }
    }

    /// The priors' gradient with respect to the logarithms `log`, added into `g`.
    fn add_priors(&self, opts: &EnvFitOptions, log: &[f32], g: &mut [f32]) {
        let (w, h) = (self.size[0] as usize, self.size[1] as usize);
        if opts.smoothness > 0.0 {
            // smoothness x mean over neighbour pairs (wrapping in azimuth) of squared
            // differences.
            let pairs = neighbour_pairs(w, h);
            let k = 2.0 * opts.smoothness / (3.0 * pairs.len() as f32);
            for (a, b) in pairs {
                for c in 0..3 {
                    let d = log[3 * a + c] - log[3 * b + c];
                    g[3 * a + c] += k * d;
                    g[3 * b + c] -= k * d;
                }
            }
        }
        if opts.gray_world > 0.0 {
            // gray_world x sum over channels of (ln mean_c - the channels' average)^2.
            let rw = row_weights(w, h);
            let mut m = [0f64; 3];
            for (i, c) in log.chunks(3).enumerate() {
                for k in 0..3 {
                    m[k] += rw[i / w] * (c[k] as f64).exp();
                }
            }
            let lm = m.map(|v| v.max(1e-30).ln());
            let avg = lm.iter().sum::<f64>() / 3.0;
            for (i, c) in log.chunks(3).enumerate() {
                for k in 0..3 {
                    let d = 2.0 * opts.gray_world as f64 * (lm[k] - avg);
                    g[3 * i + k] += (d * rw[i / w] * (c[k] as f64).exp() / m[k]) as f32;
                }
            }
        }
    }

    /// The derivative with respect to the logarithms `log` from dL/d(radiance) `d_radiance`
    /// (radiance times it; 0 where it is not finite), the priors' included.
    pub(super) fn log_gradient(
        &self,
        opts: &EnvFitOptions,
        log: &[f32],
        d_radiance: &[f32],
    ) -> Vec<f32> {
        let mut g: Vec<f32> = d_radiance
            .iter()
            .zip(log)
            .map(|(&d, &l)| if d.is_finite() { d * l.exp() } else { 0.0 })
            .collect();
        self.add_priors(opts, log, &mut g);
        g
    }

    /// After a step: with the `mean` gauge, shift the logarithms `log` so that the mean
    /// luminance is the one held.
    pub(super) fn hold_gauge(&self, opts: &EnvFitOptions, log: &mut [f32]) {
        if opts.gauge == Gauge::Mean {
            let now = luminance(channel_means(&self.env(log)));
            if now > 0.0 && self.mean_luminance > 0.0 {
                let shift = (self.mean_luminance / now).ln() as f32;
                log.iter_mut()
                    .for_each(|l| *l = (*l + shift).clamp(-20.0, 20.0));
            }
        }
    }
}

/// The buffer the gradient passes scatter the environment's derivative into: 3 floats per
/// texel of the scene's environment, then two counters (shared/env_gradient.wgsl).
pub(in crate::optim) fn env_gradient_buffer(
    gpu: &crate::gpu::Gpu,
    scene: &crate::scene::Scene,
) -> wgpu::Buffer {
    let texels = scene.env.as_ref().map_or(0, |e| e.width * e.height) as u64;
    gpu.storage_zeroed("environment gradient", (3 * texels + 2) * 4)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::param_table::{Group, ParamTable, Space, ENVIRONMENT};
    use crate::optim::Settings;

    fn state(w: u32, h: u32, f: impl Fn(usize) -> [f32; 3]) -> (Vec<f32>, EnvFitState) {
        logarithms(&EnvMap {
            width: w,
            height: h,
            rgb: (0..(w * h) as usize).map(f).collect(),
            scale: 1.0,
        })
    }

    /// The priors' gradients against central differences of their energies.
    #[test]
    fn prior_gradients_match_finite_differences() {
        let (log, s) = state(4, 3, |i| {
            [0.2 + 0.1 * i as f32, 0.5, 1.0 + 0.05 * (i % 3) as f32]
        });
        let opts = EnvFitOptions {
            smoothness: 0.7,
            gray_world: 0.3,
            ..Default::default()
        };
        let energy = |log: &[f32]| -> f64 {
            let pairs = neighbour_pairs(4, 3);
            let mut e = 0.0;
            for &(a, b) in &pairs {
                for c in 0..3 {
                    e += (log[3 * a + c] - log[3 * b + c]).powi(2) as f64;
                }
            }
            e *= 0.7 / (3.0 * pairs.len() as f64);
            let m = channel_means(&s.env(log)).map(f64::ln);
            let avg = m.iter().sum::<f64>() / 3.0;
            e + 0.3 * m.iter().map(|v| (v - avg).powi(2)).sum::<f64>()
        };
        let mut g = vec![0f32; log.len()];
        s.add_priors(&opts, &log, &mut g);
        for k in 0..log.len() {
            let h = 1e-3;
            let mut p = log.clone();
            let mut m = log.clone();
            p[k] += h;
            m[k] -= h;
            let fd = (energy(&p) - energy(&m)) / (2.0 * h as f64);
            assert!(
                (fd - g[k] as f64).abs() <= 1e-3 * (1.0 + fd.abs()),
                "entry {k}: prior gradient {} against finite difference {fd}",
                g[k]
            );
        }
    }

    /// One Adam step of the logarithms `log` at rate `lr` from dL/d(radiance) `d`, through
    /// the parameter table as the optimizer takes it, and the gauge after it.
    fn step(s: &EnvFitState, opts: &EnvFitOptions, log: &[f32], d: &[f32], lr: f32) -> Vec<f32> {
        let settings = Settings::new(8, 8, vec![0]);
        let mut table = ParamTable::new(0, &settings);
        let mut group = Group::new(ENVIRONMENT, Space::Values, log.to_vec());
        group.learning_rate = Some(lr);
        table.insert(group);
        table.step(&settings, ENVIRONMENT, &s.log_gradient(opts, log, d), 1.0);
        let mut log = table.group(ENVIRONMENT).state.values.clone();
        s.hold_gauge(opts, &mut log);
        log
    }

    /// The `mean` gauge holds the solid-angle mean luminance through a step.
    #[test]
    fn the_mean_gauge_holds_the_mean_luminance() {
        let (log, s) = state(8, 4, |i| [0.5, 0.5 + 0.01 * i as f32, 0.5]);
        let before = luminance(channel_means(&s.env(&log)));
        let opts = EnvFitOptions {
            gauge: Gauge::Mean,
            ..Default::default()
        };
        let g = vec![-1.0f32; log.len()];
        let after = luminance(channel_means(&s.env(&step(&s, &opts, &log, &g, 0.3))));
        assert!((after / before - 1.0).abs() < 1e-4, "{before} -> {after}");
        // Without the gauge the same step brightens everything.
        let free = step(&s, &EnvFitOptions::default(), &log, &g, 0.3);
        assert!(luminance(channel_means(&s.env(&free))) > 1.2 * before);
    }

    #[test]
    fn bad_options_are_refused_by_name() {
        for (o, key) in [
            (
                EnvFitOptions {
                    learning_rate: 0.0,
                    ..Default::default()
                },
                "learning_rate",
            ),
            (
                EnvFitOptions {
                    rebuild_every: 0,
                    ..Default::default()
                },
                "rebuild_every",
            ),
            (
                EnvFitOptions {
                    gray_world: f32::NAN,
                    ..Default::default()
                },
                "gray_world",
            ),
        ] {
            assert_eq!(o.check().unwrap_err().0, key);
        }
    }
}
