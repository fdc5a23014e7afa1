//! The renderer (direct light, and path-traced indirect light to the scene's `max_depth`):
//! scene upload, the `render` pass and the `trace_rays` pass.

// Field-for-field mirrors of WGSL structs: each struct names its WGSL twin, whose comments
// document the fields.
mod gpu_lights;
pub(crate) mod gpu_scene;
#[allow(missing_docs)]
pub mod layout;
pub mod params;

pub use gpu_scene::{off_modules, wrap_trial, AccelerationStructure, GpuScene};

use crate::gpu::abi::{stat, technique};
use crate::gpu::{encode_pass, encode_timed_pass, grid_2d, Gpu};
use crate::image_io::Image;
use crate::scene::Scene;
use crate::{Error, Result};
use glam::Vec3;
use layout::*;
pub use layout::{camera_info, WORKGROUP};
pub use params::ParamBuffers;
use params::ParamSet;
use std::time::Instant;

/// The renderer's passes (a pass is named after its file, which lies beside this one).
pub(crate) const WGSL: &[(&str, &str)] = &[
    ("render", include_str!("render.wgsl")),
    ("trace_rays", include_str!("trace_rays.wgsl")),
    ("texture_wrap_test", include_str!("texture_wrap_test.wgsl")),
];

/// Group 1 of `render.wgsl` (the optimizer's primal render binds it too).
pub(crate) const RENDER_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "render",
    group: 1,
    names: &["rp", "accum", "stats", "accum_prev"],
};
/// Group 1 of `trace_rays.wgsl`.
pub(crate) const TRACE_RAYS_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "trace_rays",
    group: 1,
    names: &["tp", "rays", "hits"],
};

/// Which techniques light the scene (for area and environment lights; delta lights always use
/// next-event estimation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Techniques {
    /// Both, combined by multiple importance sampling (power heuristic).
    #[default]
    Mis,
    /// Light sampling only.
    NeeOnly,
    /// BSDF sampling only.
    BsdfOnly,
}

impl Techniques {
    /// The value of `techniques` in the shaders.
    pub fn bits(self) -> u32 {
        match self {
            Techniques::NeeOnly => technique::NEE,
            Techniques::BsdfOnly => technique::BSDF,
            Techniques::Mis => technique::MIS,
        }
    }
}

/// What to render.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Random seed.
    pub seed: u32,
    /// Index of the camera.
    pub camera: usize,
    /// Sampling techniques.
    pub techniques: Techniques,
}

/// A finished render and what it cost.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Mean radiance per pixel.
    pub image: Image,
    /// Camera rays traced.
    pub camera_rays: u64,
    /// Shadow rays traced.
    pub shadow_rays: u64,
    /// BSDF rays traced.
    pub bsdf_rays: u64,
    /// Samples dropped for being NaN or infinite.
    pub dropped: u64,
    /// Wall-clock seconds with the GPU work finished (shader compilation excluded).
    pub seconds: f64,
}

impl RenderOutput {
    /// All rays over the time.
    pub fn rays_per_second(&self) -> f64 {
        (self.camera_rays + self.shadow_rays + self.bsdf_rays) as f64 / self.seconds.max(1e-9)
    }
}

/// A ray for [`Renderer::trace_rays`].
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (need not be unit length; t is in its units).
    pub dir: Vec3,
    /// Largest t.
    pub tmax: f32,
}

/// The closest hit of a ray; `tri` is the input triangle index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Distance along the ray in units of its direction.
    pub t: f32,
    /// Input triangle index, or None on a miss.
    pub tri: Option<u32>,
    /// Barycentric coordinates of vertices 1 and 2.
    pub b: [f32; 2],
}

/// The renderer: a scene on the GPU and the compiled passes.
pub struct Renderer {
    gpu: Gpu,
    /// The uploaded scene.
    pub scene: GpuScene,
    render_pipeline: wgpu::ComputePipeline,
    render_layout: wgpu::BindGroupLayout,
    trace_pipeline: wgpu::ComputePipeline,
    trace_layout: wgpu::BindGroupLayout,
}

impl Renderer {
    /// Upload `scene` and compile the passes.
    pub fn new(gpu: &Gpu, scene: &Scene) -> Result<Renderer> {
        Self::with_params(gpu, scene, &ParamSet::default())
    }

