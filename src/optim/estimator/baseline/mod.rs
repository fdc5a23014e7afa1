//! The baseline estimator (gradient.wgsl): plain Monte Carlo. Every camera sample
//! differentiates its light-sampled and BSDF-sampled contributions with respect to the
//! material at its hit point and adds them, weighted by its pixel's adjoint, into the texels
//! that the texture filter touches. Float additions are bounded compare-and-swap loops on
//! 32-bit atomics; an exhausted bound is counted, never silently lost.
//!
//! With its `cache` option (pool.rs) the samples are camera paths kept from earlier
//! iterations, `cache` of the `gradient_spp` per pixel traced anew each iteration, shaded and
//! differentiated without a ray (gradient_cached.wgsl).
mod pool;
pub use pool::BaselineOptions;

use super::{Estimator, EstimatorState, Frame, Kind, Method, Options, OptionsKind, Setup};
use crate::gpu::encode_timed_pass;
use crate::gpu::Gpu;
use crate::optim::{pass_seed, FaultCounts, PassKind, PassTimer, Seeds};
use crate::render::layout::GpuCameraInfo;
use crate::render::{Techniques, WORKGROUP};
use crate::Result;
use bytemuck::{Pod, Zeroable};

/// The baseline as the registry knows it.
pub const KIND: Kind = Kind {
    name: "baseline",
    summary: "plain Monte Carlo: every sample adds its derivative to the texels it touches",
    options: OptionsKind::of::<BaselineOptions>(),
    wgsl: &[
        ("gradient", include_str!("gradient.wgsl")),
        ("gradient_cached", include_str!("gradient_cached.wgsl")),
    ],
    generated: &[],
    groups: &[GRADIENT_GROUP, pool::GRADIENT_CACHED_GROUP],
    passes: |options| match options.get::<BaselineOptions>() {
        Ok(BaselineOptions { cache: Some(_) }) => vec!["gradient_cached", "primal_cache_trace"],
        _ => vec!["gradient"],
    },
    max_cameras: None,
    memory: pool::memory,
    warnings: super::no_warnings,
    every_texel: super::observed_only,
    build: |setup| Ok(Box::new(Baseline::new(setup)?)),
};

impl Options<super::EstimatorFamily> for BaselineOptions {
    const KIND: &'static Kind = &KIND;
    const OPTIONAL: &'static [&'static str] = &["cache"];

    fn check(&self) -> std::result::Result<(), (String, String)> {
        if self.cache == Some(0) {
            return Err(("cache".into(), "must be at least 1 (paths traced anew each iteration)".into()));
        }
        Ok(())
    }

    fn describe(&self) -> String {
        self.cache.map_or(String::new(), |r| format!("path pool, {r} traced anew"))
    }
}

/// Group 1 of `gradient.wgsl`.
pub(crate) const GRADIENT_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "gradient",
    group: 1,
    names: &["gp", "adjoint", "grad", "gstats", "env_grad"],
};

/// `GradientParams` in gradient.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GradientParams {
    pub camera: GpuCameraInfo,
    pub seed: u32,
    pub sample_offset: u32,
    pub spp: u32,
    pub techniques: u32,
    pub stride: u32,
    pub inv_spp: f32,
    pub adjoint_offset: u32,
    pub _pad: u32,
}

/// `gstats` slots of gradient.wgsl.
const STAT_LOST: usize = crate::gpu::abi::stat::GRADIENT_LOST as usize;
const STAT_DROPPED: usize = crate::gpu::abi::stat::GRADIENT_DROPPED as usize;

struct Camera {
    uniform: wgpu::Buffer,
    params: GradientParams,
    /// Per parity of the iteration (the adjoint buffers alternate).
    groups: [wgpu::BindGroup; 2],
}

/// Where the baseline's samples come from.
enum Samples {
    /// Traced by the gradient pass, per camera.
    Traced(wgpu::ComputePipeline, Vec<Camera>),
    /// Shaded from its path pool (the `cache` option).
    Pooled(pool::GradientPool),
}

/// The baseline estimator's passes and buffers.
pub(crate) struct Baseline {
    samples: Samples,
    grad: wgpu::Buffer,
    stats: wgpu::Buffer,
    grid: (u32, u32),
    queue: wgpu::Queue,
}

impl Baseline {
    pub(crate) fn new(s: &Setup) -> Result<Baseline> {
        let gpu = s.gpu;
        let options: BaselineOptions = (s.options.get())
            .map_err(|(key, msg)| crate::Error::Invalid(format!("{key} {msg}")))?;
        let stats = gpu.storage_zeroed("gradient stats", 16);
        let pool = match options.cache {
            Some(refresh) => pool::GradientPool::new(s, refresh, &stats)?,
            None => None,
        };
        let samples = match pool {
            Some(pool) => Samples::Pooled(pool),
            None => Self::traced(s, &stats)?,
        };
        Ok(Baseline {
            samples,
            grad: s.grad.clone(),
            stats,
            grid: s.grid,
            queue: gpu.queue.clone(),
        })
    }

