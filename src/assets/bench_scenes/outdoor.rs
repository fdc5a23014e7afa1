//! The benchmark scene under a light that is not given (see `bench_scenes`): `outdoor`, a
//! textured sphere on a gray floor under a sky with a sun, seen by three cameras; the fit
//! starts its environment from a uniform gray and is judged by relighting under two held-out
//! skies (a low orange sun from the other side, and an overcast sky).
use super::parts::{camera, create, floor, texture, unit, write_png, write_task};
use crate::assets::authoring::{uv_sphere, GltfBuilder};
use crate::assets::bundled::srgb8;
use crate::image_io::write_atomic_with;
use crate::scene::EnvMap;
use crate::Result;
use glam::Vec3;
use serde_json::json;
use std::path::Path;

/// A sky: a gradient from the horizon to the zenith, a dim ground below the horizon, and a
/// sun (a disc of `radius` radians with a glow) when `sun` is nonzero.
struct Sky {
    zenith: [f32; 3],
    horizon: [f32; 3],
    ground: [f32; 3],
    /// Sun direction (towards it), color x radiance, angular radius.
    sun: Vec3,
    sun_rgb: [f32; 3],
    radius: f32,
}

impl Sky {
    fn radiance(&self, d: Vec3) -> [f32; 3] {
        let mut c = if d.y < 0.0 {
            self.ground
        } else {
            let t = d.y.sqrt();
            std::array::from_fn(|k| self.horizon[k] + (self.zenith[k] - self.horizon[k]) * t)
        };
        if self.sun != Vec3::ZERO {
            let angle = d.dot(self.sun).clamp(-1.0, 1.0).acos();
            let disc = (1.0 - (angle - self.radius) / 0.02).clamp(0.0, 1.0);
            let glow = 0.04 * (-angle / 0.25).exp();
            for k in 0..3 {
                c[k] += self.sun_rgb[k] * (disc + glow);
            }
        }
        c
    }

    /// The lat-long map, `w` x `h`, each texel the mean of 4 x 4 directions over it.
    fn map(&self, w: u32, h: u32) -> Vec<[f32; 3]> {
        let mut out = Vec::with_capacity((w * h) as usize);
        for j in 0..h {
            for i in 0..w {
                let mut acc = [0f32; 3];
                for s in 0..16 {
                    let u = (i as f32 + (s % 4) as f32 / 4.0 + 0.125) / w as f32;
                    let v = (j as f32 + (s / 4) as f32 / 4.0 + 0.125) / h as f32;
                    let c = self.radiance(EnvMap::direction(u, v));
                    for k in 0..3 {
                        acc[k] += c[k] / 16.0;
                    }
                }
                out.push(acc);
            }
        }
        out
    }

    fn write(&self, path: &Path) -> Result<()> {
        let (w, h) = (64usize, 32usize);
        let rgb = self.map(w as u32, h as u32);
        write_atomic_with(path, |tmp| {
            exr::prelude::write_rgb_file(tmp, w, h, |x, y| {
                let c = rgb[y * w + x];
                (c[0], c[1], c[2])
            })
            .map_err(std::io::Error::other)
        })
    }
}

/// The direction at elevation `elev` and azimuth `u` (the lat-long map's u) in degrees/turns.
fn toward(elev_deg: f32, u: f32) -> Vec3 {
    EnvMap::direction(u, 0.5 - elev_deg / 180.0)
}

/// The sky that lights the targets: a warm sun 40 degrees up, a blue sky.
fn truth_sky() -> Sky {
    Sky {
        zenith: [0.25, 0.4, 0.8],
        horizon: [0.7, 0.75, 0.85],
        ground: [0.12, 0.1, 0.08],
        sun: toward(40.0, 0.15),
        sun_rgb: [60.0, 54.0, 44.0],
        radius: 0.09,
    }
}

