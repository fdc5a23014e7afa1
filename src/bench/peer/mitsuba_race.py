"""psrestir bench's Mitsuba 3 contender: one bench task, as psrestir wrote it into an exchange
folder (src/bench/peer/exchange.rs), recovered by Mitsuba 3 at equal time.

The scene is rebuilt from psrestir's own loaded scene (world-space meshes per material, the
cameras, punctual lights, emissive surfaces, the environment, decoded images) with
Mitsuba's principled BSDF; Mitsuba renders its own targets at the task's target spp and
optimizes the task's textures with `prb` at the task's depth and Adam from psrestir's start,
for psrestir's budget of step time, with the task's schedule; a second row adds psrestir's
smoothness prior to the gradient. Runs are scored as psrestir scores its own: RMSE over the
texels psrestir's cameras observe against psrestir's ground truth, and image relMSE of the
expectation of an `eval_spp` render against Mitsuba's own targets. The JIT's compilation is
outside the clock (two untimed iterations before it starts), as psrestir's pipeline creation
is.

Run by `psrestir bench --peers mitsuba`:
    python3 mitsuba_race.py EXCHANGE_DIR OUT_DIR [--tune [--tuned FILE]] [--threads N]
writes OUT_DIR/result.json (atomically) and prints its progress.
"""
import argparse
import json
import math
import os
import sys
import time

EXCHANGE_VERSION = 1
SLOTS = ("base_color", "roughness", "metallic", "normal")
# The principled BSDF's inputs, and the parameter each optimized slot is in Mitsuba.
PRINCIPLED = ("base_color", "roughness", "metallic")
PARAMETER = {"base_color": "base_color", "roughness": "roughness", "metallic": "metallic",
             "normal": "normalmap"}
# psrestir reads a normal-map texel as normalize(2 rgb - 1) with Z at least this.
NORMAL_Z_FLOOR = 0.1
# Relative epsilon of image relMSE, psrestir's REL_EPS.
REL_EPS = 0.01


def seed32(x):
    """A render seed: Mitsuba takes 32 bits."""
    return int(x) % (1 << 32)


def finite_or_none(x):
    """`x` with every NaN or infinity as None (JSON has no NaN)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite_or_none(v) for v in x]
    return x


def fail(msg):
    print(f"mitsuba_race: {msg}", file=sys.stderr)
    sys.exit(2)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("exchange", help="the folder psrestir wrote (scene.json)")
    p.add_argument("out", help="folder for result.json")
    p.add_argument("--tune", action="store_true",
                   help="choose the learning rate and spp by a search on another seed")
    p.add_argument("--tuned", default=None,
                   help="with --tune: a JSON file of earlier searches (per row) to reuse, "
                        "and where this one's choice is kept")
    p.add_argument("--tune-budget-s", type=float, default=None,
                   help="seconds of each trial of the search (default: a third of the budget)")
    p.add_argument("--threads", type=int, default=0, help="Dr.Jit threads (0: all cores)")
    p.add_argument("--spp", type=int, default=4, help="samples per pixel of an iteration")
    p.add_argument("--budget-s", type=float, default=None, help="override the task's budget")
    return p.parse_args(argv)


# ---------------------------------------------------------------- the exchange folder
class Exchange:
    def __init__(self, folder):
        self.dir = folder
        path = os.path.join(folder, "scene.json")
        try:
            with open(path) as f:
                self.j = json.load(f)
        except (OSError, ValueError) as e:
            fail(f"{path}: {e}")
        if self.j.get("version") != EXCHANGE_VERSION:
            fail(f"{path}: exchange version {self.j.get('version')}, this script reads "
                 f"{EXCHANGE_VERSION}")
        for o in self.j["optimized"]:
            if o["slot"] not in SLOTS:
                fail(f"{path}: an optimized `{o['slot']}` texture is not converted "
                     f"(only {', '.join(SLOTS)})")
        mapped = {o["material"] for o in self.j["optimized"] if o["slot"] == "normal"}
        for i, m in enumerate(self.j["materials"]):
            if (m["normal_texture"] or i in mapped) and self._has_mesh(i) and m["tangent_sign"] == 0:
                fail(f"{path}: material `{m['name']}` has a normal map over tangent frames of both "
                     "handednesses, which Mitsuba's normalmap (one frame from dp/du) cannot follow")
        if self.j["loss"] not in ("l2", "relmse"):
            fail(f"{path}: loss `{self.j['loss']}` is not re-implemented here (l2, relmse)")

    def _has_mesh(self, idx):
        return any(s["material"] == idx for s in self.j["meshes"])

    def array(self, a):
        import numpy as np
        dtype = {"f32": "<f4", "u8": "u1"}[a["dtype"]]
        arr = np.fromfile(os.path.join(self.dir, a["file"]), dtype=dtype)
        return arr.reshape(a["shape"])

    def __getitem__(self, k):
        return self.j[k]


def srgb_to_linear(c):
    import numpy as np
    c = np.asarray(c, dtype=np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def schedule_factor(s, progress):
    """psrestir's learning-rate schedule (src/optim/run/schedule.rs) at progress in [0, 1]."""
    p = min(max(progress, 0.0), 1.0)
    kind, final = s.get("kind", "constant"), s.get("final", 0.05)
    if kind == "cosine":
        return final + (1 - final) * 0.5 * (1 + math.cos(math.pi * p))
    if kind == "exponential":
        return final ** p
    if kind == "step":
        n = sum(1 for t in s.get("steps", []) if p >= t)
        return s.get("step_factor", 0.1) ** n
    return 1.0


