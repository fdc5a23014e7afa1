//! Gradients measured outside an optimization step (the bench's error protocol and the
//! tests): an estimate under this iteration's or a given adjoint, and a converged adjoint.

use crate::optim::{pass_seed, Optimizer, Seeds};
use crate::{Error, Result};

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
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("gradient estimate"),
            });
        self.encode_gradient(&mut enc, iteration, true);
        self.gpu.queue.submit([enc.finish()]);
        self.finish_iteration(true);
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
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("gradient estimate (given adjoint)"),
            });
        self.encode_gradient(&mut enc, iteration, false);
        self.gpu.queue.submit([enc.finish()]);
        self.finish_iteration(false);
        self.read_gradient()
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
