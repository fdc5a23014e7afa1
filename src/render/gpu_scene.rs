//! Scene upload: the BVH (or the ray-query acceleration structure), triangles, materials,
//! textures, lights and environment as bind group 0 of every tracing pass
//! (shaders/shared/scene.wgsl).
use super::gpu_lights::{capture_lights, gpu_lights, CaptureSets};
use super::layout::*;
use super::params::{ParamBuffers, ParamSet};
use crate::gpu::{Gpu, Tracer};
use crate::scene::{bvh, Scene, TextureSlot, Wrap};
use crate::{Error, Result};
use glam::Vec3;

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
    /// Number of floats of the optimized textures (bound at 9 and 10, see [`ParamBuffers`]).
    pub param_count: u32,
    /// Number of texels of all optimized textures.
    pub n_texels: u32,
    /// Whether an optimized texture replaces a normal map (see [`GpuScene::off_modules`]).
    pub normal_maps: bool,
    /// What [`GpuScene::update_environment`] rewrites: the lights as uploaded with each one's
    /// power estimate and the sets of punctual lights the cameras' captures see, the scene's
    /// radius, and the buffers of the lights, the environment's table and the scene's info.
    lights: Vec<GpuLight>,
    light_power: Vec<f64>,
    capture_sets: CaptureSets,
    radius: f32,
    lights_buffer: wgpu::Buffer,
    env_buffer: wgpu::Buffer,
    info_buffer: wgpu::Buffer,
}

fn wrap_bits(w: Wrap) -> u32 {
    match w {
        Wrap::Repeat => 0,
        Wrap::Clamp => 1,
        Wrap::Mirror => 2,
    }
}

/// `TextureWrapTestParams` in texture_wrap_test.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TextureWrapTestParams {
    pub n: i32,
    pub mode: u32,
    pub count: u32,
    pub _pad: u32,
}

/// Group 0 of `texture_wrap_test.wgsl`.
pub(crate) const TEXTURE_WRAP_TEST_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "texture_wrap_test",
    group: 0,
    names: &["tw", "coords", "wrapped"],
};

/// The texel coordinates the shaders' lookups use for `coords` in a texture `n` texels wide
/// with wrap mode `wrap` (shared/wrap.wgsl, run on the GPU), for tests against the CPU
/// lookup. At most 64 times the device's workgroups-per-dimension limit of coordinates
/// (4,194,240 on lavapipe).
pub fn wrap_trial(gpu: &Gpu, coords: &[i32], n: i32, wrap: Wrap) -> Result<Vec<i32>> {
    if coords.is_empty() {
        return Ok(Vec::new());
    }
    let count = coords.len() as u32;
    let groups = count.div_ceil(super::WORKGROUP);
    if groups > gpu.device.limits().max_compute_workgroups_per_dimension || n <= 0 {
        return Err(Error::Invalid(format!(
            "wrap_trial: {count} coordinates, width {n}"
        )));
    }
    let params = TextureWrapTestParams {
        n,
        mode: wrap_bits(wrap),
        count,
        _pad: 0,
    };
    let layout = gpu.pass_layout("texture_wrap_test", 0)?;
    let pipeline = gpu.compute_pipeline("texture_wrap_test", &[&layout])?;
    let uniform = gpu.uniform("texture_wrap_test params", bytemuck::bytes_of(&params));
    let input = gpu.storage(
        "texture_wrap_test coords",
        bytemuck::cast_slice(coords),
        wgpu::BufferUsages::empty(),
    );
    let output = gpu.storage_zeroed("texture_wrap_test wrapped", coords.len() as u64 * 4);
    let group = gpu.bind(
        &TEXTURE_WRAP_TEST_GROUP,
        "texture_wrap_test",
        &layout,
        &[("tw", &uniform), ("coords", &input), ("wrapped", &output)],
    );
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("texture_wrap_test"),
        });
    crate::gpu::encode_pass(
        &mut enc,
        "texture_wrap_test",
        &pipeline,
        &[&group],
        (groups, 1),
    );
    gpu.queue.submit([enc.finish()]);
    let mut out: Vec<i32> = gpu.read_pod(&output)?;
    out.truncate(coords.len());
    Ok(out)
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

/// Every image in one RGBA8 buffer: each image's offset (in texels) and the texels.
fn pack_textures(scene: &Scene) -> (Vec<u32>, Vec<u32>) {
    let mut image_offsets = Vec::new();
    let mut texels: Vec<u32> = Vec::new();
    for img in &scene.images {
        image_offsets.push(texels.len() as u32);
        texels.extend(img.rgba.iter().map(|p| u32::from_le_bytes(*p)));
    }
    (image_offsets, texels)
}

