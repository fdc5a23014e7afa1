//! `auto`: the configuration a task leaves unset, chosen by its regime.
//!
//! A task that names only its scene, cameras, targets and textures gets the whole
//! configuration from here: the estimator (by [`MethodChoice::Auto`]'s rule, from the samples
//! per texel, the primal's share and the path depth), the step, its moment filter, each
//! texture's learning rate, the schedule and the smoothness prior. Every key a task file, a
//! flag or the library sets wins over the rule; the run log says what the rule chose and why.
//!
//! The rule, and what it rests on (docs/studies.md, "Defaults that fit the task", and the
//! bench's default table):
//! - **The step by regime** ([`step`]). With direct light and few gradient samples per texel
//!   (the bench's direct-lit scenes: a quarter of a sample per texel and iteration) **Adam**:
//!   there it ended level with or below the variance-scaled step in texture error and below
//!   it in image error on every scene, with the baseline and with ReSTIR (30-s runs on
//!   lavapipe: the variance step at 1.00-1.15x Adam's texture error with either estimator,
//!   image error up to 1.6x). Elsewhere **the variance-scaled step**: with indirect light
//!   Adam moves every texel by about the learning rate per step however noisy its gradient,
//!   and where a texel gets only bounced light that walk is speckle (the indirect-lit bench
//!   scene `gallery` with Adam at its task's rate ends above its start); with dense sampling
//!   (the default task, 2 samples per texel) it ended lower (0.0823 against 0.0946 filtered).
//!   The variance-scaled step moves a texel by its estimate over the estimate's spread, less
//!   a threshold of one spread, clipped at one learning rate, so a texel moves only as far
//!   as its gradient is sure and the rate is a distance in the slot's units.
//! - **Filtered moments over base color only, with the variance-scaled step, and over base
//!   color and normal maps with either step, a normal map alone with Adam only**
//!   ([`moment_filter`]): over roughness and metallic the filter blurred, with Adam over base
//!   color alone it did not pay, over a normal map it took Adam's speckle away, and over a
//!   normal map alone it made the variance step tilt whole regions.
//! - **Learning rates**: for Adam the bench tasks' (0.03 for base color and metallic, 0.02
//!   for roughness); for the variance step 0.01 per step (a normal map 0.003), 0.03 with
//!   indirect light ([`StepKind::learning_rate`], [`learning_rate_for`]).
//! - **A cosine decay to 5%** over the run (its iterations or its time budget): the last
//!   steps refine instead of walking.
//! - **The smoothness prior** at 0.03 with sparse sampling, 0.01 with dense ([`smoothness`]):
//!   with few samples per texel the images leave texels free that only a prior ties to their
//!   neighbours. The multiscale gradient stays off.
use crate::optim::estimator::Regime;
use crate::optim::estimator::DENSE_SAMPLES_PER_TEXEL;
use crate::optim::moment_filter::{MomentFilterOptions, SUGGESTED_LEVELS};
use crate::optim::{Choice, MethodChoice, Schedule, ScheduleKind, StepKind};
use crate::vocab::Slot;

/// The step where a task in `regime` names none: Adam with direct light and fewer than
/// [`DENSE_SAMPLES_PER_TEXEL`] gradient samples per texel and iteration, the variance-scaled
/// step otherwise (see the module documentation).
pub fn step(regime: &Regime) -> StepKind {
    if regime.max_depth <= 1 && regime.samples_per_texel() < DENSE_SAMPLES_PER_TEXEL {
        StepKind::ADAM
    } else {
        StepKind::VARIANCE
    }
}

/// Why [`step`] chose what it chose for `regime`, in one line.
fn step_reason(regime: &Regime, step: StepKind) -> String {
    let regime_text = format!(
        "{:.2} gradient samples per texel and iteration, max_depth {}",
        regime.samples_per_texel(),
        regime.max_depth
    );
    if step == StepKind::ADAM {
        format!(
            "step adam: with direct light and sparse samples ({regime_text}) it ended level \
             with or below the variance-scaled step on every direct-lit bench scene"
        )
    } else {
        format!(
            "step {step}: it moves a texel only as far as its gradient is sure, which needs no \
             tuning against the gradient's noise ({regime_text}: indirect light or dense \
             samples, where Adam's walk of about its rate per step is speckle)"
        )
    }
}

/// The factor of the learning rate at the end of a run under the default schedule.
pub const FINAL_FACTOR: f32 = 0.05;

