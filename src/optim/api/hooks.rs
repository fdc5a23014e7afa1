//! Test hooks (feature `test-hooks`, which the crate's own tests turn on): one pass of the
//! optimizer run on given data and read back, so that a test can check the GPU pass
//! against its CPU twin. Not part of the library's interface.
use crate::optim::Optimizer;
use crate::{Error, Result};

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
