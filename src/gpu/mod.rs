//! Headless device creation, named buffers, compute passes and readback.
//!
//! On Linux the Vulkan backend is chosen explicitly: without it wgpu may pick a GL adapter with
//! far fewer features and say nothing.

pub mod abi;
mod binding;
mod made;
mod prepare;
pub mod shaders;
pub use binding::GroupDecl;
pub use made::PipelineTime;
pub use shaders::Binding;
pub use shaders::Tracer;

use crate::{Error, Result};
use std::sync::{Arc, Mutex};
use wgpu::util::DeviceExt;

/// Storage buffers that the largest pass binds at once (scene group plus pass group).
pub const REQUIRED_STORAGE_BUFFERS: u32 = 22;

const INSTALL_HINT: &str = "psrestir needs a Vulkan driver (or Metal/DX12 on other systems). \
On Debian/Ubuntu without a GPU, install the CPU driver lavapipe: \
`sudo apt-get install mesa-vulkan-drivers libvulkan1` (or run `bash ci/setup.sh`).";

/// A device and queue with the adapter they came from.
#[derive(Clone)]
pub struct Gpu {
    /// The wgpu device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter name, backend and driver.
    pub info: wgpu::AdapterInfo,
    /// Whether timestamp queries are enabled (used for per-pass timings when the adapter
    /// has them; nothing depends on them).
    pub timestamps: bool,
    /// The adapter's features, when psrestir created the device (`None` for a device the
    /// application passed in). Reported by `psrestir adapter`.
    pub adapter_features: Option<wgpu::Features>,
    /// How the passes trace rays ([`choose_tracer`]).
    pub tracer: Tracer,
    /// Uncaptured errors, recorded instead of panicking; checked after each submission.
    errors: Arc<Mutex<Vec<Fault>>>,
    /// Why the device was lost, once it is.
    lost: Arc<Mutex<Option<String>>>,
    /// The pipelines created so far and what each took ([`Gpu::pipeline_times`]).
    pipelines: Arc<Mutex<Vec<PipelineTime>>>,
    /// Whether this is a second device compiling ahead for another ([`Gpu::compile_elsewhere_in`]).
    compiles_ahead: bool,
    /// The layouts and pipelines this device has made, which later passes of the same WGSL
    /// and layouts reuse ([`Gpu::compute_pipeline_in`]).
    made: Arc<Mutex<made::Made>>,
}

/// A recorded device error, by kind.
#[derive(Clone, Debug, PartialEq)]
enum Fault {
    OutOfMemory(String),
    Other(String),
}

impl Fault {
    fn of(e: &wgpu::Error) -> Fault {
        match e {
            wgpu::Error::OutOfMemory { .. } => Fault::OutOfMemory(e.to_string()),
            _ => Fault::Other(e.to_string()),
        }
    }

    fn into_error(self, label: &str) -> Error {
        let label = label.to_string();
        match self {
            Fault::OutOfMemory(msg) => Error::OutOfMemory { label, msg },
            Fault::Other(msg) => Error::Gpu { label, msg },
        }
    }
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Gpu({})", self.describe())
    }
}

/// Each limit below what psrestir needs, as "name is X, psrestir needs Y".
fn limit_shortfalls(limits: &wgpu::Limits) -> Vec<String> {
    let need = [
        (
            "max_storage_buffers_per_shader_stage",
            limits.max_storage_buffers_per_shader_stage,
            REQUIRED_STORAGE_BUFFERS,
        ),
        (
            "max_storage_textures_per_shader_stage",
            limits.max_storage_textures_per_shader_stage,
            1,
        ),
        ("max_bind_groups", limits.max_bind_groups, 2),
        (
            "max_compute_invocations_per_workgroup",
            limits.max_compute_invocations_per_workgroup,
            64,
        ),
        (
            "max_compute_workgroup_size_x",
            limits.max_compute_workgroup_size_x,
            64,
        ),
        (
            "max_compute_workgroups_per_dimension",
            limits.max_compute_workgroups_per_dimension,
            1024,
        ),
    ];
    need.iter()
        .filter(|(_, have, want)| have < want)
        .map(|(name, have, want)| format!("{name} is {have}, psrestir needs {want}"))
        .collect()
}

fn backends() -> wgpu::Backends {
    if let Ok(s) = std::env::var("WGPU_BACKEND") {
        return wgpu::Backends::from_comma_list(&s);
    }
    if cfg!(target_os = "linux") || cfg!(target_os = "windows") {
        wgpu::Backends::VULKAN
    } else {
        wgpu::Backends::PRIMARY
    }
}

