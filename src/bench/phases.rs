//! The benchmark's phases (see the module above): the primal estimators' error, the gradient
//! error, and the equal-time optimization with its cost.
use super::*;

pub(super) fn settings(prep: &Problem, task: &Task, method: Method, o: &BenchOptions) -> Settings {
    let mut s = task_settings(task, &prep.cameras, method, o.restir);
    if let Some(p) = o.primal {
        s.primal = p;
    }
    s
}

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
                    ..settings(prep, task, Method::Baseline, o)
                },
            )?;
            let mut times = PassTimes::default();
            let mut timed = 0;
            for i in 0..o.warmup {
                opt.step()?;
                if i >= o.warmup / 2 {
                    if let Some(t) = opt.pass_times()? {
                        times.add(&t);
                        timed += 1;
                    }
                }
            }
            // One more estimate at fixed textures: its primal image is at `read_params`.
            opt.estimate_gradient(opt.iteration)?;
            let ms = (timed > 0).then(|| times.primal_ms / timed as f64);
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

/// The mean of `spp` gradient samples per pixel under `adjoint`, at `r`'s textures (`r` is a
/// baseline optimizer of at most 64 spp).
fn reference_gradient(r: &mut Optimizer, spp: u32, adjoint: &[f32]) -> Result<Vec<f64>> {
    let estimates = spp.div_ceil(r.settings().gradient_spp).max(1);
    let mut reference = vec![0f64; r.read_params()?.len()];
    for it in 0..estimates {
        let g = r.estimate_gradient_with_adjoint(it, adjoint)?;
        for (acc, v) in reference.iter_mut().zip(&g) {
            *acc += *v as f64 / estimates as f64;
        }
    }
    Ok(reference)
}

/// Mean milliseconds of `n` steps after `untimed` untimed ones.
pub(super) fn time_steps(opt: &mut Optimizer, untimed: u32, n: u32) -> Result<f64> {
    for _ in 0..untimed {
        opt.step()?;
    }
    let t0 = Instant::now();
    for _ in 0..n {
        opt.step()?;
    }
    Ok(1000.0 * t0.elapsed().as_secs_f64() / n.max(1) as f64)
}

/// Gradient error (phase 1): the scene's gradient fields and the gradients of the first seed
/// for the images.
pub(super) struct GradientPhase {
    pub(super) baseline_spp_equal_time: f64,
    pub(super) total_baseline: f64,
    pub(super) total_restir: f64,
    pub(super) total_baseline_equal_iterations: f64,
    pub(super) only_baseline: f64,
    pub(super) only_restir: f64,
    pub(super) only_baseline_equal_time: f64,
    pub(super) mean_baseline: f64,
    pub(super) mean_restir: f64,
    pub(super) ms_ratio: f64,
    pub(super) snapshot: GradientSnapshot,
    /// Per optimized texture, its parts of the equal-iteration errors (they add up to the
    /// figures above).
    pub(super) per_texture: Vec<TextureParts>,
}

/// One texture's parts of the gradient errors at equal iterations (mean over seeds; see
/// [`gradient_relmse_parts`]).
#[derive(Clone, Copy, Default)]
pub(super) struct TextureParts {
    pub(super) total_baseline_equal_iterations: f64,
    pub(super) total_restir: f64,
    pub(super) only_baseline: f64,
    pub(super) only_restir: f64,
}

fn add_to(sum: &mut [f64], g: &[f32]) {
    for (s, &v) in sum.iter_mut().zip(g) {
        *s += v as f64;
    }
}

/// The baseline's error at `k` spp (fractional) from its errors at whole spp `s0` and
/// `s0 + 1` around it, linear in 1/spp (Monte Carlo variance falls as 1/spp).
pub(super) fn interpolate_in_inverse_spp(k: f64, s0: u32, e0: f64, e1: f64) -> f64 {
    let s0 = s0 as f64;
    if k <= s0 {
        return e0;
    }
    let a = (1.0 / s0 - 1.0 / k) / (1.0 / s0 - 1.0 / (s0 + 1.0));
    e0 + a * (e1 - e0)
}

