"""psrestir.torch: the render as a torch.autograd.Function (skipped where torch is absent)."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import psrestir  # noqa: E402
import psrestir.torch  # noqa: E402
from conftest import small_task  # noqa: E402


def test_torch_gradients_are_the_backward_of_the_op(out_dir):
    op = psrestir.DiffRender(small_task(out_dir / "torch", resolution=(4, 2)), method="baseline")
    target = torch.from_numpy(op.targets()[0])
    tex = torch.full((2, 4, 3), 0.5, requires_grad=True)
    (img,) = psrestir.torch.render(op, tex, spp=4, seed=1, seed_grad=9)
    assert img.shape == (32, 32, 3) and img.dtype == torch.float32
    loss = ((img - target) ** 2).mean()
    loss.backward()
    # The same render and backward through the numpy surface, with the same seeds.
    op2 = psrestir.DiffRender(small_task(out_dir / "torch", resolution=(4, 2)), method="baseline")
    img2 = op2.render(spp=4, seed=1)[0]
    g = op2.backward([(2.0 / img2.size) * (img2 - op2.targets()[0])], seed_grad=9)
    np.testing.assert_allclose(tex.grad.numpy(), g["sphere_base_color"], rtol=1e-5, atol=1e-9)


def test_torch_gives_the_environment_and_the_gains_their_gradients(out_dir):
    from test_step import env_task

    task = env_task(out_dir / "torch_env")
    op = psrestir.DiffRender(task, method="baseline")
    target = torch.from_numpy(op.targets()[0])
    p = op.parameters()
    tex = torch.tensor(p["sphere_base_color"], requires_grad=True)
    env = torch.tensor(p["environment"] * 1.5, requires_grad=True)
    exposure = torch.tensor([1.2], requires_grad=True)
    wb = torch.tensor([[1.0, 0.9, 1.1]], requires_grad=True)
    (img,) = psrestir.torch.render(
        op, tex, environment=env, exposure=exposure, white_balance=wb, spp=4, seed=1, seed_grad=9
    )
    ((img - target) ** 2).mean().backward()
    # The same through the numpy surface, with the same parameters and seeds.
    op2 = psrestir.DiffRender(task, method="baseline")
    op2.set_parameters({"environment": env.detach().numpy(), "exposure": np.array([1.2], np.float32),
                        "white_balance": np.array([[1.0, 0.9, 1.1]], np.float32)})
    img2 = op2.render(spp=4, seed=1)[0]
    np.testing.assert_allclose(img.detach().numpy(), img2, rtol=1e-6)
    g = op2.backward([(2.0 / img2.size) * (img2 - op2.targets()[0])], seed_grad=9)
    for t, name in [(tex, "sphere_base_color"), (env, "environment"), (exposure, "exposure"),
                    (wb, "white_balance")]:
        assert t.grad is not None and t.grad.shape == t.shape, name
        np.testing.assert_allclose(t.grad.numpy(), g[name], rtol=1e-4, atol=1e-9, err_msg=name)
    assert np.abs(g["environment"]).sum() > 0 and g["exposure"][0] != 0