/// The GPU form of every material, its textures at `image_offsets` (no optimized texture
/// bound yet).
fn gpu_materials(scene: &Scene, image_offsets: &[u32]) -> Vec<GpuMaterial> {
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
    scene
        .materials
        .iter()
        .map(|m| {
            let [a, b] = xf(&m.base_color_texture);
            let [c, d] = xf(&m.metallic_roughness_texture);
            let [e, f] = xf(&m.emissive_texture);
            let [g, h] = xf(&m.normal_texture);
            GpuMaterial {
                base_color: m.base_color.to_array(),
                emissive: m.emissive.to_array(),
                metallic: m.metallic,
                roughness: m.roughness,
                double_sided: m.double_sided as u32,
                param_base_color: u32::MAX,
                param_metallic: u32::MAX,
                param_roughness: u32::MAX,
                normal_scale: m.normal_scale,
                param_normal: u32::MAX,
                _pad: 0,
                base_color_tex: tex_ref(&m.base_color_texture, true),
                mr_tex: tex_ref(&m.metallic_roughness_texture, false),
                emissive_tex: tex_ref(&m.emissive_texture, true),
                normal_tex: tex_ref(&m.normal_texture, false),
                uv_xf: [a, b, c, d, e, f, g, h],
            }
        })
        .collect()
}

/// Bind the optimized textures of `param_set` to their materials: the parameter textures'
/// table and the texels they hold in all.
fn bind_optimized(
    materials: &mut [GpuMaterial],
    scene: &Scene,
    param_set: &ParamSet,
) -> Result<(Vec<GpuParamTex>, u32)> {
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
        let (slot, index) = match t.slot {
            crate::vocab::Slot::BaseColor => (&mut m.param_base_color, 0),
            crate::vocab::Slot::Metallic => (&mut m.param_metallic, 1),
            crate::vocab::Slot::Roughness => (&mut m.param_roughness, 2),
            crate::vocab::Slot::Normal => (&mut m.param_normal, 3),
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
            slot: index,
            _pad: 0,
        });
        texel_offset += t.width * t.height;
    }
    Ok((param_textures, texel_offset))
}

/// Positions (vec4 per vertex) and shading attributes of the triangles, in BVH order.
fn bvh_triangles(
    scene: &Scene,
    bvh: &bvh::Bvh,
    tri_light: &[u32],
    materials: &[GpuMaterial],
) -> (Vec<[f32; 4]>, Vec<GpuTriShading>) {
    let n_tris = scene.triangles.len();
    let mut positions: Vec<[f32; 4]> = Vec::with_capacity(n_tris * 3);
    let mut shading: Vec<GpuTriShading> = Vec::with_capacity(n_tris);
    for &i in &bvh.order {
        let t = &scene.triangles[i as usize];
        for p in t.p {
            positions.push([p.x, p.y, p.z, 0.0]);
        }
        // A normal-mapped triangle (a glTF normal map or an optimized one) built in code
        // without tangents takes its face's.
        let mut tangents = t.t;
        let mapped = scene
            .materials
            .get(t.material as usize)
            .is_some_and(|m| m.normal_texture.is_some())
            || materials
                .get(t.material as usize)
                .is_some_and(|m| m.param_normal != u32::MAX);
        if mapped && tangents.iter().all(|v| *v == glam::Vec4::ZERO) {
            let n = (t.p[1] - t.p[0]).cross(t.p[2] - t.p[0]).normalize_or_zero();
            tangents = [crate::scene::tangents::face_tangent(t.p, t.uv, n); 3];
        }
        let packed = tangents.map(|v| if mapped { pack_tangent(v) } else { 0 });
        shading.push(GpuTriShading {
            n0: t.n[0].to_array(),
            t0: packed[0],
            n1: t.n[1].to_array(),
            t1: packed[1],
            n2: t.n[2].to_array(),
            t2: packed[2],
            uv01: [t.uv[0].x, t.uv[0].y, t.uv[1].x, t.uv[1].y],
            uv2: t.uv[2].to_array(),
            material: t.material,
            light: tri_light[i as usize],
        });
    }
    (positions, shading)
}

impl GpuScene {
    /// Upload a scene: BVH, triangles, materials, textures, lights and environment, and bind
    /// the optimized textures that replace material inputs (`param_set` lays them out,
    /// `params` holds their values).
    pub fn new(
        gpu: &Gpu,
        scene: &Scene,
        param_set: &ParamSet,
        params: &ParamBuffers,
    ) -> Result<GpuScene> {
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

        let (image_offsets, texels) = pack_textures(scene);
        check("the texture buffer", texels.len() * 4)?;
        let mut materials = gpu_materials(scene, &image_offsets);
        let (param_textures, texel_offset) = bind_optimized(&mut materials, scene, param_set)?;
        check("the optimized textures", param_set.values.len() * 4)?;
        if params.values.size() < param_set.values.len() as u64 * 4 {
            return Err(Error::Invalid(format!(
                "the parameter buffers hold {} bytes, the optimized textures need {}",
                params.values.size(),
                param_set.values.len() * 4
            )));
        }

        let (lights, light_power, tri_light, env_table, info) = gpu_lights(scene, &bvh, &gpu_index);
        check("the environment map", env_table.len() * 4)?;
        let (light_table, sets) = capture_lights(scene, &lights, &light_power);

        let (positions, shading) = bvh_triangles(scene, &bvh, &tri_light, &materials);
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
            gpu.storage("scene lights", bytemuck::cast_slice(&light_table), none),
            gpu.storage("scene env", bytemuck::cast_slice(&env_table), none),
            gpu.uniform("scene info", bytemuck::bytes_of(&info)),
            gpu.storage(
                "scene param_textures",
                bytemuck::cast_slice(&param_textures),
                none,
            ),
        ];
        let bytes = buffers.iter().map(|b| b.size()).sum();
        // Group 0 of every tracing pass (shaders/shared/scene.wgsl).
        let layout = gpu.pass_layout("render", 0)?;
        let mut refs: Vec<&wgpu::Buffer> = buffers.iter().collect();
        refs.extend([&params.values, &params.previous]);
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
        Ok(GpuScene {
            layout,
            bind_group,
            accel,
            info,
            cameras: scene.cameras.clone(),
            gpu_index,
            bytes,
            param_count: param_set.values.len() as u32,
            n_texels: texel_offset,
            normal_maps: param_set.find_slot(crate::vocab::Slot::Normal).is_some(),
            lights,
            light_power,
            capture_sets: sets,
            radius: scene.bounding_sphere().1,
            lights_buffer: buffers[5].clone(),
            env_buffer: buffers[6].clone(),
            info_buffer: buffers[7].clone(),
        })
    }
}

