"""Shared fixtures: small tasks on the bundled default scene (32x32 images, tiny textures)."""

import os

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SCENE = os.path.join(ROOT, "scenes", "default", "scene.gltf")
SKY = os.path.join(ROOT, "scenes", "default", "sky.exr")


def small_task(out, resolution=(2, 1), size=32, cameras=("main",), **optimizer):
    """A task dict: the default scene's sphere base color at `resolution`, `cameras` at
    `size`^2, targets rendered from the scene itself."""
    opt = {"iterations": 5, "gradient_spp": 4, "primal_spp": 4, "loss": "l2", "filter": "nearest"}
    opt.update(optimizer)
    return {
        "scene": SCENE,
        "cameras": list(cameras),
        "width": size,
        "height": size,
        "seed": 3,
        "env": SKY,
        "output": str(out),
        "target": {"scene": SCENE, "spp": 256},
        "optimizer": opt,
        "textures": [
            {
                "material": "sphere",
                "slot": "base_color",
                "resolution": list(resolution),
                "init": [0.5, 0.5, 0.5],
                "learning_rate": 0.02,
            }
        ],
    }


@pytest.fixture(scope="session")
def out_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("psrestir")