/// The held-out skies the recovery is relit under.
fn held_out() -> [(&'static str, Sky); 2] {
    [
        (
            "relight_dusk.exr",
            Sky {
                zenith: [0.12, 0.16, 0.3],
                horizon: [0.55, 0.38, 0.25],
                ground: [0.08, 0.06, 0.05],
                sun: toward(12.0, 0.65),
                sun_rgb: [50.0, 25.0, 10.0],
                radius: 0.09,
            },
        ),
        (
            "relight_overcast.exr",
            Sky {
                zenith: [0.95, 0.97, 1.0],
                horizon: [0.6, 0.62, 0.66],
                ground: [0.15, 0.15, 0.15],
                sun: Vec3::ZERO,
                sun_rgb: [0.0; 3],
                radius: 0.0,
            },
        ),
    ]
}

/// Base color and roughness of a sphere on a gray floor under the sky, three cameras.
pub fn write_outdoor(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    let color = texture(|u, v| {
        let patch = ((u * 8.0).floor() as i32 + (v * 4.0).floor() as i32).rem_euclid(4);
        let c = match patch {
            0 => [0.7, 0.25, 0.15],
            1 => [0.25, 0.55, 0.3],
            2 => [0.2, 0.3, 0.7],
            _ => [0.8, 0.75, 0.6],
        };
        let ring = 0.75 + 0.25 * (v * 3.0 * std::f32::consts::PI).cos().abs();
        [
            srgb8(c[0] * ring),
            srgb8(c[1] * ring),
            srgb8(c[2] * ring),
            255,
        ]
    });
    write_png(dir, "outdoor_color.png", &color)?;
    let mr = texture(|u, v| {
        let r = if ((u * 6.0).floor() as i32).rem_euclid(2) == 0 {
            0.25
        } else {
            0.7
        };
        [0, unit(r + 0.1 * v), 0, 255]
    });
    write_png(dir, "outdoor_mr.png", &mr)?;
    let ci = b.add_image_uri("outdoor_color", "outdoor_color.png");
    let ct = b.add_texture(ci, None);
    let mi = b.add_image_uri("outdoor_mr", "outdoor_mr.png");
    let mt = b.add_texture(mi, None);
    let mat = b.add_material(json!({
        "name": "sphere",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": ct},
            "metallicRoughnessTexture": {"index": mt},
            "metallicFactor": 0.0, "roughnessFactor": 1.0}
    }));
    let (p, nrm, uv, idx) = uv_sphere([0.0, 0.8, 0.0], 0.8, 96, 48);
    let mesh = b.add_mesh("sphere", &p, Some(&nrm), Some(&uv), Some(&idx), Some(mat));
    let c = [0.0, 0.7, 0.0];
    let nodes = vec![
        b.add_node(json!({"name": "sphere", "mesh": mesh})),
        floor(&mut b, 4.0, 0.5),
        camera(&mut b, "front", 0.75, [0.0, 1.6, 3.6], c),
        camera(&mut b, "left", 0.75, [-3.3, 1.9, 1.4], c),
        camera(&mut b, "back", 0.75, [2.3, 2.6, -2.6], c),
    ];
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    truth_sky().write(&dir.join("sky.exr"))?;
    for (name, sky) in held_out() {
        sky.write(&dir.join(name))?;
    }
    write_task(
        dir,
        r#"# Benchmark scene "outdoor": recover a sphere's base color and roughness and the sky that
# lights it, which the fit is not given: it starts from a uniform gray. The targets are lit by
# sky.exr; the recovery is judged by relighting under two held-out skies (relight.csv). The
# gray floor's material is known, which fixes the scale that albedo and light share.
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
env = "sky.exr"
cameras = ["front", "left", "back"]
width = 128
height = 128
seed = 17
output = "out/bench/outdoor"
relight = ["relight_dusk.exr", "relight_overcast.exr"]
"#,
        r#"
[[textures]]
material = "sphere"
slot = "base_color"
resolution = [256, 256]
init = [0.5, 0.5, 0.5]
learning_rate = 0.03

[[textures]]
material = "sphere"
slot = "roughness"
resolution = [256, 256]
init = 0.5
learning_rate = 0.02

[environment]
resolution = [32, 16]
init = 0.5
learning_rate = 0.05
rebuild_every = 4
"#,
    )
}
