//! The bench's contenders: an estimator with its step and filter, or the default
//! configuration (a task stripped to what `auto` chooses).
use super::tune;
use crate::optim::{Method, StepKind};
use crate::task::Task;
use crate::Error;

/// An estimator with its step, optimized in the equal-time phase after the baseline with Adam
/// (the reference of every ratio).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Contender {
    /// The gradient estimator.
    pub method: Method,
    /// The step.
    pub step: StepKind,
    /// With filtered moments: the task's `[optimizer.moment_filter]`, or
    /// [`moment_filter::SUGGESTED_LEVELS`](crate::optim::moment_filter::SUGGESTED_LEVELS)
    /// levels with the other defaults where the task has none.
    pub filtered: bool,
    /// The default configuration ([`Contender::AUTO`]): the scene's task stripped to what a
    /// task file naming only its scene, cameras, targets, textures and sampling gives, every
    /// other choice `auto`'s ([`bare`]); method, step and filtered are what `auto` chose.
    pub auto: bool,
}

/// `task` as a task file that names only its scene, cameras, targets, textures, sampling and
/// budget gives it: the estimator, step, moment filter, learning rates, schedule and
/// smoothness prior left to `auto` ([`crate::auto`]), no multiscale gradient.
pub fn bare(task: &Task) -> Task {
    let mut t = task.clone();
    let o = &mut t.optimizer;
    o.method = crate::optim::MethodChoice::Auto;
    o.step = None;
    o.moment_filter = None;
    o.schedule = None;
    // The estimators', the steps' and the priors' tables: every prior off but the
    // smoothness prior, whose weight is `auto`'s where none is given.
    o.tables.clear();
    for tex in &mut t.textures {
        tex.learning_rate = None;
    }
    t
}

impl Contender {
    /// The reference of every run: the baseline with Adam, unfiltered.
    pub const BASELINE: Contender = Contender {
        method: Method::BASELINE,
        step: StepKind::ADAM,
        filtered: false,
        auto: false,
    };

    /// The default configuration (see [`Contender::auto`]), before a scene resolves its
    /// estimator, step and filter ([`Contender::on`]).
    pub const AUTO: Contender = Contender {
        method: Method::BASELINE,
        step: StepKind::VARIANCE,
        filtered: false,
        auto: true,
    };

    /// The bench's default contenders: ReSTIR with Adam, the recursive estimator with Adam
    /// and with the variance-scaled step, the baseline with the variance-scaled step without
    /// and with filtered moments, and the default configuration (which the report compares
    /// with the lowest of the others).
    pub const DEFAULT: [Contender; 6] = [
        Contender {
            method: Method::RESTIR,
            step: StepKind::ADAM,
            filtered: false,
            auto: false,
        },
        Contender {
            method: Method::RECURSIVE,
            step: StepKind::ADAM,
            filtered: false,
            auto: false,
        },
        Contender {
            method: Method::RECURSIVE,
            step: StepKind::VARIANCE,
            filtered: false,
            auto: false,
        },
        Contender {
            method: Method::BASELINE,
            step: StepKind::VARIANCE,
            filtered: false,
            auto: false,
        },
        Contender {
            method: Method::BASELINE,
            step: StepKind::VARIANCE,
            filtered: true,
            auto: false,
        },
        Contender::AUTO,
    ];

    /// An estimator with Adam, unfiltered.
    pub fn adam(method: Method) -> Contender {
        Contender {
            method,
            step: StepKind::ADAM,
            filtered: false,
            auto: false,
        }
    }

    /// The contender on `task` seen by `cameras` cameras: for [`Contender::AUTO`], the
    /// estimator, step and filter that `auto` chooses for the [`bare`] task.
    pub fn on(&self, task: &Task, cameras: usize) -> Contender {
        if !self.auto {
            return *self;
        }
        let c =
            crate::task::task_configuration(&bare(task), crate::optim::MethodChoice::Auto, cameras);
        Contender {
            method: c.estimator.method,
            step: c.step,
            filtered: c.moment_filter.enabled(),
            auto: true,
        }
    }

    /// Its settings on `task` (its cameras and the bench's options from `settings`): the
    /// task's with its step and filter, or the [`bare`] task's.
    pub fn settings(
        &self,
        task: &Task,
        settings: impl Fn(&Task, Method) -> crate::optim::Settings,
    ) -> crate::optim::Settings {
        if self.auto {
            return settings(&bare(task), self.method);
        }
        let mut s = settings(task, self.method);
        self.apply(&mut s);
        s
    }

    /// Put its step and filter into `s`.
    pub fn apply(&self, s: &mut crate::optim::Settings) {
        s.step = self.step;
        if self.filtered && !s.moment_filter.enabled() {
            s.moment_filter.levels = crate::optim::moment_filter::SUGGESTED_LEVELS;
        } else if !self.filtered {
            s.moment_filter.levels = 0;
        }
    }

    /// What `auto` chose, from the default configuration's run name (`default (auto: X)`
    /// gives X); any other name as it is.
    pub fn chosen(run_name: &str) -> &str {
        run_name
            .strip_prefix("default (auto: ")
            .and_then(|n| n.strip_suffix(')'))
            .unwrap_or(run_name)
    }

    /// How reports name it, e.g. `recursive, variance-scaled step, filtered moments`, or
    /// `default (auto: baseline, variance-scaled step, filtered moments)`.
    pub fn name(&self) -> String {
        if self.auto {
            let c = Contender {
                auto: false,
                ..*self
            };
            return format!("default (auto: {})", c.name());
        }
        let step = if self.step == StepKind::ADAM {
            "Adam"
        } else if self.step == StepKind::VARIANCE {
            "variance-scaled step"
        } else {
            self.step.name()
        };
        let filtered = if self.filtered {
            ", filtered moments"
        } else {
            ""
        };
        format!("{}, {step}{filtered}", self.method.name())
    }

    /// Its key in file names (`recursive`, `recursive_variance`, `baseline_filtered`).
    pub fn key(&self) -> String {
        if self.auto {
            return "default".into();
        }
        tune::contender_key(self.method, self.step, self.filtered)
    }

    /// Parse `METHOD`, `METHOD:STEP` (`recursive:variance`), either with `+filtered`
    /// (`baseline+filtered`, `recursive:variance+filtered`), or `default` ([`Contender::AUTO`]).
    pub fn parse(s: &str) -> std::result::Result<Contender, String> {
        if s == "default" {
            return Ok(Contender::AUTO);
        }
        let (s, filtered) = match s.strip_suffix("+filtered") {
            Some(rest) => (rest, true),
            None => (s, false),
        };
        let (m, st) = s.split_once(':').unwrap_or((s, "adam"));
        let method: Method = m.parse().map_err(|e: Error| e.to_string())?;
        let step: StepKind = st.parse().map_err(|e: Error| e.to_string())?;
        Ok(Contender {
            method,
            step,
            filtered,
            auto: false,
        })
    }
}
