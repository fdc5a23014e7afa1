//! The benchmark's gradient-error phase (see the module above): the warm-up of the estimator
//! under study ([`BenchOptions::gradient_method`], ReSTIR by default; "the estimator" below),
//! the equal-time baseline spp, the reference gradient, and the total, estimator-only and
//! successive-estimate errors of the estimator and the baseline.
use super::options::BenchOptions;
use super::phases::time_steps;
use super::progress::Progress;
use super::results::GradientSnapshot;
use super::settings;
use crate::gpu::Gpu;
use crate::job::Problem;
use crate::optim::run_loop::run_steps;
use crate::optim::{Method, Optimizer, Settings};
use crate::task::Task;
use crate::{Error, Result};
use std::time::Instant;

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

/// Gradient error (phase 1): the scene's gradient fields and the gradients of the first seed
/// for the images.
pub(super) struct GradientPhase {
    pub(super) baseline_spp_equal_time: f64,
    pub(super) total_baseline: f64,
    pub(super) total_estimator: f64,
    pub(super) total_baseline_equal_iterations: f64,
    pub(super) only_baseline: f64,
    pub(super) only_estimator: f64,
    pub(super) only_baseline_equal_time: f64,
    pub(super) mean_baseline: f64,
    pub(super) mean_estimator: f64,
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
    pub(super) total_estimator: f64,
    pub(super) only_baseline: f64,
    pub(super) only_estimator: f64,
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

/// A function that builds an optimizer for the bench: (estimator, gradient spp, seed).
type NewOptimizer<'a> = dyn Fn(Method, u32, u32) -> Result<Optimizer> + 'a;

/// The baseline's gradient spp that takes the time of one iteration of the estimator, and
/// its ms per iteration over the baseline's at `spp`. Its time is `ms_estimator` when its
/// warm-up timed it, else measured here; the baseline is timed at `spp` and 4 `spp` over
/// `(untimed, timed)` iterations like the estimator's.
fn equal_time_spp(
    new: &NewOptimizer,
    task: &Task,
    method: Method,
    spp: u32,
    seed: u32,
    (untimed, timed): (u32, u32),
    ms_estimator: Option<f64>,
) -> Result<(f64, f64)> {
    let (untimed, timed) = match ms_estimator {
        Some(_) => (untimed, timed),
        None => (1, 3),
    };
    let timed = timed.max(3);
    let ms_estimator = match ms_estimator {
        Some(ms) => ms,
        None => {
            let mut r = new(method, spp, seed)?;
            time_steps(&mut r, untimed, timed)?
        }
    };
    // Three more gradient spp per pixel cost time: if they measure as free, the
    // timing was disturbed (another process on the device or the CPU), and the
    // equal-time spp would come out absurd (it is clamped at 1024, whose
    // estimates would then take hours). Timed up to three times, then an error.
    let mut tries = 0;
    let (t1, t4) = loop {
        let mut b1 = new(Method::BASELINE, spp, seed ^ 0x71)?;
        let t1 = time_steps(&mut b1, untimed, timed)?;
        drop(b1);
        let mut b4 = new(Method::BASELINE, 4 * spp, seed ^ 0x72)?;
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
    let k = (spp as f64 + (ms_estimator - t1) / per_spp).clamp(1.0, 1024.0);
    log::info!(
        "{}: {method} {ms_estimator:.1} ms/it, baseline {t1:.1} ms/it at {spp} spp \
         (+{per_spp:.1} ms per spp): {k:.2} spp at equal time",
        task.path.display()
    );
    Ok((k, ms_estimator / t1))
}

/// Which errors [`GradientPhase::add`] adds to.
#[derive(Clone, Copy)]
enum Errors {
    /// Under the adjoint of a task-spp primal render.
    Total,
    /// Under the converged adjoint.
    EstimatorOnly,
}

impl GradientPhase {
    /// Add one seed's errors of the estimator's and the baseline's gradients,
    /// `[estimator, baseline]`
    /// (the baseline at the task's spp): the whole and each texture's part (its `range`),
    /// each divided by the number of seeds `n`.
    fn add(
        &mut self,
        which: Errors,
        [estimator, baseline]: [&Vec<f32>; 2],
        reference: &[f64],
        ranges: &[std::ops::Range<usize>],
        n: f64,
    ) {
        let (r, b) = (
            gradient_relmse(estimator, reference) / n,
            gradient_relmse(baseline, reference) / n,
        );
        let parts = gradient_relmse_parts(estimator, reference, ranges)
            .into_iter()
            .zip(gradient_relmse_parts(baseline, reference, ranges));
        let (whole_r, whole_b) = match which {
            Errors::Total => (
                &mut self.total_estimator,
                &mut self.total_baseline_equal_iterations,
            ),
            Errors::EstimatorOnly => (&mut self.only_estimator, &mut self.only_baseline),
        };
        *whole_r += r;
        *whole_b += b;
        for (p, (er, eb)) in self.per_texture.iter_mut().zip(parts) {
            let (pr, pb) = match which {
                Errors::Total => (
                    &mut p.total_estimator,
                    &mut p.total_baseline_equal_iterations,
                ),
                Errors::EstimatorOnly => (&mut p.only_estimator, &mut p.only_baseline),
            };
            *pr += er / n;
            *pb += eb / n;
        }
    }

    /// Not measured (`--end-to-end-only`): every error NaN, no gradient images.
    pub(super) fn not_measured(prep: &Problem) -> GradientPhase {
        let mut g = GradientPhase::new(0, prep.set.textures.len());
        for v in [
            &mut g.baseline_spp_equal_time,
            &mut g.total_baseline,
            &mut g.total_estimator,
            &mut g.total_baseline_equal_iterations,
            &mut g.only_baseline,
            &mut g.only_estimator,
            &mut g.only_baseline_equal_time,
            &mut g.mean_baseline,
            &mut g.mean_estimator,
        ] {
            *v = f64::NAN;
        }
        g
    }

    /// Nothing measured yet, at the task's `spp` with `n_textures` textures.
    fn new(spp: u32, n_textures: usize) -> GradientPhase {
        GradientPhase {
            baseline_spp_equal_time: spp as f64,
            total_baseline: 0.0,
            total_estimator: 0.0,
            total_baseline_equal_iterations: 0.0,
            only_baseline: 0.0,
            only_estimator: 0.0,
            only_baseline_equal_time: 0.0,
            mean_baseline: 0.0,
            mean_estimator: 0.0,
            ms_ratio: f64::NAN,
            snapshot: GradientSnapshot {
                reference: Vec::new(),
                baseline: Vec::new(),
                estimator: Vec::new(),
                estimator_name: String::new(),
                baseline_spp: spp,
            },
            per_texture: vec![TextureParts::default(); n_textures],
        }
    }
}

/// The estimator's warm-up: `warmup` steps, the first quarter untimed, the rest timed. Returns
/// (untimed, timed, ms per timed step).
fn warm_up(re: &mut Optimizer, warmup: u32) -> Result<(u32, u32, Option<f64>)> {
    let untimed = (warmup / 4).max(1).min(warmup);
    run_steps(re, untimed, &mut [])?;
    let t0 = Instant::now();
    let timed = warmup - untimed;
    run_steps(re, timed, &mut [])?;
    let ms = (timed > 0).then(|| 1000.0 * t0.elapsed().as_secs_f64() / timed as f64);
    Ok((untimed, timed, ms))
}

/// The converged adjoint at the texture values `state`, and the reference gradient under it.
fn reference_at(
    new: &NewOptimizer,
    o: &BenchOptions,
    state: &[f32],
    seed: u32,
) -> Result<(Vec<f32>, Vec<f64>)> {
    let mut r = new(
        Method::BASELINE,
        o.reference_spp.clamp(1, 64),
        seed ^ 0x5eed,
    )?;
    r.write_params(state)?;
    let (converged, _) = r.converged_adjoint(o.reference_primal_spp, seed ^ 0xad)?;
    let reference = reference_gradient(&mut r, o.reference_spp, &converged)?;
    Ok((converged, reference))
}

/// An optimizer adds up successive estimates. Those of an estimator with reuse share samples
/// (ReSTIR's kept ones, the recursive estimator's running sum), so their errors are
/// correlated and their mean gains less than a mean of independent estimates would: the
/// mean of `o.successive` estimates of the estimator under `converged`, from `first`
/// (already drawn) on, and the mean of as many independent baseline estimates (from a
/// baseline that `baseline(salt)` builds at the estimator's state).
fn successive_means(
    mut re: Optimizer,
    baseline: &dyn Fn(u32) -> Result<Optimizer>,
    converged: &[f32],
    it: u32,
    o: &BenchOptions,
    first: &[f32],
) -> Result<(Vec<f32>, Vec<f32>)> {
    let successive = o.successive;
    let mut mean_estimator = first.iter().map(|&v| v as f64).collect::<Vec<_>>();
    for j in 1..successive {
        let g = re.estimate_gradient_with_adjoint(it + o.settle + j, converged)?;
        add_to(&mut mean_estimator, &g);
    }
    drop(re);
    let mut mean_baseline = vec![0.0; first.len()];
    let mut b = baseline(0xec)?;
    for j in 0..successive {
        let g = b.estimate_gradient_with_adjoint(it + 1 + j, converged)?;
        add_to(&mut mean_baseline, &g);
    }
    let mean = |sum: Vec<f64>| -> Vec<f32> {
        sum.iter()
            .map(|&v| (v / successive as f64) as f32)
            .collect()
    };
    Ok((mean(mean_estimator), mean(mean_baseline)))
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
    let mut out = GradientPhase::new(spp, prep.set.textures.len());
    // Where each optimized texture lies in a gradient.
    let ranges: Vec<_> = prep
        .set
        .textures
        .iter()
        .map(|t| t.offset as usize..t.offset as usize + t.len())
        .collect();
    let mut eq_spp = None;
    for rep in 0..repeats {
        progress.message(format!("gradient error, seed {}/{repeats}", rep + 1));
        let seed = task.seed.wrapping_add(1000 * (rep + 1));
        // The estimator from the initial textures; the later warm-up steps time an iteration.
        let mut re = new(o.gradient_method, spp, seed)?;
        let (untimed, timed, ms_estimator) = warm_up(&mut re, o.warmup)?;
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
                let (k, ms_ratio) = equal_time_spp(
                    &new,
                    task,
                    o.gradient_method,
                    spp,
                    seed,
                    (untimed, timed),
                    ms_estimator,
                )?;
                out.ms_ratio = ms_ratio;
                eq_spp = Some(k);
                k
            }
        };

        // The converged adjoint at the state, and the reference gradient under it.
        progress.message(format!(
            "gradient error, seed {}/{repeats}: reference",
            rep + 1
        ));
        let (converged, reference) = reference_at(&new, o, &state, seed)?;
        let at = SeedRun {
            new: &new,
            o,
            seed,
            spp,
            it: re.iteration,
            kept,
            reference,
            ranges: &ranges,
            n: repeats as f64,
            k,
        };
        at.total(&mut re, &mut out)?;
        at.estimator_only(re, &converged, &mut out, rep == 0)?;
        progress.done();
    }
    Ok(out)
}