    /// The gradient pass of every camera of `s`, counting in `stats`.
    fn traced(s: &Setup, stats: &wgpu::Buffer) -> Result<Samples> {
        let gpu = s.gpu;
        let layout = gpu.pass_layout("gradient", 1)?;
        let pipeline = s.scene.pipeline(gpu, "gradient", &[&s.scene.layout, &layout])?;
        let n_pixels = s.width * s.height;
        let cameras = s
            .cameras
            .iter()
            .enumerate()
            .map(|(k, &camera)| {
                let params = GradientParams {
                    camera,
                    spp: s.gradient_spp,
                    techniques: Techniques::Mis.bits(),
                    stride: s.grid.0 * WORKGROUP,
                    inv_spp: 1.0 / s.gradient_spp as f32,
                    adjoint_offset: k as u32 * n_pixels,
                    ..Default::default()
                };
                let uniform =
                    gpu.uniform(&format!("gradient params {k}"), bytemuck::bytes_of(&params));
                let groups = [0usize, 1].map(|p| {
                    gpu.bind(
                        &GRADIENT_GROUP,
                        "gradient",
                        &layout,
                        &[
                            ("gp", &uniform),
                            ("adjoint", &s.adjoint[p]),
                            ("grad", s.grad),
                            ("gstats", stats),
                            ("env_grad", s.env_grad),
                        ],
                    )
                });
                Camera {
                    uniform,
                    params,
                    groups,
                }
            })
            .collect();
        Ok(Samples::Traced(pipeline, cameras))
    }
}

impl Estimator for Baseline {
    fn encode(&mut self, enc: &mut wgpu::CommandEncoder, frame: &Frame, timer: &mut PassTimer) {
        enc.clear_buffer(&self.grad, 0, None);
        let (pipeline, cameras) = match &mut self.samples {
            Samples::Pooled(pool) => return pool.encode(enc, frame, self.grid, timer),
            Samples::Traced(pipeline, cameras) => (pipeline, cameras),
        };
        for (k, cam) in cameras.iter_mut().enumerate() {
            cam.params.seed = pass_seed(frame.seed, frame.iteration, k as u32, Seeds::GRADIENT);
            self.queue
                .write_buffer(&cam.uniform, 0, bytemuck::bytes_of(&cam.params));
            encode_timed_pass(
                enc,
                "gradient",
                pipeline,
                &[frame.scene_group, &cam.groups[frame.parity()]],
                self.grid,
                timer.next(PassKind::Gradient),
            );
        }
    }

    fn finish_iteration(&mut self) {
        if let Samples::Pooled(pool) = &mut self.samples {
            pool.finish_iteration();
        }
    }

    fn uses_previous_state(&self) -> bool {
        false
    }

    fn faults(&self, gpu: &Gpu, f: &mut FaultCounts) -> Result<()> {
        let g: Vec<u32> = gpu.read_pod(&self.stats)?;
        f.lost_updates += g[STAT_LOST];
        f.dropped_gradient += g[STAT_DROPPED];
        Ok(())
    }

    fn snapshot(&self, gpu: &Gpu, _iteration: u32) -> Result<EstimatorState> {
        let mut st = EstimatorState::new(Method::BASELINE);
        if let Samples::Pooled(pool) = &self.samples {
            pool.snapshot(gpu, &mut st)?;
        }
        Ok(st)
    }

    fn restore(&mut self, gpu: &Gpu, st: Option<&EstimatorState>, _: u32) -> Result<()> {
        if let Samples::Pooled(pool) = &mut self.samples {
            pool.restore(gpu, st)?;
        }
        Ok(())
    }

    fn state_bytes(&self) -> u64 {
        match &self.samples {
            Samples::Pooled(pool) => pool.bytes(),
            Samples::Traced(..) => 0,
        }
    }

    fn set_techniques(&mut self, techniques: Techniques) -> Result<()> {
        match &mut self.samples {
            Samples::Pooled(pool) => pool.set_techniques(techniques),
            Samples::Traced(_, cameras) => {
                for cam in cameras {
                    cam.params.techniques = techniques.bits();
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod contract_tests {
    use crate::contract_tests::mirror;

    // Its uniforms, field by field against naga's layout of its WGSL.
    #[test]
    fn uniform_mirrors_match_wgsl_field_by_field() {
        mirror!(
            "gradient",
            "GradientParams",
            super::GradientParams,
            [
                camera,
                seed,
                sample_offset,
                spp,
                techniques,
                stride,
                inv_spp,
                adjoint_offset
            ]
        );
        mirror!(
            "gradient_cached",
            "GradientCachedParams",
            super::pool::GradientCachedParams,
            [adjoint_offset, inv_spp]
        );
    }
}
