//! The recursive estimator: a recursive control variate on the gradient (STORM, Cutkosky and
//! Orabona 2019; in inverse rendering Bálint et al. 2023). Every iteration draws fresh
//! samples as the baseline does and evaluates each twice, at the current state (textures and
//! adjoint) and at the previous one, with the same hit, light and BSDF samples and the
//! current state's density (`recursive_gradient.wgsl`; no extra ray). The running estimate
//!
//! d_t = a g_t(θ_t) + (1 − a) (d_{t−1} + g_t(θ_t) − g_t(θ_{t−1}))
//!
//! keeps the whole previous estimate and corrects it by how the same samples changed
//! (`recursive_combine.wgsl`). From an unbiased start it stays unbiased for a constant a (the
//! adaptive a, computed from earlier iterations only, leaves a second-order bias through its
//! correlation with the previous estimate's error); its variance falls with the memory 1/a
//! while the difference term stays small, which the control-variate primal (a slowly
//! changing adjoint) helps. By default a is chosen per parameter scalar by inverse variance from
//! moving variances of the fresh term and of the difference, tracked up to the previous
//! iteration, with the running estimate's own variance carried along; that variance is what
//! the variance-scaled step divides by.
//!
//! This folder holds the estimator whole: its Rust, its two WGSL passes, its part of the GPU
//! contract (generated into WGSL as `gen/recursive`), its options and its counters.
use super::{Diagnostics, Estimator, EstimatorState, Frame, Kind, Method, OptionsKind, Setup};
use crate::gpu::{encode_timed_pass, grid_2d, Gpu};
use crate::optim::{pass_seed, FaultCounts, PassKind, PassTimer, Scale, Seeds};
use crate::render::layout::GpuCameraInfo;
use crate::render::WORKGROUP;
use crate::{Error, Result};
use bytemuck::{Pod, Zeroable};

/// The recursive estimator as the registry knows it.
pub const KIND: Kind = Kind {
    name: "recursive",
    summary: "a recursive control variate: each sample at the current and the previous state \
              corrects a running estimate",
    options: OptionsKind::of::<RecursiveOptions>(),
    wgsl: &[
        (
            "recursive_gradient",
            include_str!("recursive_gradient.wgsl"),
        ),
        ("recursive_combine", include_str!("recursive_combine.wgsl")),
    ],
    generated: &[("gen/recursive", abi::wgsl)],
    groups: &[GRADIENT_GROUP, COMBINE_GROUP],
    passes: |_| vec!["recursive_gradient", "recursive_combine"],
    max_cameras: None,
    memory: |sizes, _| memory(sizes.params),
    warnings: super::no_warnings,
    every_texel: super::observed_only,
    build: |setup| Ok(Box::new(Recursive::new(setup)?)),
};

/// The GPU contract of this estimator: constants that its Rust and WGSL share.
pub mod abi {
    /// `rstats` slot: gradient samples drawn.
    pub const STAT_SAMPLES: u32 = 0;
    /// `rstats` slot: additions lost (compare-and-swap bound exhausted).
    pub const STAT_LOST: u32 = 1;
    /// `rstats` slot: non-finite values dropped.
    pub const STAT_DROPPED: u32 = 2;
    /// Updates of the fresh term's moments before the adaptive weight is used (a = 1 until
    /// then: its variances are not known yet).
    pub const WARMUP: u32 = 4;

    /// (WGSL name, value) of every constant.
    pub const CONSTANTS: &[(&str, u32)] = &[
        ("RECURSIVE_STAT_SAMPLES", STAT_SAMPLES),
        ("RECURSIVE_STAT_LOST", STAT_LOST),
        ("RECURSIVE_STAT_DROPPED", STAT_DROPPED),
        ("RECURSIVE_WARMUP", WARMUP),
    ];

    /// The WGSL of `gen/recursive`.
    pub fn wgsl() -> String {
        crate::gpu::shaders::constants_wgsl("src/optim/estimator/recursive/mod.rs", CONSTANTS)
    }
}

/// The recursive estimator's options (the task file's `[optimizer.recursive]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecursiveOptions {
    /// The weight a of the fresh term, in (0, 1] (1/a is the memory); None: chosen per
    /// parameter by inverse variance.
    pub weight: Option<f32>,
    /// Lower bound of the adaptive weight, in (0, 1].
    pub min_weight: f32,
    /// Decay of the moving variances, in [0, 1).
    pub beta: f32,
}

impl Default for RecursiveOptions {
    fn default() -> Self {
        RecursiveOptions {
            weight: None,
            min_weight: 0.05,
            beta: 0.9,
        }
    }
}