impl Gpu {
    /// Create a headless device on the best adapter of the platform's primary backend.
    pub fn new() -> Result<Gpu> {
        pollster::block_on(Self::new_async(None, true))
    }

    /// [`Gpu::new`] tracing with `tracer` whatever `PSRESTIR_TRACER` says; an error if the
    /// adapter cannot (ray queries where it offers none).
    pub fn with_tracer(tracer: Tracer) -> Result<Gpu> {
        pollster::block_on(Self::new_async(Some(tracer), true))
    }

    /// A second device of the adapter [`Gpu::with_tracer`] picks, without logging it (for
    /// [`Gpu::compile_elsewhere_in`]).
    pub(crate) fn quiet(tracer: Tracer) -> Result<Gpu> {
        pollster::block_on(Self::new_async(Some(tracer), false))
    }

    async fn new_async(tracer: Option<Tracer>, announce: bool) -> Result<Gpu> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends();
        let instance = wgpu::Instance::new(desc);
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: None,
                ..Default::default()
            })
            .await
            .map_err(|e| Error::NoAdapter(format!("no GPU adapter found ({e}). {INSTALL_HINT}")))?;
        let info = adapter.get_info();
        let mut limits = Self::required_limits(&adapter.limits())?;
        let tracer = match tracer {
            None => choose_tracer(adapter.features(), info.device_type)?,
            Some(Tracer::RayQuery)
                if !adapter
                    .features()
                    .contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY) =>
            {
                return Err(Error::Unsuitable(format!(
                    "{}: the adapter offers no ray queries",
                    info.name
                )))
            }
            Some(t) => t,
        };
        // Timestamp queries are optional: requested when present, for per-pass timings.
        let mut features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        let mut experimental = wgpu::ExperimentalFeatures::disabled();
        if tracer == Tracer::RayQuery {
            features |= wgpu::Features::EXPERIMENTAL_RAY_QUERY;
            limits = limits.using_acceleration_structure_values(adapter.limits());
            // SAFETY: wgpu marks ray queries experimental; psrestir uses them only for the
            // scene's one static acceleration structure, and a test compares their hits
            // with the software BVH's wherever the adapter offers them.
            experimental = unsafe { wgpu::ExperimentalFeatures::enabled() };
        }
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("psrestir"),
                required_features: features,
                required_limits: limits,
                experimental_features: experimental,
                ..Default::default()
            })
            .await
            .map_err(|e| Error::Unsuitable(format!("{}: {e}", info.name)))?;
        let mut gpu = Gpu::wrap(device, queue, info);
        gpu.adapter_features = Some(adapter.features());
        gpu.tracer = tracer;
        if announce {
            log::info!("GPU adapter: {}", gpu.describe());
        }
        Ok(gpu)
    }

    /// The limits psrestir asks for: the defaults, raised to what the adapter offers for
    /// buffer sizes, and enough storage buffers per stage. An application that creates the
    /// device itself passes these (or higher) as its `required_limits`.
    pub fn required_limits(adapter: &wgpu::Limits) -> Result<wgpu::Limits> {
        let short = limit_shortfalls(adapter);
        if !short.is_empty() {
            return Err(Error::Unsuitable(format!(
                "the adapter's limits are too low: {}",
                short.join("; ")
            )));
        }
        Ok(wgpu::Limits {
            max_storage_buffers_per_shader_stage: REQUIRED_STORAGE_BUFFERS,
            max_storage_buffer_binding_size: adapter.max_storage_buffer_binding_size,
            max_buffer_size: adapter.max_buffer_size,
            max_compute_workgroups_per_dimension: adapter.max_compute_workgroups_per_dimension,
            ..wgpu::Limits::default()
        })
    }

    /// Wrap a device and queue that the application already owns, after checking that the
    /// device was created with the limits psrestir needs (ask for
    /// [`Gpu::required_limits`]`(&adapter.limits())` in its `DeviceDescriptor`). No feature
    /// is required; timestamp queries are used for per-pass timings when the device has
    /// them. The error names every limit that falls short.
    ///
    /// psrestir installs the device's uncaptured-error handler and device-lost callback,
    /// which record wgpu errors so that each call can return them as [`Error::OutOfMemory`],
    /// [`Error::DeviceLost`] or [`Error::Gpu`]; an application that installs its own
    /// afterwards takes those errors over.
    ///
    /// ```no_run
    /// use psrestir::{wgpu, Gpu};
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
    /// let adapter = pollster::block_on(instance.request_adapter(&Default::default()))?;
    /// let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
    ///     required_limits: Gpu::required_limits(&adapter.limits())?,
    ///     ..Default::default()
    /// }))?;
    /// // The application keeps using `device` and `queue` (they are reference-counted).
    /// let gpu = Gpu::from_device(device.clone(), queue.clone(), adapter.get_info())?;
    /// # Ok(())
    /// # }
    /// ```
    pub fn from_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        info: wgpu::AdapterInfo,
    ) -> Result<Gpu> {
        Self::check_limits(&device.limits())?;
        let limits = device.limits();
        let features = device.features();
        let device_type = info.device_type;
        let mut gpu = Self::wrap(device, queue, info);
        // Ray queries only where the application enabled them with room for one BLAS.
        if limits.max_blas_geometry_count > 0 && limits.max_tlas_instance_count > 0 {
            gpu.tracer = choose_tracer(features, device_type)?;
        }
        Ok(gpu)
    }

    /// Check a device's limits against what psrestir needs; the error lists each shortfall.
    pub fn check_limits(limits: &wgpu::Limits) -> Result<()> {
        let short = limit_shortfalls(limits);
        if short.is_empty() {
            return Ok(());
        }
        Err(Error::Unsuitable(format!(
            "the device's limits are too low: {}. Create the device with \
             `required_limits: psrestir::gpu::Gpu::required_limits(&adapter.limits())?`",
            short.join("; ")
        )))
    }

    fn wrap(device: wgpu::Device, queue: wgpu::Queue, info: wgpu::AdapterInfo) -> Gpu {
        let errors: Arc<Mutex<Vec<Fault>>> = Arc::default();
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(Fault::of(&e));
            }
        }));
        let lost: Arc<Mutex<Option<String>>> = Arc::default();
        let lost_sink = lost.clone();
        device.set_device_lost_callback(move |reason, msg| {
            if let Ok(mut l) = lost_sink.lock() {
                *l = Some(format!("{reason:?}: {msg}"));
            }
        });
        let timestamps = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        Gpu {
            device,
            queue,
            info,
            timestamps,
            adapter_features: None,
            tracer: Tracer::Software,
            errors,
            lost,
            pipelines: Arc::default(),
            compiles_ahead: false,
            made: Arc::default(),
        }
    }

    /// "name (backend, driver driver_info)".
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {} {})",
            self.info.name, self.info.backend, self.info.driver, self.info.driver_info
        )
    }

    /// Return the first uncaptured error since the last call, if any: [`Error::DeviceLost`]
    /// once the device is lost, [`Error::OutOfMemory`] for allocation failures,
    /// [`Error::Gpu`] for the rest.
    pub fn check(&self, label: &str) -> Result<()> {
        if let Some(reason) = self.lost_reason() {
            return Err(Error::DeviceLost {
                label: label.into(),
                msg: reason,
            });
        }
        let mut v = self.errors.lock().map_err(|_| Error::Gpu {
            label: label.into(),
            msg: "error sink poisoned".into(),
        })?;
        if let Some(first) = v.first().cloned() {
            v.clear();
            return Err(first.into_error(label));
        }
        Ok(())
    }

    /// Why the device was lost, if it was.
    pub fn lost_reason(&self) -> Option<String> {
        self.lost.lock().ok().and_then(|l| l.clone())
    }

    /// A storage buffer initialised with `data`, padded to at least 256 bytes so that an empty
    /// array still binds (the largest GPU struct is smaller).
    pub fn storage(&self, label: &str, data: &[u8], extra: wgpu::BufferUsages) -> wgpu::Buffer {
        let mut bytes = data.to_vec();
        if bytes.len() < 256 {
            bytes.resize(256, 0);
        }
        while bytes.len() % 4 != 0 {
            bytes.push(0);
        }
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
            })
    }

    /// A zeroed storage buffer of `size` bytes that can be copied from.
    pub fn storage_zeroed(&self, label: &str, size: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(16).next_multiple_of(4),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A uniform buffer holding `data`.
    pub fn uniform(&self, label: &str, data: &[u8]) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: data,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// Wait for all submitted work.
    pub fn wait(&self, label: &str) -> Result<()> {
        let polled = self.device.poll(wgpu::PollType::wait_indefinitely());
        // A loss found while waiting comes out as the loss, not as the poll's error.
        self.check(label)?;
        polled.map_err(|e| Error::Gpu {
            label: label.into(),
            msg: e.to_string(),
        })?;
        Ok(())
    }

    /// Copy `buffer` back to the CPU (waits for the GPU).
    pub fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>> {
        let label = "readback";
        let size = buffer.size();
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback staging"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([enc.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait(label)?;
        rx.recv()
            .map_err(|e| Error::Gpu {
                label: label.into(),
                msg: e.to_string(),
            })?
            .map_err(|e| Error::Gpu {
                label: label.into(),
                msg: e.to_string(),
            })?;
        let data = slice
            .get_mapped_range()
            .map_err(|e| Error::Gpu {
                label: label.into(),
                msg: e.to_string(),
            })?
            .to_vec();
        staging.unmap();
        Ok(data)
    }

    /// Read a buffer as a vector of plain-old-data values.
    pub fn read_pod<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
        let bytes = self.read_buffer(buffer)?;
        let n = bytes.len() / std::mem::size_of::<T>();
        Ok(bytemuck::pod_collect_to_vec(
            &bytes[..n * std::mem::size_of::<T>()],
        ))
    }

    /// Compile a compute pass from its WGSL file in `library` (composed with its imports),
    /// with the given bind group layouts, catching validation errors as [`Error::Shader`].
    /// The driver compiles it here, not at its first dispatch (`prepare.rs`), and the time it
    /// took is recorded ([`Gpu::pipeline_times`]). A pipeline this device already made from
    /// the same WGSL and layouts is returned again: a second optimizer on one device, or the
    /// bench's next run, creates no pipeline (on lavapipe each cost 0.1-0.8 s even when
    /// Mesa's shader cache held it).
    pub fn compute_pipeline_in(
        &self,
        library: &shaders::Library,
        pass: &str,
        layouts: &[&wgpu::BindGroupLayout],
    ) -> Result<wgpu::ComputePipeline> {
        self.compute_pipeline_in_without(library, pass, layouts, &[])
    }

    /// [`Gpu::compute_pipeline_in`] with the modules `off` names in their `_off` form
    /// ([`shaders::Library::compose_without`]).
    pub fn compute_pipeline_in_without(
        &self,
        library: &shaders::Library,
        pass: &str,
        layouts: &[&wgpu::BindGroupLayout],
        off: &[&str],
    ) -> Result<wgpu::ComputePipeline> {
        let start = std::time::Instant::now();
        let source = library.compose_without(pass, self.tracer, off)?;
        if let Some(pipeline) = self.made_pipeline(&source, layouts) {
            self.record_pipeline(pass, start);
            return Ok(pipeline);
        }
        let key = source.clone();
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(pass),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        let optional: Vec<Option<&wgpu::BindGroupLayout>> =
            layouts.iter().map(|l| Some(*l)).collect();
        let layout = self
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(pass),
                bind_group_layouts: &optional,
                immediate_size: 0,
            });
        let pipeline = self
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(pass),
                layout: Some(&layout),
                module: &module,
                entry_point: Some("main"),
                // Every pass writes its workgroup memory before it reads it (the loss's and
                // the multiscale prior's sums, the environment derivative's per-workgroup
                // sums, which env_local_begin clears only where it is used): the zeroing
                // WGSL otherwise asks of each workgroup is work for nothing (on lavapipe,
                // 1-3 ms per gradient pass for the 6 KiB of env_gradient.wgsl).
                compilation_options: wgpu::PipelineCompilationOptions {
                    zero_initialize_workgroup_memory: false,
                    ..Default::default()
                },
                cache: None,
            });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Shader {
                name: pass.into(),
                msg: e.to_string(),
            });
        }
        self.compile_now(library, pass, &pipeline, layouts)?;
        self.remember_pipeline(key, layouts, &pipeline);
        self.record_pipeline(pass, start);
        Ok(pipeline)
    }
}

