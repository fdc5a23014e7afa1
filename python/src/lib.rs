//! The native half of the `psrestir` Python package (`psrestir._psrestir`): one process-wide
//! GPU device, the whole task in one call ([`optimize`]) and the differentiable render
//! ([`DiffRender`]). `python/psrestir/__init__.py` wraps these in the package's public
//! surface; errors become the exception classes of `psrestir/errors.py`, and no panic
//! crosses into Python. GPU work runs with the interpreter released.

use numpy::{PyArray1, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use psrestir::image_io::Image;
use psrestir::job::run::{RowHook, RunOptions};
use psrestir::optim::checkpoint::MetricRow;
use psrestir::{Error, Gpu, MethodChoice, Task};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// The process-wide device, made at first use.
static GPU: Mutex<Option<Gpu>> = Mutex::new(None);

fn gpu() -> psrestir::Result<Gpu> {
    let mut g = GPU.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(gpu) = g.as_ref() {
        return Ok(gpu.clone());
    }
    // lavapipe at 4 SIMD lanes, as the command line asks for it (half the compilation).
    psrestir::gpu::prefer_narrow_cpu_simd();
    let gpu = Gpu::new()?;
    *g = Some(gpu.clone());
    Ok(gpu)
}

/// The exception for `e`: a class of `psrestir.errors`, with a message that names Python
/// remedies where the library's names command-line ones.
fn to_py(e: Error) -> PyErr {
    let (class, msg, path) = match e {
        Error::File { path, msg } => (
            "FileError",
            format!("{}: {msg}", path.display()),
            Some(path.display().to_string()),
        ),
        Error::NoAdapter(m) => ("AdapterError", m, None),
        Error::Unsuitable(m) => ("AdapterError", format!("GPU adapter unsuitable: {m}"), None),
        Error::OutOfMemory { label, msg } => (
            "GpuOutOfMemory",
            format!(
                "GPU out of memory in {label}: {msg}. Lower the image size (the task's width and \
                 height), the texture resolution or the samples per pixel, or free GPU memory \
                 (`del` DiffRender objects you no longer use; other programs)"
            ),
            None,
        ),
        Error::DeviceLost { label, msg } => (
            "DeviceLost",
            format!(
                "the GPU device was lost in {label}: {msg}. Nothing more can run on it in this \
                 process: restart Python, and continue an optimization from its checkpoint with \
                 psrestir.optimize(task, resume=True)"
            ),
            None,
        ),
        e @ (Error::Gpu { .. } | Error::Shader { .. }) => ("GpuError", e.to_string(), None),
        Error::Invalid(m) => ("InvalidArgument", m, None),
    };
    raise(class, msg, path)
}

/// An instance of `psrestir.errors.<class>` with `msg` (and the file's `path`).
fn raise(class: &str, msg: String, path: Option<String>) -> PyErr {
    Python::attach(|py| {
        let made = py
            .import("psrestir.errors")
            .and_then(|m| m.getattr(class))
            .and_then(|c| match &path {
                Some(p) => c.call1((msg.clone(), p.clone())),
                None => c.call1((msg.clone(),)),
            });
        match made {
            Ok(exc) => PyErr::from_value(exc),
            Err(e) => e,
        }
    })
}

/// Run `f` with the interpreter released, turning a panic into `psrestir.errors.PsrestirError`
/// and the library's errors into their classes.
fn released<T: Send>(
    py: Python<'_>,
    f: impl FnOnce() -> psrestir::Result<T> + Send,
) -> PyResult<T> {
    let r = py.detach(|| catch_unwind(AssertUnwindSafe(f)));
    match r {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_py(e)),
        Err(p) => {
            let what = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            Err(raise(
                "PsrestirError",
                format!("internal error (a bug in psrestir, please report it): {what}"),
                None,
            ))
        }
    }
}

