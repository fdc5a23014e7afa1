//! What an iteration reports, and the optimizer's state as checkpoints save it.

use crate::optim::param_table::GroupState;
use crate::optim::{ControlVariateSnapshot, EstimatorState, Optimizer, PathCacheSnapshot};
use crate::{Error, Result};
use std::collections::BTreeMap;

/// What one iteration reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepStats {
    /// Loss of this iteration's primal render (before the update).
    pub loss: f64,
}

/// The textures and adjoint images of the last iteration, which the next one evaluates kept
/// samples under (ReSTIR's merge).
#[derive(Clone, Debug, PartialEq)]
pub struct PreviousState {
    /// The textures at which the last iteration drew its samples.
    pub params: Vec<f32>,
    /// The last iteration's adjoint images (RGBA per pixel, cameras one after another).
    pub adjoint: Vec<f32>,
}

/// The state of an optimizer between iterations, on the CPU (see [`Optimizer::state`]).
#[derive(Clone, Debug, PartialEq)]
pub struct OptimizerState {
    /// Iterations done.
    pub iteration: u32,
    /// Texture values, laid out like [`ParamSet::values`](crate::render::params::ParamSet::values).
    pub params: Vec<f32>,
    /// The step's first moments (Adam's; the variance step's running mean of the gradient).
    pub m1: Vec<f32>,
    /// The step's second moments.
    pub m2: Vec<f32>,
    /// The last iteration's textures and adjoint, when the estimator or the primal uses
    /// them.
    pub previous: Option<PreviousState>,
    /// The gradient estimator's state (what it keeps across iterations, if anything).
    pub estimator: EstimatorState,
    /// The control-variate primal's state; `None` for the independent primal.
    pub control_variate: Option<ControlVariateSnapshot>,
    /// The path cache's stored paths; `None` without a cache or before its first render.
    pub path_cache: Option<PathCacheSnapshot>,
    /// The parameter table's CPU groups (exposures, white balances, the environment's
    /// logarithms when it is optimized), by name, with their step's state.
    pub groups: BTreeMap<String, GroupState>,
    /// What the environment's fit keeps besides its group, when it is optimized.
    pub environment: Option<crate::optim::environment_fit::EnvFitState>,
}

/// What a run hands back of one of its states: the textures and every CPU group's values
/// (exposures, white balances, the environment's logarithms), without the step's or the
/// estimator's state ([`Optimizer::values`], [`Optimizer::set_values`]). A run keeps the one
/// with its lowest evaluation error (`optimizer.keep_best`).
#[derive(Clone, Debug, PartialEq)]
pub struct Values {
    /// Iterations done at that state.
    pub iteration: u32,
    /// Texture values, laid out like [`ParamSet::values`](crate::render::params::ParamSet::values).
    pub params: Vec<f32>,
    /// The parameter table's CPU groups' values, by name.
    pub groups: BTreeMap<String, Vec<f32>>,
}

impl Optimizer {
    /// The gradient of the last iteration or estimate, laid out like the parameters.
    pub fn read_gradient(&self) -> Result<Vec<f32>> {
        let mut g: Vec<f32> = self.gpu.read_pod(&self.bufs.grad)?;
        g.truncate(self.set.values.len());
        Ok(g)
    }

    /// Current texture values.
    pub fn read_params(&self) -> Result<Vec<f32>> {
        let mut v: Vec<f32> = self.gpu.read_pod(&self.params.values)?;
        v.truncate(self.set.values.len());
        Ok(v)
    }

    /// Replace the texture values (e.g. from a checkpoint).
    pub fn write_params(&self, values: &[f32]) -> Result<()> {
        if values.len() != self.set.values.len() {
            return Err(Error::Invalid(format!(
                "{} values for {} parameters",
                values.len(),
                self.set.values.len()
            )));
        }
        self.gpu
            .queue
            .write_buffer(&self.params.values, 0, bytemuck::cast_slice(values));
        self.gpu.check("write params")
    }

    /// The textures and the CPU groups' values now (see [`Values`]).
    pub fn values(&self) -> Result<Values> {
        Ok(Values {
            iteration: self.iteration,
            params: self.read_params()?,
            groups: self.fit.table.values(),
        })
    }

    /// Take `values` as the textures and the CPU groups' values (the gains and the
    /// environment uploaded anew); the iteration count, the step's and the estimator's state
    /// stay. Refused before anything changes where a size or a group does not fit.
    pub fn set_values(&mut self, values: &Values) -> Result<()> {
        if values.params.len() != self.set.values.len() {
            return Err(Error::Invalid(format!(
                "{} texture values for {} parameters",
                values.params.len(),
                self.set.values.len()
            )));
        }
        self.fit.table.set_values(&values.groups)?;
        self.write_params(&values.params)?;
        self.fit_mut().upload()?;
        self.gpu.check("set optimizer values")
    }

    /// The step's first and second moments (both steps keep two).
    pub fn read_moments(&self) -> Result<[Vec<f32>; 2]> {
        let n = self.set.values.len();
        let mut a: Vec<f32> = self.gpu.read_pod(&self.bufs.moments[0])?;
        let mut b: Vec<f32> = self.gpu.read_pod(&self.bufs.moments[1])?;
        a.truncate(n);
        b.truncate(n);
        Ok([a, b])
    }

