//! Gradient estimators. Each one lives in its own module and owns its pipelines, bind groups,
//! buffers, GPU struct mirrors, memory plan, checkpoint state and fault counters; the
//! optimizer calls it through the `Estimator` trait once per iteration, after the primal render and
//! the loss have written every camera's adjoint.
//!
//! - [`baseline`]: plain Monte Carlo, every sample adds its derivative to the texels it
//!   touches (`gradient.wgsl`).
//! - [`restir`]: parameter-space ReSTIR, two reservoirs per texel reused across iterations
//!   (`restir_candidates.wgsl`, `restir_merge.wgsl`).
//! - [`recursive`]: a recursive control variate on the gradient: fresh samples evaluated at
//!   the current and the previous state correct the running estimate
//!   (`recursive_gradient.wgsl`, `recursive_combine.wgsl`).
//!
//! Each lives in its own folder with everything of its own: its Rust, its WGSL, its part of
//! the GPU contract (generated as `gen/<name>`), its uniforms' mirrors and their tests, and
//! its options ([`Options`], read from its table in [`EstimatorOptions`]). This module is the
//! registry, the one place that names each folder's items: [`Method`], `build`, `passes`,
//! `memory`, `max_cameras`, the options' checks and tuning, `WGSL` and `GENERATED`. Nothing
//! else names them (the seam test in `tests.rs` holds it), so that the optimizer, the CLI, task
//! files, checkpoints and the bench see a method's name and its options table only.
pub mod baseline;
mod choice;
pub mod recursive;
pub mod restir;

pub use choice::{
    rule as auto_rule, Choice, MethodChoice, Regime, DENSE_SAMPLES_PER_TEXEL,
    RESTIR_MAX_TEXELS_CHEAP_PRIMAL, RESTIR_PRIMAL_RATIO,
};

use super::{FaultCounts, PassTimer, Settings};
use crate::gpu::Gpu;
use crate::render::layout::GpuCameraInfo;
use crate::render::{GpuScene, Techniques};
use crate::Result;
use recursive::RecursiveOptions;
use restir::RestirOptions;

/// The gradient estimator. The library's default is the one that ends lower on the bundled
/// default task at equal time, each at its own best settings (docs/studies.md, "Which
/// estimator is the default"): on the machines measured so far, the baseline. Task files and
/// the command line default to [`MethodChoice::Auto`], which picks one by the task's regime.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Plain Monte Carlo: every candidate adds its value to the texels it touches.
    #[default]
    Baseline,
    /// Parameter-space ReSTIR.
    Restir,
    /// The recursive control variate on the gradient.
    Recursive,
}

impl Method {
    /// Every estimator, in the order reports list them.
    pub const ALL: [Method; 3] = [Method::Baseline, Method::Restir, Method::Recursive];

    /// The name used on the command line, in task files and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Baseline => "baseline",
            Method::Restir => "restir",
            Method::Recursive => "recursive",
        }
    }

    /// What it does, in one line.
    pub fn summary(self) -> &'static str {
        match self {
            Method::Baseline => {
                "plain Monte Carlo: every sample adds its derivative to the texels it touches"
            }
            Method::Restir => {
                "parameter-space ReSTIR: two reservoirs per observed texel reused across iterations"
            }
            Method::Recursive => {
                "a recursive control variate: each sample at the current and the previous \
                 state corrects a running estimate"
            }
        }
    }

    /// Every estimator's name.
    pub fn names() -> Vec<&'static str> {
        Method::ALL.iter().map(|m| m.name()).collect()
    }

    /// The estimator called `name`.
    pub fn by_name(name: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == name)
    }
}