/// The learning rate of a texture that names none in a task of `regime`: with indirect light
/// the variance-scaled step takes 0.03 (a normal map excepted), otherwise the step's own
/// ([`StepKind::learning_rate`], whose documentation in the step's folder gives the
/// measurements that chose it: 0.01, a normal map 0.003).
///
/// The three indirect-lit bench scenes chose 0.03 from one 30-s run each (it ended 2.5-7%
/// lower than 0.01). On the scene family's train split (`ci/family_study.sh`, members 0-23,
/// one seed, each at its own budget on lavapipe; docs/studies.md, "The variance step's rate
/// with indirect light") 0.01 ended lower on six of eight base color tasks (0.71-0.94x) and
/// 0.03 on the other two, the two shortest runs (116 and 143 iterations; 0.01 at 1.05x and
/// 1.21x), and on both metallic tasks (0.01 at 1.08x and 1.26x). A rule of 0.01 for base
/// color, fitted there, failed on the test split: on `1004` (a sphere under a sun, paths of
/// 3 vertices, 49 iterations in its budget) it ended at 2.9x the error of 0.03, and tied on
/// `1010` (80 iterations). On the family the rate that won followed the run's length, which a
/// time budget leaves unknown until the run has timed its iterations. A rule that read it
/// (0.01 for base color and roughness in runs of 160 iterations or more) held on the test
/// split's directly lit tasks and lost 2-9% on the bundled bounce-lit scenes (`room`,
/// `gallery`), so 0.03 stays (docs/studies.md, "The variance step's rate with indirect
/// light").
pub fn learning_rate_for(step: StepKind, slot: Slot, regime: &Regime) -> f32 {
    if step == StepKind::VARIANCE && regime.max_depth > 1 && slot != Slot::Normal {
        0.03
    } else {
        step.learning_rate(slot)
    }
}

/// The moment filter where a task sets none, for `step` over textures of `slots`: with the
/// variance-scaled step over base color textures only, [`SUGGESTED_LEVELS`] levels of 3 x 3
/// taps with the filter's other defaults; otherwise off. With Adam the filter, untuned, ended
/// at 0.98-1.13x the plain baseline's texture error on the bench scenes. Over roughness or
/// metallic it blurred: with the variance step, `vase` (roughness) ended above its start
/// (0.318 from 0.238, against 0.213 unfiltered) and `dish` (metallic) at 0.461 against 0.340:
/// a scalar's differences rarely exceed the edge-stopping scale, which is in texture units.
///
/// With a normal map and base color the filter is on with either step, and over a normal map
/// alone with Adam: a normal-map texel has two unknowns that its few pixels constrain weakly,
/// and Adam's normalized steps turn that noise into speckle. On the `wall` scene (base color
/// and normal map from flat, 60 s on lavapipe) Adam ended at a mean angle error of 11.1
/// degrees unfiltered and 6.5 filtered (from 16.0), the base color at 0.0647 and 0.0577
/// observed-texel RMSE; on the scene family's one train task where `auto` takes Adam for a
/// normal map (`10`), 9.1 degrees unfiltered and 7.8 filtered.
///
/// Over a normal map alone the variance-scaled step goes unfiltered. Its filtered variance
/// is that of a mean over many texels, which at a flat start all look alike to the
/// edge-stopping guide, so it steps boldly along the mean of gradients whose signs differ
/// across a bump and whose tangent frames turn over a curved surface: a smooth tilt the
/// images barely see (the family's sphere `19`: 15.4 -> 22.4 degrees filtered, 14.8
/// unfiltered). Fitted on the family's train split (its seven normal-map tasks with this
/// step, one seed: unfiltered ended at 0.88x the filtered angle error, geometric mean, lower
/// on six) and judged on test tasks 1014-1039 (docs/studies.md, "Normal maps on the family").
pub fn moment_filter(step: StepKind, slots: &[Slot]) -> MomentFilterOptions {
    let only = |allowed: &[Slot]| !slots.is_empty() && slots.iter().all(|s| allowed.contains(s));
    let normal_alone = only(&[Slot::Normal]);
    let on = (step == StepKind::VARIANCE && only(&[Slot::BaseColor]))
        || (slots.contains(&Slot::Normal)
            && only(&[Slot::BaseColor, Slot::Normal])
            && !(step == StepKind::VARIANCE && normal_alone));
    MomentFilterOptions {
        levels: if on { SUGGESTED_LEVELS } else { 0 },
        ..Default::default()
    }
}