    /// Upload `scene` with optimized textures (at their values in `param_set`) replacing
    /// material inputs.
    pub fn with_params(gpu: &Gpu, scene: &Scene, param_set: &ParamSet) -> Result<Renderer> {
        Self::with_param_buffers(gpu, scene, param_set, &ParamBuffers::new(gpu, param_set))
    }

    /// Upload `scene` with optimized textures laid out as `param_set` says, reading their
    /// values from `params`, which the caller owns and may change between passes (the
    /// optimizer's Adam step writes them).
    pub fn with_param_buffers(
        gpu: &Gpu,
        scene: &Scene,
        param_set: &ParamSet,
        params: &ParamBuffers,
    ) -> Result<Renderer> {
        let gscene = GpuScene::new(gpu, scene, param_set, params)?;
        let render_layout = gpu.pass_layout("render", 1)?;
        let render_pipeline = gscene.pipeline(gpu, "render", &[&gscene.layout, &render_layout])?;
        let trace_layout = gpu.pass_layout("trace_rays", 1)?;
        let trace_pipeline =
            gscene.pipeline(gpu, "trace_rays", &[&gscene.layout, &trace_layout])?;
        Ok(Renderer {
            gpu: gpu.clone(),
            scene: gscene,
            render_pipeline,
            render_layout,
            trace_pipeline,
            trace_layout,
        })
    }

    fn dispatch(
        &self,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        group1: &wgpu::BindGroup,
        grid: (u32, u32),
    ) {
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        encode_pass(
            &mut enc,
            label,
            pipeline,
            &[&self.scene.bind_group, group1],
            grid,
        );
        self.gpu.queue.submit([enc.finish()]);
    }

    /// Bind group 1 of the render pass (named as in render.wgsl: `rp`, `accum`, `stats`,
    /// `accum_prev`), for [`Renderer::encode_render`].
    pub fn bind_render_group(
        &self,
        label: &str,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        self.gpu
            .bind(&RENDER_GROUP, label, &self.render_layout, buffers)
    }

    /// Record one render pass of the image that `group` (from
    /// [`Renderer::bind_render_group`]) describes, over `grid` (see [`Renderer::tile_grid`]),
    /// with timestamps at query pair `timing.1` of `timing.0` when given.
    pub fn encode_render(
        &self,
        enc: &mut wgpu::CommandEncoder,
        label: &str,
        group: &wgpu::BindGroup,
        grid: (u32, u32),
        timing: Option<(&wgpu::QuerySet, u32)>,
    ) {
        let groups = [&self.scene.bind_group, group];
        encode_timed_pass(enc, label, &self.render_pipeline, &groups, grid, timing);
    }

    /// Workgroup grid for an image of `w` x `h` pixels in 8x8 tiles (see render.wgsl).
    pub fn tile_grid(&self, w: u32, h: u32) -> (u32, u32) {
        let max_dim = self
            .gpu
            .device
            .limits()
            .max_compute_workgroups_per_dimension;
        grid_2d(w.div_ceil(8) * h.div_ceil(8) * 64, WORKGROUP, max_dim)
    }

