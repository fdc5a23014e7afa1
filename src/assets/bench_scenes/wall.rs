//! The normal-map scene (see `bench_scenes`): `wall`, a brick wall whose bricks' bevels and
//! bumps are in its normal map, under a sky and grazing suns, one at a time: three captures,
//! two from the front and one oblique. Three tasks on the same targets measure what
//! recovering the normal map is worth: the base color and the normal map recovered together
//! (`task.toml`), the base color alone with the true normal map given
//! (`task_given_normals.toml`), and the base color alone on a wall without one
//! (`task_flat_normals.toml`, its scene `scene_flat.gltf`).
use super::parts::{camera, create, hash, texture, unit, write_png, TASK_COMMON};
use crate::assets::authoring::GltfBuilder;
use crate::assets::bundled::{look_at, srgb8, write_sky};
use crate::image_io::write_atomic;
use crate::Result;
use glam::Vec3;
use serde_json::json;
use std::path::Path;

/// Bricks per row and rows, and the mortar's half-width in a brick's width and height.
const BRICKS: (f32, f32) = (4.0, 8.0);
const MORTAR: (f32, f32) = (0.03, 0.06);
/// The cameras' vertical field of view, radians.
const FOV: f32 = 0.75;

/// Where texture coordinates (u, v) fall: the brick (column, row) and the position in it
/// (0..1 across, 0..1 down), or None in the mortar.
fn brick(u: f32, v: f32) -> Option<(i32, i32, f32, f32)> {
    let row = (v * BRICKS.1).floor();
    let x = u * BRICKS.0 + 0.5 * (row as i32).rem_euclid(2) as f32;
    let (fu, fv) = (x.fract(), (v * BRICKS.1).fract());
    let mortar = fu < MORTAR.0 || fu > 1.0 - MORTAR.0 || fv < MORTAR.1 || fv > 1.0 - MORTAR.1;
    (!mortar).then_some((
        (x.floor() as i32).rem_euclid(BRICKS.0 as i32),
        row as i32,
        fu,
        fv,
    ))
}

/// The tangent-space normal at (u, v): flat in the mortar; on a brick, bevels that tilt it
/// outwards over the outer fifth of its width and third of its height, a tilt of its own, and
/// a few gentle bumps (tangent X along u, Y up the wall: against v, glTF's convention).
fn normal_at(u: f32, v: f32) -> Vec3 {
    let Some((col, row, fu, fv)) = brick(u, v) else {
        return Vec3::Z;
    };
    let bevel = |f: f32, m: f32, w: f32| -> f32 {
        let (a, b) = ((f - m) / w, (1.0 - m - f) / w);
        if a < 1.0 {
            -0.7 * (1.0 - a)
        } else if b < 1.0 {
            0.7 * (1.0 - b)
        } else {
            0.0
        }
    };
    let (k1, k2) = (col as u32 + 17, row as u32 + 5);
    let tilt = [hash(k1, k2) - 0.5, hash(k2, k1 + 3) - 0.5];
    let bump = 0.06 * ((fu * 11.0 + row as f32).sin() * (fv * 7.0 + col as f32).cos());
    Vec3::new(
        bevel(fu, MORTAR.0, 0.2) + 0.16 * tilt[0] + bump,
        -bevel(fv, MORTAR.1, 0.33) + 0.16 * tilt[1] - bump,
        1.0,
    )
    .normalize()
}

/// A 2 m x 2 m brick wall facing +Z under a grazing sun from the upper left and the sky, its base
/// color and normal map 256², two cameras; the same wall without its normal map; and the
/// tasks, which add the other suns and the third capture.
pub fn write_wall(dir: &Path) -> Result<()> {
    create(dir)?;
    write_textures(dir)?;
    write_scenes(dir)?;
    write_sky(&dir.join("sky.exr"))?;
    write_tasks(dir)
}

/// The base color (bricks of varied reds in a light mortar) and the normal map.
fn write_textures(dir: &Path) -> Result<()> {
    let color = texture(|u, v| {
        let c = match brick(u, v) {
            None => [0.62, 0.6, 0.56],
            Some((col, row, fu, fv)) => {
                let h = hash(col as u32 + 31, row as u32 + 7);
                let speck = 0.9
                    + 0.1
                        * hash(
                            (fu * 64.0) as u32 + 7 * col as u32,
                            (fv * 32.0) as u32 + row as u32,
                        );
                [
                    (0.42 + 0.22 * h) * speck,
                    (0.16 + 0.1 * h) * speck,
                    (0.1 + 0.06 * (1.0 - h)) * speck,
                ]
            }
        };
        [srgb8(c[0]), srgb8(c[1]), srgb8(c[2]), 255]
    });
    write_png(dir, "wall_color.png", &color)?;
    let normals = texture(|u, v| {
        let n = normal_at(u, v);
        [
            unit(0.5 + 0.5 * n.x),
            unit(0.5 + 0.5 * n.y),
            unit(0.5 + 0.5 * n.z),
            255,
        ]
    });
    write_png(dir, "wall_normal.png", &normals)?;
    Ok(())
}

