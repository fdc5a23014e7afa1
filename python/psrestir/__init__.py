"""psrestir: inverse texture optimization on wgpu with parameter-space ReSTIR gradients.

Two ways in:

- :func:`optimize` runs a whole task (a task file's path, or the same content as a dict) as
  ``psrestir optimize`` does, with a progress bar or callback, and returns a :class:`Result`.
- :class:`DiffRender` is a differentiable render with the loss and the optimizer left to you:
  set the textures from numpy arrays, :meth:`~DiffRender.render` the cameras, compute dL/dI
  of any loss, and :meth:`~DiffRender.backward` returns each texture's gradient with the
  chosen estimator (``baseline``, ``restir`` or ``recursive``), which keeps its state from
  one call to the next. ``psrestir.torch`` wraps it as a ``torch.autograd.Function``.

Arrays are float32 numpy arrays of shape (height, width, channels). GPU work runs with the
interpreter released, on one device per process. Errors are the classes of
:mod:`psrestir.errors`.
"""

import json as _json
import os as _os
import sys as _sys
import time as _time
import warnings as _warnings
from dataclasses import dataclass as _dataclass, field as _field

from . import errors
from ._psrestir import DiffRender as _NativeDiffRender
from ._psrestir import adapter, estimators
from ._psrestir import optimize as _optimize
from .errors import (
    AdapterError,
    DeviceLost,
    FileError,
    GpuError,
    GpuOutOfMemory,
    InvalidArgument,
    PsrestirError,
)

__all__ = [
    "optimize",
    "Result",
    "DiffRender",
    "Step",
    "estimators",
    "adapter",
    "errors",
    "PsrestirError",
    "FileError",
    "InvalidArgument",
    "AdapterError",
    "GpuOutOfMemory",
    "DeviceLost",
    "GpuError",
]


def _task_args(task, base_dir):
    """(path, json, base) for the native calls: a task file's path, or a dict's content."""
    if isinstance(task, dict):
        base = _os.fspath(base_dir) if base_dir is not None else _os.getcwd()
        return None, _json.dumps(task), base
    if isinstance(task, (str, bytes, _os.PathLike)):
        path = _os.fsdecode(_os.fspath(task))
        return path, None, _os.path.dirname(path) or "."
    raise InvalidArgument(
        f"task: expected a task file's path or a dict, got {type(task).__name__}"
    )


@_dataclass
class Result:
    """What :func:`optimize` did."""

    #: Iterations done in total (including any before a resume).
    iterations: int
    #: Optimization seconds in total (target rendering and evaluations excluded).
    elapsed_s: float
    ms_per_iteration: float
    final_loss: float
    #: Texture RMSE against the ground truth at the start and the end (None without one).
    initial_rmse: float | None
    final_rmse: float | None
    #: The same over the texels some camera observes (the ones the images determine).
    initial_rmse_observed: float | None
    final_rmse_observed: float | None
    #: The output folder (textures, optimized.glb, metrics.csv, plot.png, checkpoint.bin).
    out: str
    #: The final textures by name (``material_slot``), float32 (height, width, channels).
    textures: dict = _field(default_factory=dict)
    #: Per texture: (initial, final) observed-texel RMSE, when the ground truth is known.
    rmse_observed_per_texture: dict = _field(default_factory=dict)
    #: Whether the run stopped early (Ctrl-C or an exception in the callback).
    interrupted: bool = False
    #: What the run warned of (also raised as ``RuntimeWarning``): a loss that had not fallen
    #: below its start after a quarter of the budget, with what to try.
    warnings: list = _field(default_factory=list)
    #: Why the run ended before its budget because it had converged (the task's
    #: ``stop_on_plateau``), or None.
    plateau: str | None = None
    #: The iteration whose state the outputs hold where it is not the last: an earlier
    #: evaluation had a lower image error (the task's ``keep_best``; 0: the start, which the
    #: run could not improve on), else None.
    kept_iteration: int | None = None
    #: The recovered environment, float32 (height, width, 3) linear radiance, row 0 at the
    #: zenith, when the task recovers it; else None.
    environment: object = None
    #: The relit errors under the task's ``relight`` environments (relight.csv): a list of
    #: dicts with ``environment``, ``relmse``, ``psnr`` and ``scale``; empty without them.
    relit: list = _field(default_factory=list)
    #: Each texel's standard deviation by texture name, float32 like the texture, -1 where the
    #: images tell nothing of it (unobserved, or never given a gradient); the
    #: ``uncertainty_*.exr`` outputs (docs/guide.md, the outputs of ``optimize``). None when no
    #: iteration ran.
    uncertainty: dict | None = None
    #: Each camera's final exposure, and white balance (three factors).
    exposure: list = _field(default_factory=list)
    white_balance: list = _field(default_factory=list)


