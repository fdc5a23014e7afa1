//! The benchmark's phases (see the module above): the primal estimators' error, and the
//! equal-time optimization with its cost; the gradient error is in `gradient.rs`.
use super::{contender::Contender, counters::Counted, options, progress::Progress, results, tune};
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::job::Problem;
use crate::optim::loss::image_relmse;
use crate::optim::observed::rmse_observed;
use crate::optim::run_loop::{run_observed, run_steps, Clock, Limits, PassSampler};
use crate::optim::{Method, Optimizer, PassTimes, Settings};
use crate::task::Task;
use crate::{Error, Result};
use options::{settings, BenchOptions};
use results::{AutoResult, CurvePoint, DefaultResult, FinalImages, OptimizationResult, RunResult};
use std::path::Path;
use std::time::Instant;

/// The primal estimators' image error and cost (issue: recursive control variates): per
/// seed, an optimizer with each primal mode runs `warmup` iterations, then one more estimate
/// with the textures held; its primal image is compared with a converged render of the same
/// textures.
pub(super) struct PrimalPhase {
    pub(super) relmse_independent: f64,
    pub(super) relmse_control_variate: f64,
    pub(super) ms_independent: Option<f64>,
    pub(super) ms_control_variate: Option<f64>,
}

impl PrimalPhase {
    /// Not measured (`--end-to-end-only`).
    pub(super) fn not_measured() -> PrimalPhase {
        PrimalPhase {
            relmse_independent: f64::NAN,
            relmse_control_variate: f64::NAN,
            ms_independent: None,
            ms_control_variate: None,
        }
    }
}

pub(super) fn primal_phase(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    progress: &Progress,
) -> Result<PrimalPhase> {
    use crate::optim::PrimalMode;
    let repeats = o.repeats.max(1);
    let mut out = PrimalPhase {
        relmse_independent: 0.0,
        relmse_control_variate: 0.0,
        ms_independent: None,
        ms_control_variate: None,
    };
    let n = (repeats as usize * prep.targets.len()) as f64;
    for rep in 0..repeats {
        progress.message(format!("primal error, seed {}/{repeats}", rep + 1));
        let seed = task.seed.wrapping_add(2000 * (rep + 1));
        for mode in [PrimalMode::Independent, PrimalMode::ControlVariate] {
            let mut opt = Optimizer::for_problem(
                gpu,
                prep,
                Settings {
                    seed,
                    primal: mode,
                    ..settings(prep, task, Method::BASELINE, o)
                },
            )?;
            // The second half of the warm-up is timed, every iteration sampled.
            let mut times = PassSampler::every(1);
            run_steps(&mut opt, o.warmup / 2, &mut [])?;
            run_steps(&mut opt, o.warmup - o.warmup / 2, &mut [&mut times])?;
            // One more estimate at fixed textures: its primal image is at `read_params`.
            opt.estimate_gradient(opt.iteration)?;
            let ms = times.mean().map(|t| t.primal_ms);
            for k in 0..prep.targets.len() {
                let converged = opt.render(
                    k,
                    o.reference_primal_spp,
                    crate::optim::pass_seed(
                        seed,
                        u32::MAX - 5,
                        k as u32,
                        crate::optim::Seeds::EVAL,
                    ),
                )?;
                let img = match opt.control_variate_image(k)? {
                    Some(img) => img,
                    None => opt.render(
                        k,
                        task.optimizer.primal_spp,
                        crate::optim::pass_seed(
                            seed,
                            u32::MAX - 6,
                            k as u32,
                            crate::optim::Seeds::PRIMAL,
                        ),
                    )?,
                };
                let e = image_relmse(&img, &converged) / n;
                match mode {
                    PrimalMode::Independent => out.relmse_independent += e,
                    PrimalMode::ControlVariate => out.relmse_control_variate += e,
                }
            }
            match mode {
                PrimalMode::Independent => out.ms_independent = ms,
                PrimalMode::ControlVariate => out.ms_control_variate = ms,
            }
        }
    }
    progress.done();
    Ok(out)
}

