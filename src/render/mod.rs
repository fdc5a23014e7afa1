//! The direct-lighting renderer: scene upload, the `render` pass and the `trace_rays` pass.

// Field-for-field mirrors of WGSL structs: each struct names its WGSL twin, whose comments
// document the fields.
#[allow(missing_docs)]
pub mod layout;
pub mod params;

use crate::gpu::Tracer;
use crate::gpu::{grid_2d, Gpu};
use crate::image_io::Image;
use crate::scene::{bvh, PunctualKind, Scene, TextureSlot, Wrap};
use crate::{Error, Result};
use glam::Vec3;
use layout::*;
use params::ParamSet;
use std::time::Instant;

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

/// Invocations per workgroup of every pass.
pub const WORKGROUP: u32 = 64;

/// Scene data on the GPU: bind group 0 of every pass that traces rays.
pub struct GpuScene {
    /// Layout of group 0 (see shaders/shared/scene.wgsl).
    pub layout: wgpu::BindGroupLayout,
    /// The bound buffers (and, with ray queries, the acceleration structure).
    pub bind_group: wgpu::BindGroup,
    /// The acceleration structure when the device traces with ray queries.
    pub accel: Option<AccelerationStructure>,
    /// Scene constants as uploaded.
    pub info: GpuSceneInfo,
    /// Cameras of the scene.
    pub cameras: Vec<crate::scene::Camera>,
    /// Position of each input triangle in GPU (BVH) order: `gpu_index[input] = k`.
    pub gpu_index: Vec<u32>,
    /// Bytes uploaded, for reports.
    pub bytes: u64,
    /// Values of the optimized textures (binding 9; Adam writes it).
    pub params: wgpu::Buffer,
    /// The optimized textures of the previous iteration (binding 10; ReSTIR's merge reads it).
    pub params_prev: wgpu::Buffer,
    /// Number of floats in `params`.
    pub param_count: u32,
    /// Number of texels of all optimized textures.
    pub n_texels: u32,
}

fn wrap_bits(w: Wrap) -> u32 {
    match w {
        Wrap::Repeat => 0,
        Wrap::Clamp => 1,
        Wrap::Mirror => 2,
    }
}

/// Luminance in f64, so that the power of a light with an intensity near f32::MAX stays
/// finite.
fn luminance(c: Vec3) -> f64 {
    0.2126 * c.x as f64 + 0.7152 * c.y as f64 + 0.0722 * c.z as f64
}

/// The scene's ray-query acceleration structure: one BLAS over the triangles in GPU order
/// (so a hit's primitive index is the triangle index of the other scene buffers) and one TLAS
/// instance of it with the identity transform. Built once; geometry never changes.
pub struct AccelerationStructure {
    /// The triangles.
    pub blas: wgpu::Blas,
    /// Its one instance, bound at group 0, binding 11 (shaders/shared/bvh_ray_query.wgsl).
    pub tlas: wgpu::Tlas,
}

/// Build the acceleration structure over `n_tris` triangles whose vertices are the vec4
/// entries of `positions` (three per triangle; w ignored).
fn build_acceleration_structure(
    gpu: &Gpu,
    positions: &wgpu::Buffer,
    n_tris: u32,
) -> AccelerationStructure {
    let size = wgpu::BlasTriangleGeometrySizeDescriptor {
        vertex_format: wgpu::VertexFormat::Float32x3,
        vertex_count: 3 * n_tris,
        index_format: None,
        index_count: None,
        flags: wgpu::AccelerationStructureGeometryFlags::OPAQUE,
    };
    let blas = gpu.device.create_blas(
        &wgpu::CreateBlasDescriptor {
            label: Some("scene blas"),
            flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
            update_mode: wgpu::AccelerationStructureUpdateMode::Build,
        },
        wgpu::BlasGeometrySizeDescriptors::Triangles {
            descriptors: vec![size.clone()],
        },
    );
    let mut tlas = gpu.device.create_tlas(&wgpu::CreateTlasDescriptor {
        label: Some("scene tlas"),
        max_instances: 1,
        flags: wgpu::AccelerationStructureFlags::PREFER_FAST_TRACE,
        update_mode: wgpu::AccelerationStructureUpdateMode::Build,
    });
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("scene acceleration structure"),
        });
    if n_tris > 0 {
        const IDENTITY: [f32; 12] = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.];
        tlas[0] = Some(wgpu::TlasInstance::new(&blas, IDENTITY, 0, 0xff));
        let entry = wgpu::BlasBuildEntry {
            blas: &blas,
            geometry: wgpu::BlasGeometries::TriangleGeometries(vec![wgpu::BlasTriangleGeometry {
                size: &size,
                vertex_buffer: positions,
                first_vertex: 0,
                vertex_stride: 16,
                index_buffer: None,
                first_index: None,
                transform_buffer: None,
                transform_buffer_offset: None,
            }]),
        };
        enc.build_acceleration_structures(std::iter::once(&entry), std::iter::once(&tlas));
    } else {
        enc.build_acceleration_structures(std::iter::empty(), std::iter::once(&tlas));
    }
    gpu.queue.submit([enc.finish()]);
    AccelerationStructure { blas, tlas }
}

