//! Texture optimization on the GPU: primal render, loss and adjoint, a gradient estimator
//! ([`estimator`]: the baseline, or ReSTIR's candidate and merge passes), and Adam, as one
//! submission per iteration.

pub mod adam;
pub mod checkpoint;
pub mod estimator;
pub mod export;
pub mod loss;
pub mod observed;
pub mod plot;
pub mod primal;
pub mod problem;
pub mod run;
pub mod schedule;
pub mod texture_export;

use crate::gpu::{grid_2d, Gpu};
use crate::image_io::Image;
use crate::render::layout::*;
use crate::render::params::ParamSet;
use crate::render::{camera_info, encode_timed_pass, Renderer, Techniques, WORKGROUP};
use crate::scene::Scene;
use crate::task::Loss;
use crate::{Error, Result};
pub use estimator::restir::{self, MergeDiagnostics};
use estimator::Estimator;
pub use estimator::{Confidence, Method, RestirOptions, RestirSnapshot};
pub use primal::{ControlVariateSnapshot, PrimalMode};
pub use problem::Problem;
pub use schedule::{Schedule, ScheduleKind};

/// How each iteration samples.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Image width of every camera.
    pub width: u32,
    /// Image height of every camera.
    pub height: u32,
    /// Cameras rendered every iteration (indices into the scene's cameras).
    pub cameras: Vec<usize>,
    /// Samples per pixel of the primal render.
    pub primal_spp: u32,
    /// How the primal image is estimated: independently, or with the recursive control
    /// variate.
    pub primal: PrimalMode,
    /// Samples per pixel of the gradient pass.
    pub gradient_spp: u32,
    /// Image loss.
    pub loss: Loss,
    /// Seed of the whole run; every pass derives its own from it.
    pub seed: u32,
    /// Gradient estimator.
    pub method: Method,
    /// ReSTIR options (used when `method` is ReSTIR).
    pub restir: RestirOptions,
    /// Learning-rate schedule: a factor of every texture's learning rate over the run (see
    /// [`Optimizer::set_progress`]).
    pub schedule: Schedule,
    /// Masked (sparse) Adam: entries whose gradient is exactly zero in an iteration keep
    /// their value and moments, as Mitsuba 3's `mask_updates`.
    pub adam_mask: bool,
    /// Optimize the per-camera exposures (see [`Optimizer::set_exposure`]) with Adam on
    /// their logarithms, at this learning rate; None: exposures stay fixed.
    pub exposure_learning_rate: Option<f32>,
}

impl Settings {
    /// The defaults of a task file (4 primal and 1 gradient samples per pixel, L2 loss,
    /// seed 1, ReSTIR with its default options) for `cameras` at `width` x `height`.
    pub fn new(width: u32, height: u32, cameras: Vec<usize>) -> Settings {
        Settings {
            width,
            height,
            cameras,
            primal_spp: 4,
            primal: PrimalMode::Independent,
            gradient_spp: 1,
            loss: Loss::L2,
            seed: 1,
            method: Method::Restir,
            restir: RestirOptions::default(),
            schedule: Schedule::constant(),
            adam_mask: false,
            exposure_learning_rate: None,
        }
    }
}

/// When [`Optimizer::run`] returns: after `iterations` more iterations, after `time_budget`,
/// or at whichever comes first. At least one must be given.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stop {
    /// Iterations to run in this call.
    pub iterations: Option<u32>,
    /// Wall-clock time for this call.
    pub time_budget: Option<std::time::Duration>,
}

impl Stop {
    /// Stop after `n` iterations.
    pub fn iterations(n: u32) -> Stop {
        Stop {
            iterations: Some(n),
            time_budget: None,
        }
    }
    /// Stop once `d` has passed (the iteration under way finishes first).
    pub fn time(d: std::time::Duration) -> Stop {
        Stop {
            iterations: None,
            time_budget: Some(d),
        }
    }
}

/// What the callback of [`Optimizer::run`] sees after each iteration.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Iterations done in total ([`Optimizer::iteration`]).
    pub iteration: u32,
    /// Iterations done in this call.
    pub in_this_run: u32,
    /// Loss of the iteration's primal render.
    pub loss: f64,
    /// Time since the call began.
    pub elapsed: std::time::Duration,
}

fn mix64(mut x: u64) -> u64 {
    // splitmix64 finalizer
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The kinds of pass that [`pass_seed`] gives independent random streams.
pub struct Seeds;

impl Seeds {
    /// The primal render of an iteration.
    pub const PRIMAL: u32 = 0;
    /// The gradient (or ReSTIR candidate) pass.
    pub const GRADIENT: u32 = 1;
    /// Target renders.
    pub const TARGET: u32 = 2;
    /// Evaluation and final renders.
    pub const EVAL: u32 = 3;
    /// ReSTIR's merge.
    pub const MERGE: u32 = 4;
}

/// Seed of pass `kind` ([`Seeds`]) of camera `camera` at iteration `iteration`: independent
/// streams, so the adjoint never shares random numbers with the gradient samples.
pub fn pass_seed(seed: u32, iteration: u32, camera: u32, kind: u32) -> u32 {
    let x =
        mix64(mix64(mix64(seed as u64) ^ iteration as u64) ^ ((camera as u64) << 8 | kind as u64));
    x as u32
}

/// The kinds of pass that timestamp queries time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PassKind {
    Primal,
    Loss,
    Gradient,
    Merge,
    Adam,
}

