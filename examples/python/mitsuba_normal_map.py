"""Does a given normal map render the same in psrestir and in Mitsuba 3?

The `wall` scene (scenes/bench/wall: a brick wall under a grazing sun and a sky, its normal
map glTF's normalTexture) rendered by both, with and without its normal map, from its two
cameras. The two BRDFs differ a little (Mitsuba's principled diffuse is Disney's, psrestir's is
Lambert x (1 - F)), so the check compares what the normal map does in each: the image with it
minus the image without it. Prints, per camera, the means, the relative L2 difference of the
two renderers' images, and of their normal-map differences.

Set-up: `pip install mitsuba numpy pillow`; drjit needs LLVM >= 15 (Debian 12: `apt-get install
libllvm19`). Run from the checkout after `cargo build --release`:
    python3 examples/python/mitsuba_normal_map.py [--spp 256]
"""
import argparse
import math
import os
import subprocess
import tempfile

import numpy as np
from PIL import Image
import mitsuba as mi
import drjit as dr

mi.set_variant("llvm_ad_rgb")
dr.set_thread_count(os.cpu_count() or 2)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WALL = os.path.join(ROOT, "scenes", "bench", "wall")
PSRESTIR = os.path.join(ROOT, "target", "release", "psrestir")
# The wall, its sun and cameras as src/assets/bench_scenes/wall.rs writes them.
QUAD = np.array([[-1, 2, 0], [1, 2, 0], [1, 0, 0], [-1, 0, 0]], np.float32)
UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
FACES = np.array([[0, 3, 2], [0, 2, 1]], np.uint32)
SUN = dict(eye=[-2.2, 3.2, 1.2], target=[0.0, 1.0, 0.0], color=[1.0, 0.92, 0.8], lux=4.0)
CAMERAS = {"front": ([0.0, 1.0, 3.2], 0.75), "oblique": ([2.2, 1.5, 2.3], 0.75)}
RES = 128


def srgb_to_linear(c):
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def image(name, srgb):
    """An 8-bit PNG's RGB as floats: decoded from sRGB (base color) or as stored (normals)."""
    a = np.asarray(Image.open(os.path.join(WALL, name)).convert("RGB"), np.float32) / 255.0
    return srgb_to_linear(a) if srgb else a


def bitmap(arr):
    return {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(arr, np.float32)),
            "raw": True, "filter_type": "bilinear", "wrap_mode": "repeat"}


def mitsuba_scene(tmp, normal_map, spp, lights=("sun", "sky")):
    mesh = mi.Mesh("wall", 4, 2, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = QUAD.ravel()
    params["vertex_texcoords"] = UV.ravel()
    params["faces"] = FACES.ravel()
    params.update()
    ply = os.path.join(tmp, "wall.ply")
    mesh.write_ply(ply)
    bsdf = {"type": "principled", "base_color": bitmap(image("wall_color.png", True)),
            "metallic": 0.0, "roughness": 0.8, "specular": 0.5}
    if normal_map:
        bsdf = {"type": "normalmap", "normalmap": bitmap(image("wall_normal.png", False)),
                "bsdf": bsdf}
    sky = np.array(mi.Bitmap(os.path.join(WALL, "sky.exr")).convert(
        mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False))[..., :3]
    # psrestir reads the sky's texels nearest; Mitsuba interpolates: replicate each 8 x 8.
    sky = np.repeat(np.repeat(sky, 8, 0), 8, 1)
    d = np.array(SUN["target"]) - np.array(SUN["eye"])
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "wall": {"type": "ply", "filename": ply, "bsdf": bsdf},
        "sun": {"type": "directional", "direction": (d / np.linalg.norm(d)).tolist(),
                "irradiance": {"type": "rgb", "value": (np.array(SUN["color"]) * SUN["lux"]).tolist()}},
        "sky": {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(sky, np.float32))},
    }
    for name in ("sun", "sky"):
        if name not in lights:
            del scene[name]
    for name, (eye, yfov) in CAMERAS.items():
        scene[f"sensor_{name}"] = {
            "type": "perspective", "fov": math.degrees(yfov), "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(origin=eye, target=[0, 1, 0], up=[0, 1, 0]),
            "sampler": {"type": "independent", "sample_count": spp},
            "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "sample_border": False},
        }
    return mi.load_dict(scene)


def psrestir_render(tmp, scene_file, camera, spp):
    out = os.path.join(tmp, f"psr_{scene_file}_{camera}.exr")
    subprocess.run([PSRESTIR, "render", os.path.join(WALL, scene_file), "--camera", camera,
                    "--env", os.path.join(WALL, "sky.exr"), "--spp", str(spp),
                    "--size", f"{RES}x{RES}", "-o", out], check=True, capture_output=True)
    return np.array(mi.Bitmap(out).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32,
                                           srgb_gamma=False))[..., :3]


def rel_l2(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", type=int, default=256)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scenes = {nm: mitsuba_scene(tmp, nm, args.spp) for nm in (True, False)}
        for k, camera in enumerate(CAMERAS):
            mi_img = {nm: np.array(mi.render(s, sensor=k, spp=args.spp, seed=3)) for nm, s in scenes.items()}
            psr = {True: psrestir_render(tmp, "scene.gltf", camera, args.spp),
                   False: psrestir_render(tmp, "scene_flat.gltf", camera, args.spp)}
            d_mi, d_psr = mi_img[True] - mi_img[False], psr[True] - psr[False]
            print(f"{camera}: mean with the map Mitsuba {mi_img[True].mean():.4f} psrestir "
                  f"{psr[True].mean():.4f}; images rel. L2 {rel_l2(mi_img[True], psr[True]):.3f}; "
                  f"what the map changes: rel. L2 {rel_l2(d_mi, d_psr):.3f} "
                  f"(Mitsuba {np.sqrt(np.mean(d_mi ** 2)):.4f}, psrestir {np.sqrt(np.mean(d_psr ** 2)):.4f} RMS), "
                  f"correlation {np.corrcoef(d_mi.ravel(), d_psr.ravel())[0, 1]:.3f}")


if __name__ == "__main__":
    main()
