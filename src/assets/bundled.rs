//! Generator of the bundled scenes under `scenes/` (run `psrestir make-scenes`).
use super::authoring::{box_triangles, png_bytes, uv_sphere, GltfBuilder};
use crate::image_io::write_atomic_with;
use crate::Result;
use glam::{Mat4, Vec3};
use serde_json::json;
use std::path::Path;

pub(crate) fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Vec<f32> {
    // Camera-to-world: -Z looks at the target, +Y is as close to `up` as it can be.
    let f = (target - eye).normalize();
    let r = f.cross(up).normalize();
    let u = r.cross(f);
    Mat4::from_cols(
        r.extend(0.0),
        u.extend(0.0),
        (-f).extend(0.0),
        eye.extend(1.0),
    )
    .to_cols_array()
    .to_vec()
}

pub(crate) fn srgb8(v: f32) -> u8 {
    (crate::image_io::linear_to_srgb(v) * 255.0 + 0.5) as u8
}

/// Write `scenes/default`: a textured sphere, a cube in a transform hierarchy and a checkered
/// floor, lit by an emissive quad, a point, a spot and a directional light; two cameras; and
/// a small sky environment map (`sky.exr`) for `--env`.
pub fn write_default_scene(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| crate::Error::file(dir, e.to_string()))?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_texture_transform");
    b.use_extension("KHR_materials_emissive_strength");

    let floor = add_floor(&mut b, dir)?;
    let sphere = add_sphere(&mut b, dir)?;

    // Cube without normals (flat normals computed on load), inside a rotated, scaled group.
    let cube_mat = b.add_material(json!({
        "name": "cube",
        "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.6, 0.25, 1.0],
            "metallicFactor": 0.0, "roughnessFactor": 0.4}
    }));
    let cp = box_triangles([0.0; 3], [0.5; 3]);
    let cube = b.add_mesh("cube", &cp, None, None, None, Some(cube_mat));

    // Area light: a one-sided emissive quad facing down.
    let light_mat = b.add_material(json!({
        "name": "area_light",
        "emissiveFactor": [1.0, 0.9, 0.75],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 12.0}},
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]}
    }));
    let q = 0.6;
    let quad = b.add_mesh(
        "area_light",
        &[[-q, 0.0, -q], [q, 0.0, -q], [q, 0.0, q], [-q, 0.0, q]],
        Some(&[[0.0, -1.0, 0.0]; 4]),
        None,
        Some(&[0, 1, 2, 0, 2, 3]),
        Some(light_mat),
    );

    let point = b.add_light(
        json!({"name": "point", "type": "point", "color": [1.0, 0.8, 0.6], "intensity": 6.0}),
    );
    let spot = b.add_light(
        json!({"name": "spot", "type": "spot", "color": [0.6, 0.7, 1.0], "intensity": 25.0,
        "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.45}}),
    );
    let sun = b.add_light(
        json!({"name": "sun", "type": "directional", "color": [1.0, 0.95, 0.9], "intensity": 0.8}),
    );

    let cam_main = b.add_camera("main", 0.7, Some(1.0));
    let cam_top = b.add_camera("top", 0.9, Some(1.0));
    let ext = |l: usize| json!({"KHR_lights_punctual": {"light": l}});
    let nodes = vec![
        b.add_node(json!({"name": "floor", "mesh": floor})),
        b.add_node(json!({"name": "sphere", "mesh": sphere, "translation": [0.0, 1.0, 0.0]})),
        {
            let cube_node = b.add_node(json!({"name": "cube", "mesh": cube, "translation": [0.0, 0.5, 0.0]}));
            b.add_node(json!({"name": "cube_group", "children": [cube_node],
                "translation": [1.9, 0.0, -0.6], "rotation": [0.0, 0.3826834, 0.0, 0.9238795],
                "scale": [0.9, 0.9, 0.9]}))
        },
        b.add_node(json!({"name": "area_light", "mesh": quad, "translation": [-0.8, 3.2, 0.5]})),
        b.add_node(json!({"name": "point", "translation": [-2.5, 2.0, 2.0], "extensions": ext(point)})),
        b.add_node(json!({"name": "spot", "matrix": look_at(Vec3::new(2.5, 4.0, 2.0), Vec3::new(0.0, 1.0, 0.0), Vec3::Y), "extensions": ext(spot)})),
        b.add_node(json!({"name": "sun", "matrix": look_at(Vec3::new(3.0, 5.0, -2.0), Vec3::ZERO, Vec3::Y), "extensions": ext(sun)})),
        b.add_node(json!({"name": "main", "camera": cam_main, "matrix": look_at(Vec3::new(0.0, 2.2, 5.5), Vec3::new(0.0, 0.8, 0.0), Vec3::Y)})),
        b.add_node(json!({"name": "top", "camera": cam_top, "matrix": look_at(Vec3::new(0.5, 6.5, 0.5), Vec3::ZERO, Vec3::NEG_Z)})),
    ];
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;

    write_sky(&dir.join("sky.exr"))
}

/// The default scene's floor: an external checker texture, tiled twice by
/// KHR_texture_transform. Returns its mesh.
fn add_floor(b: &mut GltfBuilder, dir: &Path) -> Result<usize> {
    // Floor: external checker texture, tiled twice by KHR_texture_transform.
    let mut checker = Vec::new();
    for y in 0..64 {
        for x in 0..64 {
            let on = ((x / 8) + (y / 8)) % 2 == 0;
            checker.push(if on {
                [srgb8(0.7), srgb8(0.7), srgb8(0.68), 255]
            } else {
                [srgb8(0.2), srgb8(0.25), srgb8(0.3), 255]
            });
        }
    }
    std::fs::write(dir.join("floor.png"), png_bytes(64, 64, &checker)?)
        .map_err(|e| crate::Error::file(dir.join("floor.png"), e.to_string()))?;
    let floor_img = b.add_image_uri("floor", "floor.png");
    let repeat = b.add_sampler(json!({"wrapS": 10497, "wrapT": 10497, "magFilter": 9729}));
    let floor_tex = b.add_texture(floor_img, Some(repeat));
    let floor_mat = b.add_material(json!({
        "name": "floor",
        "pbrMetallicRoughness": {
            "baseColorTexture": {"index": floor_tex,
                "extensions": {"KHR_texture_transform": {"scale": [2.0, 2.0]}}},
            "metallicFactor": 0.0, "roughnessFactor": 0.8
        }
    }));
    let s = 4.0;
    Ok(b.add_mesh(
        "floor",
        &[[-s, 0.0, -s], [s, 0.0, -s], [s, 0.0, s], [-s, 0.0, s]],
        Some(&[[0.0, 1.0, 0.0]; 4]),
        Some(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
        Some(&[0, 2, 1, 0, 3, 2]),
        Some(floor_mat),
    ))
}

/// The default scene's sphere: an embedded base color texture and an external
/// metallic-roughness texture. Returns its mesh.
fn add_sphere(b: &mut GltfBuilder, dir: &Path) -> Result<usize> {
    // Sphere: embedded base color texture, external metallic-roughness texture.
    let (w, h) = (128u32, 64u32);
    let mut color = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let band = (x / 16 + y / 16) % 3;
            let c = match band {
                0 => [0.8, 0.2, 0.1],
                1 => [0.1, 0.5, 0.8],
                _ => [0.9, 0.8, 0.3],
            };
            color.push([srgb8(c[0]), srgb8(c[1]), srgb8(c[2]), 255]);
        }
    }
    let color_png = png_bytes(w, h, &color)?;
    let color_img = b.add_image_embedded("sphere_color", &color_png, "image/png");
    let color_tex = b.add_texture(color_img, None);
    let mut mr = Vec::new();
    for y in 0..32u32 {
        for x in 0..64u32 {
            let rough = 0.15 + 0.8 * x as f32 / 63.0;
            let metal = if (y / 8) % 2 == 0 { 0 } else { 255 };
            mr.push([0, (rough * 255.0) as u8, metal, 255]);
        }
    }
    std::fs::write(dir.join("sphere_mr.png"), png_bytes(64, 32, &mr)?)
        .map_err(|e| crate::Error::file(dir.join("sphere_mr.png"), e.to_string()))?;
    let mr_img = b.add_image_uri("sphere_mr", "sphere_mr.png");
    let mr_tex = b.add_texture(mr_img, None);
    let sphere_mat = b.add_material(json!({
        "name": "sphere",
        "pbrMetallicRoughness": {
            "baseColorTexture": {"index": color_tex},
            "metallicRoughnessTexture": {"index": mr_tex},
            "metallicFactor": 1.0, "roughnessFactor": 1.0
        }
    }));
    let (p, n, t, idx) = uv_sphere([0.0, 0.0, 0.0], 1.0, 100, 50);
    Ok(b.add_mesh(
        "sphere",
        &p,
        Some(&n),
        Some(&t),
        Some(&idx),
        Some(sphere_mat),
    ))
}

/// A small sky (64x32, equirectangular): bright zenith, horizon glow, dark ground.
pub fn write_sky(path: &Path) -> Result<()> {
    let (ew, eh) = (64usize, 32usize);
    let mut sky = vec![(0f32, 0f32, 0f32); ew * eh];
    for j in 0..eh {
        let v = (j as f32 + 0.5) / eh as f32;
        let up = (std::f32::consts::PI * v).cos();
        for i in 0..ew {
            sky[j * ew + i] = if up > 0.0 {
                let t = up.powf(0.5);
                (0.9 - 0.5 * t, 0.95 - 0.35 * t, 1.0)
            } else {
                (0.15, 0.13, 0.1)
            };
        }
    }
    write_atomic_with(path, |tmp| {
        exr::prelude::write_rgb_file(tmp, ew, eh, |x, y| sky[y * ew + x])
            .map_err(std::io::Error::other)
    })
}