/// GPU milliseconds of each kind of pass in the last iteration (from timestamp queries).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PassTimes {
    /// Primal renders of all cameras.
    pub primal_ms: f64,
    /// Loss and adjoint.
    pub loss_ms: f64,
    /// Gradient passes (baseline), or ReSTIR's candidate passes.
    pub gradient_ms: f64,
    /// ReSTIR's merge pass.
    pub merge_ms: f64,
    /// Adam updates.
    pub adam_ms: f64,
}

impl PassTimes {
    /// Add `other` pass by pass.
    pub fn add(&mut self, other: &PassTimes) {
        self.primal_ms += other.primal_ms;
        self.loss_ms += other.loss_ms;
        self.gradient_ms += other.gradient_ms;
        self.merge_ms += other.merge_ms;
        self.adam_ms += other.adam_ms;
    }

    /// Every pass divided by `n` (the mean of `n` added iterations).
    pub fn divided(&self, n: f64) -> PassTimes {
        PassTimes {
            primal_ms: self.primal_ms / n,
            loss_ms: self.loss_ms / n,
            gradient_ms: self.gradient_ms / n,
            merge_ms: self.merge_ms / n,
            adam_ms: self.adam_ms / n,
        }
    }

    /// All passes together.
    pub fn total(&self) -> f64 {
        self.primal_ms + self.loss_ms + self.gradient_ms + self.merge_ms + self.adam_ms
    }
}

/// Timestamp queries around the passes of one iteration, where the device has them: each
/// pass asks for the next begin/end pair with [`PassTimer::next`], naming its kind.
pub(crate) struct PassTimer {
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    capacity: u32,
    kinds: Vec<PassKind>,
}

impl PassTimer {
    fn new(gpu: &Gpu, capacity: u32) -> PassTimer {
        let queries = gpu.timestamps.then(|| {
            let n = 2 * capacity;
            (
                gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("pass timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: n,
                }),
                gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("pass timestamps resolve"),
                    size: 8 * n as u64,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
            )
        });
        PassTimer {
            queries,
            capacity,
            kinds: Vec::new(),
        }
    }

    fn begin(&mut self) {
        self.kinds.clear();
    }

    /// The query pair of the next pass, of kind `kind` (None without timestamps).
    pub(crate) fn next(&mut self, kind: PassKind) -> Option<(&wgpu::QuerySet, u32)> {
        let (q, _) = self.queries.as_ref()?;
        let k = self.kinds.len() as u32;
        if k >= self.capacity {
            return None;
        }
        self.kinds.push(kind);
        Some((q, k))
    }

    fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        if let Some((q, buf)) = &self.queries {
            if !self.kinds.is_empty() {
                enc.resolve_query_set(q, 0..2 * self.kinds.len() as u32, buf, 0);
            }
        }
    }

    fn read(&self, gpu: &Gpu) -> Result<Option<PassTimes>> {
        let Some((_, buf)) = &self.queries else {
            return Ok(None);
        };
        let ticks: Vec<u64> = gpu.read_pod(buf)?;
        let period = gpu.queue.get_timestamp_period() as f64 * 1e-6;
        let mut t = PassTimes::default();
        for (k, kind) in self.kinds.iter().enumerate() {
            let ms = ticks[2 * k + 1].saturating_sub(ticks[2 * k]) as f64 * period;
            match kind {
                PassKind::Primal => t.primal_ms += ms,
                PassKind::Loss => t.loss_ms += ms,
                PassKind::Gradient => t.gradient_ms += ms,
                PassKind::Merge => t.merge_ms += ms,
                PassKind::Adam => t.adam_ms += ms,
            }
        }
        Ok(Some(t))
    }
}

/// What one iteration reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepStats {
    /// Loss of this iteration's primal render (before the update).
    pub loss: f64,
}

/// Counters of dropped or lost values since the optimizer was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// Gradient additions that exhausted the compare-and-swap bound.
    pub lost_updates: u32,
    /// Non-finite values dropped by the gradient or candidate pass.
    pub dropped_gradient: u32,
    /// Non-finite gradients skipped by Adam.
    pub skipped_adam: u32,
    /// Non-finite primal samples dropped.
    pub dropped_primal: u32,
    /// Pixels whose loss or adjoint was not finite (e.g. a NaN in the target), counted once
    /// per iteration and camera, and left out of the loss and the gradient.
    pub dropped_pixels: u32,
    /// ReSTIR candidates whose reservoir lock was not taken within the bound.
    pub lost_offers: u32,
    /// Non-finite values of stored ReSTIR paths dropped by the merge.
    pub dropped_replays: u32,
}

/// The textures and adjoint images of the last iteration, which the next one evaluates kept
/// samples under (ReSTIR's merge).
#[derive(Clone, Debug, PartialEq)]
pub struct PreviousState {
    /// The textures at which the last iteration drew its samples.
    pub params: Vec<f32>,
    /// The last iteration's adjoint images (RGBA per pixel, cameras one after another).
    pub adjoint: Vec<f32>,
}

/// The state of an optimizer between iterations, on the CPU (see [`Optimizer::state`]).
#[derive(Clone, Debug, PartialEq)]
pub struct OptimizerState {
    /// Iterations done.
    pub iteration: u32,
    /// Texture values, laid out like [`ParamSet::values`].
    pub params: Vec<f32>,
    /// Adam first moments.
    pub m1: Vec<f32>,
    /// Adam second moments.
    pub m2: Vec<f32>,
    /// The last iteration's textures and adjoint, when the estimator or the primal uses
    /// them.
    pub previous: Option<PreviousState>,
    /// The ReSTIR estimator's reservoirs; `None` for the baseline.
    pub restir: Option<RestirSnapshot>,
    /// The control-variate primal's state; `None` for the independent primal.
    pub control_variate: Option<ControlVariateSnapshot>,
    /// Per-camera exposures and, when they are optimized, their Adam moments.
    pub exposure: ExposureState,
}

