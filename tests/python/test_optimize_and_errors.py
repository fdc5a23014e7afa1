"""The whole task in one call, Ctrl-C and callback exceptions that stop it cleanly, and the
exception classes."""

import json
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import psrestir
from conftest import ROOT, small_task


def test_optimize_a_dict_task_returns_errors_textures_and_outputs(tmp_path):
    rows = []
    task = small_task(tmp_path / "run", resolution=(16, 8), iterations=6)
    r = psrestir.optimize(task, method="baseline", progress=False, callback=rows.append)
    assert isinstance(r, psrestir.Result)
    assert r.iterations == 6 and not r.interrupted
    # Too short a run for the loss watch to judge (it needs two disjoint windows of 20).
    assert r.warnings == []
    assert [row["iteration"] for row in rows] == [1, 2, 3, 4, 5, 6]
    assert all(np.isfinite(row["loss"]) for row in rows)
    assert r.final_rmse_observed < r.initial_rmse_observed
    tex = r.textures["sphere_base_color"]
    assert tex.dtype == np.float32 and tex.shape == (8, 16, 3)
    assert os.path.samefile(r.out, tmp_path / "run")
    for f in ["metrics.csv", "checkpoint.bin", "sphere_base_color.exr", "optimized.glb",
              "uncertainty_sphere_base_color.exr", "uncertainty_sphere_base_color.png"]:
        assert (tmp_path / "run" / f).exists(), f
    # What the images could not tell: a standard deviation per texel with a gradient, -1 for
    # the unobserved ones (and for an observed edge texel no sample reached in 6 iterations).
    u = r.uncertainty["sphere_base_color"]
    assert u.shape == (8, 16, 3) and u.dtype == np.float32
    seen = psrestir.DiffRender(task, method="baseline").observed(0)
    assert (u[~seen] == -1).all() and ((u[seen] > 0) | (u[seen] == -1)).all()
    assert (u[seen] > 0).mean() > 0.8
    # No environment is recovered and no relighting asked for; the gains stay at 1.
    assert r.environment is None and r.relit == []
    assert r.exposure == [1.0] and r.white_balance == [[1.0, 1.0, 1.0]]
    # Resuming continues from the checkpoint: two more iterations, not eight; with the
    # default progress display (the task's own budget, then an iteration count).
    r2 = psrestir.optimize(task, resume=True)
    assert r2.iterations == 6
    r3 = psrestir.optimize(task, iterations=8, resume=True)
    assert r3.iterations == 8


def test_optimize_a_task_file_with_keyword_options(tmp_path):
    task = small_task(tmp_path / "out_file", iterations=50)
    toml = tmp_path / "task.toml"
    lines = [
        f'scene = {json.dumps(task["scene"])}',
        'cameras = ["main"]',
        "width = 32",
        "height = 32",
        f'env = {json.dumps(task["env"])}',
        "[target]",
        f'scene = {json.dumps(task["scene"])}',
        "[optimizer]",
        "iterations = 50",
        "[[textures]]",
        'material = "sphere"',
        'slot = "roughness"',
        "resolution = [4, 4]",
        "init = 0.5",
        "learning_rate = 0.02",
    ]
    toml.write_text("\n".join(lines) + "\n")
    r = psrestir.optimize(
        str(toml), iterations=3, out=tmp_path / "kw", method="restir", progress=False
    )
    assert r.iterations == 3
    assert r.textures["sphere_roughness"].shape == (4, 4, 1)
    assert os.path.samefile(r.out, tmp_path / "kw")


def test_an_exception_in_the_callback_stops_the_run_with_its_checkpoint(tmp_path):
    class Stop(Exception):
        pass

    def callback(row):
        if row["iteration"] == 2:
            raise Stop("enough")

    task = small_task(tmp_path / "stopped", iterations=50)
    with pytest.raises(Stop, match="enough"):
        psrestir.optimize(task, progress=False, callback=callback)
    assert (tmp_path / "stopped" / "checkpoint.bin").exists()
    r = psrestir.optimize(task, iterations=4, resume=True, progress=False)
    assert r.iterations == 4


