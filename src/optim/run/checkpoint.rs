//! Checkpoints: everything needed to continue a run exactly where it stopped (iteration,
//! elapsed time, textures, the step's moments, the ReSTIR reservoirs with the textures they were
//! drawn at, the metrics so far; the random numbers are a pure function of seed and
//! iteration, so the iteration is the RNG state). Written atomically: a temporary file, then a
//! rename.
use crate::optim::environment_fit::EnvFitState;
use crate::optim::param_table::{GroupState, ENVIRONMENT, EXPOSURE, WHITE_BALANCE};
use crate::optim::{
    ControlVariateSnapshot, EstimatorState, OptimizerState, PathCacheSnapshot, PreviousState,
    Values,
};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

const MAGIC: &[u8; 8] = b"PSRCKPT5";

/// One row of metrics.csv.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MetricRow {
    /// Iterations done.
    pub iteration: u32,
    /// Optimization time so far (seconds, target rendering excluded).
    pub elapsed_s: f64,
    /// Loss of the iteration's primal render (None for the start, iteration 0).
    pub loss: Option<f64>,
    /// RMSE of the textures against the ground truth (linear values), when known.
    pub texture_rmse: Option<f64>,
    /// The same over the observed texels only.
    #[serde(default)]
    pub texture_rmse_observed: Option<f64>,
    /// Image relMSE of an evaluation render against the target (mean over cameras), on the
    /// iterations that have one.
    #[serde(default)]
    pub image_relmse: Option<f64>,
    /// Learning rate of the first texture in this iteration's step.
    #[serde(default)]
    pub learning_rate: Option<f64>,
    /// The relMSE of the evaluation render's expectation, without its noise
    /// (`crate::job::run::Evaluation::expected`), on the iterations that have an evaluation.
    #[serde(default)]
    pub image_relmse_expected: Option<f64>,
}

/// Small fields, stored as a JSON header.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Optimization time so far.
    pub elapsed_s: f64,
    /// What the textures are (names and sizes); a resume must match it.
    pub layout: String,
    /// Metrics so far.
    pub metrics: Vec<MetricRow>,
}

/// Sizes and flags of the binary part, stored in the file's header.
#[derive(Serialize, Deserialize)]
struct Stored {
    #[serde(flatten)]
    header: Header,
    iteration: u32,
    n_params: usize,
    /// Floats of the previous adjoint images, when the previous state is saved (then the
    /// previous textures, n_params floats, come first).
    previous_adjoint_floats: Option<usize>,
    /// The gradient estimator's state: its method, counters, and its arrays' names and
    /// lengths in words (their data follows the previous state's, in this order).
    estimator: StoredEstimator,
    /// Floats of the control variate's state; absent for the independent primal.
    #[serde(default)]
    control_variate_floats: Option<usize>,
    /// Iterations the control variate has run.
    #[serde(default)]
    control_variate_iterations: u32,
    /// Words of each camera's stored paths, when the path cache has any (their data follows
    /// the control variate's), and the slot its next refresh starts at.
    #[serde(default)]
    path_cache_words: Option<Vec<usize>>,
    #[serde(default)]
    path_cache_next_slot: u32,
    /// The parameter table's CPU groups with their step's state.
    #[serde(default)]
    groups: BTreeMap<String, GroupState>,
    /// What the environment's fit keeps besides its group, when it is optimized.
    #[serde(default)]
    environment_fit: Option<EnvFitState>,
    /// Checkpoints written before the parameter table kept the gains' state and the
    /// environment's under these keys; read into the table's groups.
    #[serde(default, skip_serializing)]
    exposure: Option<LegacyGains>,
    #[serde(default, skip_serializing)]
    environment: Option<LegacyEnvironment>,
    /// The kept state's iteration, image error and groups' values (its textures, n_params
    /// floats, come last in the data).
    #[serde(default)]
    kept: Option<StoredKept>,
}

/// [`Kept`] without its textures.
#[derive(Serialize, Deserialize)]
struct StoredKept {
    iteration: u32,
    image_relmse: f64,
    groups: BTreeMap<String, Vec<f32>>,
}

/// The gains' state in checkpoints written before the parameter table.
#[derive(Deserialize)]
struct LegacyGains {
    values: Vec<f32>,
    m1: Vec<f32>,
    m2: Vec<f32>,
    steps: u32,
    #[serde(default)]
    white_balance: Vec<[f32; 3]>,
    #[serde(default)]
    wb_m1: Vec<[f32; 3]>,
    #[serde(default)]
    wb_m2: Vec<[f32; 3]>,
    #[serde(default)]
    wb_steps: u32,
}

