"""Every parameter by name, the environment's and the gains' derivatives against finite
differences, and psrestir.Step: the built-in optimizer for gradients a Python loop computes,
with its misuse errors."""

import numpy as np
import pytest

import psrestir
from conftest import small_task


def env_task(out, **optimizer):
    """small_task with its environment recovered from gray on a 4 x 2 map."""
    t = small_task(out, resolution=(4, 2), **optimizer)
    t["environment"] = {"resolution": [4, 2], "init": 0.5, "learning_rate": 0.05}
    return t


@pytest.fixture(scope="module")
def env_op(out_dir):
    return psrestir.DiffRender(env_task(out_dir / "env"), method="baseline")


def test_every_parameter_by_name(env_op):
    op = env_op
    assert op.parameter_names == ["sphere_base_color", "environment", "exposure", "white_balance"]
    p = op.parameters()
    assert list(p) == op.parameter_names
    assert p["environment"].shape == (2, 4, 3) and p["environment"].dtype == np.float32
    np.testing.assert_allclose(p["environment"], 0.5, rtol=1e-6)
    np.testing.assert_array_equal(p["exposure"], [1.0])
    np.testing.assert_array_equal(p["white_balance"], [[1.0, 1.0, 1.0]])
    # The render is what a loss compares: the camera's exposure times white balance times
    # the linear render (the same seed gives the same samples).
    plain = op.render(spp=2, seed=4)[0]
    op.set_parameters({"exposure": np.array([2.0], np.float32),
                       "white_balance": np.array([[1.0, 0.5, 1.5]], np.float32)})
    gained = op.render(spp=2, seed=4)[0]
    np.testing.assert_allclose(gained, plain * np.array([2.0, 1.0, 3.0]), rtol=1e-5, atol=1e-7)
    sky = np.random.default_rng(2).uniform(0.2, 2.0, (2, 4, 3)).astype(np.float32)
    op.set_parameters({"environment": sky, "exposure": np.ones(1, np.float32),
                       "white_balance": np.ones((1, 3), np.float32)})
    np.testing.assert_allclose(op.parameters()["environment"], sky, rtol=1e-5)
    op.render(spp=1, seed=5)
    grads = op.backward([np.ones((32, 32, 3), np.float32)])
    assert list(grads) == op.parameter_names
    assert grads["environment"].shape == (2, 4, 3) and np.abs(grads["environment"]).sum() > 0


@pytest.mark.parametrize(
    "name, value, says",
    [
        ("exposure", np.ones(2, np.float32), "shape (1,)"),
        ("white_balance", np.ones(3, np.float32), "shape (1, 3)"),
        ("environment", np.ones((4, 2, 3), np.float32), "shape (2, 4, 3)"),
        ("environment", np.zeros((2, 4, 3), np.float32), "finite and positive"),
        ("exposure", np.zeros(1, np.float32), "positive"),
        ("sky", np.ones(1, np.float32), "no parameter `sky`"),
    ],
)
def test_bad_parameters_are_refused(env_op, name, value, says):
    before = env_op.parameters()
    with pytest.raises(psrestir.InvalidArgument) as e:
        env_op.set_parameters({name: value})
    assert says in str(e.value)
    after = env_op.parameters()
    for k in before:
        np.testing.assert_array_equal(before[k], after[k])


def test_the_environment_is_no_parameter_where_the_task_does_not_recover_it(out_dir):
    op = psrestir.DiffRender(small_task(out_dir / "noenv"), method="baseline")
    assert op.parameter_names == ["sphere_base_color", "exposure", "white_balance"]
    with pytest.raises(psrestir.InvalidArgument, match="does not recover its environment"):
        op.set_parameters({"environment": np.ones((2, 4, 3), np.float32)})


def test_the_gains_derivatives_are_exact_for_the_render(env_op):
    """dL/d(exposure) and dL/d(white balance) of an L2 loss of one render against central
    differences of the same render (same seed: the same samples, so only float rounding
    separates them)."""
    op = env_op
    target = op.targets()[0].astype(np.float64)
    e0 = np.array([1.3], np.float32)
    wb0 = np.array([[0.9, 1.1, 1.2]], np.float32)

    def loss(e, wb):
        op.set_parameters({"exposure": e, "white_balance": wb})
        img = op.render(spp=2, seed=11)[0].astype(np.float64)
        return float(np.mean((img - target) ** 2)), img

    _, img = loss(e0, wb0)
    g = op.backward([((2.0 / img.size) * (img - target)).astype(np.float32)])
    h = 1e-2
    fd_e = (loss(e0 + h, wb0)[0] - loss(e0 - h, wb0)[0]) / (2 * h)
    fd_wb = []
    for c in range(3):
        d = np.zeros((1, 3), np.float32)
        d[0, c] = h
        fd_wb.append((loss(e0, wb0 + d)[0] - loss(e0, wb0 - d)[0]) / (2 * h))
    # The loss is quadratic in each gain: the central difference is exact up to float32
    # rounding of the images (relative 1e-6 per pixel, summed over 3072 values).
    np.testing.assert_allclose(g["exposure"], [fd_e], rtol=1e-3)
    np.testing.assert_allclose(g["white_balance"][0], fd_wb, rtol=1e-3)