/// The weight of the smoothness prior where a task sets none, for a task in `regime`: 0.03
/// where the gradient pass draws fewer than [`DENSE_SAMPLES_PER_TEXEL`] samples per texel and
/// iteration, 0.01 from there (the values the bench tasks and the default task chose by scans
/// of 0 / 0.003 / 0.01 / 0.03 / 0.1). With sparse samples the images leave texels free that
/// only a prior ties to their neighbours: `lattice` with the rest of `auto`'s configuration
/// ended at 0.118 observed-texel RMSE without it and 0.069 with 0.03 (twice the rate without
/// it: 0.118 again).
pub fn smoothness(regime: &Regime) -> f32 {
    if regime.samples_per_texel() < DENSE_SAMPLES_PER_TEXEL {
        0.03
    } else {
        0.01
    }
}

/// The schedule where a task sets none: a cosine decay to [`FINAL_FACTOR`].
pub fn schedule() -> Schedule {
    Schedule {
        kind: ScheduleKind::Cosine,
        final_factor: FINAL_FACTOR,
        ..Schedule::constant()
    }
}

/// The whole configuration `auto` chose, with the reason of each choice.
#[derive(Clone, Debug)]
pub struct Configuration {
    /// The regime it was chosen for.
    pub regime: Regime,
    /// The estimator, and why.
    pub estimator: Choice,
    /// The step.
    pub step: StepKind,
    /// The moment filter.
    pub moment_filter: MomentFilterOptions,
    /// The schedule.
    pub schedule: Schedule,
    /// The weight of the smoothness prior.
    pub smoothness: f32,
    /// What `auto` chose and why, one line per choice (empty: nothing was left to it).
    pub reasons: Vec<String>,
}

impl Configuration {
    /// The configuration of a task in `regime` that asks for `method` and sets `step`,
    /// `moment_filter`, `schedule` and `smoothness` where they are Some, over `textures`: each one's slot
    /// and whether it names its learning rate.
    pub fn choose(
        regime: &Regime,
        method: MethodChoice,
        step: Option<StepKind>,
        moment_filter: Option<MomentFilterOptions>,
        schedule: Option<Schedule>,
        smoothness: Option<f32>,
        textures: &[(Slot, bool)],
    ) -> Configuration {
        let slots: Vec<Slot> = textures.iter().map(|t| t.0).collect();
        let estimator = method.resolve(regime);
        let mut reasons = Vec::new();
        if estimator.automatic {
            let why = estimator.reason.trim_start_matches("auto: ");
            reasons.push(format!("estimator {}: {why}", estimator.method.name()));
        }
        let step = step.unwrap_or_else(|| {
            let s = self::step(regime);
            reasons.push(step_reason(regime, s));
            s
        });
        let moment_filter = moment_filter.unwrap_or_else(|| {
            let f = self::moment_filter(step, &slots);
            if f.enabled() {
                reasons.push(format!(
                    "filtered moments, {} levels of {}x{} taps: the step's estimate and \
                     variance averaged over texels that look alike",
                    f.levels, f.taps, f.taps
                ));
            } else if step == StepKind::VARIANCE && slots.iter().all(|s| *s == Slot::Normal) {
                reasons.push(
                    "no moment filter: over a normal map alone the variance step, filtered, \
                     tilts whole regions (its averaged gradients' signs differ across a bump)"
                        .into(),
                );
            } else if step == StepKind::VARIANCE || slots.contains(&Slot::Normal) {
                reasons.push(
                    "no moment filter: it blurs roughness and metallic textures, whose \
                     differences rarely exceed its edge-stopping scale"
                        .into(),
                );
            }
            f
        });
        let schedule = schedule.unwrap_or_else(|| {
            reasons.push(format!(
                "learning rates decay as a cosine to {FINAL_FACTOR} of themselves over the run"
            ));
            self::schedule()
        });
        let smoothness = smoothness.unwrap_or_else(|| {
            let w = self::smoothness(regime);
            reasons.push(format!(
                "smoothness prior {w} ({:.2} gradient samples per texel and iteration; 0.03 \
                 below {DENSE_SAMPLES_PER_TEXEL}, where the images leave texels free that only \
                 a prior ties to their neighbours; `smoothness = 0` turns it off)",
                regime.samples_per_texel()
            ));
            w
        });
        let mut unset: Vec<Slot> = textures.iter().filter(|t| !t.1).map(|t| t.0).collect();
        unset.dedup();
        for slot in unset {
            reasons.push(format!(
                "learning rate {} for {} textures that name none (the {} step's)",
                learning_rate_for(step, slot, regime),
                slot.name(),
                step.name()
            ));
        }
        Configuration {
            regime: *regime,
            estimator,
            step,
            moment_filter,
            schedule,
            smoothness,
            reasons,
        }
    }

