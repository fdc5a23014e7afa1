//! The per-camera gains: exposures (optimized on their logarithms when
//! [`crate::optim::Settings::exposure_learning_rate`] is set) and white balances (per-channel
//! factors, [`FitMut::optimize_white_balance`]), both groups of the parameter table.
use super::{Fit, FitMut};
use crate::optim::param_table::{EXPOSURE, WHITE_BALANCE};
use crate::{Error, Result};

impl Fit {
    /// The current per-camera exposures.
    pub fn exposure(&self) -> &[f32] {
        &self.table.group(EXPOSURE).state.values
    }

    /// The current per-camera white balances (per-channel factors on top of the exposure).
    pub fn white_balance(&self) -> &[[f32; 3]] {
        bytemuck::cast_slice(&self.table.group(WHITE_BALANCE).state.values)
    }

    /// Each camera's per-channel gain, exposure times white balance: what its render is
    /// multiplied by before the comparison.
    pub fn gains(&self) -> Vec<[f32; 3]> {
        (self.exposure().iter().zip(self.white_balance()))
            .map(|(&e, wb)| wb.map(|w| w * e))
            .collect()
    }

    /// Whether the exposures or the white balances are optimized.
    pub(in crate::optim) fn gains_optimized(&self) -> bool {
        self.table.optimizes(&[EXPOSURE, WHITE_BALANCE])
    }
}

impl FitMut<'_> {
    /// Set the factor each camera's render is multiplied by before it is compared with its
    /// target (photos have their own exposure). With `Settings::exposure_learning_rate` the
    /// optimizer goes on from these values.
    pub fn set_exposure(&mut self, values: &[f32]) -> Result<()> {
        if values.len() != self.cameras || values.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(Error::Invalid(format!(
                "{} exposures for {} cameras (each positive)",
                values.len(),
                self.cameras
            )));
        }
        self.fit.table.group_mut(EXPOSURE).state.values = values.to_vec();
        self.fit.gain_prev = self.fit.gains();
        self.upload_exposure();
        self.gpu.check("set exposure")
    }

    /// Set each camera's white balance (per-channel factors over its exposure, positive).
    /// With the white balances optimized the optimizer goes on from these values.
    pub fn set_white_balance(&mut self, values: &[[f32; 3]]) -> Result<()> {
        if values.len() != self.cameras
            || values
                .iter()
                .flatten()
                .any(|v| !(v.is_finite() && *v > 0.0))
        {
            return Err(Error::Invalid(format!(
                "{} white balances for {} cameras (each three positive factors)",
                values.len(),
                self.cameras
            )));
        }
        self.fit.table.group_mut(WHITE_BALANCE).state.values = values.concat();
        self.fit.gain_prev = self.fit.gains();
        self.upload_exposure();
        self.gpu.check("set white balance")
    }

    /// Optimize each camera's white balance (per-channel gains over its exposure) with Adam
    /// on their logarithms at learning rate `lr`. When the environment is recovered too, the
    /// first camera's exposure and white balance stay as they are: light and camera response
    /// share a scale and a tint that images do not fix, and the first camera is the
    /// reference (the gauge).
    pub fn optimize_white_balance(&mut self, lr: f32) -> Result<()> {
        if !(lr.is_finite() && lr > 0.0 && lr <= 10.0) {
            return Err(Error::Invalid(format!(
                "optimizer.white_balance_learning_rate: must be a number in (0, 10], not {lr}"
            )));
        }
        self.fit.table.group_mut(WHITE_BALANCE).learning_rate = Some(lr);
        Ok(())
    }

    /// Upload the gains and the environment anew after their values were replaced (a
    /// checkpoint's, a kept state's): the next adjoint pairs with these gains.
    pub(in crate::optim) fn upload(&mut self) -> Result<()> {
        self.fit.gain_prev = self.fit.gains();
        self.upload_exposure();
        if self.fit.env_fit.is_some() {
            self.upload_environment(true)?;
        }
        Ok(())
    }

    pub(in crate::optim) fn upload_exposure(&mut self) {
        let gains = self.fit.gains();
        self.loss.set_gains(self.gpu, &gains, &self.fit.gain_prev);
    }

    /// One Adam step of the exposures' and the white balances' logarithms (those optimized)
    /// from this iteration's dL/d(gain), at schedule factor `factor`.
    pub(in crate::optim) fn step_gains(&mut self, factor: f32) -> Result<()> {
        if !self.fit.gains_optimized() {
            return Ok(());
        }
        let d = self.loss.read_gain_gradients(self.gpu)?;
        let g = log_gain_gradients(&d, &self.fit.gains());
        self.step_log_gains(factor, &g);
        Ok(())
    }

    /// One step of the optimized gains' logarithms from `(d_exposure, d_white_balance)`,
    /// the derivatives with respect to the logarithms of each camera's exposure and white
    /// balance, at schedule factor `factor`, and their upload.
    pub(in crate::optim) fn step_log_gains(
        &mut self,
        factor: f32,
        (d_e, d_wb): &(Vec<f32>, Vec<[f32; 3]>),
    ) {
        let gains = self.fit.gains();
        let settings = self.settings;
        self.fit.table.step(settings, EXPOSURE, d_e, factor);
        self.fit
            .table
            .step(settings, WHITE_BALANCE, &d_wb.concat(), factor);
        // The next loss pass pairs its render with this iteration's adjoint, written with
        // the gains before this step.
        self.fit.gain_prev = gains;
        self.upload_exposure();
    }
}

/// d/d(log exposure) and d/d(log white balance) per camera from dL/d(gain) `d` at `gains`
/// (exposure times white balance): gain times dL/d(gain), summed over the channels for the
/// exposure.
pub(in crate::optim) fn log_gain_gradients(
    d: &[[f64; 3]],
    gains: &[[f32; 3]],
) -> (Vec<f32>, Vec<[f32; 3]>) {
    d.iter()
        .zip(gains)
        .map(|(d, g)| {
            let per: [f32; 3] = std::array::from_fn(|c| (d[c] * g[c] as f64) as f32);
            (per.iter().sum::<f32>(), per)
        })
        .unzip()
}
