//! The contract between the optimizer and a step: what a folder exports ([`Kind`]), the
//! handle and option tables that name it ([`StepKind`], [`Steps`]), what it is built from
//! ([`Setup`]), the [`Step`] trait it is driven through, and the per-texture dispatch the
//! steps share ([`TextureSteps`]).
use super::moment_filter::{self, MomentFilter};
use crate::gpu::abi::step_phase;
use crate::gpu::{encode_timed_pass, grid_2d, Gpu, GroupDecl};
use crate::optim::registry::{self, Handle, Tables};
use crate::optim::timing::{PassKind, PassTimer};
use crate::render::params::{ParamSet, ParamTexture};
use crate::render::WORKGROUP;
use crate::vocab::Slot;
use crate::Result;

/// A step as its folder exports it: everything the rest of the crate knows of it.
pub struct Kind {
    /// The name used on the command line (`--step`), in task files (`optimizer.step`) and in
    /// reports.
    pub name: &'static str,
    /// What it does, in one line.
    pub summary: &'static str,
    /// Its options' table: the task file's `[optimizer.<table>]`.
    pub table: &'static str,
    /// Its options.
    pub options: OptionsKind,
    /// Its pass (WGSL file), which names it in timings and tests.
    pub pass: &'static str,
    /// Its WGSL files: (name, source).
    pub wgsl: &'static [(&'static str, &'static str)],
    /// Its bind-group declarations (checked against its WGSL by the contract test).
    pub groups: &'static [GroupDecl],
    /// The learning rate of a texture of a slot that names none.
    pub learning_rate: fn(Slot) -> f32,
    /// Whether it keeps a first moment, which the moment filter may write back.
    pub first_moment: bool,
    /// Whether it divides by the variance of its estimate: the estimator's own where the
    /// estimator keeps one (and the priors keep it), otherwise a moving variance. The moment
    /// filter then filters that variance as the variance of a mean.
    pub divides_by_variance: bool,
    /// Whether `bench --tune` searches its options before the moment filter's (the variance
    /// step: its clip and threshold set what the filter's pair is divided into) or after
    /// them (Adam: its decays, whose β1 candidates depend on the filter).
    pub tuned_before_filter: bool,
    /// The decay of the moving second moment it keeps in the optimizer's second moment
    /// buffer, with its options (None: it keeps none, and no uncertainty can be read).
    pub second_moment_decay: fn(&Steps) -> Option<f32>,
    /// What to try when a run with it does not converge (the loss watch's advice).
    pub if_not_converging: &'static str,
    /// Its CPU path, which moves the parameter table's CPU groups (the environment, the
    /// cameras' gains); None: the table steps them with Adam's.
    pub cpu: Option<fn(&Steps, CpuGroup)>,
    pub(crate) build: fn(Setup) -> Result<Box<dyn Step>>,
}

/// A group of parameters a step moves on the CPU (one of the parameter table's), with its
/// state: step number `t` (from 1), learning rate `lr` (the schedule's factor included) and
/// the range it clamps `values` to. A value whose gradient is not finite keeps its value and
/// state.
pub struct CpuGroup<'a> {
    /// What the step moves.
    pub values: &'a mut [f32],
    /// Its first per-value state (Adam's first moment).
    pub m1: &'a mut [f32],
    /// Its second per-value state (Adam's second moment).
    pub m2: &'a mut [f32],
    /// The derivative of the loss with respect to each value.
    pub grad: &'a [f32],
    /// The step number, from 1.
    pub t: u32,
    /// The learning rate.
    pub lr: f32,
    /// The range the values are clamped to.
    pub range: (f32, f32),
}

/// The steps as the generic registry sees them.
pub struct StepFamily;

/// What the registry knows of a step's options without their type.
pub type OptionsKind = registry::OptionsKind<StepFamily>;

/// Which step the optimizer takes with the gradient estimate (the task file's
/// `optimizer.step`, the command line's `--step`): a handle on its [`Kind`] in the
/// [`REGISTRY`](super::REGISTRY). The default is the registry's first, Adam.
pub type StepKind = Handle<StepFamily>;

/// Every step's options, one table per step's table name: the task file's
/// `[optimizer.adam]`, `[optimizer.variance_step]`, ... Each step reads its own
/// ([`Options`](super::Options)); the tables of the steps not chosen are checked all the same.
pub type Steps = Tables<StepFamily>;

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

/// What a step is built from.
pub(crate) struct Setup<'a> {
    pub gpu: &'a Gpu,
    pub set: &'a ParamSet,
    /// Every step's options (the step reads its own table).
    pub steps: &'a Steps,
    /// Masked updates: an entry whose gradient is exactly zero keeps its value and state.
    pub mask: bool,
    /// The moment filter, when the settings ask for one.
    pub filter: Option<MomentFilter>,
    pub buffers: &'a StepBuffers<'a>,
}

/// What a run chooses of its step: which, every step's options, whether an entry whose
/// gradient is exactly zero keeps its value and state, and the moment filter.
pub(crate) struct StepChoice<'a> {
    pub kind: StepKind,
    pub steps: &'a Steps,
    pub sparse: bool,
    pub moment_filter: &'a moment_filter::MomentFilterOptions,
}

/// A step's pass over every optimized texture: per texture
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
    /// The dispatches of `step`'s pass for every texture of `set`: `make` gives a texture's
    /// parameters in a phase, `bind` the bind group of a uniform (labelled by the pass) with
    /// the filter's pair (a small unused pair without the filter).
    pub(crate) fn new(
        gpu: &Gpu,
        step: StepKind,
        pipeline: wgpu::ComputePipeline,
        set: &ParamSet,
        filter: Option<MomentFilter>,
        make: impl Fn(&ParamTexture, u32) -> P,
        bind: impl Fn(&str, &wgpu::Buffer, &[wgpu::Buffer; 2]) -> wgpu::BindGroup,
    ) -> TextureSteps<P> {
        let label = step.kind().pass;
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
            let lr = self.step.texture_rate(tex) * factor;
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