impl std::str::FromStr for Method {
    type Err = crate::Error;
    fn from_str(s: &str) -> Result<Method> {
        Method::by_name(s).ok_or_else(|| {
            crate::Error::Invalid(format!(
                "unknown gradient estimator `{s}` (one of: {})",
                Method::names().join(", ")
            ))
        })
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// An estimator's options as its folder defines them: read from and written to that
/// estimator's table in [`EstimatorOptions`] (missing keys take their defaults).
pub trait Options:
    Clone + Default + serde::Serialize + serde::de::DeserializeOwned + std::fmt::Debug
{
    /// The estimator they belong to.
    const METHOD: Method;
    /// The options whose default is to be absent (an `Option` left `None`).
    const OPTIONAL: &'static [&'static str] = &[];
    /// An error naming the option (its key in the table) and what is wrong.
    fn check(&self) -> std::result::Result<(), (String, String)>;
    /// A short description for reports (empty: nothing to say), e.g. `M cap 8`.
    fn describe(&self) -> String;
}

/// Every estimator's options, one table of TOML values per method name: the task file's
/// `[optimizer.<method>]` tables, with the command line's `--estimator-option
/// METHOD.KEY=VALUE` on top. The optimizer, the job and the bench only pass the tables on;
/// each estimator reads its own ([`Options`]) and [`EstimatorOptions::check`] asks each to
/// check its table.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
#[serde(transparent)]
pub struct EstimatorOptions {
    tables: std::collections::BTreeMap<String, toml::Table>,
}

impl EstimatorOptions {
    /// Options with one estimator's table: `options`.
    pub fn with<T: Options>(options: &T) -> EstimatorOptions {
        let mut o = EstimatorOptions::default();
        o.put(options);
        o
    }

    /// `method`'s table (empty: every option at its default).
    pub fn table(&self, method: Method) -> toml::Table {
        self.tables.get(method.name()).cloned().unwrap_or_default()
    }

    /// Replace `method`'s table.
    pub fn set_table(&mut self, method: Method, table: toml::Table) {
        self.tables.insert(method.name().to_string(), table);
    }

    /// These tables with `over`'s options on top, option by option.
    pub fn merged(mut self, over: &EstimatorOptions) -> EstimatorOptions {
        for (name, table) in &over.tables {
            let mine = self.tables.entry(name.clone()).or_default();
            for (k, v) in table {
                mine.insert(k.clone(), v.clone());
            }
        }
        self
    }

    /// Set one option of `method`'s table.
    pub fn set(&mut self, method: Method, key: &str, value: toml::Value) {
        self.tables
            .entry(method.name().to_string())
            .or_default()
            .insert(key.to_string(), value);
    }

    /// Apply `METHOD.KEY=VALUE` (the value as TOML, or else as a string: `restir.m_cap=16`,
    /// `restir.confidence=candidates`).
    pub fn assign(&mut self, assignment: &str) -> Result<()> {
        let bad = |why: String| {
            crate::Error::Invalid(format!("--estimator-option `{assignment}`: {why}"))
        };
        let (path, value) = assignment
            .split_once('=')
            .ok_or_else(|| bad("expected METHOD.KEY=VALUE".into()))?;
        let (method, key) = path
            .trim()
            .split_once('.')
            .ok_or_else(|| bad("expected METHOD.KEY=VALUE".into()))?;
        let method = method.parse::<Method>().map_err(|e| bad(e.to_string()))?;
        let value = value.trim();
        let value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        self.set(method, key.trim(), value);
        self.check_one(method)
            .map_err(|(key, msg)| bad(format!("{key} {msg}")))
    }

    /// The options of `T`'s estimator, parsed from its table.
    pub fn get<T: Options>(&self) -> std::result::Result<T, (String, String)> {
        let key = format!("optimizer.{}", T::METHOD.name());
        let o = T::deserialize(toml::Value::Table(self.table(T::METHOD)))
            .map_err(|e| (key.clone(), e.to_string().trim().replace('\n', " ")))?;
        o.check().map_err(|(k, m)| (format!("{key}.{k}"), m))?;
        Ok(o)
    }

    /// Replace the table of `T`'s estimator by `options`.
    pub fn put<T: Options>(&mut self, options: &T) {
        let table = match toml::Value::try_from(options) {
            Ok(toml::Value::Table(t)) => t,
            _ => unreachable!("an estimator's options serialize to a table"),
        };
        self.set_table(T::METHOD, table);
    }

