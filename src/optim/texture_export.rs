//! The `texture_export` pass (shaders/texture_export.wgsl): one optimized texture copied into
//! an `Rgba32Float` GPU texture that an application can bind ([`Optimizer::create_texture`]).
use super::Optimizer;
use crate::gpu::grid_2d;
use crate::render::WORKGROUP;
use crate::{Error, Result};
use bytemuck::{Pod, Zeroable};

/// `ExportParams` in shaders/texture_export.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ExportParams {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
    pub channels: u32,
}

fn entry(binding: u32, ty: wgpu::BindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty,
        count: None,
    }
}

/// The pass's pipeline (built on first use).
pub(crate) fn pipeline(gpu: &crate::gpu::Gpu) -> Result<wgpu::ComputePipeline> {
    let buffer = |read_only: Option<bool>| wgpu::BindingType::Buffer {
        ty: match read_only {
            None => wgpu::BufferBindingType::Uniform,
            Some(read_only) => wgpu::BufferBindingType::Storage { read_only },
        },
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    let layout = gpu
        .device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("texture_export"),
            entries: &[
                entry(0, buffer(None)),
                entry(1, buffer(Some(true))),
                entry(
                    2,
                    wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::Rgba32Float,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                ),
            ],
        });
    gpu.compute_pipeline("texture_export", &[&layout])
}

impl Optimizer {
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
        let gpu = &self.gpu;
        let device = &gpu.device;
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
                let p = pipeline(gpu)?;
                self.export_pipeline.get_or_init(|| p)
            }
        };
        let params = ExportParams {
            offset: t.offset,
            width: t.width,
            height: t.height,
            channels: t.channels(),
        };
        let uniform = gpu.uniform("texture_export params", bytemuck::bytes_of(&params));
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
                    resource: self.params_buffer().as_entire_binding(),
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
        gpu.queue.submit([enc.finish()]);
        gpu.check("texture_export")?;
        Ok(texture)
    }
}