/// Mean milliseconds of `n` steps after `untimed` untimed ones.
pub(super) fn time_steps(opt: &mut Optimizer, untimed: u32, n: u32) -> Result<f64> {
    run_steps(opt, untimed, &mut [])?;
    let t0 = Instant::now();
    run_steps(opt, n, &mut [])?;
    Ok(1000.0 * t0.elapsed().as_secs_f64() / n.max(1) as f64)
}

/// The bench's image error of the current textures: the relMSE of the render's expectation
/// against the target, mean over the task's cameras (two independent halves of `spp`, free of
/// the render's own noise, which on the default task is most of a 64-spp render's relMSE);
/// the keeper ranks states by it too. With the render of the first camera (the same seeds
/// every time: differences are the textures', not the noise's). See [`crate::job::run::evaluate`].
pub(super) fn evaluate(
    opt: &Optimizer,
    prep: &Problem,
    task: &Task,
    spp: u32,
) -> Result<(f64, Image)> {
    let mut e = crate::job::run::evaluate(opt, &prep.targets, spp, task.seed)?;
    if e.images.is_empty() {
        return Err(Error::Invalid("the task has no camera".into()));
    }
    Ok((e.expected, e.images.swap_remove(0)))
}

/// One estimator's equal-time optimization (phase 2).
pub(super) struct OptimizationRun {
    pub(super) curve: Vec<CurvePoint>,
    pub(super) iterations: u32,
    pub(super) ms_per_iteration: f64,
    pub(super) passes: Option<PassTimes>,
    pub(super) counters_per_iteration: Vec<(String, f64)>,
    pub(super) state_bytes_per_texel: f64,
    pub(super) final_image: Image,
    pub(super) per_texture_observed: Vec<f64>,
    pub(super) relit: Relit,
    /// The errors of the state the run handed back where it was not its last (a run of the
    /// task keeps its lowest evaluation's, `optimizer.keep_best`), at that state's iteration.
    pub(super) kept: Option<CurvePoint>,
}

/// A run's relit error (mean over the task's `relight` environments) and, with the
/// environment recovered, its strongest emission's angle from the truth's.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Relit {
    pub(super) relmse: Option<f64>,
    pub(super) psnr: Option<f64>,
    pub(super) direction_error_deg: Option<f64>,
}

impl Relit {
    fn measure(gpu: &Gpu, task: &Task, prep: &Problem, opt: &Optimizer) -> Result<Relit> {
        let mut out = Relit::default();
        let Some(truth) = prep.truth.as_ref() else {
            return Ok(out);
        };
        if let (Some(env), Some(t)) = (opt.fit().environment(), truth.env.as_ref()) {
            out.direction_error_deg = Some(crate::job::relight::direction_error_deg(&env, t));
        }
        let values = opt.read_params()?;
        let errors =
            crate::job::relight::task_errors(gpu, task, prep, values, 64, task.seed ^ 0x5e11)?;
        if errors.is_empty() {
            return Ok(out);
        }
        let n = errors.len() as f64;
        out.relmse = Some(errors.iter().map(|e| e.relmse).sum::<f64>() / n);
        out.psnr = Some(errors.iter().map(|e| e.psnr).sum::<f64>() / n);
        Ok(out)
    }
}

/// The optimizer of one run of the equal-time phase: the contender's settings on the task,
/// with its search's best where it was tuned.
fn contender_optimizer(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    who: Contender,
    tuned: Option<&tune::Tunable>,
) -> Result<Optimizer> {
    let mut s = who.settings(task, |t, m| settings(prep, t, m, o));
    if let Some(t) = tuned {
        t.apply(&mut s);
    }
    let mut opt = Optimizer::for_problem(gpu, prep, s)?;
    if let Some(t) = tuned {
        t.apply_learning_rate(&mut opt, prep);
    }
    if who.auto {
        // The rates `auto` gives textures that name none, as a run of the bare task gets
        // them (`Problem::load`). None here would be the step's own rate, which is not
        // `auto`'s where the rule differs from it (the variance step with indirect light).
        let config = auto_configuration(task, prep);
        for t in &mut opt.set.textures {
            t.learning_rate = Some(config.rate(t.slot));
        }
    }
    Ok(opt)
}

/// What `auto` chooses for the bare task (what a task file naming only its scene, cameras,
/// targets, textures and sampling gets, [`super::contender::bare`]) seen by `prep`'s cameras.
fn auto_configuration(task: &Task, prep: &Problem) -> crate::auto::Configuration {
    crate::task::task_configuration(
        &super::contender::bare(task),
        crate::optim::MethodChoice::Auto,
        prep.cameras.len(),
    )
}

