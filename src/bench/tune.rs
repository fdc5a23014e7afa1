//! `bench --tune`: each estimator's own settings, chosen by a small search on a seed that is
//! not the reported one, so that neither runs on settings made for the other.
//!
//! Coordinate search from the task's settings, one pass, in this order: the learning rate
//! (x0.5, x2, and on in the better direction while it keeps improving, up to x1/8 or x8);
//! the step's own options where its kind searches them before the moment filter's
//! ([`Kind::tuned_before_filter`](crate::optim::step::Kind::tuned_before_filter): the
//! variance-scaled step's clip and threshold); with filtered moments the filter's σ (× 0.25,
//! × 4), its own weight (0.1, 0.5), log space, and where the step keeps a first moment the
//! write-back; the step's own options where they come after the filter's (Adam's β1 and β2);
//! and last the estimator's own options. What a step or an estimator searches is its options'
//! [`Options::tuning`](crate::optim::registry::Options::tuning), in its folder (ReSTIR: the M
//! cap, whether it follows the schedule, the target smoothing; the recursive estimator: the
//! lower bound of its adaptive weight). Each trial
//! optimizes for the tuning budget from the initial textures with the seed
//! [`TUNE_SEED_OFFSET`] away from the task's; its score is the observed-texel RMSE at the
//! end (the headline's measure). A value is kept only when it lowers the score by more than
//! [`MIN_GAIN`] (noise between trials of one seed is about that).
use super::progress::Progress;
use crate::gpu::Gpu;
use crate::job::Problem;
use crate::optim::moment_filter::MomentFilterOptions;
use crate::optim::observed::rmse_observed;
use crate::optim::registry::TuningContext;
use crate::optim::{EstimatorOptions, StepKind, Steps, Stop};
use crate::optim::{Method, Optimizer, Settings};
use crate::{Error, Result};
use serde::Deserialize;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// The tuning runs use the task's seed plus this.
pub const TUNE_SEED_OFFSET: u32 = 7919;

/// Relative improvement a trial needs over the best so far to replace it.
pub const MIN_GAIN: f64 = 0.01;

/// Settings of one estimator that the search chooses. A cache written before the step's
/// options became its table (with `adam`, `variance_clip`, `variance_threshold`) does not
/// read, and the search runs again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tunable {
    /// Factor of every texture's learning rate.
    pub learning_rate_scale: f32,
    /// The step's options table (its part of [`Steps`]).
    #[serde(default)]
    pub step_options: toml::Table,
    /// The estimator's options table (its part of [`EstimatorOptions`]).
    #[serde(default)]
    pub estimator: toml::Table,
    /// The step (not searched: the bench tunes each estimator with each step).
    #[serde(default)]
    pub step: StepKind,
    /// The moment filter (not searched when off).
    #[serde(default)]
    pub moment_filter: MomentFilterOptions,
}

impl Tunable {
    /// The task's and the bench options' settings.
    pub fn untuned(settings: &Settings) -> Tunable {
        Tunable {
            learning_rate_scale: 1.0,
            step_options: settings.steps.table(settings.step),
            estimator: settings.estimator_options.table(settings.method.table()),
            step: settings.step,
            moment_filter: settings.moment_filter,
        }
    }

    /// Put these settings into `settings`.
    pub fn apply(&self, settings: &mut Settings) {
        settings
            .steps
            .set_table(self.step, self.step_options.clone());
        let method = settings.method;
        settings
            .estimator_options
            .set_table(method.table(), self.estimator.clone());
        settings.step = self.step;
        settings.moment_filter = self.moment_filter;
    }

    /// Scale the learning rates of `opt`'s textures (made from `prep`).
    pub fn apply_learning_rate(&self, opt: &mut Optimizer, prep: &Problem) {
        for (t, p) in opt.set.textures.iter_mut().zip(&prep.set.textures) {
            t.learning_rate = Some(self.step.texture_rate(p) * self.learning_rate_scale);
        }
    }

    /// A short description, e.g. `adam step, lr ×2, β1 0.5, β2 0.999, M cap 2 (scheduled)`.
    pub fn describe(&self, method: Method) -> String {
        let mut steps = Steps::default();
        steps.set_table(self.step, self.step_options.clone());
        let mut s = format!("{} step, lr ×{}", self.step, self.learning_rate_scale);
        let own = steps.describe(self.step);
        if !own.is_empty() {
            let _ = write!(s, ", {own}");
        }
        let f = &self.moment_filter;
        if f.enabled() {
            let _ = write!(
                s,
                ", filter {} levels of {}×{} σ {} own {}{}{}",
                f.levels,
                f.taps,
                f.taps,
                f.sigma,
                f.own_weight,
                if f.log_space { " (log)" } else { "" },
                if f.write_back { " written back" } else { "" }
            );
        }
        let mut o = EstimatorOptions::default();
        o.set_table(method.table(), self.estimator.clone());
        let own = o.describe(method);
        if !own.is_empty() {
            let _ = write!(s, ", {own}");
        }
        s
    }
}