/// Per-camera exposures and the Adam moments of their logarithms.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExposureState {
    /// The factor each camera's render is multiplied by.
    pub values: Vec<f32>,
    /// Adam first moments (of the logarithms).
    pub m1: Vec<f32>,
    /// Adam second moments.
    pub m2: Vec<f32>,
    /// Adam steps taken.
    pub steps: u32,
}

/// The buffers an optimizer allocates besides the scene's, by label and size in bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryPlan {
    /// (label, bytes) of each buffer.
    pub buffers: Vec<(String, u64)>,
}

impl MemoryPlan {
    /// Total bytes.
    pub fn total(&self) -> u64 {
        self.buffers.iter().map(|b| b.1).sum()
    }

    /// Refuse, before anything is allocated, a buffer larger than the device binds or
    /// allocates, naming the buffer, its size and the limit.
    pub fn check(&self, gpu: &Gpu) -> Result<()> {
        let l = gpu.device.limits();
        let limit = l.max_storage_buffer_binding_size.min(l.max_buffer_size);
        if let Some((label, bytes)) = self.buffers.iter().find(|b| b.1 > limit) {
            return Err(Error::Unsuitable(format!(
                "the optimizer's {label} buffer needs {bytes} bytes ({:.1} MiB), the device allows \
                 {limit} bytes ({:.1} MiB) per storage buffer; use smaller textures or images \
                 (the optimizer needs {:.1} MiB in all)",
                *bytes as f64 / MIB,
                limit as f64 / MIB,
                self.total() as f64 / MIB
            )));
        }
        Ok(())
    }
}

const MIB: f64 = 1024.0 * 1024.0;

/// The optimizer's buffers for textures `set`, images as in `settings`, `n_cams` cameras.
pub fn memory_plan(set: &ParamSet, settings: &Settings, n_cams: usize) -> MemoryPlan {
    let n_params = set.values.len() as u64;
    let n_texels: u64 = set
        .textures
        .iter()
        .map(|t| (t.width * t.height) as u64)
        .sum();
    let pixels = settings.width as u64 * settings.height as u64;
    let mut buffers = vec![
        ("params".to_string(), 4 * n_params),
        ("params_prev".to_string(), 4 * n_params),
        ("gradient".to_string(), 4 * n_params),
        ("adam moment1".to_string(), 4 * n_params),
        ("adam moment2".to_string(), 4 * n_params),
        ("primal accum".to_string(), 16 * pixels),
        ("primal accum_prev".to_string(), 16 * pixels),
        ("adjoint even".to_string(), 16 * pixels * n_cams as u64),
        ("adjoint odd".to_string(), 16 * pixels * n_cams as u64),
    ];
    for k in 0..n_cams {
        buffers.push((format!("target {k}"), 16 * pixels));
    }
    buffers.extend(estimator::memory(settings.method, n_texels));
    if settings.primal == PrimalMode::ControlVariate {
        buffers.extend(primal::memory(pixels, n_cams as u64));
    }
    MemoryPlan { buffers }
}

/// The primal render and loss of one camera.
struct CameraPasses {
    render_uniform: wgpu::Buffer,
    render_params: GpuRenderParams,
    render_group: wgpu::BindGroup,
    loss_uniform: wgpu::Buffer,
    loss_params: loss::LossParams,
    target_buf: wgpu::Buffer,
    /// Per parity of the iteration (the adjoint buffers alternate).
    loss_groups: [wgpu::BindGroup; 2],
}

/// Counters of the passes the optimizer runs itself.
struct Stats {
    primal: wgpu::Buffer,
    adam: wgpu::Buffer,
    loss: wgpu::Buffer,
}

