"""The differentiable render from Python: arrays in and out, the checks on them, the misuse
error, the baseline's backward against finite differences, and ReSTIR lowering a loss of
Python's own."""

import numpy as np
import pytest

import psrestir
from conftest import small_task


@pytest.fixture(scope="module")
def op(out_dir):
    return psrestir.DiffRender(small_task(out_dir / "op", resolution=(4, 2)), method="baseline")


def test_shapes_and_dtypes_round_trip(op):
    assert op.texture_names == ["sphere_base_color"]
    assert op.texture_shapes == {"sphere_base_color": (2, 4, 3)}
    assert op.camera_names == ["main"]
    assert op.image_shape == (32, 32)
    t = op.texture("sphere_base_color")
    assert t.dtype == np.float32 and t.shape == (2, 4, 3)
    np.testing.assert_array_equal(t, np.full((2, 4, 3), 0.5, np.float32))
    new = np.random.default_rng(1).uniform(0.1, 0.9, (2, 4, 3)).astype(np.float32)
    op.set_texture(0, new)  # by index as well as by name
    np.testing.assert_array_equal(op.texture("sphere_base_color"), new)
    # A non-contiguous view of the right shape and dtype is read in logical order.
    wide = np.zeros((2, 8, 3), np.float32)
    wide[:, ::2] = new
    op.set_texture("sphere_base_color", wide[:, ::2])
    np.testing.assert_array_equal(op.texture(0), new)
    images = op.render(spp=2, seed=1)
    assert isinstance(images, list) and len(images) == 1
    assert images[0].dtype == np.float32 and images[0].shape == (32, 32, 3)
    assert np.isfinite(images[0]).all() and images[0].max() > 0
    grads = op.backward([np.ones((32, 32, 3), np.float32)])
    assert list(grads) == ["sphere_base_color", "exposure", "white_balance"]
    assert grads["sphere_base_color"].dtype == np.float32
    assert grads["sphere_base_color"].shape == (2, 4, 3)
    seen = op.observed("sphere_base_color")
    assert seen.dtype == np.bool_ and seen.shape == (2, 4) and seen.any()


@pytest.mark.parametrize(
    "values, says",
    [
        (np.full((2, 4, 3), 0.5, np.float64), "dtype float64"),
        (np.full((4, 2, 3), 0.5, np.float32), "shape [4, 2, 3]"),
        (np.full((2, 4), 0.5, np.float32), "shape [2, 4]"),
        ([[0.5] * 3] * 8, "a list"),
        (np.full((2, 4, 3), np.nan, np.float32), "outside the slot's range"),
        (np.full((2, 4, 3), 1.5, np.float32), "outside the slot's range [0, 1]"),
    ],
)
def test_bad_textures_are_refused_with_what_was_expected(op, values, says):
    before = op.texture(0)
    with pytest.raises(psrestir.InvalidArgument) as e:
        op.set_texture("sphere_base_color", values)
    assert says in str(e.value)
    assert isinstance(e.value, ValueError) and isinstance(e.value, psrestir.PsrestirError)
    np.testing.assert_array_equal(op.texture(0), before)


def test_bad_names_and_adjoints_are_refused(op):
    with pytest.raises(psrestir.InvalidArgument, match="sphere_base_color"):
        op.texture("sphere_roughness")
    with pytest.raises(psrestir.InvalidArgument, match="no optimized texture 3"):
        op.texture(3)
    op.render(spp=1, seed=2)
    with pytest.raises(psrestir.InvalidArgument, match="2 adjoint images for 1 cameras"):
        op.backward([np.zeros((32, 32, 3), np.float32)] * 2)
    with pytest.raises(psrestir.InvalidArgument, match=r"shape \(32, 32, 3\)"):
        op.backward([np.zeros((16, 16, 3), np.float32)])
    with pytest.raises(psrestir.InvalidArgument, match="not finite"):
        op.backward([np.full((32, 32, 3), np.inf, np.float32)])
    with pytest.raises(psrestir.InvalidArgument, match="spp must be between 1 and 65536"):
        op.render(spp=0, seed=0)
    with pytest.raises(psrestir.InvalidArgument, match="unknown gradient estimator `fast`"):
        psrestir.DiffRender(small_task("unused"), method="fast")


