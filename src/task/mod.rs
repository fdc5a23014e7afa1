//! Task files: what an optimization solves (TOML).
//!
//! ```toml
//! scene = "scene.gltf"            # the scene with known geometry and lights
//! cameras = ["main"]              # all of them are rendered every iteration (default: all)
//! width = 128                     # image size of every camera
//! height = 128
//! seed = 1
//! output = "out/default"          # relative to the working directory
//! # relight = ["dusk.exr"]        # held-out environments the result is judged under
//!
//! [target]                        # either a ground-truth scene rendered at `spp` ...
//! scene = "scene.gltf"
//! spp = 256
//! # images = { main = "main.exr" } # ... or one image per camera (EXR or PNG)
//!
//! [optimizer]
//! iterations = 300                # and/or time_budget_s
//! # Every key of [optimizer] that is absent is chosen by `auto` (the `auto` module): the estimator,
//! # the step, its moment filter, the learning rates, their schedule and the smoothness prior.
//! method = "baseline"             # gradient estimator: or "restir", "recursive", "auto"
//! step = "adam"                   # or "variance" (auto's): the variance-scaled step
//! primal_spp = 2
//! primal = "control_variate"      # or "independent" (the default)
//! cv_max_weight = 0.9             # upper clamp of the control variate's weight (0..1)
//! gradient_spp = 2
//! loss = "l2"                     # or "relmse"
//! filter = "bilinear"             # or "nearest"
//! checkpoint_every = 25
//! sparse_steps = true             # either step: zero-gradient entries keep value and moments
//! multiscale_levels = 4           # short for [optimizer.multiscale] levels = 4
//! smoothness = 0.1                # short for [optimizer.smoothness] weight = 0.1
//! eval_every = 10                 # low-noise image error every N iterations (0: never)
//! eval_spp = 16
//!
//! [optimizer.adam]                # Adam's decays and epsilon (these are the defaults)
//! beta1 = 0.9
//! beta2 = 0.999
//! eps = 1e-8
//!
//! [optimizer.recursive]           # an estimator's options (these are the recursive one's defaults)
//! # weight = 0.1                  # fixed weight of the fresh term; absent: by inverse variance
//! min_weight = 0.05               # lower bound of the adaptive weight
//! beta = 0.9                      # decay of its moving variances
//!
//! [optimizer.restir]              # ReSTIR's options (these are the defaults)
//! m_cap = 8.0                     # confidence cap of the kept samples
//! confidence = "samples"          # of the fresh candidates: or "candidates"
//! temporal = true                 # reuse across iterations
//! positivization = true           # two reservoirs per texel
//! # target_smoothing = 0.9        # absent: 0.9 with the independent primal, 0 with the control variate
//! m_cap_follows_schedule = false  # the cap times the learning-rate schedule's factor
//! verify_paths = false            # self-check of the stored paths (diagnostic)
//!
//! [optimizer.variance_step]       # the variance-scaled step (these are the defaults)
//! clip = 1.0                      # the largest step, in learning rates
//! threshold = 1.0                 # standard deviations taken off each estimate
//! beta = 0.9                      # decay of the moving variance (estimators without their own)
//! eps = 1e-12
//!
//! [optimizer.moment_filter]       # filtered moments (absent: auto's, 5 levels with the variance step)
//! levels = 5                      # a-trous levels: taps 1, 2, 4, 8, 16 texels apart (at most 8)
//! taps = 3                        # taps per side of a level: 3 or 5
//! sigma = 0.1                     # edge-stopping scale of the texture's differences
//! log_space = false               # differences of logarithms instead
//! own_weight = 0.25               # weight of a texel's own moments against the filtered ones
//! write_back = false              # the mix replaces Adam's moments (Adam only)
//!
//! # [optimizer.multiscale]        # a prior's options, in place of its shorthand above
//! # levels = 4                    # gradient averaged over 2^l-texel blocks, l <= 4 (0: off)
//! # [optimizer.smoothness]        # the smoothness prior on observed texels
//! # weight = 0.1                  # 0: off; absent: auto's
//!
//! [optimizer.schedule]            # learning-rate schedule (absent: auto's, cosine to 0.05)
//! kind = "cosine"                 # or "constant", "step", "exponential"
//! final = 0.05
//!
//! [[textures]]
//! material = "sphere"
//! slot = "base_color"             # or "roughness", "metallic"
//! resolution = [64, 32]
//! init = [0.5, 0.5, 0.5]          # one value for roughness and metallic
//! learning_rate = 0.02            # absent: auto's for the step (variance 0.01, Adam 0.02)
//!
//! # [environment]                 # the environment recovered too: see [`EnvironmentSpec`]
//! ```
pub use crate::vocab::{check_texture, Filter, Init, Loss, Slot, TextureSpec, ROUGHNESS_FLOOR};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

impl Task {
    /// Whether one of the task's textures replaces `slot` (a normal map changes which
    /// estimators can run it and how its passes are composed).
    pub fn optimizes(&self, slot: crate::vocab::Slot) -> bool {
        self.textures.iter().any(|t| t.slot == slot)
    }