pub(super) fn optimization_phase(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    who: Contender,
    tuned: Option<&tune::Tunable>,
    start: &Start,
    progress: &Progress,
) -> Result<OptimizationRun> {
    let mut opt = contender_optimizer(gpu, task, prep, o, who, tuned)?;
    let truth = prep.reference.as_deref();
    let observed = opt.observed_texels()?.to_vec();
    // A run of the task hands back its lowest evaluation's state, the start's included.
    let mut keeper = crate::job::keep::Keeper::new(task.optimizer.keep_best, None);
    keeper.offer(&opt, Some(start.image))?;
    let mut watch = BenchWatch {
        prep,
        task,
        o,
        observed: &observed,
        progress,
        name: who.name(),
        points: o.curve_points.max(2),
        next_eval: 1,
        curve: Vec::new(),
        counted: Counted::default(),
        last_image: None,
        last_expected: None,
        keeper,
    };
    let mut sampler = PassSampler::default();
    // Only the iterations count: every evaluation, curve point and sample is set aside.
    let mut clock = Clock::start(0.0);
    let limits = Limits {
        first: 0,
        iterations: None,
        seconds: Some(o.budget_s),
    };
    run_observed(
        &mut opt,
        limits,
        &mut clock,
        &mut [&mut sampler, &mut watch],
    )?;
    let seconds = clock.seconds();
    let BenchWatch {
        curve,
        counted,
        last_image,
        last_expected,
        keeper,
        ..
    } = watch;
    // The loop ends with an evaluation at the end of the budget. The errors below are those
    // of the state the run hands back.
    let mut kept = None;
    let final_image = match (keeper.hand_back(&mut opt, last_expected)?, last_image) {
        (Some(h), _) => {
            let (e, img) = evaluate(&opt, prep, task, o.eval_spp)?;
            let p = curve_point(&opt, prep, &observed, f64::NAN, seconds)?;
            let (iteration, image_relmse) = (h.iteration, Some(e));
            kept = Some(CurvePoint {
                iteration,
                image_relmse,
                ..p
            });
            img
        }
        (None, Some(img)) => img,
        (None, None) => evaluate(&opt, prep, task, o.eval_spp)?.1,
    };
    let passes = sampler.mean();
    let iterations = opt.iteration;
    let per_texture_observed = match truth {
        Some(r) => crate::optim::observed::rmse_observed_per_texture(
            &prep.set,
            &opt.read_params()?,
            r,
            &observed,
        ),
        None => vec![f64::NAN; prep.set.textures.len()],
    };
    let relit = Relit::measure(gpu, task, prep, &opt)?;
    progress.done();
    Ok(OptimizationRun {
        relit,
        ms_per_iteration: 1000.0 * seconds / iterations.max(1) as f64,
        iterations,
        passes,
        counters_per_iteration: counted.per_iteration(),
        state_bytes_per_texel: opt.state_bytes_per_texel(),
        curve,
        final_image,
        per_texture_observed,
        kept,
    })
}

/// The bench's observer of a contender's run: evaluations at evenly spaced times and at the
/// end of the budget, a point of the error curve per iteration, and the estimator's counters
/// on the iterations the passes are sampled on; all of it set aside on the clock.
struct BenchWatch<'a> {
    prep: &'a Problem,
    task: &'a Task,
    o: &'a BenchOptions,
    observed: &'a [bool],
    progress: &'a Progress,
    name: String,
    points: u32,
    next_eval: u32,
    curve: Vec<CurvePoint>,
    counted: Counted,
    last_image: Option<Image>,
    /// The last evaluation's relMSE of the render's expectation.
    last_expected: Option<f64>,
    /// The state with the lowest evaluation error so far.
    keeper: crate::job::keep::Keeper,
}

