//! The baseline's gradient from a pool of stored camera paths (its `cache` option): each
//! camera keeps `gradient_spp` paths per pixel (the path cache's layout and trace pass,
//! [`PathPool`]), drawn from the gradient's own random numbers; `cache` of them are traced
//! anew each iteration, and gradient_cached.wgsl shades and differentiates every one under
//! the current textures without a ray. A pool refreshed whole draws the camera samples that
//! gradient.wgsl would trace.
use crate::gpu::{encode_timed_pass, Gpu};
use crate::optim::estimator::{EstimatorOptions, EstimatorState, Frame, Scale, Setup, Sizes};
use crate::optim::primal::path_pool::{camera_bytes, unusable, PathCacheSnapshot, PathPool};
use crate::optim::primal::path_pool::{PoolSetup, PrimalCachedParams, MAX_VERTICES};
use crate::optim::{pass_seed, PassKind, PassTimer, Seeds};
use crate::render::Techniques;
use crate::Result;
use bytemuck::{Pod, Zeroable};

/// The baseline's options (the task file's `[optimizer.baseline]`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct BaselineOptions {
    /// The gradient's path pool: of the `gradient_spp` camera paths kept per pixel, this many
    /// are traced anew each iteration (at most `gradient_spp`); None: every sample is traced.
    pub cache: Option<u32>,
}

/// Group 1 of `gradient_cached.wgsl`.
pub(crate) const GRADIENT_CACHED_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "gradient_cached",
    group: 1,
    names: &["cp", "gcp", "adjoint", "grad", "gstats", "env_grad", "path_cache"],
};

/// `GradientCachedParams` in gradient_cached.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GradientCachedParams {
    pub adjoint_offset: u32,
    pub inv_spp: f32,
    pub _pad: [u32; 2],
}

/// The names of a pool's state in an [`EstimatorState`]: camera k's paths, and the slot the
/// next refresh starts at.
fn pool_array(k: usize) -> String {
    format!("gradient pool {k}")
}
const NEXT_SLOT: &str = "gradient pool next slot";

/// The pool's buffers in the memory plan, where the options ask for one.
pub(super) fn memory(sizes: &Sizes, options: &EstimatorOptions) -> Vec<(String, u64, Scale)> {
    let o: BaselineOptions = options.get().unwrap_or_default();
    if o.cache.is_none() || sizes.max_depth > MAX_VERTICES || sizes.pixels == 0 {
        return Vec::new();
    }
    let spp = (sizes.gradient_samples / sizes.pixels) as u32;
    let bytes = camera_bytes(sizes.pixels, spp, sizes.max_depth);
    vec![("gradient path pool".into(), bytes, Scale::Pixel)]
}

struct Camera {
    /// The shading pass's uniform (the pool's parameters) and its group per parity of the
    /// iteration (the adjoint buffers alternate).
    uniform: wgpu::Buffer,
    groups: [wgpu::BindGroup; 2],
}

/// The pool of every camera and the pass that differentiates it.
pub(super) struct GradientPool {
    pool: PathPool,
    pipeline: wgpu::ComputePipeline,
    cameras: Vec<Camera>,
    /// Bytes of the stored paths, all cameras'.
    bytes: u64,
    queue: wgpu::Queue,
}