    /// Read and check a task file.
    pub fn load(path: &Path) -> Result<Task> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        Task::parse(&text, path)
    }

    /// Parse and check task text; `path` names it in errors and anchors relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Task> {
        let mut task: Task = toml::from_str(text)
            .map_err(|e| Error::file(path, e.to_string().trim_end().to_string()))?;
        task.path = path.to_path_buf();
        task.base = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        task.check()?;
        Ok(task)
    }

    fn bad(&self, key: &str, msg: impl std::fmt::Display) -> Error {
        Error::file(&self.path, format!("`{key}`: {msg}"))
    }

    fn check(&self) -> Result<()> {
        // The optimizer's settings as this task gives them (options the command line adds
        // are checked where it reads them).
        self.optimizer
            .estimator_options()
            .map_err(|(key, msg)| self.bad(&key, msg))?;
        self.optimizer
            .step_options()
            .map_err(|(key, msg)| self.bad(&key, msg))?;
        self.optimizer
            .prior_options()
            .map_err(|(key, msg)| self.bad(&key, msg))?;
        let method = task_method(self, self.optimizer.method, named_cameras(self)).method;
        let mut settings = task_settings(self, &[], method, &Default::default());
        settings.exposure_learning_rate = Some(self.optimizer.exposure_learning_rate);
        settings
            .validate()
            .map_err(|(key, msg)| self.bad(&key, msg))?;
        if !(self.env_scale.is_finite() && self.env_scale >= 0.0) {
            return Err(self.bad("env_scale", "must be a finite number >= 0"));
        }
        crate::scene::MaxDepth::new(self.max_depth).map_err(|m| self.bad("max_depth", m))?;
        let t = &self.target;
        match (&t.scene, &t.images) {
            (None, None) if self.cameras_file.is_none() => {
                return Err(self.bad(
                    "target",
                    "give `scene` or `images` (or a `cameras_file` whose frames have images)",
                ))
            }
            (Some(_), Some(_)) => {
                return Err(self.bad("target", "give `scene` or `images`, not both"))
            }
            _ => {}
        }
        if t.spp == 0 || t.spp > 1 << 16 {
            return Err(self.bad("target.spp", "must be between 1 and 65536"));
        }
        let o = &self.optimizer;
        if o.iterations.is_none() && o.time_budget_s.is_none() {
            return Err(self.bad("optimizer", "give `iterations`, `time_budget_s` or both"));
        }
        if let Some(b) = o.time_budget_s {
            if !(b.is_finite() && b > 0.0) {
                return Err(self.bad(
                    "optimizer.time_budget_s",
                    "must be a positive number of seconds",
                ));
            }
        }
        if !(o.checkpoint_every_s.is_finite() && o.checkpoint_every_s >= 0.0) {
            return Err(self.bad(
                "optimizer.checkpoint_every_s",
                "must be a number of seconds >= 0",
            ));
        }
        if let Some(e) = &self.target.exposure {
            if let Some((k, v)) = e.iter().find(|(_, v)| !(v.is_finite() && **v > 0.0)) {
                return Err(self.bad(
                    &format!("target.exposure.{k}"),
                    format!("must be a positive number, not {v}"),
                ));
            }
        }
        for (i, c) in self.camera_defs.iter().enumerate() {
            c.check()
                .map_err(|(key, msg)| self.bad(&format!("camera[{i}].{key}"), msg))?;
        }
        for (i, l) in self.lights.iter().enumerate() {
            l.check()
                .map_err(|(key, msg)| self.bad(&format!("light[{i}].{key}"), msg))?;
        }
        if o.eval_spp == 0 || o.eval_spp > 4096 {
            return Err(self.bad("optimizer.eval_spp", "must be between 1 and 4096"));
        }
        if self.textures.is_empty() {
            return Err(self.bad("textures", "name at least one texture to optimize"));
        }
        for (i, tex) in self.textures.iter().enumerate() {
            check_texture(tex, &self.textures[..i])
                .map_err(|(key, msg)| self.bad(&format!("textures[{i}].{key}"), msg))?;
        }
        let wb = o.white_balance_learning_rate;
        if !(wb.is_finite() && wb > 0.0 && wb <= 10.0) {
            return Err(self.bad(
                "optimizer.white_balance_learning_rate",
                "must be a number in (0, 10]",
            ));
        }
        if let Some(e) = &self.environment {
            e.check()
                .map_err(|(key, msg)| self.bad(&format!("environment.{key}"), msg))?;
        }
        if !self.relight.is_empty() && self.target.scene.is_none() {
            return Err(self.bad(
                "relight",
                "relighting compares with the ground truth: it needs `target.scene`",
            ));
        }
        Ok(())
    }

    /// A path from the task, resolved against the task file's folder.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base.join(p)
        }
    }

    /// The output folder: `output`, or `out/<task file stem>`.
    pub fn output_dir(&self) -> PathBuf {
        self.output.clone().unwrap_or_else(|| {
            PathBuf::from("out").join(
                self.path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "task".into()),
            )
        })
    }
}

mod environment;
mod optimizer;
mod resolve;
mod schema;
mod set;
pub use environment::{EnvInit, EnvironmentSpec};
pub use optimizer::OptimizerSpec;
pub use resolve::{named_cameras, task_configuration, task_method, task_regime, task_settings};
pub use schema::{CameraDef, LightDef, LightKind, TargetSpec, Task};

#[cfg(test)]
mod tests;
