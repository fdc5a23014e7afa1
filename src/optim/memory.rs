//! The buffers an optimizer allocates, before it allocates them.

pub use super::estimator::Scale;
use super::{estimator, primal, PrimalMode, Settings};
use crate::gpu::Gpu;
use crate::render::params::ParamSet;
use crate::{Error, Result};

/// The buffers an optimizer allocates besides the scene's, by label and size in bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryPlan {
    /// (label, bytes, what it scales with) of each buffer.
    pub buffers: Vec<(String, u64, Scale)>,
    /// Texels of the optimized textures.
    pub texels: u64,
    /// Texels that a camera observes.
    pub observed_texels: u64,
    /// Pixels of all cameras.
    pub pixels: u64,
}

impl MemoryPlan {
    /// Total bytes.
    pub fn total(&self) -> u64 {
        self.buffers.iter().map(|b| b.1).sum()
    }

    /// Bytes per unit of `scale` (per texel, per observed texel or per pixel).
    pub fn bytes_per(&self, scale: Scale) -> f64 {
        let n = match scale {
            Scale::Texel => self.texels,
            Scale::ObservedTexel => self.observed_texels,
            Scale::Pixel => self.pixels,
        };
        let bytes: u64 = self
            .buffers
            .iter()
            .filter(|b| b.2 == scale)
            .map(|b| b.1)
            .sum();
        bytes as f64 / n.max(1) as f64
    }

    /// One line: the total and the bytes per texel, per observed texel and per pixel.
    pub fn summary(&self) -> String {
        format!(
            "optimizer memory {:.1} MiB: {:.1} bytes per texel ({} texels), {:.1} per observed \
             texel ({} observed), {:.1} per pixel ({} pixels of all cameras)",
            self.total() as f64 / MIB,
            self.bytes_per(Scale::Texel),
            self.texels,
            self.bytes_per(Scale::ObservedTexel),
            self.observed_texels,
            self.bytes_per(Scale::Pixel),
            self.pixels
        )
    }

    /// Refuse, before anything is allocated, a buffer larger than the device binds or
    /// allocates, naming the buffer, its size and the limit.
    pub fn check(&self, gpu: &Gpu) -> Result<()> {
        let l = gpu.device.limits();
        let limit = l.max_storage_buffer_binding_size.min(l.max_buffer_size);
        if let Some((label, bytes, _)) = self.buffers.iter().find(|b| b.1 > limit) {
            return Err(Error::Unsuitable(format!(
                "the optimizer's {label} buffer needs {bytes} bytes ({:.1} MiB), the device allows \
                 {limit} bytes ({:.1} MiB) per storage buffer; use smaller textures or images, \
                 or fewer observed texels ({})",
                *bytes as f64 / MIB,
                limit as f64 / MIB,
                self.summary()
            )));
        }
        Ok(())
    }
}

const MIB: f64 = 1024.0 * 1024.0;

/// The optimizer's buffers for textures `set` of which `n_observed` texels are observed,
/// images as in `settings`, `n_cams` cameras, paths of `max_depth` vertices.
pub fn memory_plan(
    set: &ParamSet,
    settings: &Settings,
    n_cams: usize,
    n_observed: u64,
    max_depth: u32,
) -> MemoryPlan {
    let n_params = set.values.len() as u64;
    let n_texels: u64 = set
        .textures
        .iter()
        .map(|t| (t.width * t.height) as u64)
        .sum();
    let pixels = settings.width as u64 * settings.height as u64;
    let all_pixels = pixels * n_cams as u64;
    let texel = |label: &str, bytes: u64| (label.to_string(), bytes, Scale::Texel);
    let pixel = |label: String, bytes: u64| (label, bytes, Scale::Pixel);
    let mut buffers = vec![
        texel("params", 4 * n_params),
        texel("params_prev", 4 * n_params),
        texel("gradient", 4 * n_params),
        texel("step moment1", 4 * n_params),
        texel("step moment2", 4 * n_params),
        texel("observed texels", 4 * n_texels),
        pixel("primal accum".into(), 16 * pixels),
        pixel("primal accum_prev".into(), 16 * pixels),
        pixel("adjoint even".into(), 16 * all_pixels),
        pixel("adjoint odd".into(), 16 * all_pixels),
    ];
    for k in 0..n_cams {
        buffers.push(pixel(format!("target {k}"), 16 * pixels));
    }
    buffers.extend(estimator::memory(
        settings.method,
        &settings.estimator_options,
        set,
        n_texels,
        n_observed,
        all_pixels,
        settings.gradient_spp,
        max_depth,
    ));
    if settings.moment_filter.enabled() {
        buffers.extend(
            super::moment_filter::memory(set)
                .into_iter()
                .map(|(l, b)| (l, b, Scale::Texel)),
        );
    }
    // (Settings ask for a cache only where the images can use one: path_cache::usable.)
    if settings.path_cache.is_some() {
        for k in 0..n_cams {
            let bytes = primal::path_cache::camera_bytes(pixels, settings.primal_spp, max_depth);
            buffers.push(pixel(format!("path cache {k}"), bytes));
        }
    }
    if settings.primal == PrimalMode::ControlVariate {
        buffers.extend(
            primal::memory(pixels, n_cams as u64)
                .into_iter()
                .map(|(l, b)| (l, b, Scale::Pixel)),
        );
    }
    MemoryPlan {
        buffers,
        texels: n_texels,
        observed_texels: n_observed,
        pixels: all_pixels,
    }
}
