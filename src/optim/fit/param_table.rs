//! The parameter table: every group of parameters the optimizer steps, by name. The textures
//! are its GPU groups: [`ParamSet`](crate::render::params::ParamSet) lays them out on the GPU
//! and the chosen step's pass moves them. The environment's texels and the cameras' exposures
//! and white balances are its CPU groups, held here with their step's state and moved by the
//! same step's CPU path ([`step::Kind::cpu`](crate::optim::step::Kind::cpu)): there is one Adam,
//! with one set of options, for everything a run optimizes. A step without a CPU path (the
//! variance-scaled step divides by an estimator's variance, which the CPU groups lack) leaves
//! them to Adam.
use crate::optim::step::{CpuGroup, StepKind, Steps};
use crate::optim::Settings;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The cameras' exposures (positive factors, one per camera; stepped as logarithms).
pub const EXPOSURE: &str = "exposure";
/// The cameras' white balances (three positive factors per camera; stepped as logarithms).
pub const WHITE_BALANCE: &str = "white_balance";
/// The environment's texels: ln(radiance) per texel and channel, row 0 at the zenith.
pub const ENVIRONMENT: &str = "environment";

/// A group's values and its step's state per value: what checkpoints save of it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GroupState {
    /// The values.
    pub values: Vec<f32>,
    /// The step's first per-value state (Adam's first moment).
    pub m1: Vec<f32>,
    /// The step's second per-value state (Adam's second moment).
    pub m2: Vec<f32>,
    /// Steps taken.
    pub steps: u32,
}

impl GroupState {
    /// `values` before any step.
    pub fn new(values: Vec<f32>) -> GroupState {
        let n = values.len();
        GroupState {
            values,
            m1: vec![0.0; n],
            m2: vec![0.0; n],
            steps: 0,
        }
    }
}

/// What a group's step moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Space {
    /// The values themselves.
    Values,
    /// The logarithms of the values (positive factors, stored as they are).
    Logarithms,
}

/// One CPU group of the table.
#[derive(Clone, Debug)]
pub struct Group {
    /// Its name in the table and in checkpoints.
    pub name: &'static str,
    /// What its step moves.
    pub space: Space,
    /// The range the step clamps what it moves to.
    pub range: (f32, f32),
    /// Its learning rate; None: it holds.
    pub learning_rate: Option<f32>,
    /// Leading values that hold (the reference camera's while the light is recovered).
    pub held: usize,
    /// Its values and its step's state.
    pub state: GroupState,
}

impl Group {
    /// A group of `values` that holds until it is given a learning rate.
    pub fn new(name: &'static str, space: Space, values: Vec<f32>) -> Group {
        Group {
            name,
            space,
            range: (-20.0, 20.0),
            learning_rate: None,
            held: 0,
            state: GroupState::new(values),
        }
    }

    /// One step of `kind` (options in `steps`) from `grad` (one derivative per value, with
    /// respect to what the step moves) at its learning rate times `factor`; nothing when it
    /// holds. A value whose derivative is not finite keeps its value and state.
    fn step(&mut self, kind: StepKind, steps: &Steps, grad: &[f32], factor: f32) {
        let Some(lr) = self.learning_rate else {
            return;
        };
        let cpu = kind.kind().cpu.expect("the table's step has a CPU path");
        let s = &mut self.state;
        debug_assert_eq!(grad.len(), s.values.len(), "{}'s gradient", self.name);
        s.steps += 1;
        let h = self.held.min(s.values.len());
        let mut logs: Vec<f32> = match self.space {
            Space::Values => Vec::new(),
            Space::Logarithms => s.values[h..].iter().map(|v| v.ln()).collect(),
        };
        let moved = match self.space {
            Space::Values => &mut s.values[h..],
            Space::Logarithms => &mut logs[..],
        };
        cpu(
            steps,
            CpuGroup {
                values: moved,
                m1: &mut s.m1[h..],
                m2: &mut s.m2[h..],
                grad: &grad[h..],
                t: s.steps,
                lr: lr * factor,
                range: self.range,
            },
        );
        if self.space == Space::Logarithms {
            for (i, l) in logs.iter().enumerate() {
                if grad[h + i].is_finite() {
                    s.values[h + i] = l.exp();
                }
            }
        }
    }
}

/// The CPU groups of the parameter table.
pub struct ParamTable {
    groups: Vec<Group>,
}

