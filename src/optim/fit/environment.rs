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

#[cfg(test)]
mod tests {
    use super::super::environment_fit::*;
    use super::*;
    use crate::optim::param_table::ParamTable;
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