/// A task from a file's path, or from the same content as JSON text (a dict on the Python
/// side) anchored in `base` (relative paths resolve against it; errors name `<base>/<name>`).
fn load_task(path: Option<PathBuf>, json: Option<String>, base: PathBuf) -> psrestir::Result<Task> {
    match (path, json) {
        (Some(p), None) => Task::load(&p),
        (None, Some(j)) => {
            let anchor = base.join("dict_task.toml");
            let value: serde_json::Value =
                serde_json::from_str(&j).map_err(|e| Error::Invalid(format!("task dict: {e}")))?;
            let text = toml::to_string(&value).map_err(|e| {
                Error::Invalid(format!(
                    "task dict: {e} (values must be str, int, float, bool, lists or dicts; \
                     no None)"
                ))
            })?;
            Task::parse(&text, &anchor)
        }
        _ => Err(Error::Invalid("give a task file's path or a dict".into())),
    }
}

fn primal_mode(name: &str) -> PyResult<psrestir::optim::PrimalMode> {
    match name {
        "independent" => Ok(psrestir::optim::PrimalMode::Independent),
        "control_variate" => Ok(psrestir::optim::PrimalMode::ControlVariate),
        _ => Err(to_py(Error::Invalid(format!(
            "primal: `{name}` is not one of \"independent\", \"control_variate\""
        )))),
    }
}

fn method_choice(name: &str) -> psrestir::Result<MethodChoice> {
    name.parse::<MethodChoice>()
        .map_err(|e| Error::Invalid(format!("method: {e}")))
}

/// A float32 array of shape `shape` (e.g. `(h, w, c)`) copied out of any numpy array of that
/// shape and dtype float32; anything else is an `InvalidArgument` that says what was
/// expected.
fn read_array(what: &str, obj: &Bound<'_, PyAny>, shape: &[usize]) -> PyResult<Vec<f32>> {
    let dims_text = shape
        .iter()
        .map(|d| d.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let bad = |got: String| {
        let meaning = if shape.len() == 3 {
            " (height, width, channels)"
        } else {
            ""
        };
        let comma = if shape.len() == 1 { "," } else { "" };
        raise(
            "InvalidArgument",
            format!("{what}: expected a numpy float32 array of shape ({dims_text}{comma}){meaning}, got {got}"),
            None,
        )
    };
    let Ok(arr) = obj.cast::<PyUntypedArray>() else {
        return Err(bad(format!(
            "a {} (convert it with numpy.asarray(x, dtype=numpy.float32))",
            obj.get_type().name()?
        )));
    };
    let dims = arr.shape().to_vec();
    let dtype = arr.dtype();
    if !dtype.is_equiv_to(&numpy::dtype::<f32>(obj.py())) {
        return Err(bad(format!(
            "dtype {} (convert it with .astype(numpy.float32))",
            dtype.str()?
        )));
    }
    if dims != shape {
        return Err(bad(format!("shape {dims:?}")));
    }
    let typed = obj
        .cast::<numpy::PyArrayDyn<f32>>()
        .map_err(|e| bad(e.to_string()))?;
    let ro = typed.readonly();
    let v: Vec<f32> = ro.as_array().iter().copied().collect();
    Ok(v)
}

fn to_array<'py>(py: Python<'py>, v: Vec<f32>, shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v).reshape(shape)?.into_any())
}

fn image_array<'py>(py: Python<'py>, img: &Image) -> PyResult<Bound<'py, PyAny>> {
    let v: Vec<f32> = img.rgb.iter().flatten().copied().collect();
    to_array(py, v, &[img.height as usize, img.width as usize, 3])
}

fn env_array<'py>(py: Python<'py>, e: &psrestir::scene::EnvMap) -> PyResult<Bound<'py, PyAny>> {
    let v: Vec<f32> = e.rgb.iter().flatten().map(|x| x * e.scale).collect();
    to_array(py, v, &[e.height as usize, e.width as usize, 3])
}

/// The relit errors as a list of dicts (environment, relmse, psnr, scale).
fn relit_list<'py>(
    py: Python<'py>,
    errors: &[psrestir::job::relight::RelitError],
) -> PyResult<Bound<'py, PyList>> {
    let list = PyList::empty(py);
    for e in errors {
        let d = PyDict::new(py);
        d.set_item("environment", &e.environment)?;
        d.set_item("relmse", e.relmse)?;
        d.set_item("psnr", e.psnr)?;
        d.set_item("scale", e.scale.to_vec())?;
        list.append(d)?;
    }
    Ok(list)
}

