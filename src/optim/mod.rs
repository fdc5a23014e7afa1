//! Texture optimization on the GPU: primal render, loss and adjoint, a gradient estimator
//! (the baseline pass, or ReSTIR's candidate and merge passes), and Adam, as one submission
//! per iteration.

pub mod adam;
pub mod checkpoint;
pub mod export;
pub mod loss;
pub mod plot;
pub mod problem;
pub mod restir;
pub mod run;

use crate::gpu::{grid_2d, Binding, Gpu};
use crate::image_io::Image;
use crate::render::layout::*;
use crate::render::params::ParamSet;
use crate::render::{camera_info, encode_timed_pass, Renderer, Techniques, WORKGROUP};
use crate::scene::Scene;
use crate::task::Loss;
use crate::{Error, Result};
pub use problem::Problem;
pub use restir::{Method, RestirOptions};

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
            gradient_spp: 1,
            loss: Loss::L2,
            seed: 1,
            method: Method::Restir,
            restir: RestirOptions::default(),
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

/// Seed of pass `kind` (0 primal, 1 gradient, 2 target, 3 final render, 4 merge) of camera
/// `camera` at iteration `iteration`: independent streams, so the adjoint never shares random
/// numbers with the gradient samples.
pub fn pass_seed(seed: u32, iteration: u32, camera: u32, kind: u32) -> u32 {
    let x =
        mix64(mix64(mix64(seed as u64) ^ iteration as u64) ^ ((camera as u64) << 8 | kind as u64));
    x as u32
}

struct CameraState {
    render_uniform: wgpu::Buffer,
    gradient_uniform: wgpu::Buffer,
    candidate_uniform: wgpu::Buffer,
    render_group: wgpu::BindGroup,
    /// Per parity of the iteration (the adjoint and reservoir buffers alternate).
    loss_groups: [wgpu::BindGroup; 2],
    gradient_groups: [wgpu::BindGroup; 2],
    candidate_groups: Option<[wgpu::BindGroup; 2]>,
    render_params: GpuRenderParams,
    gradient_params: GpuGradientParams,
    candidate_params: GpuCandidateParams,
}

/// What one iteration reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepStats {
    /// Loss of this iteration's primal render (before the update).
    pub loss: f64,
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
}

/// Timestamp queries: one begin/end pair per pass of an iteration.
struct Timing {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    /// Kind of pass k: 0 primal, 1 loss, 2 gradient or candidates, 3 adam, 4 merge.
    kinds: Vec<u8>,
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
    /// Non-finite ReSTIR replays dropped.
    pub dropped_replays: u32,
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
    /// The ReSTIR estimator's state; `None` for the baseline.
    pub restir: Option<RestirSnapshot>,
}

/// The part of a ReSTIR optimizer's state that carries over to the next iteration.
#[derive(Clone, Debug, PartialEq)]
pub struct RestirSnapshot {
    /// The reservoirs kept from the last iteration (two per texel, 12 words each).
    pub reservoirs: Vec<u32>,
    /// The textures at which the kept reservoirs were drawn.
    pub params_prev: Vec<f32>,
    /// The adjoint images (RGBA per pixel, cameras one after another) of the last iteration,
    /// at which the kept samples' targets were evaluated.
    pub adjoint_prev: Vec<f32>,
    /// Whether the kept reservoirs are to be reused (false before the first iteration).
    pub have_prev: bool,
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
        ("adjoint even".to_string(), 16 * pixels * n_cams as u64),
        ("adjoint odd".to_string(), 16 * pixels * n_cams as u64),
    ];
    for k in 0..n_cams {
        buffers.push((format!("target {k}"), 16 * pixels));
    }
    if settings.method == Method::Restir {
        let res = n_texels * 2 * restir::RESERVOIR_WORDS * 4;
        buffers.push(("reservoirs even".to_string(), res));
        buffers.push(("reservoirs odd".to_string(), res));
        buffers.push(("reservoir locks".to_string(), n_texels * 2 * 4));
    }
    MemoryPlan { buffers }
}

fn export_entry(binding: u32, ty: wgpu::BindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty,
        count: None,
    }
}

