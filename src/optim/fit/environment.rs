//! The environment in the fit: its logarithms read, set and optimized with the textures, the
//! way [`gains`](super::gains) holds the cameras' response. Its options and its state in
//! progress are [`environment_fit`](super::environment_fit)'s.
use super::environment_fit::{
    channel_means, logarithms, luminance, EnvFit, EnvFitOptions, EnvFitState,
};
use super::{Fit, FitMut};
use crate::optim::param_table::{Group, Space, ENVIRONMENT, EXPOSURE, WHITE_BALANCE};
use crate::scene::EnvMap;
use crate::{Error, Result};

impl Fit {
    /// The recovered environment's logarithms (the table's `environment` group).
    pub(in crate::optim) fn environment_log(&self) -> &[f32] {
        &self.table.group(ENVIRONMENT).state.values
    }

    /// Whether the textures hold this iteration: the environment's warm-up
    /// ([`EnvFitOptions::warmup_iterations`]) is not over.
    pub(in crate::optim) fn environment_warming_up(&self) -> bool {
        self.env_fit
            .as_ref()
            .is_some_and(|f| self.table.group(ENVIRONMENT).state.steps < f.opts.warmup_iterations)
    }

    /// The environment as recovered so far (None unless it is optimized).
    pub fn environment(&self) -> Option<EnvMap> {
        (self.env_fit.as_ref()).map(|f| f.state.env(self.environment_log()))
    }

    /// What the environment's fit keeps besides its group in the table, for checkpoints.
    pub fn environment_state(&self) -> Option<&EnvFitState> {
        self.env_fit.as_ref().map(|f| &f.state)
    }

    pub(in crate::optim) fn clear_environment_gradient(&self, enc: &mut wgpu::CommandEncoder) {
        if self.env_fit.is_some() {
            enc.clear_buffer(&self.env_grad, 0, None);
        }
    }
}

impl FitMut<'_> {
    /// Recover the environment with the textures, starting from `start` (the size of the
    /// scene's environment as uploaded; the task's `[environment]` table builds both).
    pub fn optimize_environment(&mut self, start: &EnvMap, opts: EnvFitOptions) -> Result<()> {
        opts.check()
            .map_err(|(k, m)| Error::Invalid(format!("environment.{k}: {m}")))?;
        let info = self.scene.info;
        if info.env_width == 0 || (start.width, start.height) != (info.env_width, info.env_height) {
            return Err(Error::Invalid(format!(
                "optimize_environment: the scene was uploaded with a {}x{} environment, the \
                 start is {}x{} (give the scene its starting environment)",
                info.env_width, info.env_height, start.width, start.height
            )));
        }
        let (log, state) = logarithms(start);
        let mut group = Group::new(ENVIRONMENT, Space::Values, log);
        group.learning_rate = Some(opts.learning_rate);
        self.fit.table.insert(group);
        // The reference camera keeps its response while the light is recovered.
        self.fit.table.group_mut(EXPOSURE).held = 1;
        self.fit.table.group_mut(WHITE_BALANCE).held = 3;
        self.fit.env_fit = Some(EnvFit { opts, state });
        self.upload_environment(true)?;
        self.gpu.check("optimize environment")
    }

    /// Upload the recovered environment, and its sampling tables with `tables`.
    pub(in crate::optim) fn upload_environment(&mut self, tables: bool) -> Result<()> {
        let fit = self
            .fit
            .env_fit
            .as_ref()
            .expect("the environment is recovered");
        let env = fit.state.env(self.fit.environment_log());
        self.scene.update_environment(self.gpu, &env, tables, true)
    }

    /// Replace the recovered environment's radiance (`width * height` RGB texels, each
    /// finite and positive, row 0 at the zenith), keeping its step's state; the `mean` gauge
    /// then holds this environment's mean luminance. The sampling tables are rebuilt.
    pub fn set_environment(&mut self, rgb: &[[f32; 3]]) -> Result<()> {
        let Some(fit) = &mut self.fit.env_fit else {
            return Err(Error::Invalid(
                "the environment is not a parameter (the task's [environment] does not \
                 optimize it)"
                    .into(),
            ));
        };
        let [w, h] = fit.state.size;
        if rgb.len() != (w * h) as usize {
            return Err(Error::Invalid(format!(
                "the environment is {h}x{w}x3, {} texels given",
                rgb.len()
            )));
        }
        if let Some(i) = rgb
            .iter()
            .flatten()
            .position(|v| !(v.is_finite() && *v > 0.0))
        {
            return Err(Error::Invalid(format!(
                "the environment's radiance must be finite and positive (value {} at index {i})",
                rgb[i / 3][i % 3]
            )));
        }
        let log: Vec<f32> = (rgb.iter().flatten())
            .map(|v| v.ln().clamp(-20.0, 20.0))
            .collect();
        fit.state.mean_luminance = luminance(channel_means(&fit.state.env(&log)));
        self.fit.table.group_mut(ENVIRONMENT).state.values = log;
        self.upload_environment(true)?;
        self.gpu.check("set environment")
    }

    /// Go on from a checkpoint's environment state (of the same size; its logarithms are
    /// the table's `environment` group, restored with the table).
    pub(in crate::optim) fn restore_environment(&mut self, state: &EnvFitState) -> Result<()> {
        let Some(fit) = &mut self.fit.env_fit else {
            return Err(Error::Invalid(
                "the checkpoint has an environment state, the task does not optimize the \
                 environment"
                    .into(),
            ));
        };
        if state.size != fit.state.size {
            return Err(Error::Invalid(format!(
                "the checkpoint's environment is {}x{}, the task's {}x{}",
                state.size[0], state.size[1], fit.state.size[0], fit.state.size[1]
            )));
        }
        fit.state = state.clone();
        Ok(())
    }

    /// This iteration's dL/d(radiance) of the environment's texels (3 per texel), as the
    /// gradient pass left it, and the updates it lost or dropped.
    pub fn read_environment_gradient(&self) -> Result<(Vec<f32>, u32)> {
        let raw: Vec<u32> = self.gpu.read_pod(&self.fit.env_grad)?;
        let info = self.scene.info;
        let n = 3 * (info.env_width * info.env_height) as usize;
        let g = raw[..n].iter().map(|&b| f32::from_bits(b)).collect();
        Ok((g, raw[n] + raw[n + 1]))
    }

    /// One step of the environment from this iteration's gradient (schedule factor
    /// `factor`), and its upload; the sampling tables when they are due.
    pub(in crate::optim) fn step_environment(&mut self, factor: f32) -> Result<()> {
        if self.fit.env_fit.is_none() {
            return Ok(());
        }
        let (d_radiance, faults) = self.read_environment_gradient()?;
        self.fit.env_faults += faults;
        let fit = self.fit.env_fit.as_ref().expect("checked above");
        let log = &self.fit.table.group(ENVIRONMENT).state.values;
        let g = fit.state.log_gradient(&fit.opts, log, &d_radiance);
        self.fit.table.step(self.settings, ENVIRONMENT, &g, factor);
        let group = self.fit.table.group_mut(ENVIRONMENT);
        fit.state.hold_gauge(&fit.opts, &mut group.state.values);
        let tables = group.state.steps % fit.opts.rebuild_every == 0;
        self.upload_environment(tables)
    }
}
