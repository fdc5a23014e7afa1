//! Texture optimization on the GPU. At this folder's root the engine, [`Optimizer`]: primal
//! render ([`primal`]), loss and adjoint ([`loss`]), a gradient estimator ([`estimator`]:
//! the baseline, ReSTIR or the recursive control variate), the priors ([`prior`]) and a
//! step ([`step`]: Adam or the variance-scaled step, with or without filtered moments), as
//! one submission per iteration; the three kinds of plugin share one shape ([`registry`]).
//! Around it, a room per role: the run (`run/`: loop, schedule, seeds, checkpoints), the fit
//! of the light and the cameras' response (`fit/`) and what the optimizer offers outside its
//! iteration (`api/`: `DiffRender`, the problem, export, uncertainty, measurements).

mod api;
mod cameras;
pub mod estimator;
mod fit;
pub mod loss;
mod memory;
pub mod observed;
mod parts;
#[cfg(test)]
mod plane_tests;
pub mod primal;
pub mod prior;
pub mod registry;
mod run;
mod settings;
pub mod step;
mod timing;
pub use api::diff_render::{DiffRender, Gradients};
pub use api::{texture_export, uncertainty};
pub use fit::{environment_fit, param_table, Fit, FitMut};
pub use memory::*;
pub use run::seeds::*;
pub use run::snapshot::*;
pub use run::{checkpoint, run_loop, schedule};
pub use settings::*;
pub use timing::*;

use crate::gpu::abi::stat;
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::render::params::{ParamBuffers, ParamSet};
use crate::render::{Renderer, Techniques};
use crate::scene::Scene;
use crate::{Error, Result};
use cameras::{camera_passes, check_inputs, CameraSetup};
pub use estimator::{Choice, EstimatorOptions, EstimatorState, Method, MethodChoice};
use parts::{build_step, pass_timer, Inputs, IterationBuffers, Passes, Plugins};
pub use primal::path_cache::PathCacheSnapshot;
pub use primal::{ControlVariateSnapshot, PrimalMode};
pub use prior::{multiscale, smoothness, Priors};
/// The optimizer's own passes besides the steps', priors' and estimators' (a pass is named
/// after its file, which lies beside its driver in this folder).
pub(crate) const WGSL: &[(&str, &str)] = &[
    ("loss", include_str!("loss/loss.wgsl")),
    ("primal_cv", include_str!("primal/primal_cv.wgsl")),
    ("primal_cached", include_str!("primal/primal_cached.wgsl")),
    (
        "primal_cache_trace",
        include_str!("primal/primal_cache_trace.wgsl"),
    ),
    ("primal/path_cache", include_str!("primal/path_cache.wgsl")),
    (
        "observed_texels",
        include_str!("observed/observed_texels.wgsl"),
    ),
    ("texture_export", include_str!("api/texture_export.wgsl")),
];

pub use api::problem::{EnvironmentFit, Problem};
pub use schedule::{Schedule, ScheduleKind};
pub use step::variance_step::VarianceStepOptions;
pub use step::{adam, moment_filter, variance_step, StepKind, Steps};

/// The optimizer: a scene on the GPU with its optimized textures, targets, and the passes.
pub struct Optimizer {
    gpu: Gpu,
    renderer: Renderer,
    /// The optimized textures' values, current and previous (the renderer binds them).
    params: ParamBuffers,
    /// Layout and learning rates of the optimized textures (values as at creation).
    pub set: ParamSet,
    settings: Settings,
    /// The buffers one iteration's passes hand each other.
    bufs: IterationBuffers,
    /// The passes the engine runs itself, per camera and once.
    passes: Passes,
    /// The gradient estimator, the step and the priors.
    plugins: Plugins,
    /// The targets and the texels they observe.
    inputs: Inputs,
    /// The fit of the light and the cameras' response.
    fit: fit::Fit,
    /// Where the run stands, for the schedule and the log.
    run: run::RunState,
    /// Iterations done (steps taken).
    pub iteration: u32,
}

/// The constants of the settings' cameras at the settings' image size, each with the
/// lights of its capture.
fn camera_infos(
    scene: &crate::render::GpuScene,
    settings: &Settings,
) -> Result<Vec<crate::render::layout::GpuCameraInfo>> {
    settings
        .cameras
        .iter()
        .map(|&cam| scene.camera_info(cam, settings.width, settings.height))
        .collect()
}