/// `scene.gltf` (with the normal map) and `scene_flat.gltf` (without).
fn write_scenes(dir: &Path) -> Result<()> {
    for (file, with_normals) in [("scene.gltf", true), ("scene_flat.gltf", false)] {
        let mut b = GltfBuilder::new();
        let ci = b.add_image_uri("wall_color", "wall_color.png");
        let ct = b.add_texture(ci, None);
        let mut mat = json!({
            "name": "wall",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": ct},
                "metallicFactor": 0.0, "roughnessFactor": 0.8}
        });
        if with_normals {
            let ni = b.add_image_uri("wall_normal", "wall_normal.png");
            mat["normalTexture"] = json!({"index": b.add_texture(ni, None)});
        }
        let m = b.add_material(mat);
        let mesh = b.add_mesh(
            "wall",
            &[
                [-1.0, 2.0, 0.0],
                [1.0, 2.0, 0.0],
                [1.0, 0.0, 0.0],
                [-1.0, 0.0, 0.0],
            ],
            Some(&[[0.0, 0.0, 1.0]; 4]),
            Some(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
            Some(&[0, 3, 2, 0, 2, 1]),
            Some(m),
        );
        let sun = b.add_light(json!({"name": "sun", "type": "directional",
            "color": [1.0, 0.92, 0.8], "intensity": 4.0}));
        let c = [0.0, 1.0, 0.0];
        let nodes = vec![
            b.add_node(json!({"name": "wall", "mesh": mesh})),
            // 69 degrees from the wall's normal, from the upper left: every bevel of a brick
            // faces towards it or away.
            b.add_node(
                json!({"name": "sun", "matrix": look_at(Vec3::new(-2.2, 3.2, 1.2),
                Vec3::from(c), Vec3::Y), "extensions": {"KHR_lights_punctual": {"light": sun}}}),
            ),
            camera(&mut b, "front", FOV, [0.0, 1.0, 3.2], c),
            camera(&mut b, "oblique", FOV, [2.2, 1.5, 2.3], c),
        ];
        b.set_scene(&nodes);
        b.write_gltf(&dir.join(file), false)?;
    }
    Ok(())
}

/// The three tasks on the same targets: three captures, each under one sun (the scene's
/// from the upper left, and two the tasks add, from the right and from below), two of them
/// from the front camera's pose. Under one light a texel's shading gives one equation for its
/// normal's two unknowns, and its color trades against its shading; three lights, one at a
/// time, determine both (photometric stereo).
fn write_tasks(dir: &Path) -> Result<()> {
    let fov_deg = FOV.to_degrees();
    let head = |what: &str, scene: &str, out: &str| {
        format!(
            r#"# Normal-map scene "wall": {what}
# Three captures, each under one sun and the sky: `front` under the scene's sun (upper left),
# `front_right` from the same pose under a sun from the right, `oblique` under a sun from
# below ([target] lights).
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "{scene}"
env = "sky.exr"
cameras = ["front", "front_right", "oblique"]
width = 128
height = 128
seed = 23
output = "out/bench/{out}"

[[camera]]
name = "front_right"
eye = [0.0, 1.0, 3.2]
target = [0.0, 1.0, 0.0]
yfov_deg = {fov_deg}

[[light]]
name = "sun_right"
type = "directional"
direction = [-2.6, -0.3, -1.2]
color = [0.9, 0.95, 1.0]
intensity = 4.0

[[light]]
name = "sun_below"
type = "directional"
direction = [-0.5, 2.4, -1.2]
color = [0.9, 0.95, 1.0]
intensity = 4.0
"#
        )
    };
    // (Still in [optimizer]: the comparison is at the whole budget.)
    let base_color = r#"stop_on_plateau = false

[[textures]]
material = "wall"
slot = "base_color"
resolution = [256, 256]
init = [0.5, 0.5, 0.5]
learning_rate = 0.03
"#;
    write(
        dir,
        "task.toml",
        &head(
            "recover the base color and the normal map of a brick wall under grazing suns,\n# the normal map from flat (it replaces the scene's).",
            "scene.gltf",
            "wall",
        ),
        &format!(
            "{base_color}
[[textures]]
material = \"wall\"
slot = \"normal\"
resolution = [256, 256]
init = [0.5, 0.5, 1.0]
"
        ),
    )?;
    write(
        dir,
        "task_given_normals.toml",
        &head(
            "recover the base color alone, the true normal map given.",
            "scene.gltf",
            "wall_given_normals",
        ),
        base_color,
    )?;
    write(
        dir,
        "task_flat_normals.toml",
        &head(
            "recover the base color alone on a wall without a normal map (the bumps'\n# shading left to the base color).",
            "scene_flat.gltf",
            "wall_flat_normals",
        ),
        base_color,
    )
}

/// A task: the head, the bench's shared settings with each capture's sun, the textures.
fn write(dir: &Path, name: &str, head: &str, textures: &str) -> Result<()> {
    let common = TASK_COMMON.replacen(
        "spp = 256\n",
        "spp = 256\nlights = { front = [\"sun\"], front_right = [\"sun_right\"], oblique = [\"sun_below\"] }\n",
        1,
    );
    write_atomic(
        &dir.join(name),
        format!("{head}{common}{textures}").as_bytes(),
    )
}