    /// Check `method`'s table: an error names the task-file key and what is wrong.
    pub fn check_one(&self, method: Method) -> std::result::Result<(), (String, String)> {
        match method {
            Method::Baseline => {
                let t = self.table(method);
                match t.keys().next() {
                    Some(k) => Err((
                        format!("optimizer.baseline.{k}"),
                        "is not an option: the baseline has none".into(),
                    )),
                    None => Ok(()),
                }
            }
            Method::Restir => self.get::<RestirOptions>().map(|_| ()),
            Method::Recursive => self.get::<RecursiveOptions>().map(|_| ()),
        }
    }

    /// Check every table.
    pub fn check(&self) -> std::result::Result<(), (String, String)> {
        for name in self.tables.keys() {
            let method = Method::by_name(name).ok_or_else(|| {
                (
                    format!("optimizer.{name}"),
                    format!("is no gradient estimator ({})", Method::names().join(", ")),
                )
            })?;
            self.check_one(method)?;
        }
        Ok(())
    }

    /// Every table as `METHOD.KEY=VALUE` assignments, comma-separated (`none` without any).
    pub fn summary(&self) -> String {
        let all: Vec<String> = self
            .tables
            .iter()
            .flat_map(|(m, t)| t.iter().map(move |(k, v)| format!("{m}.{k}={v}")))
            .collect();
        if all.is_empty() {
            "none".into()
        } else {
            all.join(", ")
        }
    }

    /// `method`'s options at their defaults, as the TOML of its task-file table (empty when
    /// it has none; options whose default is to be absent as comments).
    pub fn defaults_toml(method: Method) -> String {
        fn t<T: Options>() -> String {
            let mut s = toml::to_string(&T::default()).unwrap_or_default();
            for key in T::OPTIONAL {
                s.push_str(&format!("# {key} = ...  (absent by default)\n"));
            }
            s
        }
        match method {
            Method::Baseline => String::new(),
            Method::Restir => t::<RestirOptions>(),
            Method::Recursive => t::<RecursiveOptions>(),
        }
    }

    /// A short description of `method`'s options for reports (empty for none).
    pub fn describe(&self, method: Method) -> String {
        fn d<T: Options>(o: &EstimatorOptions) -> String {
            o.get::<T>().map(|t| t.describe()).unwrap_or_default()
        }
        match method {
            Method::Baseline => String::new(),
            Method::Restir => d::<RestirOptions>(self),
            Method::Recursive => d::<RecursiveOptions>(self),
        }
    }

    /// What `bench --tune` tries for `method`'s own options: for each option searched, in
    /// search order, a function from the best table so far to the tables to try.
    pub fn tuning(method: Method) -> Vec<TuningAxis> {
        match method {
            Method::Baseline => Vec::new(),
            Method::Restir => typed_axes(restir::tuning()),
            Method::Recursive => typed_axes(recursive::tuning()),
        }
    }
}

/// One option an estimator's search varies: the tables to try around the best so far.
pub type TuningAxis = Box<dyn Fn(&toml::Table) -> Vec<toml::Table>>;

/// An axis over typed options: the candidates a function of the options gives.
pub type TypedAxis<T> = fn(&T) -> Vec<T>;

fn typed_axes<T: Options + 'static>(axes: Vec<TypedAxis<T>>) -> Vec<TuningAxis> {
    axes.into_iter()
        .map(|axis| -> TuningAxis {
            Box::new(move |table: &toml::Table| {
                let mut o = EstimatorOptions::default();
                o.set_table(T::METHOD, table.clone());
                let best = o.get::<T>().unwrap_or_default();
                axis(&best)
                    .iter()
                    .map(|c| {
                        o.put(c);
                        o.table(T::METHOD)
                    })
                    .collect()
            })
        })
        .collect()
}

/// The part of an estimator's state that carries over to the next iteration, as the optimizer
/// and its checkpoints hold it without knowing the estimator: the method that wrote it (its
/// [`Method::name`]), named counters and named arrays of 32-bit words. Each estimator says
/// what its names mean and checks them when it restores.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EstimatorState {
    /// The [`Method::name`] of the estimator that wrote it.
    pub method: String,
    /// Named counters.
    pub counters: Vec<(String, u32)>,
    /// Named arrays of 32-bit words (floats are stored as their bits).
    pub arrays: Vec<(String, Vec<u32>)>,
}

