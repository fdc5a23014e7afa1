//! An optimization problem in memory: the scene, the cameras, the textures to recover and one
//! target image per camera, and the optimizer made for it ([`Optimizer::for_problem`]). An
//! application builds one from data it already holds ([`Problem::new`]); a task file
//! describes one (`Problem::from_task`, in `job`).
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::optim::{pass_seed, Optimizer};
use crate::render::params::ParamSet;
use crate::render::{RenderSettings, Renderer, Techniques};
use crate::scene::Scene;
use crate::vocab::{Filter, TextureSpec};
use crate::{Error, Result};
use std::path::Path;

/// Scenes, targets and textures of an optimization, ready for an
/// [`Optimizer`](crate::optim::Optimizer).
#[derive(Clone, Debug)]
pub struct Problem {
    /// The scene to optimize (its geometry, lights and cameras are known and fixed).
    pub scene: Scene,
    /// Ground-truth scene, when the targets were rendered from one.
    pub truth: Option<Scene>,
    /// The cameras rendered every iteration (indices into `scene.cameras`).
    pub cameras: Vec<usize>,
    /// One target image per camera, in the order of `cameras` (empty until set).
    pub targets: Vec<Image>,
    /// The optimized textures, laid out in one array, at their initial values.
    pub set: ParamSet,
    /// Ground-truth texture values laid out like `set.values`, when known.
    pub reference: Option<Vec<f32>>,
    /// Per camera, a weight per pixel of its loss and gradient (0 leaves the pixel out);
    /// None: every pixel counts fully.
    pub masks: Vec<Option<Vec<f32>>>,
    /// Per camera, the factor its render is multiplied by before the comparison (the
    /// starting value when exposures are optimized).
    pub exposure: Vec<f32>,
    /// Per camera, the image a camera file gave its frame, if any.
    pub frame_images: Vec<Option<std::path::PathBuf>>,
    /// The environment recovered with the textures, when it is not known: where it starts
    /// (the scene's environment is that start) and how it is stepped.
    pub environment: Option<EnvironmentFit>,
    /// The learning rate of the cameras' white balances, when they are optimized
    /// ([`FitMut::optimize_white_balance`](crate::optim::FitMut::optimize_white_balance)).
    pub white_balance_learning_rate: Option<f32>,
}

/// An environment to recover ([`Problem::recover_environment`]).
#[derive(Clone, Debug)]
pub struct EnvironmentFit {
    /// The starting environment.
    pub start: crate::scene::EnvMap,
    /// How it is stepped.
    pub options: crate::optim::environment_fit::EnvFitOptions,
}

impl Problem {
    /// A problem on `scene` seen by `cameras`, recovering `textures` (checked as a task file's
    /// `[[textures]]` are). Give it targets with [`Problem::set_targets`] or
    /// [`Problem::render_targets`] before optimizing.
    pub fn new(
        scene: Scene,
        cameras: Vec<usize>,
        textures: &[TextureSpec],
        filter: Filter,
    ) -> Result<Problem> {
        if cameras.is_empty() {
            return Err(Error::Invalid("a problem needs at least one camera".into()));
        }
        if let Some(&c) = cameras.iter().find(|&&c| c >= scene.cameras.len()) {
            return Err(Error::Invalid(format!(
                "camera {c} does not exist (the scene has {})",
                scene.cameras.len()
            )));
        }
        if textures.is_empty() {
            return Err(Error::Invalid(
                "name at least one texture to optimize".into(),
            ));
        }
        for (i, t) in textures.iter().enumerate() {
            crate::vocab::check_texture(t, &textures[..i])
                .map_err(|(key, msg)| Error::Invalid(format!("textures[{i}].{key}: {msg}")))?;
        }
        let set = ParamSet::from_specs(&scene, textures, filter, Path::new("<problem>"))?;
        Ok(Problem::without_targets(scene, cameras, set))
    }

    pub(crate) fn without_targets(scene: Scene, cameras: Vec<usize>, set: ParamSet) -> Problem {
        let n = cameras.len();
        Problem {
            scene,
            truth: None,
            cameras,
            targets: Vec::new(),
            set,
            reference: None,
            masks: vec![None; n],
            exposure: vec![1.0; n],
            frame_images: vec![None; n],
            environment: None,
            white_balance_learning_rate: None,
        }
    }

