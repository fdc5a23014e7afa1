//! The optimizer's per-camera passes: the checks of its inputs, and each camera's primal
//! render and loss bindings.
use super::{estimator, Settings};
use crate::gpu::Gpu;
use crate::image_io::Image;
use crate::render::layout::*;
use crate::render::{Renderer, Techniques, WORKGROUP};
use crate::{Error, Result};

/// The primal render of one camera.
pub(super) struct CameraPasses {
    pub(super) render_uniform: wgpu::Buffer,
    pub(super) render_params: GpuRenderParams,
    pub(super) render_group: wgpu::BindGroup,
}

impl CameraPasses {
    /// Point this camera's primal render at `spp` samples from sample `offset` of `seed`'s
    /// stream, under the current textures (and with `two_states` the previous ones too, for
    /// the control variate), and upload its uniform: a chunk of a render outside the
    /// iteration. Returns `spp`.
    pub(super) fn set_samples(
        &mut self,
        queue: &wgpu::Queue,
        seed: u32,
        offset: u32,
        spp: u32,
        two_states: bool,
    ) -> u32 {
        self.render_params.seed = seed;
        self.render_params.sample_offset = offset;
        self.render_params.spp = spp;
        self.render_params.two_states = two_states as u32;
        queue.write_buffer(
            &self.render_uniform,
            0,
            bytemuck::bytes_of(&self.render_params),
        );
        spp
    }
}

/// Counters of the passes the optimizer runs itself.
pub(super) struct Stats {
    pub(super) primal: wgpu::Buffer,
    pub(super) step: wgpu::Buffer,
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
    if let Some(max) = estimator::max_cameras(settings.method) {
        if targets.len() > max {
            return Err(Error::Invalid(format!(
                "the {} estimator handles at most {max} cameras, the task has {}",
                settings.method.name(),
                targets.len()
            )));
        }
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

/// What the primal render of each camera binds.
pub(super) struct CameraSetup<'a> {
    pub(super) gpu: &'a Gpu,
    pub(super) renderer: &'a Renderer,
    pub(super) settings: &'a Settings,
    pub(super) camera_infos: &'a [GpuCameraInfo],
    pub(super) grid: (u32, u32),
    pub(super) two_states: bool,
    pub(super) accum: &'a wgpu::Buffer,
    pub(super) accum_prev: &'a wgpu::Buffer,
    pub(super) stats: &'a Stats,
}

/// Per camera: the primal render's uniform and bind group.
pub(super) fn camera_passes(s: &CameraSetup) -> Vec<CameraPasses> {
    let CameraSetup {
        gpu,
        renderer,
        settings,
        camera_infos,
        grid,
        two_states,
        accum,
        accum_prev,
        stats,
    } = *s;
    let mut cams = Vec::new();
    for (k, camera) in camera_infos.iter().enumerate() {
        let render_params = GpuRenderParams {
            camera: *camera,
            spp: settings.primal_spp,
            techniques: Techniques::Mis.bits(),
            stride: grid.0 * WORKGROUP,
            two_states: two_states as u32,
            ..Default::default()
        };
        let render_uniform = gpu.uniform(
            &format!("primal params {k}"),
            bytemuck::bytes_of(&render_params),
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
            render_uniform,
            render_params,
        });
    }
    cams
}
