"""Recover the bundled default task's base color with a loss written in PyTorch and
psrestir's own step.

    python examples/python/default_task_torch.py [--iterations 500] [--step psrestir|adam]

`psrestir.torch.render` is a torch.autograd.Function: the loss's backward runs psrestir's
estimator. `--step psrestir` (the default) then updates the texture with the task's own step
(`psrestir.Step`: the variance-scaled step, filtered moments, priors and schedule of
`psrestir optimize`); `--step adam` with torch's Adam at a constant learning rate instead.
"""

import argparse
import os

import numpy as np
import torch

import psrestir
import psrestir.torch

HERE = os.path.dirname(os.path.abspath(__file__))
TASK = os.path.join(HERE, "..", "..", "scenes", "default", "task.toml")

parser = argparse.ArgumentParser()
parser.add_argument("--iterations", type=int, default=500)
parser.add_argument("--step", choices=["psrestir", "adam"], default="psrestir")
args = parser.parse_args()

op = psrestir.DiffRender(TASK)
name = op.texture_names[0]
targets = [torch.from_numpy(t) for t in op.targets()]
truth, seen = op.reference(name), op.observed(name)
tex = torch.tensor(op.texture(name), requires_grad=True)
step = psrestir.Step(op, iterations=args.iterations)
adam = torch.optim.Adam([tex], lr=0.02)
for it in range(args.iterations):
    images = psrestir.torch.render(op, tex, spp=4, seed=it)
    loss = sum(((i - t) ** 2).mean() for i, t in zip(images, targets)) / len(images)
    adam.zero_grad()
    loss.backward()  # psrestir's estimator: tex.grad, and the gradient Step uses
    if args.step == "psrestir":
        step()
        with torch.no_grad():
            tex.copy_(torch.from_numpy(op.texture(name)))
    else:
        adam.step()
        with torch.no_grad():
            tex.clamp_(0.0, 1.0)
end = tex.detach().numpy()
print(f"observed-texel RMSE after {args.iterations} iterations: "
      f"{np.sqrt(np.mean((end[seen] - truth[seen]) ** 2)):.4f}")
