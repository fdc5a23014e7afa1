"""psrestir's differentiable render as a ``torch.autograd.Function``.

Importing this module imports torch; ``import psrestir`` alone does not. Tensors cross as
CPU float32 (a tensor on another device is copied to the CPU and its gradient copied back).

    import psrestir, psrestir.torch
    op = psrestir.DiffRender("task.toml", method="restir")
    tex = torch.tensor(op.texture(0), requires_grad=True)
    opt = torch.optim.Adam([tex], lr=0.02)
    for it in range(500):
        images = psrestir.torch.render(op, tex, spp=4, seed=it)
        loss = sum(((i - t) ** 2).mean() for i, t in zip(images, targets))
        opt.zero_grad(); loss.backward(); opt.step()
        with torch.no_grad():
            tex.clamp_(0.0, 1.0)
"""

import numpy as np
import torch

__all__ = ["render", "RenderFunction"]


class RenderFunction(torch.autograd.Function):
    """forward(op, spp, seed, seed_grad, *textures) -> one image per camera; backward gives
    each texture the gradient ``op.backward`` estimates from the images' gradients."""

    @staticmethod
    def forward(ctx, op, spp, seed, seed_grad, *textures):
        names = op.texture_names
        if len(textures) != len(names):
            from .errors import InvalidArgument

            raise InvalidArgument(
                f"render: {len(textures)} textures given, the task optimizes {len(names)}: {names}"
            )
        for name, t in zip(names, textures):
            op.set_texture(name, np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32))
        images = op.render(spp=spp, seed=seed)
        ctx.op = op
        ctx.seed_grad = seed_grad
        ctx.devices = [t.device for t in textures]
        device = textures[0].device if textures else torch.device("cpu")
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
        out = [torch.from_numpy(grads[n]).to(d) for n, d in zip(op.texture_names, ctx.devices)]
        return (None, None, None, None, *out)


def render(op, *textures, spp=4, seed=0, seed_grad=None):
    """Render ``op``'s cameras with ``textures`` (one tensor per texture, in
    ``op.texture_names`` order, each of its (h, w, c) shape): a tuple of (h, w, 3) images
    whose gradients reach the textures through ``op.backward``."""
    return RenderFunction.apply(op, spp, seed, seed_grad, *textures)
