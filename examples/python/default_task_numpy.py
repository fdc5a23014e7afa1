"""Recover the bundled default task's base color with your own loss in numpy.

    python examples/python/default_task_numpy.py [--iterations 500] [--step psrestir|adam]

psrestir renders the cameras (with the task's control-variate primal) and turns dL/dI into
texel gradients; the loss (L2, the mean over both cameras' pixels and channels) and its
derivative are the numpy below. `--step psrestir` (the default) updates the texture with
psrestir's own step for the task (the variance-scaled step with filtered moments, the
smoothness and multiscale priors, the cosine schedule: what `psrestir optimize` runs);
`--step adam` with a plain Adam in numpy instead, at the same schedule. It prints the
observed-texel RMSE against the true texture, and where the time goes.
"""

import argparse
import os
import time

import numpy as np

import psrestir

HERE = os.path.dirname(os.path.abspath(__file__))
TASK = os.path.join(HERE, "..", "..", "scenes", "default", "task.toml")

parser = argparse.ArgumentParser()
parser.add_argument("--iterations", type=int, default=500)
parser.add_argument("--method", default="auto")
parser.add_argument("--step", choices=["psrestir", "adam"], default="psrestir")
parser.add_argument("--lr", type=float, default=0.02, help="the numpy Adam's learning rate")
parser.add_argument("--spp", type=int, default=4)
args = parser.parse_args()

op = psrestir.DiffRender(TASK, method=args.method)
name = op.texture_names[0]  # "sphere_base_color", 128 x 256 x 3
targets = op.targets()  # the task's targets: renders of the true scene, one per camera
truth = op.reference(name)
seen = op.observed(name)
step = psrestir.Step(op, iterations=args.iterations)


def rmse(tex):
    return float(np.sqrt(np.mean((tex[seen] - truth[seen]) ** 2)))


def loss_and_adjoint(images):
    """L2, mean over all cameras' pixels and channels, and dL/dI."""
    n = sum(i.size for i in images)
    diffs = [i - t for i, t in zip(images, targets)]
    loss = sum(float(np.sum(d * d)) for d in diffs) / n
    return loss, [(2.0 / n) * d for d in diffs]


tex = op.texture(name)
m = np.zeros_like(tex)
v = np.zeros_like(tex)
beta1, beta2, eps = 0.9, 0.999, 1e-8


def numpy_adam(it, grad):
    """Adam, with the cosine decay of the learning rate to 1% over the run."""
    global tex, m, v
    lr = args.lr * (0.01 + 0.99 * 0.5 * (1.0 + np.cos(np.pi * it / args.iterations)))
    m = beta1 * m + (1 - beta1) * grad
    v = beta2 * v + (1 - beta2) * grad * grad
    update = lr * (m / (1 - beta1 ** (it + 1))) / (np.sqrt(v / (1 - beta2 ** (it + 1))) + eps)
    tex = np.clip(tex - update, 0.0, 1.0).astype(np.float32)
    op.set_texture(name, tex)


print(f"{op}, primal {op.primal}\nobserved-texel RMSE at the start: {rmse(tex):.4f}")
gpu_s = python_s = 0.0
for it in range(args.iterations):
    t0 = time.perf_counter()
    images = op.render(spp=args.spp, seed=it)
    t1 = time.perf_counter()
    loss, adjoints = loss_and_adjoint(images)
    t2 = time.perf_counter()
    grad = op.backward(adjoints)[name]
    t3 = time.perf_counter()
    if args.step == "psrestir":
        step()  # psrestir's step from the gradient the backward left on the GPU
        t4 = time.perf_counter()
        gpu_s += t4 - t3
    else:
        numpy_adam(it, grad)
        t4 = time.perf_counter()
        python_s += t4 - t3
    gpu_s += (t1 - t0) + (t3 - t2)
    python_s += t2 - t1
    if it % 100 == 0 or it == args.iterations - 1:
        print(f"iteration {it}: loss {loss:.4e}, observed-texel RMSE {rmse(op.texture(name)):.4f}")
n = args.iterations
print(
    f"observed-texel RMSE at the end: {rmse(op.texture(name)):.4f}; "
    f"{1000 * (gpu_s + python_s) / n:.1f} ms per iteration: render, backward and step "
    f"{1000 * gpu_s / n:.1f} ms, numpy {1000 * python_s / n:.1f} ms "
    f"({100 * python_s / (gpu_s + python_s):.1f}%)"
)
