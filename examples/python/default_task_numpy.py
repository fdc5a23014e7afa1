"""Recover the bundled default task's base color with your own loss and a plain Adam in numpy.

    python examples/python/default_task_numpy.py [--iterations 500] [--method baseline]

psrestir renders the cameras and turns dL/dI into texel gradients; the loss (L2, the mean over
both cameras' pixels and channels, as the task's), its derivative, the learning-rate schedule
(cosine decay from 0.02 to 1% of it) and Adam are the numpy below. It prints the observed-texel
RMSE against the true texture, and where the time goes.
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
parser.add_argument("--method", default="baseline")
parser.add_argument("--lr", type=float, default=0.02)
parser.add_argument("--spp", type=int, default=4)
args = parser.parse_args()

op = psrestir.DiffRender(TASK, method=args.method)
name = op.texture_names[0]  # "sphere_base_color", 128 x 256 x 3
targets = op.targets()  # the task's targets: renders of the true scene, one per camera
truth = op.reference(name)
seen = op.observed(name)


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
print(f"{op}\nobserved-texel RMSE at the start: {rmse(tex):.4f}")
gpu_s = python_s = 0.0
for it in range(args.iterations):
    t0 = time.perf_counter()
    images = op.render(spp=args.spp, seed=it)
    t1 = time.perf_counter()
    loss, adjoints = loss_and_adjoint(images)
    t2 = time.perf_counter()
    grad = op.backward(adjoints)[name]
    t3 = time.perf_counter()
    # Adam, with the cosine decay of the learning rate to 1% over the run.
    lr = args.lr * (0.01 + 0.99 * 0.5 * (1.0 + np.cos(np.pi * it / args.iterations)))
    m = beta1 * m + (1 - beta1) * grad
    v = beta2 * v + (1 - beta2) * grad * grad
    step = lr * (m / (1 - beta1 ** (it + 1))) / (np.sqrt(v / (1 - beta2 ** (it + 1))) + eps)
    tex = np.clip(tex - step, 0.0, 1.0).astype(np.float32)
    op.set_texture(name, tex)
    t4 = time.perf_counter()
    gpu_s += (t1 - t0) + (t3 - t2)
    python_s += (t2 - t1) + (t4 - t3)
    if it % 100 == 0 or it == args.iterations - 1:
        print(f"iteration {it}: loss {loss:.4e}, observed-texel RMSE {rmse(tex):.4f}")
n = args.iterations
print(
    f"observed-texel RMSE at the end: {rmse(tex):.4f}; {1000 * (gpu_s + python_s) / n:.1f} ms "
    f"per iteration: render and backward {1000 * gpu_s / n:.1f} ms, loss and Adam in numpy "
    f"{1000 * python_s / n:.1f} ms ({100 * python_s / (gpu_s + python_s):.1f}%)"
)
