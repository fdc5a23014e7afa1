//! The path cache (primal_cache_trace.wgsl stores paths, primal_cached.wgsl shades them, in
//! the layout of path_cache.wgsl): each camera's primal image shaded from a pool of
//! stored camera paths, `primal_spp` per pixel, of which `refresh` are traced anew every
//! iteration in rotation, so that every path is replaced within `primal_spp / refresh`
//! iterations. Geometry, cameras and lights never change in a texture optimization, so a
//! stored path is a sample of the same path space under any textures; shading it under the
//! current ones, with the densities and MIS weights of the iteration that drew it, stays an
//! unbiased estimate of the current render. The image of one iteration is not independent
//! of the last ones (they share paths), which is what the refresh bounds.
use crate::gpu::Gpu;
use crate::optim::parts::IterationBuffers;
use crate::optim::{PassKind, PassTimer, Settings};
use crate::render::layout::GpuCameraInfo;
use crate::render::{Renderer, WORKGROUP};
use crate::{Error, Result};
use bytemuck::{Pod, Zeroable};

/// Group 1 of `primal_cached.wgsl`.
pub(crate) const PRIMAL_CACHED_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "primal_cached",
    group: 1,
    names: &["cp", "accum", "stats", "accum_prev", "path_cache"],
};
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

/// `settings` without the path cache where the images cannot use one (the log says why; the
/// primal then traces every sample, as without it), so that the memory plan counts it only
/// where it is made.
pub(crate) fn usable(gpu: &Gpu, mut settings: Settings, max_depth: u32) -> Settings {
    if settings.path_cache.is_some() {
        let pixels = settings.width as u64 * settings.height as u64;
        if let Some(why) = unusable(gpu, pixels, settings.primal_spp, max_depth) {
            log::warn!("path cache off, the primal traces every sample: {why}");
            settings.path_cache = None;
        }
    }
    settings
}

/// What a checkpoint keeps of the path cache: every camera's stored paths and where the next
/// refresh starts. Paths are samples of the same path space under any textures, so a resumed
/// run shades them as the uninterrupted run does.
#[derive(Clone, Debug, PartialEq)]
pub struct PathCacheSnapshot {
    /// Per camera, the pool's words (path_cache.wgsl's layout).
    pub pools: Vec<Vec<u32>>,
    /// The slot the next refresh starts at.
    pub next_slot: u32,
}

struct Camera {
    pool: wgpu::Buffer,
    /// The trace pass's uniform and the shading pass's (their strides differ).
    uniform: wgpu::Buffer,
    shade_uniform: wgpu::Buffer,
    params: PrimalCachedParams,
    /// The trace pass's group and the shading pass's.
    trace_group: wgpu::BindGroup,
    group: wgpu::BindGroup,
}

/// The cached primal passes of every camera and their pools.
pub(crate) struct PathCache {
    trace_pipeline: wgpu::ComputePipeline,
    pipeline: wgpu::ComputePipeline,
    cameras: Vec<Camera>,
    /// Paths kept per pixel, and traced anew per pixel and iteration.
    spp: u32,
    refresh: u32,
    /// Whether the pools hold paths (false until the first render, and after a restore).
    filled: bool,
    /// Where the next refresh starts.
    next_slot: u32,
    max_dim: u32,
    queue: wgpu::Queue,
}

/// The cache `settings` asks for (after [`usable`]) for the cameras `camera_infos` of
/// `renderer`'s scene (paths of `max_depth` vertices), rendered over `grid` into the
/// iteration's accumulators; None without.
pub(in crate::optim) fn build(
    gpu: &Gpu,
    (renderer, camera_infos, grid): (&Renderer, &[GpuCameraInfo], (u32, u32)),
    (settings, max_depth): (&Settings, u32),
    bufs: &IterationBuffers,
) -> Result<Option<PathCache>> {
    let Some(refresh) = settings.path_cache else {
        return Ok(None);
    };
    log::info!(
        "path cache: {} paths per pixel, {refresh} traced anew each iteration",
        settings.primal_spp
    );
    PathCache::new(
        gpu,
        (renderer, camera_infos, grid),
        settings,
        bufs,
        (refresh, max_depth),
    )
    .map(Some)
}