    /// Recover the environment with the textures, from `start` (which replaces the scene's
    /// environment; the ground truth keeps its own).
    pub fn recover_environment(
        &mut self,
        start: crate::scene::EnvMap,
        options: crate::optim::environment_fit::EnvFitOptions,
    ) -> Result<()> {
        options
            .check()
            .map_err(|(k, m)| Error::Invalid(format!("environment.{k}: {m}")))?;
        self.scene.env = Some(start.clone());
        self.environment = Some(EnvironmentFit { start, options });
        Ok(())
    }

    /// Use `images` as the targets, one per camera, all `width` x `height`.
    pub fn set_targets(&mut self, images: Vec<Image>) -> Result<()> {
        if images.len() != self.cameras.len() {
            return Err(Error::Invalid(format!(
                "{} target images for {} cameras",
                images.len(),
                self.cameras.len()
            )));
        }
        if let Some(i) = images
            .iter()
            .position(|im| (im.width, im.height) != (images[0].width, images[0].height))
        {
            return Err(Error::Invalid(format!(
                "target {i} is {}x{}, target 0 is {}x{}",
                images[i].width, images[i].height, images[0].width, images[0].height
            )));
        }
        self.targets = images;
        Ok(())
    }

    /// Render the targets from `truth` (the same geometry and cameras with the true
    /// materials) at `spp` samples per pixel, and take the ground-truth texture values from
    /// it for texture RMSE. The seed of camera `k` derives from `seed` as in a task run.
    pub fn render_targets(
        &mut self,
        gpu: &Gpu,
        truth: Scene,
        width: u32,
        height: u32,
        spp: u32,
        seed: u32,
    ) -> Result<()> {
        if truth.cameras.len() != self.scene.cameras.len() {
            return Err(Error::Invalid(
                "the target scene's cameras differ from the scene's".into(),
            ));
        }
        let r = Renderer::new(gpu, &truth)?;
        let mut targets = Vec::new();
        for (k, &camera) in self.cameras.iter().enumerate() {
            let settings = RenderSettings {
                width,
                height,
                spp,
                seed: pass_seed(seed, u32::MAX, k as u32, 2),
                camera,
                techniques: Techniques::Mis,
            };
            targets.push(r.render(&settings, |_| {})?.image);
        }
        self.set_truth(truth)?;
        self.targets = targets;
        Ok(())
    }

    /// Record the ground-truth scene and take the reference texture values from it.
    pub(crate) fn set_truth(&mut self, truth: Scene) -> Result<()> {
        let mut all = Vec::with_capacity(self.set.values.len());
        for i in 0..self.set.textures.len() {
            all.extend(self.set.reference_values(i, &truth).ok_or_else(|| {
                Error::Invalid(format!(
                    "the target scene has no material `{}`",
                    self.set.textures[i].material_name
                ))
            })?);
        }
        self.reference = Some(all);
        self.truth = Some(truth);
        Ok(())
    }
}

impl Problem {
    /// The RMSE of `values` (laid out like `set.values`) against the ground truth over every
    /// texel, normal maps as the renderer reads them ([`crate::optim::observed::texture_rmse`]);
    /// None without a ground truth.
    pub fn texture_rmse(&self, values: &[f32]) -> Option<f64> {
        let r = self.reference.as_ref()?;
        Some(crate::optim::observed::texture_rmse(&self.set, values, r))
    }

    /// Give `opt` the problem's cameras' exposures, the environment's fit and the white
    /// balances' rate: what an optimizer (or a differentiable render, whose loss is the
    /// caller's) takes from the problem besides its targets and masks.
    pub fn set_camera_and_light(&self, opt: &mut Optimizer) -> Result<()> {
        if self.exposure.iter().any(|&e| e != 1.0) {
            opt.fit_mut().set_exposure(&self.exposure)?;
        }
        if let Some(e) = &self.environment {
            opt.fit_mut()
                .optimize_environment(&e.start, e.options.clone())?;
        }
        if let Some(lr) = self.white_balance_learning_rate {
            opt.fit_mut().optimize_white_balance(lr)?;
        }
        Ok(())
    }
}
