//! Generator of the benchmark scenes under `scenes/bench/` (run `psrestir make-scenes`): the
//! paper's four experiments in miniature, a room lit mostly by indirect light and a gallery
//! whose painting is lit only by bounced light, an atelier whose floor and wall are both
//! recovered, the wall lit only by the floor's bounce, and an object under a sky the fit is not
//! given (`outdoor`), each a glTF scene holding the ground-truth texture and a task file that
//! starts the optimized texture from a constant; and beside them a brick wall whose normal
//! map is recovered (`wall`, [`STUDY_SCENES`]).
use super::authoring::{box_triangles, lathe, uv_sphere, GltfBuilder};
use super::bundled::{look_at, srgb8, write_sky};
use crate::Result;
use glam::Vec3;
use serde_json::json;
use std::path::Path;

mod outdoor;
mod parts;
mod room;
mod wall;

pub(super) use parts::{area_light, camera, hash};
use parts::{create, floor, texture, unit, write_png, write_task};

/// Names of the benchmark scenes, in the order `psrestir bench` runs them.
pub const BENCH_SCENES: [&str; 8] = [
    "vase", "lattice", "dish", "sphere", "room", "gallery", "atelier", "outdoor",
];

/// Scenes that `psrestir make-scenes` writes beside the benchmark scenes and `psrestir bench`
/// runs only when named: `wall`, whose three tasks compare fits with and without its normal
/// map (docs/guide.md, "Normal maps").
pub const STUDY_SCENES: [&str; 1] = ["wall"];

/// Write every benchmark scene into `dir/<name>/`.
pub fn write_bench_scenes(dir: &Path) -> Result<()> {
    write_vase(&dir.join("vase"))?;
    write_lattice(&dir.join("lattice"))?;
    write_dish(&dir.join("dish"))?;
    write_sphere(&dir.join("sphere"))?;
    room::write_room(&dir.join("room"))?;
    room::write_gallery(&dir.join("gallery"))?;
    room::write_atelier(&dir.join("atelier"))?;
    outdoor::write_outdoor(&dir.join("outdoor"))?;
    wall::write_wall(&dir.join("wall"))
}

/// The paper's tire and chalice: a roughness texture on a curved metallic vase lit by three
/// colored area lights and an environment map.
pub fn write_vase(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    // Roughness (green channel) in diagonal bands, a rough belt and a slow ramp; metallic 1.
    let mr = texture(|u, v| {
        let band = ((u * 12.0 + v * 6.0).floor() as i32).rem_euclid(2) == 0;
        let mut r = if band { 0.12 } else { 0.5 } + 0.2 * v;
        if (0.45..0.55).contains(&v) {
            r = 0.85;
        }
        [0, unit(r), 255, 255]
    });
    write_png(dir, "vase_mr.png", &mr)?;
    let img = b.add_image_uri("vase_mr", "vase_mr.png");
    let tex = b.add_texture(img, None);
    let mat = b.add_material(json!({
        "name": "vase",
        "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.8, 0.55, 1.0],
            "metallicRoughnessTexture": {"index": tex},
            "metallicFactor": 1.0, "roughnessFactor": 1.0}
    }));
    let mut profile = vec![[0.0, 0.0]];
    let n = 80;
    for i in 0..=n {
        let t = i as f32 / n as f32;
        let pi = std::f32::consts::PI;
        profile.push([
            0.28 + 0.32 * (pi * t).sin() + 0.08 * (3.0 * pi * t).sin(),
            1.6 * t,
        ]);
    }
    profile.push([0.0, 1.62]);
    let (p, nrm, uv, idx) = lathe(&profile, 96);
    let mesh = b.add_mesh("vase", &p, Some(&nrm), Some(&uv), Some(&idx), Some(mat));
    let mut nodes = vec![b.add_node(json!({"name": "vase", "mesh": mesh}))];
    let c = [0.0, 0.8, 0.0];
    nodes.push(area_light(
        &mut b,
        "light_red",
        [-2.0, 1.6, 1.2],
        c,
        0.7,
        [1.0, 0.35, 0.2],
        10.0,
    ));
    nodes.push(area_light(
        &mut b,
        "light_green",
        [2.2, 0.6, 1.0],
        c,
        0.6,
        [0.3, 1.0, 0.4],
        10.0,
    ));
    nodes.push(area_light(
        &mut b,
        "light_blue",
        [0.4, 3.0, 1.8],
        c,
        0.8,
        [0.35, 0.5, 1.0],
        8.0,
    ));
    nodes.push(camera(
        &mut b,
        "main",
        0.62,
        [0.0, 1.3, 3.2],
        [0.0, 0.8, 0.0],
    ));
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    write_sky(&dir.join("sky.exr"))?;
    write_task(
        dir,
        r#"# Benchmark scene "vase" (the paper's tire and chalice): recover the roughness texture of a
# curved metallic vase lit by three colored area lights and an environment map.
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
env = "sky.exr"
env_scale = 0.6
cameras = ["main"]
width = 128
height = 128
seed = 11
output = "out/bench/vase"
"#,
        r#"
[[textures]]
material = "vase"
slot = "roughness"
resolution = [256, 256]
init = 0.5
learning_rate = 0.02
"#,
    )
}

