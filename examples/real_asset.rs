//! Write a real-asset-sized task: a camera-less, light-less GLB whose material has 2048²
//! JPEG base color, metallic-roughness and normal textures (as glTF sample models and
//! photogrammetry exports carry), four views at 128² in a NeRF-style `transforms.json`, and a
//! task that recovers the 2048² base color from renders of the asset itself, from gray.
//!
//!     cargo run --release --example real_asset -- OUT_DIR
//!     psrestir optimize OUT_DIR/task.toml --time-budget 300 [--method restir]
use psrestir::assets::authoring::{uv_sphere, GltfBuilder};
use psrestir::glam::{Mat4, Vec3};
use psrestir::scene::Camera;
use serde_json::json;
use std::path::Path;

const SIZE: u32 = 2048;

fn jpeg(rgb: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 92)
        .encode(rgb, SIZE, SIZE, image::ExtendedColorType::Rgb8)
        .expect("JPEG encoding");
    out
}

/// RGB texels of a 2048² texture from `f(u, v)` (u, v in [0, 1)).
fn texture(f: impl Fn(f32, f32) -> [f32; 3]) -> Vec<u8> {
    let mut out = Vec::with_capacity((SIZE * SIZE * 3) as usize);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let (u, v) = (
                (x as f32 + 0.5) / SIZE as f32,
                (y as f32 + 0.5) / SIZE as f32,
            );
            out.extend(f(u, v).map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8));
        }
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args().nth(1).ok_or("usage: real_asset OUT_DIR")?;
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir)?;
    use std::f32::consts::TAU;
    // An albedo with large painted regions and fine detail; a rough dielectric with a
    // metallic band; bumps of several sizes in the normal map.
    let base = jpeg(&texture(|u, v| {
        let band = (v * 6.0).floor() as i32 % 3;
        let hue = [[0.75, 0.35, 0.2], [0.25, 0.55, 0.7], [0.85, 0.8, 0.45]][band as usize];
        let d = 0.85 + 0.15 * (u * TAU * 24.0).sin() * (v * TAU * 12.0).sin();
        hue.map(|c| c * d)
    }));
    let mr = jpeg(&texture(|_u, v| {
        let metal = if (0.45..0.55).contains(&v) { 1.0 } else { 0.0 };
        [0.0, 0.45 + 0.2 * (v * TAU * 3.0).sin(), metal]
    }));
    let normal = jpeg(&texture(|u, v| {
        let (dx, dy) = (
            0.3 * (u * TAU * 40.0).cos() + 0.1 * (u * TAU * 160.0).cos(),
            0.3 * (v * TAU * 20.0).cos(),
        );
        let n = Vec3::new(dx, dy, 1.0).normalize();
        [n.x, n.y, n.z].map(|c| 0.5 * (c + 1.0))
    }));
    let mut b = GltfBuilder::new();
    let tex = |b: &mut GltfBuilder, name: &str, bytes: &[u8]| {
        let img = b.add_image_embedded(name, bytes, "image/jpeg");
        b.add_texture(img, None)
    };
    let (tb, tm, tn) = (
        tex(&mut b, "albedo", &base),
        tex(&mut b, "metal_rough", &mr),
        tex(&mut b, "normal", &normal),
    );
    let mat = b.add_material(json!({
        "name": "body",
        "pbrMetallicRoughness": {
            "baseColorTexture": {"index": tb},
            "metallicRoughnessTexture": {"index": tm}
        },
        "normalTexture": {"index": tn, "scale": 1.0}
    }));
    let (p, n, uv, idx) = uv_sphere([0.0, 0.0, 0.0], 1.0, 96, 48);
    let mesh = b.add_mesh("body", &p, Some(&n), Some(&uv), Some(&idx), Some(mat));
    let node = b.add_node(json!({"mesh": mesh, "name": "body"}));
    b.set_scene(&[node]);
    b.write_glb(&dir.join("asset.glb"))?;

    // Four views around and above the sphere, 128² pinholes.
    let frames: Vec<serde_json::Value> = [
        Vec3::new(0.0, 0.8, 3.0),
        Vec3::new(3.0, 0.2, 0.0),
        Vec3::new(0.0, 1.2, -2.8),
        Vec3::new(-2.6, -0.6, 1.0),
    ]
    .iter()
    .enumerate()
    .map(|(i, eye)| {
        let m: Mat4 = Camera::look_at("v", *eye, Vec3::ZERO, Vec3::Y, 0.8).world;
        let rows: Vec<Vec<f32>> = (0..4).map(|r| m.row(r).to_array().to_vec()).collect();
        json!({"file_path": format!("view_{i}"), "transform_matrix": rows})
    })
    .collect();
    let transforms = json!({"camera_angle_x": 0.8, "w": 128, "h": 128, "frames": frames});
    std::fs::write(
        dir.join("transforms.json"),
        serde_json::to_string_pretty(&transforms)?,
    )?;
    std::fs::write(
        dir.join("task.toml"),
        r#"# A real-asset-sized task (written by `cargo run --example real_asset`): recover the
# 2048² base color of a camera-less, light-less GLB (JPEG textures with a normal map) from
# four 128² renders of itself under the default environment, from gray.
scene = "asset.glb"
cameras_file = "transforms.json"
width = 128
height = 128
seed = 3
output = "out"

[target]
scene = "asset.glb"
spp = 256

[optimizer]
time_budget_s = 300
primal_spp = 4
gradient_spp = 2
primal = "control_variate"
schedule = { kind = "cosine", final = 0.05 }
multiscale_levels = 4
smoothness = 0.01

[[textures]]
material = "body"
slot = "base_color"
resolution = [2048, 2048]
init = [0.5, 0.5, 0.5]
learning_rate = 0.02
"#,
    )?;
    println!("wrote {}", dir.display());
    Ok(())
}