/// The optimizer: a scene on the GPU with its optimized textures, targets, and the passes.
pub struct Optimizer {
    gpu: Gpu,
    renderer: Renderer,
    /// Layout and learning rates of the optimized textures (values as at creation).
    pub set: ParamSet,
    settings: Settings,
    cams: Vec<CameraPasses>,
    grad: wgpu::Buffer,
    /// Adjoint images of all cameras; iteration t writes buffer t % 2.
    adjoint: [wgpu::Buffer; 2],
    moments: [wgpu::Buffer; 2],
    stats: Stats,
    loss_partial: wgpu::Buffer,
    /// Partial sums of dL/d(exposure) per workgroup and camera.
    exposure_partial: wgpu::Buffer,
    /// The targets (CPU copies, for re-uploading them with masks).
    targets: Vec<Image>,
    /// Exposures and their optimizer state.
    exposure: ExposureState,
    /// Workgroups of one camera's loss pass.
    n_loss_groups: u32,
    grid: (u32, u32),
    loss_grid: (u32, u32),
    loss_pipeline: wgpu::ComputePipeline,
    adam_pipeline: wgpu::ComputePipeline,
    adam: Vec<(wgpu::Buffer, wgpu::BindGroup, adam::AdamParams)>,
    accum: wgpu::Buffer,
    /// The primal samples under the previous textures (control variate).
    accum_prev: wgpu::Buffer,
    /// The control-variate primal, when `settings.primal` asks for it.
    control_variate: Option<primal::ControlVariate>,
    timer: PassTimer,
    estimator: Box<dyn Estimator>,
    /// Camera constants of the task's cameras at the task's image size.
    camera_infos: Vec<GpuCameraInfo>,
    /// The texture_export pipeline, built on first use.
    export_pipeline: std::sync::OnceLock<wgpu::ComputePipeline>,
    /// The observed-texel mask, computed on first use.
    observed: std::sync::OnceLock<Vec<bool>>,
    /// Fraction of the run done, for the learning-rate schedule.
    progress: f64,
    /// Learning rate of each texture in the last Adam step.
    last_learning_rates: Vec<f32>,
    /// Iterations done (Adam steps taken).
    pub iteration: u32,
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
        if targets.len() != settings.cameras.len() {
            return Err(Error::Invalid(format!(
                "{} targets for {} cameras",
                targets.len(),
                settings.cameras.len()
            )));
        }
        if settings.method == Method::Restir && targets.len() > restir::MAX_CAMERAS {
            return Err(Error::Invalid(format!(
                "ReSTIR handles at most {} cameras, the task has {}",
                restir::MAX_CAMERAS,
                targets.len()
            )));
        }
        for t in targets {
            if (t.width, t.height) != (w, h) {
                return Err(Error::Invalid(format!(
                    "target is {}x{}, the task renders {w}x{h}",
                    t.width, t.height
                )));
            }
        }
        memory_plan(&set, &settings, targets.len()).check(gpu)?;
        let renderer = Renderer::with_params(gpu, scene, &set)?;
        let loss_layout = gpu.pass_layout("loss", 0)?;
        let adam_layout = gpu.pass_layout("adam", 0)?;
        let loss_pipeline = gpu.compute_pipeline("loss", &[&loss_layout])?;
        let adam_pipeline = gpu.compute_pipeline("adam", &[&adam_layout])?;

        let n_pixels = w * h;
        let n_cams = targets.len() as u32;
        let n_params = set.values.len() as u64;
        if settings.primal == PrimalMode::ControlVariate && settings.primal_spp == 0 {
            return Err(Error::Invalid("primal_spp must be at least 1".into()));
        }
        let accum = gpu.storage_zeroed("primal accum", n_pixels as u64 * 16);
        let accum_prev = gpu.storage_zeroed("primal accum_prev", n_pixels as u64 * 16);
        let control_variate = match settings.primal {
            PrimalMode::ControlVariate => Some(primal::ControlVariate::new(
                gpu,
                (w, h),
                targets.len(),
                &accum,
                &accum_prev,
            )?),
            PrimalMode::Independent => None,
        };
        let adjoint_size = (n_pixels * n_cams) as u64 * 16;
        let adjoint = [
            gpu.storage_zeroed("adjoint even", adjoint_size),
            gpu.storage_zeroed("adjoint odd", adjoint_size),
        ];
        let grad = gpu.storage_zeroed("gradient", n_params * 4);
        let moments = [
            gpu.storage_zeroed("adam moment1", n_params * 4),
            gpu.storage_zeroed("adam moment2", n_params * 4),
        ];
        let stats = Stats {
            primal: gpu.storage_zeroed("primal stats", 16),
            adam: gpu.storage_zeroed("adam stats", 16),
            loss: gpu.storage_zeroed("loss stats", 16),
        };
        let n_loss_groups = n_pixels.div_ceil(WORKGROUP);
        let loss_partial =
            gpu.storage_zeroed("loss partial sums", (n_loss_groups * n_cams) as u64 * 4);
        let exposure_partial =
            gpu.storage_zeroed("exposure partial sums", (n_loss_groups * n_cams) as u64 * 4);
        let grid = renderer.tile_grid(w, h);
        let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
        let loss_grid = grid_2d(n_pixels, WORKGROUP, max_dim);
        let norm = 1.0 / (n_pixels as f32 * 3.0 * n_cams as f32);

        let mut camera_infos = Vec::new();
        for &cam in &settings.cameras {
            let c = scene
                .cameras
                .get(cam)
                .ok_or_else(|| Error::Invalid(format!("camera index {cam} out of range")))?;
            camera_infos.push(camera_info(c, w, h));
        }
        let estimator = estimator::build(&estimator::Setup {
            gpu,
            scene: &renderer.scene,
            set: &set,
            settings: &settings,
            cameras: &camera_infos,
            adjoint: &adjoint,
            grad: &grad,
            grid,
        })?;