def test_backward_without_a_render_at_the_current_textures_is_an_error(op):
    adj = [np.ones((32, 32, 3), np.float32)]
    op.render(spp=1, seed=3)
    op.backward(adj)
    # A second backward for the same render.
    with pytest.raises(psrestir.InvalidArgument, match="backward needs a render"):
        op.backward(adj)
    # A render, then the textures change: the render is not at the current textures.
    op.render(spp=1, seed=4)
    op.set_texture(0, np.full((2, 4, 3), 0.4, np.float32))
    with pytest.raises(psrestir.InvalidArgument, match="backward needs a render"):
        op.backward(adj)
    op.render(spp=1, seed=5)
    op.backward(adj)


def test_backward_matches_finite_differences(out_dir):
    """The mean of many baseline estimates under adjoints of independent renders equals the
    central finite difference of the L2 loss, as tests/gradient.rs checks it in Rust (same
    unbiased loss estimate, same tolerance)."""
    op = psrestir.DiffRender(small_task(out_dir / "fd", resolution=(2, 1)), method="baseline")
    target = op.targets()[0]
    values = np.array([[[0.3, 0.6, 0.2], [0.7, 0.4, 0.5]]], np.float32)
    op.set_texture(0, values)
    n_pix = target.size

    k = 48
    grads = []
    for it in range(k):
        img = op.render(spp=16, seed=1000 + it)[0]
        adj = (2.0 / n_pix) * (img - target)
        grads.append(op.backward([adj], seed_grad=7)["sphere_base_color"].astype(np.float64))
    grads = np.array(grads)
    mean = grads.mean(axis=0).ravel()
    var_mean = grads.var(axis=0, ddof=1).ravel() / k

    # The product of two independent renders' residuals has expectation (I - G)^2 exactly;
    # common random numbers on both sides, two repetitions estimate the difference's noise.
    h, spp = 0.02, 256

    def loss(vals, seed):
        op.set_texture(0, vals.astype(np.float32))
        a = op.render(spp=spp, seed=seed)[0].astype(np.float64)
        b = op.render(spp=spp, seed=seed + 1)[0].astype(np.float64)
        return float(np.sum((a - target) * (b - target))) / n_pix

    n = values.size
    fd = np.zeros(n)
    fd_var = 0.0
    for i in range(n):
        reps = []
        for r in range(2):
            plus = values.ravel().copy()
            minus = values.ravel().copy()
            plus[i] += h
            minus[i] -= h
            seed = 5000 + 10 * r
            reps.append(
                (loss(plus.reshape(values.shape), seed) - loss(minus.reshape(values.shape), seed))
                / (2 * h)
            )
        fd[i] = 0.5 * (reps[0] + reps[1])
        fd_var += 0.25 * (reps[0] - reps[1]) ** 2 / n
    scale = np.abs(fd).max()
    assert scale > 0, "all finite differences are zero: the test sees nothing"
    # 4 standard errors of the difference, 5% of the derivative for the O(h^2) truncation,
    # 0.1% of the largest derivative for float rounding (tests/gradient.rs).
    tol = 4 * np.sqrt(var_mean + fd_var) + 0.05 * np.abs(fd) + 1e-3 * scale
    assert (np.abs(mean - fd) <= tol).all(), (mean, fd, tol)


def test_restir_lowers_a_loss_computed_in_python(out_dir):
    op = psrestir.DiffRender(small_task(out_dir / "restir", resolution=(16, 8)), method="restir")
    assert op.method == "restir"
    target = op.targets()[0]
    name = op.texture_names[0]

    def loss(seed):
        img = op.render(spp=64, seed=seed)[0]
        return float(np.mean((img - target) ** 2))

    start = loss(10_000)
    tex = op.texture(name)
    m = np.zeros_like(tex)
    v = np.zeros_like(tex)
    for it in range(40):
        img = op.render(spp=4, seed=it)[0]
        g = op.backward([(2.0 / img.size) * (img - target)])[name]
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g * g
        step = 0.03 * (m / (1 - 0.9 ** (it + 1))) / (np.sqrt(v / (1 - 0.999 ** (it + 1))) + 1e-8)
        tex = np.clip(tex - step, 0, 1).astype(np.float32)
        op.set_texture(name, tex)
    assert op.iteration == 40
    end = loss(10_001)
    assert end < 0.5 * start, (start, end)