def test_the_environment_gradient_matches_finite_differences(out_dir):
    """The mean of many baseline estimates of dL/d(radiance) of the environment's texels
    under adjoints of independent renders against central finite differences of the L2
    loss, as tests/gradient.rs checks the textures' (same unbiased loss estimate, same
    tolerance), on one channel of four of the 8 texels (both rows, every channel)."""
    op = psrestir.DiffRender(env_task(out_dir / "env_fd"), method="baseline")
    target = op.targets()[0]
    sky = np.random.default_rng(5).uniform(0.3, 1.5, (2, 4, 3)).astype(np.float32)
    op.set_parameters({"environment": sky})
    n_pix = target.size
    k = 48
    grads = []
    for it in range(k):
        img = op.render(spp=16, seed=1000 + it)[0]
        grads.append(op.backward([(2.0 / n_pix) * (img - target)], seed_grad=7)["environment"])
    grads = np.array(grads, np.float64)
    entries = [(0, 0, 0), (0, 3, 1), (1, 1, 2), (1, 2, 0)]
    mean = np.array([grads[:, j, i, c].mean() for j, i, c in entries])
    var_mean = np.array([grads[:, j, i, c].var(ddof=1) / k for j, i, c in entries])

    h, spp = 0.05, 256

    def loss(env, seed):
        op.set_parameters({"environment": env})
        a = op.render(spp=spp, seed=seed)[0].astype(np.float64)
        b = op.render(spp=spp, seed=seed + 1)[0].astype(np.float64)
        return float(np.sum((a - target) * (b - target))) / n_pix

    fd = np.zeros(len(entries))
    fd_var = np.zeros(len(entries))
    for n, (j, i, c) in enumerate(entries):
        reps = []
        for r in range(2):
            plus, minus = sky.copy(), sky.copy()
            plus[j, i, c] += h
            minus[j, i, c] -= h
            seed = 5000 + 10 * r
            reps.append((loss(plus, seed) - loss(minus, seed)) / (2 * h))
        fd[n] = 0.5 * (reps[0] + reps[1])
        fd_var[n] = 0.25 * (reps[0] - reps[1]) ** 2
    scale = np.abs(fd).max()
    assert scale > 0, "all finite differences are zero: the test sees nothing"
    tol = 4 * np.sqrt(var_mean + fd_var) + 0.05 * np.abs(fd) + 1e-3 * scale
    assert (np.abs(mean - fd) <= tol).all(), (mean, fd, tol)


def test_a_step_needs_a_gradient_of_the_right_shape(out_dir):
    op = psrestir.DiffRender(env_task(out_dir / "misuse"), method="baseline")
    step = psrestir.Step(op, iterations=10)
    with pytest.raises(psrestir.InvalidArgument, match="step needs a gradient"):
        step()
    img = op.render(spp=1, seed=0)[0]
    grads = op.backward([np.zeros_like(img)])
    step()
    # Each backward's gradient serves one step.
    with pytest.raises(psrestir.InvalidArgument, match="step needs a gradient"):
        step()
    bad = dict(grads, sphere_base_color=np.zeros((4, 2, 3), np.float32))
    with pytest.raises(psrestir.InvalidArgument, match=r"shape \(2, 4, 3\)"):
        step(bad)
    with pytest.raises(psrestir.InvalidArgument, match="lack `environment`"):
        step({"sphere_base_color": grads["sphere_base_color"]})
    with pytest.raises(psrestir.InvalidArgument, match="no parameter `albedo`"):
        step(dict(grads, albedo=grads["sphere_base_color"]))
    with pytest.raises(psrestir.InvalidArgument, match="not finite"):
        step(dict(grads, environment=np.full((2, 4, 3), np.nan, np.float32)))
    with pytest.raises(psrestir.InvalidArgument, match="iterations must be positive"):
        psrestir.Step(op, iterations=0)
    assert step.steps == 1


