//! A differentiable render with the loss left to the caller: [`Optimizer::render_cameras`]
//! renders every camera at the current textures, [`Optimizer::backward`] turns the adjoint
//! images of the caller's own loss (dL/dI per pixel) into each texel's gradient with the
//! optimizer's estimator, which keeps its state across calls as it does across iterations
//! (both in `outward.rs`). [`DiffRender`] wraps the two with the checks an application needs
//! (one backward per render, textures in range); the Python package is built on it.

use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::optim::{Optimizer, PrimalMode, Settings};
use crate::render::params::{ParamSet, ParamTexture};
use crate::scene::Scene;
use crate::{Error, Result};

/// A differentiable render whose loss belongs to the caller: set the parameters (the
/// textures, the environment when it is recovered, each camera's exposure and white balance),
/// [`render`](DiffRender::render) the cameras, compute dL/dI of any loss, and
/// [`backward`](DiffRender::backward) gives each parameter's gradient, the textures' and the
/// environment's with the chosen estimator. [`step`](DiffRender::step) then updates the
/// parameters with the built-in optimizer's step, priors and schedule, from that gradient or
/// one the caller gives. Each backward pairs with the render before it (a second backward, or
/// one after the parameters changed, is refused): that is what keeps ReSTIR's reuse, which
/// pairs each gradient with the previous call's textures and adjoint, and every estimate,
/// honest.
pub struct DiffRender {
    opt: Optimizer,
    /// The primal a render uses unless told otherwise (the settings').
    primal: PrimalMode,
    /// The images of the last render (before the cameras' gains), while no backward has
    /// used them and the parameters have not changed.
    rendered: Option<Vec<Image>>,
    /// dL/d(gain) per camera and channel of the last backward, while no step has used it.
    gain_gradient: Option<Vec<[f64; 3]>>,
    /// Steps taken.
    steps: u32,
}

/// The gradient of every parameter of a [`DiffRender`]: each texture's (laid out as
/// [`DiffRender::texture`]), the environment's dL/d(radiance) (3 per texel, row 0 at the
/// zenith) when it is recovered, and each camera's exposure's and white balance's.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gradients {
    /// Per texture.
    pub textures: Vec<Vec<f32>>,
    /// Per environment texel and channel, when the environment is a parameter.
    pub environment: Option<Vec<f32>>,
    /// Per camera.
    pub exposure: Vec<f32>,
    /// Per camera and channel.
    pub white_balance: Vec<[f32; 3]>,
}

// The Python package holds a DiffRender across calls that release the interpreter.
const _: fn() = || {
    fn send<T: Send>() {}
    send::<DiffRender>();
};

impl DiffRender {
    /// A differentiable render of `scene` seen by `settings.cameras`, with the textures of
    /// `set` (at their initial values) as its parameters, and the step, priors and schedule
    /// of `settings` for [`DiffRender::step`]. The control-variate primal is always there
    /// ([`DiffRender::render`] picks); `settings.primal` is the one a render uses by default
    /// (and the one the estimator's options assume).
    pub fn new(gpu: &Gpu, scene: &Scene, set: ParamSet, settings: Settings) -> Result<DiffRender> {
        let primal = settings.primal;
        // The loss pass is built but never run: placeholders of the images' size.
        let blank = Image {
            width: settings.width,
            height: settings.height,
            rgb: vec![[0.0; 3]; (settings.width * settings.height) as usize],
        };
        let targets = vec![blank; settings.cameras.len()];
        let mut opt = Optimizer::new(gpu, scene, set, settings, &targets)?;
        // The settings' primal also picks estimator options (ReSTIR's target smoothing): it
        // stays, and the control variate is added beside it.
        if opt.passes.control_variate.is_none() {
            let (w, h) = (opt.settings.width, opt.settings.height);
            opt.passes.control_variate = Some(crate::optim::primal::ControlVariate::new(
                gpu,
                (w, h),
                opt.passes.cams.len(),
                &opt.bufs.accum,
                &opt.bufs.accum_prev,
                opt.settings.cv_max_weight,
            )?);
        }
        Ok(DiffRender {
            opt,
            primal,
            rendered: None,
            gain_gradient: None,
            steps: 0,
        })
    }

    /// The optimized textures (names, slots, sizes, layout).
    pub fn textures(&self) -> &[ParamTexture] {
        &self.opt.set.textures
    }

    /// The image size (width, height) of every camera.
    pub fn image_size(&self) -> (u32, u32) {
        (self.opt.settings.width, self.opt.settings.height)
    }

    /// The cameras rendered (indices into the scene's cameras).
    pub fn cameras(&self) -> &[usize] {
        &self.opt.settings.cameras
    }