def test_from_scene_needs_no_task_file(tmp_path, monkeypatch):
    from conftest import SCENE, SKY

    monkeypatch.chdir(tmp_path)  # its targets are cached under out/dict_task
    op = psrestir.DiffRender.from_scene(
        SCENE,
        [("sphere", "roughness", (4, 4)), ("sphere", "base_color", (8, 4), [0.2, 0.3, 0.4])],
        cameras=["top"],
        width=32,
        height=32,
        env=SKY,
        method="recursive",
    )
    assert op.texture_names == ["sphere_roughness", "sphere_base_color"]
    assert op.texture_shapes == {"sphere_roughness": (4, 4, 1), "sphere_base_color": (4, 8, 3)}
    np.testing.assert_allclose(op.texture("sphere_base_color")[0, 0], [0.2, 0.3, 0.4])
    assert op.camera_names == ["top"] and op.method == "recursive"
    img = op.render(spp=2, seed=0)[0]
    target = op.targets()[0]
    grads = op.backward([(2.0 / img.size) * (img - target)])
    assert grads["sphere_roughness"].shape == (4, 4, 1)
    assert np.abs(grads["sphere_base_color"]).sum() > 0
    # The observed texels of the second texture are its own (the flags of the textures lie
    # one after another): the same mask as a render that optimizes it alone.
    alone = psrestir.DiffRender.from_scene(
        SCENE, [("sphere", "base_color", (8, 4))], cameras=["top"], width=32, height=32, env=SKY
    )
    np.testing.assert_array_equal(op.observed("sphere_base_color"), alone.observed(0))
    assert op.observed("sphere_roughness").shape == (4, 4)
    with pytest.raises(psrestir.InvalidArgument, match="expected \\(material, slot"):
        psrestir.DiffRender.from_scene(SCENE, [("sphere", "roughness")])


def test_a_normal_map_is_a_texture_like_the_others(tmp_path, monkeypatch):
    from conftest import SCENE, SKY

    monkeypatch.chdir(tmp_path)
    kw = dict(cameras=["main"], width=32, height=32, env=SKY)
    op = psrestir.DiffRender.from_scene(SCENE, [("sphere", "normal", (8, 4))], **kw)
    assert op.texture_shapes == {"sphere_normal": (4, 8, 3)}
    # Flat by default: glTF's (0.5, 0.5, 1).
    np.testing.assert_allclose(op.texture("sphere_normal"), np.tile([0.5, 0.5, 1.0], (4, 8, 1)))
    img = op.render(spp=4, seed=0)[0]
    grads = op.backward([(2.0 / img.size) * (img - op.targets()[0] * 0.5)])
    assert grads["sphere_normal"].shape == (4, 8, 3)
    assert np.abs(grads["sphere_normal"][..., :2]).sum() > 0
    # Every estimator takes one: ReSTIR too (tests/restir.rs checks its mean).
    re = psrestir.DiffRender.from_scene(
        SCENE, [("sphere", "normal", (8, 4))], method="restir", **kw
    )
    img = re.render(spp=4, seed=0)[0]
    grads = re.backward([(2.0 / img.size) * (img - re.targets()[0] * 0.5)])
    assert grads["sphere_normal"].shape == (4, 8, 3)
    assert np.abs(grads["sphere_normal"][..., :2]).sum() > 0


def test_each_capture_sees_its_own_lights(tmp_path, monkeypatch):
    from conftest import SCENE

    monkeypatch.chdir(tmp_path)
    kw = dict(cameras=["main"], width=32, height=32)
    tex = [("sphere", "base_color", (8, 4))]
    every = psrestir.DiffRender.from_scene(SCENE, tex, **kw).targets()[0]
    sun = psrestir.DiffRender.from_scene(SCENE, tex, lights={"main": ["sun"]}, **kw).targets()[0]
    # The default scene's point and spot lamps are off in the second capture: darker, and
    # nowhere brighter than the noise of a 256-spp target.
    assert sun.mean() < 0.8 * every.mean()
    with pytest.raises(psrestir.PsrestirError, match="no punctual light `lamp`"):
        psrestir.DiffRender.from_scene(SCENE, tex, lights={"main": ["lamp"]}, **kw)