    /// Restore the step's moments.
    pub fn write_moments(&self, m: &[Vec<f32>; 2]) -> Result<()> {
        for (buf, v) in self.bufs.moments.iter().zip(m) {
            if v.len() != self.set.values.len() {
                return Err(Error::Invalid(
                    "the step's moments do not match the parameters".into(),
                ));
            }
            self.gpu.queue.write_buffer(buf, 0, bytemuck::cast_slice(v));
        }
        self.gpu.check("write moments")
    }

    /// Current values of texture `i` (index into `set.textures`), copied to the CPU.
    pub fn texture_values(&self, i: usize) -> Result<Vec<f32>> {
        let t = self.set.textures.get(i).ok_or_else(|| {
            Error::Invalid(format!(
                "texture {i} does not exist ({} optimized)",
                self.set.textures.len()
            ))
        })?;
        let all = self.read_params()?;
        Ok(all[t.offset as usize..t.offset as usize + t.len()].to_vec())
    }

    /// Everything a later run needs to continue exactly where this one stands: iteration,
    /// textures, the step's moments and, for ReSTIR, the kept reservoirs with the textures and
    /// adjoint they were drawn at. Restore it with [`Optimizer::restore`].
    pub fn state(&self) -> Result<OptimizerState> {
        let [m1, m2] = self.read_moments()?;
        let previous = if self.uses_previous_state() {
            let last = (self.iteration as usize + 1) % 2;
            let mut params: Vec<f32> = self.gpu.read_pod(&self.params.previous)?;
            params.truncate(self.set.values.len());
            Some(PreviousState {
                params,
                adjoint: self.gpu.read_pod(&self.bufs.adjoint[last])?,
            })
        } else {
            None
        };
        Ok(OptimizerState {
            iteration: self.iteration,
            params: self.read_params()?,
            m1,
            m2,
            previous,
            estimator: self.plugins.estimator.snapshot(&self.gpu, self.iteration)?,
            control_variate: match &self.passes.control_variate {
                Some(cv) => Some(cv.snapshot(&self.gpu)?),
                None => None,
            },
            path_cache: match &self.passes.path_cache {
                Some(cache) => cache.snapshot(&self.gpu)?,
                None => None,
            },
            groups: self.fit.table.states(),
            environment: self.fit.environment_state().cloned(),
        })
    }

    /// Continue from a state taken with [`Optimizer::state`] of an optimizer made with the same
    /// scene, textures and estimator; one written by another estimator is refused before
    /// anything is restored. An estimator state without arrays restores a ReSTIR optimizer
    /// with empty reservoirs (its next iteration starts afresh, as the first does).
    pub fn restore(&mut self, state: &OptimizerState) -> Result<()> {
        state.estimator.check_method(self.settings.method)?;
        self.write_params(&state.params)?;
        self.write_moments(&[state.m1.clone(), state.m2.clone()])?;
        let last = (state.iteration as usize + 1) % 2;
        let mut snapshot = Some(&state.estimator);
        let mut cv_snapshot = state.control_variate.as_ref();
        match &state.previous {
            Some(p) => {
                if p.adjoint.len() as u64 * 4 != self.bufs.adjoint[last].size()
                    || p.params.len() != self.set.values.len()
                {
                    return Err(Error::Invalid(
                        "the saved state does not match this optimizer's textures and images"
                            .into(),
                    ));
                }
                let q = &self.gpu.queue;
                q.write_buffer(
                    &self.bufs.adjoint[last],
                    0,
                    bytemuck::cast_slice(&p.adjoint),
                );
                let prev = &self.params.previous;
                q.write_buffer(prev, 0, bytemuck::cast_slice(&p.params));
            }
            // Kept samples and the last image cannot be reused without the state they were
            // drawn at.
            None => {
                snapshot = None;
                cv_snapshot = None;
            }
        }
        self.plugins
            .estimator
            .restore(&self.gpu, snapshot, state.iteration)?;
        if let Some(cv) = &mut self.passes.control_variate {
            cv.restore(&self.gpu, cv_snapshot)?;
        }
        if let Some(cache) = &mut self.passes.path_cache {
            // (Stored paths are samples under any textures: they need no previous state.)
            cache.restore(&self.gpu, state.path_cache.as_ref())?;
        }
        if let Some(env) = &state.environment {
            self.fit_mut().restore_environment(env)?;
        }
        self.fit.table.restore(&state.groups)?;
        self.fit_mut().upload()?;
        self.iteration = state.iteration;
        self.gpu.check("restore optimizer state")
    }

    /// Bytes of GPU memory the optimizer keeps per optimized texel: the textures (current and
    /// previous), gradient and the step's moments, plus ReSTIR's reservoirs, headers, compaction
    /// map and moving moments. Buffers that scale with the image (targets, adjoints, ReSTIR's
    /// claim log) are not counted.
    pub fn state_bytes_per_texel(&self) -> f64 {
        let bytes = self.params.values.size()
            + self.params.previous.size()
            + self.bufs.grad.size()
            + self.bufs.moments.iter().map(|b| b.size()).sum::<u64>()
            + self.plugins.estimator.state_bytes();
        bytes as f64 / self.renderer.scene.n_texels.max(1) as f64
    }

    /// The textures of the last iteration (those its primal and gradient were drawn at;
    /// [`Optimizer::read_params`] has them after the step).
    pub fn read_params_prev(&self) -> Result<Vec<f32>> {
        let mut v: Vec<f32> = self.gpu.read_pod(&self.params.previous)?;
        v.truncate(self.set.values.len());
        Ok(v)
    }
}