        let mut cams = Vec::new();
        for (k, (camera, target)) in camera_infos.iter().zip(targets).enumerate() {
            let render_params = GpuRenderParams {
                camera: *camera,
                spp: settings.primal_spp,
                techniques: Techniques::Mis.bits(),
                stride: grid.0 * WORKGROUP,
                two_states: control_variate.is_some() as u32,
                ..Default::default()
            };
            let loss_params = loss::LossParams {
                n_pixels,
                kind: match settings.loss {
                    Loss::L2 => 0,
                    Loss::Relmse => 1,
                },
                norm,
                partial_offset: k as u32 * n_loss_groups,
                adjoint_offset: k as u32 * n_pixels,
                exposure: 1.0,
                _pad: [0; 2],
            };
            // Mask weight 1 everywhere until set_masks.
            let target_data: Vec<[f32; 4]> =
                target.rgb.iter().map(|p| [p[0], p[1], p[2], 1.0]).collect();
            let target_buf = gpu.storage(
                &format!("target {k}"),
                bytemuck::cast_slice(&target_data),
                wgpu::BufferUsages::empty(),
            );
            let render_uniform = gpu.uniform(
                &format!("primal params {k}"),
                bytemuck::bytes_of(&render_params),
            );
            let loss_uniform = gpu.uniform(
                &format!("loss params {k}"),
                bytemuck::bytes_of(&loss_params),
            );
            cams.push(CameraPasses {
                render_group: gpu.bind_group(
                    "primal",
                    &renderer.render_layout,
                    &[&render_uniform, &accum, &stats.primal, &accum_prev],
                ),
                loss_groups: [0usize, 1].map(|p| {
                    gpu.bind_group(
                        "loss",
                        &loss_layout,
                        &[
                            &loss_uniform,
                            &accum,
                            &target_buf,
                            &adjoint[p],
                            &loss_partial,
                            &stats.loss,
                            &exposure_partial,
                            &adjoint[1 - p],
                        ],
                    )
                }),
                render_uniform,
                render_params,
                loss_uniform,
                loss_params,
                target_buf,
            });
        }
        let mut adam = Vec::new();
        for t in &set.textures {
            let (lo, hi) = t.slot.range();
            let p = adam::AdamParams {
                offset: t.offset,
                count: t.len() as u32,
                lr: t.learning_rate,
                beta1: adam::BETA1,
                beta2: adam::BETA2,
                eps: adam::EPS,
                bias1: 1.0,
                bias2: 1.0,
                lo,
                hi,
                mask: settings.adam_mask as u32,
                _pad: 0,
            };
            let u = gpu.uniform(&format!("adam params {}", t.name()), bytemuck::bytes_of(&p));
            let g = gpu.bind_group(
                "adam",
                &adam_layout,
                &[
                    &u,
                    &grad,
                    &renderer.scene.params,
                    &moments[0],
                    &moments[1],
                    &stats.adam,
                ],
            );
            adam.push((u, g, p));
        }
        // Primal, control variate and loss per camera, the estimator's passes (at most two
        // per camera), Adam per texture.
        let timer = PassTimer::new(gpu, 6 * n_cams + 2 + set.textures.len() as u32);
        gpu.check("optimizer setup")?;
        Ok(Optimizer {
            gpu: gpu.clone(),
            renderer,
            set,
            settings,
            cams,
            grad,
            adjoint,
            moments,
            stats,
            loss_partial,
            exposure_partial,
            targets: targets.to_vec(),
            exposure: ExposureState {
                values: vec![1.0; targets.len()],
                m1: vec![0.0; targets.len()],
                m2: vec![0.0; targets.len()],
                steps: 0,
            },
            n_loss_groups,
            grid,
            loss_grid,
            loss_pipeline,
            adam_pipeline,
            adam,
            accum,
            accum_prev,
            control_variate,
            timer,
            estimator,
            camera_infos,
            export_pipeline: std::sync::OnceLock::new(),
            observed: std::sync::OnceLock::new(),
            progress: 0.0,
            last_learning_rates: Vec::new(),
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
        for (k, cam) in self.cams.iter_mut().enumerate() {
            cam.render_params.seed =
                pass_seed(self.settings.seed, iteration, k as u32, Seeds::PRIMAL);
            cam.render_params.sample_offset = 0;
            cam.render_params.spp = self.settings.primal_spp;
            cam.render_params.two_states = self.control_variate.is_some() as u32;
            self.gpu.queue.write_buffer(
                &cam.render_uniform,
                0,
                bytemuck::bytes_of(&cam.render_params),
            );
            enc.clear_buffer(&self.accum, 0, None);
            if self.control_variate.is_some() {
                enc.clear_buffer(&self.accum_prev, 0, None);
            }
            let groups = [&self.renderer.scene.bind_group, &cam.render_group];
            let pipe = &self.renderer.render_pipeline;
            let t = self.timer.next(PassKind::Primal);
            encode_timed_pass(enc, "primal", pipe, &groups, self.grid, t);
            if let Some(cv) = &mut self.control_variate {
                cv.encode(enc, k, &mut self.timer);
            }
            let groups = [&cam.loss_groups[parity]];
            let t = self.timer.next(PassKind::Loss);
            encode_timed_pass(enc, "loss", &self.loss_pipeline, &groups, self.loss_grid, t);
        }
    }

    /// Record iteration `iteration` up to the gradient (in `grad`): the primal render and
    /// loss of every camera (unless the adjoint was written already), the estimator's passes,
    /// and the copy of the textures that the next iteration calls previous.
    fn encode_gradient(&mut self, enc: &mut wgpu::CommandEncoder, iteration: u32, primal: bool) {
        self.timer.begin();
        if primal {
            self.encode_primal(enc, iteration);
        }
        let frame = estimator::Frame {
            iteration,
            scene_group: &self.renderer.scene.bind_group,
        };
        self.estimator.encode(enc, &frame, &mut self.timer);
        if self.uses_previous_state() {
            let params = &self.renderer.scene.params;
            let prev = &self.renderer.scene.params_prev;
            enc.copy_buffer_to_buffer(params, 0, prev, 0, params.size());
        }
    }

    /// Whether the next iteration needs this one's textures (ReSTIR's merge, the control
    /// variate).
    fn uses_previous_state(&self) -> bool {
        self.estimator.uses_previous_state() || self.control_variate.is_some()
    }

    /// Bookkeeping once an iteration's work is submitted.
    fn finish_iteration(&mut self, primal: bool) {
        self.estimator.finish_iteration();
        if primal {
            if let Some(cv) = &mut self.control_variate {
                cv.finish_iteration();
            }
        }
    }

    fn read_loss(&self) -> Result<f64> {
        let partial: Vec<f32> = self.gpu.read_pod(&self.loss_partial)?;
        Ok(partial.iter().map(|&v| v as f64).sum())
    }

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
            self.gpu
                .queue
                .write_buffer(&self.cams[k].target_buf, 0, bytemuck::cast_slice(&data));
        }
        if !(total > 0.0) {
            return Err(Error::Invalid("the masks leave no pixel to compare".into()));
        }
        let norm = (1.0 / (3.0 * total)) as f32;
        for cam in &mut self.cams {
            cam.loss_params.norm = norm;
            self.gpu
                .queue
                .write_buffer(&cam.loss_uniform, 0, bytemuck::bytes_of(&cam.loss_params));
        }
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