pub(super) fn gradient_phase(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    progress: &Progress,
) -> Result<GradientPhase> {
    let spp = task.optimizer.gradient_spp.max(1);
    let new = |method: Method, gradient_spp: u32, seed: u32| -> Result<Optimizer> {
        Optimizer::for_problem(
            gpu,
            prep,
            Settings {
                gradient_spp,
                seed,
                ..settings(prep, task, method, o)
            },
        )
    };
    let repeats = o.repeats.max(1);
    let n = repeats as f64;
    let mut out = GradientPhase {
        baseline_spp_equal_time: spp as f64,
        total_baseline: 0.0,
        total_restir: 0.0,
        total_baseline_equal_iterations: 0.0,
        only_baseline: 0.0,
        only_restir: 0.0,
        only_baseline_equal_time: 0.0,
        mean_baseline: 0.0,
        mean_restir: 0.0,
        ms_ratio: f64::NAN,
        snapshot: GradientSnapshot {
            reference: Vec::new(),
            baseline: Vec::new(),
            restir: Vec::new(),
            baseline_spp: spp,
        },
        per_texture: vec![TextureParts::default(); prep.set.textures.len()],
    };
    // Where each optimized texture lies in a gradient.
    let ranges: Vec<_> = prep
        .set
        .textures
        .iter()
        .map(|t| t.offset as usize..t.offset as usize + t.len())
        .collect();
    // Adds g's error to `whole` and each texture's part of it to `field` of its parts, each
    // divided by the number of seeds.
    let add_errors = |g: &[f32],
                      reference: &[f64],
                      whole: &mut f64,
                      field: fn(&mut TextureParts) -> &mut f64,
                      parts: &mut [TextureParts]| {
        *whole += gradient_relmse(g, reference) / n;
        for (p, e) in parts
            .iter_mut()
            .zip(gradient_relmse_parts(g, reference, &ranges))
        {
            *field(p) += e / n;
        }
    };
    let mut eq_spp = None;
    for rep in 0..repeats {
        progress.message(format!("gradient error, seed {}/{repeats}", rep + 1));
        let seed = task.seed.wrapping_add(1000 * (rep + 1));
        // ReSTIR from the initial textures; the later warm-up steps time an iteration.
        let mut re = new(Method::Restir, spp, seed)?;
        let untimed = (o.warmup / 4).max(1).min(o.warmup);
        for _ in 0..untimed {
            re.step()?;
        }
        let t0 = Instant::now();
        for _ in untimed..o.warmup {
            re.step()?;
        }
        let timed = o.warmup - untimed;
        let ms_restir = if timed > 0 {
            Some(1000.0 * t0.elapsed().as_secs_f64() / timed as f64)
        } else {
            None
        };
        let state = re.read_params()?;
        let kept = re.state()?;

        // The baseline's cost per gradient spp, measured once: iterations at spp and 4 spp,
        // timed over the same iterations as ReSTIR's (the same number of untimed ones first,
        // then as many timed, at least 3). The equal-time spp rests on ReSTIR's overhead, a
        // difference of two iteration times that is small beside either (5-15 ms of 0.3-1 s
        // with the paper's 32-spp primal): timed over 3 iterations at 1 and 4 spp against
        // ReSTIR's 15, it moved by up to 0.6 spp between runs.
        let k = match eq_spp {
            Some(k) => k,
            None => {
                let (untimed, timed) = match ms_restir {
                    Some(_) => (untimed, timed),
                    None => (1, 3),
                };
                let timed = timed.max(3);
                let ms_restir = match ms_restir {
                    Some(ms) => ms,
                    None => {
                        let mut r = new(Method::Restir, spp, seed)?;
                        time_steps(&mut r, untimed, timed)?
                    }
                };
                // Three more gradient spp per pixel cost time: if they measure as free, the
                // timing was disturbed (another process on the device or the CPU), and the
                // equal-time spp would come out absurd (it is clamped at 1024, whose
                // estimates would then take hours). Timed up to three times, then an error.
                let mut tries = 0;
                let (t1, t4) = loop {
                    let mut b1 = new(Method::Baseline, spp, seed ^ 0x71)?;
                    let t1 = time_steps(&mut b1, untimed, timed)?;
                    drop(b1);
                    let mut b4 = new(Method::Baseline, 4 * spp, seed ^ 0x72)?;
                    let t4 = time_steps(&mut b4, untimed, timed)?;
                    drop(b4);
                    tries += 1;
                    if t4 > t1 {
                        break (t1, t4);
                    }
                    log::warn!(
                        "{}: the baseline timed {t4:.1} ms/it at {} spp and {t1:.1} at {spp}: \
                         timing again",
                        task.path.display(),
                        4 * spp
                    );
                    if tries == 3 {
                        return Err(Error::Invalid(format!(
                            "bench: {}: the baseline's iterations at {} gradient spp timed no \
                             slower than at {spp} ({t4:.1} against {t1:.1} ms) three times: \
                             something else is using the device or the CPU; run the bench \
                             alone",
                            task.path.display(),
                            4 * spp
                        )));
                    }
                };
                let per_spp = (t4 - t1) / (3 * spp) as f64;
                let k = (spp as f64 + (ms_restir - t1) / per_spp).clamp(1.0, 1024.0);
                log::info!(
                    "{}: ReSTIR {ms_restir:.1} ms/it, baseline {t1:.1} ms/it at {spp} spp \
                     (+{per_spp:.1} ms per spp): {k:.2} spp at equal time",
                    task.path.display()
                );
                out.ms_ratio = ms_restir / t1;
                eq_spp = Some(k);
                k
            }
        };
        let s0 = (k.floor() as u32).max(1);

        // The converged adjoint at the state, and the reference gradient under it.
        progress.message(format!(
            "gradient error, seed {}/{repeats}: reference",
            rep + 1
        ));
        let mut r = new(
            Method::Baseline,
            o.reference_spp.clamp(1, 64),
            seed ^ 0x5eed,
        )?;
        r.write_params(&state)?;
        let (converged, _) = r.converged_adjoint(o.reference_primal_spp, seed ^ 0xad)?;
        let reference = reference_gradient(&mut r, o.reference_spp, &converged)?;
        drop(r);

        // Total: ReSTIR's next gradient with its own primal render, and the baseline's at the
        // task's spp and around the equal-time spp under the adjoint of that same render
        // (common random numbers). Every figure is still an estimator under the adjoint of
        // one task-spp primal render, so each expected error is what a user gets; sharing
        // the render takes the primal's noise out of the comparison, which with one render
        // per estimate and seed dominated it (`sphere`, paper protocol, a render of its own
        // for each: the baseline's total error at 1 / 2 / 3 gradient spp was 17.2 / 1.3 /
        // about 7e-8, not falling with the spp, against 3.7e-8 estimator-only at 1 spp).
        // The baseline continues from ReSTIR's state without the reservoirs: the same
        // textures (and, with the control-variate primal, the same carried image and
        // statistics).
        let it = re.iteration;
        let (g_restir_total, _) = re.estimate_gradient(it)?;
        let adjoint_total = re.read_adjoint(it)?;
        re.restore(&kept)?;
        // A baseline at ReSTIR's state without the reservoirs.
        let baseline = |spp: u32, salt: u32| -> Result<Optimizer> {
            let mut b = new(Method::Baseline, spp, seed ^ salt)?;
            b.restore(&crate::optim::OptimizerState {
                restir: None,
                ..kept.clone()
            })?;
            Ok(b)
        };
        let baseline_at = |spp: u32, salt: u32, adjoint: &[f32]| -> Result<Vec<f32>> {
            baseline(spp, salt)?.estimate_gradient_with_adjoint(it + 1, adjoint)
        };
        let total = |spp, salt| -> Result<f64> {
            Ok(gradient_relmse(
                &baseline_at(spp, salt, &adjoint_total)?,
                &reference,
            ))
        };
        let parts = &mut out.per_texture;
        add_errors(
            &g_restir_total,
            &reference,
            &mut out.total_restir,
            |p| &mut p.total_restir,
            parts,
        );
        add_errors(
            &baseline_at(spp, 0xea, &adjoint_total)?,
            &reference,
            &mut out.total_baseline_equal_iterations,
            |p| &mut p.total_baseline_equal_iterations,
            parts,
        );
        out.total_baseline +=
            interpolate_in_inverse_spp(k, s0, total(s0, 0xe9)?, total(s0 + 1, 0xeb)?) / n;

        // Estimator-only: both under the converged adjoint. ReSTIR first draws `settle` more
        // estimates under it at the same textures, so that its reservoirs hold samples
        // chosen for the integrand it is measured on. Measured right after the warm-up, its
        // reservoirs were filled under the noisy adjoints of its own primal renders, and the
        // switch of adjoint, not the reuse, dominated the error. The textures stay where they
        // are: under one fixed adjoint, Adam pushes every texel the same way at every step
        // (on `vase`, 20 such steps made both estimators' errors 5-8x larger).
        for j in 0..o.settle {
            re.estimate_gradient_with_adjoint(it + j, &converged)?;
        }
        let g_restir_only = re.estimate_gradient_with_adjoint(it + o.settle, &converged)?;
        // An optimizer adds up successive estimates. ReSTIR's share samples (the kept ones),
        // so their errors are correlated and their mean gains less than a mean of
        // independent estimates would: the error of the mean of `successive` estimates, from
        // this one on, against the mean of as many independent baseline estimates.
        let successive = o.successive;
        let mut mean_restir = g_restir_only.iter().map(|&v| v as f64).collect::<Vec<_>>();
        for j in 1..successive {
            let g = re.estimate_gradient_with_adjoint(it + o.settle + j, &converged)?;
            add_to(&mut mean_restir, &g);
        }
        drop(re);
        let b_only = baseline_at(spp, 0xea, &converged)?;
        let mut mean_baseline = vec![0.0; b_only.len()];
        {
            let mut b = baseline(spp, 0xec)?;
            for j in 0..successive {
                let g = b.estimate_gradient_with_adjoint(it + 1 + j, &converged)?;
                add_to(&mut mean_baseline, &g);
            }
        }
        let mean = |sum: Vec<f64>| -> Vec<f32> {
            sum.iter()
                .map(|&v| (v / successive as f64) as f32)
                .collect()
        };
        out.mean_restir += gradient_relmse(&mean(mean_restir), &reference) / n;
        out.mean_baseline += gradient_relmse(&mean(mean_baseline), &reference) / n;
        let only = |spp, salt| -> Result<f64> {
            Ok(gradient_relmse(
                &baseline_at(spp, salt, &converged)?,
                &reference,
            ))
        };
        let parts = &mut out.per_texture;
        add_errors(
            &g_restir_only,
            &reference,
            &mut out.only_restir,
            |p| &mut p.only_restir,
            parts,
        );
        add_errors(
            &b_only,
            &reference,
            &mut out.only_baseline,
            |p| &mut p.only_baseline,
            parts,
        );
        out.only_baseline_equal_time +=
            interpolate_in_inverse_spp(k, s0, only(s0, 0xe9)?, only(s0 + 1, 0xeb)?) / n;
        out.baseline_spp_equal_time = k;
        if rep == 0 {
            out.snapshot = GradientSnapshot {
                reference: reference.iter().map(|&v| v as f32).collect(),
                baseline: b_only,
                restir: g_restir_only,
                baseline_spp: spp,
            };
        }
        progress.done();
    }
    Ok(out)
}

