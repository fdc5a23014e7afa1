//! The buffers an optimizer allocates, before it allocates them.

use super::{estimator, primal, PrimalMode, Settings};
use crate::gpu::Gpu;
use crate::render::params::ParamSet;
use crate::{Error, Result};

/// The buffers an optimizer allocates besides the scene's, by label and size in bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryPlan {
    /// (label, bytes) of each buffer.
    pub buffers: Vec<(String, u64)>,
}

impl MemoryPlan {
    /// Total bytes.
    pub fn total(&self) -> u64 {
        self.buffers.iter().map(|b| b.1).sum()
    }

    /// Refuse, before anything is allocated, a buffer larger than the device binds or
    /// allocates, naming the buffer, its size and the limit.
    pub fn check(&self, gpu: &Gpu) -> Result<()> {
        let l = gpu.device.limits();
        let limit = l.max_storage_buffer_binding_size.min(l.max_buffer_size);
        if let Some((label, bytes)) = self.buffers.iter().find(|b| b.1 > limit) {
            return Err(Error::Unsuitable(format!(
                "the optimizer's {label} buffer needs {bytes} bytes ({:.1} MiB), the device allows \
                 {limit} bytes ({:.1} MiB) per storage buffer; use smaller textures or images \
                 (the optimizer needs {:.1} MiB in all)",
                *bytes as f64 / MIB,
                limit as f64 / MIB,
                self.total() as f64 / MIB
            )));
        }
        Ok(())
    }
}

const MIB: f64 = 1024.0 * 1024.0;

/// The optimizer's buffers for textures `set`, images as in `settings`, `n_cams` cameras.
pub fn memory_plan(set: &ParamSet, settings: &Settings, n_cams: usize) -> MemoryPlan {
    let n_params = set.values.len() as u64;
    let n_texels: u64 = set
        .textures
        .iter()
        .map(|t| (t.width * t.height) as u64)
        .sum();
    let pixels = settings.width as u64 * settings.height as u64;
    let mut buffers = vec![
        ("params".to_string(), 4 * n_params),
        ("params_prev".to_string(), 4 * n_params),
        ("gradient".to_string(), 4 * n_params),
        ("adam moment1".to_string(), 4 * n_params),
        ("adam moment2".to_string(), 4 * n_params),
        ("primal accum".to_string(), 16 * pixels),
        ("primal accum_prev".to_string(), 16 * pixels),
        ("adjoint even".to_string(), 16 * pixels * n_cams as u64),
        ("adjoint odd".to_string(), 16 * pixels * n_cams as u64),
    ];
    for k in 0..n_cams {
        buffers.push((format!("target {k}"), 16 * pixels));
    }
    buffers.extend(estimator::memory(
        settings.method,
        n_texels,
        pixels * n_cams as u64,
    ));
    if settings.primal == PrimalMode::ControlVariate {
        buffers.extend(primal::memory(pixels, n_cams as u64));
    }
    MemoryPlan { buffers }
}