    fn upload_exposure(&mut self) {
        for (cam, &e) in self.cams.iter_mut().zip(&self.exposure.values) {
            cam.loss_params.exposure = e;
            self.gpu
                .queue
                .write_buffer(&cam.loss_uniform, 0, bytemuck::bytes_of(&cam.loss_params));
        }
    }

    /// One Adam step of the exposures' logarithms from this iteration's dL/d(exposure).
    fn step_exposure(&mut self, lr: f32) -> Result<()> {
        let partial: Vec<f32> = self.gpu.read_pod(&self.exposure_partial)?;
        let n = self.n_loss_groups as usize;
        let e = &mut self.exposure;
        e.steps += 1;
        let t = e.steps as i32;
        for k in 0..e.values.len() {
            let d: f64 = partial[k * n..(k + 1) * n].iter().map(|&v| v as f64).sum();
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

    /// One iteration: render, loss, gradient, Adam. Returns the loss of the render.
    pub fn step(&mut self) -> Result<StepStats> {
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("iteration"),
            });
        self.encode_gradient(&mut enc, self.iteration, true);
        let t = self.iteration + 1;
        let max_dim = self
            .gpu
            .device
            .limits()
            .max_compute_workgroups_per_dimension;
        let factor = self.settings.schedule.factor(self.iteration, self.progress);
        self.last_learning_rates.clear();
        for ((u, g, p), tex) in self.adam.iter_mut().zip(&self.set.textures) {
            p.lr = tex.learning_rate * factor;
            self.last_learning_rates.push(p.lr);
            p.bias1 = 1.0 - adam::BETA1.powi(t as i32);
            p.bias2 = 1.0 - adam::BETA2.powi(t as i32);
            self.gpu.queue.write_buffer(u, 0, bytemuck::bytes_of(p));
            let grid = grid_2d(p.count, WORKGROUP, max_dim);
            let timing = self.timer.next(PassKind::Adam);
            encode_timed_pass(&mut enc, "adam", &self.adam_pipeline, &[g], grid, timing);
        }
        self.timer.resolve(&mut enc);
        self.gpu.queue.submit([enc.finish()]);
        self.finish_iteration(true);
        self.iteration = t;
        let loss = self.read_loss()?;
        if let Some(lr) = self.settings.exposure_learning_rate {
            self.step_exposure(lr * factor)?;
        }
        Ok(StepStats { loss })
    }

    /// Tell the learning-rate schedule which fraction of the run is done (in [0, 1]; for a
    /// run of N iterations, i / N before iteration i; for a time budget, the elapsed
    /// fraction). [`Optimizer::run`] sets it from its [`Stop`]. Without a schedule it has no
    /// effect.
    pub fn set_progress(&mut self, fraction: f64) {
        self.progress = if fraction.is_finite() {
            fraction.clamp(0.0, 1.0)
        } else {
            0.0
        };
    }

    /// The learning rate of each texture in the last [`Optimizer::step`] (the schedule's
    /// factor times the texture's rate); empty before the first.
    pub fn last_learning_rates(&self) -> &[f32] {
        &self.last_learning_rates
    }