/// Image relMSE of the current textures, mean over the task's cameras, and the render of
/// the first camera (the same seed every time: differences are the textures', not the
/// noise's).
pub(super) fn evaluate(
    opt: &Optimizer,
    prep: &Problem,
    task: &Task,
    spp: u32,
) -> Result<(f64, Image)> {
    let (e, mut images) = crate::optim::run::evaluate(opt, &prep.targets, spp, task.seed)?;
    if images.is_empty() {
        return Err(Error::Invalid("the task has no camera".into()));
    }
    Ok((e, images.swap_remove(0)))
}

/// One estimator's equal-time optimization (phase 2).
pub(super) struct OptimizationRun {
    pub(super) curve: Vec<CurvePoint>,
    pub(super) iterations: u32,
    pub(super) ms_per_iteration: f64,
    pub(super) passes: Option<PassTimes>,
    pub(super) merge_evaluations: Option<f64>,
    pub(super) state_bytes_per_texel: f64,
    pub(super) final_image: Image,
}

pub(super) fn optimization_phase(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    method: Method,
    progress: &Progress,
) -> Result<OptimizationRun> {
    let mut opt = Optimizer::for_problem(gpu, prep, settings(prep, task, method, o))?;
    let truth = prep.reference.as_deref();
    let texture_rmse = |v: &[f32]| truth.map(|r| rmse(v, r)).unwrap_or(f64::NAN);
    let observed = opt.observed_texels()?.to_vec();
    let texture_rmse_observed = |v: &[f32]| {
        truth
            .map(|r| rmse_observed(&prep.set, v, r, &observed))
            .unwrap_or(f64::NAN)
    };
    let points = o.curve_points.max(2);
    let mut next_eval = 1u32;
    let mut curve = Vec::new();
    let mut seconds = 0.0;
    let mut passes: Option<(PassTimes, u32)> = None;
    // The merge's counter at the last sampled iteration, and the kept paths it evaluated
    // since the first one with the number of iterations they span.
    let mut last_count: Option<(u32, u32)> = None;
    let mut evaluations: Option<(u64, u32)> = None;
    let mut last_image = None;
    let name = match method {
        Method::Baseline => "baseline",
        Method::Restir => "ReSTIR",
    };
    loop {
        let eval_due = seconds >= o.budget_s * next_eval as f64 / (points - 1) as f64;
        if seconds >= o.budget_s || eval_due {
            let (e, img) = evaluate(&opt, prep, task, o.eval_spp)?;
            last_image = Some(img);
            if let Some(p) = curve.last_mut() {
                let p: &mut CurvePoint = p;
                p.image_relmse = Some(e);
            }
            next_eval += 1;
            progress.message(format!(
                "{name}: {seconds:.0}/{:.0} s, image relMSE {e:.3e}",
                o.budget_s
            ));
        }
        if seconds >= o.budget_s {
            break;
        }
        // Both estimators follow the task's schedule over the same budget.
        opt.set_progress(seconds / o.budget_s);
        let t0 = Instant::now();
        let stats = opt.step()?;
        seconds += t0.elapsed().as_secs_f64();
        if opt.iteration % 8 == 2 {
            if let Some(t) = opt.pass_times()? {
                let (s, n) = passes.get_or_insert((PassTimes::default(), 0));
                s.add(&t);
                *n += 1;
            }
            // The merge's counter (32 bits on the GPU: it may wrap over a long run, never
            // between two samples).
            if let Some(d) = opt.merge_diagnostics()? {
                let count = d.evaluations as u32;
                if let Some((iteration, last)) = last_count {
                    let (s, n) = evaluations.get_or_insert((0, 0));
                    *s += count.wrapping_sub(last) as u64;
                    *n += opt.iteration - iteration;
                }
                last_count = Some((opt.iteration, count));
            }
        }
        let values = opt.read_params()?;
        let factor = match (opt.last_learning_rates().first(), prep.set.textures.first()) {
            (Some(&l), Some(t)) if t.learning_rate > 0.0 => Some(l as f64 / t.learning_rate as f64),
            _ => None,
        };
        curve.push(CurvePoint {
            iteration: opt.iteration,
            seconds,
            loss: stats.loss,
            texture_rmse: texture_rmse(&values),
            texture_rmse_observed: texture_rmse_observed(&values),
            learning_rate_factor: factor,
            image_relmse: None,
        });
    }
    // The loop ends with an evaluation at the end of the budget.
    let final_image = match last_image {
        Some(img) => img,
        None => evaluate(&opt, prep, task, o.eval_spp)?.1,
    };
    let iterations = opt.iteration;
    progress.done();
    Ok(OptimizationRun {
        ms_per_iteration: 1000.0 * seconds / iterations.max(1) as f64,
        iterations,
        passes: passes.map(|(s, n)| s.divided(n as f64)),
        merge_evaluations: evaluations.map(|(s, n)| s as f64 / n as f64),
        state_bytes_per_texel: opt.state_bytes_per_texel(),
        curve,
        final_image,
    })
}