impl GpuScene {
    /// Upload a scene: BVH, triangles, materials, textures, lights, environment, and the
    /// optimized textures that replace material inputs.
    pub fn new(gpu: &Gpu, scene: &Scene, param_set: &ParamSet) -> Result<GpuScene> {
        scene.validate()?;
        let limits = gpu.device.limits();
        let max_binding = limits.max_storage_buffer_binding_size;
        let check = |label: &str, bytes: usize| -> Result<()> {
            if bytes as u64 > max_binding {
                return Err(Error::Unsuitable(format!(
                    "{}: {label} needs {bytes} bytes, the device binds at most {max_binding} \
                     bytes per buffer (all images share one buffer: use smaller textures, or a \
                     GPU with larger limits)",
                    scene.source.display(),
                )));
            }
            Ok(())
        };
        let tris: Vec<[Vec3; 3]> = scene.triangles.iter().map(|t| t.p).collect();
        let bvh = bvh::build(&tris);
        let mut gpu_index = vec![0u32; tris.len()];
        for (k, &i) in bvh.order.iter().enumerate() {
            gpu_index[i as usize] = k as u32;
        }

        // Textures: one packed RGBA8 buffer.
        let mut image_offsets = Vec::new();
        let mut texels: Vec<u32> = Vec::new();
        for img in &scene.images {
            image_offsets.push(texels.len() as u32);
            texels.extend(img.rgba.iter().map(|p| u32::from_le_bytes(*p)));
        }
        check("the texture buffer", texels.len() * 4)?;
        let tex_ref = |slot: &Option<TextureSlot>, srgb: bool| -> GpuTexRef {
            match slot {
                None => GpuTexRef::NONE,
                Some(s) => {
                    let img = &scene.images[s.image];
                    GpuTexRef {
                        offset: image_offsets[s.image],
                        width: img.width,
                        height: img.height,
                        flags: wrap_bits(s.wrap_s)
                            | (wrap_bits(s.wrap_t) << 2)
                            | if srgb { 16 } else { 0 }
                            | if s.nearest { 32 } else { 0 },
                    }
                }
            }
        };
        let xf = |slot: &Option<TextureSlot>| -> [[f32; 4]; 2] {
            let t = slot
                .as_ref()
                .map(|s| s.transform)
                .unwrap_or([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
            [
                [t[0][0], t[0][1], t[0][2], 0.0],
                [t[1][0], t[1][1], t[1][2], 0.0],
            ]
        };
        let materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| {
                let [a, b] = xf(&m.base_color_texture);
                let [c, d] = xf(&m.metallic_roughness_texture);
                let [e, f] = xf(&m.emissive_texture);
                GpuMaterial {
                    base_color: m.base_color.to_array(),
                    emissive: m.emissive.to_array(),
                    metallic: m.metallic,
                    roughness: m.roughness,
                    double_sided: m.double_sided as u32,
                    param_base_color: u32::MAX,
                    param_metallic: u32::MAX,
                    param_roughness: u32::MAX,
                    _pad: [0; 3],
                    base_color_tex: tex_ref(&m.base_color_texture, true),
                    mr_tex: tex_ref(&m.metallic_roughness_texture, false),
                    emissive_tex: tex_ref(&m.emissive_texture, true),
                    uv_xf: [a, b, c, d, e, f],
                }
            })
            .collect();

        let mut materials = materials;
        let mut param_textures = Vec::new();
        let mut texel_offset = 0u32;
        for (i, t) in param_set.textures.iter().enumerate() {
            let m = materials.get_mut(t.material as usize).ok_or_else(|| {
                Error::Invalid(format!(
                    "optimized texture {i} refers to material {} of {}",
                    t.material,
                    scene.materials.len()
                ))
            })?;
            let slot = match t.slot {
                crate::vocab::Slot::BaseColor => &mut m.param_base_color,
                crate::vocab::Slot::Metallic => &mut m.param_metallic,
                crate::vocab::Slot::Roughness => &mut m.param_roughness,
            };
            *slot = i as u32;
            param_textures.push(GpuParamTex {
                offset: t.offset,
                width: t.width,
                height: t.height,
                channels: t.channels(),
                filtering: match t.filter {
                    crate::vocab::Filter::Nearest => 0,
                    crate::vocab::Filter::Bilinear => 1,
                },
                texel_offset,
                _pad: [0; 2],
            });
            texel_offset += t.width * t.height;
        }
        check("the optimized textures", param_set.values.len() * 4)?;

        // Lights, with selection probability proportional to a power estimate.
        let (_, radius) = scene.bounding_sphere();
        use std::f64::consts::PI;
        let mut lights: Vec<GpuLight> = Vec::new();
        let mut power: Vec<f64> = Vec::new();
        for l in &scene.lights {
            let mut g = GpuLight {
                position: l.position.to_array(),
                direction: l.direction.to_array(),
                intensity: l.intensity.to_array(),
                range: l.range,
                ..Default::default()
            };
            let lum = luminance(l.intensity);
            match l.kind {
                PunctualKind::Point => {
                    g.kind = LIGHT_POINT;
                    power.push(4.0 * PI * lum);
                }
                PunctualKind::Spot {
                    inner_cone,
                    outer_cone,
                } => {
                    g.kind = LIGHT_SPOT;
                    let scale = 1.0 / (inner_cone.cos() - outer_cone.cos()).max(1e-3);
                    g.spot_scale = scale;
                    g.spot_offset = -outer_cone.cos() * scale;
                    power.push(2.0 * PI * (1.0 - outer_cone.cos() as f64).max(1e-3) * lum);
                }
                PunctualKind::Directional => {
                    g.kind = LIGHT_DIRECTIONAL;
                    power.push(PI * (radius as f64).powi(2) * lum);
                }
            }
            lights.push(g);
        }
        let mut tri_light = vec![u32::MAX; tris.len()];
        for (i, t) in scene.triangles.iter().enumerate() {
            let m = &scene.materials[t.material as usize];
            let lum = luminance(m.emissive);
            let area = t.area();
            if lum > 0.0 && area > 0.0 {
                tri_light[i] = lights.len() as u32;
                lights.push(GpuLight {
                    kind: LIGHT_AREA,
                    tri: gpu_index[i],
                    ..Default::default()
                });
                let sides = if m.double_sided { 2.0 } else { 1.0 };
                power.push(PI * lum * area as f64 * sides);
            }
        }
        let mut env_table = vec![0f32; 4];
        let mut info = GpuSceneInfo {
            n_nodes: bvh.nodes.len() as u32,
            n_tris: tris.len() as u32,
            env_light: u32::MAX,
            scene_radius: radius,
            ..Default::default()
        };
        if let Some(env) = &scene.env {
            let (table, marginal, conditional) = env.gpu_table();
            env_table = table;
            info.env_width = env.width;
            info.env_height = env.height;
            info.env_marginal = marginal;
            info.env_conditional = conditional;
            info.env_scale = env.scale;
            let p = env.power(radius);
            if p > 0.0 {
                info.env_light = lights.len() as u32;
                lights.push(GpuLight {
                    kind: LIGHT_ENV,
                    ..Default::default()
                });
                power.push(p);
            }
        }
        let total: f64 = power.iter().map(|&p| p.max(0.0)).sum();
        if total <= 0.0 {
            log::warn!(
                "{}: the scene has no light with positive power (no punctual light, emissive \
                 triangle of non-zero area or environment): every render is black",
                scene.source.display()
            );
        }
        let mut acc = 0f64;
        for (l, p) in lights.iter_mut().zip(&power) {
            let pmf = if total > 0.0 { p.max(0.0) / total } else { 0.0 };
            acc += pmf;
            l.pmf = pmf as f32;
            l.cdf = acc as f32;
        }
        if let Some(last) = lights.last_mut() {
            last.cdf = 1.0;
        }
        info.n_lights = lights.len() as u32;
        check("the environment map", env_table.len() * 4)?;

        // Triangles in BVH order.
        let mut positions: Vec<[f32; 4]> = Vec::with_capacity(tris.len() * 3);
        let mut shading: Vec<GpuTriShading> = Vec::with_capacity(tris.len());
        for &i in &bvh.order {
            let t = &scene.triangles[i as usize];
            for p in t.p {
                positions.push([p.x, p.y, p.z, 0.0]);
            }
            shading.push(GpuTriShading {
                n0: t.n[0].extend(0.0).to_array(),
                n1: t.n[1].extend(0.0).to_array(),
                n2: t.n[2].extend(0.0).to_array(),
                uv01: [t.uv[0].x, t.uv[0].y, t.uv[1].x, t.uv[1].y],
                uv2: t.uv[2].to_array(),
                material: t.material,
                light: tri_light[i as usize],
            });
        }
        check("the triangle positions", positions.len() * 16)?;
        check("the triangle attributes", shading.len() * 80)?;
        check("the BVH", bvh.nodes.len() * 32)?;

        let none = wgpu::BufferUsages::empty();
        let buffers = [
            gpu.storage("scene nodes", bytemuck::cast_slice(&bvh.nodes), none),
            gpu.storage(
                "scene tri_positions",
                bytemuck::cast_slice(&positions),
                if gpu.tracer == Tracer::RayQuery {
                    wgpu::BufferUsages::BLAS_INPUT
                } else {
                    none
                },
            ),
            gpu.storage("scene tri_shading", bytemuck::cast_slice(&shading), none),
            gpu.storage("scene materials", bytemuck::cast_slice(&materials), none),
            gpu.storage("scene texels", bytemuck::cast_slice(&texels), none),
            gpu.storage("scene lights", bytemuck::cast_slice(&lights), none),
            gpu.storage("scene env", bytemuck::cast_slice(&env_table), none),
            gpu.uniform("scene info", bytemuck::bytes_of(&info)),
            gpu.storage(
                "scene param_textures",
                bytemuck::cast_slice(&param_textures),
                none,
            ),
            gpu.storage(
                "scene params",
                bytemuck::cast_slice(&param_set.values),
                wgpu::BufferUsages::COPY_SRC,
            ),
            gpu.storage(
                "scene params_prev",
                bytemuck::cast_slice(&param_set.values),
                wgpu::BufferUsages::COPY_SRC,
            ),
        ];
        let bytes = buffers.iter().map(|b| b.size()).sum();
        // Group 0 of every tracing pass (shaders/shared/scene.wgsl).
        let layout = gpu.pass_layout("render", 0)?;
        let refs: Vec<&wgpu::Buffer> = buffers.iter().collect();
        if gpu.tracer == Tracer::RayQuery
            && tris.len() as u64 > limits.max_blas_primitive_count as u64
        {
            return Err(Error::Unsuitable(format!(
                "{}: {} triangles, the device's ray-query acceleration structures hold at most \
                 {} (set PSRESTIR_TRACER=software to trace with the software BVH)",
                scene.source.display(),
                tris.len(),
                limits.max_blas_primitive_count
            )));
        }
        let accel = match gpu.tracer {
            Tracer::RayQuery => Some(build_acceleration_structure(
                gpu,
                &buffers[1],
                tris.len() as u32,
            )),
            Tracer::Software => None,
        };
        let bind_group =
            gpu.bind_group_with_tlas("scene", &layout, &refs, accel.as_ref().map(|a| &a.tlas));
        gpu.check("scene upload")?;
        let [_, _, _, _, _, _, _, _, _, params, params_prev] = buffers;
        Ok(GpuScene {
            layout,
            bind_group,
            accel,
            info,
            cameras: scene.cameras.clone(),
            gpu_index,
            bytes,
            params,
            params_prev,
            param_count: param_set.values.len() as u32,
            n_texels: texel_offset,
        })
    }
}

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
            Techniques::NeeOnly => 1,
            Techniques::BsdfOnly => 2,
            Techniques::Mis => 3,
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

/// Record one compute pass: `groups[k]` is bound at group k.
pub(crate) fn encode_pass(
    enc: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups: &[&wgpu::BindGroup],
    grid: (u32, u32),
) {
    encode_timed_pass(enc, label, pipeline, groups, grid, None)
}

/// [`encode_pass`], writing timestamps `2k` and `2k + 1` of the query set at the pass's start
/// and end when given `(query set, k)`.
pub(crate) fn encode_timed_pass(
    enc: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups: &[&wgpu::BindGroup],
    grid: (u32, u32),
    timing: Option<(&wgpu::QuerySet, u32)>,
) {
    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: timing.map(|(q, k)| wgpu::ComputePassTimestampWrites {
            query_set: q,
            beginning_of_pass_write_index: Some(2 * k),
            end_of_pass_write_index: Some(2 * k + 1),
        }),
    });
    pass.set_pipeline(pipeline);
    for (k, g) in groups.iter().enumerate() {
        pass.set_bind_group(k as u32, *g, &[]);
    }
    pass.dispatch_workgroups(grid.0, grid.1, 1);
}

