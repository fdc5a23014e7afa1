//! The path cache (primal_cache_trace.wgsl stores paths, primal_cached.wgsl shades them, in
//! the layout of path_cache.wgsl): each camera's primal image shaded from a pool of
//! stored camera paths, `primal_spp` per pixel, of which `refresh` are traced anew every
//! iteration in rotation, so that every path is replaced within `primal_spp / refresh`
//! iterations. Geometry, cameras and lights never change in a texture optimization, so a
//! stored path is a sample of the same path space under any textures; shading it under the
//! current ones, with the densities and MIS weights of the iteration that drew it, stays an
//! unbiased estimate of the current render. The image of one iteration is not independent
//! of the last ones (they share paths), which is what the refresh bounds.
pub use super::path_pool::{
    camera_bytes, path_words, unusable, PathCacheSnapshot, PrimalCachedParams, MAX_VERTICES,
};
use super::path_pool::{PathPool, PoolSetup};
use crate::gpu::Gpu;
use crate::optim::parts::IterationBuffers;
use crate::optim::{PassKind, PassTimer, Settings};
use crate::render::layout::GpuCameraInfo;
use crate::render::Renderer;
use crate::Result;

/// Group 1 of `primal_cached.wgsl`.
pub(crate) const PRIMAL_CACHED_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "primal_cached",
    group: 1,
    names: &["cp", "accum", "stats", "accum_prev", "path_cache"],
};
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

struct Camera {
    /// The shading pass's uniform and group.
    uniform: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// The cached primal passes of every camera and their pools.
pub(crate) struct PathCache {
    pool: PathPool,
    pipeline: wgpu::ComputePipeline,
    cameras: Vec<Camera>,
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
    let scene = &renderer.scene;
    let pool = PathPool::new(
        gpu,
        &PoolSetup {
            scene,
            cameras: camera_infos,
            grid,
            spp: settings.primal_spp,
            refresh,
            max_depth,
            techniques: crate::render::Techniques::Mis.bits(),
            optimized_only: false,
            stats: &bufs.stats.primal,
            label: "path cache",
        },
    )?;
    let layout = gpu.pass_layout("primal_cached", 1)?;
    let pipeline = scene.pipeline(gpu, "primal_cached", &[&scene.layout, &layout])?;
    let cameras = (0..camera_infos.len())
        .map(|k| {
            let uniform = gpu.uniform(
                &format!("primal_cached params {k}"),
                bytemuck::bytes_of(&PrimalCachedParams::default()),
            );
            let group = gpu.bind(
                &PRIMAL_CACHED_GROUP,
                "primal_cached",
                &layout,
                &[
                    ("cp", &uniform),
                    ("accum", &bufs.accum),
                    ("stats", &bufs.stats.primal),
                    ("accum_prev", &bufs.accum_prev),
                    ("path_cache", pool.pool(k)),
                ],
            );
            Camera { uniform, group }
        })
        .collect();
    Ok(Some(PathCache {
        pool,
        pipeline,
        cameras,
        queue: gpu.queue.clone(),
    }))
}

impl PathCache {
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
        let mut shade =
            self.pool
                .encode_trace(enc, scene, (k, seed), grid, PassKind::Primal, timer);
        shade.two_states = two_states as u32;
        let cam = &self.cameras[k];
        self.queue
            .write_buffer(&cam.uniform, 0, bytemuck::bytes_of(&shade));
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
        self.pool.finish_iteration();
    }

    /// The stored paths, once the pool is filled.
    pub(crate) fn snapshot(&self, gpu: &Gpu) -> Result<Option<PathCacheSnapshot>> {
        self.pool.snapshot(gpu)
    }

    /// Continue from `s`; None empties the pool (the next render traces every slot).
    pub(crate) fn restore(&mut self, gpu: &Gpu, s: Option<&PathCacheSnapshot>) -> Result<()> {
        self.pool.restore(gpu, s)
    }
}