/// The name of an estimator with a step in file names: the method's, with `_<step>` for a
/// step other than Adam (`_variance`; Adam adds nothing, so that earlier caches stay valid) and
/// `_filtered` with filtered moments.
pub fn contender_key(method: Method, step: StepKind, filtered: bool) -> String {
    let step = if step == StepKind::ADAM {
        String::new()
    } else {
        format!("_{step}")
    };
    let filtered = if filtered { "_filtered" } else { "" };
    format!("{}{step}{filtered}", method.name())
}

/// One trial of the search.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Trial {
    /// The settings tried.
    pub settings: Tunable,
    /// Observed-texel RMSE at the end of the tuning budget.
    pub score: f64,
}

/// What the search chose for one estimator, and its trials (`tune_<method>.json` in the
/// scene's output folder).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Tuned {
    /// What the cached result was made for (task, sizes, priors, budget, version): a cache
    /// with another key is searched again.
    pub key: String,
    /// The chosen settings.
    pub best: Tunable,
    /// Their score.
    pub score: f64,
    /// Every trial, in order.
    pub trials: Vec<Trial>,
}

/// One coordinate of the search: its candidates around the best settings so far.
type Coordinate = Box<dyn Fn(&Tunable) -> Vec<Tunable>>;

/// The candidates of each coordinate, in search order.
fn coordinates(method: Method, step: StepKind, filtered: bool) -> Vec<Coordinate> {
    let learning_rate: Coordinate = Box::new(|b: &Tunable| {
        [0.5, 2.0]
            .map(|f| Tunable {
                learning_rate_scale: b.learning_rate_scale * f,
                ..b.clone()
            })
            .to_vec()
    });
    let context = TuningContext { filtered };
    let step_axes = || -> Vec<Coordinate> {
        Steps::tuning(step, &context)
            .into_iter()
            .map(|axis| -> Coordinate {
                Box::new(move |b: &Tunable| {
                    axis(&b.step_options)
                        .into_iter()
                        .map(|step_options| Tunable {
                            step_options,
                            ..b.clone()
                        })
                        .collect()
                })
            })
            .collect()
    };
    let mut c: Vec<Coordinate> = vec![learning_rate];
    let kind = step.kind();
    if kind.tuned_before_filter {
        c.extend(step_axes());
    }
    if filtered {
        c.extend(filter_axes(kind.first_moment));
    }
    if !kind.tuned_before_filter {
        c.extend(step_axes());
    }
    for axis in EstimatorOptions::tuning(method, &context) {
        c.push(Box::new(move |b: &Tunable| {
            axis(&b.estimator)
                .into_iter()
                .map(|estimator| Tunable {
                    estimator,
                    ..b.clone()
                })
                .collect()
        }));
    }
    c
}

/// The moment filter's coordinates: σ, its own weight, log space, and the write-back into a
/// step's first moment where it keeps one.
fn filter_axes(first_moment: bool) -> Vec<Coordinate> {
    let mut c: Vec<Coordinate> = vec![
        Box::new(|b: &Tunable| {
            [0.25, 4.0]
                .map(|f| {
                    let mut t = b.clone();
                    t.moment_filter.sigma *= f;
                    t
                })
                .to_vec()
        }),
        Box::new(|b: &Tunable| {
            [0.1, 0.5]
                .map(|own_weight| {
                    let mut t = b.clone();
                    t.moment_filter.own_weight = own_weight;
                    t
                })
                .to_vec()
        }),
        Box::new(|b: &Tunable| {
            let mut t = b.clone();
            t.moment_filter.log_space = !t.moment_filter.log_space;
            vec![t]
        }),
    ];
    if first_moment {
        c.push(Box::new(|b: &Tunable| {
            let mut t = b.clone();
            t.moment_filter.write_back = !t.moment_filter.write_back;
            vec![t]
        }));
    }
    c
}