fn row_dict<'py>(py: Python<'py>, r: &MetricRow) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("iteration", r.iteration)?;
    d.set_item("elapsed_s", r.elapsed_s)?;
    d.set_item("loss", r.loss)?;
    d.set_item("texture_rmse", r.texture_rmse)?;
    d.set_item("texture_rmse_observed", r.texture_rmse_observed)?;
    d.set_item("image_relmse", r.image_relmse)?;
    d.set_item("learning_rate", r.learning_rate)?;
    d.set_item("image_relmse_expected", r.image_relmse_expected)?;
    Ok(d)
}

/// `optimize(path, json, base, method, iterations, time_budget, out, resume, callback)`: a
/// task run as `psrestir optimize` runs it; `callback(row: dict)` after each iteration (a
/// Ctrl-C, or an exception in the callback, stops the run after the iteration under way,
/// with the checkpoint and outputs written, and is raised then). Returns a dict.
#[pyfunction]
#[pyo3(signature = (path, json, base, method, iterations, time_budget, out, resume, callback))]
#[allow(clippy::too_many_arguments)]
fn optimize<'py>(
    py: Python<'py>,
    path: Option<PathBuf>,
    json: Option<String>,
    base: PathBuf,
    method: &str,
    iterations: Option<u32>,
    time_budget: Option<f64>,
    out: Option<PathBuf>,
    resume: bool,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    if let Some(b) = time_budget {
        if !(b.is_finite() && b > 0.0) {
            return Err(to_py(Error::Invalid(format!(
                "time_budget must be a positive number of seconds, not {b}"
            ))));
        }
    }
    let interrupt = Arc::new(AtomicBool::new(false));
    // The first exception from the callback or a signal: raised once the run has ended.
    let pending: Arc<Mutex<Option<PyErr>>> = Arc::new(Mutex::new(None));
    let hook = {
        let interrupt = interrupt.clone();
        let pending = pending.clone();
        RowHook(Arc::new(move |row: &MetricRow| {
            Python::attach(|py| {
                let result = py.check_signals().and_then(|_| match &callback {
                    Some(cb) => cb.call1(py, (row_dict(py, row)?,)).map(|_| ()),
                    None => Ok(()),
                });
                if let Err(e) = result {
                    let mut p = pending.lock().unwrap_or_else(|p| p.into_inner());
                    if p.is_none() {
                        *p = Some(e);
                    }
                    interrupt.store(true, Ordering::SeqCst);
                }
            })
        }))
    };
    let summary = released(py, || {
        let task = load_task(path, json, base)?;
        let gpu = gpu()?;
        psrestir::job::run::run(
            &gpu,
            &task,
            &RunOptions {
                method: method_choice(method)?,
                iterations,
                time_budget_s: time_budget,
                out,
                resume,
                progress: false,
                interrupt: Some(interrupt),
                on_row: Some(hook),
                ..Default::default()
            },
        )
    })?;
    let d = summary_dict(py, &summary)?;
    if let Some(e) = pending.lock().unwrap_or_else(|p| p.into_inner()).take() {
        d.set_item("error", e.into_value(py))?;
    }
    Ok(d)
}