class _Bar:
    """A one-line progress display on ``sys.stderr`` (which notebooks show)."""

    def __init__(self, iterations, time_budget):
        self.iterations = iterations
        self.time_budget = time_budget
        self.last = 0.0

    def __call__(self, row):
        now = _time.monotonic()
        if now - self.last < 0.2:
            return
        self.last = now
        if self.iterations:
            done = f"{row['iteration']}/{self.iterations} iterations"
        elif self.time_budget:
            done = f"{row['elapsed_s']:.0f}/{self.time_budget:.0f} s, iteration {row['iteration']}"
        else:  # the task's own budget
            done = f"iteration {row['iteration']}, {row['elapsed_s']:.1f} s"
        parts = [done]
        if row.get("loss") is not None:
            parts.append(f"loss {row['loss']:.4e}")
        if row.get("texture_rmse_observed") is not None:
            parts.append(f"texture RMSE {row['texture_rmse_observed']:.4f}")
        _sys.stderr.write("\r" + ", ".join(parts) + " " * 4)
        _sys.stderr.flush()

    def close(self):
        _sys.stderr.write("\n")
        _sys.stderr.flush()


def optimize(
    task,
    *,
    method="auto",
    iterations=None,
    time_budget=None,
    out=None,
    resume=False,
    progress=True,
    callback=None,
    base_dir=None,
):
    """Run a whole task, as ``psrestir optimize`` does, and return a :class:`Result`.

    ``task`` is a task file's path or the same content as a dict (relative paths in it
    resolve against ``base_dir``, by default the working directory; its outputs go to its
    ``output`` key or ``out/dict_task``). ``method`` is ``"auto"``, ``"baseline"``,
    ``"restir"`` or ``"recursive"``; ``iterations`` and ``time_budget`` (seconds) override the
    task's; ``out`` the output folder; ``resume=True`` continues from its checkpoint.
    ``progress`` shows a one-line progress display on stderr; ``callback(row)`` is called
    after each iteration with a dict (iteration, elapsed_s, loss, texture_rmse,
    texture_rmse_observed, image_relmse, learning_rate, image_relmse_expected).

    Ctrl-C stops the run after the iteration under way, writes the checkpoint and outputs,
    and raises ``KeyboardInterrupt`` (continue with ``resume=True``); an exception raised by
    ``callback`` stops it the same way and is raised then.
    """
    path, text, base = _task_args(task, base_dir)
    bar = _Bar(iterations, time_budget) if progress else None

    def on_row(row):
        if bar is not None:
            bar(row)
        if callback is not None:
            callback(row)

    try:
        r = _optimize(
            path,
            text,
            base,
            method,
            iterations,
            time_budget,
            None if out is None else _os.fspath(out),
            resume,
            on_row,
        )
    finally:
        if bar is not None:
            bar.close()
    error = r.pop("error", None)
    result = Result(**r)
    for w in result.warnings:
        _warnings.warn(w, RuntimeWarning, stacklevel=2)
    if error is not None:
        if isinstance(error, KeyboardInterrupt):
            raise KeyboardInterrupt(
                f"interrupted at iteration {result.iterations}; the checkpoint and outputs are "
                f"in {result.out}: continue with psrestir.optimize(task, out={result.out!r}, "
                "resume=True)"
            )
        raise error
    return result


