//! A pool of stored camera paths (the layout of path_cache.wgsl), traced by
//! primal_cache_trace.wgsl: per camera and pixel `spp` paths, of which `refresh` are traced
//! anew every iteration in rotation, so that every path is replaced within `spp / refresh`
//! iterations. The primal's path cache ([`super::PathCache`]) shades one; the baseline
//! estimator's gradient pool (src/optim/estimator/baseline) shades another, drawn from the
//! gradient's own random numbers, so that the image and the gradient stay independent.
use crate::gpu::Gpu;
use crate::optim::{PassKind, PassTimer};
use crate::render::layout::GpuCameraInfo;
use crate::render::{GpuScene, WORKGROUP};
use crate::{Error, Result};
use bytemuck::{Pod, Zeroable};

/// Group 1 of `primal_cache_trace.wgsl`.
pub(crate) const PRIMAL_CACHE_TRACE_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "primal_cache_trace",
    group: 1,
    names: &["cp", "stats", "path_cache"],
};

/// `PrimalCachedParams` in path_cache.wgsl (a test checks the layout); the fields are
/// documented there.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct PrimalCachedParams {
    pub camera: GpuCameraInfo,
    pub seed: u32,
    pub spp: u32,
    pub techniques: u32,
    pub stride: u32,
    pub two_states: u32,
    pub refresh_first: u32,
    pub refresh_count: u32,
    pub vertices: u32,
    pub optimized_only: u32,
    pub _pad: [u32; 3],
}

pub use crate::gpu::abi::path_cache::MAX_VERTICES;

/// Words of one stored path with `vertices` vertices (path_cache.wgsl: its header, and per
/// vertex the vertex and two arrivals).
pub fn path_words(vertices: u32) -> u64 {
    use crate::gpu::abi::path_cache::*;
    (HEADER_WORDS + vertices * (VERTEX_WORDS + 2 * ARRIVAL_WORDS)) as u64
}

/// Bytes of the cache of one camera: `pixels` x `spp` paths of `max_depth` vertices.
pub fn camera_bytes(pixels: u64, spp: u32, max_depth: u32) -> u64 {
    4 * pixels * spp as u64 * path_words(max_depth.clamp(1, MAX_VERTICES))
}

/// Why the cache cannot be used for images of `pixels` pixels, `spp` paths each of
/// `max_depth` vertices, or None: paths deeper than it keeps, or a camera's pool larger than
/// one storage buffer.
pub fn unusable(gpu: &Gpu, pixels: u64, spp: u32, max_depth: u32) -> Option<String> {
    if max_depth > MAX_VERTICES {
        return Some(format!(
            "it keeps paths of at most {MAX_VERTICES} vertices (the scene's depth is {max_depth})"
        ));
    }
    let bytes = camera_bytes(pixels, spp, max_depth);
    let l = gpu.device.limits();
    let limit = l.max_storage_buffer_binding_size.min(l.max_buffer_size);
    (bytes > limit).then(|| {
        format!(
            "one camera's pool would take {:.0} MiB, more than one storage buffer holds \
             ({:.0} MiB)",
            bytes as f64 / 1048576.0,
            limit as f64 / 1048576.0
        )
    })
}

/// What a checkpoint keeps of a pool of stored paths (the primal's path cache, the baseline's
/// gradient pool): every camera's stored paths and where the next refresh starts. Paths are
/// samples of the same path space under any textures, so a resumed run shades them as the
/// uninterrupted run does.
#[derive(Clone, Debug, PartialEq)]
pub struct PathCacheSnapshot {
    /// Per camera, the pool's words (path_cache.wgsl's layout).
    pub pools: Vec<Vec<u32>>,
    /// The slot the next refresh starts at.
    pub next_slot: u32,
}

struct Camera {
    pool: wgpu::Buffer,
    uniform: wgpu::Buffer,
    params: PrimalCachedParams,
    group: wgpu::BindGroup,
}

/// What a pool is made of: the cameras' constants and the scene's paths.
pub(crate) struct PoolSetup<'a> {
    pub scene: &'a GpuScene,
    pub cameras: &'a [GpuCameraInfo],
    /// Workgroups of one camera's image in 8x8 tiles.
    pub grid: (u32, u32),
    /// Paths kept per pixel, traced anew per pixel and iteration, vertices of a path.
    pub spp: u32,
    pub refresh: u32,
    pub max_depth: u32,
    /// The techniques the paths are sampled with (`Techniques::bits`).
    pub techniques: u32,
    /// Whether a path whose first vertex has no optimized texture is shaded only where a
    /// later vertex or the environment may need it (PrimalCachedParams::optimized_only).
    pub optimized_only: bool,
    /// Where the trace pass counts its rays (render.wgsl's statistics).
    pub stats: &'a wgpu::Buffer,
    /// The buffers' labels start with it.
    pub label: &'a str,
}

/// The stored paths of every camera and the pass that traces them.
pub(crate) struct PathPool {
    pipeline: wgpu::ComputePipeline,
    cameras: Vec<Camera>,
    spp: u32,
    refresh: u32,
    /// Whether the pools hold paths (false until the first trace, and after a restore
    /// without one).
    filled: bool,
    /// Where the next refresh starts.
    next_slot: u32,
    max_dim: u32,
    queue: wgpu::Queue,
}