/// The paper's Christmas tree: a base color texture on a wall seen through, and shadowed by,
/// two layers of thin bars lit by a small area light and the sun, so that visibility makes
/// the gradient sparse.
pub fn write_lattice(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    b.use_extension("KHR_lights_punctual");
    // Colored baubles on a green-to-teal background.
    let color = texture(|u, v| {
        let mut c = [0.08 + 0.1 * u, 0.35 - 0.15 * v, 0.12 + 0.2 * v];
        let cells = 8.0;
        let (cx, cy) = ((u * cells).floor(), (v * cells).floor());
        let (i, j) = (cx as u32, cy as u32);
        let (ox, oy) = (
            cx + 0.3 + 0.4 * hash(i, j),
            cy + 0.3 + 0.4 * hash(j + 17, i),
        );
        let d = ((u * cells - ox).powi(2) + (v * cells - oy).powi(2)).sqrt();
        if d < 0.28 {
            c = match (hash(i + 5, j + 9) * 3.0) as u32 {
                0 => [0.85, 0.1, 0.08],
                1 => [0.95, 0.75, 0.2],
                _ => [0.15, 0.3, 0.9],
            };
        }
        [srgb8(c[0]), srgb8(c[1]), srgb8(c[2]), 255]
    });
    write_png(dir, "wall_color.png", &color)?;
    let img = b.add_image_uri("wall_color", "wall_color.png");
    let tex = b.add_texture(img, None);
    let wall_mat = b.add_material(json!({
        "name": "wall",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": tex},
            "metallicFactor": 0.0, "roughnessFactor": 0.7}
    }));
    let s = 1.5;
    let wall = b.add_mesh(
        "wall",
        &[
            [-s, 0.0, 0.0],
            [s, 0.0, 0.0],
            [s, 2.0 * s, 0.0],
            [-s, 2.0 * s, 0.0],
        ],
        Some(&[[0.0, 0.0, 1.0]; 4]),
        Some(&[[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]),
        Some(&[0, 1, 2, 0, 2, 3]),
        Some(wall_mat),
    );
    // Bars: vertical ones close to the wall, horizontal ones further out.
    let mut bars = Vec::new();
    for i in 0..13 {
        let x = -1.5 + 0.25 * i as f32;
        bars.extend(box_triangles([x, 1.5, 0.6], [0.015, 1.6, 0.015]));
    }
    for j in 0..10 {
        let y = 0.15 + 0.3 * j as f32;
        bars.extend(box_triangles([0.0, y, 1.1], [1.7, 0.012, 0.012]));
    }
    let bar_mat = b.add_material(json!({
        "name": "bars",
        "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.2, 0.12, 1.0],
            "metallicFactor": 0.0, "roughnessFactor": 0.6}
    }));
    let bar_mesh = b.add_mesh("bars", &bars, None, None, None, Some(bar_mat));
    let sun = b.add_light(
        json!({"name": "sun", "type": "directional", "color": [1.0, 0.95, 0.85], "intensity": 2.5}),
    );
    let mut nodes = vec![
        b.add_node(json!({"name": "wall", "mesh": wall})),
        b.add_node(json!({"name": "bars", "mesh": bar_mesh})),
        b.add_node(json!({"name": "sun",
            "matrix": look_at(Vec3::new(-3.0, 4.0, 4.0), Vec3::ZERO, Vec3::Y),
            "extensions": {"KHR_lights_punctual": {"light": sun}}})),
    ];
    nodes.push(area_light(
        &mut b,
        "lamp",
        [1.6, 3.2, 3.0],
        [0.0, 1.5, 0.0],
        0.15,
        [1.0, 0.85, 0.6],
        400.0,
    ));
    nodes.push(camera(
        &mut b,
        "main",
        0.8,
        [0.3, 1.5, 4.0],
        [0.0, 1.5, 0.0],
    ));
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    write_task(
        dir,
        r#"# Benchmark scene "lattice" (the paper's Christmas tree): recover the base color texture of
# a wall seen through, and shadowed by, two layers of thin bars (sparse gradients).
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
cameras = ["main"]
width = 128
height = 128
seed = 12
output = "out/bench/lattice"
"#,
        r#"
[[textures]]
material = "wall"
slot = "base_color"
resolution = [256, 256]
init = [0.5, 0.5, 0.5]
learning_rate = 0.03
"#,
    )
}

