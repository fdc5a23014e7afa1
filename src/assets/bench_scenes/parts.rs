//! What the benchmark scenes are built from: the texture size, procedural textures and their
//! PNGs, the task files' common part, the floor, area lights and cameras.
use crate::assets::authoring::{png_bytes, quad_facing, GltfBuilder};
use crate::assets::bundled::look_at;
use crate::image_io::write_atomic;
use crate::{Error, Result};
use glam::Vec3;
use serde_json::json;
use std::path::Path;

/// Texture resolution of the ground truth and of the optimized textures.
const TEX: u32 = 256;

pub(in crate::assets) fn create(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))
}

/// A deterministic hash to [0, 1) for procedural patterns.
pub(in crate::assets) fn hash(a: u32, b: u32) -> f32 {
    let mut h = a.wrapping_mul(0x9E37_79B9) ^ b.wrapping_mul(0x85EB_CA6B);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2C1B_3C6D);
    h ^= h >> 12;
    (h >> 8) as f32 / (1u32 << 24) as f32
}

/// A `TEX` x `TEX` RGBA8 image from a function of the texel centre's UV.
pub(in crate::assets) fn texture(f: impl Fn(f32, f32) -> [u8; 4]) -> Vec<[u8; 4]> {
    let mut out = Vec::with_capacity((TEX * TEX) as usize);
    for y in 0..TEX {
        for x in 0..TEX {
            out.push(f(
                (x as f32 + 0.5) / TEX as f32,
                (y as f32 + 0.5) / TEX as f32,
            ));
        }
    }
    out
}

pub(in crate::assets) fn unit(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

pub(in crate::assets) fn write_png(dir: &Path, name: &str, rgba: &[[u8; 4]]) -> Result<()> {
    write_atomic(&dir.join(name), &png_bytes(TEX, TEX, rgba)?)
}

/// Target and optimizer settings shared by every benchmark task.
pub(in crate::assets) const TASK_COMMON: &str = r#"
[target]
scene = "scene.gltf"
spp = 256

[optimizer]
time_budget_s = 60
primal_spp = 2
gradient_spp = 1
loss = "l2"
filter = "bilinear"
checkpoint_every = 50
# Cosine decay to 5%: with a constant rate Adam's normalized steps keep every texel
# random-walking by about the rate per step (the default task: observed-texel RMSE 0.239
# constant, 0.217 cosine after 150 iterations).
schedule = { kind = "cosine", final = 0.05 }
# The smoothness prior (README, Results): 150-iteration scan of 0 / 0.01 / 0.03 / 0.1 on the
# four bench tasks; with it every run ended at its lowest observed-texel RMSE.
smoothness = 0.03
"#;

/// `task.toml`: the scene-specific head, the shared settings, then the textures.
pub(in crate::assets) fn write_task(dir: &Path, head: &str, textures: &str) -> Result<()> {
    write_task_named(dir, "task.toml", head, textures)
}

/// [`write_task`] into the file `name`.
fn write_task_named(dir: &Path, name: &str, head: &str, textures: &str) -> Result<()> {
    let text = format!("{head}{TASK_COMMON}{textures}");
    write_atomic(&dir.join(name), text.as_bytes())
}

/// An emissive square of side `size` at `at`, facing `toward`, with `color` x `strength`.
pub(in crate::assets) fn area_light(
    b: &mut GltfBuilder,
    name: &str,
    at: [f32; 3],
    toward: [f32; 3],
    size: f32,
    color: [f32; 3],
    strength: f32,
) -> usize {
    let m = b.add_material(json!({
        "name": name,
        "emissiveFactor": color,
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": strength}},
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]}
    }));
    let (p, n, idx) = quad_facing(at, toward, size);
    let mesh = b.add_mesh(name, &p, Some(&n), None, Some(&idx), Some(m));
    b.add_node(json!({"name": name, "mesh": mesh}))
}

/// A diffuse floor square of half-size `s` at height 0.
pub(in crate::assets) fn floor(b: &mut GltfBuilder, s: f32, color: f32) -> usize {
    let m = b.add_material(json!({
        "name": "floor",
        "pbrMetallicRoughness": {"baseColorFactor": [color, color, color, 1.0],
            "metallicFactor": 0.0, "roughnessFactor": 0.9}
    }));
    let mesh = b.add_mesh(
        "floor",
        &[[-s, 0.0, -s], [s, 0.0, -s], [s, 0.0, s], [-s, 0.0, s]],
        Some(&[[0.0, 1.0, 0.0]; 4]),
        None,
        Some(&[0, 2, 1, 0, 3, 2]),
        Some(m),
    );
    b.add_node(json!({"name": "floor", "mesh": mesh}))
}

pub(in crate::assets) fn camera(
    b: &mut GltfBuilder,
    name: &str,
    yfov: f32,
    eye: [f32; 3],
    target: [f32; 3],
) -> usize {
    let c = b.add_camera(name, yfov, Some(1.0));
    b.add_node(json!({"name": name, "camera": c,
        "matrix": look_at(Vec3::from(eye), Vec3::from(target), Vec3::Y)}))
}
