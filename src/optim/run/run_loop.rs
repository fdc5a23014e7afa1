//! The one iteration loop: [`run_observed`] steps until a limit (iterations,
//! seconds of optimization) or an observer ends it, and hands each iteration to its
//! [`Observer`]s: the job's metrics, checkpoints, progress bar and loss watches
//! (`crate::job::run`), the bench's evaluations and samples (`crate::bench`), a caller's
//! callback ([`Optimizer::run`]), and [`PassSampler`], the passes' mean times. The time an
//! observer sets aside ([`Clock::aside`]: evaluation renders, metrics) is not optimization
//! time: budgets, progress and the schedule read [`Clock::seconds`].
use crate::optim::{Optimizer, PassTimes, Progress, StepStats, Stop};
use crate::{Error, Result};
use std::ops::ControlFlow;
use std::time::Instant;

/// A run's clock: the seconds of optimization, those of a resumed run's earlier sessions
/// (`offset`) plus the wall time since the clock started, less what observers set aside.
#[derive(Debug)]
pub struct Clock {
    start: Instant,
    offset: f64,
    aside: f64,
}

impl Clock {
    /// A clock started now at `offset` seconds.
    pub fn start(offset: f64) -> Clock {
        Clock {
            start: Instant::now(),
            offset,
            aside: 0.0,
        }
    }

    /// Seconds of optimization so far.
    pub fn seconds(&self) -> f64 {
        self.offset + self.session_seconds()
    }

    /// Seconds of optimization since the clock started (the offset left out).
    pub fn session_seconds(&self) -> f64 {
        self.start.elapsed().as_secs_f64() - self.aside
    }

    /// Run `f` and set its time aside: not optimization time.
    pub fn aside<T>(&mut self, f: impl FnOnce() -> T) -> T {
        let t0 = Instant::now();
        let out = f();
        self.aside += t0.elapsed().as_secs_f64();
        out
    }
}

/// Where a run stops by itself: at an iteration count (of the optimizer's
/// [`Optimizer::iteration`], a resumed run's included) and after seconds of optimization
/// ([`Clock::seconds`]), whichever comes first. Without either, only an observer ends it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Limits {
    /// The iteration count the run's share of iterations counts from (0 for a job, whose
    /// schedule spans its resumed sessions; the optimizer's count for a call of
    /// [`Optimizer::run`]).
    pub first: u32,
    /// The iteration count at which the run stops.
    pub iterations: Option<u32>,
    /// The seconds of optimization after which it stops.
    pub seconds: Option<f64>,
}

impl Limits {
    /// How far the run is, in [0, 1]: the larger of the iterations' and the seconds' shares
    /// (0 without limits). The schedule follows it.
    pub fn progress(&self, iteration: u32, seconds: f64) -> f64 {
        let by_iterations = self.iterations.map_or(0.0, |n| {
            iteration.saturating_sub(self.first) as f64 / n.saturating_sub(self.first).max(1) as f64
        });
        let by_time = self.seconds.map_or(0.0, |b| seconds / b.max(1e-9));
        by_iterations.max(by_time)
    }

    fn reached(&self, iteration: u32, seconds: f64) -> bool {
        self.iterations.is_some_and(|n| iteration >= n)
            || self.seconds.is_some_and(|b| seconds >= b)
    }
}

/// Something that watches a run. Both calls may end it (`Break`); time they set aside on the
/// clock does not count as optimization.
pub trait Observer {
    /// Before each iteration, and once more when a limit is reached (with `last` set): an
    /// evaluation due at this time, an interrupt.
    fn before(
        &mut self,
        _opt: &mut Optimizer,
        _clock: &mut Clock,
        _last: bool,
    ) -> Result<ControlFlow<()>> {
        Ok(ControlFlow::Continue(()))
    }