impl Optimizer {
    /// Upload the scene with its optimized textures and one target image per camera.
    pub fn new(
        gpu: &Gpu,
        scene: &Scene,
        set: ParamSet,
        settings: Settings,
        targets: &[Image],
    ) -> Result<Optimizer> {
        let (w, h) = (settings.width, settings.height);
        check_inputs(&settings, targets)?;
        // Textures and scene first: the texels the paths reach decide what ReSTIR allocates.
        let depth = scene.max_depth.get();
        let settings = primal::path_cache::usable(gpu, settings, depth);
        memory_plan(&set, &settings, targets.len(), 0, depth).check(gpu)?;
        let params = ParamBuffers::new(gpu, &set);
        let renderer = Renderer::with_param_buffers(gpu, scene, &set, &params)?;
        let camera_infos = camera_infos(&renderer.scene, &settings)?;
        let grid = renderer.tile_grid(w, h);
        let observed = observed::observed_mask(gpu, &renderer.scene, &camera_infos, grid)?;
        let n_state = state_texels(&observed.0, settings.method, depth);
        let plan = memory_plan(&set, &settings, targets.len(), n_state, depth);
        plan.check(gpu)?;
        log::info!("{}", plan.summary());
        let n_cams = targets.len() as u32;
        let bufs = IterationBuffers::new(gpu, (w, h), n_cams, set.values.len() as u64);
        let control_variate = parts::control_variate(gpu, &settings, targets.len(), &bufs)?;
        let loss = loss::LossPass::new(
            gpu,
            settings.loss,
            (w, h),
            targets,
            &bufs.accum,
            &bufs.adjoint,
        )?;
        let env_grad = environment_fit::env_gradient_buffer(gpu, scene);
        let estimator = estimator::build(&estimator::Setup {
            gpu,
            scene: &renderer.scene,
            set: &set,
            method: settings.method,
            options: &settings.estimator_options,
            gradient_spp: settings.gradient_spp,
            width: settings.width,
            height: settings.height,
            primal: settings.primal,
            cameras: &camera_infos,
            adjoint: &bufs.adjoint,
            grad: &bufs.grad,
            env_grad: &env_grad,
            grid,
            observed: &observed.0,
        })?;

        let cache_for = (&renderer, &camera_infos[..], grid);
        let path_cache = primal::path_cache::build(gpu, cache_for, (&settings, depth), &bufs)?;
        let cams = camera_passes(&CameraSetup {
            gpu,
            renderer: &renderer,
            settings: &settings,
            camera_infos: &camera_infos,
            grid,
            two_states: control_variate.is_some(),
            accum: &bufs.accum,
            accum_prev: &bufs.accum_prev,
            stats: &bufs.stats,
        });
        let step = build_step(
            gpu,
            (&set, &params),
            &settings,
            &observed.1,
            &bufs,
            estimator.as_ref(),
        )?;
        let timer = pass_timer(gpu, n_cams, set.textures.len(), step.as_ref());
        gpu.check("optimizer setup")?;
        let table = param_table::ParamTable::new(targets.len(), &settings);
        Ok(Optimizer {
            gpu: gpu.clone(),
            renderer,
            params,
            set,
            settings,
            bufs,
            passes: Passes {
                cams,
                loss,
                grid,
                control_variate,
                path_cache,
                timer,
                export_pipeline: std::sync::OnceLock::new(),
                camera_images: std::sync::OnceLock::new(),
            },
            plugins: Plugins {
                estimator,
                step,
                priors: None,
            },
            fit: fit::Fit {
                table,
                gain_prev: vec![[1.0; 3]; targets.len()],
                env_grad,
                env_fit: None,
                env_faults: 0,
            },
            inputs: Inputs {
                targets: targets.to_vec(),
                observed,
            },
            run: run::RunState::default(),
            iteration: 0,
        })
    }