/// The shared WGSL modules composed in their `_off` form for a scene that does not optimize
/// a normal map (`normal_maps` false): `shared/normal_map`.
pub fn off_modules(normal_maps: bool) -> &'static [&'static str] {
    if normal_maps {
        &[]
    } else {
        &["shared/normal_map"]
    }
}

impl GpuScene {
    /// The shared WGSL modules that the passes over this scene compose in their `_off` form
    /// (`crate::gpu::shaders::Library::compose_without`): `shared/normal_map` where no
    /// optimized texture replaces a normal map. Measured on lavapipe: the default task's
    /// pipelines compile in 7.4 s without it, against 9.6-10.0 s with the normal-map code
    /// compiled in.
    pub fn off_modules(&self) -> &'static [&'static str] {
        off_modules(self.normal_maps)
    }

    /// Compile the crate's pass `pass`, which binds this scene at group 0, in the form its
    /// features need ([`GpuScene::off_modules`]).
    pub fn pipeline(
        &self,
        gpu: &crate::gpu::Gpu,
        pass: &str,
        layouts: &[&wgpu::BindGroupLayout],
    ) -> crate::Result<wgpu::ComputePipeline> {
        gpu.compute_pipeline_without(pass, layouts, self.off_modules())
    }

    /// The constants of camera `cam` (an index into [`GpuScene::cameras`]) for a `width` x
    /// `height` render ([`super::camera_info`]), with the lights of its capture.
    pub fn camera_info(&self, cam: usize, width: u32, height: u32) -> Result<GpuCameraInfo> {
        let c = self
            .cameras
            .get(cam)
            .ok_or_else(|| Error::Invalid(format!("camera index {cam} out of range")))?;
        let mut info = super::camera_info(c, width, height);
        if let Some(set) = &c.lights {
            info.light_base = self
                .capture_sets
                .base(set, self.info.n_lights)
                .ok_or_else(|| {
                    Error::Invalid(format!(
                        "camera `{}` sees the lights {set:?}, a set the scene was not \
                         uploaded with",
                        c.name
                    ))
                })?;
        }
        Ok(info)
    }

    /// Write a new environment of the uploaded one's size (the optimized environment): its
    /// texels, and with `tables` its sampling tables and its share of the light choice, rebuilt
    /// from these values. Between rebuilds the sampling follows the tables of the last one,
    /// which every density the passes compute reads too, so the estimates stay unbiased; only
    /// their variance grows as the environment drifts from the tables. `optimized` tells the
    /// gradient passes to differentiate the environment.
    pub fn update_environment(
        &mut self,
        gpu: &Gpu,
        env: &crate::scene::EnvMap,
        tables: bool,
        optimized: bool,
    ) -> Result<()> {
        if (env.width, env.height) != (self.info.env_width, self.info.env_height) {
            return Err(Error::Invalid(format!(
                "a {}x{} environment for a scene uploaded with {}x{}",
                env.width, env.height, self.info.env_width, self.info.env_height
            )));
        }
        if tables {
            let (table, _, _) = env.gpu_table();
            gpu.queue
                .write_buffer(&self.env_buffer, 0, bytemuck::cast_slice(&table));
            if let Some(p) = self.light_power.get_mut(self.info.env_light as usize) {
                *p = env.power(self.radius);
                let (table, _) = self.capture_sets.table(&self.lights, &self.light_power);
                gpu.queue
                    .write_buffer(&self.lights_buffer, 0, bytemuck::cast_slice(&table));
            }
        } else {
            let texels: Vec<f32> = env.rgb.iter().flatten().copied().collect();
            gpu.queue
                .write_buffer(&self.env_buffer, 0, bytemuck::cast_slice(&texels));
        }
        self.info.env_scale = env.scale;
        self.info.env_optimized = optimized as u32;
        gpu.queue
            .write_buffer(&self.info_buffer, 0, bytemuck::bytes_of(&self.info));
        Ok(())
    }
}
