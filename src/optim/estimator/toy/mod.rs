//! A toy estimator, compiled for the tests only: it shows that an estimator is its folder and
//! one entry of the registry. Its "gradient" is that of ½ weight (θ − target)² for every
//! parameter scalar θ (`toy_gradient.wgsl`), which reads no image, so an optimization with it
//! moves every texel to its `target` option. The test runs it through the optimizer by name,
//! with an option set as the command line sets one.
use super::{no_memory, no_warnings, Estimator, EstimatorState, Frame, Kind, Method};
use super::{Options, OptionsKind, Setup};
use crate::gpu::{encode_timed_pass, grid_2d, Gpu, GroupDecl};
use crate::optim::{FaultCounts, PassKind, PassTimer};
use crate::Result;
use bytemuck::{Pod, Zeroable};

/// The toy as the registry knows it.
pub const KIND: Kind = Kind {
    name: "toy",
    summary: "a test's toy: the gradient of a pull toward a constant",
    options: OptionsKind::of::<ToyOptions>(),
    wgsl: &[("toy_gradient", include_str!("toy_gradient.wgsl"))],
    generated: &[],
    groups: &[TOY_GROUP],
    passes: |_| vec!["toy_gradient"],
    max_cameras: None,
    memory: no_memory,
    warnings: no_warnings,
    every_texel: super::observed_only,
    build: |setup| Ok(Box::new(Toy::new(setup)?)),
};

/// Group 1 of `toy_gradient.wgsl`.
const TOY_GROUP: GroupDecl = GroupDecl {
    pass: "toy_gradient",
    group: 1,
    names: &["tp", "grad"],
};

/// The toy's options (`[optimizer.toy]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ToyOptions {
    /// The value every parameter is pulled toward.
    pub target: f32,
    /// The pull's weight.
    pub weight: f32,
}

impl Default for ToyOptions {
    fn default() -> Self {
        ToyOptions {
            target: 0.25,
            weight: 1.0,
        }
    }
}

impl Options<super::EstimatorFamily> for ToyOptions {
    const KIND: &'static Kind = &KIND;

    fn check(&self) -> std::result::Result<(), (String, String)> {
        if !(0.0..=1.0).contains(&self.target) {
            return Err(("target".into(), "must be in [0, 1]".into()));
        }
        if !(self.weight > 0.0) {
            return Err(("weight".into(), "must be above 0".into()));
        }
        Ok(())
    }

    fn describe(&self) -> String {
        format!("target {}", self.target)
    }
}

/// `ToyParams` in toy_gradient.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct ToyParams {
    n: u32,
    stride: u32,
    target_value: f32,
    weight: f32,
}

struct Toy {
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    grid: (u32, u32),
}

impl Toy {
    fn new(s: &Setup) -> Result<Toy> {
        let gpu = s.gpu;
        let options: ToyOptions = s
            
            .options
            .get()
            .map_err(|(k, m)| crate::Error::Invalid(format!("{k} {m}")))?;
        let layout = gpu.pass_layout("toy_gradient", 1)?;
        let pipeline = s.scene.pipeline(gpu, "toy_gradient", &[&s.scene.layout, &layout])?;
        let n = s.set.values.len() as u32;
        let grid = grid_2d(n, 64, 65535);
        let params = ToyParams {
            n,
            stride: grid.0 * 64,
            target_value: options.target,
            weight: options.weight,
        };
        let uniform = gpu.uniform("toy params", bytemuck::bytes_of(&params));
        let group = gpu.bind(
            &TOY_GROUP,
            "toy_gradient",
            &layout,
            &[("tp", &uniform), ("grad", s.grad)],
        );
        Ok(Toy {
            pipeline,
            group,
            grid,
        })
    }
}

impl Estimator for Toy {
    fn encode(&mut self, enc: &mut wgpu::CommandEncoder, frame: &Frame, timer: &mut PassTimer) {
        encode_timed_pass(
            enc,
            "toy_gradient",
            &self.pipeline,
            &[frame.scene_group, &self.group],
            self.grid,
            timer.next(PassKind::Gradient),
        );
    }

    fn uses_previous_state(&self) -> bool {
        false
    }

    fn faults(&self, _gpu: &Gpu, _f: &mut FaultCounts) -> Result<()> {
        Ok(())
    }

    fn snapshot(&self, _gpu: &Gpu, _iteration: u32) -> Result<EstimatorState> {
        Ok(EstimatorState::new(KIND_METHOD))
    }

    fn restore(&mut self, _: &Gpu, _: Option<&EstimatorState>, _: u32) -> Result<()> {
        Ok(())
    }

    fn state_bytes(&self) -> u64 {
        0
    }
}

const KIND_METHOD: Method = Method::of(&KIND);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract_tests::mirror;
    use crate::optim::plane_tests::run_on_plane;
    use crate::optim::EstimatorOptions;

    #[test]
    fn uniform_mirror_matches_wgsl() {
        mirror!(
            "toy_gradient",
            "ToyParams",
            ToyParams,
            [n, stride, target_value, weight]
        );
    }

    /// Found by name with its options, built, compiled and run by the optimizer: every texel
    /// ends at the option's target.
    #[test]
    fn a_folder_and_a_registry_entry_make_an_estimator() {
        let method: Method = "toy".parse().unwrap();
        assert_eq!(method.summary(), KIND.summary);
        let bad = EstimatorOptions::default().assign("toy.target=2");
        assert!(bad.unwrap_err().to_string().contains("target must be in [0, 1]"));
        let values = run_on_plane(120, |settings| {
            settings.method = method;
            settings
                .estimator_options
                .assign("toy.target=0.125")
                .unwrap();
        });
        for v in values {
            // Adam at 0.01 reaches the target in about 38 steps and then circles it by
            // about its rate.
            assert!((v - 0.125).abs() < 0.03, "{v}");
        }
    }
}
