//! The optimizer's per-camera passes: the checks of its inputs, and each camera's primal
//! render and loss bindings.
use super::{loss, restir, Method, Settings, LOSS_GROUP};
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::render::layout::*;
use crate::render::{Renderer, Techniques, WORKGROUP};
use crate::vocab::Loss;
use crate::{Error, Result};

/// The primal render and loss of one camera.
pub(super) struct CameraPasses {
    pub(super) render_uniform: wgpu::Buffer,
    pub(super) render_params: GpuRenderParams,
    pub(super) render_group: wgpu::BindGroup,
    pub(super) loss_uniform: wgpu::Buffer,
    pub(super) loss_params: loss::LossParams,
    pub(super) target_buf: wgpu::Buffer,
    /// Per parity of the iteration (the adjoint buffers alternate).
    pub(super) loss_groups: [wgpu::BindGroup; 2],
}

/// Counters of the passes the optimizer runs itself.
pub(super) struct Stats {
    pub(super) primal: wgpu::Buffer,
    pub(super) adam: wgpu::Buffer,
    pub(super) loss: wgpu::Buffer,
}

/// The settings in range, one target per camera, each of the settings' size, and no more
/// cameras than the estimator handles.
pub(super) fn check_inputs(settings: &Settings, targets: &[Image]) -> Result<()> {
    let (w, h) = (settings.width, settings.height);
    settings
        .validate()
        .map_err(|(key, msg)| Error::Invalid(format!("settings: `{key}` {msg}")))?;
    if targets.len() != settings.cameras.len() {
        return Err(Error::Invalid(format!(
            "{} targets for {} cameras",
            targets.len(),
            settings.cameras.len()
        )));
    }
    if settings.method == Method::Restir && targets.len() > restir::MAX_CAMERAS {
        return Err(Error::Invalid(format!(
            "ReSTIR handles at most {} cameras, the task has {}",
            restir::MAX_CAMERAS,
            targets.len()
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
    Ok(())
}

/// What the primal render and loss passes of each camera bind.
pub(super) struct CameraSetup<'a> {
    pub(super) gpu: &'a Gpu,
    pub(super) renderer: &'a Renderer,
    pub(super) settings: &'a Settings,
    pub(super) camera_infos: &'a [GpuCameraInfo],
    pub(super) targets: &'a [Image],
    pub(super) grid: (u32, u32),
    pub(super) two_states: bool,
    pub(super) n_loss_groups: u32,
    pub(super) loss_layout: &'a wgpu::BindGroupLayout,
    pub(super) accum: &'a wgpu::Buffer,
    pub(super) accum_prev: &'a wgpu::Buffer,
    pub(super) stats: &'a Stats,
    pub(super) adjoint: &'a [wgpu::Buffer; 2],
    pub(super) loss_partial: &'a wgpu::Buffer,
    pub(super) exposure_partial: &'a wgpu::Buffer,
}

/// Per camera: the primal render's uniform and bind group, and the loss pass's uniform,
/// target image and bind groups (one per adjoint parity).
pub(super) fn camera_passes(s: &CameraSetup) -> Vec<CameraPasses> {
    let CameraSetup {
        gpu,
        renderer,
        settings,
        camera_infos,
        targets,
        grid,
        two_states,
        n_loss_groups,
        loss_layout,
        accum,
        accum_prev,
        stats,
        adjoint,
        loss_partial,
        exposure_partial,
    } = *s;
    let (w, h) = (settings.width, settings.height);
    let n_pixels = w * h;
    let norm = 1.0 / (n_pixels as f32 * 3.0 * targets.len() as f32);
    let mut cams = Vec::new();
    for (k, (camera, target)) in camera_infos.iter().zip(targets).enumerate() {
        let render_params = GpuRenderParams {
            camera: *camera,
            spp: settings.primal_spp,
            techniques: Techniques::Mis.bits(),
            stride: grid.0 * WORKGROUP,
            two_states: two_states as u32,
            ..Default::default()
        };
        let loss_params = loss::LossParams {
            n_pixels,
            kind: match settings.loss {
                Loss::L2 => 0,
                Loss::Relmse => 1,
            },
            norm,
            partial_offset: k as u32 * n_loss_groups,
            adjoint_offset: k as u32 * n_pixels,
            exposure: 1.0,
            _pad: [0; 2],
        };
        // Mask weight 1 everywhere until set_masks.
        let target_data: Vec<[f32; 4]> =
            target.rgb.iter().map(|p| [p[0], p[1], p[2], 1.0]).collect();
        let target_buf = gpu.storage(
            &format!("target {k}"),
            bytemuck::cast_slice(&target_data),
            wgpu::BufferUsages::empty(),
        );
        let render_uniform = gpu.uniform(
            &format!("primal params {k}"),
            bytemuck::bytes_of(&render_params),
        );
        let loss_uniform = gpu.uniform(
            &format!("loss params {k}"),
            bytemuck::bytes_of(&loss_params),
        );
        cams.push(CameraPasses {
            render_group: renderer.bind_render_group(
                "primal",
                &[
                    ("rp", &render_uniform),
                    ("accum", accum),
                    ("stats", &stats.primal),
                    ("accum_prev", accum_prev),
                ],
            ),
            loss_groups: [0usize, 1].map(|p| {
                gpu.bind(
                    &LOSS_GROUP,
                    "loss",
                    loss_layout,
                    &[
                        ("lp", &loss_uniform),
                        ("accum", accum),
                        ("target_image", &target_buf),
                        ("adjoint", &adjoint[p]),
                        ("loss_partial", loss_partial),
                        ("loss_stats", &stats.loss),
                        ("exposure_partial", exposure_partial),
                        ("adjoint_prev", &adjoint[1 - p]),
                    ],
                )
            }),
            render_uniform,
            render_params,
            loss_uniform,
            loss_params,
            target_buf,
        });
    }
    cams
}