impl crate::optim::estimator::Options<crate::optim::estimator::EstimatorFamily> for RecursiveOptions {
    const KIND: &'static crate::optim::estimator::Kind = &KIND;
    const OPTIONAL: &'static [&'static str] = &["weight"];

    fn check(&self) -> std::result::Result<(), (String, String)> {
        let bad = |k: &str, m: &str| Err((k.to_string(), m.to_string()));
        if let Some(a) = self.weight {
            if !(a > 0.0 && a <= 1.0) {
                return bad("weight", "must be in (0, 1]");
            }
        }
        if !(self.min_weight > 0.0 && self.min_weight <= 1.0) {
            return bad("min_weight", "must be in (0, 1]");
        }
        if !(0.0..1.0).contains(&self.beta) {
            return bad("beta", "must be in [0, 1)");
        }
        Ok(())
    }

    fn describe(&self) -> String {
        match self.weight {
            Some(a) => format!("weight {a}"),
            None => format!("weight ≥ {}", self.min_weight),
        }
    }

    fn tuning(
        _: &crate::optim::estimator::TuningContext,
    ) -> Vec<crate::optim::estimator::TypedAxis<Self>> {
        tuning()
    }
}

/// What `bench --tune` searches for the recursive estimator: the lower bound of its adaptive
/// weight (0.2, 0.5).
fn tuning() -> Vec<crate::optim::estimator::TypedAxis<RecursiveOptions>> {
    vec![|b| {
        [0.2, 0.5]
            .map(|min_weight| RecursiveOptions { min_weight, ..*b })
            .to_vec()
    }]
}

/// Group 1 of `recursive_gradient.wgsl`.
pub(crate) const GRADIENT_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "recursive_gradient",
    group: 1,
    names: &[
        "rp",
        "adjoint",
        "adjoint_prev",
        "grad",
        "grad_prev",
        "rstats",
        "env_grad",
    ],
};

/// Group 0 of `recursive_combine.wgsl`.
pub(crate) const COMBINE_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "recursive_combine",
    group: 0,
    names: &[
        "cp",
        "grad",
        "grad_prev",
        "running",
        "fresh_mean",
        "fresh_sq",
        "diff_mean",
        "diff_sq",
        "variance",
    ],
};

/// `RecursiveGradientParams` in recursive_gradient.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RecursiveGradientParams {
    pub camera: GpuCameraInfo,
    pub seed: u32,
    pub spp: u32,
    pub stride: u32,
    pub inv_spp: f32,
    pub adjoint_offset: u32,
    pub have_prev: u32,
    pub _pad: [u32; 2],
}

/// `RecursiveCombineParams` in recursive_combine.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RecursiveCombineParams {
    pub count: u32,
    pub have_prev: u32,
    pub fixed_weight: f32,
    pub min_weight: f32,
    pub beta: f32,
    pub bias_f: f32,
    pub bias_dl: f32,
    pub n_f: u32,
}

/// The arrays of state kept per parameter scalar, by label (also their checkpoint names).
const STATE: [&str; 6] = [
    "running",
    "fresh_mean",
    "fresh_sq",
    "diff_mean",
    "diff_sq",
    "variance",
];

/// The buffers the estimator allocates for `n_params` parameter scalars.
fn memory(n_params: u64) -> Vec<(String, u64, Scale)> {
    std::iter::once("grad_prev")
        .chain(STATE)
        .map(|l| (format!("recursive {l}"), 4 * n_params, Scale::Texel))
        .collect()
}

struct Camera {
    uniform: wgpu::Buffer,
    params: RecursiveGradientParams,
    /// Per parity of the iteration (the adjoint buffers alternate).
    groups: [wgpu::BindGroup; 2],
}

/// The recursive estimator's passes, buffers and counters.
pub(crate) struct Recursive {
    gradient: wgpu::ComputePipeline,
    combine: wgpu::ComputePipeline,
    cameras: Vec<Camera>,
    combine_uniform: wgpu::Buffer,
    combine_group: wgpu::BindGroup,
    combine_params: RecursiveCombineParams,
    grad: wgpu::Buffer,
    grad_prev: wgpu::Buffer,
    /// `STATE`'s buffers, in its order.
    state: Vec<wgpu::Buffer>,
    stats: wgpu::Buffer,
    grid: (u32, u32),
    combine_grid: (u32, u32),
    options: RecursiveOptions,
    /// Updates of the fresh term's and of the difference's moments so far.
    n_f: u32,
    n_dl: u32,
    /// Whether the running estimate holds a previous iteration's.
    have_prev: bool,
    queue: wgpu::Queue,
}

