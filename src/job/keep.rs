//! A run never hands back something worse than what it saw: the job's keeper follows the
//! evaluation image error (the rows of `metrics.csv` that have one, the start's included)
//! and keeps the textures and light of the lowest; at the end the run writes that state
//! (`optimizer.keep_best`, on by default), as early stopping on a validation measure does.
//! The error it ranks by is the relMSE of the evaluation render's expectation
//! (`image_relmse_expected`, [`crate::job::run::Evaluation::expected`]), not the render's own
//! relMSE: that one adds the render's variance, which changes with the textures, so it
//! would keep the quietest state rather than the closest. The evaluation renders use the
//! same seeds for the whole run, so two states' errors differ by what their textures do,
//! not by the render's noise. The bench keeps its runs' states with the same keeper, so that
//! it scores what a run of the task hands back.
use crate::optim::checkpoint::Kept;
use crate::optim::Optimizer;
use crate::Result;

/// Keeps the state with the lowest evaluation image error; see the module documentation.
#[derive(Debug)]
pub(crate) struct Keeper {
    on: bool,
    kept: Option<Kept>,
}

/// Which state a run handed back, when it was not its last.
#[derive(Clone, Debug, PartialEq)]
pub struct HandedBack {
    /// The iteration whose state the outputs hold (0: the start).
    pub iteration: u32,
    /// Its evaluation image error (the relMSE of the render's expectation).
    pub image_relmse: f64,
    /// The last iteration's.
    pub last_image_relmse: f64,
}

impl Keeper {
    /// A keeper (`on`: `optimizer.keep_best`), going on from a resumed run's kept state.
    pub(crate) fn new(on: bool, resumed: Option<Kept>) -> Keeper {
        Keeper {
            on,
            kept: resumed.filter(|_| on),
        }
    }

    /// The state kept so far (what a checkpoint saves).
    pub(super) fn kept(&self) -> Option<&Kept> {
        self.kept.as_ref()
    }

    /// The state `opt` holds now, with its evaluation image error (None: not evaluated):
    /// kept when that error is the lowest so far (its values read back then only).
    pub(crate) fn offer(&mut self, opt: &Optimizer, image_relmse: Option<f64>) -> Result<()> {
        let Some(e) = image_relmse.filter(|e| e.is_finite()) else {
            return Ok(());
        };
        if !self.on || self.kept.as_ref().is_some_and(|k| k.image_relmse <= e) {
            return Ok(());
        }
        self.kept = Some(Kept {
            image_relmse: e,
            values: opt.values()?,
        });
        Ok(())
    }

    /// At the end, `last` the last state's evaluation image error: put the kept state into
    /// `opt` where it is lower than the last; None where the last state stands.
    pub(crate) fn hand_back(
        &self,
        opt: &mut Optimizer,
        last: Option<f64>,
    ) -> Result<Option<HandedBack>> {
        let (Some(k), Some(last_e)) = (&self.kept, last) else {
            return Ok(None);
        };
        if k.values.iteration == opt.iteration || !(k.image_relmse < last_e) {
            return Ok(None);
        }
        opt.set_values(&k.values)?;
        Ok(Some(HandedBack {
            iteration: k.values.iteration,
            image_relmse: k.image_relmse,
            last_image_relmse: last_e,
        }))
    }
}

impl HandedBack {
    /// Log it after a run whose last iteration is `last_iteration`: a warning, added to
    /// `warnings`, where it is the start.
    pub(super) fn log(&self, last_iteration: u32, warnings: &mut Vec<String>) {
        let message = self.describe(last_iteration);
        if self.iteration == 0 {
            log::warn!("{message}");
            warnings.push(message);
        } else {
            log::info!("{message}");
        }
    }

    /// What the log says of it: a warning where the run could not improve on its start.
    pub fn describe(&self, last_iteration: u32) -> String {
        if self.iteration == 0 {
            format!(
                "the run did not improve on its start: every evaluation's image error (the \
                 relMSE of the render's expectation, image_relmse_expected) was above the \
                 start's ({:.4e}; the last, iteration {last_iteration}'s, {:.4e}), so the \
                 outputs are the initial textures and light (optimizer.keep_best = false \
                 writes the last state). Check the targets, the learning rate and the sampling",
                self.image_relmse, self.last_image_relmse
            )
        } else {
            format!(
                "the outputs are iteration {}'s state, the lowest evaluation image error of the \
                 run (the relMSE of the render's expectation, image_relmse_expected: {:.4e}, \
                 against {:.4e} at the last iteration, {last_iteration}); \
                 the checkpoint holds the last state, which --resume continues \
                 (optimizer.keep_best = false writes the last state)",
                self.iteration, self.image_relmse, self.last_image_relmse
            )
        }
    }
}
