"""Recover the outdoor bench scene's base color, roughness and the sky that lights it, from
Python, with psrestir's own step and a loss of your choice.

    python examples/python/outdoor_environment.py [--iterations 300] [--loss l2|log] [--compare]

The task (scenes/bench/outdoor) starts the sphere's textures and the environment from gray;
the targets are renders under the true sky. Each iteration renders the three cameras, takes
the loss and its derivative in numpy, and `psrestir.Step` steps the textures and the
environment with the task's configuration. `--loss log` compares log(1 + x) of the images
instead of the images (a loss the command line does not have: it weighs the dark side of
the sphere as much as the lit one). The textures are judged as `psrestir optimize` judges
them, relit under two other environments; `--compare` runs `psrestir.optimize` on the same
task for the same iterations and prints its relit errors too.
"""

import argparse
import os
import time

import numpy as np

import psrestir

HERE = os.path.dirname(os.path.abspath(__file__))
TASK = os.path.join(HERE, "..", "..", "scenes", "bench", "outdoor", "task.toml")

parser = argparse.ArgumentParser()
parser.add_argument("--iterations", type=int, default=300)
parser.add_argument("--loss", choices=["l2", "log"], default="l2")
parser.add_argument("--spp", type=int, default=2, help="primal samples per pixel (the task's)")
parser.add_argument("--compare", action="store_true")
args = parser.parse_args()

op = psrestir.DiffRender(TASK)
targets = op.targets()
log_targets = [np.log1p(t) for t in targets]
n = sum(t.size for t in targets)


def loss_and_adjoint(images):
    """The mean over all cameras' pixels and channels, and dL/dI."""
    if args.loss == "l2":
        diffs = [i - t for i, t in zip(images, targets)]
        return sum(float(np.sum(d * d)) for d in diffs) / n, [(2.0 / n) * d for d in diffs]
    diffs = [np.log1p(np.maximum(i, 0.0)) - t for i, t in zip(images, log_targets)]
    adjoints = [(2.0 / n) * d / (1.0 + np.maximum(i, 0.0)) for d, i in zip(diffs, images)]
    return sum(float(np.sum(d * d)) for d in diffs) / n, adjoints


step = psrestir.Step(op, iterations=args.iterations)
print(f"{op}\nparameters: {op.parameter_names}")
start = time.perf_counter()
for it in range(args.iterations):
    images = op.render(spp=args.spp, seed=it)
    loss, adjoints = loss_and_adjoint(images)
    op.backward(adjoints)
    step()
    if it % 50 == 0 or it == args.iterations - 1:
        print(f"iteration {it}: {args.loss} loss {loss:.4e}")
seconds = time.perf_counter() - start
print(f"{1000 * seconds / args.iterations:.1f} ms per iteration")
for e in op.relit_errors():
    print(f"relit under {e['environment']}: relMSE {e['relmse']:.4e}, PSNR {e['psnr']:.2f} dB")
if args.compare:
    r = psrestir.optimize(TASK, iterations=args.iterations, out=os.path.join("out", "outdoor_cli"),
                          progress=False)
    print(f"psrestir.optimize, {args.iterations} iterations: {r.ms_per_iteration:.1f} ms each")
    for e in r.relit:
        print(f"relit under {e['environment']}: relMSE {e['relmse']:.4e}, PSNR {e['psnr']:.2f} dB")