/// `optimize`'s result as a dict: figures, final textures, environment, relit errors,
/// uncertainty, the cameras' gains and each texture's observed-texel errors.
fn summary_dict<'py>(
    py: Python<'py>,
    summary: &psrestir::job::run::RunSummary,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("iterations", summary.iterations)?;
    d.set_item("elapsed_s", summary.elapsed_s)?;
    d.set_item("ms_per_iteration", summary.ms_per_iteration)?;
    d.set_item("final_loss", summary.final_loss)?;
    d.set_item("initial_rmse", summary.initial_rmse)?;
    d.set_item("final_rmse", summary.final_rmse)?;
    d.set_item("initial_rmse_observed", summary.initial_rmse_observed)?;
    d.set_item("final_rmse_observed", summary.final_rmse_observed)?;
    d.set_item("out", summary.out.display().to_string())?;
    d.set_item("interrupted", summary.interrupted)?;
    d.set_item("warnings", summary.warnings.clone())?;
    d.set_item("plateau", summary.plateau.clone())?;
    d.set_item(
        "kept_iteration",
        summary.handed_back.as_ref().map(|h| h.iteration),
    )?;
    let textures = PyDict::new(py);
    for (i, t) in summary.set.textures.iter().enumerate() {
        let v = summary.set.values_of(i).to_vec();
        let shape = [t.height as usize, t.width as usize, t.channels() as usize];
        textures.set_item(t.name(), to_array(py, v, &shape)?)?;
    }
    d.set_item("textures", textures)?;
    d.set_item(
        "environment",
        summary
            .environment
            .as_ref()
            .map(|e| env_array(py, e))
            .transpose()?,
    )?;
    d.set_item("relit", relit_list(py, &summary.relit)?)?;
    let uncertainty = match &summary.uncertainty {
        Some(sigma) => {
            let u = PyDict::new(py);
            for t in &summary.set.textures {
                let v = sigma[t.offset as usize..t.offset as usize + t.len()].to_vec();
                let shape = [t.height as usize, t.width as usize, t.channels() as usize];
                u.set_item(t.name(), to_array(py, v, &shape)?)?;
            }
            Some(u)
        }
        None => None,
    };
    d.set_item("uncertainty", uncertainty)?;
    d.set_item(
        "exposure",
        summary.gains.iter().map(|g| g.0).collect::<Vec<_>>(),
    )?;
    d.set_item(
        "white_balance",
        summary
            .gains
            .iter()
            .map(|g| g.1.to_vec())
            .collect::<Vec<_>>(),
    )?;
    let per = PyDict::new(py);
    for t in &summary.per_texture {
        per.set_item(&t.texture, (t.initial_rmse_observed, t.final_rmse_observed))?;
    }
    d.set_item("rmse_observed_per_texture", per)?;
    Ok(d)
}

/// The differentiable render of a task's scene (see `psrestir.DiffRender`).
#[pyclass(module = "psrestir._psrestir")]
struct DiffRender {
    inner: Mutex<psrestir::optim::DiffRender>,
    task: Task,
    /// Texture names (`material_slot`), shapes (height, width, channels).
    names: Vec<String>,
    shapes: Vec<[usize; 3]>,
    cameras: Vec<String>,
    method: String,
    /// (height, width, 3) of the environment when it is a parameter.
    env_shape: Option<[usize; 3]>,
    /// The task's targets and reference textures, loaded at first use.
    targets: Mutex<Option<psrestir::Problem>>,
}

impl DiffRender {
    fn index(&self, texture: &Bound<'_, PyAny>) -> PyResult<usize> {
        if let Ok(i) = texture.extract::<usize>() {
            if i < self.names.len() {
                return Ok(i);
            }
        } else if let Ok(name) = texture.extract::<String>() {
            if let Some(i) = self.names.iter().position(|n| *n == name) {
                return Ok(i);
            }
        }
        Err(raise(
            "InvalidArgument",
            format!(
                "no optimized texture {}: the textures are {:?} (by name or index)",
                texture.repr()?,
                self.names
            ),
            None,
        ))
    }

    fn problem(&self, py: Python<'_>) -> PyResult<psrestir::Problem> {
        let mut cached = self.targets.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(p) = cached.as_ref() {
            return Ok(p.clone());
        }
        let task = self.task.clone();
        let p = released(py, move || {
            let gpu = gpu()?;
            let out = task.output_dir();
            std::fs::create_dir_all(&out).map_err(|e| Error::file(&out, e.to_string()))?;
            psrestir::Problem::from_task(&gpu, &task, &out, true)
        })?;
        *cached = Some(p.clone());
        Ok(p)
    }
}