/// Observed-texel RMSE after optimizing `prep` for `budget_s` with `settings` and `t`, from
/// the initial textures, with the tuning seed.
fn trial(
    gpu: &Gpu,
    prep: &Problem,
    settings: &Settings,
    t: &Tunable,
    budget_s: f64,
) -> Result<f64> {
    let mut s = settings.clone();
    t.apply(&mut s);
    s.seed = s.seed.wrapping_add(TUNE_SEED_OFFSET);
    let mut opt = Optimizer::for_problem(gpu, prep, s)?;
    t.apply_learning_rate(&mut opt, prep);
    let stop = Stop {
        iterations: None,
        time_budget: Some(std::time::Duration::from_secs_f64(budget_s)),
    };
    opt.run(stop, |_| std::ops::ControlFlow::Continue(()))?;
    let observed = opt.observed_texels()?.to_vec();
    let values = opt.read_params()?;
    let score = match prep.reference.as_deref() {
        Some(r) => rmse_observed(&prep.set, &values, r, &observed),
        None => f64::NAN,
    };
    Ok(if score.is_finite() {
        score
    } else {
        f64::INFINITY
    })
}

/// The settings of `method` chosen by the search (or read from `dir`'s cache when it was made
/// for the same `key`), printed.
pub(super) fn tune(
    gpu: &Gpu,
    prep: &Problem,
    settings: &Settings,
    budget_s: f64,
    key: &str,
    dir: &Path,
    progress: &Progress,
) -> Result<Tuned> {
    let method = settings.method;
    let filtered = settings.moment_filter.enabled();
    let who = contender_key(method, settings.step, filtered);
    let path = dir.join(format!("tune_{who}.json"));
    if let Ok(text) = std::fs::read_to_string(&path) {
        if let Ok(t) = serde_json::from_str::<Tuned>(&text) {
            if t.key == key {
                progress.message(format!(
                    "{}: tuned settings from {}: {}",
                    who,
                    path.display(),
                    t.best.describe(method)
                ));
                return Ok(t);
            }
        }
    }
    if prep.reference.is_none() {
        return Err(Error::Invalid(
            "bench --tune needs the scene's ground-truth textures (its target scene)".into(),
        ));
    }
    let mut best = Tunable::untuned(settings);
    progress.message(format!("{}: tuning, {}", who, best.describe(method)));
    let mut best_score = trial(gpu, prep, settings, &best, budget_s)?;
    let mut trials = vec![Trial {
        settings: best.clone(),
        score: best_score,
    }];
    let mut try_one = |candidate: Tunable, best: &mut Tunable, best_score: &mut f64| {
        let score = trial(gpu, prep, settings, &candidate, budget_s)?;
        progress.message(format!(
            "{}: tuning, {} → {score:.4} (best {best_score:.4})",
            who,
            candidate.describe(method)
        ));
        trials.push(Trial {
            settings: candidate.clone(),
            score,
        });
        let better = score < *best_score * (1.0 - MIN_GAIN);
        if better {
            *best = candidate;
            *best_score = score;
        }
        Ok::<bool, Error>(better)
    };
    for (k, coordinate) in coordinates(method, settings.step, filtered)
        .into_iter()
        .enumerate()
    {
        let base = best.clone();
        for candidate in coordinate(&base) {
            try_one(candidate, &mut best, &mut best_score)?;
        }
        // The learning rate: on in the direction that improved.
        if k == 0 && best.learning_rate_scale != base.learning_rate_scale {
            let step = best.learning_rate_scale / base.learning_rate_scale;
            while (0.125..=8.0).contains(&(best.learning_rate_scale * step)) {
                let next = Tunable {
                    learning_rate_scale: best.learning_rate_scale * step,
                    ..best.clone()
                };
                if !try_one(next, &mut best, &mut best_score)? {
                    break;
                }
            }
        }
    }
    let tuned = Tuned {
        key: key.to_string(),
        best,
        score: best_score,
        trials,
    };
    let json = serde_json::to_string_pretty(&tuned)
        .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    crate::image_io::write_atomic(&path, json.as_bytes())?;
    println!(
        "{}: tuned {}: {} (observed-texel RMSE {best_score:.4} on the tuning seed, {} trials)",
        dir.file_name().unwrap_or_default().to_string_lossy(),
        who,
        tuned.best.describe(method),
        tuned.trials.len()
    );
    Ok(tuned)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::adam::AdamOptions;
    use crate::optim::VarianceStepOptions;

    /// What a candidate sets of what the search varies, as `key value` pairs.
    fn show(t: &Tunable, method: Method) -> Vec<String> {
        let f = &t.moment_filter;
        let mut out = vec![format!("lr {}", t.learning_rate_scale)];
        let mut steps = Steps::default();
        steps.set_table(t.step, t.step_options.clone());
        if t.step == StepKind::VARIANCE {
            let v = steps.of::<VarianceStepOptions>();
            out.push(format!("clip {}", v.clip));
            out.push(format!("threshold {}", v.threshold));
        } else {
            let a = steps.of::<AdamOptions>();
            out.push(format!("beta1 {}", a.beta1));
            out.push(format!("beta2 {}", a.beta2));
        }
        out.push(format!("sigma {}", f.sigma));
        out.push(format!("own {}", f.own_weight));
        out.push(format!("log {}", f.log_space));
        out.push(format!("wb {}", f.write_back));
        let defaults = method.kind().options.defaults();
        for (k, v) in &t.estimator {
            if defaults.get(k) != Some(v) {
                out.push(format!("{k} {v}"));
            }
        }
        out
    }

    /// Each coordinate's candidates in search order, each as what it changes from the base.
    fn search(method: Method, step: StepKind, filtered: bool) -> Vec<String> {
        let base = Tunable {
            learning_rate_scale: 1.0,
            step_options: toml::Table::new(),
            estimator: toml::Table::new(),
            step,
            moment_filter: MomentFilterOptions {
                levels: if filtered { 2 } else { 0 },
                ..Default::default()
            },
        };
        let was = show(&base, method);
        coordinates(method, step, filtered)
            .iter()
            .map(|c| {
                let changes: Vec<String> = c(&base)
                    .iter()
                    .map(|t| {
                        let now = show(t, method);
                        let changed: Vec<&str> = now
                            .iter()
                            .filter(|p| !was.contains(p))
                            .map(String::as_str)
                            .collect();
                        changed.join(", ")
                    })
                    .collect();
                changes.join(" | ")
            })
            .collect()
    }

    /// A cache of the earlier format is not read as settings at their defaults.
    #[test]
    fn an_earlier_cache_is_searched_again() {
        let old = r#"{"learning_rate_scale": 1.0, "adam": {"beta1": 0.5, "beta2": 0.999,
            "eps": 1e-8}, "estimator": {}, "step": "adam", "variance_clip": 1.0,
            "variance_threshold": 1.0, "moment_filter": {}}"#;
        assert!(serde_json::from_str::<Tunable>(old).is_err());
        let t = Tunable {
            learning_rate_scale: 2.0,
            step_options: toml::toml! { beta1 = 0.5 },
            estimator: toml::Table::new(),
            step: StepKind::ADAM,
            moment_filter: MomentFilterOptions::default(),
        };
        let back: Tunable = serde_json::from_str(&serde_json::to_string(&t).unwrap()).unwrap();
        assert_eq!(back, t);
        assert_eq!(
            t.describe(Method::BASELINE),
            "adam step, lr ×2, β1 0.5, β2 0.999"
        );
    }

    /// The search's coordinates and their candidates, in order, for each step with and
    /// without the moment filter: the protocol `bench --tune` results were made with.
    #[test]
    fn the_search_order_is_the_protocol() {
        let adam = ["lr 0.5 | lr 2", "beta1 0.5 | beta1 0", "beta2 0.99"];
        assert_eq!(search(Method::BASELINE, StepKind::ADAM, false), adam);
        let adam_filtered = [
            "lr 0.5 | lr 2",
            "sigma 0.025 | sigma 0.4",
            "own 0.1 | own 0.5",
            "log true",
            "wb true",
            "beta1 0.5 | beta1 0.2 | beta1 0",
            "beta2 0.99",
        ];
        assert_eq!(
            search(Method::BASELINE, StepKind::ADAM, true),
            adam_filtered
        );
        let variance_restir = [
            "lr 0.5 | lr 2",
            "clip 0.5 | clip 2",
            "threshold 0 | threshold 2",
            "m_cap 2.0 | m_cap 32.0",
            "m_cap_follows_schedule true",
            "target_smoothing 0.0 | target_smoothing 0.9",
        ];
        assert_eq!(
            search(Method::RESTIR, StepKind::VARIANCE, false),
            variance_restir
        );
        let variance_filtered_recursive = [
            "lr 0.5 | lr 2",
            "clip 0.5 | clip 2",
            "threshold 0 | threshold 2",
            "sigma 0.025 | sigma 0.4",
            "own 0.1 | own 0.5",
            "log true",
            "min_weight 0.2 | min_weight 0.5",
        ];
        assert_eq!(
            search(Method::RECURSIVE, StepKind::VARIANCE, true),
            variance_filtered_recursive
        );
    }
}