/// The paper's ashtray: a metallic texture on a glossy copper dish on a floor, under a few
/// area lights.
pub fn write_dish(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    // Metallic (blue channel): rings along the profile, spokes on the inner floor and a ramp
    // around the rim; roughness (green) constant 0.3.
    let mr = texture(|u, v| {
        let m = if v > 0.72 {
            ((u * 16.0).floor() as i32 % 2 == 0) as u8 as f32
        } else if (0.42..0.5).contains(&v) {
            u
        } else {
            ((v * 14.0).floor() as i32 % 2 == 0) as u8 as f32
        };
        [0, unit(0.3), unit(m), 255]
    });
    write_png(dir, "dish_mr.png", &mr)?;
    let img = b.add_image_uri("dish_mr", "dish_mr.png");
    let tex = b.add_texture(img, None);
    let mat = b.add_material(json!({
        "name": "dish",
        "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.64, 0.54, 1.0],
            "metallicRoughnessTexture": {"index": tex},
            "metallicFactor": 1.0, "roughnessFactor": 1.0}
    }));
    // Outer bottom, outer wall, lip, inner wall and inner floor, as one profile.
    let mut profile = vec![[0.0, 0.0], [0.8, 0.0]];
    let n = 16;
    for i in 1..=n {
        let t = i as f32 / n as f32;
        let a = t * std::f32::consts::FRAC_PI_2;
        profile.push([0.8 + 0.2 * a.sin(), 0.25 * (1.0 - a.cos())]);
    }
    for i in 1..=n {
        let a = i as f32 / n as f32 * std::f32::consts::PI;
        profile.push([0.96 + 0.04 * a.cos(), 0.25 + 0.04 * a.sin()]);
    }
    for i in 1..=n {
        let t = i as f32 / n as f32;
        let a = t * std::f32::consts::FRAC_PI_2;
        profile.push([0.92 - 0.2 * a.sin(), 0.25 - 0.15 * (1.0 - a.cos())]);
    }
    profile.push([0.4, 0.1]);
    profile.push([0.0, 0.1]);
    let (p, nrm, uv, idx) = lathe(&profile, 96);
    let mesh = b.add_mesh("dish", &p, Some(&nrm), Some(&uv), Some(&idx), Some(mat));
    let mut nodes = vec![
        b.add_node(json!({"name": "dish", "mesh": mesh})),
        floor(&mut b, 3.0, 0.5),
    ];
    let c = [0.0, 0.1, 0.0];
    nodes.push(area_light(
        &mut b,
        "key",
        [-1.2, 2.5, 0.8],
        c,
        0.8,
        [1.0, 0.95, 0.85],
        12.0,
    ));
    nodes.push(area_light(
        &mut b,
        "fill",
        [1.5, 1.8, -0.6],
        c,
        0.6,
        [0.75, 0.85, 1.0],
        8.0,
    ));
    nodes.push(area_light(
        &mut b,
        "rim",
        [0.3, 1.2, -2.0],
        c,
        0.5,
        [1.0, 0.9, 0.8],
        10.0,
    ));
    nodes.push(camera(
        &mut b,
        "main",
        0.75,
        [0.0, 2.0, 2.0],
        [0.0, 0.05, 0.0],
    ));
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    write_task(
        dir,
        r#"# Benchmark scene "dish" (the paper's ashtray): recover the metallic texture of a glossy
# copper dish under three area lights.
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
cameras = ["main"]
width = 128
height = 128
seed = 13
output = "out/bench/dish"
# Lit by its area lights alone: no default environment.
default_environment = false
"#,
        r#"
[[textures]]
material = "dish"
slot = "metallic"
resolution = [256, 256]
init = 0.5
learning_rate = 0.03
"#,
    )
}