/// The environment's state in checkpoints written before the parameter table.
#[derive(Deserialize)]
struct LegacyEnvironment {
    size: [u32; 2],
    log: Vec<f32>,
    m1: Vec<f32>,
    m2: Vec<f32>,
    steps: u32,
    mean_luminance: f64,
}

impl Stored {
    /// The table's groups and the environment's fit, from this file's keys or the legacy
    /// ones.
    fn groups(&mut self) -> (BTreeMap<String, GroupState>, Option<EnvFitState>) {
        let mut groups = std::mem::take(&mut self.groups);
        let mut fit = self.environment_fit.take();
        if let Some(e) = self.exposure.take().filter(|e| !e.values.is_empty()) {
            let n = e.values.len();
            let exposure = GroupState {
                values: e.values,
                m1: e.m1,
                m2: e.m2,
                steps: e.steps,
            };
            groups.insert(EXPOSURE.into(), exposure);
            // Checkpoints written before white balances had none.
            let white_balance = if e.white_balance.len() == n {
                GroupState {
                    values: e.white_balance.concat(),
                    m1: e.wb_m1.concat(),
                    m2: e.wb_m2.concat(),
                    steps: e.wb_steps,
                }
            } else {
                GroupState::new(vec![1.0; 3 * n])
            };
            groups.insert(WHITE_BALANCE.into(), white_balance);
        }
        if let Some(e) = self.environment.take() {
            let environment = GroupState {
                values: e.log,
                m1: e.m1,
                m2: e.m2,
                steps: e.steps,
            };
            groups.insert(ENVIRONMENT.into(), environment);
            fit = Some(EnvFitState {
                size: e.size,
                mean_luminance: e.mean_luminance,
            });
        }
        (groups, fit)
    }
}

/// [`EstimatorState`] without its arrays' data.
#[derive(Serialize, Deserialize)]
struct StoredEstimator {
    method: String,
    counters: Vec<(String, u32)>,
    arrays: Vec<(String, usize)>,
}

/// The state a run hands back (`optimizer.keep_best`): the one with the lowest evaluation
/// image error so far.
#[derive(Clone, Debug, PartialEq)]
pub struct Kept {
    /// Its evaluation's image error: the relMSE of the render's expectation
    /// (`crate::job::run::Evaluation::expected`).
    pub image_relmse: f64,
    /// Its textures and groups' values.
    pub values: Values,
}

/// A whole checkpoint.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// Header.
    pub header: Header,
    /// The optimizer's state.
    pub state: OptimizerState,
    /// The state the run hands back, when it keeps one other than its last.
    pub kept: Option<Kept>,
}

impl Checkpoint {
    /// Write atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let st = &self.state;
        let stored = Stored {
            header: self.header.clone(),
            iteration: st.iteration,
            n_params: st.params.len(),
            previous_adjoint_floats: st.previous.as_ref().map(|p| p.adjoint.len()),
            estimator: StoredEstimator {
                method: st.estimator.method.clone(),
                counters: st.estimator.counters.clone(),
                arrays: (st.estimator.arrays.iter())
                    .map(|(name, a)| (name.clone(), a.len()))
                    .collect(),
            },
            control_variate_floats: st.control_variate.as_ref().map(|c| c.state.len()),
            control_variate_iterations: st.control_variate.as_ref().map_or(0, |c| c.iterations),
            path_cache_words: (st.path_cache.as_ref())
                .map(|c| c.pools.iter().map(Vec::len).collect()),
            path_cache_next_slot: st.path_cache.as_ref().map_or(0, |c| c.next_slot),
            groups: st.groups.clone(),
            environment_fit: st.environment.clone(),
            exposure: None,
            environment: None,
            kept: self.kept.as_ref().map(|k| StoredKept {
                iteration: k.values.iteration,
                image_relmse: k.image_relmse,
                groups: k.values.groups.clone(),
            }),
        };
        if st.m1.len() != st.params.len()
            || self
                .kept
                .as_ref()
                .is_some_and(|k| k.values.params.len() != st.params.len())
            || st.m2.len() != st.params.len()
            || st
                .previous
                .as_ref()
                .is_some_and(|p| p.params.len() != st.params.len())
        {
            return Err(Error::file(path, "checkpoint arrays differ in length"));
        }
        let header = serde_json::to_vec(&stored).map_err(|e| Error::file(path, e.to_string()))?;
        let mut out = Vec::with_capacity(16 + header.len() + 16 * st.params.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(&header);
        for a in [&st.params, &st.m1, &st.m2] {
            out.extend_from_slice(bytemuck::cast_slice(a));
        }
        if let Some(p) = &st.previous {
            out.extend_from_slice(bytemuck::cast_slice(&p.params));
            out.extend_from_slice(bytemuck::cast_slice(&p.adjoint));
        }
        for (_, a) in &st.estimator.arrays {
            out.extend_from_slice(bytemuck::cast_slice(a));
        }
        if let Some(c) = &st.control_variate {
            out.extend_from_slice(bytemuck::cast_slice(&c.state));
        }
        for p in st.path_cache.iter().flat_map(|c| &c.pools) {
            out.extend_from_slice(bytemuck::cast_slice(p));
        }
        if let Some(k) = &self.kept {
            out.extend_from_slice(bytemuck::cast_slice(&k.values.params));
        }
        crate::image_io::write_atomic(path, &out)
    }

