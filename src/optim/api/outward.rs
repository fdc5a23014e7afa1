//! The optimizer's passes run one at a time, outside its iteration: the forward and
//! backward halves of a differentiable render ([`DiffRender`](super::diff_render::DiffRender)
//! is built on them), gradients measured outside a step (the bench's error protocol and the
//! tests: an estimate under this iteration's or a given adjoint, and a converged adjoint),
//! the test hooks (feature `test-hooks`, which the crate's own tests turn on: one pass
//! run on given data and read back, so that a test can check the GPU pass against its CPU
//! twin; not part of the library's interface), and the engine as the outside makes and runs
//! it: from a [`Problem`] and through the run's loop.

use super::problem::Problem;
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::optim::{pass_seed, run_loop, Optimizer, PrimalMode, Progress, Seeds, Settings, Stop};
use crate::{Error, Result};

impl Optimizer {
    /// Render every camera at the current textures, `spp` samples per pixel from `seed`'s
    /// streams (camera `k` draws from `pass_seed(seed, 0, k, Seeds::PRIMAL)`), in one
    /// submission unless the samples need chunks (2^20 per dispatch), and read the images
    /// back: the forward half of a differentiable render. With `primal` the control variate
    /// (which the optimizer must have), each sample is also evaluated under the previous
    /// textures and the images are the control variate's `I_t` (src/optim/primal/), whose
    /// state advances once; otherwise no state changes. No loss, adjoint or estimator state
    /// changes either way.
    pub fn render_cameras(
        &mut self,
        spp: u32,
        seed: u32,
        primal: PrimalMode,
    ) -> Result<Vec<Image>> {
        if spp == 0 || spp > 1 << 16 {
            return Err(Error::Invalid(format!(
                "spp must be between 1 and 65536, not {spp}"
            )));
        }
        let two_states = primal == PrimalMode::ControlVariate;
        if two_states && self.passes.control_variate.is_none() {
            return Err(Error::Invalid(
                "this render has no control-variate primal (the optimizer was made with the \
                 independent one)"
                    .into(),
            ));
        }
        let (w, h) = (self.settings.width, self.settings.height);
        let n_pixels = w * h;
        let bytes = n_pixels as u64 * 16;
        let n_cams = self.passes.cams.len() as u64;
        let gpu = &self.gpu;
        let images = self
            .passes
            .camera_images
            .get_or_init(|| gpu.storage_zeroed("render_cameras images", bytes * n_cams))
            .clone();
        let chunk = ((1u32 << 20) / n_pixels).clamp(1, 64);
        let new_encoder = |gpu: &Gpu| {
            gpu.device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("render_cameras"),
                })
        };
        self.passes.timer.begin();
        let mut enc = new_encoder(&self.gpu);
        for k in 0..self.passes.cams.len() {
            let mut done = 0;
            while done < spp {
                let cam = &mut self.passes.cams[k];
                let n = cam.set_samples(
                    &self.gpu.queue,
                    pass_seed(seed, 0, k as u32, Seeds::PRIMAL),
                    done,
                    chunk.min(spp - done),
                    two_states,
                );
                if done == 0 {
                    enc.clear_buffer(&self.bufs.accum, 0, None);
                    if two_states {
                        enc.clear_buffer(&self.bufs.accum_prev, 0, None);
                    }
                }
                self.renderer.encode_render(
                    &mut enc,
                    "primal",
                    &cam.render_group,
                    self.passes.grid,
                    None,
                );
                done += n;
                if done < spp {
                    // The next chunk writes this camera's uniform again: submit this one first.
                    self.gpu.queue.submit([enc.finish()]);
                    enc = new_encoder(&self.gpu);
                }
            }
            if let Some(cv) = self.passes.control_variate.as_mut().filter(|_| two_states) {
                // I_t replaces the render in accum.
                cv.encode(&mut enc, k, &mut self.passes.timer);
            }
            enc.copy_buffer_to_buffer(&self.bufs.accum, 0, &images, k as u64 * bytes, bytes);
        }
        self.gpu.queue.submit([enc.finish()]);
        if two_states {
            if let Some(cv) = &mut self.passes.control_variate {
                cv.finish_iteration();
            }
        }
        let sums: Vec<[f32; 4]> = self.gpu.read_pod(&images)?;
        Ok(sums
            .chunks(n_pixels as usize)
            .take(self.passes.cams.len())
            .map(|c| crate::render::accum_image(w, h, c))
            .collect())
    }

    /// The gradient of a loss whose derivative with respect to the rendered images is
    /// `adjoint` (dL/dI: RGB per pixel, row-major, the cameras one after another as
    /// [`Optimizer::render_cameras`] returns them), laid out like the parameters, estimated
    /// with the optimizer's estimator from `seed`'s streams (mixed with the iteration). The
    /// estimator's state advances one iteration, as an [`Optimizer::step`] advances it: ReSTIR
    /// pairs this call's samples with the textures and adjoint of the previous call. The
    /// textures do not change. Unbiased when the adjoint comes from a render whose random
    /// numbers are independent of the gradient's (another seed, or another stream of one).
    pub fn backward(&mut self, adjoint: &[[f32; 3]], seed: u32) -> Result<Vec<f32>> {
        let n = (self.settings.width * self.settings.height) as usize * self.passes.cams.len();
        if adjoint.len() != n {
            return Err(Error::Invalid(format!(
                "the adjoint has {} pixels, the cameras' images have {n} ({} cameras of {}x{})",
                adjoint.len(),
                self.passes.cams.len(),
                self.settings.width,
                self.settings.height
            )));
        }
        if let Some(i) = adjoint
            .iter()
            .position(|a| !a.iter().all(|v| v.is_finite()))
        {
            return Err(Error::Invalid(format!(
                "the adjoint is not finite at pixel {i} (counting through the cameras)"
            )));
        }
        // The w component says whether the loss pass's own gain derivative may read the
        // adjoint; an external adjoint is not one it wrote.
        let rgba: Vec<[f32; 4]> = adjoint.iter().map(|a| [a[0], a[1], a[2], 0.0]).collect();
        let t = self.iteration;
        self.gpu.queue.write_buffer(
            &self.bufs.adjoint[(t % 2) as usize],
            0,
            bytemuck::cast_slice(&rgba),
        );
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("backward"),
            });
        self.encode_gradient_seeded(&mut enc, t, false, seed);
        self.gpu.queue.submit([enc.finish()]);
        self.finish_iteration(false);
        self.iteration = t + 1;
        let g = self.read_gradient()?;
        self.gpu.check("backward")?;
        Ok(g)
    }
}

