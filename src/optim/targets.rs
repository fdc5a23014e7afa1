//! The targets' per-pixel masks and the per-camera exposures (optimized with Adam on their
//! logarithms when [`super::Settings::exposure_learning_rate`] is set).
use super::{adam, Optimizer};
use crate::{Error, Result};

impl Optimizer {
    /// Weigh each camera's pixels by a mask (one value per pixel in [0, 1]; None: all 1):
    /// masked-out pixels add neither loss nor gradient. The loss is the mean over the
    /// masked pixels.
    pub fn set_masks(&mut self, masks: &[Option<Vec<f32>>]) -> Result<()> {
        let n_pixels = (self.settings.width * self.settings.height) as usize;
        if masks.len() != self.cams.len() {
            return Err(Error::Invalid(format!(
                "{} masks for {} cameras",
                masks.len(),
                self.cams.len()
            )));
        }
        let mut total = 0f64;
        for (k, m) in masks.iter().enumerate() {
            let data: Vec<[f32; 4]> = match m {
                Some(m) => {
                    if m.len() != n_pixels || m.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                        return Err(Error::Invalid(format!(
                            "the mask of camera {k} needs {n_pixels} finite weights >= 0"
                        )));
                    }
                    self.targets[k]
                        .rgb
                        .iter()
                        .zip(m)
                        .map(|(p, &w)| [p[0], p[1], p[2], w])
                        .collect()
                }
                None => self.targets[k]
                    .rgb
                    .iter()
                    .map(|p| [p[0], p[1], p[2], 1.0])
                    .collect(),
            };
            total += data.iter().map(|p| p[3] as f64).sum::<f64>();
            self.loss.write_target(&self.gpu, k, &data);
        }
        // Also catches a NaN total.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(total > 0.0) {
            return Err(Error::Invalid("the masks leave no pixel to compare".into()));
        }
        let norm = (1.0 / (3.0 * total)) as f32;
        self.loss.set_norm(&self.gpu, norm);
        self.gpu.check("set masks")
    }

    /// Set the factor each camera's render is multiplied by before it is compared with its
    /// target (photos have their own exposure). With `Settings::exposure_learning_rate` the
    /// optimizer goes on from these values.
    pub fn set_exposure(&mut self, values: &[f32]) -> Result<()> {
        if values.len() != self.cams.len() || values.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(Error::Invalid(format!(
                "{} exposures for {} cameras (each positive)",
                values.len(),
                self.cams.len()
            )));
        }
        self.exposure.values = values.to_vec();
        self.upload_exposure();
        self.gpu.check("set exposure")
    }

    /// The current per-camera exposures.
    pub fn exposure(&self) -> &[f32] {
        &self.exposure.values
    }

    pub(super) fn upload_exposure(&mut self) {
        self.loss.set_exposures(&self.gpu, &self.exposure.values);
    }

    /// One Adam step of the exposures' logarithms from this iteration's dL/d(exposure).
    pub(super) fn step_exposure(&mut self, lr: f32) -> Result<()> {
        let gradients = self.loss.read_exposure_gradients(&self.gpu)?;
        let e = &mut self.exposure;
        e.steps += 1;
        let t = e.steps as i32;
        for (k, d) in gradients.into_iter().enumerate() {
            // d/d(log e) = e d/de.
            let g = (d * e.values[k] as f64) as f32;
            if !g.is_finite() {
                continue;
            }
            e.m1[k] = adam::BETA1 * e.m1[k] + (1.0 - adam::BETA1) * g;
            e.m2[k] = adam::BETA2 * e.m2[k] + (1.0 - adam::BETA2) * g * g;
            let m = e.m1[k] / (1.0 - adam::BETA1.powi(t));
            let v = e.m2[k] / (1.0 - adam::BETA2.powi(t));
            let log_e = e.values[k].ln() - lr * m / (v.sqrt() + adam::EPS);
            e.values[k] = log_e.clamp(-20.0, 20.0).exp();
        }
        self.upload_exposure();
        Ok(())
    }
}