    /// GPU time per kind of pass in the last [`Optimizer::step`], when the adapter has
    /// timestamp queries.
    pub fn pass_times(&self) -> Result<Option<PassTimes>> {
        self.timer.read(&self.gpu)
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

    /// [`Optimizer::estimate_gradient`] with a given adjoint (RGBA per pixel, the cameras one
    /// after another, as [`Optimizer::converged_adjoint`] returns it) instead of the one of
    /// the iteration's own primal render: the gradient estimator alone, without the noise of
    /// the adjoint. Returns the gradient.
    pub fn estimate_gradient_with_adjoint(
        &mut self,
        iteration: u32,
        adjoint: &[f32],
    ) -> Result<Vec<f32>> {
        let buf = &self.adjoint[(iteration % 2) as usize];
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
        for k in 0..self.cams.len() {
            let mut done = 0;
            while done < spp {
                let cam = &mut self.cams[k];
                cam.render_params.seed = pass_seed(seed, u32::MAX - 3, k as u32, Seeds::PRIMAL);
                cam.render_params.sample_offset = done;
                cam.render_params.spp = chunk.min(spp - done);
                cam.render_params.two_states = 0;
                self.gpu.queue.write_buffer(
                    &cam.render_uniform,
                    0,
                    bytemuck::bytes_of(&cam.render_params),
                );
                let mut enc =
                    self.gpu
                        .device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some("converged primal"),
                        });
                if done == 0 {
                    enc.clear_buffer(&self.accum, 0, None);
                }
                let groups = [&self.renderer.scene.bind_group, &cam.render_group];
                let pipe = &self.renderer.render_pipeline;
                encode_timed_pass(&mut enc, "primal", pipe, &groups, self.grid, None);
                done += cam.render_params.spp;
                if done >= spp {
                    let groups = [&cam.loss_groups[parity]];
                    let pipe = &self.loss_pipeline;
                    encode_timed_pass(&mut enc, "loss", pipe, &groups, self.loss_grid, None);
                }
                self.gpu.queue.submit([enc.finish()]);
                self.gpu.wait("converged primal")?;
            }
        }
        let adjoint = self.gpu.read_pod(&self.adjoint[parity])?;
        Ok((adjoint, self.read_loss()?))
    }

    /// The gradient of the last iteration or estimate, laid out like the parameters.
    pub fn read_gradient(&self) -> Result<Vec<f32>> {
        let mut g: Vec<f32> = self.gpu.read_pod(&self.grad)?;
        g.truncate(self.set.values.len());
        Ok(g)
    }

    /// Current texture values.
    pub fn read_params(&self) -> Result<Vec<f32>> {
        let mut v: Vec<f32> = self.gpu.read_pod(&self.renderer.scene.params)?;
        v.truncate(self.set.values.len());
        Ok(v)
    }

    /// Replace the texture values (e.g. from a checkpoint).
    pub fn write_params(&self, values: &[f32]) -> Result<()> {
        if values.len() != self.set.values.len() {
            return Err(Error::Invalid(format!(
                "{} values for {} parameters",
                values.len(),
                self.set.values.len()
            )));
        }
        self.gpu
            .queue
            .write_buffer(&self.renderer.scene.params, 0, bytemuck::cast_slice(values));
        self.gpu.check("write params")
    }

    /// Adam's first and second moments.
    pub fn read_moments(&self) -> Result<[Vec<f32>; 2]> {
        let n = self.set.values.len();
        let mut a: Vec<f32> = self.gpu.read_pod(&self.moments[0])?;
        let mut b: Vec<f32> = self.gpu.read_pod(&self.moments[1])?;
        a.truncate(n);
        b.truncate(n);
        Ok([a, b])
    }

    /// Restore Adam's moments.
    pub fn write_moments(&self, m: &[Vec<f32>; 2]) -> Result<()> {
        for (buf, v) in self.moments.iter().zip(m) {
            if v.len() != self.set.values.len() {
                return Err(Error::Invalid(
                    "Adam moments do not match the parameters".into(),
                ));
            }
            self.gpu.queue.write_buffer(buf, 0, bytemuck::cast_slice(v));
        }
        self.gpu.check("write moments")
    }

    /// An optimizer for `problem`: its scene, textures and targets, with the sampling options
    /// of `settings` (whose cameras, width and height are taken from the problem).
    pub fn for_problem(gpu: &Gpu, problem: &Problem, settings: Settings) -> Result<Optimizer> {
        let first = problem.targets.first().ok_or_else(|| {
            Error::Invalid("the problem has no targets: set or render them first".into())
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
        if problem.exposure.iter().any(|&e| e != 1.0) {
            opt.set_exposure(&problem.exposure)?;
        }
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
        mut on_iteration: impl FnMut(&Progress) -> std::ops::ControlFlow<()>,
    ) -> Result<Option<Progress>> {
        if stop.iterations.is_none() && stop.time_budget.is_none() {
            return Err(Error::Invalid(
                "Optimizer::run needs a number of iterations, a time budget or both".into(),
            ));
        }
        let start = std::time::Instant::now();
        let mut last = None;
        let mut done = 0;
        loop {
            if stop.iterations.is_some_and(|n| done >= n)
                || stop.time_budget.is_some_and(|b| start.elapsed() >= b)
            {
                break;
            }
            let by_iterations = stop.iterations.map_or(0.0, |n| done as f64 / n as f64);
            let by_time = stop.time_budget.map_or(0.0, |b| {
                start.elapsed().as_secs_f64() / b.as_secs_f64().max(1e-9)
            });
            self.set_progress(by_iterations.max(by_time));
            let stats = self.step()?;
            done += 1;
            let p = Progress {
                iteration: self.iteration,
                in_this_run: done,
                loss: stats.loss,
                elapsed: start.elapsed(),
            };
            last = Some(p);
            if on_iteration(&p).is_break() {
                break;
            }
        }
        Ok(last)
    }

    /// The GPU buffer that holds the current values of all optimized textures (`f32`s, laid
    /// out as [`Optimizer::set`] describes: texture `i` starts at float
    /// `set.textures[i].offset`, row-major, `channels()` floats per texel). It has
    /// `STORAGE | COPY_SRC | COPY_DST` usage; the application may bind or copy it between
    /// calls. Writes to it change what the next iteration optimizes from.
    pub fn params_buffer(&self) -> &wgpu::Buffer {
        &self.renderer.scene.params
    }

    /// Current values of texture `i` (index into `set.textures`), copied to the CPU.
    pub fn texture_values(&self, i: usize) -> Result<Vec<f32>> {
        let t = self.set.textures.get(i).ok_or_else(|| {
            Error::Invalid(format!(
                "texture {i} does not exist ({} optimized)",
                self.set.textures.len()
            ))
        })?;
        let all = self.read_params()?;
        Ok(all[t.offset as usize..t.offset as usize + t.len()].to_vec())
    }

    /// Everything a later run needs to continue exactly where this one stands: iteration,
    /// textures, Adam moments and, for ReSTIR, the kept reservoirs with the textures and
    /// adjoint they were drawn at. Restore it with [`Optimizer::restore`].
    pub fn state(&self) -> Result<OptimizerState> {
        let [m1, m2] = self.read_moments()?;
        let previous = if self.uses_previous_state() {
            let last = (self.iteration as usize + 1) % 2;
            let mut params: Vec<f32> = self.gpu.read_pod(&self.renderer.scene.params_prev)?;
            params.truncate(self.set.values.len());
            Some(PreviousState {
                params,
                adjoint: self.gpu.read_pod(&self.adjoint[last])?,
            })
        } else {
            None
        };
        Ok(OptimizerState {
            iteration: self.iteration,
            params: self.read_params()?,
            m1,
            m2,
            previous,
            restir: self.estimator.snapshot(&self.gpu, self.iteration)?,
            control_variate: match &self.control_variate {
                Some(cv) => Some(cv.snapshot(&self.gpu)?),
                None => None,
            },
            exposure: self.exposure.clone(),
        })
    }

    /// Continue from a state taken with [`Optimizer::state`] of an optimizer made with the same
    /// scene, textures and estimator. A state without reservoirs restores a ReSTIR optimizer
    /// with empty ones (its next iteration starts afresh, as the first does).
    pub fn restore(&mut self, state: &OptimizerState) -> Result<()> {
        self.write_params(&state.params)?;
        self.write_moments(&[state.m1.clone(), state.m2.clone()])?;
        let last = (state.iteration as usize + 1) % 2;
        let mut snapshot = state.restir.as_ref();
        let mut cv_snapshot = state.control_variate.as_ref();
        match &state.previous {
            Some(p) => {
                if p.adjoint.len() as u64 * 4 != self.adjoint[last].size()
                    || p.params.len() != self.set.values.len()
                {
                    return Err(Error::Invalid(
                        "the saved state does not match this optimizer's textures and images"
                            .into(),
                    ));
                }
                let q = &self.gpu.queue;
                q.write_buffer(&self.adjoint[last], 0, bytemuck::cast_slice(&p.adjoint));
                let prev = &self.renderer.scene.params_prev;
                q.write_buffer(prev, 0, bytemuck::cast_slice(&p.params));
            }
            // Kept samples and the last image cannot be reused without the state they were
            // drawn at.
            None => {
                snapshot = None;
                cv_snapshot = None;
            }
        }
        self.estimator
            .restore(&self.gpu, snapshot, state.iteration)?;
        if let Some(cv) = &mut self.control_variate {
            cv.restore(&self.gpu, cv_snapshot)?;
        }
        if state.exposure.values.len() == self.cams.len() {
            self.exposure = state.exposure.clone();
            self.upload_exposure();
        }
        self.iteration = state.iteration;
        self.gpu.check("restore optimizer state")
    }

    /// Bytes of GPU memory the optimizer keeps per optimized texel: the textures (current and
    /// previous), gradient and Adam moments, plus the reservoirs and locks of ReSTIR. Buffers
    /// that scale with the image (targets, adjoints) are not counted.
    pub fn state_bytes_per_texel(&self) -> f64 {
        let scene = &self.renderer.scene;
        let bytes = scene.params.size()
            + scene.params_prev.size()
            + self.grad.size()
            + self.moments.iter().map(|b| b.size()).sum::<u64>()
            + self.estimator.state_bytes();
        bytes as f64 / scene.n_texels.max(1) as f64
    }

    /// Dropped and lost values so far.
    pub fn faults(&self) -> Result<FaultCounts> {
        let p: Vec<u32> = self.gpu.read_pod(&self.stats.primal)?;
        let a: Vec<u32> = self.gpu.read_pod(&self.stats.adam)?;
        let l: Vec<u32> = self.gpu.read_pod(&self.stats.loss)?;
        let mut f = FaultCounts {
            skipped_adam: a[0],
            dropped_primal: p[3],
            dropped_pixels: l[0],
            ..Default::default()
        };
        self.estimator.faults(&self.gpu, &mut f)?;
        Ok(f)
    }

    /// The control-variate primal image of task camera `k` from the last iteration or
    /// estimate (the image its loss and adjoint used, at the textures of that iteration);
    /// None for the independent primal.
    pub fn control_variate_image(&self, k: usize) -> Result<Option<Image>> {
        let Some(cv) = &self.control_variate else {
            return Ok(None);
        };
        let (w, h) = (self.settings.width, self.settings.height);
        Ok(Some(Image {
            width: w,
            height: h,
            rgb: cv.image(&self.gpu, k, (w * h) as usize)?,
        }))
    }

    /// The textures of the last iteration (those its primal and gradient were drawn at;
    /// [`Optimizer::read_params`] has them after the Adam step).
    pub fn read_params_prev(&self) -> Result<Vec<f32>> {
        let mut v: Vec<f32> = self.gpu.read_pod(&self.renderer.scene.params_prev)?;
        v.truncate(self.set.values.len());
        Ok(v)
    }

    /// What ReSTIR's merge pass counted (None for the baseline).
    pub fn merge_diagnostics(&self) -> Result<Option<MergeDiagnostics>> {
        self.estimator.restir_diagnostics(&self.gpu)
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