/// Measurements.
impl Optimizer {
    /// Restrict the gradient samples to light sampling or BSDF sampling (for area and
    /// environment lights; delta lights always use light sampling), or return to MIS: a
    /// diagnostic for the tests, which check that the techniques agree in expectation. The
    /// baseline estimator only; the others refuse.
    pub fn set_gradient_techniques(&mut self, techniques: crate::render::Techniques) -> Result<()> {
        self.plugins.estimator.set_techniques(techniques)
    }

    /// Forget what the gradient estimator carries over from earlier iterations (ReSTIR's
    /// reservoirs, the recursive estimator's running estimate and variances): the next
    /// iteration starts it afresh, as the first one did. The textures, the step's moments and the
    /// previous iteration's textures and adjoint are left as they are.
    pub fn reset_estimator(&mut self) -> Result<()> {
        self.plugins
            .estimator
            .restore(&self.gpu, None, self.iteration)
    }

    /// One gradient estimate at the current textures, as iteration `iteration` would draw it,
    /// without changing the textures. For ReSTIR this advances the reservoirs like an
    /// iteration does. Returns (gradient laid out like the parameters, loss).
    pub fn estimate_gradient(&mut self, iteration: u32) -> Result<(Vec<f32>, f64)> {
        self.submit_gradient("gradient estimate", iteration, true);
        let loss = self.read_loss()?;
        Ok((self.read_gradient()?, loss))
    }