impl crate::optim::run_loop::Observer for BenchWatch<'_> {
    fn before(
        &mut self,
        opt: &mut Optimizer,
        clock: &mut crate::optim::run_loop::Clock,
        last: bool,
    ) -> Result<std::ops::ControlFlow<()>> {
        let (o, seconds) = (self.o, clock.seconds());
        let due = seconds >= o.budget_s * self.next_eval as f64 / (self.points - 1) as f64;
        if last || due {
            let (e, img) = clock.aside(|| evaluate(opt, self.prep, self.task, o.eval_spp))?;
            clock.aside(|| self.keeper.offer(opt, Some(e)))?;
            self.last_image = Some(img);
            self.last_expected = Some(e);
            if let Some(p) = self.curve.last_mut() {
                p.image_relmse = Some(e);
            }
            self.next_eval += 1;
            self.progress.message(format!(
                "{}: {seconds:.0}/{:.0} s, image relMSE {e:.3e}",
                self.name, o.budget_s
            ));
        }
        Ok(std::ops::ControlFlow::Continue(()))
    }

    fn after(
        &mut self,
        opt: &mut Optimizer,
        stats: &crate::optim::StepStats,
        _: f64,
        clock: &mut crate::optim::run_loop::Clock,
    ) -> Result<std::ops::ControlFlow<()>> {
        let seconds = clock.seconds();
        let point = clock.aside(|| -> Result<CurvePoint> {
            // (The passes' sampler runs first: its iterations are the counters' too.)
            if opt.iteration % 8 == 1 {
                self.counted.sample(opt)?;
            }
            curve_point(opt, self.prep, self.observed, stats.loss, seconds)
        })?;
        self.curve.push(point);
        Ok(std::ops::ControlFlow::Continue(()))
    }
}

/// The point of the error curve after an iteration that took the run to `seconds`.
fn curve_point(
    opt: &Optimizer,
    prep: &Problem,
    observed: &[bool],
    loss: f64,
    seconds: f64,
) -> Result<CurvePoint> {
    let values = opt.read_params()?;
    let truth = prep.reference.as_deref();
    let factor = match (opt.last_learning_rates().first(), prep.set.textures.first()) {
        (Some(&l), Some(t)) => {
            let rate = opt.settings().step.texture_rate(t);
            (rate > 0.0).then(|| l as f64 / rate as f64)
        }
        _ => None,
    };
    Ok(CurvePoint {
        iteration: opt.iteration,
        seconds,
        loss,
        texture_rmse: prep.texture_rmse(&values).unwrap_or(f64::NAN),
        texture_rmse_observed: truth
            .map(|r| rmse_observed(&prep.set, &values, r, observed))
            .unwrap_or(f64::NAN),
        learning_rate_factor: factor,
        image_relmse: None,
    })
}

/// The errors every run starts from: the initial textures' image error ([`evaluate`]),
/// texture RMSE over all and over the observed texels, and which texels are observed.
pub(super) struct Start {
    image: f64,
    texture: f64,
    texture_observed: f64,
    observed: Vec<bool>,
}

impl Start {
    fn measure(gpu: &Gpu, task: &Task, prep: &Problem, o: &BenchOptions) -> Result<Start> {
        let init = Optimizer::for_problem(gpu, prep, settings(prep, task, Method::BASELINE, o))?;
        let (image, _) = evaluate(&init, prep, task, o.eval_spp)?;
        let truth = prep.reference.as_deref();
        let observed = init.observed_texels()?.to_vec();
        Ok(Start {
            image,
            texture: prep.texture_rmse(&prep.set.values).unwrap_or(f64::NAN),
            texture_observed: truth
                .map(|r| rmse_observed(&prep.set, &prep.set.values, r, &observed))
                .unwrap_or(f64::NAN),
            observed,
        })
    }

    /// The curve's first point.
    fn point(&self) -> CurvePoint {
        CurvePoint {
            iteration: 0,
            seconds: 0.0,
            loss: f64::NAN,
            texture_rmse: self.texture,
            texture_rmse_observed: self.texture_observed,
            learning_rate_factor: None,
            image_relmse: Some(self.image),
        }
    }