/// GPU state of the ReSTIR estimator.
struct RestirState {
    candidate_pipeline: wgpu::ComputePipeline,
    merge_pipeline: wgpu::ComputePipeline,
    /// Reservoirs: fresh then merged at iteration t in buffer t % 2, kept in the other.
    reservoirs: [wgpu::Buffer; 2],
    locks: wgpu::Buffer,
    merge_uniform: wgpu::Buffer,
    merge_params: GpuMergeParams,
    merge_groups: [wgpu::BindGroup; 2],
    merge_grid: (u32, u32),
    /// [candidate stats, merge stats]
    stats: [wgpu::Buffer; 2],
    /// The adjoint buffers (shared with the loss pass): the merge reads the previous one.
    adjoint: [wgpu::Buffer; 2],
    /// Whether the kept reservoirs hold the previous iteration's samples.
    have_prev: bool,
}

/// The optimizer: a scene on the GPU with its optimized textures, targets, and the passes.
pub struct Optimizer {
    gpu: Gpu,
    renderer: Renderer,
    /// Layout and learning rates of the optimized textures (values as at creation).
    pub set: ParamSet,
    settings: Settings,
    cams: Vec<CameraState>,
    grad: wgpu::Buffer,
    moments: [wgpu::Buffer; 2],
    stats: [wgpu::Buffer; 4],
    loss_partial: wgpu::Buffer,
    grid: (u32, u32),
    loss_pipeline: wgpu::ComputePipeline,
    gradient_pipeline: wgpu::ComputePipeline,
    adam_pipeline: wgpu::ComputePipeline,
    adam: Vec<(wgpu::Buffer, wgpu::BindGroup, GpuAdamParams)>,
    accum: wgpu::Buffer,
    timing: Option<Timing>,
    restir: Option<RestirState>,
    /// The texture_export pipeline, built on first use.
    export_pipeline: std::sync::OnceLock<wgpu::ComputePipeline>,
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
        if settings.method == Method::Restir && targets.len() > MAX_CAMERAS {
            return Err(Error::Invalid(format!(
                "ReSTIR handles at most {MAX_CAMERAS} cameras, the task has {}",
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
        use Binding::*;
        let loss_layout = gpu.layout(
            "loss",
            &[Uniform, Storage, Storage, StorageRw, StorageRw, StorageRw],
        );
        let gradient_layout = gpu.layout("gradient", &[Uniform, Storage, StorageRw, StorageRw]);
        let adam_layout = gpu.layout(
            "adam",
            &[Uniform, Storage, StorageRw, StorageRw, StorageRw, StorageRw],
        );
        let loss_pipeline = gpu.compute_pipeline("loss", &[&loss_layout])?;
        let gradient_pipeline =
            gpu.compute_pipeline("gradient", &[&renderer.scene.layout, &gradient_layout])?;
        let adam_pipeline = gpu.compute_pipeline("adam", &[&adam_layout])?;

        let n_pixels = w * h;
        let n_cams = targets.len() as u32;
        let n_params = set.values.len() as u64;
        let accum = gpu.storage_zeroed("primal accum", n_pixels as u64 * 16);
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
        let stats = [
            gpu.storage_zeroed("primal stats", 16),
            gpu.storage_zeroed("gradient stats", 16),
            gpu.storage_zeroed("adam stats", 16),
            gpu.storage_zeroed("loss stats", 16),
        ];
        let n_loss_groups = n_pixels.div_ceil(WORKGROUP);
        let loss_partial =
            gpu.storage_zeroed("loss partial sums", (n_loss_groups * n_cams) as u64 * 4);
        let grid = renderer.tile_grid(w, h);
        let norm = 1.0 / (n_pixels as f32 * 3.0 * n_cams as f32);
        let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;

        // ReSTIR buffers and pipelines.
        let n_texels = renderer.scene.n_texels as u64;
        let restir_parts = if settings.method == Method::Restir {
            let candidate_layout = gpu.layout(
                "restir_candidates",
                &[Uniform, Storage, StorageRw, StorageRw, StorageRw],
            );
            let merge_layout = gpu.layout(
                "restir_merge",
                &[
                    Uniform, Storage, Storage, Storage, StorageRw, StorageRw, StorageRw,
                ],
            );
            let candidate_pipeline = gpu.compute_pipeline(
                "restir_candidates",
                &[&renderer.scene.layout, &candidate_layout],
            )?;
            let merge_pipeline =
                gpu.compute_pipeline("restir_merge", &[&renderer.scene.layout, &merge_layout])?;
            let res_size = n_texels * 2 * restir::RESERVOIR_WORDS * 4;
            let reservoirs = [
                gpu.storage_zeroed("reservoirs even", res_size),
                gpu.storage_zeroed("reservoirs odd", res_size),
            ];
            let locks = gpu.storage_zeroed("reservoir locks", n_texels * 2 * 4);
            let rstats = [
                gpu.storage_zeroed("candidate stats", 16),
                gpu.storage_zeroed("merge stats", 16),
            ];
            let merge_grid = grid_2d(n_texels as u32, WORKGROUP, max_dim);
            let mut cameras = [GpuCameraInfo::default(); MAX_CAMERAS];
            for (k, &cam) in settings.cameras.iter().enumerate() {
                cameras[k] = camera_info(&scene.cameras[cam], w, h);
            }
            let merge_params = GpuMergeParams {
                cameras,
                n_texels: n_texels as u32,
                n_pixels,
                seed: 0,
                flags: 0,
                m_fresh: (2 * settings.gradient_spp * n_cams) as f32,
                m_cap: settings.restir.m_cap,
                inv_spp: 1.0 / settings.gradient_spp as f32,
                n_textures: set.textures.len() as u32,
                stride: merge_grid.0 * WORKGROUP,
                _pad: [0; 3],
            };
            let merge_uniform = gpu.uniform("merge params", bytemuck::bytes_of(&merge_params));
            let merge_groups = [0usize, 1].map(|p| {
                gpu.bind_group(
                    "restir_merge",
                    &merge_layout,
                    &[
                        &merge_uniform,
                        &adjoint[p],
                        &adjoint[1 - p],
                        &reservoirs[1 - p],
                        &reservoirs[p],
                        &grad,
                        &rstats[1],
                    ],
                )
            });
            Some((
                candidate_layout,
                RestirState {
                    candidate_pipeline,
                    merge_pipeline,
                    reservoirs,
                    locks,
                    merge_uniform,
                    merge_params,
                    merge_groups,
                    merge_grid,
                    stats: rstats,
                    adjoint: adjoint.clone(),
                    have_prev: false,
                },
            ))
        } else {
            None
        };

        let mut cams = Vec::new();
        for (k, (&cam, target)) in settings.cameras.iter().zip(targets).enumerate() {
            let camera = camera_info(
                scene
                    .cameras
                    .get(cam)
                    .ok_or_else(|| Error::Invalid(format!("camera index {cam} out of range")))?,
                w,
                h,
            );
            let render_params = GpuRenderParams {
                camera,
                spp: settings.primal_spp,
                techniques: Techniques::Mis.bits(),
                stride: grid.0 * WORKGROUP,
                ..Default::default()
            };
            let gradient_params = GpuGradientParams {
                camera,
                spp: settings.gradient_spp,
                techniques: Techniques::Mis.bits(),
                stride: grid.0 * WORKGROUP,
                inv_spp: 1.0 / settings.gradient_spp as f32,
                adjoint_offset: k as u32 * n_pixels,
                ..Default::default()
            };
            let candidate_params = GpuCandidateParams {
                camera,
                seed: 0,
                spp: settings.gradient_spp,
                stride: grid.0 * WORKGROUP,
                inv_spp: 1.0 / settings.gradient_spp as f32,
                camera_index: k as u32,
                adjoint_offset: k as u32 * n_pixels,
                positivize: settings.restir.positivization as u32,
                _pad: 0,
            };
            let loss_params = GpuLossParams {
                n_pixels,
                kind: match settings.loss {
                    Loss::L2 => 0,
                    Loss::Relmse => 1,
                },
                norm,
                partial_offset: k as u32 * n_loss_groups,
                adjoint_offset: k as u32 * n_pixels,
                _pad: [0; 3],
            };
            let target_data: Vec<[f32; 4]> =
                target.rgb.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
            let target_buf = gpu.storage(
                &format!("target {k}"),
                bytemuck::cast_slice(&target_data),
                wgpu::BufferUsages::empty(),
            );
            let render_uniform = gpu.uniform(
                &format!("primal params {k}"),
                bytemuck::bytes_of(&render_params),
            );
            let gradient_uniform = gpu.uniform(
                &format!("gradient params {k}"),
                bytemuck::bytes_of(&gradient_params),
            );
            let candidate_uniform = gpu.uniform(
                &format!("candidate params {k}"),
                bytemuck::bytes_of(&candidate_params),
            );
            let loss_uniform = gpu.uniform(
                &format!("loss params {k}"),
                bytemuck::bytes_of(&loss_params),
            );
            let candidate_groups = restir_parts.as_ref().map(|(layout, st)| {
                [0usize, 1].map(|p| {
                    gpu.bind_group(
                        "restir_candidates",
                        layout,
                        &[
                            &candidate_uniform,
                            &adjoint[p],
                            &st.reservoirs[p],
                            &st.locks,
                            &st.stats[0],
                        ],
                    )
                })
            });
            cams.push(CameraState {
                render_group: gpu.bind_group(
                    "primal",
                    &renderer.render_layout,
                    &[&render_uniform, &accum, &stats[0]],
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
                            &stats[3],
                        ],
                    )
                }),
                gradient_groups: [0usize, 1].map(|p| {
                    gpu.bind_group(
                        "gradient",
                        &gradient_layout,
                        &[&gradient_uniform, &adjoint[p], &grad, &stats[1]],
                    )
                }),
                candidate_groups,
                render_uniform,
                gradient_uniform,
                candidate_uniform,
                render_params,
                gradient_params,
                candidate_params,
            });
        }
        let mut adam = Vec::new();
        for t in &set.textures {
            let (lo, hi) = t.slot.range();
            let p = GpuAdamParams {
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
                _pad: [0; 2],
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
                    &stats[2],
                ],
            );
            adam.push((u, g, p));
        }
        // Timestamps: per camera primal, loss, gradient (or candidates); then the merge; then
        // one Adam pass per texture.
        let timing = gpu.timestamps.then(|| {
            let mut kinds = Vec::new();
            for _ in 0..cams.len() {
                kinds.extend_from_slice(&[0, 1, 2]);
            }
            if restir_parts.is_some() {
                kinds.push(4);
            }
            kinds.extend(std::iter::repeat_n(3, adam.len()));
            let n = 2 * kinds.len() as u32;
            Timing {
                queries: gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("pass timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: n,
                }),
                resolve: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("pass timestamps resolve"),
                    size: 8 * n as u64,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                kinds,
            }
        });
        gpu.check("optimizer setup")?;
        Ok(Optimizer {
            gpu: gpu.clone(),
            renderer,
            set,
            settings,
            cams,
            grad,
            moments,
            stats,
            loss_partial,
            grid,
            loss_pipeline,
            gradient_pipeline,
            adam_pipeline,
            adam,
            accum,
            timing,
            restir: restir_parts.map(|(_, st)| st),
            export_pipeline: std::sync::OnceLock::new(),
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

    /// Record primal, loss and gradient passes of every camera for iteration `iteration`
    /// (for ReSTIR: candidates per camera, then the merge, then the copy of the textures that
    /// the next merge will call previous). The gradient ends in `grad`.
    fn encode_gradient(&mut self, enc: &mut wgpu::CommandEncoder, iteration: u32) {
        let parity = (iteration % 2) as usize;
        let scene_group = &self.renderer.scene.bind_group;
        let max_dim = self
            .gpu
            .device
            .limits()
            .max_compute_workgroups_per_dimension;
        let loss_grid = grid_2d(
            self.settings.width * self.settings.height,
            WORKGROUP,
            max_dim,
        );
        let q = self.timing.as_ref().map(|t| &t.queries);
        match &self.restir {
            None => enc.clear_buffer(&self.grad, 0, None),
            Some(st) => {
                enc.clear_buffer(&st.reservoirs[parity], 0, None);
                enc.clear_buffer(&st.locks, 0, None);
            }
        }
        for (k, cam) in self.cams.iter_mut().enumerate() {
            cam.render_params.seed = pass_seed(self.settings.seed, iteration, k as u32, 0);
            let gseed = pass_seed(self.settings.seed, iteration, k as u32, 1);
            cam.gradient_params.seed = gseed;
            cam.candidate_params.seed = gseed;
            self.gpu.queue.write_buffer(
                &cam.render_uniform,
                0,
                bytemuck::bytes_of(&cam.render_params),
            );
            self.gpu.queue.write_buffer(
                &cam.gradient_uniform,
                0,
                bytemuck::bytes_of(&cam.gradient_params),
            );
            self.gpu.queue.write_buffer(
                &cam.candidate_uniform,
                0,
                bytemuck::bytes_of(&cam.candidate_params),
            );
            enc.clear_buffer(&self.accum, 0, None);
            let t = 3 * k as u32;
            let groups = [scene_group, &cam.render_group];
            let pipe = &self.renderer.render_pipeline;
            encode_timed_pass(enc, "primal", pipe, &groups, self.grid, q.map(|q| (q, t)));
            let groups = [&cam.loss_groups[parity]];
            let pipe = &self.loss_pipeline;
            encode_timed_pass(enc, "loss", pipe, &groups, loss_grid, q.map(|q| (q, t + 1)));
            match (&self.restir, &cam.candidate_groups) {
                (Some(st), Some(cg)) => {
                    let groups = [scene_group, &cg[parity]];
                    let pipe = &st.candidate_pipeline;
                    encode_timed_pass(
                        enc,
                        "restir_candidates",
                        pipe,
                        &groups,
                        self.grid,
                        q.map(|q| (q, t + 2)),
                    );
                }
                _ => {
                    let groups = [scene_group, &cam.gradient_groups[parity]];
                    let pipe = &self.gradient_pipeline;
                    encode_timed_pass(
                        enc,
                        "gradient",
                        pipe,
                        &groups,
                        self.grid,
                        q.map(|q| (q, t + 2)),
                    );
                }
            }
        }
        let merge_slot = 3 * self.cams.len() as u32;
        if let Some(st) = &mut self.restir {
            let o = &self.settings.restir;
            st.merge_params.seed = pass_seed(self.settings.seed, iteration, 0, 4);
            st.merge_params.flags =
                (o.temporal as u32) | (o.positivization as u32) << 1 | (st.have_prev as u32) << 2;
            self.gpu
                .queue
                .write_buffer(&st.merge_uniform, 0, bytemuck::bytes_of(&st.merge_params));
            let groups = [scene_group, &st.merge_groups[parity]];
            encode_timed_pass(
                enc,
                "restir_merge",
                &st.merge_pipeline,
                &groups,
                st.merge_grid,
                q.map(|q| (q, merge_slot)),
            );
            // The textures of this iteration become the previous ones of the next merge.
            let params = &self.renderer.scene.params;
            enc.copy_buffer_to_buffer(
                params,
                0,
                &self.renderer.scene.params_prev,
                0,
                params.size(),
            );
            st.have_prev = o.temporal;
        }
    }

    fn read_loss(&self) -> Result<f64> {
        let partial: Vec<f32> = self.gpu.read_pod(&self.loss_partial)?;
        Ok(partial.iter().map(|&v| v as f64).sum())
    }

    /// One iteration: render, loss, gradient, Adam. Returns the loss of the render.
    pub fn step(&mut self) -> Result<StepStats> {
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("iteration"),
            });
        self.encode_gradient(&mut enc, self.iteration);
        let t = self.iteration + 1;
        let max_dim = self
            .gpu
            .device
            .limits()
            .max_compute_workgroups_per_dimension;
        let first = 3 * self.cams.len() as u32 + self.restir.is_some() as u32;
        for (k, (u, g, p)) in self.adam.iter_mut().enumerate() {
            p.bias1 = 1.0 - adam::BETA1.powi(t as i32);
            p.bias2 = 1.0 - adam::BETA2.powi(t as i32);
            self.gpu.queue.write_buffer(u, 0, bytemuck::bytes_of(p));
            let timing = self
                .timing
                .as_ref()
                .map(|tm| (&tm.queries, first + k as u32));
            let grid = grid_2d(p.count, WORKGROUP, max_dim);
            encode_timed_pass(&mut enc, "adam", &self.adam_pipeline, &[g], grid, timing);
        }
        if let Some(tm) = &self.timing {
            enc.resolve_query_set(&tm.queries, 0..2 * tm.kinds.len() as u32, &tm.resolve, 0);
        }
        self.gpu.queue.submit([enc.finish()]);
        self.iteration = t;
        let loss = self.read_loss()?;
        Ok(StepStats { loss })
    }

    /// GPU time per kind of pass in the last [`Optimizer::step`], when the adapter has
    /// timestamp queries.
    pub fn pass_times(&self) -> Result<Option<PassTimes>> {
        let Some(tm) = &self.timing else {
            return Ok(None);
        };
        let ticks: Vec<u64> = self.gpu.read_pod(&tm.resolve)?;
        let period = self.gpu.queue.get_timestamp_period() as f64 * 1e-6;
        let mut t = PassTimes::default();
        for (k, kind) in tm.kinds.iter().enumerate() {
            let ms = ticks[2 * k + 1].saturating_sub(ticks[2 * k]) as f64 * period;
            match kind {
                0 => t.primal_ms += ms,
                1 => t.loss_ms += ms,
                2 => t.gradient_ms += ms,
                4 => t.merge_ms += ms,
                _ => t.adam_ms += ms,
            }
        }
        Ok(Some(t))
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
        self.encode_gradient(&mut enc, iteration);
        self.gpu.queue.submit([enc.finish()]);
        let loss = self.read_loss()?;
        let mut g: Vec<f32> = self.gpu.read_pod(&self.grad)?;
        g.truncate(self.set.values.len());
        Ok((g, loss))
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
        Optimizer::new(
            gpu,
            &problem.scene,
            problem.set.clone(),
            settings,
            &problem.targets,
        )
    }

    /// Run iterations until `stop`, calling `on_iteration` after each; the callback returns
    /// [`ControlFlow::Break`](std::ops::ControlFlow::Break) to stop early. Returns the
    /// progress after the last iteration run (`None` if none ran).
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

    /// Texture `i` (index into `set.textures`) as a new `Rgba32Float` GPU texture of its size
    /// that the application can bind: RGB for base color, the value in R, G and B for
    /// roughness and metallic, alpha 1. Usage: `TEXTURE_BINDING | STORAGE_BINDING |
    /// COPY_SRC`. The copy is made on the GPU when this is called.
    pub fn create_texture(&self, i: usize) -> Result<wgpu::Texture> {
        let t = self.set.textures.get(i).ok_or_else(|| {
            Error::Invalid(format!(
                "texture {i} does not exist ({} optimized)",
                self.set.textures.len()
            ))
        })?;
        let device = &self.gpu.device;
        let label = format!("texture_export {}", t.name());
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(&label),
            size: wgpu::Extent3d {
                width: t.width,
                height: t.height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let pipeline = match self.export_pipeline.get() {
            Some(p) => p,
            None => {
                let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("texture_export"),
                    entries: &[
                        export_entry(
                            0,
                            wgpu::BindingType::Buffer {
                                ty: wgpu::BufferBindingType::Uniform,
                                has_dynamic_offset: false,
                                min_binding_size: None,
                            },
                        ),
                        export_entry(
                            1,
                            wgpu::BindingType::Buffer {
                                ty: wgpu::BufferBindingType::Storage { read_only: true },
                                has_dynamic_offset: false,
                                min_binding_size: None,
                            },
                        ),
                        export_entry(
                            2,
                            wgpu::BindingType::StorageTexture {
                                access: wgpu::StorageTextureAccess::WriteOnly,
                                format: wgpu::TextureFormat::Rgba32Float,
                                view_dimension: wgpu::TextureViewDimension::D2,
                            },
                        ),
                    ],
                });
                let p = self.gpu.compute_pipeline("texture_export", &[&layout])?;
                self.export_pipeline.get_or_init(|| p)
            }
        };
        let params = GpuExportParams {
            offset: t.offset,
            width: t.width,
            height: t.height,
            channels: t.channels(),
        };
        let uniform = self
            .gpu
            .uniform("texture_export params", bytemuck::bytes_of(&params));
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("texture_export"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: self.renderer.scene.params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
            ],
        });
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("texture_export"),
        });
        let max_dim = device.limits().max_compute_workgroups_per_dimension;
        let grid = grid_2d(t.width * t.height, WORKGROUP, max_dim);
        crate::render::encode_pass(&mut enc, "texture_export", pipeline, &[&group], grid);
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.check("texture_export")?;
        Ok(texture)
    }

    /// Everything a later run needs to continue exactly where this one stands: iteration,
    /// textures, Adam moments and, for ReSTIR, the kept reservoirs with the textures they were
    /// drawn at. Restore it with [`Optimizer::restore`].
    pub fn state(&self) -> Result<OptimizerState> {
        let [m1, m2] = self.read_moments()?;
        let restir = match &self.restir {
            None => None,
            Some(st) => {
                let last = (self.iteration as usize + 1) % 2;
                let kept = &st.reservoirs[last];
                let mut params_prev: Vec<f32> =
                    self.gpu.read_pod(&self.renderer.scene.params_prev)?;
                params_prev.truncate(self.set.values.len());
                Some(RestirSnapshot {
                    reservoirs: self.gpu.read_pod(kept)?,
                    adjoint_prev: self.gpu.read_pod(&st.adjoint[last])?,
                    params_prev,
                    have_prev: st.have_prev,
                })
            }
        };
        Ok(OptimizerState {
            iteration: self.iteration,
            params: self.read_params()?,
            m1,
            m2,
            restir,
        })
    }

    /// Continue from a state taken with [`Optimizer::state`] of an optimizer made with the same
    /// scene, textures and estimator. A state without reservoirs restores a ReSTIR optimizer
    /// with empty ones (its next iteration starts afresh, as the first does).
    pub fn restore(&mut self, state: &OptimizerState) -> Result<()> {
        self.write_params(&state.params)?;
        self.write_moments(&[state.m1.clone(), state.m2.clone()])?;
        if let Some(st) = &mut self.restir {
            let last = (state.iteration as usize + 1) % 2;
            let kept = &st.reservoirs[last];
            match &state.restir {
                Some(r) => {
                    if r.reservoirs.len() as u64 * 4 != kept.size()
                        || r.adjoint_prev.len() as u64 * 4 != st.adjoint[last].size()
                        || r.params_prev.len() != self.set.values.len()
                    {
                        return Err(Error::Invalid(
                            "the saved ReSTIR state does not match this optimizer's textures and images".into(),
                        ));
                    }
                    let q = &self.gpu.queue;
                    q.write_buffer(kept, 0, bytemuck::cast_slice(&r.reservoirs));
                    let adjoint = &st.adjoint[last];
                    q.write_buffer(adjoint, 0, bytemuck::cast_slice(&r.adjoint_prev));
                    let prev = &self.renderer.scene.params_prev;
                    q.write_buffer(prev, 0, bytemuck::cast_slice(&r.params_prev));
                    st.have_prev = r.have_prev && self.settings.restir.temporal;
                }
                None => st.have_prev = false,
            }
        }
        self.iteration = state.iteration;
        self.gpu.check("restore optimizer state")
    }

    /// Bytes of GPU memory the optimizer keeps per optimized texel: the textures (current and
    /// previous), gradient and Adam moments, plus the reservoirs and locks of ReSTIR. Buffers
    /// that scale with the image (targets, adjoints) are not counted.
    pub fn state_bytes_per_texel(&self) -> f64 {
        let scene = &self.renderer.scene;
        let mut bytes = scene.params.size()
            + scene.params_prev.size()
            + self.grad.size()
            + self.moments.iter().map(|b| b.size()).sum::<u64>();
        if let Some(r) = &self.restir {
            bytes += r.reservoirs.iter().map(|b| b.size()).sum::<u64>() + r.locks.size();
        }
        bytes as f64 / scene.n_texels.max(1) as f64
    }

    /// Dropped and lost values so far.
    pub fn faults(&self) -> Result<FaultCounts> {
        let p: Vec<u32> = self.gpu.read_pod(&self.stats[0])?;
        let g: Vec<u32> = self.gpu.read_pod(&self.stats[1])?;
        let a: Vec<u32> = self.gpu.read_pod(&self.stats[2])?;
        let l: Vec<u32> = self.gpu.read_pod(&self.stats[3])?;
        let mut f = FaultCounts {
            lost_updates: g[1],
            dropped_gradient: g[2],
            skipped_adam: a[0],
            dropped_primal: p[3],
            dropped_pixels: l[0],
            ..Default::default()
        };
        if let Some(st) = &self.restir {
            let c: Vec<u32> = self.gpu.read_pod(&st.stats[0])?;
            let m: Vec<u32> = self.gpu.read_pod(&st.stats[1])?;
            f.lost_offers = c[1];
            f.dropped_gradient += c[2];
            f.dropped_replays = m[1];
        }
        Ok(f)
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