    /// The learning rate of a texture of `slot` that names none.
    pub fn rate(&self, slot: Slot) -> f32 {
        learning_rate_for(self.step, slot, &self.regime)
    }

    /// Put the estimator, step, moment filter and schedule into `settings` (the library's
    /// way to the task files' defaults: [`Settings::new`](crate::optim::Settings::new) keeps the
    /// plain ones, Adam without a filter or schedule; textures whose learning rate is None
    /// take the step's, [`StepKind::learning_rate`]).
    pub fn apply(&self, settings: &mut crate::optim::Settings) {
        settings.method = self.estimator.method;
        settings.step = self.step;
        settings.moment_filter = self.moment_filter;
        settings.schedule = self.schedule.clone();
        let mut smoothness = settings
            .priors
            .of::<crate::optim::smoothness::SmoothnessOptions>();
        smoothness.weight = self.smoothness;
        settings.priors.put(&smoothness);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::Method;

    fn regime(gradient_spp: u32, pixels: u64, texels: u64, max_depth: u32) -> Regime {
        Regime {
            primal_spp: 2,
            gradient_spp,
            pixels,
            texels,
            max_depth,
            recovers_light: false,
            normal_maps: false,
        }
    }

    /// `auto`'s whole configuration for a base color texture of a task in `r` that sets
    /// nothing.
    fn unset(r: &Regime) -> Configuration {
        let base_color = &[(Slot::BaseColor, false)];
        Configuration::choose(r, MethodChoice::Auto, None, None, None, None, base_color)
    }

    #[test]
    fn an_unset_task_gets_the_variance_step_filtered_and_a_cosine_decay() {
        // The indirect-lit bench scene's regime: two 128² views, a 256² texture, depth 3.
        let r = regime(1, 2 * 128 * 128, 256 * 256, 3);
        let c = unset(&r);
        assert_eq!(c.estimator.method, Method::BASELINE);
        assert_eq!(c.step, StepKind::VARIANCE);
        assert_eq!(c.moment_filter.levels, SUGGESTED_LEVELS);
        assert_eq!(c.schedule.kind, ScheduleKind::Cosine);
        assert_eq!(c.schedule.final_factor, FINAL_FACTOR);
        // Sparse sampling (0.5 per texel): the stronger smoothness prior.
        assert_eq!(c.smoothness, 0.03);
        // One reason per choice: estimator, step, filter, schedule, prior, learning rate.
        assert_eq!(c.reasons.len(), 6, "{:?}", c.reasons);
        assert!(
            c.reasons[1].contains("0.50 gradient samples"),
            "{:?}",
            c.reasons
        );
        assert!(c.reasons[5].contains("base_color"), "{:?}", c.reasons);
        // Dense sampling (the default task's 2 per texel): the weaker one.
        let dense = regime(2, 2 * 128 * 128, 256 * 128, 1);
        assert_eq!(smoothness(&dense), 0.01);
    }

    #[test]
    fn every_key_a_task_sets_wins() {
        let r = regime(1, 128 * 128, 256 * 256, 1);
        let f = MomentFilterOptions {
            levels: 2,
            ..Default::default()
        };
        let c = Configuration::choose(
            &r,
            MethodChoice::Fixed(Method::RECURSIVE),
            Some(StepKind::ADAM),
            Some(f),
            Some(Schedule::constant()),
            Some(0.0),
            &[(Slot::BaseColor, true)],
        );
        assert_eq!(c.estimator.method, Method::RECURSIVE);
        assert_eq!(c.step, StepKind::ADAM);
        assert_eq!(c.moment_filter, f);
        assert_eq!(c.schedule, Schedule::constant());
        assert_eq!(c.smoothness, 0.0);
        assert!(c.reasons.is_empty(), "{:?}", c.reasons);
        // A step that is set decides the filter and the rates left unset.
        let c = Configuration::choose(
            &r,
            MethodChoice::Auto,
            Some(StepKind::ADAM),
            None,
            None,
            Some(0.1),
            &[(Slot::Roughness, false)],
        );
        assert!(!c.moment_filter.enabled());
        assert_eq!(c.step.learning_rate(Slot::Roughness), 0.02);
    }

    #[test]
    fn direct_light_with_sparse_samples_gets_adam_unfiltered() {
        // The direct-lit bench scenes' regime: one 128² view, a 256² texture, depth 1.
        let sparse = regime(1, 128 * 128, 256 * 256, 1);
        let c = unset(&sparse);
        assert_eq!(c.estimator.method, Method::RESTIR);
        assert_eq!(c.step, StepKind::ADAM);
        assert!(!c.moment_filter.enabled());
        assert!(c.reasons[1].starts_with("step adam"), "{:?}", c.reasons);
        assert_eq!(c.rate(Slot::BaseColor), 0.03);
        assert_eq!(c.rate(Slot::Roughness), 0.02);
        // Dense samples (the default task's 2 per texel) and indirect light keep the
        // variance-scaled step.
        assert_eq!(
            step(&regime(2, 2 * 128 * 128, 256 * 128, 1)),
            StepKind::VARIANCE
        );
        assert_eq!(
            step(&regime(1, 128 * 128, 256 * 256, 3)),
            StepKind::VARIANCE
        );
    }

    #[test]
    fn with_indirect_light_the_variance_step_takes_the_higher_rate_but_for_normal_maps() {
        let indirect = unset(&regime(1, 128 * 128, 256 * 256, 3));
        assert_eq!(indirect.step, StepKind::VARIANCE);
        for slot in [Slot::BaseColor, Slot::Roughness, Slot::Metallic] {
            assert_eq!(indirect.rate(slot), 0.03, "{slot:?}");
        }
        assert_eq!(indirect.rate(Slot::Normal), 0.003);
        // Direct light with dense samples: the variance step's own for every slot.
        let dense = unset(&regime(2, 2 * 128 * 128, 256 * 128, 1));
        assert_eq!(dense.step, StepKind::VARIANCE);
        assert_eq!(dense.rate(Slot::BaseColor), 0.01);
        assert_eq!(dense.rate(Slot::Metallic), 0.01);
    }

    #[test]
    fn the_filter_is_for_base_color_and_normal_maps() {
        // Indirect light: the variance-scaled step, which the filter goes with.
        let r = regime(1, 128 * 128, 256 * 256, 3);
        let with = |textures: &[(Slot, bool)]| {
            Configuration::choose(&r, MethodChoice::Auto, None, None, None, None, textures)
        };
        assert!(with(&[(Slot::BaseColor, true)]).moment_filter.enabled());
        for scalar in [Slot::Roughness, Slot::Metallic] {
            let c = with(&[(Slot::BaseColor, true), (scalar, true)]);
            assert_eq!(c.step, StepKind::VARIANCE);
            assert!(!c.moment_filter.enabled());
            assert!(
                c.reasons.iter().any(|r| r.contains("no moment filter")),
                "{:?}",
                c.reasons
            );
        }
        // Direct light, sparse samples: Adam, filtered where a normal map is optimized.
        let adam = |textures: &[(Slot, bool)]| {
            let r = Regime {
                normal_maps: true,
                ..regime(1, 128 * 128, 256 * 256, 1)
            };
            Configuration::choose(&r, MethodChoice::Auto, None, None, None, None, textures)
        };
        let c = adam(&[(Slot::BaseColor, true), (Slot::Normal, true)]);
        assert_eq!(c.step, StepKind::ADAM);
        assert!(c.moment_filter.enabled());
        assert!(adam(&[(Slot::Normal, true)]).moment_filter.enabled());
        let c = adam(&[(Slot::Normal, true), (Slot::Roughness, true)]);
        assert!(!c.moment_filter.enabled());
        assert!(!adam(&[(Slot::BaseColor, true)]).moment_filter.enabled());
        // The variance step over a normal map alone: unfiltered, and the log says why; with
        // base color, filtered.
        let c = with(&[(Slot::Normal, true)]);
        assert_eq!(c.step, StepKind::VARIANCE);
        assert!(!c.moment_filter.enabled());
        assert!(
            c.reasons
                .iter()
                .any(|r| r.contains("over a normal map alone")),
            "{:?}",
            c.reasons
        );
        assert!(with(&[(Slot::BaseColor, true), (Slot::Normal, true)])
            .moment_filter
            .enabled());
    }
}
