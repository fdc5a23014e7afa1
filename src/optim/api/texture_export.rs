//! The `texture_export` pass (src/optim/texture_export.wgsl): one optimized texture copied into
//! an `Rgba32Float` GPU texture that an application can bind ([`create_texture`]).
use crate::gpu::grid_2d;
use crate::optim::Optimizer;
use crate::render::WORKGROUP;
use crate::{Error, Result};
use bytemuck::{Pod, Zeroable};

/// `ExportParams` in src/optim/texture_export.wgsl (a test checks the layout).
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

/// Group 0 of `texture_export.wgsl`.
pub(crate) const TEXTURE_EXPORT_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "texture_export",
    group: 0,
    names: &["ep", "params", "texture_out"],
};

/// The pass's pipeline (built on first use).
pub(crate) fn pipeline(gpu: &crate::gpu::Gpu) -> Result<wgpu::ComputePipeline> {
    let layout = gpu.pass_layout("texture_export", 0)?;
    gpu.compute_pipeline("texture_export", &[&layout])
}

/// Texture `i` (index into `set.textures`) as a new `Rgba32Float` GPU texture of its size
/// that the application can bind: RGB for base color, the value in R, G and B for
/// roughness and metallic, alpha 1. Usage: `TEXTURE_BINDING | STORAGE_BINDING |
/// COPY_SRC`. The copy is made on the GPU when this is called.
pub fn create_texture(opt: &Optimizer, i: usize) -> Result<wgpu::Texture> {
    let t = opt.set.textures.get(i).ok_or_else(|| {
        Error::Invalid(format!(
            "texture {i} does not exist ({} optimized)",
            opt.set.textures.len()
        ))
    })?;
    let gpu = &opt.gpu;
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
    let pipeline = match opt.passes.export_pipeline.get() {
        Some(p) => p,
        None => {
            let p = pipeline(gpu)?;
            opt.passes.export_pipeline.get_or_init(|| p)
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
    let group = gpu.bind_resources(
        &TEXTURE_EXPORT_GROUP,
        "texture_export",
        &pipeline.get_bind_group_layout(0),
        &[
            ("ep", uniform.as_entire_binding()),
            ("params", opt.params_buffer().as_entire_binding()),
            ("texture_out", wgpu::BindingResource::TextureView(&view)),
        ],
    );
    let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("texture_export"),
    });
    let max_dim = device.limits().max_compute_workgroups_per_dimension;
    let grid = grid_2d(t.width * t.height, WORKGROUP, max_dim);
    crate::gpu::encode_pass(&mut enc, "texture_export", pipeline, &[&group], grid);
    gpu.queue.submit([enc.finish()]);
    gpu.check("texture_export")?;
    Ok(texture)
}
