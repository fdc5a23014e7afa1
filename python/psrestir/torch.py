"""psrestir's differentiable render as a ``torch.autograd.Function``.

Importing this module imports torch; ``import psrestir`` alone does not. Tensors cross as
CPU float32 (a tensor on another device is copied to the CPU and its gradient copied back).

    import psrestir, psrestir.torch
    op = psrestir.DiffRender("task.toml")
    tex = torch.tensor(op.texture(0), requires_grad=True)
    opt = torch.optim.Adam([tex], lr=0.02)
    for it in range(500):
        images = psrestir.torch.render(op, tex, spp=4, seed=it)
        loss = sum(((i - t) ** 2).mean() for i, t in zip(images, targets))
        opt.zero_grad(); loss.backward(); opt.step()
        with torch.no_grad():
            tex.clamp_(0.0, 1.0)

The environment (when the task recovers it) and each camera's exposure and white balance
are parameters too: pass them as ``environment=``, ``exposure=`` and ``white_balance=``
tensors (the shapes of ``op.parameters()``) and they get their gradients.
"""

import numpy as np
import torch

__all__ = ["render", "RenderFunction"]

_KEYWORDS = ("environment", "exposure", "white_balance")


class RenderFunction(torch.autograd.Function):
    """forward(op, spp, seed, seed_grad, primal, names, *tensors) -> one image per camera,
    ``names`` the parameter of each tensor; backward gives each tensor the gradient
    ``op.backward`` computes from the images' gradients."""

    @staticmethod
    def forward(ctx, op, spp, seed, seed_grad, primal, names, *tensors):
        op.set_parameters(
            {
                n: np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32)
                for n, t in zip(names, tensors)
            }
        )
        images = op.render(spp=spp, seed=seed, primal=primal)
        ctx.op = op
        ctx.seed_grad = seed_grad
        ctx.names = names
        ctx.devices = [t.device for t in tensors]
        device = tensors[0].device if tensors else torch.device("cpu")
        return tuple(torch.from_numpy(i).to(device) for i in images)

    @staticmethod
    def backward(ctx, *grad_images):
        op = ctx.op
        h, w = op.image_shape
        adjoints = [
            np.zeros((h, w, 3), np.float32)
            if g is None
            else np.ascontiguousarray(g.detach().cpu().numpy(), dtype=np.float32)
            for g in grad_images
        ]
        grads = op.backward(adjoints, seed_grad=ctx.seed_grad)
        out = [torch.from_numpy(grads[n]).to(d) for n, d in zip(ctx.names, ctx.devices)]
        return (None, None, None, None, None, None, *out)


def render(
    op,
    *textures,
    environment=None,
    exposure=None,
    white_balance=None,
    spp=4,
    seed=0,
    seed_grad=None,
    primal=None,
):
    """Render ``op``'s cameras with ``textures`` (one tensor per texture, in
    ``op.texture_names`` order, each of its (h, w, c) shape) and, where given, the
    ``environment`` (h, w, 3), ``exposure`` (n_cameras,) and ``white_balance``
    (n_cameras, 3) tensors: a tuple of (h, w, 3) images (the gains applied) whose gradients
    reach every tensor given through ``op.backward``. ``primal`` as in ``op.render``."""
    names = op.texture_names
    if len(textures) != len(names):
        from .errors import InvalidArgument

        raise InvalidArgument(
            f"render: {len(textures)} textures given, the task optimizes {len(names)}: {names}"
        )
    tensors = list(textures)
    names = list(names)
    for key, t in zip(_KEYWORDS, (environment, exposure, white_balance)):
        if t is not None:
            names.append(key)
            tensors.append(t)
    return RenderFunction.apply(op, spp, seed, seed_grad, primal, tuple(names), *tensors)