/// Camera constants for a pinhole camera at the given image size: the camera's intrinsics
/// scaled to it, or, without intrinsics, square pixels with the vertical field of view and
/// the principal point at the center.
pub fn camera_info(cam: &crate::scene::Camera, width: u32, height: u32) -> GpuCameraInfo {
    let m = cam.world;
    let right = m.transform_vector3(Vec3::X).normalize_or(Vec3::X);
    let up = m.transform_vector3(Vec3::Y).normalize_or(Vec3::Y);
    let forward = m.transform_vector3(Vec3::NEG_Z).normalize_or(Vec3::NEG_Z);
    let [fx, fy, cx, cy] = cam.pixel_intrinsics(width, height);
    GpuCameraInfo {
        origin: m.transform_point3(Vec3::ZERO).to_array(),
        fx,
        right: right.to_array(),
        fy,
        up: up.to_array(),
        width,
        forward: forward.to_array(),
        height,
        cx,
        cy,
        _pad: [0; 2],
    }
}

/// The renderer: a scene on the GPU and the compiled passes.
pub struct Renderer {
    gpu: Gpu,
    /// The uploaded scene.
    pub scene: GpuScene,
    pub(crate) render_pipeline: wgpu::ComputePipeline,
    pub(crate) render_layout: wgpu::BindGroupLayout,
    trace_pipeline: wgpu::ComputePipeline,
    trace_layout: wgpu::BindGroupLayout,
}