impl Recursive {
    pub(crate) fn new(s: &Setup) -> Result<Recursive> {
        let gpu = s.gpu;
        let options: RecursiveOptions = s
            
            .options
            .get()
            .map_err(|(key, msg)| crate::Error::Invalid(format!("{key} {msg}")))?;
        let layout = gpu.pass_layout("recursive_gradient", 1)?;
        let gradient = s.scene.pipeline(gpu, "recursive_gradient", &[&s.scene.layout, &layout])?;
        let combine_layout = gpu.pass_layout("recursive_combine", 0)?;
        let combine = gpu.compute_pipeline("recursive_combine", &[&combine_layout])?;
        let n_params = s.set.values.len() as u64;
        let stats = gpu.storage_zeroed("recursive stats", 16);
        let grad_prev = gpu.storage_zeroed("recursive grad_prev", 4 * n_params);
        let state: Vec<wgpu::Buffer> = STATE
            .iter()
            .map(|l| gpu.storage_zeroed(&format!("recursive {l}"), 4 * n_params))
            .collect();
        let n_pixels = s.width * s.height;
        let cameras = s
            .cameras
            .iter()
            .enumerate()
            .map(|(k, &camera)| {
                let params = RecursiveGradientParams {
                    camera,
                    spp: s.gradient_spp,
                    stride: s.grid.0 * WORKGROUP,
                    inv_spp: 1.0 / s.gradient_spp as f32,
                    adjoint_offset: k as u32 * n_pixels,
                    ..Default::default()
                };
                let uniform = gpu.uniform(
                    &format!("recursive gradient params {k}"),
                    bytemuck::bytes_of(&params),
                );
                let groups = [0usize, 1].map(|p| {
                    gpu.bind(
                        &GRADIENT_GROUP,
                        "recursive_gradient",
                        &layout,
                        &[
                            ("rp", &uniform),
                            ("adjoint", &s.adjoint[p]),
                            ("adjoint_prev", &s.adjoint[1 - p]),
                            ("grad", s.grad),
                            ("grad_prev", &grad_prev),
                            ("rstats", &stats),
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
        let combine_params = RecursiveCombineParams {
            count: n_params as u32,
            fixed_weight: options.weight.unwrap_or(-1.0),
            min_weight: options.min_weight,
            beta: options.beta,
            ..Default::default()
        };
        let combine_uniform = gpu.uniform(
            "recursive combine params",
            bytemuck::bytes_of(&combine_params),
        );
        let mut named: Vec<(&str, &wgpu::Buffer)> = vec![
            ("cp", &combine_uniform),
            ("grad", s.grad),
            ("grad_prev", &grad_prev),
        ];
        named.extend(STATE.iter().copied().zip(state.iter()));
        let combine_group = gpu.bind(&COMBINE_GROUP, "recursive_combine", &combine_layout, &named);
        let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
        Ok(Recursive {
            gradient,
            combine,
            cameras,
            combine_uniform,
            combine_group,
            combine_params,
            grad: s.grad.clone(),
            grad_prev,
            state,
            stats,
            grid: s.grid,
            combine_grid: grid_2d(n_params as u32, WORKGROUP, max_dim),
            options,
            n_f: 0,
            n_dl: 0,
            have_prev: false,
            queue: gpu.queue.clone(),
        })
    }

    /// 1 − beta^n.
    fn bias(&self, n: u32) -> f32 {
        1.0 - self.options.beta.powi(n.min(1 << 20) as i32)
    }
}

impl Estimator for Recursive {
    fn encode(&mut self, enc: &mut wgpu::CommandEncoder, frame: &Frame, timer: &mut PassTimer) {
        enc.clear_buffer(&self.grad, 0, None);
        enc.clear_buffer(&self.grad_prev, 0, None);
        let have_prev = self.have_prev as u32;
        for (k, cam) in self.cameras.iter_mut().enumerate() {
            // The baseline's seeds: with the same settings, the fresh term is its gradient.
            cam.params.seed = pass_seed(frame.seed, frame.iteration, k as u32, Seeds::GRADIENT);
            cam.params.have_prev = have_prev;
            self.queue
                .write_buffer(&cam.uniform, 0, bytemuck::bytes_of(&cam.params));
            encode_timed_pass(
                enc,
                "recursive_gradient",
                &self.gradient,
                &[frame.scene_group, &cam.groups[frame.parity()]],
                self.grid,
                timer.next(PassKind::Gradient),
            );
        }
        self.combine_params.have_prev = have_prev;
        self.combine_params.bias_f = self.bias(self.n_f);
        self.combine_params.bias_dl = self.bias(self.n_dl);
        self.combine_params.n_f = self.n_f;
        self.queue.write_buffer(
            &self.combine_uniform,
            0,
            bytemuck::bytes_of(&self.combine_params),
        );
        encode_timed_pass(
            enc,
            "recursive_combine",
            &self.combine,
            &[&self.combine_group],
            self.combine_grid,
            timer.next(PassKind::Combine),
        );
        self.n_f = self.n_f.saturating_add(1);
        self.n_dl = self.n_dl.saturating_add(have_prev);
        self.have_prev = true;
    }

    fn uses_previous_state(&self) -> bool {
        true
    }

    fn faults(&self, gpu: &Gpu, f: &mut FaultCounts) -> Result<()> {
        let g: Vec<u32> = gpu.read_pod(&self.stats)?;
        f.lost_updates += g[abi::STAT_LOST as usize];
        f.dropped_gradient += g[abi::STAT_DROPPED as usize];
        Ok(())
    }

    fn snapshot(&self, gpu: &Gpu, _iteration: u32) -> Result<EstimatorState> {
        let mut s = EstimatorState::new(Method::RECURSIVE);
        s.counters = vec![
            ("fresh_updates".into(), self.n_f),
            ("diff_updates".into(), self.n_dl),
            ("have_prev".into(), self.have_prev as u32),
        ];
        for (name, buf) in STATE.iter().zip(&self.state) {
            s.arrays.push((name.to_string(), gpu.read_pod(buf)?));
        }
        Ok(s)
    }

    fn restore(&mut self, gpu: &Gpu, state: Option<&EstimatorState>, _: u32) -> Result<()> {
        let state = state.filter(|s| !s.arrays.is_empty());
        let Some(state) = state else {
            // Start afresh: the next iteration's estimate is its fresh term.
            let mut enc = gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("recursive reset"),
                });
            for b in &self.state {
                enc.clear_buffer(b, 0, None);
            }
            gpu.queue.submit([enc.finish()]);
            self.n_f = 0;
            self.n_dl = 0;
            self.have_prev = false;
            return gpu.check("recursive reset");
        };
        let counter = |name: &str| {
            state.counter(name).ok_or_else(|| {
                Error::Invalid(format!(
                    "the saved recursive estimator state has no counter {name}"
                ))
            })
        };
        let (n_f, n_dl, have_prev) = (
            counter("fresh_updates")?,
            counter("diff_updates")?,
            counter("have_prev")?,
        );
        for (name, buf) in STATE.iter().zip(&self.state) {
            let a = state.array(name).ok_or_else(|| {
                Error::Invalid(format!("the saved recursive estimator state has no {name}"))
            })?;
            if a.len() as u64 * 4 != buf.size() {
                return Err(Error::Invalid(format!(
                    "the saved recursive estimator state's {name} has {} values, the \
                     textures have {}",
                    a.len(),
                    buf.size() / 4
                )));
            }
        }
        for (name, buf) in STATE.iter().zip(&self.state) {
            if let Some(a) = state.array(name) {
                gpu.queue.write_buffer(buf, 0, bytemuck::cast_slice(a));
            }
        }
        self.n_f = n_f;
        self.n_dl = n_dl;
        self.have_prev = have_prev != 0;
        gpu.check("recursive restore")
    }

    fn state_bytes(&self) -> u64 {
        self.grad_prev.size() + self.state.iter().map(|b| b.size()).sum::<u64>()
    }

    fn variance(&self) -> Option<&wgpu::Buffer> {
        self.state.last()
    }

    fn diagnostics(&self, gpu: &Gpu) -> Result<Diagnostics> {
        let g: Vec<u32> = gpu.read_pod(&self.stats)?;
        Ok(vec![
            ("samples", g[abi::STAT_SAMPLES as usize] as f64),
            ("fresh updates", self.n_f as f64),
            ("difference updates", self.n_dl as f64),
        ])
    }
}

#[cfg(test)]
mod contract_tests {
    use crate::contract_tests::mirror;

    // Its uniforms, field by field against naga's layout of its WGSL.
    #[test]
    fn uniform_mirrors_match_wgsl_field_by_field() {
        mirror!(
            "recursive_gradient",
            "RecursiveGradientParams",
            super::RecursiveGradientParams,
            [
                camera,
                seed,
                spp,
                stride,
                inv_spp,
                adjoint_offset,
                have_prev
            ]
        );
        mirror!(
            "recursive_combine",
            "RecursiveCombineParams",
            super::RecursiveCombineParams,
            [
                count,
                have_prev,
                fixed_weight,
                min_weight,
                beta,
                bias_f,
                bias_dl,
                n_f
            ]
        );
    }
}