impl PathCache {
    fn new(
        gpu: &Gpu,
        (renderer, camera_infos, grid): (&Renderer, &[GpuCameraInfo], (u32, u32)),
        settings: &Settings,
        bufs: &IterationBuffers,
        (refresh, max_depth): (u32, u32),
    ) -> Result<PathCache> {
        let spp = settings.primal_spp;
        let layout = gpu.pass_layout("primal_cached", 1)?;
        let trace_layout = gpu.pass_layout("primal_cache_trace", 1)?;
        let scene = &renderer.scene;
        let pipeline = scene.pipeline(gpu, "primal_cached", &[&scene.layout, &layout])?;
        let trace_pipeline =
            scene.pipeline(gpu, "primal_cache_trace", &[&scene.layout, &trace_layout])?;
        let vertices = max_depth.clamp(1, MAX_VERTICES);
        let cameras = camera_infos
            .iter()
            .enumerate()
            .map(|(k, camera)| {
                let pixels = camera.width as u64 * camera.height as u64;
                let pool = gpu.storage_zeroed(
                    &format!("path cache {k}"),
                    camera_bytes(pixels, spp, max_depth),
                );
                let params = PrimalCachedParams {
                    camera: *camera,
                    spp,
                    techniques: crate::render::Techniques::Mis.bits(),
                    stride: grid.0 * WORKGROUP,
                    vertices,
                    ..Default::default()
                };
                let uniform = gpu.uniform(
                    &format!("primal_cache_trace params {k}"),
                    bytemuck::bytes_of(&params),
                );
                let shade_uniform = gpu.uniform(
                    &format!("primal_cached params {k}"),
                    bytemuck::bytes_of(&params),
                );
                let group = gpu.bind(
                    &PRIMAL_CACHED_GROUP,
                    "primal_cached",
                    &layout,
                    &[
                        ("cp", &shade_uniform),
                        ("accum", &bufs.accum),
                        ("stats", &bufs.stats.primal),
                        ("accum_prev", &bufs.accum_prev),
                        ("path_cache", &pool),
                    ],
                );
                let trace_group = gpu.bind(
                    &PRIMAL_CACHE_TRACE_GROUP,
                    "primal_cache_trace",
                    &trace_layout,
                    &[
                        ("cp", &uniform),
                        ("stats", &bufs.stats.primal),
                        ("path_cache", &pool),
                    ],
                );
                Camera {
                    pool,
                    uniform,
                    shade_uniform,
                    params,
                    trace_group,
                    group,
                }
            })
            .collect();
        if refresh == 0 || refresh > spp {
            return Err(Error::Invalid(format!(
                "path cache: {refresh} paths refreshed per iteration of {spp} kept"
            )));
        }
        Ok(PathCache {
            trace_pipeline,
            pipeline,
            cameras,
            spp,
            refresh,
            filled: false,
            next_slot: 0,
            max_dim: gpu.device.limits().max_compute_workgroups_per_dimension,
            queue: gpu.queue.clone(),
        })
    }

    /// Record camera `k`'s primal render into the accumulators (cleared by the caller): the
    /// paths traced this iteration, drawn from `seed`, stored, then the pool shaded, with
    /// `two_states` under the previous textures too (`scene`: the scene's bind group; `grid`
    /// the image's tiles, [`Renderer::tile_grid`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn encode(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        scene: &wgpu::BindGroup,
        k: usize,
        seed: u32,
        two_states: bool,
        grid: (u32, u32),
        timer: &mut PassTimer,
    ) {
        let cam = &mut self.cameras[k];
        cam.params.seed = seed;
        cam.params.two_states = two_states as u32;
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
            &self.trace_pipeline,
            &[scene, &cam.trace_group],
            trace_grid,
            timer.next(PassKind::Primal),
        );
        // (The shading pass reads the same uniform, its stride the image's: a second copy.)
        let mut shade = cam.params;
        shade.stride = grid.0 * WORKGROUP;
        self.queue
            .write_buffer(&cam.shade_uniform, 0, bytemuck::bytes_of(&shade));
        crate::gpu::encode_timed_pass(
            enc,
            "primal_cached",
            &self.pipeline,
            &[scene, &cam.group],
            grid,
            timer.next(PassKind::Primal),
        );
    }

    /// Called once an iteration's renders are submitted: the next refresh starts where this
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

    /// Continue from `s`; None empties the pool (the next render traces every slot).
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