    /// The adjoint that the primal render of `iteration` wrote (RGBA per pixel, the cameras
    /// one after another, as [`Optimizer::estimate_gradient_with_adjoint`] takes it): read
    /// right after [`Optimizer::estimate_gradient`] for that iteration, the adjoint its
    /// gradient was estimated under.
    pub fn read_adjoint(&self, iteration: u32) -> Result<Vec<f32>> {
        self.gpu
            .read_pod(&self.bufs.adjoint[(iteration % 2) as usize])
    }

    /// [`Optimizer::estimate_gradient`] with a given adjoint (RGBA per pixel, the cameras one
    /// after another, as [`Optimizer::converged_adjoint`] returns it) instead of the one of
    /// the iteration's own primal render: the gradient estimator alone, without the noise of
    /// the adjoint. Returns the gradient.
    pub fn estimate_gradient_with_adjoint(
        &mut self,
        iteration: u32,
        adjoint: &[f32],
    ) -> Result<Vec<f32>> {
        let buf = &self.bufs.adjoint[(iteration % 2) as usize];
        if adjoint.len() as u64 * 4 != buf.size() {
            return Err(Error::Invalid(format!(
                "the adjoint has {} floats, the optimizer's images need {}",
                adjoint.len(),
                buf.size() / 4
            )));
        }
        self.gpu
            .queue
            .write_buffer(buf, 0, bytemuck::cast_slice(adjoint));
        self.submit_gradient("gradient estimate (given adjoint)", iteration, false);
        self.read_gradient()
    }

    /// Submit iteration `iteration`'s gradient passes in one command buffer labelled `label`
    /// (its primal render and loss first with `primal`), the textures held.
    fn submit_gradient(&mut self, label: &str, iteration: u32, primal: bool) {
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        self.encode_gradient(&mut enc, iteration, primal);
        self.gpu.queue.submit([enc.finish()]);
        self.finish_iteration(primal);
    }

    /// The adjoint of the loss at the current textures from a primal render of `spp` samples
    /// per pixel (a converged one for `spp` in the hundreds), and that render's loss. It is
    /// computed in the adjoint buffer that the next iteration overwrites, so the optimizer's
    /// state (a ReSTIR optimizer's previous adjoint included) is unchanged. `seed` picks the
    /// random numbers.
    pub fn converged_adjoint(&mut self, spp: u32, seed: u32) -> Result<(Vec<f32>, f64)> {
        if spp == 0 {
            return Err(Error::Invalid(
                "converged_adjoint: spp must be at least 1".into(),
            ));
        }
        let parity = (self.iteration % 2) as usize;
        let n_pixels = self.settings.width * self.settings.height;
        let chunk = ((1u32 << 20) / n_pixels).clamp(1, 64);
        for k in 0..self.passes.cams.len() {
            let mut done = 0;
            while done < spp {
                let cam = &mut self.passes.cams[k];
                let n = cam.set_samples(
                    &self.gpu.queue,
                    pass_seed(seed, u32::MAX - 3, k as u32, Seeds::PRIMAL),
                    done,
                    chunk.min(spp - done),
                    false,
                );
                let mut enc =
                    self.gpu
                        .device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some("converged primal"),
                        });
                if done == 0 {
                    enc.clear_buffer(&self.bufs.accum, 0, None);
                }
                self.renderer.encode_render(
                    &mut enc,
                    "primal",
                    &cam.render_group,
                    self.passes.grid,
                    None,
                );
                done += n;
                if done >= spp {
                    self.passes.loss.encode(&mut enc, k, parity, None);
                }
                self.gpu.queue.submit([enc.finish()]);
                self.gpu.wait("converged primal")?;
            }
        }
        let adjoint = self.gpu.read_pod(&self.bufs.adjoint[parity])?;
        Ok((adjoint, self.read_loss()?))
    }
}

