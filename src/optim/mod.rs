//! Texture optimization on the GPU: primal render, loss and adjoint, the baseline gradient
//! pass, and Adam, as one submission per iteration.

pub mod adam;
pub mod checkpoint;
pub mod export;
pub mod loss;
pub mod plot;
pub mod run;

use crate::gpu::{grid_2d, Binding, Gpu};
use crate::image_io::Image;
use crate::render::layout::*;
use crate::render::params::ParamSet;
use crate::render::{camera_info, encode_timed_pass, Renderer, Techniques, WORKGROUP};
use crate::scene::Scene;
use crate::task::Loss;
use crate::{Error, Result};

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
}

/// Seed of pass `kind` (0 primal, 1 gradient) of camera `camera` at iteration `iteration`:
/// independent streams, so the adjoint never shares random numbers with the gradient samples.
pub fn pass_seed(seed: u32, iteration: u32, camera: u32, kind: u32) -> u32 {
    let mut x = (seed as u64) << 32 ^ (iteration as u64) << 8 ^ (camera as u64) << 2 ^ kind as u64;
    // splitmix64 finalizer
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (x ^ (x >> 31)) as u32
}

struct CameraState {
    render_uniform: wgpu::Buffer,
    gradient_uniform: wgpu::Buffer,
    render_group: wgpu::BindGroup,
    loss_group: wgpu::BindGroup,
    gradient_group: wgpu::BindGroup,
    render_params: GpuRenderParams,
    gradient_params: GpuGradientParams,
}

/// What one iteration reports.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepStats {
    /// Loss of this iteration's primal render (before the update).
    pub loss: f64,
}

/// GPU milliseconds of each kind of pass in the last iteration (from timestamp queries).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PassTimes {
    /// Primal renders of all cameras.
    pub primal_ms: f64,
    /// Loss and adjoint.
    pub loss_ms: f64,
    /// Gradient passes.
    pub gradient_ms: f64,
    /// Adam updates.
    pub adam_ms: f64,
}

/// Timestamp queries: one begin/end pair per pass of an iteration.
struct Timing {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    /// Kind of pass k: 0 primal, 1 loss, 2 gradient, 3 adam.
    kinds: Vec<u8>,
}