    /// The renderer holding the scene and the current textures.
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// The sampling settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Record the primal render and loss of every camera at `spp` samples per pixel into
    /// `adjoint[iteration % 2]`, with the seeds of iteration `iteration` (in chunks of at most
    /// `chunk` samples; each chunk after the first needs its own submission, see
    /// [`Optimizer::converged_adjoint`]).
    fn encode_primal(&mut self, enc: &mut wgpu::CommandEncoder, iteration: u32) {
        let parity = (iteration % 2) as usize;
        for (k, cam) in self.passes.cams.iter_mut().enumerate() {
            cam.render_params.seed =
                pass_seed(self.settings.seed, iteration, k as u32, Seeds::PRIMAL);
            cam.render_params.sample_offset = 0;
            cam.render_params.spp = self.settings.primal_spp;
            cam.render_params.two_states = self.passes.control_variate.is_some() as u32;
            self.gpu.queue.write_buffer(
                &cam.render_uniform,
                0,
                bytemuck::bytes_of(&cam.render_params),
            );
            enc.clear_buffer(&self.bufs.accum, 0, None);
            if self.passes.control_variate.is_some() {
                enc.clear_buffer(&self.bufs.accum_prev, 0, None);
            }
            if let Some(cache) = &mut self.passes.path_cache {
                cache.encode(
                    enc,
                    &self.renderer.scene.bind_group,
                    k,
                    cam.render_params.seed,
                    cam.render_params.two_states != 0,
                    self.passes.grid,
                    &mut self.passes.timer,
                );
            } else {
                let t = self.passes.timer.next(PassKind::Primal);
                self.renderer
                    .encode_render(enc, "primal", &cam.render_group, self.passes.grid, t);
            }
            if let Some(cv) = &mut self.passes.control_variate {
                cv.encode(enc, k, &mut self.passes.timer);
            }
            let t = self.passes.timer.next(PassKind::Loss);
            self.passes.loss.encode(enc, k, parity, t);
        }
    }

    /// Record iteration `iteration` up to the gradient (in `grad`): the primal render and
    /// loss of every camera (unless the adjoint was written already), the estimator's passes,
    /// and the copy of the textures that the next iteration calls previous.
    fn encode_gradient(&mut self, enc: &mut wgpu::CommandEncoder, iteration: u32, primal: bool) {
        self.encode_gradient_seeded(enc, iteration, primal, self.settings.seed);
    }

    /// [`Optimizer::encode_gradient`] with the gradient samples drawn from `seed`'s streams.
    fn encode_gradient_seeded(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        iteration: u32,
        primal: bool,
        seed: u32,
    ) {
        self.passes.timer.begin();
        self.fit.clear_environment_gradient(enc);
        if primal {
            self.encode_primal(enc, iteration);
        }
        let frame = estimator::Frame {
            iteration,
            seed,
            scene_group: &self.renderer.scene.bind_group,
            schedule_factor: self.settings.schedule.factor(iteration, self.run.progress),
        };
        self.plugins
            .estimator
            .encode(enc, &frame, &mut self.passes.timer);
        if self.uses_previous_state() {
            self.params.encode_copy_to_previous(enc);
        }
    }

    /// Whether the next iteration needs this one's textures (ReSTIR's merge, the recursive
    /// estimator, the control variate).
    fn uses_previous_state(&self) -> bool {
        self.plugins.estimator.uses_previous_state() || self.passes.control_variate.is_some()
    }

    /// Bookkeeping once an iteration's work is submitted.
    fn finish_iteration(&mut self, primal: bool) {
        self.plugins.estimator.finish_iteration();
        if primal {
            if let Some(cv) = &mut self.passes.control_variate {
                cv.finish_iteration();
            }
            if let Some(cache) = &mut self.passes.path_cache {
                cache.finish_iteration();
            }
        }
    }

    fn read_loss(&self) -> Result<f64> {
        self.passes.loss.read_loss(&self.gpu)
    }