impl ParamTable {
    /// The table of `n_cameras` cameras at exposure and white balance 1; the exposures at
    /// `settings.exposure_learning_rate` when given.
    pub fn new(n_cameras: usize, settings: &Settings) -> ParamTable {
        let mut exposure = Group::new(EXPOSURE, Space::Logarithms, vec![1.0; n_cameras]);
        exposure.learning_rate = settings.exposure_learning_rate;
        let white_balance = Group::new(WHITE_BALANCE, Space::Logarithms, vec![1.0; 3 * n_cameras]);
        ParamTable {
            groups: vec![exposure, white_balance],
        }
    }

    /// The step that moves the CPU groups in a run with `settings`: its step where that has
    /// a CPU path, Adam otherwise.
    pub fn step_kind(settings: &Settings) -> StepKind {
        match settings.step.kind().cpu {
            Some(_) => settings.step,
            None => StepKind::ADAM,
        }
    }

    /// The group called `name`, if the table has it.
    pub fn get(&self, name: &str) -> Option<&Group> {
        self.groups.iter().find(|g| g.name == name)
    }

    /// The group called `name`, which the table has.
    pub fn group(&self, name: &str) -> &Group {
        self.get(name)
            .unwrap_or_else(|| panic!("no `{name}` group in the parameter table"))
    }

    /// The group called `name`, which the table has, to change.
    pub fn group_mut(&mut self, name: &str) -> &mut Group {
        self.groups
            .iter_mut()
            .find(|g| g.name == name)
            .unwrap_or_else(|| panic!("no `{name}` group in the parameter table"))
    }

    /// Add `group`, or replace the group of its name.
    pub fn insert(&mut self, group: Group) {
        self.groups.retain(|g| g.name != group.name);
        self.groups.push(group);
    }

    /// Whether any of the groups `names` is optimized.
    pub fn optimizes(&self, names: &[&str]) -> bool {
        names
            .iter()
            .any(|n| self.get(n).is_some_and(|g| g.learning_rate.is_some()))
    }

    /// One step of the group `name` from `grad` at schedule factor `factor`, by the step
    /// of a run with `settings` ([`ParamTable::step_kind`]) with its options.
    pub fn step(&mut self, settings: &Settings, name: &str, grad: &[f32], factor: f32) {
        let kind = ParamTable::step_kind(settings);
        (self.group_mut(name)).step(kind, &settings.steps, grad, factor);
    }

    /// Every group's state, by name, for checkpoints.
    pub fn states(&self) -> BTreeMap<String, GroupState> {
        (self.groups.iter())
            .map(|g| (g.name.to_string(), g.state.clone()))
            .collect()
    }

    /// Every group's values, by name (without its step's state).
    pub fn values(&self) -> BTreeMap<String, Vec<f32>> {
        (self.groups.iter())
            .map(|g| (g.name.to_string(), g.state.values.clone()))
            .collect()
    }

    /// Take `values` (from [`ParamTable::values`]) as the named groups' values; their step's
    /// state stays. A name this table lacks or a size that differs is refused before
    /// anything changes.
    pub fn set_values(&mut self, values: &BTreeMap<String, Vec<f32>>) -> Result<()> {
        for (name, v) in values {
            match self.get(name) {
                Some(g) if g.state.values.len() == v.len() => {}
                Some(g) => {
                    return Err(Error::Invalid(format!(
                        "`{name}` has {} values, this task's {}",
                        v.len(),
                        g.state.values.len()
                    )))
                }
                None => {
                    return Err(Error::Invalid(format!(
                        "`{name}` is not a group this task optimizes"
                    )))
                }
            }
        }
        for (name, v) in values {
            self.group_mut(name).state.values.clone_from(v);
        }
        Ok(())
    }