    /// A run's result: its last errors (the start's where it measured none), their ratios
    /// over the baseline's (`first`), the observed-texel RMSE at a third of the budget (the
    /// last point before it) and its lowest, and its curve from the start.
    fn result(
        &self,
        o: &BenchOptions,
        who: Contender,
        run: OptimizationRun,
        first: Option<&RunResult>,
        settings: String,
        tuned: Option<tune::Tuned>,
    ) -> RunResult {
        let (t_last, to_last) = run
            .curve
            .last()
            .map(|p| (p.texture_rmse, p.texture_rmse_observed))
            .unwrap_or((self.texture, self.texture_observed));
        let i_last = run
            .curve
            .iter()
            .rev()
            .find_map(|p| p.image_relmse)
            .unwrap_or(self.image);
        let (t, to, i) = match &run.kept {
            Some(k) => (
                k.texture_rmse,
                k.texture_rmse_observed,
                k.image_relmse.unwrap_or(f64::NAN),
            ),
            None => (t_last, to_last, i_last),
        };
        let (ib, tob) = first.map_or((i, to), |b| (b.image_relmse, b.texture_rmse_observed));
        let third = run
            .curve
            .iter()
            .take_while(|p| p.seconds <= o.budget_s / 3.0)
            .last()
            .map(|p| p.texture_rmse_observed)
            .unwrap_or(self.texture_observed);
        let min = run
            .curve
            .iter()
            .map(|p| p.texture_rmse_observed)
            .fold(self.texture_observed, f64::min);
        let mut curve = vec![self.point()];
        curve.extend_from_slice(&run.curve);
        let relit_ratio = match (run.relit.relmse, first.and_then(|b| b.relit_relmse)) {
            (Some(a), Some(b)) => Some(a / b),
            (Some(_), None) => Some(1.0),
            _ => None,
        };
        RunResult {
            relit_relmse: run.relit.relmse,
            relit_relmse_ratio: relit_ratio,
            relit_psnr: run.relit.psnr,
            light_direction_error_deg: run.relit.direction_error_deg,
            name: who.name(),
            key: who.key(),
            method: who.method.name().to_string(),
            image_relmse: i,
            image_relmse_ratio: i / ib,
            texture_rmse: t,
            texture_rmse_observed: to,
            texture_rmse_observed_ratio: to / tob,
            texture_rmse_observed_third: third,
            texture_rmse_observed_min: min,
            texture_rmse_observed_per_texture: run.per_texture_observed,
            kept_iteration: run.kept.as_ref().map(|k| k.iteration),
            last_state_errors: run.kept.is_some().then_some([to_last, i_last]),
            ms_per_iteration: run.ms_per_iteration,
            iterations: run.iterations,
            passes: run.passes,
            diagnostics_per_iteration: run.counters_per_iteration,
            state_bytes_per_texel: run.state_bytes_per_texel,
            settings,
            tuned,
            curve,
        }
    }
}

/// How a run's settings read in the report: its tuned (or untuned) settings, and for the
/// default configuration the rates and schedule `auto` gave.
fn describe_run(
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    who: Contender,
    t: Option<&tune::Tunable>,
) -> String {
    let s = who.settings(task, |t, m| settings(prep, t, m, o));
    let d = t
        .cloned()
        .unwrap_or_else(|| tune::Tunable::untuned(&s))
        .describe(who.method);
    if !who.auto {
        return d;
    }
    // The rates and schedule `auto` gave, which the scale above multiplies.
    let config = auto_configuration(task, prep);
    let rates: Vec<String> = prep
        .set
        .textures
        .iter()
        .map(|t| format!("{}", config.rate(t.slot)))
        .collect();
    format!(
        "{d}; auto's rates {}, {}, smoothness {}",
        rates.join(" / "),
        s.schedule.describe(),
        s.priors
            .of::<crate::optim::smoothness::SmoothnessOptions>()
            .weight
    )
}

