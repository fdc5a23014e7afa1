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
