//! A toy prior, compiled for the tests only: it shows that a prior is its folder and one
//! entry of the registry. It adds the gradient of ½ weight (θ − target)² to every parameter
//! scalar θ's (`toy_prior.wgsl`). The test runs it through the optimizer with the toy
//! estimator, its options read from a task file's `[optimizer.toy_prior]` table.
use super::{Kind, Options, OptionsKind, Prior, Setup};
use crate::gpu::{encode_timed_pass, grid_2d, Gpu, GroupDecl};
use crate::optim::{PassKind, PassTimer};
use crate::Result;
use bytemuck::{Pod, Zeroable};

/// The toy prior as the registry knows it.
pub const KIND: Kind = Kind {
    name: "toy_prior",
    summary: "a test's toy: a pull of every parameter toward a constant",
    options: OptionsKind::of::<ToyPriorOptions>(),
    shorthand: None,
    pass: "toy_prior",
    keeps_variance: true,
    wgsl: &[("toy_prior", include_str!("toy_prior.wgsl"))],
    groups: &[TOY_PRIOR_GROUP],
    build: |s, priors| Ok(Box::new(ToyPrior::new(s, priors.of())?)),
};

/// Group 0 of `toy_prior.wgsl`.
const TOY_PRIOR_GROUP: GroupDecl = GroupDecl {
    pass: "toy_prior",
    group: 0,
    names: &["tp", "grad", "params"],
};

/// The toy prior's options (`[optimizer.toy_prior]`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ToyPriorOptions {
    /// The value every parameter is pulled toward.
    pub target: f32,
    /// The pull's weight (0: off).
    pub weight: f32,
}

impl Options<super::PriorFamily> for ToyPriorOptions {
    const KIND: &'static Kind = &KIND;

    fn check(&self) -> std::result::Result<(), (String, String)> {
        if !(0.0..=1.0).contains(&self.target) {
            return Err(("target".into(), "must be in [0, 1]".into()));
        }
        if !(self.weight >= 0.0) {
            return Err(("weight".into(), "must be 0 (off) or more".into()));
        }
        Ok(())
    }

    fn on(&self) -> bool {
        self.weight > 0.0
    }

    fn describe(&self) -> String {
        format!("toy prior toward {}", self.target)
    }
}

/// `ToyPriorParams` in toy_prior.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct ToyPriorParams {
    n: u32,
    stride: u32,
    target_value: f32,
    weight: f32,
}

struct ToyPrior {
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    grid: (u32, u32),
}

impl ToyPrior {
    fn new(s: &Setup, options: ToyPriorOptions) -> Result<ToyPrior> {
        let gpu = s.gpu;
        let layout = gpu.pass_layout("toy_prior", 0)?;
        let pipeline = gpu.compute_pipeline("toy_prior", &[&layout])?;
        let n = s.set.values.len() as u32;
        let grid = grid_2d(n, 64, 65535);
        let params = ToyPriorParams {
            n,
            stride: grid.0 * 64,
            target_value: options.target,
            weight: options.weight,
        };
        let uniform = gpu.uniform("toy_prior params", bytemuck::bytes_of(&params));
        let group = gpu.bind(
            &TOY_PRIOR_GROUP,
            "toy_prior",
            &layout,
            &[("tp", &uniform), ("grad", s.grad), ("params", s.params)],
        );
        Ok(ToyPrior {
            pipeline,
            group,
            grid,
        })
    }
}

impl Prior for ToyPrior {
    fn encode(
        &mut self,
        _gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        _seed: u32,
        _iteration: u32,
        timer: &mut PassTimer,
    ) {
        let timing = timer.next(PassKind::Prior);
        encode_timed_pass(enc, "toy_prior", &self.pipeline, &[&self.group], self.grid, timing);
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
            "toy_prior",
            "ToyPriorParams",
            ToyPriorParams,
            [n, stride, target_value, weight]
        );
    }

    /// Found by name, its options read from a task file's table, built, compiled and run by
    /// the optimizer after the toy estimator: the toy estimator pulls every texel toward
    /// 0.125 and the prior, with the same weight, toward 0.625, so every texel ends halfway.
    #[test]
    fn a_folder_and_a_registry_entry_make_a_prior() {
        assert_eq!(super::super::Kind::by_name("toy_prior").unwrap().summary, KIND.summary);
        let spec = |table: &str| -> OptimizerSpec { toml::from_str(table).unwrap() };
        let bad = spec("[toy_prior]\ntarget = 2.0").prior_options().unwrap_err();
        assert_eq!(bad.0, "optimizer.toy_prior.target", "{bad:?}");
        let unknown = spec("[toy_prior]\ntarjet = 0.5").prior_options().unwrap_err();
        assert!(unknown.1.contains("tarjet"), "{unknown:?}");
        let priors = spec("[toy_prior]\ntarget = 0.625\nweight = 1.0")
            .prior_options()
            .unwrap();
        assert!(priors.describe_active().contains("toy prior toward 0.625"));
        let values = run_on_plane(120, |settings| {
            settings.method = "toy".parse::<Method>().unwrap();
            settings
                .estimator_options
                .assign("toy.target=0.125")
                .unwrap();
            settings.priors = priors;
        });
        for v in values {
            // Adam at 0.01 reaches the equilibrium in about 13 steps and then circles it by
            // about its rate.
            assert!((v - 0.375).abs() < 0.03, "{v}");
        }
    }
}