/// One seed's measurements after the warm-up: the estimator's state, the reference under
/// the converged adjoint, and the baseline's spp at equal time.
struct SeedRun<'a> {
    new: &'a NewOptimizer<'a>,
    o: &'a BenchOptions,
    seed: u32,
    /// The task's gradient spp.
    spp: u32,
    /// The estimator's iteration after the warm-up.
    it: u32,
    /// Its state then.
    kept: crate::optim::OptimizerState,
    reference: Vec<f64>,
    ranges: &'a [std::ops::Range<usize>],
    /// Seeds averaged over.
    n: f64,
    /// The baseline's gradient spp at the estimator's time per iteration.
    k: f64,
}

impl SeedRun<'_> {
    /// A baseline at the estimator's state without the estimator's own (ReSTIR's
    /// reservoirs, the recursive running estimate): the same textures (and, with the
    /// control-variate primal, the same carried image and statistics).
    fn baseline(&self, spp: u32, salt: u32) -> Result<Optimizer> {
        let mut b = (self.new)(Method::BASELINE, spp, self.seed ^ salt)?;
        b.restore(&crate::optim::OptimizerState {
            estimator: crate::optim::EstimatorState::new(Method::BASELINE),
            ..self.kept.clone()
        })?;
        Ok(b)
    }

    /// That baseline's gradient under `adjoint`.
    fn baseline_at(&self, spp: u32, salt: u32, adjoint: &[f32]) -> Result<Vec<f32>> {
        self.baseline(spp, salt)?
            .estimate_gradient_with_adjoint(self.it + 1, adjoint)
    }

    /// The baseline's error under `adjoint` at the equal-time spp, interpolated in 1/spp
    /// between the whole spp around it.
    fn baseline_equal_time(&self, adjoint: &[f32]) -> Result<f64> {
        let s0 = (self.k.floor() as u32).max(1);
        let e = |spp, salt| -> Result<f64> {
            Ok(gradient_relmse(
                &self.baseline_at(spp, salt, adjoint)?,
                &self.reference,
            ))
        };
        Ok(interpolate_in_inverse_spp(
            self.k,
            s0,
            e(s0, 0xe9)?,
            e(s0 + 1, 0xeb)?,
        ))
    }

    /// Total: the estimator's next gradient with its own primal render, and the baseline's
    /// at the task's spp and around the equal-time spp under the adjoint of that same render
    /// (common random numbers). Every figure is still an estimator under the adjoint of one
    /// task-spp primal render, so each expected error is what a user gets; sharing the
    /// render takes the primal's noise out of the comparison, which with one render per
    /// estimate and seed dominated it (`sphere`, paper protocol, a render of its own for
    /// each: the baseline's total error at 1 / 2 / 3 gradient spp was 17.2 / 1.3 / about
    /// 7e-8, not falling with the spp, against 3.7e-8 estimator-only at 1 spp). The
    /// estimator is restored to its state after.
    fn total(&self, re: &mut Optimizer, out: &mut GradientPhase) -> Result<()> {
        let (g_estimator, _) = re.estimate_gradient(self.it)?;
        let adjoint = re.read_adjoint(self.it)?;
        re.restore(&self.kept)?;
        let g_baseline = self.baseline_at(self.spp, 0xea, &adjoint)?;
        let errors = [&g_estimator, &g_baseline];
        out.add(Errors::Total, errors, &self.reference, self.ranges, self.n);
        out.total_baseline += self.baseline_equal_time(&adjoint)? / self.n;
        Ok(())
    }

    /// Estimator-only: both under the converged adjoint. The estimator first draws `settle`
    /// more estimates under it at the same textures, so that its reservoirs hold samples
    /// chosen for the integrand it is measured on. Measured right after the warm-up, its
    /// reservoirs were filled under the noisy adjoints of its own primal renders, and the
    /// switch of adjoint, not the reuse, dominated the error. The textures stay where they
    /// are: under one fixed adjoint, Adam pushes every texel the same way at every step (on
    /// `vase`, 20 such steps made both estimators' errors 5-8x larger).
    fn estimator_only(
        &self,
        mut re: Optimizer,
        converged: &[f32],
        out: &mut GradientPhase,
        snapshot: bool,
    ) -> Result<()> {
        let (it, o) = (self.it, self.o);
        for j in 0..o.settle {
            re.estimate_gradient_with_adjoint(it + j, converged)?;
        }
        let g_estimator = re.estimate_gradient_with_adjoint(it + o.settle, converged)?;
        let (mean_estimator, mean_baseline) = successive_means(
            re,
            &|salt| self.baseline(self.spp, salt),
            converged,
            it,
            o,
            &g_estimator,
        )?;
        out.mean_estimator += gradient_relmse(&mean_estimator, &self.reference) / self.n;
        out.mean_baseline += gradient_relmse(&mean_baseline, &self.reference) / self.n;
        let g_baseline = self.baseline_at(self.spp, 0xea, converged)?;
        let errors = [&g_estimator, &g_baseline];
        out.add(
            Errors::EstimatorOnly,
            errors,
            &self.reference,
            self.ranges,
            self.n,
        );
        out.only_baseline_equal_time += self.baseline_equal_time(converged)? / self.n;
        out.baseline_spp_equal_time = self.k;
        if snapshot {
            out.snapshot = GradientSnapshot {
                reference: self.reference.iter().map(|&v| v as f32).collect(),
                baseline: g_baseline,
                estimator: g_estimator,
                estimator_name: o.gradient_method.name().to_string(),
                baseline_spp: self.spp,
            };
        }
        Ok(())
    }
}

/// relMSE over entries with a non-zero reference: mean of (g - r)^2 / (r^2 + 1e-2).
pub fn gradient_relmse(g: &[f32], reference: &[f64]) -> f64 {
    let whole = 0..g.len();
    gradient_relmse_parts(g, reference, std::slice::from_ref(&whole))[0]
}

/// Each range's part of [`gradient_relmse`]: the sum of its terms over the range's entries
/// (those with a non-zero reference), divided by the number of such entries in the whole
/// vector, so that the parts of disjoint ranges covering it add up to the whole. With one
/// range per optimized texture it says which texture the error is in.
pub fn gradient_relmse_parts(
    g: &[f32],
    reference: &[f64],
    ranges: &[std::ops::Range<usize>],
) -> Vec<f64> {
    let term = |i: usize| -> Option<f64> {
        let (a, r) = (*g.get(i)? as f64, *reference.get(i)?);
        (r != 0.0).then(|| (a - r).powi(2) / (r * r + 1e-2))
    };
    let n = (0..g.len().min(reference.len()))
        .filter(|&i| term(i).is_some())
        .count()
        .max(1) as f64;
    ranges
        .iter()
        .map(|range| range.clone().filter_map(term).sum::<f64>() / n)
        .collect()
}