/// Counters of dropped or lost values since the optimizer was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// Gradient additions that exhausted the compare-and-swap bound.
    pub lost_updates: u32,
    /// Non-finite values dropped by the gradient pass.
    pub dropped_gradient: u32,
    /// Non-finite gradients skipped by Adam.
    pub skipped_adam: u32,
    /// Non-finite primal samples dropped.
    pub dropped_primal: u32,
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
    stats: [wgpu::Buffer; 3],
    loss_partial: wgpu::Buffer,
    grid: (u32, u32),
    loss_pipeline: wgpu::ComputePipeline,
    gradient_pipeline: wgpu::ComputePipeline,
    adam_pipeline: wgpu::ComputePipeline,
    adam: Vec<(wgpu::Buffer, wgpu::BindGroup, GpuAdamParams)>,
    accum: wgpu::Buffer,
    timing: Option<Timing>,
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
        for t in targets {
            if (t.width, t.height) != (w, h) {
                return Err(Error::Invalid(format!(
                    "target is {}x{}, the task renders {w}x{h}",
                    t.width, t.height
                )));
            }
        }
        let renderer = Renderer::with_params(gpu, scene, &set)?;
        use Binding::*;
        let loss_layout = gpu.layout("loss", &[Uniform, Storage, Storage, StorageRw, StorageRw]);
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
        let n_params = set.values.len() as u64;
        let accum = gpu.storage_zeroed("primal accum", n_pixels as u64 * 16);
        let adjoint = gpu.storage_zeroed("adjoint", n_pixels as u64 * 16);
        let grad = gpu.storage_zeroed("gradient", n_params * 4);
        let moments = [
            gpu.storage_zeroed("adam moment1", n_params * 4),
            gpu.storage_zeroed("adam moment2", n_params * 4),
        ];
        let stats = [
            gpu.storage_zeroed("primal stats", 16),
            gpu.storage_zeroed("gradient stats", 16),
            gpu.storage_zeroed("adam stats", 16),
        ];
        let n_loss_groups = n_pixels.div_ceil(WORKGROUP);
        let loss_partial = gpu.storage_zeroed(
            "loss partial sums",
            (n_loss_groups * targets.len() as u32) as u64 * 4,
        );
        let grid = renderer.tile_grid(w, h);
        let norm = 1.0 / (n_pixels as f32 * 3.0 * targets.len() as f32);
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
                ..Default::default()
            };
            let loss_params = GpuLossParams {
                n_pixels,
                kind: match settings.loss {
                    Loss::L2 => 0,
                    Loss::Relmse => 1,
                },
                norm,
                partial_offset: k as u32 * n_loss_groups,
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
            let loss_uniform = gpu.uniform(
                &format!("loss params {k}"),
                bytemuck::bytes_of(&loss_params),
            );
            cams.push(CameraState {
                render_group: gpu.bind_group(
                    "primal",
                    &renderer.render_layout,
                    &[&render_uniform, &accum, &stats[0]],
                ),
                loss_group: gpu.bind_group(
                    "loss",
                    &loss_layout,
                    &[&loss_uniform, &accum, &target_buf, &adjoint, &loss_partial],
                ),
                gradient_group: gpu.bind_group(
                    "gradient",
                    &gradient_layout,
                    &[&gradient_uniform, &adjoint, &grad, &stats[1]],
                ),
                render_uniform,
                gradient_uniform,
                render_params,
                gradient_params,
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
        let timing = gpu.timestamps.then(|| {
            let mut kinds = Vec::new();
            for _ in 0..cams.len() {
                kinds.extend_from_slice(&[0, 1, 2]);
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

    /// Record primal, loss and gradient passes of every camera for iteration `iteration`.
    fn encode_gradient(&mut self, enc: &mut wgpu::CommandEncoder, iteration: u32) {
        enc.clear_buffer(&self.grad, 0, None);
        let scene_group = &self.renderer.scene.bind_group;
        let loss_grid = grid_2d(
            self.settings.width * self.settings.height,
            WORKGROUP,
            self.gpu
                .device
                .limits()
                .max_compute_workgroups_per_dimension,
        );
        let q = self.timing.as_ref().map(|t| &t.queries);
        for (k, cam) in self.cams.iter_mut().enumerate() {
            cam.render_params.seed = pass_seed(self.settings.seed, iteration, k as u32, 0);
            cam.gradient_params.seed = pass_seed(self.settings.seed, iteration, k as u32, 1);
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
            enc.clear_buffer(&self.accum, 0, None);
            let t = 3 * k as u32;
            let groups = [scene_group, &cam.render_group];
            let pipe = &self.renderer.render_pipeline;
            encode_timed_pass(enc, "primal", pipe, &groups, self.grid, q.map(|q| (q, t)));
            let groups = [&cam.loss_group];
            let pipe = &self.loss_pipeline;
            encode_timed_pass(enc, "loss", pipe, &groups, loss_grid, q.map(|q| (q, t + 1)));
            let groups = [scene_group, &cam.gradient_group];
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
        let first = 3 * self.cams.len() as u32;
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
                _ => t.adam_ms += ms,
            }
        }
        Ok(Some(t))
    }

    /// One gradient estimate at the current textures, as iteration `iteration` would draw it,
    /// without changing anything. Returns (gradient laid out like the parameters, loss).
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

    /// Dropped and lost values so far.
    pub fn faults(&self) -> Result<FaultCounts> {
        let p: Vec<u32> = self.gpu.read_pod(&self.stats[0])?;
        let g: Vec<u32> = self.gpu.read_pod(&self.stats[1])?;
        let a: Vec<u32> = self.gpu.read_pod(&self.stats[2])?;
        Ok(FaultCounts {
            lost_updates: g[1],
            dropped_gradient: g[2],
            skipped_adam: a[0],
            dropped_primal: p[3],
        })
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