# ---------------------------------------------------------------- the Mitsuba scene
class SceneBuilder:
    """Mitsuba scene dicts from the exchange: the ground truth, or with the optimized slots'
    bitmaps at given values."""

    def __init__(self, mi, ex):
        self.mi, self.ex = mi, ex
        self.images = {}

    def image(self, i):
        if i not in self.images:
            self.images[i] = self.ex.array(self.ex["images"][i]).astype("float32") / 255.0
        return self.images[i]

    def bitmap(self, arr, nearest, wrap="repeat", transform=None):
        import numpy as np
        mi = self.mi
        b = {"type": "bitmap", "raw": True, "bitmap": mi.Bitmap(np.ascontiguousarray(arr, "float32")),
             "filter_type": "nearest" if nearest else "bilinear", "wrap_mode": wrap}
        if transform is not None and transform != [[1, 0, 0], [0, 1, 0]]:
            m = [list(transform[0]), list(transform[1]), [0.0, 0.0, 1.0]]
            b["to_uv"] = mi.ScalarTransform3f(m)
        return b

    def texture(self, t, decode, channels, factor):
        """A material slot's texture as psrestir reads it: texels decoded (sRGB or linear),
        channels picked, times the factor (bilinear commutes with both)."""
        import numpy as np
        img = self.image(t["image"])
        v = img[..., channels]
        if decode:
            v = srgb_to_linear(v)
        v = v * np.asarray(factor, dtype=np.float32)
        if t["wrap"][0] != t["wrap"][1]:
            print("mitsuba_race: warning: a texture wraps differently in u and v; Mitsuba takes u's",
                  file=sys.stderr)
        return self.bitmap(v, t["nearest"], t["wrap"][0], t["transform"])

    def file_normal_map(self, m):
        """A material's own normal map for Mitsuba's normalmap: X and Y times its scale, Z
        floored as psrestir floors it, green flipped where the tangent frames are
        left-handed (Mitsuba's bitangent is always cross(n, dp/du))."""
        import numpy as np
        t = m["normal_texture"]
        v = self.image(t["image"])[..., :3] * 2 - 1
        v = np.stack([v[..., 0] * m["normal_scale"], v[..., 1] * m["normal_scale"] * m["tangent_sign"],
                      np.maximum(v[..., 2], NORMAL_Z_FLOOR)], -1)
        return self.bitmap(0.5 + 0.5 * v, t["nearest"], t["wrap"][0], t["transform"])

    def material(self, idx, replaced):
        """Material `idx`'s principled BSDF (under its normal map, where it has one);
        `replaced`: slot -> (array, nearest), an optimized texture in Mitsuba's convention."""
        m = self.ex["materials"][idx]
        bsdf = {"type": "principled", "specular": 0.5}
        for slot in PRINCIPLED:
            if slot in replaced:
                arr, nearest = replaced[slot]
                bsdf[slot] = self.bitmap(arr, nearest)
                continue
            if slot == "base_color":
                t = m["base_color_texture"]
                bsdf[slot] = (self.texture(t, True, slice(0, 3), m["base_color"][:3]) if t
                              else {"type": "rgb", "value": m["base_color"][:3]})
            else:
                t = m["metallic_roughness_texture"]
                ch = slice(1, 2) if slot == "roughness" else slice(2, 3)
                bsdf[slot] = self.texture(t, False, ch, [m[slot]]) if t else float(m[slot])
        if "normal" in replaced:
            arr, nearest = replaced["normal"]
            bsdf = {"type": "normalmap", "normalmap": self.bitmap(arr, nearest), "bsdf": bsdf}
        elif m["normal_texture"]:
            bsdf = {"type": "normalmap", "normalmap": self.file_normal_map(m), "bsdf": bsdf}
        bsdf["id"] = f"bsdf_{idx}"
        if m["double_sided"]:
            return {"type": "twosided", "id": f"bsdf_{idx}", "material": {**bsdf, "id": f"inner_{idx}"}}
        return bsdf

    def spot_profile(self, inner, outer, res=256):
        """glTF's smooth cone fall-off (t^2, t = (cos - cos_o) / (cos_i - cos_o)) as the
        spot's projected texture over [-tan(outer), tan(outer)]^2."""
        import numpy as np
        s = (np.arange(res) + 0.5) / res * 2 - 1
        x, y = np.meshgrid(s * math.tan(outer), s * math.tan(outer))
        cos = 1 / np.sqrt(1 + x * x + y * y)
        t = np.clip((cos - math.cos(outer)) / max(math.cos(inner) - math.cos(outer), 1e-4), 0, 1)
        return np.repeat((t * t)[..., None], 3, 2).astype("float32")

    def light(self, L):
        mi = self.mi
        I = {"type": "rgb", "value": L["intensity"]}
        if L["kind"] == "point":
            return {"type": "point", "position": L["position"], "intensity": I}
        if L["kind"] == "directional":
            return {"type": "directional", "direction": L["direction"], "irradiance": I}
        p, d = L["position"], L["direction"]
        up = [0, 1, 0] if abs(d[1]) < 0.9 else [1, 0, 0]
        return {"type": "spot", "intensity": I, "cutoff_angle": math.degrees(L["outer_cone"]),
                "beam_width": math.degrees(L["outer_cone"]) * 0.99999,
                "to_world": mi.ScalarTransform4f().look_at(origin=p, target=[p[i] + d[i] for i in range(3)], up=up),
                "texture": self.bitmap(self.spot_profile(L["inner_cone"], L["outer_cone"]), False, "clamp")}

    def environment(self):
        import numpy as np
        env = self.ex["environment"]
        if env is None:
            return None
        rgb = self.ex.array(env["radiance"])
        if not env["bilinear"]:
            # psrestir looks the environment up at its nearest texel, Mitsuba bilinearly:
            # texels repeated so that the blend spans a small part of each.
            k = max(1, min(8, 1024 // max(rgb.shape[1], 1)))
            rgb = np.repeat(np.repeat(rgb, k, 0), k, 1)
        return {"type": "envmap", "bitmap": self.mi.Bitmap(np.ascontiguousarray(rgb, "float32"))}

    def sensor(self, cam, spp):
        import numpy as np
        mi = self.mi
        w = np.asarray(cam["world"], dtype=np.float64).reshape(4, 4).T
        o, up, fwd = w[:3, 3], w[:3, 1], -w[:3, 2]
        return {"type": "perspective", "fov": math.degrees(cam["yfov"]), "fov_axis": "y",
                "near_clip": 1e-3, "far_clip": 1e5,
                "to_world": mi.ScalarTransform4f().look_at(origin=o.tolist(), target=(o + fwd).tolist(), up=up.tolist()),
                "sampler": {"type": "independent", "sample_count": spp},
                "film": {"type": "hdrfilm", "width": self.ex["width"], "height": self.ex["height"],
                         "rfilter": {"type": "box"}, "pixel_format": "rgb", "sample_border": False}}

    def scene(self, replaced, spp, lights=None):
        """`replaced`: material index -> {slot: (array, nearest)}; `lights`: the punctual
        lights that are on (indices; None: all). Emitting surfaces and the environment light
        every camera, as in psrestir's captures."""
        ex = self.ex
        d = {"type": "scene",
             "integrator": {"type": "prb", "max_depth": ex["max_depth"] + 1, "hide_emitters": False}}
        for mesh in ex["meshes"]:
            idx = mesh["material"]
            m = ex["materials"][idx]
            shape = {"type": "ply", "filename": os.path.join(ex.dir, mesh["file"]),
                     "id": f"mesh_{idx}", "bsdf": self.material(idx, replaced.get(idx, {}))}
            if any(m["emissive"]):
                rad = {"type": "rgb", "value": m["emissive"]}
                if m["emissive_texture"]:
                    rad = self.texture(m["emissive_texture"], True, slice(0, 3), m["emissive"])
                shape["emitter"] = {"type": "area", "radiance": rad}
            d[f"mesh_{idx}"] = shape
        for k, L in enumerate(ex["lights"]):
            if lights is None or k in lights:
                d[f"light_{k}"] = self.light(L)
        env = self.environment()
        if env is not None:
            d["environment"] = env
        for k, cam in enumerate(ex["cameras"]):
            d[f"sensor_{k}"] = self.sensor(cam, spp)
        return self.mi.load_dict(d)


# ---------------------------------------------------------------- the race
class Race:
    def __init__(self, mi, dr, ex):
        import numpy as np
        self.mi, self.dr, self.ex, self.np = mi, dr, ex, np
        self.builder = SceneBuilder(mi, ex)
        self.opt = ex["optimized"]
        self.init = [ex.array(o["init"]) for o in self.opt]
        self.truth = [self.as_seen(o, ex.array(o["truth"])) for o in self.opt]
        self.observed = [ex.array(o["observed"]).astype(bool) for o in self.opt]
        self.n_pixels = len(ex["cameras"]) * ex["width"] * ex["height"]
        # Cameras grouped by the punctual lights on in their captures: one Mitsuba scene each.
        self.groups = {}
        for k, cam in enumerate(ex["cameras"]):
            key = None if cam.get("lights") is None else tuple(sorted(cam["lights"]))
            self.groups.setdefault(key, []).append(k)

    def as_seen(self, o, v):
        """Texture `o`'s values as psrestir scores them: a normal map's texels re-encoded from
        the unit normal each stands for (Z floored), other slots as they are."""
        np = self.np
        if o["slot"] != "normal":
            return v
        n = v.astype(np.float64) * 2 - 1
        n[..., 2] = np.maximum(n[..., 2], NORMAL_Z_FLOOR)
        return 0.5 + 0.5 * n / np.linalg.norm(n, axis=-1, keepdims=True)

    def mitsuba_values(self, o, v):
        """psrestir's texture values in Mitsuba's convention and back (an involution): a
        normal map's green flipped where the tangent frames are left-handed."""
        if o["slot"] == "normal" and self.ex["materials"][o["material"]]["tangent_sign"] < 0:
            v = v.copy()
            v[..., 1] = 1 - v[..., 1]
        return v

    def targets(self, seed):
        """Mitsuba's targets of the ground truth at the task's target spp."""
        mi, dr = self.mi, self.dr
        out = [None] * len(self.ex["cameras"])
        for lights, cams in self.groups.items():
            scene = self.builder.scene({}, self.ex["target_spp"], lights)
            for k in cams:
                img = mi.render(scene, sensor=k, spp=self.ex["target_spp"], seed=seed32(seed * 7919 + k))
                out[k] = self.np.array(img, dtype="float32")
        dr.sync_thread()
        return out

    def forward_check(self, mine):
        rows = []
        for k, cam in enumerate(self.ex["cameras"]):
            theirs = self.ex.array(self.ex["targets"][k])
            a = mine[k].reshape(-1, 3).mean(0)
            b = theirs.reshape(-1, 3).mean(0)
            rel = float(self.np.mean((mine[k] - theirs) ** 2 / (theirs * theirs + REL_EPS)))
            rows.append({"camera": cam["name"], "mitsuba_mean": a.tolist(), "psrestir_mean": b.tolist(),
                         "mean_ratio": float(a.mean() / max(b.mean(), 1e-12)), "relmse": rel})
        return rows

    def errors(self, values):
        """Observed-texel RMSE (all textures together), all-texel RMSE, and per texture."""
        np = self.np
        s = n = s_all = n_all = 0.0
        per = []
        for o, v, t, m in zip(self.opt, values, self.truth, self.observed):
            d = (self.as_seen(o, v.astype(np.float64)) - t) ** 2
            ts, tn = float(d[m].sum()), int(m.sum()) * d.shape[2]
            s, n = s + ts, n + tn
            s_all, n_all = s_all + float(d.sum()), n_all + d.size
            per.append(math.sqrt(ts / tn) if tn else float("nan"))
        return (math.sqrt(s / n) if n else float("nan"), math.sqrt(s_all / max(n_all, 1)), per)

    def smoothness_grad(self, values, weight):
        """psrestir's smoothness prior's derivative (src/optim/prior/smoothness): weight x the
        mean over observed 4-neighbour pairs and channels of squared differences, no wrap."""
        np = self.np
        out = []
        for v, m in zip(values, self.observed):
            v = v.astype(np.float64)
            g = np.zeros_like(v)
            ph = (m[:, 1:] & m[:, :-1])[..., None]
            pv = (m[1:, :] & m[:-1, :])[..., None]
            pairs = int(ph.sum() + pv.sum())
            c = 2 * weight / (v.shape[2] * max(pairs, 1))
            dh = (v[:, 1:] - v[:, :-1]) * ph
            dv = (v[1:, :] - v[:-1, :]) * pv
            g[:, 1:] += c * dh
            g[:, :-1] -= c * dh
            g[1:, :] += c * dv
            g[:-1, :] -= c * dv
            out.append((g * m[..., None]).astype(np.float32))
        return out

    def optimized_scenes(self, values, spp):
        """Per group of cameras, (scene, its parameters, the cameras), and the optimized
        textures' keys (the same in every scene)."""
        replaced = {}
        for o, v in zip(self.opt, values):
            replaced.setdefault(o["material"], {})[o["slot"]] = (self.mitsuba_values(o, v), o["nearest"])
        groups, keys = [], []
        for lights, cams in self.groups.items():
            scene = self.builder.scene(replaced, spp, lights)
            params = self.mi.traverse(scene)
            keys = []
            for o in self.opt:
                want = [k for k in params.keys() if k.startswith(f"mesh_{o['material']}.bsdf.")
                        and k.endswith(f".{PARAMETER[o['slot']]}.data")]
                if len(want) != 1:
                    fail(f"no single parameter for {o['slot']} of material {o['material']}: {want}")
                keys.append(want[0])
            params.keep(keys)
            groups.append((scene, params, cams))
        return groups, keys

    def loss(self, img, ref):
        dr = self.dr
        d = dr.square(img - ref)
        if self.ex["loss"] == "relmse":
            d = d / (dr.square(ref) + REL_EPS)
        return dr.sum(d, axis=None) / (3 * self.n_pixels)

    def run(self, targets, lr_scale, spp, smoothness, budget_s, seed, curve_points=11):
        """Adam from psrestir's start for `budget_s` seconds of step time."""
        mi, dr, np = self.mi, self.dr, self.np
        groups, keys = self.optimized_scenes(self.init, spp)
        refs = [mi.TensorXf(t) for t in targets]
        rates = [o["learning_rate"] * lr_scale for o in self.opt]

        def fresh():
            for _, params, _ in groups:
                for key, o, v in zip(keys, self.opt, self.init):
                    params[key] = mi.TensorXf(self.mitsuba_values(o, v))
                params.update()
            opt = mi.ad.Adam(lr=rates[0], params={k: groups[0][1][k] for k in keys})
            for _, params, _ in groups:
                params.update(opt)
            return opt

        def step(opt, it, factor):
            for key, r in zip(keys, rates):
                opt.set_learning_rate({key: r * factor})
            loss = 0
            for scene, params, cams in groups:
                for k in cams:
                    img = mi.render(scene, params, sensor=k, spp=spp,
                                    seed=seed32(seed * 1_000_003 + it * len(refs) + k))
                    loss = loss + self.loss(img, refs[k])
            dr.backward(loss)
            if smoothness > 0:
                values = [np.array(opt[key]) for key in keys]
                for key, g in zip(keys, self.smoothness_grad(values, smoothness)):
                    dr.set_grad(opt[key], dr.grad(opt[key]) + mi.TensorXf(g))
            opt.step()
            for key in keys:
                opt[key] = dr.clip(opt[key], 0.0, 1.0)
            for _, params, _ in groups:
                params.update(opt)
            dr.eval(loss)
            dr.sync_thread()
            return float(loss.array[0])

        t0 = time.perf_counter()
        opt = fresh()
        for it in range(2):  # the JIT compiles its kernels here, outside the clock
            step(opt, 10_000_000 + it, 1.0)
        warmup = time.perf_counter() - t0
        opt = fresh()

        def values():
            return [self.mitsuba_values(o, np.array(opt[k])) for o, k in zip(self.opt, keys)]

        def point(it, seconds, loss):
            obs, all_, _ = self.errors(values())
            return {"iteration": it, "seconds": seconds, "loss": loss, "texture_rmse": all_,
                    "texture_rmse_observed": obs}

        curve = [point(0, 0.0, float("nan"))]
        elapsed, it, next_eval = 0.0, 0, budget_s / (curve_points - 1)
        while elapsed < budget_s and it < 1_000_000:
            factor = schedule_factor(self.ex["schedule"], elapsed / budget_s)
            t = time.perf_counter()
            loss = step(opt, it, factor)
            elapsed += time.perf_counter() - t
            it += 1
            if elapsed >= next_eval or elapsed >= budget_s:
                curve.append(point(it, elapsed, loss))
                next_eval += budget_s / (curve_points - 1)
        obs, all_, per = self.errors(values())
        # Image error, as psrestir's bench measures its own: the eval_spp samples of every
        # camera as two independent renders A and B (halves of the spp), against Mitsuba's
        # own targets T. The relMSE of their weighted mean is the render's (its noise
        # included); the mean of (A - T)(B - T) / (T^2 + eps) is that of the render's
        # expectation, which the bench reports.
        rel, expected = [], []
        n = self.ex["eval_spp"]
        halves = (n - n // 2, n // 2) if n > 1 else (1, 1)
        for scene, params, cams in groups:
            for k in cams:
                t = targets[k]
                a, b = (np.array(mi.render(scene, params, sensor=k, spp=h,
                                           seed=seed32(seed + 99_991 + 7 * k + j)))
                        for j, h in enumerate(halves))
                img = (a * halves[0] + b * halves[1]) / sum(halves)
                w = 1.0 / (t * t + REL_EPS)
                rel.append(float(np.mean((img - t) ** 2 * w)))
                expected.append(float(np.mean((a - t) * (b - t) * w)))
        return {"learning_rate_scale": lr_scale, "learning_rates": rates, "spp": spp,
                "smoothness": smoothness, "iterations": it, "seconds": elapsed,
                "ms_per_iteration": 1e3 * elapsed / max(it, 1), "warmup_s": warmup,
                "texture_rmse_observed": obs, "texture_rmse": all_,
                "texture_rmse_observed_per_texture": per, "image_relmse": float(np.mean(rel)),
                "image_relmse_expected": float(np.mean(expected)), "curve": curve}


def tune(race, smoothness, budget_s, seed, spp):
    """The learning rate (x1/3, x1, x3 the task's Adam rate) and spp (spp, spp x 4) by the
    lowest observed-texel RMSE after `budget_s` on another seed's targets."""
    targets = race.targets(seed)
    trials = []
    for s in (spp, spp * 4):
        for scale in (1 / 3, 1.0, 3.0):
            r = race.run(targets, scale, s, smoothness, budget_s, seed, curve_points=2)
            trials.append({"learning_rate_scale": scale, "spp": s,
                           "texture_rmse_observed": r["texture_rmse_observed"]})
            print(f"mitsuba_race: tune spp {s} rate x{scale:.3g}: {r['texture_rmse_observed']:.4f}",
                  flush=True)
    best = min(trials, key=lambda t: t["texture_rmse_observed"])
    return best, trials


def main(argv=None):
    args = parse_args(argv)
    ex = Exchange(args.exchange)
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as e:
        fail(f"Mitsuba 3 is not installed ({e}): `pip install mitsuba`, and LLVM >= 15 from the "
             "system's packages (Debian: apt-get install libllvm19)")
    mi.set_variant("llvm_ad_rgb")
    if args.threads > 0:
        dr.set_thread_count(args.threads)
    race = Race(mi, dr, ex)
    budget = args.budget_s or ex["budget_s"]
    seed = ex["seed"]
    t0 = time.perf_counter()
    targets = race.targets(seed)
    targets_s = time.perf_counter() - t0
    forward = race.forward_check(targets)
    for f in forward:
        print(f"mitsuba_race: camera {f['camera']}: Mitsuba's target mean / psrestir's "
              f"{f['mean_ratio']:.3f}, image relMSE between them {f['relmse']:.4g}", flush=True)
    rows = [("plain", 0.0)]
    if ex["smoothness"] > 0:
        rows.append(("priors", float(ex["smoothness"])))
    out = []
    for name, smoothness in rows:
        scale, spp, trials = 1.0, args.spp, None
        if args.tune:
            kept = load_tuned(args.tuned)
            if name in kept:
                best, trials = kept[name]["best"], kept[name]["trials"]
                print(f"mitsuba_race: {name}: the search's choice from {args.tuned}", flush=True)
            else:
                best, trials = tune(race, smoothness, args.tune_budget_s or budget / 3, seed + 7919, args.spp)
                kept[name] = {"best": best, "trials": trials}
                save_json(args.tuned, kept)
            scale, spp = best["learning_rate_scale"], best["spp"]
        r = race.run(targets, scale, spp, smoothness, budget, seed)
        r["row"] = name
        r["tuned"] = trials
        out.append(r)
        print(f"mitsuba_race: {name}: {r['iterations']} iterations in {r['seconds']:.1f} s, "
              f"observed-texel RMSE {r['curve'][0]['texture_rmse_observed']:.4f} -> "
              f"{r['texture_rmse_observed']:.4f}, image relMSE {r['image_relmse_expected']:.4g}", flush=True)
    result = {"version": EXCHANGE_VERSION, "mitsuba": mi.__version__, "variant": mi.variant(),
              "threads": dr.thread_count(), "targets_s": targets_s, "forward": forward, "rows": out}
    os.makedirs(args.out, exist_ok=True)
    save_json(os.path.join(args.out, "result.json"), result)


def load_tuned(path):
    """Earlier searches kept in `path` (per row), or none."""
    if path is None or not os.path.exists(path):
        return {}
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        fail(f"{path}: {e}")


def save_json(path, value):
    """`value` as JSON in `path`, atomically (NaN written as null)."""
    if path is None:
        return
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(finite_or_none(value), f, indent=1, allow_nan=False)
    os.replace(tmp, path)


if __name__ == "__main__":
    main()