#[pymethods]
impl DiffRender {
    #[new]
    #[pyo3(signature = (path, json, base, method))]
    fn new(
        py: Python<'_>,
        path: Option<PathBuf>,
        json: Option<String>,
        base: PathBuf,
        method: &str,
    ) -> PyResult<DiffRender> {
        let (op, problem, task) = released(py, || {
            let task = load_task(path, json, base)?;
            let gpu = gpu()?;
            let choice = method_choice(method)?;
            let (op, problem) =
                psrestir::optim::DiffRender::for_task(&gpu, &task, choice, &Default::default())?;
            Ok((op, problem, task))
        })?;
        let names = op.textures().iter().map(|t| t.name()).collect();
        let shapes = op
            .textures()
            .iter()
            .map(|t| [t.height as usize, t.width as usize, t.channels() as usize])
            .collect();
        let cameras = problem
            .cameras
            .iter()
            .map(|&c| problem.scene.cameras[c].name.clone())
            .collect();
        let method = op.optimizer().settings().method.name().to_string();
        let env_shape = op
            .environment()
            .map(|e| [e.height as usize, e.width as usize, 3]);
        Ok(DiffRender {
            inner: Mutex::new(op),
            task,
            names,
            shapes,
            cameras,
            method,
            env_shape,
            targets: Mutex::new(None),
        })
    }

    /// The optimized textures' names (`material_slot`), in order.
    #[getter]
    fn texture_names(&self) -> Vec<String> {
        self.names.clone()
    }

    /// Shape (height, width, channels) of each texture, by name.
    #[getter]
    fn texture_shapes(&self) -> Vec<(String, (usize, usize, usize))> {
        self.names
            .iter()
            .zip(&self.shapes)
            .map(|(n, s)| (n.clone(), (s[0], s[1], s[2])))
            .collect()
    }

    /// The cameras' names, in the order of the rendered images.
    #[getter]
    fn camera_names(&self) -> Vec<String> {
        self.cameras.clone()
    }

    /// (height, width) of every image.
    #[getter]
    fn image_shape(&self) -> (u32, u32) {
        let (w, h) = self.lock().image_size();
        (h, w)
    }

    /// The gradient estimator's name.
    #[getter]
    fn method(&self) -> String {
        self.method.clone()
    }

    /// Backward calls so far.
    #[getter]
    fn iteration(&self) -> u32 {
        self.lock().iteration()
    }