impl PathPool {
    pub(crate) fn new(gpu: &Gpu, s: &PoolSetup) -> Result<PathPool> {
        if s.refresh == 0 || s.refresh > s.spp {
            return Err(Error::Invalid(format!(
                "{}: {} paths refreshed per iteration of {} kept",
                s.label, s.refresh, s.spp
            )));
        }
        let layout = gpu.pass_layout("primal_cache_trace", 1)?;
        let pipeline = s
            .scene
            .pipeline(gpu, "primal_cache_trace", &[&s.scene.layout, &layout])?;
        let cameras = (s.cameras.iter().enumerate())
            .map(|(k, camera)| {
                let pixels = camera.width as u64 * camera.height as u64;
                let pool = gpu.storage_zeroed(
                    &format!("{} {k}", s.label),
                    camera_bytes(pixels, s.spp, s.max_depth),
                );
                let params = PrimalCachedParams {
                    camera: *camera,
                    spp: s.spp,
                    techniques: s.techniques,
                    stride: s.grid.0 * WORKGROUP,
                    vertices: s.max_depth.clamp(1, MAX_VERTICES),
                    optimized_only: s.optimized_only as u32,
                    ..Default::default()
                };
                let uniform = gpu.uniform(
                    &format!("{} trace params {k}", s.label),
                    bytemuck::bytes_of(&params),
                );
                let group = gpu.bind(
                    &PRIMAL_CACHE_TRACE_GROUP,
                    "primal_cache_trace",
                    &layout,
                    &[("cp", &uniform), ("stats", s.stats), ("path_cache", &pool)],
                );
                Camera {
                    pool,
                    uniform,
                    params,
                    group,
                }
            })
            .collect();
        Ok(PathPool {
            pipeline,
            cameras,
            spp: s.spp,
            refresh: s.refresh,
            filled: false,
            next_slot: 0,
            max_dim: gpu.device.limits().max_compute_workgroups_per_dimension,
            queue: gpu.queue.clone(),
        })
    }

    /// Sample the paths traced from now on with `techniques` ([`Techniques::bits`]).
    ///
    /// [`Techniques::bits`]: crate::render::Techniques::bits
    pub(crate) fn set_techniques(&mut self, techniques: u32) {
        for cam in &mut self.cameras {
            cam.params.techniques = techniques;
        }
    }

    /// Camera `k`'s pool.
    pub(crate) fn pool(&self, k: usize) -> &wgpu::Buffer {
        &self.cameras[k].pool
    }

    /// Record the trace pass of camera `k` (its image `grid` of tiles): this iteration's
    /// slots traced anew from `seed` and stored (every slot while the pool is empty), timed
    /// as a pass of `kind`. Returns the pool's parameters with the image's stride, for the
    /// pass that shades it.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn encode_trace(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        scene: &wgpu::BindGroup,
        (k, seed): (usize, u32),
        grid: (u32, u32),
        kind: PassKind,
        timer: &mut PassTimer,
    ) -> PrimalCachedParams {
        let cam = &mut self.cameras[k];
        cam.params.seed = seed;
        cam.params.refresh_first = self.next_slot;
        cam.params.refresh_count = if self.filled { self.refresh } else { self.spp };
        let tiles = grid.0 as u64 * grid.1 as u64 * WORKGROUP as u64;
        let invocations = tiles * cam.params.refresh_count as u64;
        let trace_grid = crate::gpu::grid_2d(
            invocations.min(u32::MAX as u64) as u32,
            WORKGROUP,
            self.max_dim,
        );
        cam.params.stride = trace_grid.0 * WORKGROUP;
        self.queue
            .write_buffer(&cam.uniform, 0, bytemuck::bytes_of(&cam.params));
        crate::gpu::encode_timed_pass(
            enc,
            "primal_cache_trace",
            &self.pipeline,
            &[scene, &cam.group],
            trace_grid,
            timer.next(kind),
        );
        PrimalCachedParams {
            stride: grid.0 * WORKGROUP,
            ..cam.params
        }
    }

    /// Called once an iteration's passes are submitted: the next refresh starts where this
    /// one ended.
    pub(crate) fn finish_iteration(&mut self) {
        if self.filled {
            self.next_slot = (self.next_slot + self.refresh) % self.spp;
        }
        self.filled = true;
    }

    /// The stored paths, once the pool is filled.
    pub(crate) fn snapshot(&self, gpu: &Gpu) -> Result<Option<PathCacheSnapshot>> {
        if !self.filled {
            return Ok(None);
        }
        let pools = (self.cameras.iter())
            .map(|c| gpu.read_pod::<u32>(&c.pool))
            .collect::<Result<Vec<_>>>()?;
        Ok(Some(PathCacheSnapshot {
            pools,
            next_slot: self.next_slot,
        }))
    }

    /// Continue from `s`; None empties the pool (the next trace fills every slot).
    pub(crate) fn restore(&mut self, gpu: &Gpu, s: Option<&PathCacheSnapshot>) -> Result<()> {
        let Some(s) = s else {
            self.filled = false;
            self.next_slot = 0;
            return Ok(());
        };
        if s.pools.len() != self.cameras.len()
            || s.next_slot >= self.spp
            || (s.pools.iter().zip(&self.cameras)).any(|(p, c)| p.len() as u64 * 4 != c.pool.size())
        {
            return Err(Error::Invalid(
                "the saved path cache does not match this optimizer's images and paths".into(),
            ));
        }
        for (p, c) in s.pools.iter().zip(&self.cameras) {
            gpu.queue.write_buffer(&c.pool, 0, bytemuck::cast_slice(p));
        }
        self.filled = true;
        self.next_slot = s.next_slot;
        Ok(())
    }
}
