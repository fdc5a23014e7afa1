//! The `[optimizer]` table of a task file and the optimizer settings a task asks for.
use super::{Filter, Loss};
use crate::optim::prior::{self, smoothness, smoothness::SmoothnessOptions, Priors};
use crate::optim::registry::Family;
use crate::optim::step::{self, Steps};
use crate::optim::{EstimatorOptions, Method, MethodChoice};
use serde::Deserialize;

/// Optimizer settings.
#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct OptimizerSpec {
    /// Iterations to run (at most).
    pub iterations: Option<u32>,
    /// Wall-clock budget in seconds (at most).
    pub time_budget_s: Option<f64>,
    /// End the run once the loss and the evaluation image error have stopped falling
    /// (job::watch::PlateauWatch). None: where the task gives a time budget and no
    /// iteration count; a task that names its iterations runs them all.
    #[serde(default)]
    pub stop_on_plateau: Option<bool>,
    /// Write the state with the lowest evaluation image error the run saw (the start's
    /// included; the relMSE of the render's expectation, `job::run::Evaluation::expected`)
    /// instead of the last one (`job::keep`); needs `eval_every` > 0.
    #[serde(default = "yes")]
    pub keep_best: bool,
    /// Samples per pixel of the primal render (independent of the gradient samples).
    #[serde(default = "default_primal_spp")]
    pub primal_spp: u32,
    /// How the primal image is estimated: "independent" or "control_variate".
    #[serde(default)]
    pub primal: crate::optim::PrimalMode,
    /// Upper clamp of the control variate's per-pixel weight, in [0, 1].
    #[serde(default = "default_cv_max_weight")]
    pub cv_max_weight: f32,
    /// The path cache: the primal image shades `primal_spp` stored camera paths per pixel,
    /// this many of them traced anew each iteration (absent: every path traced anew, no
    /// cache).
    #[serde(default)]
    pub path_cache: Option<u32>,
    /// Samples per pixel of the gradient pass.
    #[serde(default = "one")]
    pub gradient_spp: u32,
    /// Gradient estimator: "auto" (the default: chosen by the task's sampling, see
    /// [`MethodChoice`]), "baseline", "restir" or "recursive"; `--method` overrides it.
    #[serde(default)]
    pub method: MethodChoice,
    /// The step taken with each gradient: "adam" or "variance" (None: `auto`'s,
    /// [`crate::auto`]); its options are its table (`[optimizer.adam]`,
    /// `[optimizer.variance_step]`).
    #[serde(default)]
    pub step: Option<crate::optim::StepKind>,
    /// Image loss.
    #[serde(default)]
    pub loss: Loss,
    /// Texture filter of the optimized textures.
    #[serde(default)]
    pub filter: Filter,
    /// Iterations between checkpoints (0: not by iterations).
    #[serde(default = "default_checkpoint")]
    pub checkpoint_every: u32,
    /// Seconds between checkpoints (0: not by time); whichever of the two comes first.
    #[serde(default = "default_checkpoint_s")]
    pub checkpoint_every_s: f64,
    /// Optimize a per-camera exposure factor with the textures (photos have unknown
    /// exposure); it starts at `target.exposure` (or 1).
    #[serde(default)]
    pub optimize_exposure: bool,
    /// Adam learning rate of the exposures' logarithms.
    #[serde(default = "default_exposure_lr")]
    pub exposure_learning_rate: f32,
    /// Optimize a per-camera white balance (a factor per channel over the exposure) with the
    /// textures; with the environment recovered, the first camera's response is held (the
    /// gauge of light against camera).
    #[serde(default)]
    pub optimize_white_balance: bool,
    /// Adam learning rate of the white balances' logarithms.
    #[serde(default = "default_exposure_lr")]
    pub white_balance_learning_rate: f32,
    /// Learning-rate schedule over the run (None: `auto`'s, a cosine decay).
    #[serde(default)]
    pub schedule: Option<crate::optim::Schedule>,
    /// Sparse steps: entries with an exactly zero gradient keep their value and moments
    /// (either step; `adam_mask`, its earlier name, is read too).
    #[serde(default, alias = "adam_mask")]
    pub sparse_steps: bool,
    /// The moment filter (`[optimizer.moment_filter]`: `levels` (0: off), `sigma`,
    /// `log_space`, `own_weight`, `write_back`; None: `auto`'s for the step).
    #[serde(default)]
    pub moment_filter: Option<crate::optim::moment_filter::MomentFilterOptions>,
    /// Iterations between evaluation renders (image relMSE of an `eval_spp` render of every
    /// camera against its target, outside the timed budget); 0: none.
    #[serde(default = "default_eval_every")]
    pub eval_every: u32,
    /// Samples per pixel of the evaluation renders.
    #[serde(default = "default_eval_spp")]
    pub eval_spp: u32,
    /// Each estimator's, each step's and each prior's options: the tables
    /// `[optimizer.<estimator>]` (`[optimizer.restir]`), passed on to the estimator, which
    /// reads and checks its own; the steps' tables (`[optimizer.adam]`,
    /// `[optimizer.variance_step]`), passed on to the steps; the tables `[optimizer.<prior>]`
    /// (`[optimizer.multiscale]`) and the priors' shorthands (`smoothness = 0.03`,
    /// `multiscale_levels = 4`), passed on to the priors. Any other key is refused when the
    /// task is checked.
    #[serde(flatten)]
    pub tables: std::collections::BTreeMap<String, toml::Value>,
}

