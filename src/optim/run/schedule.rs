//! Learning-rate schedules: a factor of each texture's learning rate as a function of the
//! iteration and of the fraction of the run done (iterations or time budget, whichever is
//! further along), so that a time-budgeted run decays as an iteration-budgeted one does.
//!
//! ```toml
//! [optimizer.schedule]
//! kind = "cosine"        # "constant", "step", "cosine" or "exponential"
//! final = 0.05           # cosine, exponential: the factor at the end of the run
//! steps = [0.5, 0.75]    # step: fractions of the run after which ...
//! step_factor = 0.3      # ... the rate is multiplied by this
//! warmup = 0             # iterations of linear warm-up from 1/(warmup+1)
//! ```
use serde::{Deserialize, Serialize};

/// The shape of a schedule.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ScheduleKind {
    /// The learning rate as given.
    #[default]
    Constant,
    /// Multiplied by `step_factor` after each fraction of the run in `steps`.
    Step,
    /// Half a cosine from 1 to `final`.
    Cosine,
    /// Geometric from 1 to `final`.
    Exponential,
}

/// A learning-rate schedule (see the module documentation).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// The shape.
    #[serde(default)]
    pub kind: ScheduleKind,
    /// Factor at the end of the run (cosine and exponential).
    #[serde(default = "default_final", rename = "final")]
    pub final_factor: f32,
    /// Fractions of the run (in (0, 1), increasing) after which a step schedule multiplies
    /// the rate by `step_factor`.
    #[serde(default = "default_steps")]
    pub steps: Vec<f32>,
    /// Factor of each step.
    #[serde(default = "default_step_factor")]
    pub step_factor: f32,
    /// Iterations of linear warm-up: iteration i (from 0) of the first `warmup` uses the
    /// factor (i + 1) / (warmup + 1) times the schedule's.
    #[serde(default)]
    pub warmup: u32,
}

fn default_final() -> f32 {
    0.05
}
fn default_steps() -> Vec<f32> {
    vec![0.5, 0.75]
}
fn default_step_factor() -> f32 {
    0.3
}

impl Default for Schedule {
    fn default() -> Self {
        Schedule::constant()
    }
}

impl Schedule {
    /// No schedule: the learning rates as given.
    pub fn constant() -> Schedule {
        Schedule {
            kind: ScheduleKind::Constant,
            final_factor: default_final(),
            steps: default_steps(),
            step_factor: default_step_factor(),
            warmup: 0,
        }
    }

    /// Half a cosine from 1 to `final_factor` over the run.
    pub fn cosine(final_factor: f32) -> Schedule {
        Schedule {
            kind: ScheduleKind::Cosine,
            final_factor,
            ..Schedule::constant()
        }
    }

    /// The factor of the learning rate at iteration `iteration` (from 0) when the fraction
    /// `progress` of the run is done (clamped to [0, 1]).
    pub fn factor(&self, iteration: u32, progress: f64) -> f32 {
        let p = progress.clamp(0.0, 1.0);
        let f = self.final_factor as f64;
        let shape = match self.kind {
            ScheduleKind::Constant => 1.0,
            ScheduleKind::Step => {
                let n = self.steps.iter().filter(|&&s| p >= s as f64).count() as i32;
                (self.step_factor as f64).powi(n)
            }
            ScheduleKind::Cosine => f + (1.0 - f) * 0.5 * (1.0 + (std::f64::consts::PI * p).cos()),
            ScheduleKind::Exponential => f.powf(p),
        };
        let warm = if iteration < self.warmup {
            (iteration + 1) as f64 / (self.warmup + 1) as f64
        } else {
            1.0
        };
        (shape * warm) as f32
    }

    /// Check the numbers; on failure the key at fault and what is wrong.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.final_factor.is_finite() && self.final_factor > 0.0 && self.final_factor <= 1.0) {
            return Err(("final", "must be in (0, 1]".into()));
        }
        if !(self.step_factor.is_finite() && self.step_factor > 0.0 && self.step_factor <= 1.0) {
            return Err(("step_factor", "must be in (0, 1]".into()));
        }
        if self.steps.iter().any(|s| !(*s > 0.0 && *s < 1.0))
            || self.steps.windows(2).any(|w| w[0] >= w[1])
        {
            return Err(("steps", "must be increasing fractions in (0, 1)".into()));
        }
        if self.warmup > 100_000 {
            return Err(("warmup", "must be at most 100000 iterations".into()));
        }
        Ok(())
    }

    /// A short description, e.g. `cosine to 0.05`.
    pub fn describe(&self) -> String {
        let base = match self.kind {
            ScheduleKind::Constant => "constant".to_string(),
            ScheduleKind::Step => {
                format!("x{} after {:?} of the run", self.step_factor, self.steps)
            }
            ScheduleKind::Cosine => format!("cosine to {}", self.final_factor),
            ScheduleKind::Exponential => format!("exponential to {}", self.final_factor),
        };
        if self.warmup > 0 {
            format!("{base}, {} warm-up iterations", self.warmup)
        } else {
            base
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_follow_the_formulas() {
        let c = Schedule::cosine(0.1);
        assert_eq!(c.factor(0, 0.0), 1.0);
        assert!((c.factor(5, 0.5) - 0.55).abs() < 1e-6);
        assert!((c.factor(9, 1.0) - 0.1).abs() < 1e-6);
        let e = Schedule {
            kind: ScheduleKind::Exponential,
            final_factor: 0.01,
            ..Schedule::constant()
        };
        assert!((e.factor(0, 0.5) - 0.1).abs() < 1e-6);
        let s = Schedule {
            kind: ScheduleKind::Step,
            ..Schedule::constant()
        };
        assert_eq!(s.factor(0, 0.49), 1.0);
        assert!((s.factor(0, 0.5) - 0.3).abs() < 1e-6);
        assert!((s.factor(0, 0.9) - 0.09).abs() < 1e-6);
        let w = Schedule {
            warmup: 3,
            ..Schedule::constant()
        };
        assert_eq!(
            (0..5).map(|i| w.factor(i, 0.0)).collect::<Vec<_>>(),
            vec![0.25, 0.5, 0.75, 1.0, 1.0]
        );
        assert!(Schedule {
            steps: vec![0.6, 0.3],
            ..Schedule::constant()
        }
        .check()
        .is_err());
    }
}