    fn texture<'py>(
        &self,
        py: Python<'py>,
        texture: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let i = self.index(texture)?;
        let v = released(py, || self.lock().texture(i))?;
        to_array(py, v, &self.shapes[i])
    }

    fn set_texture(
        &self,
        py: Python<'_>,
        texture: &Bound<'_, PyAny>,
        values: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let i = self.index(texture)?;
        let v = read_array(
            &format!("texture `{}`", self.names[i]),
            values,
            &self.shapes[i],
        )?;
        released(py, || self.lock().set_texture(i, &v))
    }

    #[pyo3(signature = (spp, seed, primal))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        spp: u32,
        seed: u32,
        primal: Option<&str>,
    ) -> PyResult<Bound<'py, PyList>> {
        let primal = primal.map(primal_mode).transpose()?;
        let images = released(py, || self.lock().render(spp, seed, primal))?;
        let list = PyList::empty(py);
        for img in &images {
            list.append(image_array(py, img)?)?;
        }
        Ok(list)
    }

    /// The primal a render uses by default (the task's).
    #[getter]
    fn primal(&self) -> String {
        self.lock().primal().name().to_string()
    }

    #[pyo3(signature = (adjoints, seed_grad))]
    fn backward<'py>(
        &self,
        py: Python<'py>,
        adjoints: &Bound<'py, PyAny>,
        seed_grad: Option<u32>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (h, w) = self.image_shape();
        let items: Vec<Bound<'py, PyAny>> = adjoints
            .try_iter()
            .map_err(|_| {
                raise(
                    "InvalidArgument",
                    "backward: give a list of adjoint images, one per camera".into(),
                    None,
                )
            })?
            .collect::<PyResult<_>>()?;
        if items.len() != self.cameras.len() {
            return Err(raise(
                "InvalidArgument",
                format!(
                    "backward: {} adjoint images for {} cameras ({:?})",
                    items.len(),
                    self.cameras.len(),
                    self.cameras
                ),
                None,
            ));
        }
        let mut images = Vec::new();
        for (k, a) in items.iter().enumerate() {
            let v = read_array(
                &format!("adjoint image {k} (camera `{}`)", self.cameras[k]),
                a,
                &[h as usize, w as usize, 3],
            )?;
            images.push(Image {
                width: w,
                height: h,
                rgb: v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
            });
        }
        let grads = released(py, || self.lock().backward(&images, seed_grad))?;
        self.gradient_dict(py, grads)
    }

    /// Every parameter's current value by name: the textures, `environment` (when the task
    /// recovers it), `exposure` (n_cameras,) and `white_balance` (n_cameras, 3).
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (i, (name, shape)) in self.names.iter().zip(&self.shapes).enumerate() {
            let v = released(py, || self.lock().texture(i))?;
            d.set_item(name, to_array(py, v, shape)?)?;
        }
        let op = self.lock();
        if let Some(e) = op.environment() {
            d.set_item("environment", env_array(py, &e)?)?;
        }
        let n = self.cameras.len();
        d.set_item("exposure", to_array(py, op.exposure().to_vec(), &[n])?)?;
        let wb: Vec<f32> = op.white_balance().iter().flatten().copied().collect();
        d.set_item("white_balance", to_array(py, wb, &[n, 3])?)?;
        Ok(d)
    }

    /// Set one parameter by name (see `parameters`); a render must follow before the next
    /// backward.
    fn set_parameter(&self, py: Python<'_>, name: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = self.cameras.len();
        if let Some(i) = self.names.iter().position(|t| t == name) {
            let v = read_array(&format!("texture `{name}`"), value, &self.shapes[i])?;
            return released(py, || self.lock().set_texture(i, &v));
        }
        match name {
            "environment" => {
                let Some(shape) = self.env_shape else {
                    return Err(to_py(Error::Invalid(
                        "`environment` is not a parameter: the task does not recover its \
                         environment (its [environment] table with optimize = true)"
                            .into(),
                    )));
                };
                let v = read_array("environment", value, &shape)?;
                let rgb: Vec<[f32; 3]> = v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                released(py, || self.lock().set_environment(&rgb))
            }
            "exposure" => {
                let v = read_array("exposure", value, &[n])?;
                released(py, || self.lock().set_exposure(&v))
            }
            "white_balance" => {
                let v = read_array("white_balance", value, &[n, 3])?;
                let rgb: Vec<[f32; 3]> = v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                released(py, || self.lock().set_white_balance(&rgb))
            }
            _ => Err(to_py(Error::Invalid(format!(
                "no parameter `{name}`: the parameters are {:?}",
                self.parameter_names()
            )))),
        }
    }

    /// The parameters' names, in the order of `parameters()`.
    #[getter(parameter_names)]
    fn parameter_names_py(&self) -> Vec<String> {
        self.parameter_names()
    }

    /// One step of the task's optimizer from the last backward's gradient (`grads` None) or
    /// from `grads` (a dict like backward's).
    #[pyo3(signature = (grads))]
    fn step(&self, py: Python<'_>, grads: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
        let given = grads.map(|g| self.read_gradients(g)).transpose()?;
        released(py, || self.lock().step(given.as_ref()))
    }

    /// The task's (iterations, time budget in seconds), either None.
    fn budget(&self) -> (Option<u32>, Option<f64>) {
        (
            self.task.optimizer.iterations,
            self.task.optimizer.time_budget_s,
        )
    }

    /// Steps taken.
    #[getter]
    fn steps(&self) -> u32 {
        self.lock().steps()
    }

    /// The fraction of the run done, for the learning-rate schedule.
    fn set_progress(&self, fraction: f64) {
        self.lock().set_progress(fraction);
    }

    /// How far a run of `iterations` steps or `time_budget` seconds is after the steps
    /// taken and `elapsed` seconds, by the run loop's own measure (the larger share, at
    /// most 1), so that `Step` follows the schedule as `psrestir optimize` does.
    #[pyo3(signature = (iterations, time_budget, elapsed))]
    fn run_progress(&self, iterations: Option<u32>, time_budget: Option<f64>, elapsed: f64) -> f64 {
        let limits = psrestir::optim::run_loop::Limits {
            first: 0,
            iterations,
            seconds: time_budget,
        };
        limits.progress(self.lock().steps(), elapsed).min(1.0)
    }

    /// Each texture's learning rate in the last step, by name.
    fn learning_rates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let op = self.lock();
        for (name, lr) in self.names.iter().zip(op.last_learning_rates()) {
            d.set_item(name, *lr)?;
        }
        Ok(d)
    }

    /// Each texture's variance of its last gradient estimate, where the estimator tracks one.
    fn gradient_variance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(v) = released(py, || self.lock().gradient_variance())? else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        for ((name, shape), t) in self.names.iter().zip(&self.shapes).zip(v) {
            d.set_item(name, to_array(py, t, shape)?)?;
        }
        Ok(Some(d))
    }

    /// The relit errors of `textures` (a dict by name; None: the current ones) under the
    /// task's `relight` environments, as `psrestir optimize` measures them.
    #[pyo3(signature = (textures))]
    fn relit_errors<'py>(
        &self,
        py: Python<'py>,
        textures: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyList>> {
        let p = self.problem(py)?;
        let mut values = Vec::new();
        for (i, (name, shape)) in self.names.iter().zip(&self.shapes).enumerate() {
            let given = match textures {
                Some(d) => d.get_item(name)?,
                None => None,
            };
            values.extend(match given {
                Some(a) => read_array(&format!("texture `{name}`"), &a, shape)?,
                None => released(py, || self.lock().texture(i))?,
            });
        }
        let task = self.task.clone();
        let errors = released(py, move || {
            let gpu = gpu()?;
            let seed = psrestir::optim::pass_seed(
                task.seed,
                u32::MAX - 5,
                0,
                psrestir::optim::Seeds::EVAL,
            );
            let spp = task.target.spp.min(256);
            psrestir::job::relight::task_errors(&gpu, &task, &p, values, spp, seed)
        })?;
        relit_list(py, &errors)
    }
    /// Which texels some camera sample reaches: bool array (height, width).
    fn observed<'py>(
        &self,
        py: Python<'py>,
        texture: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let i = self.index(texture)?;
        let op = self.lock();
        let texels = |t: &psrestir::render::params::ParamTexture| (t.width * t.height) as usize;
        let t = &op.textures()[i];
        let all = op.optimizer().observed_texels().map_err(to_py)?;
        // One flag per texel, the textures one after another.
        let start: usize = op.textures()[..i].iter().map(texels).sum();
        let n = texels(t);
        let v: Vec<bool> = all[start..start + n].to_vec();
        let shape = [t.height as usize, t.width as usize];
        Ok(PyArray1::from_vec(py, v).reshape(shape)?.into_any())
    }

    /// The task's target images (rendered from its target scene, or its photos).
    fn targets<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let p = self.problem(py)?;
        let list = PyList::empty(py);
        for img in &p.targets {
            list.append(image_array(py, img)?)?;
        }
        Ok(list)
    }

    /// The ground-truth values of a texture, when the task's targets come from a scene.
    fn reference<'py>(
        &self,
        py: Python<'py>,
        texture: &Bound<'py, PyAny>,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let i = self.index(texture)?;
        let p = self.problem(py)?;
        let Some(r) = &p.reference else {
            return Ok(None);
        };
        let t = &p.set.textures[i];
        let v = r[t.offset as usize..t.offset as usize + t.len()].to_vec();
        Ok(Some(to_array(py, v, &self.shapes[i])?))
    }

    /// Forget the estimator's state from earlier backward calls.
    fn reset(&self, py: Python<'_>) -> PyResult<()> {
        released(py, || self.lock().reset_estimator())
    }
}