/// What a key under `[optimizer]` that is not one of [`OptimizerSpec`]'s own fields names.
enum TableKey {
    Estimator(Method),
    Step(&'static step::Kind),
    Prior(&'static prior::Kind),
    /// A prior's shorthand: the prior and the option it sets.
    Shorthand(&'static prior::Kind, &'static str),
}

impl TableKey {
    fn of(name: &str, value: &toml::Value) -> std::result::Result<TableKey, (String, String)> {
        let key = format!("optimizer.{name}");
        let shorthand = prior::REGISTRY
            .iter()
            .find_map(|k| k.shorthand.filter(|s| s.0 == name).map(|s| (*k, s.1)));
        let (method, prior) = (Method::by_name(name), prior::Kind::by_name(name));
        let step = <step::StepFamily as Family>::by_table(name);
        let found = match (value.is_table(), method, step, prior, shorthand) {
            (true, Some(m), ..) => TableKey::Estimator(m),
            (true, None, Some(k), ..) => TableKey::Step(k),
            (true, None, None, Some(k), _) => TableKey::Prior(k),
            (false, .., Some((k, option))) => TableKey::Shorthand(k, option),
            (false, Some(_), ..) => {
                return Err((key, "must be a table of the estimator's options".into()))
            }
            (false, None, Some(_), ..) => {
                return Err((key, "must be a table of the step's options".into()))
            }
            (false, None, None, Some(_), _) => {
                return Err((key, "must be a table of the prior's options".into()))
            }
            _ => {
                return Err((
                    key,
                    format!(
                        "unknown key (nor the options of an estimator: {}; of a step: {}; of a \
                         prior: {})",
                        Method::names().join(", "),
                        <step::StepFamily as Family>::tables().join(", "),
                        prior::Kind::names().join(", ")
                    ),
                ));
            }
        };
        Ok(found)
    }
}

impl OptimizerSpec {
    /// The estimators' option tables (an error names a key that is neither an option nor
    /// an estimator's, a step's or a prior's table).
    pub fn estimator_options(&self) -> std::result::Result<EstimatorOptions, (String, String)> {
        let mut o = EstimatorOptions::default();
        for (name, value) in &self.tables {
            if let (TableKey::Estimator(method), toml::Value::Table(t)) =
                (TableKey::of(name, value)?, value)
            {
                o.set_table(method.table(), t.clone());
            }
        }
        Ok(o)
    }

    /// The steps' option tables, checked: an error names the key and what is wrong.
    pub fn step_options(&self) -> std::result::Result<Steps, (String, String)> {
        let mut steps = Steps::default();
        for (name, value) in &self.tables {
            if let (TableKey::Step(k), toml::Value::Table(t)) = (TableKey::of(name, value)?, value)
            {
                for (option, v) in t {
                    steps.set(k.table, option, v.clone());
                }
            }
        }
        steps.check()?;
        Ok(steps)
    }

    /// The priors' option tables, shorthands included, checked: an error names the key the
    /// task gave (a shorthand's own key where the option came from one).
    pub fn prior_options(&self) -> std::result::Result<Priors, (String, String)> {
        let mut p = Priors::default();
        let mut shorthands = Vec::new();
        for (name, value) in &self.tables {
            if let (TableKey::Prior(k), toml::Value::Table(t)) = (TableKey::of(name, value)?, value)
            {
                for (option, v) in t {
                    p.set(k.name, option, v.clone());
                }
            }
        }
        // The shorthands after every table, so that a clash is found whichever comes first.
        for (name, value) in &self.tables {
            if let TableKey::Shorthand(k, option) = TableKey::of(name, value)? {
                if p.table(k.name).contains_key(option) {
                    return Err((
                        format!("optimizer.{name}"),
                        format!("`[optimizer.{}]` sets `{option}` too: give one", k.name),
                    ));
                }
                shorthands.push((format!("optimizer.{}.{option}", k.name), name));
                p.set(k.name, option, value.clone());
            }
        }
        p.check().map_err(
            |(key, msg)| match shorthands.iter().find(|(long, _)| *long == key) {
                Some((_, short)) => (format!("optimizer.{short}"), msg),
                None => (key, msg),
            },
        )?;
        Ok(p)
    }

    /// The smoothness prior's weight where the task gives one (None: `auto`'s).
    pub fn smoothness(&self) -> Option<f32> {
        let p = self.prior_options().ok()?;
        let given = p.table(smoothness::KIND.name).contains_key("weight");
        given.then(|| p.of::<SmoothnessOptions>().weight)
    }

    /// Set `key` of `[optimizer]` among [`OptimizerSpec::tables`] (a prior's shorthand, an
    /// estimator's or a prior's table) as a task file gives it: `set("smoothness", 0.03)`.
    pub fn set(&mut self, key: &str, value: impl Into<toml::Value>) {
        self.tables.insert(key.to_string(), value.into());
    }

    /// Switch every prior off: each prior's table at its defaults, which leave it off (the
    /// smoothness prior's weight given as 0, so that `auto` does not choose one).
    pub fn priors_off(&mut self) {
        self.tables.retain(|name, value| {
            !matches!(
                TableKey::of(name, value),
                Ok(TableKey::Prior(_) | TableKey::Shorthand(..))
            )
        });
        for kind in prior::REGISTRY {
            let defaults = kind.options.defaults();
            self.tables
                .insert(kind.name.to_string(), toml::Value::Table(defaults));
        }
    }
}

fn default_checkpoint_s() -> f64 {
    60.0
}
fn default_exposure_lr() -> f32 {
    0.01
}
fn default_eval_every() -> u32 {
    10
}
fn default_eval_spp() -> u32 {
    16
}

fn default_cv_max_weight() -> f32 {
    crate::optim::primal::DEFAULT_MAX_WEIGHT
}

fn default_primal_spp() -> u32 {
    4
}
pub(super) fn one() -> u32 {
    1
}
pub(super) fn yes() -> bool {
    true
}
fn default_checkpoint() -> u32 {
    25
}