    /// Render an image; `progress` is called with the samples per pixel done so far.
    pub fn render(
        &self,
        settings: &RenderSettings,
        mut progress: impl FnMut(u32),
    ) -> Result<RenderOutput> {
        let (w, h) = (settings.width, settings.height);
        if w == 0 || h == 0 || w > 16384 || h > 16384 {
            return Err(Error::Invalid(format!(
                "image size {w}x{h} out of range (1..16384)"
            )));
        }
        let camera = self.scene.camera_info(settings.camera, w, h)?;
        let n_pixels = w * h;
        let grid = self.tile_grid(w, h);
        let mut params = GpuRenderParams {
            camera,
            seed: settings.seed,
            sample_offset: 0,
            spp: 0,
            techniques: settings.techniques.bits(),
            stride: grid.0 * WORKGROUP,
            two_states: 0,
            _pad: [0; 2],
        };
        let uniform = self
            .gpu
            .uniform("render params", bytemuck::bytes_of(&params));
        let accum = self
            .gpu
            .storage_zeroed("render accum", n_pixels as u64 * 16);
        let stats = self.gpu.storage_zeroed("render stats", 16);
        // No second state: a placeholder for the previous-textures accumulator.
        let unused = self.gpu.storage_zeroed("render accum_prev (unused)", 16);
        let group = self.gpu.bind(
            &RENDER_GROUP,
            "render",
            &self.render_layout,
            &[
                ("rp", &uniform),
                ("accum", &accum),
                ("stats", &stats),
                ("accum_prev", &unused),
            ],
        );
        // Compile the pass (lavapipe compiles at first dispatch) before the clock starts.
        self.dispatch("render warm-up", &self.render_pipeline, &group, (1, 1));
        self.gpu.wait("render warm-up")?;

        // Dispatches of about 2^20 samples each keep every submission short.
        let chunk = ((1u32 << 20) / n_pixels).clamp(1, 64);
        let start = Instant::now();
        let mut done = 0;
        while done < settings.spp {
            params.sample_offset = done;
            params.spp = chunk.min(settings.spp - done);
            self.gpu
                .queue
                .write_buffer(&uniform, 0, bytemuck::bytes_of(&params));
            self.dispatch("render", &self.render_pipeline, &group, grid);
            self.gpu.wait("render")?;
            done += params.spp;
            progress(done);
        }
        let seconds = start.elapsed().as_secs_f64();
        let sums: Vec<[f32; 4]> = self.gpu.read_pod(&accum)?;
        let counts: Vec<u32> = self.gpu.read_pod(&stats)?;
        let image = accum_image(w, h, &sums);
        Ok(RenderOutput {
            image,
            camera_rays: counts[stat::RENDER_CAMERA_RAYS as usize] as u64,
            shadow_rays: counts[stat::RENDER_SHADOW_RAYS as usize] as u64,
            bsdf_rays: counts[stat::RENDER_BSDF_RAYS as usize] as u64,
            dropped: counts[stat::RENDER_DROPPED as usize] as u64,
            seconds,
        })
    }

    /// Trace rays through the BVH, or against every triangle when `brute_force` (the
    /// reference the tests compare the BVH with).
    pub fn trace_rays(&self, rays: &[Ray], brute_force: bool) -> Result<Vec<RayHit>> {
        let n = rays.len() as u32;
        let max_dim = self
            .gpu
            .device
            .limits()
            .max_compute_workgroups_per_dimension;
        let grid = grid_2d(n, WORKGROUP, max_dim);
        let params = GpuTraceParams {
            n_rays: n,
            brute_force: brute_force as u32,
            stride: grid.0 * WORKGROUP,
            _pad: 0,
        };
        let data: Vec<[f32; 4]> = rays
            .iter()
            .flat_map(|r| {
                [
                    r.origin.extend(r.tmax).to_array(),
                    r.dir.extend(0.0).to_array(),
                ]
            })
            .collect();
        let uniform = self
            .gpu
            .uniform("trace_rays params", bytemuck::bytes_of(&params));
        let ray_buf = self.gpu.storage(
            "trace_rays rays",
            bytemuck::cast_slice(&data),
            wgpu::BufferUsages::empty(),
        );
        let hit_buf = self.gpu.storage_zeroed("trace_rays hits", n as u64 * 16);
        let group = self.gpu.bind(
            &TRACE_RAYS_GROUP,
            "trace_rays",
            &self.trace_layout,
            &[("tp", &uniform), ("rays", &ray_buf), ("hits", &hit_buf)],
        );
        self.dispatch("trace_rays", &self.trace_pipeline, &group, grid);
        self.gpu.wait("trace_rays")?;
        let hits: Vec<[f32; 4]> = self.gpu.read_pod(&hit_buf)?;
        let mut input_of = vec![0u32; self.scene.gpu_index.len()];
        for (i, &k) in self.scene.gpu_index.iter().enumerate() {
            input_of[k as usize] = i as u32;
        }
        Ok(hits[..n as usize]
            .iter()
            .map(|h| {
                let tri = h[1].to_bits();
                RayHit {
                    t: h[0],
                    tri: (tri != u32::MAX).then(|| input_of[tri as usize]),
                    b: [h[2], h[3]],
                }
            })
            .collect())
    }
}

/// The image of a `w` x `h` render's accumulator (per pixel: the sum of its samples' RGB, and
/// their count in the fourth value).
pub fn accum_image(w: u32, h: u32, sums: &[[f32; 4]]) -> Image {
    Image {
        width: w,
        height: h,
        rgb: sums
            .iter()
            .map(|s| {
                let n = s[3].max(1.0);
                [s[0] / n, s[1] / n, s[2] / n]
            })
            .collect(),
    }
}