impl EstimatorState {
    /// An empty state written by `method`.
    pub fn new(method: Method) -> EstimatorState {
        EstimatorState {
            method: method.name().to_string(),
            ..Default::default()
        }
    }

    /// The counter `name`, if the state has it.
    pub fn counter(&self, name: &str) -> Option<u32> {
        self.counters.iter().find(|(n, _)| n == name).map(|c| c.1)
    }

    /// The array `name`, if the state has it.
    pub fn array(&self, name: &str) -> Option<&[u32]> {
        self.arrays
            .iter()
            .find(|(n, _)| n == name)
            .map(|a| a.1.as_slice())
    }

    /// An error unless the state was written by `method`.
    pub fn check_method(&self, method: Method) -> Result<()> {
        if self.method == method.name() {
            return Ok(());
        }
        Err(crate::Error::Invalid(format!(
            "the saved state was written by the {} gradient estimator, not by {}; resume with \
             the same --method",
            self.method,
            method.name()
        )))
    }
}

/// Named values an estimator counted since it was made (for diagnostics and tests; see
/// [`restir::MergeDiagnostics`]).
pub type Diagnostics = Vec<(&'static str, f64)>;

/// What an estimator is built from: the optimizer's scene, images and shared buffers.
pub(crate) struct Setup<'a> {
    pub gpu: &'a Gpu,
    pub scene: &'a GpuScene,
    pub set: &'a crate::render::params::ParamSet,
    pub settings: &'a Settings,
    /// Camera constants of the task's cameras, in task order, at the task's image size.
    pub cameras: &'a [GpuCameraInfo],
    /// The adjoint images of all cameras, one after another; iteration t writes buffer t % 2
    /// (the other holds the previous iteration's).
    pub adjoint: &'a [wgpu::Buffer; 2],
    /// The gradient, laid out like the parameters.
    pub grad: &'a wgpu::Buffer,
    /// Workgroups of one camera's image in 8x8 tiles.
    pub grid: (u32, u32),
    /// Which texels the cameras observe (one flag per texel of all optimized textures).
    pub observed: &'a [bool],
}

/// What one iteration's encoding needs.
pub(crate) struct Frame<'a> {
    /// The iteration (seeds derive from it and from `seed`).
    pub iteration: u32,
    /// The seed whose streams the gradient samples draw from, mixed with the iteration
    /// ([`pass_seed`](crate::optim::pass_seed)): the settings' seed in an optimization, the
    /// caller's in [`Optimizer::backward`](crate::optim::Optimizer::backward).
    pub seed: u32,
    /// The scene bind group (group 0).
    pub scene_group: &'a wgpu::BindGroup,
    /// The learning-rate schedule's factor at this iteration (1 without a schedule).
    pub schedule_factor: f32,
}

impl Frame<'_> {
    /// Which of the double-buffered adjoints this iteration writes.
    pub fn parity(&self) -> usize {
        (self.iteration % 2) as usize
    }
}