def test_a_step_for_a_given_gradient_is_the_tasks_adam(out_dir):
    """With the task's step Adam (no priors, no schedule), a first step from a given gradient
    moves each texel by the learning rate against the gradient's sign (Adam's bias-corrected
    first step is g / |g|), clamped to the slot's range; a texel whose gradient is zero stays."""
    task = small_task(out_dir / "adam", resolution=(4, 2), step="adam", smoothness=0.0,
                      multiscale_levels=0)
    op = psrestir.DiffRender(task, method="baseline")
    before = op.texture(0)
    rng = np.random.default_rng(3)
    g = (rng.choice([-1, 1], (2, 4, 3)) * rng.uniform(1e-3, 2e-3, (2, 4, 3))).astype(np.float32)
    g[0, 0] = 0.0
    step = psrestir.Step(op, iterations=1)
    step({"sphere_base_color": g})
    lr = step.learning_rates["sphere_base_color"]
    assert lr == pytest.approx(0.02)
    expect = np.clip(before - lr * g / (np.abs(g) + 1e-8), 0.0, 1.0)  # Adam's eps: 1e-8
    np.testing.assert_allclose(op.texture(0), expect, atol=1e-6)


def test_the_python_loop_with_step_ends_where_optimize_ends(out_dir):
    """The same task (the default task's configuration in miniature: variance-scaled step,
    filtered moments, smoothness, multiscale gradient, cosine schedule, control-variate
    primal) run by `optimize` and by a Python loop with its own L2 loss and Step: the loop's
    observed-texel error ends within 15% of optimize's (different random streams; measured
    ratios in docs/python.md)."""
    task = small_task(
        out_dir / "loop", resolution=(16, 8), iterations=40, step="variance",
        primal="control_variate", multiscale_levels=2, smoothness=0.01,
        schedule={"kind": "cosine", "final": 0.05}, moment_filter={"levels": 2},
    )
    task["textures"][0]["learning_rate"] = 0.05
    r = psrestir.optimize(task, method="baseline", progress=False, out=out_dir / "loop_cli")
    op = psrestir.DiffRender(task, method="baseline")
    assert op.primal == "control_variate"
    name = op.texture_names[0]
    target = op.targets()[0]
    truth, seen = op.reference(name), op.observed(name)
    step = psrestir.Step(op)
    assert step.iterations == 40
    start = float(np.sqrt(np.mean((op.texture(name)[seen] - truth[seen]) ** 2)))
    for it in range(step.iterations):
        img = op.render(spp=4, seed=it)[0]
        op.backward([(2.0 / img.size) * (img - target)])
        step()
    assert step.done
    end = float(np.sqrt(np.mean((op.texture(name)[seen] - truth[seen]) ** 2)))
    assert start == pytest.approx(r.initial_rmse_observed, rel=1e-4)
    assert end < 0.75 * start, (start, end)
    assert end <= 1.15 * r.final_rmse_observed, (end, r.final_rmse_observed)


def test_the_environment_is_recovered_from_python(out_dir):
    """A Python loop with Step recovers the environment with the texture: the loss falls to
    under half its start, and the environment's error against the truth's mean falls."""
    op = psrestir.DiffRender(env_task(out_dir / "env_loop", iterations=40), method="baseline")
    target = op.targets()[0]
    step = psrestir.Step(op)

    def loss(seed):
        img = op.render(spp=64, seed=seed, primal="independent")[0]
        return float(np.mean((img - target) ** 2))

    start = loss(10_000)
    for it in range(step.iterations):
        img = op.render(spp=4, seed=it)[0]
        op.backward([(2.0 / img.size) * (img - target)])
        step()
    assert loss(10_001) < 0.5 * start
    env = op.parameters()["environment"]
    assert np.ptp(env) > 0.05, "the environment did not move"


def test_the_gradient_variance_where_the_estimator_tracks_one(out_dir):
    base = psrestir.DiffRender(small_task(out_dir / "var_b", resolution=(4, 2)), method="baseline")
    assert base.gradient_variance() is None
    op = psrestir.DiffRender(small_task(out_dir / "var_r", resolution=(4, 2)), method="recursive")
    target = op.targets()[0]
    for it in range(3):
        img = op.render(spp=2, seed=it)[0]
        op.backward([(2.0 / img.size) * (img - target)])
    v = op.gradient_variance()["sphere_base_color"]
    assert v.shape == (2, 4, 3) and v.dtype == np.float32
    assert np.isfinite(v).all() and (v >= 0).all() and v[op.observed(0)].max() > 0


def test_optimize_returns_the_recovered_environment(out_dir):
    r = psrestir.optimize(env_task(out_dir / "env_opt", iterations=3), method="baseline",
                          progress=False)
    assert r.environment.shape == (2, 4, 3) and r.environment.dtype == np.float32
    assert np.isfinite(r.environment).all() and (r.environment > 0).all()
    # It moved from its gray start, and is the one written to environment.exr.
    assert np.abs(r.environment - 0.5).max() > 1e-4
    assert (out_dir / "env_opt" / "environment.exr").exists()