/// The environment variable through which Mesa's CPU drivers (lavapipe, llvmpipe) take the
/// width of the SIMD code they compile shaders to, in bits.
pub const CPU_SIMD_WIDTH_VAR: &str = "LP_NATIVE_VECTOR_WIDTH";

/// Ask Mesa's CPU Vulkan driver (lavapipe) for 128-bit (4-lane) shader code, unless the
/// environment already names a width ([`CPU_SIMD_WIDTH_VAR`]). On a machine with AVX2,
/// lavapipe compiles 8-lane code by default, and since it loads buffer elements lane by lane,
/// every load is compiled once per lane: at 4 lanes the passes compile in about half the
/// time and run as fast, with the same images (measured in docs/performance.md, "SIMD width
/// on lavapipe"). The variable is read when the driver starts, so this must run before a
/// wgpu instance is created, and, since it sets the process environment, while the program
/// has only one thread (the command line calls it first thing). A GPU driver ignores it. A
/// library user's application decides for itself; `ci/test.sh` sets it for the tests.
pub fn prefer_narrow_cpu_simd() {
    if std::env::var_os(CPU_SIMD_WIDTH_VAR).is_none() {
        std::env::set_var(CPU_SIMD_WIDTH_VAR, "128");
    }
}

/// How the passes trace rays on an adapter with `features` of type `device_type`. The
/// environment variable `PSRESTIR_TRACER` chooses (`software` or `ray-query`); by default
/// ray queries are used where the adapter offers them on a GPU. On lavapipe, which offers
/// them too, the WGSL BVH is faster (ray queries trace 0.40× its rays/s, `ci/rays.sh`), so
/// CPU adapters keep it unless asked.
pub fn choose_tracer(features: wgpu::Features, device_type: wgpu::DeviceType) -> Result<Tracer> {
    let offered = features.contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY);
    match std::env::var("PSRESTIR_TRACER").ok().as_deref() {
        None | Some("") | Some("auto") => Ok(if offered && device_type != wgpu::DeviceType::Cpu {
            Tracer::RayQuery
        } else {
            Tracer::Software
        }),
        Some("software") => Ok(Tracer::Software),
        Some("ray-query") if offered => Ok(Tracer::RayQuery),
        Some("ray-query") => Err(Error::Unsuitable(
            "PSRESTIR_TRACER=ray-query, but this adapter offers no ray queries \
             (unset it to trace with the software BVH)"
                .into(),
        )),
        Some(other) => Err(Error::Unsuitable(format!(
            "PSRESTIR_TRACER={other}: expected `software`, `ray-query` or `auto`"
        ))),
    }
}