impl GradientPool {
    /// The pool of `s`'s cameras with `refresh` paths traced anew per pixel and iteration,
    /// counting its samples in `stats` (gradient.wgsl's); None where the paths cannot be
    /// kept (the log says why; the gradient then traces every sample).
    pub(super) fn new(
        s: &Setup,
        refresh: u32,
        stats: &wgpu::Buffer,
    ) -> Result<Option<GradientPool>> {
        let gpu = s.gpu;
        let max_depth = s.scene.info.max_depth.max(1);
        let pixels = s.width as u64 * s.height as u64;
        if refresh > s.gradient_spp {
            return Err(crate::Error::Invalid(format!(
                "optimizer.baseline.cache ({refresh}) must be at most gradient_spp ({})",
                s.gradient_spp
            )));
        }
        if let Some(why) = unusable(gpu, pixels, s.gradient_spp, max_depth) {
            log::warn!("gradient path pool off, the gradient traces every sample: {why}");
            return Ok(None);
        }
        log::info!(
            "gradient path pool: {} paths per pixel, {refresh} traced anew each iteration",
            s.gradient_spp
        );
        // (The trace pass counts its rays in render.wgsl's slots: a buffer of its own.)
        let trace_stats = gpu.storage_zeroed("gradient pool trace stats", 16);
        let pool = PathPool::new(
            gpu,
            &PoolSetup {
                scene: s.scene,
                cameras: s.cameras,
                grid: s.grid,
                spp: s.gradient_spp,
                refresh,
                max_depth,
                techniques: Techniques::Mis.bits(),
                optimized_only: true,
                stats: &trace_stats,
                label: "gradient path pool",
            },
        )?;
        let layout = gpu.pass_layout("gradient_cached", 1)?;
        let pipeline = (s.scene).pipeline(gpu, "gradient_cached", &[&s.scene.layout, &layout])?;
        let n_pixels = s.width * s.height;
        let cameras = (0..s.cameras.len())
            .map(|k| {
                let uniform = gpu.uniform(
                    &format!("gradient_cached params {k}"),
                    bytemuck::bytes_of(&PrimalCachedParams::default()),
                );
                let gcp = GradientCachedParams {
                    adjoint_offset: k as u32 * n_pixels,
                    inv_spp: 1.0 / s.gradient_spp as f32,
                    ..Default::default()
                };
                let gcp = gpu.uniform(
                    &format!("gradient_cached adjoint params {k}"),
                    bytemuck::bytes_of(&gcp),
                );
                let groups = [0usize, 1].map(|p| {
                    gpu.bind(
                        &GRADIENT_CACHED_GROUP,
                        "gradient_cached",
                        &layout,
                        &[
                            ("cp", &uniform),
                            ("gcp", &gcp),
                            ("adjoint", &s.adjoint[p]),
                            ("grad", s.grad),
                            ("gstats", stats),
                            ("env_grad", s.env_grad),
                            ("path_cache", pool.pool(k)),
                        ],
                    )
                });
                Camera { uniform, groups }
            })
            .collect();
        Ok(Some(GradientPool {
            pool,
            pipeline,
            cameras,
            bytes: s.cameras.len() as u64 * camera_bytes(pixels, s.gradient_spp, max_depth),
            queue: gpu.queue.clone(),
        }))
    }

    /// Record every camera's refresh and the shading of its pool into the gradient (over
    /// `grid`, one camera's image in tiles).
    pub(super) fn encode(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        frame: &Frame,
        grid: (u32, u32),
        timer: &mut PassTimer,
    ) {
        for (k, cam) in self.cameras.iter().enumerate() {
            let seed = pass_seed(frame.seed, frame.iteration, k as u32, Seeds::GRADIENT);
            let shade = (self.pool).encode_trace(
                enc,
                frame.scene_group,
                (k, seed),
                grid,
                PassKind::Gradient,
                timer,
            );
            self.queue
                .write_buffer(&cam.uniform, 0, bytemuck::bytes_of(&shade));
            encode_timed_pass(
                enc,
                "gradient_cached",
                &self.pipeline,
                &[frame.scene_group, &cam.groups[frame.parity()]],
                grid,
                timer.next(PassKind::Gradient),
            );
        }
    }

    pub(super) fn finish_iteration(&mut self) {
        self.pool.finish_iteration();
    }

    pub(super) fn set_techniques(&mut self, techniques: Techniques) {
        self.pool.set_techniques(techniques.bits());
    }

    /// Bytes of the stored paths.
    pub(super) fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The stored paths into `st` (nothing before the pool is filled).
    pub(super) fn snapshot(&self, gpu: &Gpu, st: &mut EstimatorState) -> Result<()> {
        if let Some(s) = self.pool.snapshot(gpu)? {
            st.counters.push((NEXT_SLOT.into(), s.next_slot));
            for (k, p) in s.pools.into_iter().enumerate() {
                st.arrays.push((pool_array(k), p));
            }
        }
        Ok(())
    }

    /// Continue from the paths in `st` (none: an empty pool, filled at the next iteration).
    pub(super) fn restore(&mut self, gpu: &Gpu, st: Option<&EstimatorState>) -> Result<()> {
        let saved = st.and_then(|st| {
            let next_slot = st.counter(NEXT_SLOT)?;
            let pools = (0..self.cameras.len())
                .map(|k| st.array(&pool_array(k)).map(<[u32]>::to_vec))
                .collect::<Option<Vec<_>>>()?;
            Some(PathCacheSnapshot { pools, next_slot })
        });
        self.pool.restore(gpu, saved.as_ref())
    }
}