/// Test hooks.
#[cfg(feature = "test-hooks")]
impl Optimizer {
    /// The loss pass on the GPU applied to `images` (one per camera, as renders before the
    /// gains): each written where the primal render leaves its image, the pass run for
    /// iteration 0, and the loss and the adjoint images read back (RGB per pixel, the cameras
    /// one after another). For tests against [`crate::optim::loss::loss`] and
    /// [`crate::optim::loss::adjoint`].
    pub fn apply_loss(
        &mut self,
        images: &[crate::image_io::Image],
    ) -> Result<(f64, Vec<[f32; 3]>)> {
        if images.len() != self.passes.cams.len() {
            return Err(Error::Invalid(format!(
                "apply_loss: {} images for {} cameras",
                images.len(),
                self.passes.cams.len()
            )));
        }
        for (k, img) in images.iter().enumerate() {
            let rgba: Vec<[f32; 4]> = img.rgb.iter().map(|p| [p[0], p[1], p[2], 1.0]).collect();
            self.gpu
                .queue
                .write_buffer(&self.bufs.accum, 0, bytemuck::cast_slice(&rgba));
            let mut enc = self
                .gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("apply_loss"),
                });
            self.passes.loss.encode(&mut enc, k, 0, None);
            self.gpu.queue.submit([enc.finish()]);
        }
        let loss = self.read_loss()?;
        let a = self.read_adjoint(0)?;
        Ok((loss, a.chunks(4).map(|c| [c[0], c[1], c[2]]).collect()))
    }

    /// `grad` (laid out like the parameters) written to the gradient buffer, transformed on
    /// the GPU by the passes `encode` records, and read back: how the tests check a pass that
    /// acts on the gradient before Adam against its CPU twin. `what` names the caller in
    /// errors.
    pub(crate) fn transform_gradient(
        &mut self,
        what: &str,
        grad: &[f32],
        encode: impl FnOnce(&mut Optimizer, &mut wgpu::CommandEncoder),
    ) -> Result<Vec<f32>> {
        if grad.len() != self.set.values.len() {
            return Err(Error::Invalid(format!(
                "{what}: {} values for {} parameters",
                grad.len(),
                self.set.values.len()
            )));
        }
        self.gpu
            .queue
            .write_buffer(&self.bufs.grad, 0, bytemuck::cast_slice(grad));
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(what) });
        self.passes.timer.begin();
        encode(self, &mut enc);
        self.gpu.queue.submit([enc.finish()]);
        self.read_gradient()
    }

    /// `grad` (laid out like the parameters) through the prior called `name` on the GPU, as
    /// iteration `iteration` applies it: it is written to the gradient buffer, transformed
    /// and read back. For tests against the prior's CPU reference; an error when the settings
    /// do not switch that prior on.
    pub fn apply_prior(&mut self, name: &str, grad: &[f32], iteration: u32) -> Result<Vec<f32>> {
        let what = format!("apply_prior({name})");
        self.prepare()?;
        // Taken out for the call, which borrows the optimizer, and put back after.
        let mut priors = self.plugins.priors.take().unwrap_or_default();
        let seed = self.settings.seed;
        let result = match priors.iter().position(|(k, _)| k.name == name) {
            Some(k) => self.transform_gradient(&what, grad, |opt, enc| {
                priors[k]
                    .1
                    .encode(&opt.gpu, enc, seed, iteration, &mut opt.passes.timer)
            }),
            None => Err(Error::Invalid(format!(
                "{what}: the settings do not ask for this prior"
            ))),
        };
        self.plugins.priors = Some(priors);
        result
    }

    /// The multiscale pass of `iteration` applied to `grad` ([`Optimizer::apply_prior`]),
    /// for tests against [`crate::optim::multiscale::reference`].
    pub fn apply_multiscale(&mut self, grad: &[f32], iteration: u32) -> Result<Vec<f32>> {
        self.apply_prior("multiscale", grad, iteration)
    }

    /// The gradient `grad` plus the smoothness prior's derivative at the current parameters
    /// ([`Optimizer::apply_prior`]), for tests against [`crate::optim::smoothness::reference`].
    pub fn apply_smoothness(&mut self, grad: &[f32]) -> Result<Vec<f32>> {
        let it = self.iteration;
        self.apply_prior("smoothness", grad, it)
    }

    /// The moment filter on the GPU applied to `pair` (two arrays laid out like the
    /// parameters), guided by the current textures: texture by texture, the pair is written to
    /// the filter's input, filtered and read back. For tests against [`crate::optim::moment_filter::reference`]; an error
    /// when the settings have no moment filter. The optimizer's moments are not touched.
    pub fn apply_moment_filter(&mut self, pair: [&[f32]; 2]) -> Result<[Vec<f32>; 2]> {
        let n = self.set.values.len();
        if pair.iter().any(|p| p.len() != n) {
            return Err(crate::Error::Invalid(format!(
                "apply_moment_filter: the pair must have {n} values each"
            )));
        }
        let filter = self.plugins.step.filter();
        let f = filter.ok_or_else(|| {
            crate::Error::Invalid("apply_moment_filter: the settings have no moment filter".into())
        })?;
        let mut out = [vec![0.0f32; n], vec![0.0f32; n]];
        for (k, t) in self.set.textures.iter().enumerate() {
            let range = t.offset as usize..t.offset as usize + t.len();
            for (buf, p) in f.input().iter().zip(pair) {
                let values = bytemuck::cast_slice(&p[range.clone()]);
                self.gpu.queue.write_buffer(buf, 0, values);
            }
            let mut enc = self
                .gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("apply_moment_filter"),
                });
            self.passes.timer.begin();
            f.encode(&mut enc, k, &mut self.passes.timer);
            self.gpu.queue.submit([enc.finish()]);
            for (o, buf) in out.iter_mut().zip(f.output()) {
                let filtered: Vec<f32> = self.gpu.read_pod(buf)?;
                o[range.clone()].copy_from_slice(&filtered[..t.len()]);
            }
        }
        Ok(out)
    }
}