/// Two textures at once (base color and roughness) on a sphere, seen by two cameras.
pub fn write_sphere(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    let color = texture(|u, v| {
        let stripe = ((u * 10.0 + (v * 6.0).sin()).floor() as i32).rem_euclid(3);
        let c = match stripe {
            0 => [0.75, 0.3, 0.12],
            1 => [0.2, 0.45, 0.7],
            _ => [0.85, 0.85, 0.8],
        };
        let shade = 0.6 + 0.4 * (v * std::f32::consts::PI).sin();
        [
            srgb8(c[0] * shade),
            srgb8(c[1] * shade),
            srgb8(c[2] * shade),
            255,
        ]
    });
    write_png(dir, "sphere_color.png", &color)?;
    let mr = texture(|u, v| {
        let spots = ((u * 8.0).fract() - 0.5).powi(2) + ((v * 4.0).fract() - 0.5).powi(2) < 0.06;
        let r = if spots { 0.1 } else { 0.3 + 0.5 * u };
        [0, unit(r), 0, 255]
    });
    write_png(dir, "sphere_mr.png", &mr)?;
    let ci = b.add_image_uri("sphere_color", "sphere_color.png");
    let ct = b.add_texture(ci, None);
    let mi = b.add_image_uri("sphere_mr", "sphere_mr.png");
    let mt = b.add_texture(mi, None);
    let mat = b.add_material(json!({
        "name": "sphere",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": ct},
            "metallicRoughnessTexture": {"index": mt},
            "metallicFactor": 0.0, "roughnessFactor": 1.0}
    }));
    let (p, nrm, uv, idx) = uv_sphere([0.0, 1.0, 0.0], 1.0, 96, 48);
    let mesh = b.add_mesh("sphere", &p, Some(&nrm), Some(&uv), Some(&idx), Some(mat));
    let mut nodes = vec![
        b.add_node(json!({"name": "sphere", "mesh": mesh})),
        floor(&mut b, 4.0, 0.4),
    ];
    let c = [0.0, 1.0, 0.0];
    nodes.push(area_light(
        &mut b,
        "key",
        [-2.0, 3.0, 2.0],
        c,
        0.6,
        [1.0, 0.95, 0.9],
        30.0,
    ));
    nodes.push(area_light(
        &mut b,
        "side",
        [2.5, 1.5, 1.0],
        c,
        0.5,
        [0.8, 0.9, 1.0],
        25.0,
    ));
    nodes.push(area_light(
        &mut b,
        "back",
        [0.5, 2.5, -2.5],
        c,
        0.6,
        [1.0, 0.9, 0.8],
        20.0,
    ));
    nodes.push(camera(&mut b, "front", 0.7, [0.0, 1.6, 3.8], c));
    nodes.push(camera(&mut b, "side", 0.7, [3.3, 2.2, -1.5], c));
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    write_task(
        dir,
        r#"# Benchmark scene "sphere": recover two textures at once (base color and roughness) of a
# sphere seen by two cameras.
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
cameras = ["front", "side"]
width = 128
height = 128
seed = 14
output = "out/bench/sphere"
# Lit by its area lights alone: no default environment.
default_environment = false
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
"#,
    )
}
