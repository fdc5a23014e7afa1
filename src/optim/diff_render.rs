//! A differentiable render with the loss left to the caller: [`Optimizer::render_cameras`]
//! renders every camera at the current textures, [`Optimizer::backward`] turns the adjoint
//! images of the caller's own loss (dL/dI per pixel) into each texel's gradient with the
//! optimizer's estimator, which keeps its state across calls as it does across iterations.
//! [`DiffRender`] wraps the two with the checks an application needs (one backward per
//! render, textures in range); the Python package is built on it.

use super::{pass_seed, Optimizer, PrimalMode, Seeds, Settings, StepKind};
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::render::params::{ParamSet, ParamTexture};
use crate::scene::Scene;
use crate::{Error, Result};

impl Optimizer {
    /// Render every camera of the optimizer at the current textures, `spp` samples per pixel
    /// from `seed`'s streams (camera `k` draws from `pass_seed(seed, 0, k, Seeds::PRIMAL)`),
    /// in one submission unless the samples need chunks (2^20 per dispatch), and read the
    /// images back: the forward half of a differentiable render. No loss, adjoint or
    /// estimator state changes.
    pub fn render_cameras(&mut self, spp: u32, seed: u32) -> Result<Vec<Image>> {
        if spp == 0 || spp > 1 << 16 {
            return Err(Error::Invalid(format!(
                "spp must be between 1 and 65536, not {spp}"
            )));
        }
        let (w, h) = (self.settings.width, self.settings.height);
        let n_pixels = w * h;
        let bytes = n_pixels as u64 * 16;
        let n_cams = self.cams.len() as u64;
        let gpu = &self.gpu;
        let images = self
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
        let mut enc = new_encoder(&self.gpu);
        for k in 0..self.cams.len() {
            let mut done = 0;
            while done < spp {
                let cam = &mut self.cams[k];
                let n = cam.set_samples(
                    &self.gpu.queue,
                    pass_seed(seed, 0, k as u32, Seeds::PRIMAL),
                    done,
                    chunk.min(spp - done),
                );
                if done == 0 {
                    enc.clear_buffer(&self.accum, 0, None);
                }
                self.renderer
                    .encode_render(&mut enc, "primal", &cam.render_group, self.grid, None);
                done += n;
                if done < spp {
                    // The next chunk writes this camera's uniform again: submit this one first.
                    self.gpu.queue.submit([enc.finish()]);
                    enc = new_encoder(&self.gpu);
                }
            }
            enc.copy_buffer_to_buffer(&self.accum, 0, &images, k as u64 * bytes, bytes);
        }
        self.gpu.queue.submit([enc.finish()]);
        let sums: Vec<[f32; 4]> = self.gpu.read_pod(&images)?;
        Ok(sums
            .chunks(n_pixels as usize)
            .take(self.cams.len())
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
        let n = (self.settings.width * self.settings.height) as usize * self.cams.len();
        if adjoint.len() != n {
            return Err(Error::Invalid(format!(
                "the adjoint has {} pixels, the cameras' images have {n} ({} cameras of {}x{})",
                adjoint.len(),
                self.cams.len(),
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
            &self.adjoint[(t % 2) as usize],
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

/// A differentiable render whose loss and optimizer belong to the caller: set the textures,
/// [`render`](DiffRender::render) the cameras, compute dL/dI of any loss, and
/// [`backward`](DiffRender::backward) gives each texel's gradient with the chosen estimator.
/// Each backward pairs with the render before it (a second backward, or one after the
/// textures changed, is refused): that is what keeps ReSTIR's reuse, which pairs each
/// gradient with the previous call's textures and adjoint, and every estimate, honest.
pub struct DiffRender {
    opt: Optimizer,
    /// Whether a render at the current textures has not been used by a backward yet.
    rendered: bool,
}

// The Python package holds a DiffRender across calls that release the interpreter.
const _: fn() = || {
    fn send<T: Send>() {}
    send::<DiffRender>();
};

impl DiffRender {
    /// A differentiable render of `scene` seen by `settings.cameras`, with the textures of
    /// `set` (at their initial values) as its parameters.
    pub fn new(gpu: &Gpu, scene: &Scene, set: ParamSet, settings: Settings) -> Result<DiffRender> {
        let settings = Settings {
            primal: PrimalMode::Independent,
            step: StepKind::Adam,
            multiscale_levels: 0,
            smoothness: 0.0,
            exposure_learning_rate: None,
            moment_filter: Default::default(),
            ..settings
        };
        // The loss pass is built but never run: placeholders of the images' size.
        let blank = Image {
            width: settings.width,
            height: settings.height,
            rgb: vec![[0.0; 3]; (settings.width * settings.height) as usize],
        };
        let targets = vec![blank; settings.cameras.len()];
        let opt = Optimizer::new(gpu, scene, set, settings, &targets)?;
        Ok(DiffRender {
            opt,
            rendered: false,
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

    /// Backward calls so far.
    pub fn iteration(&self) -> u32 {
        self.opt.iteration
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
        self.rendered = false;
        self.opt.gpu.check("set_texture")
    }

    /// Render every camera at the current textures (`spp` samples per pixel from `seed`'s
    /// streams, independent of any backward's).
    pub fn render(&mut self, spp: u32, seed: u32) -> Result<Vec<Image>> {
        let images = self.opt.render_cameras(spp, seed)?;
        self.rendered = true;
        Ok(images)
    }

    /// Each texture's gradient (laid out as [`DiffRender::texture`]) of the loss whose dL/dI
    /// is `adjoint`, one image per camera, for the images of the last [`DiffRender::render`].
    /// `seed` picks the gradient samples' streams (None: the settings' seed); they are mixed
    /// with the number of backward calls, so one seed serves a whole run.
    pub fn backward(&mut self, adjoint: &[Image], seed: Option<u32>) -> Result<Vec<Vec<f32>>> {
        if !self.rendered {
            return Err(Error::Invalid(
                "backward needs a render at the current textures first: call render() after \
                 setting the textures and before each backward (each backward pairs with one \
                 render)"
                    .into(),
            ));
        }
        let (w, h) = self.image_size();
        if adjoint.len() != self.opt.cams.len() {
            return Err(Error::Invalid(format!(
                "{} adjoint images for {} cameras",
                adjoint.len(),
                self.opt.cams.len()
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
        let flat: Vec<[f32; 3]> = adjoint.iter().flat_map(|a| a.rgb.iter().copied()).collect();
        let seed = seed.unwrap_or(self.opt.settings.seed);
        let g = self.opt.backward(&flat, seed)?;
        self.rendered = false;
        Ok(self
            .opt
            .set
            .textures
            .iter()
            .map(|t| g[t.offset as usize..t.offset as usize + t.len()].to_vec())
            .collect())
    }

    /// Forget what the estimator carries over from earlier backward calls (ReSTIR's
    /// reservoirs, the recursive estimator's running estimate).
    pub fn reset_estimator(&mut self) -> Result<()> {
        self.opt.reset_estimator()
    }
}