/// The optimizer made for a problem, and run by the run's loop.
impl Optimizer {
    /// An optimizer for `problem`: its scene, textures and targets, with the sampling options
    /// of `settings` (whose cameras, width and height are taken from the problem).
    pub fn for_problem(gpu: &Gpu, problem: &Problem, settings: Settings) -> Result<Optimizer> {
        let first = problem.targets.first().ok_or_else(|| {
            crate::Error::Invalid("the problem has no targets: set or render them first".into())
        })?;
        let settings = Settings {
            width: first.width,
            height: first.height,
            cameras: problem.cameras.clone(),
            ..settings
        };
        let mut opt = Optimizer::new(
            gpu,
            &problem.scene,
            problem.set.clone(),
            settings,
            &problem.targets,
        )?;
        if problem.masks.iter().any(Option::is_some) {
            opt.set_masks(&problem.masks)?;
        }
        problem.set_camera_and_light(&mut opt)?;
        Ok(opt)
    }

    /// Run iterations until `stop`, calling `on_iteration` after each; the callback returns
    /// [`ControlFlow::Break`](std::ops::ControlFlow::Break) to stop early. Returns the
    /// progress after the last iteration run (`None` if none ran). The learning-rate
    /// schedule runs over this call: its progress is the larger of the fractions of
    /// `stop`'s iterations and time budget done.
    pub fn run(
        &mut self,
        stop: Stop,
        on_iteration: impl FnMut(&Progress) -> std::ops::ControlFlow<()>,
    ) -> Result<Option<Progress>> {
        run_loop::run(self, stop, on_iteration)
    }
}