    /// The optimizer underneath (the estimator's diagnostics, the observed texels).
    pub fn optimizer(&self) -> &Optimizer {
        &self.opt
    }

    /// The optimizer underneath, to set what [`Optimizer::for_problem`] sets (exposures,
    /// the environment's fit, the white balances' rate) before the first render.
    pub fn optimizer_mut(&mut self) -> &mut Optimizer {
        self.rendered = None;
        &mut self.opt
    }

    /// The primal a render uses by default.
    pub fn primal(&self) -> PrimalMode {
        self.primal
    }

    /// Backward calls so far.
    pub fn iteration(&self) -> u32 {
        self.opt.iteration
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Current values of texture `i` (row-major, `channels()` floats per texel).
    pub fn texture(&self, i: usize) -> Result<Vec<f32>> {
        self.opt.texture_values(i)
    }

    /// Replace texture `i`'s values: `width * height * channels` finite values within the
    /// slot's range (base color and metallic [0, 1], roughness [0.02, 1]). A render must
    /// follow before the next backward.
    pub fn set_texture(&mut self, i: usize, values: &[f32]) -> Result<()> {
        let t = self.opt.set.textures.get(i).ok_or_else(|| {
            Error::Invalid(format!(
                "texture {i} does not exist ({} optimized)",
                self.opt.set.textures.len()
            ))
        })?;
        if values.len() != t.len() {
            return Err(Error::Invalid(format!(
                "texture `{}` has {}x{}x{} = {} values, {} given",
                t.name(),
                t.height,
                t.width,
                t.channels(),
                t.len(),
                values.len()
            )));
        }
        let (lo, hi) = t.slot.range();
        if let Some(k) = values
            .iter()
            .position(|v| !(v.is_finite() && *v >= lo && *v <= hi))
        {
            return Err(Error::Invalid(format!(
                "texture `{}`: value {} at index {k} is outside the slot's range [{lo}, {hi}] \
                 (clip the values to it)",
                t.name(),
                values[k]
            )));
        }
        let offset = t.offset as u64 * 4;
        self.opt.gpu.queue.write_buffer(
            &self.opt.params.values,
            offset,
            bytemuck::cast_slice(values),
        );
        self.rendered = None;
        self.opt.gpu.check("set_texture")
    }

    /// The environment, when it is recovered (a parameter); None otherwise.
    pub fn environment(&self) -> Option<crate::scene::EnvMap> {
        self.opt.fit().environment()
    }

    /// Replace the recovered environment's radiance (`width * height` RGB texels, each
    /// finite and positive, row 0 at the zenith); its sampling tables are rebuilt.
    pub fn set_environment(&mut self, rgb: &[[f32; 3]]) -> Result<()> {
        self.opt.fit_mut().set_environment(rgb)?;
        self.rendered = None;
        Ok(())
    }

    /// Each camera's exposure (the factor its render is multiplied by).
    pub fn exposure(&self) -> &[f32] {
        self.opt.fit().exposure()
    }

    /// Each camera's white balance (per-channel factors over its exposure).
    pub fn white_balance(&self) -> &[[f32; 3]] {
        self.opt.fit().white_balance()
    }

    /// Set each camera's exposure (positive).
    pub fn set_exposure(&mut self, values: &[f32]) -> Result<()> {
        self.opt.fit_mut().set_exposure(values)?;
        self.rendered = None;
        Ok(())
    }

    /// Set each camera's white balance (positive per channel).
    pub fn set_white_balance(&mut self, values: &[[f32; 3]]) -> Result<()> {
        self.opt.fit_mut().set_white_balance(values)?;
        self.rendered = None;
        Ok(())
    }

    /// Render every camera at the current parameters (`spp` samples per pixel from `seed`'s
    /// streams, independent of any backward's) with `primal` (None: the settings'), each
    /// image multiplied by its camera's exposure and white balance: what a loss compares
    /// with a photo.
    pub fn render(
        &mut self,
        spp: u32,
        seed: u32,
        primal: Option<PrimalMode>,
    ) -> Result<Vec<Image>> {
        let raw = self
            .opt
            .render_cameras(spp, seed, primal.unwrap_or(self.primal))?;
        let gains = self.opt.fit().gains();
        let images = raw
            .iter()
            .zip(&gains)
            .map(|(img, g)| Image {
                width: img.width,
                height: img.height,
                rgb: img
                    .rgb
                    .iter()
                    .map(|p| std::array::from_fn(|c| p[c] * g[c]))
                    .collect(),
            })
            .collect();
        self.rendered = Some(raw);
        Ok(images)
    }

    /// Every parameter's gradient of the loss whose dL/dI is `adjoint`, one image per camera,
    /// for the images of the last [`DiffRender::render`] (as it returned them, the gains
    /// applied). `seed` picks the gradient samples' streams (None: the settings' seed); they
    /// are mixed with the number of backward calls, so one seed serves a whole run. The
    /// gains' derivatives are exact for the rendered images: sum over pixels of the adjoint
    /// times the render.
    pub fn backward(&mut self, adjoint: &[Image], seed: Option<u32>) -> Result<Gradients> {
        let Some(raw) = self.rendered.as_ref() else {
            return Err(Error::Invalid(
                "backward needs a render at the current parameters first: call render() after \
                 setting them and before each backward (each backward pairs with one render)"
                    .into(),
            ));
        };
        let (w, h) = self.image_size();
        if adjoint.len() != self.opt.passes.cams.len() {
            return Err(Error::Invalid(format!(
                "{} adjoint images for {} cameras",
                adjoint.len(),
                self.opt.passes.cams.len()
            )));
        }
        if let Some(k) = adjoint
            .iter()
            .position(|a| (a.width, a.height) != (w, h) || a.rgb.len() != (w * h) as usize)
        {
            return Err(Error::Invalid(format!(
                "adjoint image {k} is {}x{}, the cameras render {w}x{h}",
                adjoint[k].width, adjoint[k].height
            )));
        }
        let gains = self.opt.fit().gains();
        // dL/d(gain) = sum of the adjoint times the render; the render's own adjoint is the
        // gain times the image's.
        let d_gain: Vec<[f64; 3]> = adjoint
            .iter()
            .zip(raw)
            .map(|(a, r)| {
                let mut d = [0f64; 3];
                for (p, q) in a.rgb.iter().zip(&r.rgb) {
                    for c in 0..3 {
                        d[c] += p[c] as f64 * q[c] as f64;
                    }
                }
                d
            })
            .collect();
        let flat: Vec<[f32; 3]> = adjoint
            .iter()
            .zip(&gains)
            .flat_map(|(a, g)| {
                a.rgb
                    .iter()
                    .map(move |p| std::array::from_fn(|c| p[c] * g[c]))
            })
            .collect();
        let seed = seed.unwrap_or(self.opt.settings.seed);
        let g = self.opt.backward(&flat, seed)?;
        self.rendered = None;
        // The updates the pass lost or dropped are counted when a step reads the gradient.
        let environment = if self.opt.fit.env_fit.is_some() {
            Some(self.opt.fit_mut().read_environment_gradient()?.0)
        } else {
            None
        };
        let (exposure, white_balance) = self.gain_parts(&d_gain);
        self.gain_gradient = Some(d_gain);
        Ok(Gradients {
            textures: self
                .opt
                .set
                .textures
                .iter()
                .map(|t| g[t.offset as usize..t.offset as usize + t.len()].to_vec())
                .collect(),
            environment,
            exposure,
            white_balance,
        })
    }

    /// dL/d(exposure) and dL/d(white balance) per camera from dL/d(gain).
    fn gain_parts(&self, d_gain: &[[f64; 3]]) -> (Vec<f32>, Vec<[f32; 3]>) {
        let (e, wb) = (self.opt.fit().exposure(), self.opt.fit().white_balance());
        d_gain
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let de: f64 = (0..3).map(|c| d[c] * wb[k][c] as f64).sum();
                (
                    de as f32,
                    std::array::from_fn(|c| (d[c] * e[k] as f64) as f32),
                )
            })
            .unzip()
    }

    /// The variance of each texel's last gradient estimate, where the estimator tracks one
    /// (the recursive estimator; ReSTIR with `own_variance`); None otherwise.
    pub fn gradient_variance(&self) -> Result<Option<Vec<Vec<f32>>>> {
        let Some(buf) = self.opt.plugins.estimator.variance() else {
            return Ok(None);
        };
        let v: Vec<f32> = self.opt.gpu.read_pod(buf)?;
        Ok(Some(
            self.opt
                .set
                .textures
                .iter()
                .map(|t| v[t.offset as usize..t.offset as usize + t.len()].to_vec())
                .collect(),
        ))
    }

    /// Tell the learning-rate schedule which fraction of the run is done (see
    /// [`Optimizer::set_progress`]).
    pub fn set_progress(&mut self, fraction: f64) {
        self.opt.set_progress(fraction);
    }

    /// The learning rate of each texture in the last step.
    pub fn last_learning_rates(&self) -> &[f32] {
        self.opt.last_learning_rates()
    }

    /// One step of the built-in optimizer (its step, Adam or the variance-scaled one with
    /// its filtered moments, the priors and the schedule; the environment's and the gains'
    /// Adam where they are optimized) from the last backward's gradient, or from `given`
    /// (every texture's, and the environment's and gains' where they are optimized; a
    /// gradient the caller computed or changed). The parameters change: render again
    /// before the next backward.
    pub fn step(&mut self, given: Option<&Gradients>) -> Result<()> {
        let d_log_gains = match given {
            Some(g) => self.upload_gradients(g)?,
            None => {
                let Some(d) = self.gain_gradient.as_ref() else {
                    return Err(Error::Invalid(
                        "step needs a gradient: call backward() first (each step uses the \
                         last backward's gradient once), or give the gradients"
                            .into(),
                    ));
                };
                let gains = self.opt.fit().gains();
                crate::optim::fit::gains::log_gain_gradients(d, &gains)
            }
        };
        self.gain_gradient = None;
        self.opt.prepare()?;
        let mut enc = self
            .opt
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("step"),
            });
        self.opt.passes.timer.begin();
        let iteration = self.steps;
        let factor = self.opt.encode_update(&mut enc, iteration, iteration + 1);
        self.opt.gpu.queue.submit([enc.finish()]);
        self.steps += 1;
        if self.opt.fit().gains_optimized() {
            self.opt.fit_mut().step_log_gains(factor, &d_log_gains);
        }
        self.opt.fit_mut().step_environment(factor)?;
        self.rendered = None;
        self.opt.gpu.check("step")
    }

    /// Write `g` where the step reads its gradients; returns d/d(log exposure) and
    /// d/d(log white balance).
    fn upload_gradients(&mut self, g: &Gradients) -> Result<(Vec<f32>, Vec<[f32; 3]>)> {
        let ts = &self.opt.set.textures;
        if g.textures.len() != ts.len() {
            return Err(Error::Invalid(format!(
                "{} texture gradients for {} textures",
                g.textures.len(),
                ts.len()
            )));
        }
        let mut all = vec![0f32; self.opt.set.values.len()];
        for (t, v) in ts.iter().zip(&g.textures) {
            check_gradient(&format!("texture `{}`", t.name()), v, t.len())?;
            all[t.offset as usize..t.offset as usize + t.len()].copy_from_slice(v);
        }
        self.opt
            .gpu
            .queue
            .write_buffer(&self.opt.bufs.grad, 0, bytemuck::cast_slice(&all));
        match (&self.opt.fit.env_fit, &g.environment) {
            (Some(f), Some(e)) => {
                let [w, h] = f.state.size;
                check_gradient("the environment", e, 3 * (w * h) as usize)?;
                let mut words: Vec<u32> = e.iter().map(|v| v.to_bits()).collect();
                words.extend([0, 0]);
                self.opt.gpu.queue.write_buffer(
                    &self.opt.fit.env_grad,
                    0,
                    bytemuck::cast_slice(&words),
                );
            }
            (Some(_), None) => {
                return Err(Error::Invalid(
                    "the environment is optimized: give its gradient too".into(),
                ))
            }
            (None, Some(_)) => {
                return Err(Error::Invalid(
                    "an environment gradient, but the environment is not a parameter (the \
                     task's [environment] does not optimize it)"
                        .into(),
                ))
            }
            (None, None) => {}
        }
        let n = self.opt.passes.cams.len();
        if !self.opt.fit().gains_optimized() {
            return Ok((vec![0.0; n], vec![[0.0; 3]; n]));
        }
        let flat: Vec<f32> = g.white_balance.iter().flatten().copied().collect();
        check_gradient("the exposures", &g.exposure, n)?;
        check_gradient("the white balances", &flat, 3 * n)?;
        let (e, wb) = (self.opt.fit().exposure(), self.opt.fit().white_balance());
        Ok((
            (0..n).map(|k| g.exposure[k] * e[k]).collect(),
            (0..n)
                .map(|k| std::array::from_fn(|c| g.white_balance[k][c] * wb[k][c]))
                .collect(),
        ))
    }

    /// Forget what the estimator carries over from earlier backward calls (ReSTIR's
    /// reservoirs, the recursive estimator's running estimate).
    pub fn reset_estimator(&mut self) -> Result<()> {
        self.opt.reset_estimator()
    }
}

/// `n` finite values, or an error naming `what`.
fn check_gradient(what: &str, v: &[f32], n: usize) -> Result<()> {
    if v.len() != n {
        return Err(Error::Invalid(format!(
            "the gradient of {what} has {} values, {n} expected",
            v.len()
        )));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(Error::Invalid(format!(
            "the gradient of {what} is not finite at index {i}"
        )));
    }
    Ok(())
}