    /// Read and check.
    pub fn load(path: &Path) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
        let bad = |m: &str| Error::file(path, format!("not a psrestir checkpoint: {m}"));
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(bad(
                "wrong magic (a checkpoint of an older psrestir cannot be resumed)",
            ));
        }
        let hlen = u64::from_le_bytes(bytes[8..16].try_into().map_err(|_| bad("short"))?);
        let hend = usize::try_from(hlen)
            .ok()
            .and_then(|h| h.checked_add(16))
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| bad("truncated header"))?;
        let mut stored: Stored =
            serde_json::from_slice(&bytes[16..hend]).map_err(|e| bad(&e.to_string()))?;
        let (groups, environment) = stored.groups();
        if groups
            .values()
            .any(|g| [g.m1.len(), g.m2.len()] != [g.values.len(); 2])
        {
            return Err(bad(
                "a parameter group's state differs in length from its values",
            ));
        }
        let n = stored.n_params;
        // Sections of 4-byte words, in file order.
        let mut sizes = vec![Some(n), Some(n), Some(n)];
        if let Some(a) = stored.previous_adjoint_floats {
            sizes.push(Some(n));
            sizes.push(Some(a));
        }
        for (_, len) in &stored.estimator.arrays {
            sizes.push(Some(*len));
        }
        if let Some(c) = stored.control_variate_floats {
            sizes.push(Some(c));
        }
        for &w in stored.path_cache_words.iter().flatten() {
            sizes.push(Some(w));
        }
        if stored.kept.is_some() {
            sizes.push(Some(n));
        }
        let words = sizes
            .iter()
            .try_fold(0usize, |acc, s| s.and_then(|s| acc.checked_add(s)));
        if words.and_then(|w| w.checked_mul(4)) != Some(bytes.len() - hend) {
            return Err(bad("truncated data"));
        }
        let mut data = &bytes[hend..];
        let mut take = |count: usize| -> &[u8] {
            let (a, b) = data.split_at(4 * count);
            data = b;
            a
        };
        let params: Vec<f32> = bytemuck::pod_collect_to_vec(take(n));
        let m1: Vec<f32> = bytemuck::pod_collect_to_vec(take(n));
        let m2: Vec<f32> = bytemuck::pod_collect_to_vec(take(n));
        let previous = stored.previous_adjoint_floats.map(|a| PreviousState {
            params: bytemuck::pod_collect_to_vec(take(n)),
            adjoint: bytemuck::pod_collect_to_vec(take(a)),
        });
        let estimator = EstimatorState {
            method: stored.estimator.method,
            counters: stored.estimator.counters,
            arrays: (stored.estimator.arrays.into_iter())
                .map(|(name, len)| (name, bytemuck::pod_collect_to_vec(take(len))))
                .collect(),
        };
        let control_variate = stored
            .control_variate_floats
            .map(|c| ControlVariateSnapshot {
                state: bytemuck::pod_collect_to_vec(take(c)),
                iterations: stored.control_variate_iterations,
            });
        let path_cache = stored.path_cache_words.map(|words| PathCacheSnapshot {
            pools: (words.into_iter())
                .map(|w| bytemuck::pod_collect_to_vec(take(w)))
                .collect(),
            next_slot: stored.path_cache_next_slot,
        });
        let kept = stored.kept.map(|k| Kept {
            image_relmse: k.image_relmse,
            values: Values {
                iteration: k.iteration,
                params: bytemuck::pod_collect_to_vec(take(n)),
                groups: k.groups,
            },
        });
        Ok(Checkpoint {
            kept,
            header: stored.header,
            state: OptimizerState {
                iteration: stored.iteration,
                params,
                m1,
                m2,
                previous,
                estimator,
                control_variate,
                path_cache,
                groups,
                environment,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation_is_detected() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.bin");
        let c = Checkpoint {
            header: Header {
                elapsed_s: 1.5,
                layout: "x".into(),
                metrics: vec![MetricRow {
                    iteration: 1,
                    elapsed_s: 0.1,
                    loss: Some(2.0),
                    texture_rmse: None,
                    texture_rmse_observed: Some(0.5),
                    image_relmse: Some(0.25),
                    image_relmse_expected: Some(0.125),
                    learning_rate: Some(0.01),
                }],
            },
            state: OptimizerState {
                iteration: 7,
                params: vec![1.0, 2.0, 3.0],
                m1: vec![0.1; 3],
                m2: vec![0.2; 3],
                previous: Some(PreviousState {
                    params: vec![0.9, 1.9, 2.9],
                    adjoint: vec![0.5; 8],
                }),
                estimator: EstimatorState {
                    method: "restir".into(),
                    counters: vec![("history".into(), 5)],
                    arrays: vec![
                        ("reservoirs".into(), (0..24).collect()),
                        ("targets".into(), vec![7; 16]),
                    ],
                },
                control_variate: Some(ControlVariateSnapshot {
                    state: vec![0.25; 32],
                    iterations: 9,
                }),
                path_cache: Some(PathCacheSnapshot {
                    pools: vec![vec![1, 2, 3], vec![4, 5, 6]],
                    next_slot: 1,
                }),
                groups: [
                    (EXPOSURE, vec![1.5], 3),
                    (WHITE_BALANCE, vec![1.1, 1.0, 0.9], 2),
                    (ENVIRONMENT, vec![0.5; 6], 4),
                ]
                .into_iter()
                .map(|(name, values, steps)| {
                    let n = values.len();
                    let (m1, m2) = (vec![0.1; n], vec![0.01; n]);
                    let g = GroupState {
                        values,
                        m1,
                        m2,
                        steps,
                    };
                    (name.to_string(), g)
                })
                .collect(),
                environment: Some(EnvFitState {
                    size: [2, 1],
                    mean_luminance: 1.25,
                }),
            },
            kept: Some(Kept {
                image_relmse: 0.125,
                values: Values {
                    iteration: 4,
                    params: vec![0.5, 0.25, 0.75],
                    groups: [(EXPOSURE.to_string(), vec![1.25])].into_iter().collect(),
                },
            }),
        };
        // Without reservoirs (the baseline) and without a kept state as well.
        let mut base = c.clone();
        base.kept = None;
        base.state.estimator = EstimatorState::new(crate::optim::Method::BASELINE);
        base.state.previous = None;
        base.state.control_variate = None;
        base.save(&p).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), base);
        c.save(&p).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 1]).unwrap();
        assert!(Checkpoint::load(&p)
            .unwrap_err()
            .to_string()
            .contains("truncated"));
        // A checkpoint written before the parameter table: the gains' and the environment's
        // state under their own keys (one camera, no white balance yet) reads into the same
        // groups, the white balance at 1.
        let data_at = 16 + u64::from_le_bytes(bytes[8..16].try_into().unwrap()) as usize;
        let mut header: serde_json::Value = serde_json::from_slice(&bytes[16..data_at]).unwrap();
        let h = header.as_object_mut().unwrap();
        h.remove("groups");
        h.remove("environment_fit");
        h.insert(
            "exposure".into(),
            serde_json::json!({"values": [1.5], "m1": [0.1], "m2": [0.01], "steps": 3}),
        );
        h.insert(
            "environment".into(),
            serde_json::json!({"size": [2, 1], "log": vec![0.5; 6], "m1": vec![0.1; 6],
                "m2": vec![0.01; 6], "steps": 4, "mean_luminance": 1.25}),
        );
        let text = serde_json::to_vec(&header).unwrap();
        let mut old = MAGIC.to_vec();
        old.extend((text.len() as u64).to_le_bytes());
        old.extend(text);
        old.extend(&bytes[data_at..]);
        std::fs::write(&p, old).unwrap();
        let mut want = c.clone();
        want.state
            .groups
            .insert(WHITE_BALANCE.into(), GroupState::new(vec![1.0; 3]));
        assert_eq!(Checkpoint::load(&p).unwrap(), want);
    }
}