class DiffRender:
    """A differentiable render of a task's scene with your own loss.

    ``task`` (a task file's path or a dict, as for :func:`optimize`) gives the scene, its
    lights and environment, the cameras, the image size, the path depth, the parameters (the
    textures at their ``init`` values, the environment when its ``[environment]`` table
    recovers it, each camera's exposure and white balance), the gradient samples per pixel,
    the seed, and the optimizer that :class:`Step` runs (its step, priors, schedule and
    primal); its targets are what :meth:`targets` returns. ``method`` picks the gradient
    estimator: ``"auto"`` (chosen with the whole configuration as :func:`optimize` chooses),
    ``"baseline"`` (plain Monte Carlo), ``"restir"`` (parameter-space ReSTIR, which reuses
    samples from earlier backward calls) or ``"recursive"`` (a recursive control variate).

    One iteration::

        images = op.render(spp=4, seed=it)
        adjoints = [dloss_dimage(img, k) for k, img in enumerate(images)]
        grads = op.backward(adjoints)           # {name: array like the parameter}
        step()                                  # step = psrestir.Step(op), or your own

    Each backward pairs with the render before it: a backward with no render since the last
    parameter change or backward raises :class:`InvalidArgument`. The estimator's state
    advances once per backward (ReSTIR reuses the previous call's samples under the current
    textures and adjoint).
    """

    def __init__(self, task, *, method="auto", base_dir=None):
        path, text, base = _task_args(task, base_dir)
        self._op = _NativeDiffRender(path, text, base, method)

    @classmethod
    def from_scene(
        cls,
        scene,
        textures,
        *,
        cameras=None,
        width=256,
        height=256,
        env=None,
        max_depth=1,
        spp_grad=1,
        seed=1,
        filter="bilinear",
        method="baseline",
        lights=None,
    ):
        """A differentiable render of a glTF file without a task file.

        ``textures`` lists what to recover, each ``(material, slot, (width, height))`` or
        ``(material, slot, (width, height), init)`` with ``slot`` one of ``"base_color"``,
        ``"roughness"``, ``"metallic"``, ``"normal"`` (``init``: a value or an RGB triple; by
        default 0.5 gray, roughness 0.5, metallic 0, a flat normal map [0.5, 0.5, 1]). ``cameras`` names the file's cameras (None: all);
        ``env`` an environment map (lat-long EXR or HDR); ``max_depth`` the path depth
        (1: direct light); ``lights`` the punctual lights on in each camera's capture,
        ``{camera: [light, ...]}`` by name (None: every light in every capture; photos of one
        object under one light at a time are cameras at the same pose with different lights).
        :meth:`targets` renders the file's own materials.
        """
        defaults = {
            "base_color": [0.5, 0.5, 0.5],
            "roughness": 0.5,
            "metallic": 0.0,
            "normal": [0.5, 0.5, 1.0],
        }
        specs = []
        for t in textures:
            if len(t) not in (3, 4):
                raise InvalidArgument(
                    f"textures: expected (material, slot, (width, height)[, init]), got {t!r}"
                )
            material, slot, resolution = t[0], t[1], t[2]
            init = t[3] if len(t) == 4 else defaults.get(slot, 0.5)
            specs.append(
                {
                    "material": material,
                    "slot": slot,
                    "resolution": list(resolution),
                    "init": init,
                    "learning_rate": 0.01,
                }
            )
        scene = _os.path.abspath(_os.fspath(scene))
        task = {
            "scene": scene,
            "width": width,
            "height": height,
            "seed": seed,
            "max_depth": max_depth,
            "target": {"scene": scene},
            "optimizer": {"iterations": 1, "gradient_spp": spp_grad, "filter": filter},
            "textures": specs,
        }
        if cameras is not None:
            task["cameras"] = list(cameras)
        if env is not None:
            task["env"] = _os.path.abspath(_os.fspath(env))
        if lights is not None:
            task["target"]["lights"] = {c: list(names) for c, names in dict(lights).items()}
        return cls(task, method=method)

    @property
    def texture_names(self):
        """The optimized textures, ``material_slot``, in the task's order."""
        return self._op.texture_names

    @property
    def texture_shapes(self):
        """{name: (height, width, channels)}."""
        return dict(self._op.texture_shapes)

    @property
    def camera_names(self):
        """The cameras, in the order of :meth:`render`'s images."""
        return self._op.camera_names

    @property
    def image_shape(self):
        """(height, width) of every image."""
        return self._op.image_shape

    @property
    def method(self):
        """The gradient estimator in use."""
        return self._op.method

    @property
    def iteration(self):
        """Backward calls so far."""
        return self._op.iteration

    def texture(self, name):
        """A copy of a texture's current values (by name or index): float32 (h, w, c)."""
        return self._op.texture(name)

    def set_texture(self, name, values):
        """Replace a texture's values: a float32 array of its shape, finite, within its
        slot's range (base color, metallic and normal maps [0, 1], roughness [0.02, 1])."""
        self._op.set_texture(name, values)

    def render(self, spp=4, seed=0, primal=None):
        """Render every camera at the current parameters: a list of float32 (h, w, 3) linear
        RGB images, each multiplied by its camera's exposure and white balance (what a loss
        compares with a photo). ``seed`` picks the random numbers (use a new one each
        iteration). ``primal``: ``"independent"`` (a fresh render), ``"control_variate"``
        (the render carried over from the previous one through a control variate: the same
        mean, far less noise once the parameters move slowly) or None, the task's
        (:attr:`primal`)."""
        return self._op.render(spp, seed, primal)

    @property
    def primal(self):
        """The primal :meth:`render` uses by default: the task's ``primal``."""
        return self._op.primal

    def backward(self, adjoints, seed_grad=None):
        """Every parameter's gradient of a loss whose derivative with respect to the images
        of the last :meth:`render` is ``adjoints`` (a list of float32 (h, w, 3) arrays, one
        per camera): {name: float32 array of the parameter's shape}, the names of
        :meth:`parameters`. The textures' and the environment's come from the estimator;
        the exposures' and white balances' are exact for the rendered images (the sum over
        pixels of adjoint times render). ``seed_grad`` picks the gradient samples' random
        numbers (mixed with the number of backward calls; None: the task's seed); they are
        independent of the render's."""
        return self._op.backward(list(adjoints), seed_grad)

    def gradient_variance(self):
        """{texture name: the variance of each value of the last gradient estimate}, where
        the estimator tracks one (``recursive``; ``restir`` with its ``own_variance``
        option); else None."""
        return self._op.gradient_variance()

    @property
    def parameter_names(self):
        """The parameters' names: the textures', ``environment`` (when the task recovers
        it), ``exposure`` and ``white_balance``."""
        return self._op.parameter_names

    def parameters(self):
        """A copy of every parameter by name: each texture, ``environment`` (float32
        (h, w, 3) linear radiance, row 0 at the zenith) when the task recovers it,
        ``exposure`` (n_cameras,) and ``white_balance`` (n_cameras, 3)."""
        return self._op.parameters()

    def set_parameters(self, values):
        """Set parameters from a dict like :meth:`parameters`'s (any subset): float32 arrays
        of the parameters' shapes; textures within their slot's range, the environment,
        exposures and white balances positive."""
        for name, value in values.items():
            self._op.set_parameter(name, value)

    def relit_errors(self, textures=None):
        """The relit errors of ``textures`` (a dict by name; None: the current ones) under
        the task's ``relight`` environments, as :func:`optimize` measures them: a list of
        dicts (``environment``, ``relmse``, ``psnr``, ``scale``); empty without them or
        without a ground truth."""
        return self._op.relit_errors(textures)

    def observed(self, name):
        """bool (h, w): the texels some camera sample reaches (the others get no gradient)."""
        return self._op.observed(name)

    def targets(self):
        """The task's target images, float32 (h, w, 3), one per camera (rendered from its
        target scene at the first call and cached in its output folder, or its photos)."""
        return self._op.targets()

    def reference(self, name):
        """The true values of a texture when the task's targets come from a scene, else
        None."""
        return self._op.reference(name)

    def reset(self):
        """Forget the estimator's state from earlier backward calls."""
        self._op.reset()

    def __repr__(self):
        h, w = self.image_shape
        return (
            f"DiffRender(method={self.method!r}, textures={self.texture_shapes}, "
            f"cameras={self.camera_names}, image={w}x{h})"
        )


