//! The `[environment]` table of a task file: the environment recovered with the textures
//! (or assumed), where it starts and how it is stepped.
//!
//! ```toml
//! [environment]                   # present: the environment is optimized
//! resolution = [32, 16]           # lat-long texels (with a constant `init`)
//! init = 0.5                      # a gray level, [r, g, b], or an .exr/.hdr file
//! learning_rate = 0.05            # Adam on the texels' logarithms
//! rebuild_every = 4               # iterations between rebuilds of its sampling tables
//! smoothness = 0.0                # prior on neighbouring texels' logarithms (0: off)
//! gray_world = 0.0                # prior pulling the channels' means together (0: off)
//! gauge = "none"                  # or "mean": its mean luminance held at the start's
//! filter = "nearest"              # or "bilinear" lookups of the recovered map
//! warmup_iterations = 0           # iterations in which only the environment steps
//! # optimize = false              # the environment fixed at `init` instead (an assumption)
//! ```
use crate::optim::environment_fit::EnvFitOptions;
use crate::scene::EnvMap;
use crate::{Error, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Where the recovered environment starts.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum EnvInit {
    /// A uniform gray radiance.
    Gray(f32),
    /// A uniform RGB radiance.
    Rgb([f32; 3]),
    /// An environment map file (relative to the task), at its own size.
    File(PathBuf),
}

/// The `[environment]` table: where the environment starts and whether it is recovered
/// (its own keys), and how it is stepped (every other key, read by [`EnvFitOptions`] itself,
/// which refuses a key it does not know).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(try_from = "toml::Table")]
pub struct EnvironmentSpec {
    /// Texels (width, height) of a constant start; a file keeps its own size.
    pub resolution: Option<[u32; 2]>,
    /// The start (default: gray 0.5).
    pub init: EnvInit,
    /// The lookup: "nearest" (the default) or "bilinear" (four texels, wrapping in azimuth).
    pub filter: Option<crate::vocab::Filter>,
    /// Whether it is recovered (true) or held at `init` (a fit that assumes a light).
    pub optimize: bool,
    /// How it is stepped: the learning rate, its priors, its gauge and its warm-up.
    pub fit: EnvFitOptions,
}

/// The keys of `[environment]` that are the spec's own, not the fit's.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Start {
    resolution: Option<[u32; 2]>,
    #[serde(default = "default_init")]
    init: EnvInit,
    #[serde(default)]
    filter: Option<crate::vocab::Filter>,
    #[serde(default = "yes")]
    optimize: bool,
}

impl TryFrom<toml::Table> for EnvironmentSpec {
    type Error = String;

    fn try_from(mut table: toml::Table) -> std::result::Result<EnvironmentSpec, String> {
        const OWN: [&str; 4] = ["resolution", "init", "filter", "optimize"];
        let own: toml::Table = OWN
            .iter()
            .filter_map(|k| table.remove(*k).map(|v| (k.to_string(), v)))
            .collect();
        let start = Start::deserialize(toml::Value::Table(own)).map_err(|e| e.to_string())?;
        let fit = EnvFitOptions::deserialize(toml::Value::Table(table)).map_err(|e| {
            let e = e.to_string();
            match e.contains("unknown field") {
                true => format!("{} (or one of {})", e.trim_end(), OWN.join(", ")),
                false => e,
            }
        })?;
        Ok(EnvironmentSpec {
            resolution: start.resolution,
            init: start.init,
            filter: start.filter,
            optimize: start.optimize,
            fit,
        })
    }
}

fn yes() -> bool {
    true
}

fn default_init() -> EnvInit {
    EnvInit::Gray(0.5)
}

/// The largest side of a recovered environment.
pub const MAX_ENV_SIDE: u32 = 1024;

impl EnvironmentSpec {
    /// Range checks: the key (under `environment.`) and what is wrong.
    pub fn check(&self) -> std::result::Result<(), (String, String)> {
        self.fit.check()?;
        let bad = |k: &str, m: String| Err((k.to_string(), m));
        match (&self.init, self.resolution) {
            (EnvInit::File(_), Some(_)) => {
                return bad(
                    "resolution",
                    "a file start keeps its own size: give `resolution` with a constant `init`"
                        .into(),
                )
            }
            (EnvInit::Gray(v), _) if !(v.is_finite() && *v > 0.0) => {
                return bad("init", format!("must be a positive radiance, not {v}"))
            }
            (EnvInit::Rgb(v), _) if !v.iter().all(|x| x.is_finite() && *x > 0.0) => {
                return bad(
                    "init",
                    format!("must be three positive radiances, not {v:?}"),
                )
            }
            _ => {}
        }
        if let Some([w, h]) = self.resolution {
            if !(1..=MAX_ENV_SIDE).contains(&w) || !(1..=MAX_ENV_SIDE).contains(&h) {
                return bad(
                    "resolution",
                    format!("each side must be between 1 and {MAX_ENV_SIDE} texels, not {w}x{h}"),
                );
            }
        }
        Ok(())
    }

    /// The starting environment (files resolved against `base`).
    pub fn start(&self, base: &Path) -> Result<EnvMap> {
        let [w, h] = self.resolution.unwrap_or([32, 16]);
        let uniform = |rgb: [f32; 3]| EnvMap {
            width: w,
            height: h,
            rgb: vec![rgb; (w * h) as usize],
            scale: 1.0,
        };
        match &self.init {
            EnvInit::Gray(v) => Ok(uniform([*v; 3])),
            EnvInit::Rgb(v) => Ok(uniform(*v)),
            EnvInit::File(p) => {
                let path = if p.is_absolute() {
                    p.clone()
                } else {
                    base.join(p)
                };
                let env = EnvMap::load(&path)?;
                if env.width > MAX_ENV_SIDE || env.height > MAX_ENV_SIDE {
                    return Err(Error::file(
                        &path,
                        format!(
                            "a {}x{} environment is larger than the {MAX_ENV_SIDE} texels a side \
                             that a recovered one may have",
                            env.width, env.height
                        ),
                    ));
                }
                // Logarithms need positive texels.
                let mut env = env;
                env.rgb.iter_mut().flatten().for_each(|v| *v = v.max(1e-4));
                Ok(env)
            }
        }
    }
}