    /// The passes (WGSL files) that an optimizer with `settings` creates, its estimator's
    /// first (the slowest to compile), without the renderer's (`render`, `trace_rays`),
    /// which a [`Problem`] creates first. [`Gpu::compile_elsewhere`]
    /// compiles them while the targets render; a test checks the list against what an
    /// optimizer creates.
    pub fn passes(settings: &Settings) -> Vec<&'static str> {
        let mut p = estimator::passes(settings.method, &settings.estimator_options);
        p.push("observed_texels");
        if settings.primal == primal::PrimalMode::ControlVariate {
            p.push("primal_cv");
        }
        if settings.path_cache.is_some() {
            p.push("primal_cache_trace");
            p.push("primal_cached");
        }
        p.push("loss");
        p.push(settings.step.kind().pass);
        p.extend(prior::passes(&settings.priors));
        if settings.moment_filter.enabled() {
            p.push("moment_filter");
        }
        p
    }

    /// Create the passes that the first [`Optimizer::step`] would otherwise create (the
    /// priors', which need the observed texels), so that no pipeline is compiled inside a
    /// timed iteration. `step` calls it too; calling it first only moves the work.
    pub fn prepare(&mut self) -> Result<()> {
        if self.plugins.priors.is_none() {
            let setup = prior::Setup {
                gpu: &self.gpu,
                set: &self.set,
                grad: &self.bufs.grad,
                params: &self.params.values,
                observed: &self.inputs.observed,
            };
            self.plugins.priors = Some(prior::build(&setup, &self.settings.priors)?);
            for (kind, _) in self.plugins.priors.iter().flatten() {
                log::debug!("prior `{}` ready", kind.name);
            }
        }
        Ok(())
    }

    /// One iteration: render, loss, gradient, step. Returns the loss of the render.
    pub fn step(&mut self) -> Result<StepStats> {
        self.prepare()?;
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("iteration"),
            });
        self.encode_gradient(&mut enc, self.iteration, true);
        let t = self.iteration + 1;
        let factor = self.encode_update(&mut enc, self.iteration, t);
        self.passes.timer.resolve(&mut enc);
        self.gpu.queue.submit([enc.finish()]);
        self.finish_iteration(true);
        self.iteration = t;
        let loss = self.read_loss()?;
        let mut fit = self.fit_mut();
        fit.step_gains(factor)?;
        fit.step_environment(factor)?;
        Ok(StepStats { loss })
    }

    /// Record the update of the textures from the gradient in `grad`: the priors (drawn
    /// with iteration `iteration`'s seeds), then the step, its `t`-th (Adam's bias
    /// correction). Returns the schedule's factor, with which the gains and the
    /// environment step once the work is submitted.
    pub(crate) fn encode_update(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        iteration: u32,
        t: u32,
    ) -> f32 {
        for (_, p) in self.plugins.priors.iter_mut().flatten() {
            p.encode(
                &self.gpu,
                enc,
                self.settings.seed,
                iteration,
                &mut self.passes.timer,
            );
        }
        let factor = self.settings.schedule.factor(iteration, self.run.progress);
        // While the environment warms up the textures hold (environment_fit.rs).
        let texture_factor = if self.fit.environment_warming_up() {
            0.0
        } else {
            factor
        };
        self.run.last_learning_rates = self.plugins.step.encode(
            &self.gpu,
            enc,
            &self.set,
            texture_factor,
            t,
            &mut self.passes.timer,
        );
        factor
    }

    /// Weigh each camera's pixels by a mask (one value per pixel in [0, 1]; None: all 1):
    /// masked-out pixels add neither loss nor gradient. The loss is the mean over the
    /// masked pixels.
    pub fn set_masks(&mut self, masks: &[Option<Vec<f32>>]) -> Result<()> {
        let n_pixels = (self.settings.width * self.settings.height) as usize;
        if masks.len() != self.passes.cams.len() {
            return Err(Error::Invalid(format!(
                "{} masks for {} cameras",
                masks.len(),
                self.passes.cams.len()
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
                    self.inputs.targets[k]
                        .rgb
                        .iter()
                        .zip(m)
                        .map(|(p, &w)| [p[0], p[1], p[2], w])
                        .collect()
                }
                None => self.inputs.targets[k]
                    .rgb
                    .iter()
                    .map(|p| [p[0], p[1], p[2], 1.0])
                    .collect(),
            };
            total += data.iter().map(|p| p[3] as f64).sum::<f64>();
            self.passes.loss.write_target(&self.gpu, k, &data);
        }
        // Also catches a NaN total.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(total > 0.0) {
            return Err(Error::Invalid("the masks leave no pixel to compare".into()));
        }
        let norm = (1.0 / (3.0 * total)) as f32;
        self.passes.loss.set_norm(&self.gpu, norm);
        self.gpu.check("set masks")
    }

    /// For every texel of the optimized textures (in the order of `set.textures`, row-major
    /// within each), whether some camera sample of the task reaches it with a non-zero filter
    /// weight: 4 x 4 rays per pixel and camera, computed on the GPU when the optimizer is made
    /// (ReSTIR gives reservoirs to these texels only).
    pub fn observed_texels(&self) -> Result<&[bool]> {
        Ok(&self.inputs.observed.0)
    }

    /// The fit of the light and the cameras' response: exposures, white balances, the
    /// environment as recovered so far.
    pub fn fit(&self) -> &Fit {
        &self.fit
    }

    /// The fit, to change: set or optimize the cameras' response and the environment.
    pub fn fit_mut(&mut self) -> FitMut<'_> {
        FitMut {
            fit: &mut self.fit,
            gpu: &self.gpu,
            scene: &mut self.renderer.scene,
            loss: &mut self.passes.loss,
            settings: &self.settings,
            cameras: self.passes.cams.len(),
        }
    }

    /// The fraction of the run done, as the schedule reads it (see
    /// [`Optimizer::set_progress`]).
    pub fn progress(&self) -> f64 {
        self.run.progress
    }

    /// Tell the learning-rate schedule which fraction of the run is done (in [0, 1]; for a
    /// run of N iterations, i / N before iteration i; for a time budget, the elapsed
    /// fraction). [`Optimizer::run`] sets it from its [`Stop`]. Without a schedule it has no
    /// effect.
    pub fn set_progress(&mut self, fraction: f64) {
        self.run.progress = if fraction.is_finite() {
            fraction.clamp(0.0, 1.0)
        } else {
            0.0
        };
    }

    /// The learning rate of each texture in the last [`Optimizer::step`] (the schedule's
    /// factor times the texture's rate); empty before the first.
    pub fn last_learning_rates(&self) -> &[f32] {
        &self.run.last_learning_rates
    }

    /// GPU time per kind of pass in the last [`Optimizer::step`], when the adapter has
    /// timestamp queries.
    pub fn pass_times(&self) -> Result<Option<PassTimes>> {
        self.passes.timer.read(&self.gpu)
    }

    /// The GPU buffer that holds the current values of all optimized textures (`f32`s, laid
    /// out as [`Optimizer::set`] describes: texture `i` starts at float
    /// `set.textures[i].offset`, row-major, `channels()` floats per texel). It has
    /// `STORAGE | COPY_SRC | COPY_DST` usage; the application may bind or copy it between
    /// calls. Writes to it change what the next iteration optimizes from.
    pub fn params_buffer(&self) -> &wgpu::Buffer {
        &self.params.values
    }

    /// Dropped and lost values so far.
    pub fn faults(&self) -> Result<FaultCounts> {
        let p: Vec<u32> = self.gpu.read_pod(&self.bufs.stats.primal)?;
        let a: Vec<u32> = self.gpu.read_pod(&self.bufs.stats.step)?;
        let l: Vec<u32> = self.gpu.read_pod(&self.passes.loss.stats)?;
        let mut f = FaultCounts {
            skipped_step: a[stat::STEP_SKIPPED as usize],
            dropped_primal: p[stat::RENDER_DROPPED as usize],
            dropped_pixels: l[stat::LOSS_DROPPED as usize],
            ..Default::default()
        };
        self.plugins.estimator.faults(&self.gpu, &mut f)?;
        // The environment's gradient updates lost or dropped (environment_fit.rs).
        f.lost_updates += self.fit.env_faults;
        Ok(f)
    }

    /// The control-variate primal image of task camera `k` from the last iteration or
    /// estimate (the image its loss and adjoint used, at the textures of that iteration);
    /// None for the independent primal.
    pub fn control_variate_image(&self, k: usize) -> Result<Option<Image>> {
        let Some(cv) = &self.passes.control_variate else {
            return Ok(None);
        };
        let (w, h) = (self.settings.width, self.settings.height);
        Ok(Some(Image {
            width: w,
            height: h,
            rgb: cv.image(&self.gpu, k, (w * h) as usize)?,
        }))
    }

    /// What the gradient estimator counted since the optimizer was made, by name (each
    /// estimator documents its names).
    pub fn estimator_diagnostics(&self) -> Result<estimator::Diagnostics> {
        self.plugins.estimator.diagnostics(&self.gpu)
    }

    /// The estimator's [`estimator_diagnostics`](Self::estimator_diagnostics) that are
    /// counters (a rate per iteration means something), with their values.
    pub fn estimator_counters(&self) -> Result<estimator::Diagnostics> {
        let names = self.plugins.estimator.counters();
        if names.is_empty() {
            // No readback for an estimator that counts nothing per iteration.
            return Ok(Vec::new());
        }
        let mut d = self.plugins.estimator.diagnostics(&self.gpu)?;
        d.retain(|(n, _)| names.contains(n));
        Ok(d)
    }

    /// Render camera `k` of the task (index into `settings.cameras`) at the current textures.
    pub fn render(&self, k: usize, spp: u32, seed: u32) -> Result<Image> {
        let out = self.renderer.render(
            &crate::render::RenderSettings {
                width: self.settings.width,
                height: self.settings.height,
                spp,
                seed,
                camera: self.settings.cameras[k],
                techniques: Techniques::Mis,
            },
            |_| {},
        )?;
        Ok(out.image)
    }
}

/// The texels `method` keeps state for: the observed ones, or every texel where paths of
/// `max_depth` vertices reach texels no camera sees ([`estimator::every_texel`]).
fn state_texels(observed: &[bool], method: Method, max_depth: u32) -> u64 {
    if estimator::every_texel(method, max_depth) {
        observed.len() as u64
    } else {
        observed.iter().filter(|&&o| o).count() as u64
    }
}