def test_ctrl_c_stops_cleanly_with_the_checkpoint_written(tmp_path):
    """A real SIGINT to a process running optimize: KeyboardInterrupt once the iteration
    under way is done, with the checkpoint and outputs written."""
    task = small_task(tmp_path / "sigint", time_budget_s=100.0)
    del task["optimizer"]["iterations"]
    # A process started in the background by a non-interactive shell inherits SIGINT ignored,
    # and Python then installs no KeyboardInterrupt handler: install it, as an interactive
    # interpreter has it.
    script = textwrap.dedent(
        f"""
        import json, signal, sys, psrestir
        signal.signal(signal.SIGINT, signal.default_int_handler)
        def cb(row):
            if row["iteration"] == 1:
                print("started", flush=True)
        try:
            psrestir.optimize(json.loads({json.dumps(json.dumps(task))}), progress=False, callback=cb)
        except KeyboardInterrupt as e:
            print("interrupted:", e, flush=True)
            sys.exit(3)
        """
    )
    p = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        line = p.stdout.readline()
        assert line.strip() == "started", (line, p.stderr.read() if p.poll() is not None else "")
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=120)
    finally:
        p.kill()
    assert p.returncode == 3, (out, err)
    assert "resume=True" in out
    assert (tmp_path / "sigint" / "checkpoint.bin").exists()
    assert (tmp_path / "sigint" / "sphere_base_color.exr").exists()


def test_bad_task_files_raise_file_error_with_the_path(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(psrestir.FileError) as e:
        psrestir.optimize(str(missing), progress=False)
    assert e.value.path == str(missing) and isinstance(e.value, OSError)
    bad = tmp_path / "bad.toml"
    bad.write_text("scene = 3\n")
    with pytest.raises(psrestir.FileError, match="bad.toml"):
        psrestir.DiffRender(str(bad))
    task = small_task(tmp_path / "x")
    task["textures"][0]["material"] = "marble"
    with pytest.raises(psrestir.FileError, match="no material `marble`"):
        psrestir.DiffRender(task)
    with pytest.raises(psrestir.InvalidArgument, match="task file's path or a dict"):
        psrestir.optimize(42)


@pytest.mark.parametrize(
    "kind, cls, says",
    [
        ("file", psrestir.FileError, "scene.glb: not a glTF file"),
        ("no_adapter", psrestir.AdapterError, "no Vulkan adapter"),
        ("unsuitable", psrestir.AdapterError, "too few storage buffers"),
        ("out_of_memory", psrestir.GpuOutOfMemory, "del"),
        ("device_lost", psrestir.DeviceLost, "resume=True"),
        ("gpu", psrestir.GpuError, "validation"),
        ("panic", psrestir.PsrestirError, "internal error"),
    ],
)
def test_each_library_error_becomes_its_class(kind, cls, says):
    from psrestir._psrestir import _error_for_test

    e = _error_for_test(kind)
    assert type(e) is cls and isinstance(e, psrestir.PsrestirError)
    assert says in str(e)
    assert "--" not in str(e), "a Python message names no command-line flag"


def test_no_vulkan_driver_is_an_adapter_error():
    env = dict(os.environ, VK_ICD_FILENAMES="/nonexistent.json", VK_DRIVER_FILES="/nonexistent.json")
    script = (
        "import psrestir\n"
        "try:\n"
        "    psrestir.adapter()\n"
        "except psrestir.AdapterError as e:\n"
        "    print('AdapterError:', e)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.stdout.startswith("AdapterError:"), (out.stdout, out.stderr)
    assert "lavapipe" in out.stdout


def test_the_package_imports_without_torch():
    out = subprocess.run(
        [sys.executable, "-c", "import sys, psrestir; print('torch' in sys.modules)"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert out.stdout.strip() == "False", out.stderr