/// Workgroups for `n` invocations of size `wg`, as a 2D grid that respects the per-dimension
/// limit (lavapipe: 65535). Shaders recover the linear index as `id.x + id.y * stride`, where
/// stride is `grid.0 * wg`.
pub fn grid_2d(n: u32, wg: u32, max_dim: u32) -> (u32, u32) {
    let groups = n.div_ceil(wg).max(1);
    if groups <= max_dim {
        (groups, 1)
    } else {
        let y = groups.div_ceil(max_dim);
        (groups.div_ceil(y), y)
    }
}

/// Record one compute pass: `groups[k]` is bound at group k.
pub fn encode_pass(
    enc: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups: &[&wgpu::BindGroup],
    grid: (u32, u32),
) {
    encode_timed_pass(enc, label, pipeline, groups, grid, None)
}

/// [`encode_pass`], writing timestamps `2k` and `2k + 1` of the query set at the pass's start
/// and end when given `(query set, k)`.
pub fn encode_timed_pass(
    enc: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups: &[&wgpu::BindGroup],
    grid: (u32, u32),
    timing: Option<(&wgpu::QuerySet, u32)>,
) {
    begin_timed_pass(enc, label, pipeline, groups, timing).dispatch_workgroups(grid.0, grid.1, 1);
}