class Step:
    """psrestir's own optimizer step for the gradients your loop computes, with your loss.

    It runs the same GPU passes as :func:`optimize`: the task's step (the variance-scaled
    step or Adam, with filtered moments), its priors (smoothness, the multiscale gradient),
    its learning rates and schedule, and where the task recovers them the environment's and
    the gains' Adam, with ``auto``'s choices where the task leaves them to it. It updates
    ``op``'s parameters in place::

        step = psrestir.Step(op)                # the task's iterations or time budget
        for it in range(step.iterations):
            images = op.render(spp=4, seed=it)  # the task's primal (control variate or not)
            grads = op.backward(my_adjoints(images))
            step()                              # or step(grads) with gradients you changed

    ``iterations`` and ``time_budget`` (seconds) set the run the learning-rate schedule
    decays over (by default the task's); the schedule's progress is the larger of the
    steps' and the elapsed time's fractions, as in :func:`optimize`.
    """

    def __init__(self, op, *, iterations=None, time_budget=None):
        if not isinstance(op, DiffRender):
            raise InvalidArgument(f"Step: expected a psrestir.DiffRender, got {type(op).__name__}")
        task_iterations, task_budget = op._op.budget()
        if iterations is None and time_budget is None:
            iterations, time_budget = task_iterations, task_budget
        for name, v in (("iterations", iterations), ("time_budget", time_budget)):
            if v is not None and not v > 0:
                raise InvalidArgument(f"Step: {name} must be positive, not {v!r}")
        self.op = op
        self.iterations = iterations
        self.time_budget = time_budget
        self._start = None

    def _progress(self):
        # The run loop's own measure of the run's progress (psrestir's Limits::progress).
        return self.op._op.run_progress(self.iterations, self.time_budget, self.elapsed_s)

    @property
    def steps(self):
        """Steps taken."""
        return self.op._op.steps

    @property
    def elapsed_s(self):
        """Seconds since the first step."""
        return 0.0 if self._start is None else _time.monotonic() - self._start

    @property
    def done(self):
        """Whether the iterations or the time budget are spent."""
        return self._progress() >= 1.0

    def __call__(self, grads=None):
        """Update the parameters from the last :meth:`DiffRender.backward`'s gradient
        (``grads`` None) or from ``grads``, a dict like backward's (every texture's, the
        environment's where it is a parameter; the gains' zero where absent). A step
        without a backward since the last one, and no ``grads``, raises
        :class:`InvalidArgument`."""
        if self._start is None:
            self._start = _time.monotonic()
        self.op._op.set_progress(self._progress())
        self.op._op.step(grads)
        # The next backward's estimator reads the schedule too.
        self.op._op.set_progress(self._progress())

    def step(self, grads=None):
        """The same as calling the step."""
        self(grads)

    @property
    def learning_rates(self):
        """Each texture's learning rate in the last step (the schedule's factor applied)."""
        return self.op._op.learning_rates()

    def __repr__(self):
        return (
            f"Step(iterations={self.iterations}, time_budget={self.time_budget}, "
            f"steps={self.steps})"
        )
