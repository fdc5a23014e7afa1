"""Fit textures to photos with clipped highlights: the `l2` loss against the `srgb` loss.

    python examples/python/clipped_photos.py [--scene sphere] [--exposure 3] [--time-budget 60]

The bench scene's targets (renders of its ground truth) are taken through a camera: times
an exposure, clipped to [0, 1] and saved as 8-bit sRGB PNGs, the way a camera clips its
highlights. A task that fits the scene's textures to those photos, with the exposure known
(`[target] exposure`), then runs once per loss at equal time; the recovered base color is
judged against the scene's true texture on the texels the cameras observe.
"""

import argparse
import copy
import os
import struct
import zlib

import numpy as np

import psrestir

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..", "..")

parser = argparse.ArgumentParser()
parser.add_argument("--scene", default="sphere")
parser.add_argument("--exposure", type=float, default=3.0)
parser.add_argument("--time-budget", type=float, default=60.0)
parser.add_argument("--losses", default="l2,srgb,log")
parser.add_argument("--out", default=os.path.join("out", "clipped_photos"))
args = parser.parse_args()


def srgb8(linear):
    """Linear [0, 1] values to 8-bit sRGB."""
    x = np.clip(linear, 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


def write_png(path, rgb8):
    """An 8-bit RGB PNG (numpy and zlib only)."""
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[y].tobytes() for y in range(h))

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


scene_dir = os.path.abspath(os.path.join(ROOT, "scenes", "bench", args.scene))
task_path = os.path.join(scene_dir, "task.toml")
truth_op = psrestir.DiffRender(task_path, method="baseline")
out = os.path.abspath(args.out)
os.makedirs(out, exist_ok=True)
images, clipped = {}, []
for name, target in zip(truth_op.camera_names, truth_op.targets()):
    exposed = args.exposure * target
    clipped.append(float((exposed > 1.0).any(axis=2).mean()))
    path = os.path.join(out, f"photo_{name}.png")
    write_png(path, srgb8(exposed))
    images[name] = path
print(f"{args.scene}: photos at exposure {args.exposure}, pixels clipped per camera: "
      + ", ".join(f"{100 * c:.1f}%" for c in clipped))

# The scene's own task, its targets replaced by the photos and their exposure.
import tomllib  # noqa: E402

with open(task_path, "rb") as f:
    base = tomllib.load(f)
base["scene"] = os.path.join(scene_dir, base["scene"])
for key in ("env",):
    if key in base:
        base[key] = os.path.join(scene_dir, base[key])
base.pop("relight", None)
base["target"] = {"images": images, "exposure": {n: args.exposure for n in images}}
base["optimizer"].pop("iterations", None)
base["optimizer"]["time_budget_s"] = args.time_budget
base["optimizer"]["stop_on_plateau"] = False
# A nonlinear loss of a noisy render is biased by its noise: every loss here gets the
# low-noise control-variate primal.
base["optimizer"]["primal"] = "control_variate"
if "environment" in base:
    raise SystemExit("a scene whose light is recovered: pick one whose light is known")

names = truth_op.texture_names
truth = {n: truth_op.reference(n) for n in names}
seen = {n: truth_op.observed(n) for n in names}
for loss in args.losses.split(","):
    task = copy.deepcopy(base)
    task["optimizer"]["loss"] = loss
    task["output"] = os.path.join(out, loss)
    r = psrestir.optimize(task, progress=False)
    errors = []
    for n in names:
        d = r.textures[n][seen[n]] - truth[n][seen[n]]
        errors.append(f"{n} {np.sqrt(np.mean(d * d)):.4f}")
    print(f"loss {loss}: {r.iterations} iterations in {r.elapsed_s:.1f} s, observed-texel RMSE "
          + ", ".join(errors))
