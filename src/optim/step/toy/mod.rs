//! A toy step, compiled for the tests only: it shows that a step is its folder and one
//! entry of the registry. It is plain gradient descent, each parameter scalar moved by
//! −lr × its gradient (`toy_step.wgsl`; its CPU path for the parameter table's CPU groups),
//! with the learning rate `scale` times the texture's.
//! The test runs it through the optimizer with the toy estimator, its options read from a
//! task file's `[optimizer.toy_step]` table.
use super::{Kind, Options, OptionsKind, Setup, Step, StepKind, TextureSteps};
use crate::gpu::{Gpu, GroupDecl};
use crate::optim::PassTimer;
use crate::render::params::{ParamSet, ParamTexture};
use crate::Result;
use bytemuck::{Pod, Zeroable};

/// The toy step as the registry knows it.
pub const KIND: Kind = Kind {
    name: "toy",
    summary: "a test's toy: plain gradient descent",
    table: "toy_step",
    options: OptionsKind::of::<ToyStepOptions>(),
    pass: "toy_step",
    wgsl: &[("toy_step", include_str!("toy_step.wgsl"))],
    groups: &[TOY_STEP_GROUP],
    learning_rate: |_| 0.1,
    first_moment: false,
    divides_by_variance: false,
    tuned_before_filter: false,
    second_moment_decay: |_| None,
    if_not_converging: "try a lower learning rate",
    cpu: Some(|steps, g| {
        let lr = g.lr * steps.of::<ToyStepOptions>().scale;
        for (v, d) in g.values.iter_mut().zip(g.grad) {
            if d.is_finite() {
                *v = (*v - lr * d).clamp(g.range.0, g.range.1);
            }
        }
    }),
    build: |s| Ok(Box::new(ToyStep::new(s)?)),
};

/// Group 0 of `toy_step.wgsl`.
const TOY_STEP_GROUP: GroupDecl = GroupDecl {
    pass: "toy_step",
    group: 0,
    names: &["tsp", "grad", "params"],
};

/// The toy step's options (`[optimizer.toy_step]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ToyStepOptions {
    /// The factor of every texture's learning rate (> 0).
    pub scale: f32,
}

impl Default for ToyStepOptions {
    fn default() -> Self {
        ToyStepOptions { scale: 1.0 }
    }
}

impl Options<super::StepFamily> for ToyStepOptions {
    const KIND: &'static Kind = &KIND;

    fn check(&self) -> std::result::Result<(), (String, String)> {
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(("scale".into(), "must be a positive number".into()));
        }
        Ok(())
    }
}

/// `ToyStepParams` in toy_step.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct ToyStepParams {
    offset: u32,
    count: u32,
    lr: f32,
    lo: f32,
    hi: f32,
    _pad: [u32; 3],
}

struct ToyStep {
    steps: TextureSteps<ToyStepParams>,
    scale: f32,
}

impl ToyStep {
    fn new(s: Setup) -> Result<ToyStep> {
        if s.filter.is_some() {
            return Err(crate::Error::Invalid(
                "the toy step takes no moment filter".into(),
            ));
        }
        let (gpu, b) = (s.gpu, s.buffers);
        let layout = gpu.pass_layout("toy_step", 0)?;
        let pipeline = gpu.compute_pipeline("toy_step", &[&layout])?;
        let make = |t: &ParamTexture, _phase: u32| {
            let (lo, hi) = t.slot.range();
            ToyStepParams {
                offset: t.offset,
                count: t.len() as u32,
                lo,
                hi,
                ..Default::default()
            }
        };
        let bind = |label: &str, u: &wgpu::Buffer, _pair: &[wgpu::Buffer; 2]| {
            gpu.bind(
                &TOY_STEP_GROUP,
                label,
                &layout,
                &[("tsp", u), ("grad", b.grad), ("params", b.params)],
            )
        };
        let kind = StepKind::by_name(KIND.name).expect("the toy step is registered");
        let steps = TextureSteps::new(gpu, kind, pipeline, s.set, None, make, bind);
        Ok(ToyStep {
            steps,
            scale: s.steps.of::<ToyStepOptions>().scale,
        })
    }
}

impl Step for ToyStep {
    fn encode(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        set: &ParamSet,
        factor: f32,
        _t: u32,
        timer: &mut PassTimer,
    ) -> Vec<f32> {
        let scale = self.scale;
        self.steps.encode(gpu, enc, set, factor * scale, timer, |p, lr| {
            p.lr = lr;
            p.count
        })
    }

    fn filter(&self) -> Option<&super::moment_filter::MomentFilter> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract_tests::mirror;
    use crate::optim::plane_tests::run_on_plane;
    use crate::optim::Method;
    use crate::task::OptimizerSpec;

    #[test]
    fn uniform_mirror_matches_wgsl() {
        mirror!(
            "toy_step",
            "ToyStepParams",
            ToyStepParams,
            [offset, count, lr, lo, hi]
        );
    }

    /// Found by name from a task file's `step`, its options read from the file's table,
    /// built, compiled and run by the optimizer after the toy estimator, whose gradient
    /// θ − 0.125 pulls every texel toward 0.125: gradient descent at 0.01 × scale 10 takes
    /// each texel from 0.5 to 0.125 + 0.375 × 0.9^t after t steps, exactly (Adam would move
    /// it by about 0.01 per step instead).
    #[test]
    fn a_folder_and_a_registry_entry_make_a_step() {
        let spec = |table: &str| -> OptimizerSpec { toml::from_str(table).unwrap() };
        let bad = spec("step = \"toy\"\n[toy_step]\nscale = 0.0")
            .step_options()
            .unwrap_err();
        assert_eq!(bad.0, "optimizer.toy_step.scale", "{bad:?}");
        let unknown = spec("[toy_step]\nscael = 2.0").step_options().unwrap_err();
        assert!(unknown.1.contains("scael"), "{unknown:?}");
        let task = spec("step = \"toy\"\n[toy_step]\nscale = 10.0");
        let step = task.step.unwrap();
        assert_eq!(step.kind().summary, KIND.summary);
        let steps = task.step_options().unwrap();
        let t = 20;
        let values = run_on_plane(t, |settings| {
            settings.method = "toy".parse::<Method>().unwrap();
            settings
                .estimator_options
                .assign("toy.target=0.125")
                .unwrap();
            settings.step = step;
            settings.steps = steps;
        });
        let expected = 0.125 + 0.375 * 0.9f32.powi(t as i32);
        for v in values {
            assert!((v - expected).abs() < 1e-4, "{v} against {expected}");
        }
    }
}