impl DiffRender {
    fn parameter_names(&self) -> Vec<String> {
        let mut n = self.names.clone();
        if self.env_shape.is_some() {
            n.push("environment".into());
        }
        n.push("exposure".into());
        n.push("white_balance".into());
        n
    }

    fn gradient_dict<'py>(
        &self,
        py: Python<'py>,
        g: psrestir::optim::Gradients,
    ) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for ((name, shape), t) in self.names.iter().zip(&self.shapes).zip(g.textures) {
            d.set_item(name, to_array(py, t, shape)?)?;
        }
        if let (Some(e), Some(shape)) = (g.environment, self.env_shape) {
            d.set_item("environment", to_array(py, e, &shape)?)?;
        }
        let n = self.cameras.len();
        d.set_item("exposure", to_array(py, g.exposure, &[n])?)?;
        let wb: Vec<f32> = g.white_balance.iter().flatten().copied().collect();
        d.set_item("white_balance", to_array(py, wb, &[n, 3])?)?;
        Ok(d)
    }

    /// Gradients from a dict like backward's: every texture's (and the environment's where
    /// it is a parameter) required, the gains' zero where absent.
    fn read_gradients(&self, d: &Bound<'_, PyDict>) -> PyResult<psrestir::optim::Gradients> {
        let known = self.parameter_names();
        for k in d.keys() {
            let k: String = k.extract()?;
            if !known.contains(&k) {
                return Err(to_py(Error::Invalid(format!(
                    "step: no parameter `{k}`: the parameters are {known:?}"
                ))));
            }
        }
        let need = |name: &str| -> PyResult<Bound<'_, PyAny>> {
            d.get_item(name)?.ok_or_else(|| {
                to_py(Error::Invalid(format!(
                    "step: the gradients lack `{name}` (give every texture's, and the \
                     environment's when it is a parameter)"
                )))
            })
        };
        let mut textures = Vec::new();
        for (name, shape) in self.names.iter().zip(&self.shapes) {
            textures.push(read_array(
                &format!("the gradient of `{name}`"),
                &need(name)?,
                shape,
            )?);
        }
        let environment = match self.env_shape {
            Some(shape) => Some(read_array(
                "the gradient of `environment`",
                &need("environment")?,
                &shape,
            )?),
            None => None,
        };
        let n = self.cameras.len();
        let exposure = match d.get_item("exposure")? {
            Some(a) => read_array("the gradient of `exposure`", &a, &[n])?,
            None => vec![0.0; n],
        };
        let white_balance = match d.get_item("white_balance")? {
            Some(a) => read_array("the gradient of `white_balance`", &a, &[n, 3])?
                .chunks(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
            None => vec![[0.0; 3]; n],
        };
        Ok(psrestir::optim::Gradients {
            textures,
            environment,
            exposure,
            white_balance,
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, psrestir::optim::DiffRender> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The estimators' names and one-line summaries.
#[pyfunction]
fn estimators() -> Vec<(String, String)> {
    psrestir::Method::all()
        .map(|m| (m.name().to_string(), m.summary().to_string()))
        .collect()
}

/// The adapter psrestir runs on, in words (makes the device at first use).
#[pyfunction]
fn adapter(py: Python<'_>) -> PyResult<String> {
    released(py, || {
        let g = gpu()?;
        Ok(format!(
            "{} ({:?}, {} {})",
            g.info.name, g.info.backend, g.info.driver, g.info.driver_info
        ))
    })
}

/// The exception a library error of kind `kind` becomes (for the tests of the mapping).
#[pyfunction]
fn _error_for_test(kind: &str) -> PyErr {
    let e = match kind {
        "file" => Error::file(Path::new("scene.glb"), "not a glTF file"),
        "no_adapter" => Error::NoAdapter("no Vulkan adapter".into()),
        "unsuitable" => Error::Unsuitable("too few storage buffers".into()),
        "out_of_memory" => Error::OutOfMemory {
            label: "params".into(),
            msg: "allocation failed".into(),
        },
        "device_lost" => Error::DeviceLost {
            label: "render".into(),
            msg: "driver reset".into(),
        },
        "gpu" => Error::Gpu {
            label: "render".into(),
            msg: "validation".into(),
        },
        "panic" => {
            return Python::attach(|py| released::<()>(py, || panic!("test panic")).unwrap_err())
        }
        _ => Error::Invalid(format!("unknown kind {kind}")),
    };
    to_py(e)
}

#[pymodule]
fn _psrestir(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let _ = env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn"))
        .try_init();
    m.add_class::<DiffRender>()?;
    m.add_function(wrap_pyfunction!(optimize, m)?)?;
    m.add_function(wrap_pyfunction!(estimators, m)?)?;
    m.add_function(wrap_pyfunction!(adapter, m)?)?;
    m.add_function(wrap_pyfunction!(_error_for_test, m)?)?;
    Ok(())
}