/// A compute pass of `pipeline` with `groups` bound, timed as [`encode_timed_pass`] says.
fn begin_timed_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups: &[&wgpu::BindGroup],
    timing: Option<(&wgpu::QuerySet, u32)>,
) -> wgpu::ComputePass<'e> {
    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: timing.map(|(q, k)| wgpu::ComputePassTimestampWrites {
            query_set: q,
            beginning_of_pass_write_index: Some(2 * k),
            end_of_pass_write_index: Some(2 * k + 1),
        }),
    });
    pass.set_pipeline(pipeline);
    for (k, g) in groups.iter().enumerate() {
        pass.set_bind_group(k as u32, *g, &[]);
    }
    pass
}

/// [`encode_timed_pass`] with its workgroup counts read from `args` at byte `offset` (x, y, z
/// as u32; a zero count dispatches nothing).
pub fn encode_timed_pass_indirect(
    enc: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups: &[&wgpu::BindGroup],
    args: (&wgpu::Buffer, u64),
    timing: Option<(&wgpu::QuerySet, u32)>,
) {
    begin_timed_pass(enc, label, pipeline, groups, timing)
        .dispatch_workgroups_indirect(args.0, args.1);
}

#[cfg(test)]
mod tests {
    use super::Fault;
    use crate::Error;

    #[test]
    fn out_of_memory_is_told_apart_from_other_device_errors() {
        let oom = wgpu::Error::OutOfMemory {
            source: "allocation failed".into(),
        };
        let e = Fault::of(&oom).into_error("reservoir slots");
        assert!(matches!(e, Error::OutOfMemory { .. }), "{e:?}");
        let text = e.to_string();
        assert!(text.contains("reservoir slots") && text.contains("Lower the image size"));
        let validation = wgpu::Error::Validation {
            source: "bad binding".into(),
            description: "bad binding".into(),
        };
        assert!(matches!(
            Fault::of(&validation).into_error("render"),
            Error::Gpu { .. }
        ));
    }
}