/// The equal-time optimization of every run (phase 2: the baseline with Adam, then the
/// contenders) and their cost (phase 3). `tuned` holds each run's search, in that order.
pub(super) fn optimization_phases(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    (dir, tune_dir): (&Path, &Path),
    mut tuned: Vec<Option<tune::Tuned>>,
    progress: &Progress,
) -> Result<(OptimizationResult, FinalImages)> {
    let start = Start::measure(gpu, task, prep, o)?;
    let runs_of = std::iter::once(Contender::BASELINE)
        .chain(o.contenders.iter().copied())
        .map(|c| c.on(task, prep.cameras.len()));
    tuned.resize(1 + o.contenders.len(), None);
    let mut runs: Vec<RunResult> = Vec::new();
    let mut finals = FinalImages {
        target: prep.targets[0].clone(),
        runs: Vec::new(),
    };
    for (who, tuned) in runs_of.zip(tuned) {
        let t_best = tuned.as_ref().map(|t| &t.best);
        let mut run = optimization_phase(gpu, task, prep, o, who, t_best, &start, progress)?;
        let empty = Image {
            width: 0,
            height: 0,
            rgb: Vec::new(),
        };
        let image = std::mem::replace(&mut run.final_image, empty);
        let described = describe_run(task, prep, o, who, t_best);
        let result = start.result(o, who, run, runs.first(), described, tuned.clone());
        runs.push(result);
        finals.runs.push((who.name(), image));
    }
    let peer_forward =
        super::peer::race((dir, tune_dir), task, prep, o, &start.observed, &mut runs);
    let observed = &start.observed;
    let result = OptimizationResult {
        image_relmse_initial: start.image,
        texture_rmse_initial: start.texture,
        texture_rmse_observed_initial: start.texture_observed,
        observed_fraction: observed.iter().filter(|&&b| b).count() as f64
            / observed.len().max(1) as f64,
        observed_texels: observed.iter().filter(|&&b| b).count() as u64,
        schedule: settings(prep, task, Method::BASELINE, o)
            .schedule
            .describe(),
        textures: prep.set.textures.iter().map(|t| t.name()).collect(),
        texture_rmse_observed_initial_per_texture: match prep.reference.as_deref() {
            Some(r) => crate::optim::observed::rmse_observed_per_texture(
                &prep.set,
                &prep.set.values,
                r,
                observed,
            ),
            None => vec![f64::NAN; prep.set.textures.len()],
        },
        auto: auto_result(task, prep.cameras.len(), &runs, start.texture_observed),
        runs,
        peer_forward,
    };
    Ok((result, finals))
}

/// What `auto` picks for `task` and how the run of its pick (with Adam, unfiltered) compares
/// with the lower of the baseline's and ReSTIR's, when both are among `runs`.
fn auto_result(task: &Task, cameras: usize, runs: &[RunResult], start: f64) -> AutoResult {
    let regime = crate::task::task_regime(task, cameras);
    let choice = crate::optim::MethodChoice::Auto.resolve(&regime);
    let run = |m: Method| runs.iter().find(|r| r.key == Contender::adam(m).key());
    let over_best = |f: fn(&RunResult) -> f64| {
        let picked = f(run(choice.method)?);
        let best = [Method::BASELINE, Method::RESTIR]
            .into_iter()
            .map(|m| run(m).map(f))
            .collect::<Option<Vec<f64>>>()?
            .into_iter()
            .fold(f64::INFINITY, f64::min);
        Some(picked / best)
    };
    AutoResult {
        method: choice.method.name().into(),
        reason: choice.reason,
        samples_per_texel: regime.samples_per_texel(),
        texels: regime.texels,
        texture_rmse_observed_over_best: over_best(|r| r.texture_rmse_observed),
        image_relmse_over_best: over_best(|r| r.image_relmse),
        default_run: default_result(runs, start),
    }
}

/// The default configuration's run (the contender `default`) against the start and, in
/// observed-texel RMSE and in image relMSE, the lowest of the other runs; None unless it ran.
fn default_result(runs: &[RunResult], start: f64) -> Option<DefaultResult> {
    let d = runs.iter().find(|r| r.key == Contender::AUTO.key())?;
    let lowest = |f: fn(&RunResult) -> f64| {
        runs.iter()
            .filter(|r| r.key != d.key && r.method != super::peer::MITSUBA)
            .min_by(|a, b| f(a).total_cmp(&f(b)))
    };
    let best = lowest(|r| r.texture_rmse_observed)?;
    let best_image = lowest(|r| r.image_relmse)?;
    Some(DefaultResult {
        name: d.name.clone(),
        texture_rmse_observed: d.texture_rmse_observed,
        over_start: d.texture_rmse_observed / start,
        best: best.name.clone(),
        over_best: d.texture_rmse_observed / best.texture_rmse_observed,
        best_image: best_image.name.clone(),
        image_over_best: d.image_relmse / best_image.image_relmse,
    })
}