impl Renderer {
    /// Upload `scene` and compile the passes.
    pub fn new(gpu: &Gpu, scene: &Scene) -> Result<Renderer> {
        Self::with_params(gpu, scene, &ParamSet::default())
    }

    /// Upload `scene` with optimized textures replacing material inputs.
    pub fn with_params(gpu: &Gpu, scene: &Scene, param_set: &ParamSet) -> Result<Renderer> {
        let gscene = GpuScene::new(gpu, scene, param_set)?;
        let render_layout = gpu.pass_layout("render", 1)?;
        let render_pipeline = gpu.compute_pipeline("render", &[&gscene.layout, &render_layout])?;
        let trace_layout = gpu.pass_layout("trace_rays", 1)?;
        let trace_pipeline =
            gpu.compute_pipeline("trace_rays", &[&gscene.layout, &trace_layout])?;
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

    /// Workgroup grid for an image of `w` x `h` pixels in 8x8 tiles (see render.wgsl).
    pub(crate) fn tile_grid(&self, w: u32, h: u32) -> (u32, u32) {
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
        let cam = self.scene.cameras.get(settings.camera).ok_or_else(|| {
            Error::Invalid(format!("camera index {} out of range", settings.camera))
        })?;
        let n_pixels = w * h;
        let grid = self.tile_grid(w, h);
        let mut params = GpuRenderParams {
            camera: camera_info(cam, w, h),
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
        let image = Image {
            width: w,
            height: h,
            rgb: sums
                .iter()
                .map(|s| {
                    let n = s[3].max(1.0);
                    [s[0] / n, s[1] / n, s[2] / n]
                })
                .collect(),
        };
        Ok(RenderOutput {
            image,
            camera_rays: counts[0] as u64,
            shadow_rays: counts[1] as u64,
            bsdf_rays: counts[2] as u64,
            dropped: counts[3] as u64,
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