/// A gradient estimator as the optimizer drives it.
pub(crate) trait Estimator: Send {
    /// Record the passes that turn the adjoint of every camera (in `adjoint[parity]`) into the
    /// gradient of iteration `frame.iteration`, in `grad`.
    fn encode(&mut self, enc: &mut wgpu::CommandEncoder, frame: &Frame, timer: &mut PassTimer);
    /// Called once the iteration's work is submitted.
    fn finish_iteration(&mut self) {}
    /// Whether the estimator reads the previous iteration's textures and adjoint (the
    /// optimizer then copies the textures before each Adam step).
    fn uses_previous_state(&self) -> bool;
    /// Add the estimator's counters of dropped or lost values to `f`.
    fn faults(&self, gpu: &Gpu, f: &mut FaultCounts) -> Result<()>;
    /// The state that carries over to the next iteration (for checkpoints), taken after
    /// `iteration` iterations.
    fn snapshot(&self, gpu: &Gpu, iteration: u32) -> Result<EstimatorState>;
    /// Restore a snapshot taken after `iteration` iterations (None, or a state without
    /// arrays: start afresh). The optimizer has checked that this estimator wrote it; an
    /// error when it was written for other textures or images.
    fn restore(&mut self, gpu: &Gpu, state: Option<&EstimatorState>, iteration: u32) -> Result<()>;
    /// Bytes of GPU state the estimator keeps besides the optimizer's.
    fn state_bytes(&self) -> u64;
    /// Which techniques the gradient samples use for area and environment lights (MIS unless
    /// set): a diagnostic, so that the tests can check that light-sampled and BSDF-sampled
    /// gradients agree. Estimators that cannot restrict their samples refuse.
    fn set_techniques(&mut self, techniques: Techniques) -> Result<()> {
        Err(crate::Error::Invalid(format!(
            "this estimator samples with MIS only; {techniques:?} is for the baseline"
        )))
    }
    /// The variance of each gradient scalar it wrote, laid out like the gradient, when the
    /// estimator tracks it (the variance-scaled step divides by its square root; without it
    /// the step tracks a moving variance of the gradient itself).
    fn variance(&self) -> Option<&wgpu::Buffer> {
        None
    }
    /// What the estimator counted since it was made (empty unless it counts something).
    fn diagnostics(&self, _gpu: &Gpu) -> Result<Diagnostics> {
        Ok(Vec::new())
    }
    /// Which of its [`Estimator::diagnostics`] are counters (they rise by the work of each
    /// iteration, so that a rate per iteration means something; 32 bits on the GPU, they may
    /// wrap); the others are levels.
    fn counters(&self) -> &'static [&'static str] {
        &[]
    }
}

/// The estimator of `settings.method`.
pub(crate) fn build(setup: &Setup) -> Result<Box<dyn Estimator>> {
    Ok(match setup.settings.method {
        Method::Baseline => Box::new(baseline::Baseline::new(setup)?),
        Method::Restir => Box::new(restir::Restir::new(setup)?),
        Method::Recursive => Box::new(recursive::Recursive::new(setup)?),
    })
}

/// Every estimator's WGSL files: (name, source), a pass named after its file, another module
/// as `<method>/<file stem>` (what `#import` names).
pub(crate) const WGSL: [&[(&str, &str)]; 3] = [baseline::WGSL, restir::WGSL, recursive::WGSL];

/// The WGSL the estimators generate from their Rust (`gen/<method>`).
pub(crate) const GENERATED: &[(&str, crate::gpu::shaders::Generator)] = &[
    ("gen/restir", restir::abi::wgsl),
    ("gen/recursive", recursive::abi::wgsl),
];

/// Every estimator's bind-group declarations (for the contract test).
#[cfg(test)]
pub(crate) fn groups() -> Vec<crate::gpu::GroupDecl> {
    [baseline::GROUPS, restir::GROUPS, recursive::GROUPS].concat()
}

/// The passes (WGSL files) `method` creates, the slowest to compile first.
pub(crate) fn passes(method: Method) -> Vec<&'static str> {
    match method {
        Method::Baseline => baseline::PASSES.to_vec(),
        Method::Restir => restir::PASSES.to_vec(),
        Method::Recursive => recursive::PASSES.to_vec(),
    }
}

/// The most cameras `method` can use in one optimization (None: no limit of its own).
pub(crate) fn max_cameras(method: Method) -> Option<usize> {
    match method {
        Method::Baseline | Method::Recursive => None,
        Method::Restir => Some(restir::MAX_CAMERAS),
    }
}

/// The buffers `method` allocates for `n_params` parameter scalars in `n_texels` texels of
/// which `n_observed` are observed, and `n_pixels` pixels (all cameras'), by label, size in
/// bytes and what the size scales with.
pub(crate) fn memory(
    method: Method,
    n_params: u64,
    n_texels: u64,
    n_observed: u64,
    n_pixels: u64,
) -> Vec<(String, u64, crate::optim::Scale)> {
    match method {
        Method::Baseline => Vec::new(),
        Method::Restir => restir::memory(n_texels, n_observed, n_pixels),
        Method::Recursive => recursive::memory(n_params),
    }
}

#[cfg(test)]
mod tests;