    /// After each iteration, with its statistics and the run's progress (as the schedule
    /// read it).
    fn after(
        &mut self,
        opt: &mut Optimizer,
        stats: &StepStats,
        progress: f64,
        clock: &mut Clock,
    ) -> Result<ControlFlow<()>>;
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ended {
    /// At a limit.
    Limit,
    /// An observer ended it.
    Observer,
}

/// The passes' mean times, read back on every 8th iteration of a run by default (one
/// readback less per iteration, and the mean is as good; [`PassSampler::every`] sets the
/// period); the readback is set aside on the clock.
#[derive(Debug)]
pub struct PassSampler {
    sum: Option<(PassTimes, u32)>,
    seen: u32,
    period: u32,
}

impl Default for PassSampler {
    fn default() -> PassSampler {
        PassSampler::every(8)
    }
}

impl PassSampler {
    /// A sampler that reads the times on every `period`-th iteration, the first included.
    pub fn every(period: u32) -> PassSampler {
        PassSampler {
            sum: None,
            seen: 0,
            period: period.max(1),
        }
    }

    /// The mean of the samples so far.
    pub fn mean(&self) -> Option<PassTimes> {
        self.sum.as_ref().map(|(s, n)| s.divided(*n as f64))
    }

    /// Whether this iteration is one it samples (by default the run's 1st, 9th, 17th, ...):
    /// other observers sample their own counters on the same iterations.
    pub fn due(&self) -> bool {
        self.seen >= 1 && (self.seen - 1) % self.period == 0
    }
}

impl Observer for PassSampler {
    fn after(
        &mut self,
        opt: &mut Optimizer,
        _: &StepStats,
        _: f64,
        clock: &mut Clock,
    ) -> Result<ControlFlow<()>> {
        self.seen += 1;
        if self.due() {
            if let Some(t) = clock.aside(|| opt.pass_times())? {
                let (s, n) = self.sum.get_or_insert((PassTimes::default(), 0));
                s.add(&t);
                *n += 1;
            }
        }
        Ok(ControlFlow::Continue(()))
    }
}

/// Step until `limits` or an observer ends the run, every pass compiled first. Before each
/// iteration every observer's `before` is called, then the limits are checked (at a limit
/// the observers' `before` is called once more with `last`); the schedule's progress is
/// set from the limits and the clock; after the step every observer's `after` is called
/// (all of them, even when one ends the run).
pub fn run_observed(
    opt: &mut Optimizer,
    limits: Limits,
    clock: &mut Clock,
    observers: &mut [&mut dyn Observer],
) -> Result<Ended> {
    drive(opt, limits, ScheduleProgress::Follows, clock, observers)
}

/// `n` more iterations through the same loop, with the schedule held where it is: its
/// progress is not set, so a fresh optimizer steps at its start. The bench's warm-ups and
/// timed steps measure an iteration near a run's start, not a run of `n` iterations,
/// whose schedule would decay over them.
pub fn run_steps(opt: &mut Optimizer, n: u32, observers: &mut [&mut dyn Observer]) -> Result<()> {
    let first = opt.iteration;
    let limits = Limits {
        first,
        iterations: Some(first.saturating_add(n)),
        seconds: None,
    };
    drive(
        opt,
        limits,
        ScheduleProgress::Held,
        &mut Clock::start(0.0),
        observers,
    )?;
    Ok(())
}

/// Whether the loop sets the schedule's progress from its limits (`Follows`) or leaves it
/// where it is (`Held`).
#[derive(Clone, Copy, PartialEq)]
enum ScheduleProgress {
    Follows,
    Held,
}

fn drive(
    opt: &mut Optimizer,
    limits: Limits,
    mode: ScheduleProgress,
    clock: &mut Clock,
    observers: &mut [&mut dyn Observer],
) -> Result<Ended> {
    opt.prepare()?;
    loop {
        let last = limits.reached(opt.iteration, clock.seconds());
        let mut stop = false;
        for o in observers.iter_mut() {
            stop |= o.before(opt, clock, last)?.is_break();
        }
        if last {
            return Ok(Ended::Limit);
        }
        if stop {
            return Ok(Ended::Observer);
        }
        let progress = match mode {
            ScheduleProgress::Follows => {
                let p = limits.progress(opt.iteration, clock.seconds());
                opt.set_progress(p);
                p
            }
            ScheduleProgress::Held => opt.progress(),
        };
        let stats = opt.step()?;
        for o in observers.iter_mut() {
            stop |= o.after(opt, &stats, progress, clock)?.is_break();
        }
        if stop {
            return Ok(Ended::Observer);
        }
    }
}

/// [`Optimizer::run`]: the loop with the caller's callback as its one observer.
pub fn run(
    opt: &mut Optimizer,
    stop: Stop,
    on_iteration: impl FnMut(&Progress) -> std::ops::ControlFlow<()>,
) -> Result<Option<Progress>> {
    if stop.iterations.is_none() && stop.time_budget.is_none() {
        return Err(Error::Invalid(
            "Optimizer::run needs a number of iterations, a time budget or both".into(),
        ));
    }
    /// The caller's callback as an observer, with the last iteration's progress.
    struct Callback<F> {
        first: u32,
        last: Option<Progress>,
        on_iteration: F,
    }
    impl<F: FnMut(&Progress) -> std::ops::ControlFlow<()>> Observer for Callback<F> {
        fn after(
            &mut self,
            opt: &mut Optimizer,
            stats: &StepStats,
            _: f64,
            clock: &mut Clock,
        ) -> Result<std::ops::ControlFlow<()>> {
            let p = Progress {
                iteration: opt.iteration,
                in_this_run: opt.iteration - self.first,
                loss: stats.loss,
                elapsed: std::time::Duration::from_secs_f64(clock.seconds().max(0.0)),
            };
            self.last = Some(p);
            Ok((self.on_iteration)(&p))
        }
    }
    let first = opt.iteration;
    let limits = Limits {
        first,
        iterations: stop.iterations.map(|n| first.saturating_add(n)),
        seconds: stop.time_budget.map(|d| d.as_secs_f64()),
    };
    let mut callback = Callback {
        first,
        last: None,
        on_iteration,
    };
    run_observed(opt, limits, &mut Clock::start(0.0), &mut [&mut callback])?;
    Ok(callback.last)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The schedule's progress is the larger share, iterations counted from `first`; a limit
    /// is reached at the count or the seconds; time set aside is not counted.
    #[test]
    fn limits_and_the_clock() {
        let l = Limits {
            first: 10,
            iterations: Some(30),
            seconds: Some(4.0),
        };
        assert_eq!(l.progress(20, 1.0), 0.5);
        assert_eq!(l.progress(12, 3.0), 0.75);
        assert!(!l.reached(29, 3.9) && l.reached(30, 0.0) && l.reached(11, 4.0));
        assert_eq!(Limits::default().progress(5, 9.0), 0.0);
        let mut c = Clock::start(2.0);
        c.aside(|| std::thread::sleep(std::time::Duration::from_millis(30)));
        assert!(c.seconds() >= 2.0 && c.seconds() < 2.02, "{}", c.seconds());
        assert!(c.session_seconds() < 0.02);
    }

    /// `run_steps` takes exactly `n` more iterations through the loop, its observers called
    /// on each, at the schedule's position as it was: a cosine schedule's factor at 0.25 of
    /// the run in its last step, not the factor of a run that ends with the steps.
    #[test]
    fn steps_hold_the_schedule() {
        use crate::optim::schedule::Schedule;
        let mut opt = crate::optim::plane_tests::plane_optimizer(|s| {
            s.schedule = Schedule::cosine(0.1);
        });
        opt.set_progress(0.25);
        let mut sampler = PassSampler::every(1);
        run_steps(&mut opt, 2, &mut []).unwrap();
        run_steps(&mut opt, 3, &mut [&mut sampler]).unwrap();
        assert_eq!(opt.iteration, 5);
        assert_eq!(sampler.seen, 3);
        assert_eq!(opt.progress(), 0.25);
        let want = 0.01 * Schedule::cosine(0.1).factor(4, 0.25);
        assert_eq!(opt.last_learning_rates(), &[want]);
        assert!(want < 0.01 && want > 0.01 * Schedule::cosine(0.1).factor(4, 1.0));
    }

    /// A sampler reads on its first iteration and every `period`-th after it.
    #[test]
    fn the_sampler_period() {
        let mut s = PassSampler::default();
        let mut due = Vec::new();
        for _ in 0..20 {
            s.seen += 1;
            if s.due() {
                due.push(s.seen);
            }
        }
        assert_eq!(due, [1, 9, 17]);
        assert!(!PassSampler::every(1).due());
    }
}