/// The equal-time optimization of both estimators (phase 2) and the cost (phase 3).
pub(super) fn optimization_phases(
    gpu: &Gpu,
    task: &Task,
    prep: &Problem,
    o: &BenchOptions,
    progress: &Progress,
) -> Result<(OptimizationResult, FinalImages)> {
    let init = Optimizer::for_problem(gpu, prep, settings(prep, task, Method::Baseline, o))?;
    let (image_initial, _) = evaluate(&init, prep, task, o.eval_spp)?;
    let texture_initial = prep
        .reference
        .as_deref()
        .map(|r| rmse(&prep.set.values, r))
        .unwrap_or(f64::NAN);
    let observed = init.observed_texels()?.to_vec();
    let texture_observed_initial = prep
        .reference
        .as_deref()
        .map(|r| rmse_observed(&prep.set, &prep.set.values, r, &observed))
        .unwrap_or(f64::NAN);
    drop(init);
    let start = CurvePoint {
        iteration: 0,
        seconds: 0.0,
        loss: f64::NAN,
        texture_rmse: texture_initial,
        texture_rmse_observed: texture_observed_initial,
        learning_rate_factor: None,
        image_relmse: Some(image_initial),
    };
    let base = optimization_phase(gpu, task, prep, o, Method::Baseline, progress)?;
    let re = optimization_phase(gpu, task, prep, o, Method::Restir, progress)?;
    let last = |r: &OptimizationRun| -> (f64, f64, f64) {
        let t = r
            .curve
            .last()
            .map(|p| (p.texture_rmse, p.texture_rmse_observed))
            .unwrap_or((texture_initial, texture_observed_initial));
        let i = r
            .curve
            .iter()
            .rev()
            .find_map(|p| p.image_relmse)
            .unwrap_or(image_initial);
        (t.0, t.1, i)
    };
    // The observed-texel RMSE at a third of the budget (the last point before it).
    let third = |r: &OptimizationRun| -> f64 {
        r.curve
            .iter()
            .take_while(|p| p.seconds <= o.budget_s / 3.0)
            .last()
            .map(|p| p.texture_rmse_observed)
            .unwrap_or(texture_observed_initial)
    };
    let (tb, tob, ib) = last(&base);
    let (tr, tor, ir) = last(&re);
    let with_start = |c: &[CurvePoint]| {
        let mut v = vec![start.clone()];
        v.extend_from_slice(c);
        v
    };
    let result = OptimizationResult {
        image_relmse_initial: image_initial,
        image_relmse_baseline: ib,
        image_relmse_restir: ir,
        image_relmse_ratio: ir / ib,
        texture_rmse_initial: texture_initial,
        texture_rmse_baseline: tb,
        texture_rmse_restir: tr,
        texture_rmse_observed_initial: texture_observed_initial,
        texture_rmse_observed_baseline: tob,
        texture_rmse_observed_restir: tor,
        texture_rmse_observed_third_baseline: third(&base),
        texture_rmse_observed_third_restir: third(&re),
        observed_fraction: observed.iter().filter(|&&b| b).count() as f64
            / observed.len().max(1) as f64,
        schedule: task.optimizer.schedule.describe(),
        ms_per_iteration_baseline: base.ms_per_iteration,
        ms_per_iteration_restir: re.ms_per_iteration,
        iterations_baseline: base.iterations,
        iterations_restir: re.iterations,
        passes_baseline: base.passes,
        passes_restir: re.passes,
        merge_evaluations_per_iteration: re.merge_evaluations,
        state_bytes_per_texel: re.state_bytes_per_texel,
        state_bytes_per_texel_baseline: base.state_bytes_per_texel,
        curve_baseline: with_start(&base.curve),
        curve_restir: with_start(&re.curve),
    };
    let finals = FinalImages {
        target: prep.targets[0].clone(),
        baseline: base.final_image,
        restir: re.final_image,
    };
    Ok((result, finals))
}