    /// Go on from `states` (a checkpoint's): each group named there takes its state; one this
    /// table lacks or of another size is refused before anything changes.
    pub fn restore(&mut self, states: &BTreeMap<String, GroupState>) -> Result<()> {
        for (name, s) in states {
            let Some(g) = self.get(name) else {
                return Err(Error::Invalid(format!(
                    "the checkpoint has a state for `{name}`, which this task does not optimize"
                )));
            };
            let n = g.state.values.len();
            if [s.values.len(), s.m1.len(), s.m2.len()] != [n; 3] {
                return Err(Error::Invalid(format!(
                    "the checkpoint's `{name}` has {} values, this task's {n}",
                    s.values.len()
                )));
            }
        }
        for (name, s) in states {
            self.group_mut(name).state = s.clone();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::adam;

    /// A group of exposures stepped as logarithms, its first camera held: each other value
    /// moves exactly as one CPU Adam step of its logarithm, and a value whose derivative is
    /// not finite keeps its value and moments.
    #[test]
    fn logarithm_groups_step_as_adam_on_their_logarithms() {
        let settings = Settings {
            step: StepKind::VARIANCE,
            exposure_learning_rate: Some(0.1),
            ..Settings::new(8, 8, vec![0])
        };
        let mut t = ParamTable::new(4, &settings);
        assert_eq!(ParamTable::step_kind(&settings), StepKind::ADAM);
        t.group_mut(EXPOSURE).state.values = vec![0.5, 2.0, 1.5, 0.75];
        t.group_mut(EXPOSURE).held = 1;
        let grad = [0.3, -0.2, f32::NAN, 0.4];
        let (mut m1, mut m2) = ([0f32; 4], [0f32; 4]);
        let mut want = [0.5f32, 2.0, 1.5, 0.75];
        for t_ in 1..=3u32 {
            t.step(&settings, EXPOSURE, &grad, 0.5);
            for k in [1, 3] {
                let mut l = [want[k].ln()];
                let o = adam::AdamOptions::default();
                let (a, b) = (&mut m1[k..k + 1], &mut m2[k..k + 1]);
                adam::step_with(
                    &o,
                    &mut l,
                    a,
                    b,
                    &grad[k..k + 1],
                    0.05,
                    t_,
                    (-20.0, 20.0),
                    false,
                );
                want[k] = l[0].exp();
            }
        }
        let g = t.group(EXPOSURE);
        assert_eq!(g.state.values, want);
        assert_eq!(g.state.steps, 3);
        assert_eq!((g.state.m1[0], g.state.m1[2]), (0.0, 0.0));
        // The white balances hold: they have no learning rate.
        t.step(&settings, WHITE_BALANCE, &[1.0; 12], 1.0);
        assert_eq!(t.group(WHITE_BALANCE).state, GroupState::new(vec![1.0; 12]));
    }

    /// The run's step moves the CPU groups where it has a CPU path: the toy step is plain
    /// gradient descent, its `scale` read from its table.
    #[test]
    fn the_chosen_step_moves_the_cpu_groups() {
        let toy = StepKind::by_name("toy").unwrap();
        let mut steps = Steps::default();
        steps.set("toy_step", "scale", toml::Value::Float(2.0));
        let settings = Settings {
            step: toy,
            steps,
            ..Settings::new(8, 8, vec![0])
        };
        let mut t = ParamTable::new(1, &settings);
        assert_eq!(ParamTable::step_kind(&settings), toy);
        let mut env = Group::new(ENVIRONMENT, Space::Values, vec![0.25, 0.5]);
        env.learning_rate = Some(0.1);
        t.insert(env);
        t.step(&settings, ENVIRONMENT, &[1.0, -0.5], 0.5);
        // 0.25 - 0.1 x 0.5 x 2 x 1, 0.5 + 0.1 x 0.5 x 2 x 0.5.
        let v = &t.group(ENVIRONMENT).state.values;
        assert!(
            (v[0] - 0.15).abs() < 1e-6 && (v[1] - 0.55).abs() < 1e-6,
            "{v:?}"
        );
    }

    /// A checkpoint's group of another size, or one the table lacks, is refused by name and
    /// changes nothing.
    #[test]
    fn restore_refuses_a_group_that_does_not_fit() {
        let settings = Settings {
            exposure_learning_rate: Some(0.1),
            ..Settings::new(8, 8, vec![0])
        };
        let mut t = ParamTable::new(2, &settings);
        let mut states = t.states();
        states.get_mut(EXPOSURE).unwrap().values = vec![3.0, 3.0];
        states.get_mut(EXPOSURE).unwrap().steps = 5;
        let mut bad = states.clone();
        bad.insert(ENVIRONMENT.into(), GroupState::new(vec![0.0; 6]));
        let e = t.restore(&bad).unwrap_err().to_string();
        assert!(e.contains("`environment`"), "{e}");
        bad = states.clone();
        bad.insert(WHITE_BALANCE.into(), GroupState::new(vec![1.0; 3]));
        let e = t.restore(&bad).unwrap_err().to_string();
        assert!(
            e.contains("`white_balance` has 3 values, this task's 6"),
            "{e}"
        );
        assert_eq!(t.group(EXPOSURE).state.values, vec![1.0, 1.0]);
        t.restore(&states).unwrap();
        assert_eq!(t.states(), states);
    }
}
