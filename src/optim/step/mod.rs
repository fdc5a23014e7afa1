//! The steps the optimizer takes with each gradient estimate, behind one trait (`Step`):
//! Adam ([`adam`]), the variance-scaled step ([`variance_step`]), and the filtered moments
//! either can take ([`moment_filter`]). Each module holds its pass's driver, the mirror of its
//! uniform and its CPU reference; its WGSL lies beside it, named after the pass. The
//! per-texture dispatch logic they share is `TextureSteps`.
pub mod adam;
pub mod moment_filter;
pub mod variance_step;

use crate::gpu::abi::step_phase;
use crate::gpu::{encode_timed_pass, grid_2d, Gpu};
use crate::optim::{PassKind, PassTimer, Settings};
use crate::render::params::{ParamSet, ParamTexture};
use crate::render::WORKGROUP;
use crate::Result;
use moment_filter::MomentFilter;

/// The steps' WGSL: (name, source) of their passes.
pub(crate) const WGSL: &[(&str, &str)] = &[
    ("adam", include_str!("adam.wgsl")),
    ("variance_step", include_str!("variance_step.wgsl")),
    ("moment_filter", include_str!("moment_filter.wgsl")),
];

/// Which step the optimizer takes with the gradient estimate (the task file's
/// `optimizer.step`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StepKind {
    /// Adam (first and second moments).
    #[default]
    Adam,
    /// The variance-scaled step: no first moment, the estimate's variance in the denominator.
    Variance,
}

impl StepKind {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            StepKind::Adam => "adam",
            StepKind::Variance => "variance",
        }
    }
}

/// A step as the optimizer drives it, once per iteration after the gradient.
pub(crate) trait Step: Send {
    /// Record step `t` (from 1) of every texture at its learning rate times `factor`;
    /// returns the learning rates used, one per texture.
    fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        set: &ParamSet,
        factor: f32,
        t: u32,
        timer: &mut PassTimer,
    ) -> Vec<f32>;
    /// The moment filter, when the step has one.
    fn filter(&self) -> Option<&MomentFilter>;
}

/// What a step binds.
pub(crate) struct StepBuffers<'a> {
    /// The gradient, laid out like the parameters.
    pub grad: &'a wgpu::Buffer,
    /// The parameters it moves.
    pub params: &'a wgpu::Buffer,
    /// Its per-parameter state (Adam's moments; the variance step's moving mean and
    /// variance).
    pub moments: &'a [wgpu::Buffer; 2],
    /// The estimator's variance, or None (the variance step then keeps a moving variance of
    /// the gradient; Adam has no use for it).
    pub variance: Option<&'a wgpu::Buffer>,
    /// Its statistics buffer.
    pub stats: &'a wgpu::Buffer,
}

/// The step `settings.step` with the moment filter `settings.moment_filter` asks for.
pub(crate) fn build(
    gpu: &Gpu,
    set: &ParamSet,
    settings: &Settings,
    observed_map: &wgpu::Buffer,
    b: &StepBuffers,
) -> Result<Box<dyn Step>> {
    let mf = &settings.moment_filter;
    let filter = if mf.enabled() {
        // The variance step's second array is the variance of its estimate.
        let of_mean = settings.step == StepKind::Variance;
        Some(MomentFilter::new(
            gpu,
            set,
            (mf, of_mean),
            b.params,
            observed_map,
        )?)
    } else {
        None
    };
    Ok(match settings.step {
        StepKind::Adam => Box::new(adam::AdamPass::new(
            gpu,
            set,
            (settings.adam, settings.adam_mask),
            filter,
            b,
        )?),
        StepKind::Variance => Box::new(variance_step::VarianceStepPass::new(
            gpu,
            set,
            (settings.variance_step, settings.adam_mask),
            filter,
            b,
        )?),
    })
}

/// A step pass (Adam or the variance-scaled step) over every optimized texture: per texture
/// one dispatch (phase [`step_phase::FUSED`]), or with the moment filter two around it
/// ([`step_phase::PAIR`], the filter's levels, [`step_phase::FILTERED`]), each with its
/// uniform, bind group and parameters.
pub(crate) struct TextureSteps<P> {
    label: &'static str,
    step: StepKind,
    pipeline: wgpu::ComputePipeline,
    textures: Vec<Vec<(wgpu::Buffer, wgpu::BindGroup, P)>>,
    pub(crate) filter: Option<MomentFilter>,
}

impl<P: bytemuck::Pod> TextureSteps<P> {
    /// The dispatches of pass `label` for every texture of `set`: `make` gives a texture's
    /// parameters in a phase, `bind` the bind group of a uniform with the filter's pair (a
    /// small unused pair without the filter).
    pub(crate) fn new(
        gpu: &Gpu,
        label: &'static str,
        step: StepKind,
        pipeline: wgpu::ComputePipeline,
        set: &ParamSet,
        filter: Option<MomentFilter>,
        make: impl Fn(&ParamTexture, u32) -> P,
        bind: impl Fn(&str, &wgpu::Buffer, &[wgpu::Buffer; 2]) -> wgpu::BindGroup,
    ) -> TextureSteps<P> {
        let unused = || {
            [
                gpu.storage_zeroed(&format!("{label} unused pair first"), 16),
                gpu.storage_zeroed(&format!("{label} unused pair second"), 16),
            ]
        };
        let phases: Vec<(u32, [wgpu::Buffer; 2])> = match &filter {
            None => vec![(step_phase::FUSED, unused())],
            Some(f) => vec![
                (step_phase::PAIR, f.input().clone()),
                (step_phase::FILTERED, f.output().clone()),
            ],
        };
        let textures = set
            .textures
            .iter()
            .map(|t| {
                phases
                    .iter()
                    .map(|(phase, pair)| {
                        let p = make(t, *phase);
                        let name = format!("{label} params {} phase {phase}", t.name());
                        let u = gpu.uniform(&name, bytemuck::bytes_of(&p));
                        (u.clone(), bind(label, &u, pair), p)
                    })
                    .collect()
            })
            .collect();
        TextureSteps {
            label,
            step,
            pipeline,
            textures,
            filter,
        }
    }

    /// Record the step of every texture: `prepare` sets a texture's uniform for the learning
    /// rate it is given (the texture's rate times `factor`) and returns its number of
    /// entries. Returns the learning rates used, one per texture.
    pub(crate) fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        set: &ParamSet,
        factor: f32,
        timer: &mut PassTimer,
        mut prepare: impl FnMut(&mut P, f32) -> u32,
    ) -> Vec<f32> {
        let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
        let mut rates = Vec::with_capacity(self.textures.len());
        for (k, (dispatches, tex)) in self.textures.iter_mut().zip(&set.textures).enumerate() {
            let lr = crate::optim::auto::texture_rate(tex, self.step) * factor;
            rates.push(lr);
            for (j, (u, g, p)) in dispatches.iter_mut().enumerate() {
                let count = prepare(p, lr);
                gpu.queue.write_buffer(u, 0, bytemuck::bytes_of(p));
                let grid = grid_2d(count, WORKGROUP, max_dim);
                let timing = timer.next(PassKind::Step);
                encode_timed_pass(enc, self.label, &self.pipeline, &[g], grid, timing);
                if let (0, Some(f)) = (j, &self.filter) {
                    f.encode(enc, k, timer);
                }
            }
        }
        rates
    }
}
