//! The benchmark scenes lit by indirect light (see `bench_scenes`): `room`, lit mostly by
//! light that bounced, and `gallery`, whose painting is lit only by bounced light.
use super::parts::{area_light, camera, create, hash, texture, write_png, write_task};
use crate::assets::authoring::{box_triangles, GltfBuilder};
use crate::assets::bundled::srgb8;
use crate::Result;
use glam::Vec3;
use serde_json::json;
use std::path::Path;

/// A flat panel with corners `c` (in order around it) facing along `n`, UVs (0, 1), (1, 1),
/// (1, 0), (0, 0) at the corners when `uv`.
fn panel(
    b: &mut GltfBuilder,
    name: &str,
    c: [[f32; 3]; 4],
    n: [f32; 3],
    uv: bool,
    m: usize,
) -> usize {
    let p: Vec<Vec3> = c.iter().map(|&v| Vec3::from(v)).collect();
    // Counter-clockwise seen from the side the normal points to (glTF's front face).
    let idx: [u32; 6] = if (p[1] - p[0]).cross(p[2] - p[0]).dot(Vec3::from(n)) > 0.0 {
        [0, 1, 2, 0, 2, 3]
    } else {
        [0, 2, 1, 0, 3, 2]
    };
    let uvs = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
    let mesh = b.add_mesh(
        name,
        &c,
        Some(&[n; 4]),
        uv.then_some(&uvs[..]),
        Some(&idx),
        Some(m),
    );
    b.add_node(json!({"name": name, "mesh": mesh}))
}

/// A dielectric material of base color `c` and roughness `r`, without textures.
fn plain_material(b: &mut GltfBuilder, name: &str, c: [f32; 3], r: f64) -> usize {
    b.add_material(json!({
        "name": name,
        "pbrMetallicRoughness": {"baseColorFactor": [c[0], c[1], c[2], 1.0],
            "metallicFactor": 0.0, "roughnessFactor": r}
    }))
}

/// The materials of a room's walls.
struct Shell {
    back: usize,
    /// Whether the back wall has UVs (for a texture).
    back_uv: bool,
    floor: usize,
    ceiling: usize,
    left: usize,
    right: usize,
}

/// A room `2w` wide and deep and `h` high, open at the front (+z): its back wall, floor,
/// ceiling, left and right walls, in that order.
fn shell(b: &mut GltfBuilder, (w, h): (f32, f32), m: Shell) -> Vec<usize> {
    vec![
        panel(
            b,
            "back",
            [[-w, 0.0, -w], [w, 0.0, -w], [w, h, -w], [-w, h, -w]],
            [0.0, 0.0, 1.0],
            m.back_uv,
            m.back,
        ),
        panel(
            b,
            "floor",
            [[-w, 0.0, w], [w, 0.0, w], [w, 0.0, -w], [-w, 0.0, -w]],
            [0.0, 1.0, 0.0],
            false,
            m.floor,
        ),
        panel(
            b,
            "ceiling",
            [[-w, h, -w], [w, h, -w], [w, h, w], [-w, h, w]],
            [0.0, -1.0, 0.0],
            false,
            m.ceiling,
        ),
        panel(
            b,
            "left",
            [[-w, 0.0, w], [-w, 0.0, -w], [-w, h, -w], [-w, h, w]],
            [1.0, 0.0, 0.0],
            false,
            m.left,
        ),
        panel(
            b,
            "right",
            [[w, 0.0, -w], [w, 0.0, w], [w, h, w], [w, h, -w]],
            [-1.0, 0.0, 0.0],
            false,
            m.right,
        ),
    ]
}

/// A room open at the front, lit by one lamp under its ceiling: most of what the camera sees
/// is lit by light that bounced off another wall first (indirect light, `max_depth = 3`).
/// The back wall's tiled base color texture is optimized.
pub fn write_room(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    // Tiles of varied colors with light grout.
    let color = texture(|u, v| {
        let tiles = 6.0;
        let (fu, fv) = ((u * tiles).fract(), (v * tiles).fract());
        let c = if fu < 0.06 || fv < 0.06 {
            [0.8, 0.78, 0.72]
        } else {
            let (i, j) = ((u * tiles) as u32, (v * tiles) as u32);
            let h = hash(i + 3, j + 11);
            let shade = 0.85 + 0.15 * hash(j * 7 + 1, i * 3 + 2);
            match (h * 4.0) as u32 {
                0 => [0.65 * shade, 0.25 * shade, 0.15 * shade],
                1 => [0.2 * shade, 0.4 * shade, 0.6 * shade],
                2 => [0.7 * shade, 0.6 * shade, 0.3 * shade],
                _ => [0.3 * shade, 0.55 * shade, 0.35 * shade],
            }
        };
        [srgb8(c[0]), srgb8(c[1]), srgb8(c[2]), 255]
    });
    write_png(dir, "tiles.png", &color)?;
    let img = b.add_image_uri("tiles", "tiles.png");
    let tex = b.add_texture(img, None);
    let tiled = b.add_material(json!({
        "name": "tiles",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": tex},
            "metallicFactor": 0.0, "roughnessFactor": 0.6}
    }));
    let plain = |b: &mut GltfBuilder, name: &str, c: [f32; 3]| plain_material(b, name, c, 0.8);
    let white = plain(&mut b, "white", [0.75, 0.75, 0.72]);
    let red = plain(&mut b, "red", [0.7, 0.15, 0.12]);
    let green = plain(&mut b, "green", [0.15, 0.55, 0.2]);
    let (w, h) = (1.0f32, 2.0f32);
    let mut nodes = shell(
        &mut b,
        (w, h),
        Shell {
            back: tiled,
            back_uv: true,
            floor: white,
            ceiling: white,
            left: red,
            right: green,
        },
    );
    // A block that hides part of the back wall from the lamp.
    let block = b.add_mesh(
        "block",
        &box_triangles([0.35, 0.45, -0.35], [0.3, 0.45, 0.3]),
        None,
        None,
        None,
        Some(white),
    );
    nodes.push(b.add_node(json!({"name": "block", "mesh": block})));
    nodes.push(area_light(
        &mut b,
        "lamp",
        [0.0, h - 0.01, 0.2],
        [0.0, 0.0, 0.2],
        0.5,
        [1.0, 0.9, 0.8],
        12.0,
    ));
    nodes.push(camera(
        &mut b,
        "main",
        0.75,
        [0.0, 1.0, 3.4],
        [0.0, 0.95, 0.0],
    ));
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    write_task(
        dir,
        r#"# Benchmark scene "room": recover the tiled base color of a room's back wall, most of
# whose light arrives after a bounce on another wall, with paths of 3 vertices (max_depth).
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
cameras = ["main"]
width = 128
height = 128
seed = 5
max_depth = 3
# Lit by its lamp alone: no default environment through the open front.
default_environment = false
output = "out/bench/room"
"#,
        r#"
[[textures]]
material = "tiles"
slot = "base_color"
resolution = [256, 256]
init = [0.5, 0.5, 0.5]
learning_rate = 0.03
"#,
    )
}

/// The painting of `gallery`: colored discs and a band over a warm ground.
fn painting(u: f32, v: f32) -> [f32; 3] {
    let mut c = [0.78 - 0.25 * v, 0.7 - 0.3 * v, 0.55 - 0.3 * v];
    if (0.62..0.7).contains(&v) {
        c = [0.15, 0.25, 0.45];
    }
    for k in 0..9u32 {
        let (x, y) = (hash(k, 1), hash(k, 2));
        let r = 0.05 + 0.12 * hash(k, 3);
        if (u - x).powi(2) + ((v - y) * 0.75).powi(2) < r * r {
            c = match k % 4 {
                0 => [0.75, 0.2, 0.12],
                1 => [0.2, 0.45, 0.25],
                2 => [0.9, 0.8, 0.35],
                _ => [0.12, 0.12, 0.14],
            };
        }
    }
    c
}

/// A gallery room whose painting on the back wall is lit only by bounced light: the lamp
/// hangs above the painting's top edge and shines at the ceiling, so no point of the painting
/// sees its emitting side, and every path that lights the painting bounces first (`max_depth
/// = 3`: the ceiling and one more surface). The painting's base color is optimized, seen by
/// two cameras.
pub fn write_gallery(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    let color = texture(|u, v| {
        let c = painting(u, v);
        [srgb8(c[0]), srgb8(c[1]), srgb8(c[2]), 255]
    });
    write_png(dir, "painting.png", &color)?;
    let img = b.add_image_uri("painting", "painting.png");
    let tex = b.add_texture(img, None);
    let canvas = b.add_material(json!({
        "name": "painting",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": tex},
            "metallicFactor": 0.0, "roughnessFactor": 0.7}
    }));
    let plain = |b: &mut GltfBuilder, name: &str, c: [f32; 3]| plain_material(b, name, c, 0.8);
    let white = plain(&mut b, "white", [0.8, 0.8, 0.78]);
    let wall = plain(&mut b, "wall", [0.6, 0.62, 0.66]);
    let wood = plain(&mut b, "wood", [0.45, 0.3, 0.18]);
    let (w, h) = (1.2f32, 2.0f32);
    let (px, py0, py1, pz) = (0.6f32, 0.55f32, 1.45f32, -w + 0.01);
    let mut nodes = vec![panel(
        &mut b,
        "painting",
        [[-px, py0, pz], [px, py0, pz], [px, py1, pz], [-px, py1, pz]],
        [0.0, 0.0, 1.0],
        true,
        canvas,
    )];
    nodes.extend(shell(
        &mut b,
        (w, h),
        Shell {
            back: wall,
            back_uv: false,
            floor: wood,
            ceiling: white,
            left: wall,
            right: wall,
        },
    ));
    // The lamp's shade: a flat box under the lamp, which faces the ceiling from above the
    // painting's top edge (the painting lies below the lamp's plane: no direct light).
    let ly = py1 + 0.2;
    let shade = b.add_mesh(
        "shade",
        &box_triangles([0.0, ly - 0.03, -0.2], [0.3, 0.025, 0.3]),
        None,
        None,
        None,
        Some(white),
    );
    nodes.push(b.add_node(json!({"name": "shade", "mesh": shade})));
    nodes.push(area_light(
        &mut b,
        "lamp",
        [0.0, ly, -0.2],
        [0.0, h, -0.2],
        0.5,
        [1.0, 0.92, 0.82],
        30.0,
    ));
    nodes.push(camera(&mut b, "main", 0.5, [0.0, 1.0, 3.0], [0.0, 1.0, -w]));
    nodes.push(camera(
        &mut b,
        "side",
        0.55,
        [0.9, 0.8, 2.0],
        [-0.1, 1.0, -w],
    ));
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    write_task(
        dir,
        r#"# Benchmark scene "gallery": recover the base color of a painting lit only by bounced
# light (its lamp shines at the ceiling from above the painting), seen by two cameras, with
# paths of 3 vertices (max_depth).
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
cameras = ["main", "side"]
width = 128
height = 128
seed = 6
max_depth = 3
# Lit by its lamp alone: no default environment through the open front.
default_environment = false
output = "out/bench/gallery"
"#,
        r#"
[[textures]]
material = "painting"
slot = "base_color"
resolution = [256, 256]
init = [0.5, 0.5, 0.5]
learning_rate = 0.03
"#,
    )
}

/// The floor of `atelier`: planks of varied tones along x, with dark seams.
fn planks(u: f32, v: f32) -> [f32; 3] {
    let rows = 8.0;
    let row = (v * rows) as u32;
    let (fv, shift) = ((v * rows).fract(), hash(row, 5) * 0.7);
    let plank = ((u + shift) * 2.5) as u32;
    if fv < 0.05 || ((u + shift) * 2.5).fract() < 0.012 {
        return [0.12, 0.09, 0.07];
    }
    let tone = 0.75 + 0.25 * hash(row * 13 + plank, 9);
    let grain = 0.92 + 0.08 * ((u * 40.0 + 7.0 * hash(row, plank)).sin());
    let s = tone * grain;
    [0.55 * s, 0.36 * s, 0.2 * s]
}

/// The back wall of `atelier`: a wallpaper of colored diamonds on a pale ground.
fn wallpaper(u: f32, v: f32) -> [f32; 3] {
    let n = 5.0;
    let (x, y) = ((u * n).fract() - 0.5, (v * n).fract() - 0.5);
    let (i, j) = ((u * n) as u32, (v * n) as u32);
    if x.abs() + y.abs() < 0.32 {
        match (hash(i + 17, j + 3) * 3.0) as u32 {
            0 => [0.2, 0.35, 0.6],
            1 => [0.65, 0.3, 0.25],
            _ => [0.3, 0.5, 0.3],
        }
    } else {
        [0.78, 0.74, 0.64]
    }
}

/// The lamp of `atelier` (0.3 wide, 0.2 under the ceiling at height `h`, facing down) in a
/// shade of material `dark` 0.5 deep: its light leaves in a cone that reaches the floor and
/// never the back wall. The nodes of the shade's sides and top, then the lamp's.
fn shaded_lamp(b: &mut GltfBuilder, h: f32, dark: usize) -> Vec<usize> {
    let mut nodes = Vec::new();
    let (lz, ly, half) = (0.45f32, h - 0.2, 0.15f32);
    let depth = 0.5f32;
    for (name, c, e) in [
        (
            "shade_l",
            [-half - 0.01, ly - depth / 2.0, lz],
            [0.01, depth / 2.0, half + 0.02],
        ),
        (
            "shade_r",
            [half + 0.01, ly - depth / 2.0, lz],
            [0.01, depth / 2.0, half + 0.02],
        ),
        (
            "shade_b",
            [0.0, ly - depth / 2.0, lz - half - 0.01],
            [half + 0.02, depth / 2.0, 0.01],
        ),
        (
            "shade_f",
            [0.0, ly - depth / 2.0, lz + half + 0.01],
            [half + 0.02, depth / 2.0, 0.01],
        ),
        (
            "shade_top",
            [0.0, ly + 0.02, lz],
            [half + 0.02, 0.01, half + 0.02],
        ),
    ] {
        let mesh = b.add_mesh(name, &box_triangles(c, e), None, None, None, Some(dark));
        nodes.push(b.add_node(json!({"name": name, "mesh": mesh})));
    }
    nodes.push(area_light(
        b,
        "lamp",
        [0.0, ly, lz],
        [0.0, 0.0, lz],
        2.0 * half,
        [1.0, 0.93, 0.85],
        100.0,
    ));
    nodes
}

/// A room whose floor and back wall are both recovered, and whose wall is lit only by the
/// floor's bounce: a lamp under the ceiling near the open front shines down through a deep
/// shade, which keeps its light off the walls, onto the planked floor; the light the floor
/// sends back lights the wallpapered back wall (and the rest), paths of 3 vertices
/// (`max_depth`). Both base color textures are optimized, seen by two cameras: the wall's
/// gradient is in paths that cross the floor, and the floor's in paths that end at the wall.
pub fn write_atelier(dir: &Path) -> Result<()> {
    create(dir)?;
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    let textured = |b: &mut GltfBuilder, name: &str, f: fn(f32, f32) -> [f32; 3], r: f32| {
        let pixels = texture(|u, v| {
            let c = f(u, v);
            [srgb8(c[0]), srgb8(c[1]), srgb8(c[2]), 255]
        });
        write_png(dir, &format!("{name}.png"), &pixels)?;
        let img = b.add_image_uri(name, &format!("{name}.png"));
        let tex = b.add_texture(img, None);
        Ok::<_, crate::Error>(b.add_material(json!({
            "name": name,
            "pbrMetallicRoughness": {"baseColorTexture": {"index": tex},
                "metallicFactor": 0.0, "roughnessFactor": r}
        })))
    };
    let floor = textured(&mut b, "planks", planks, 0.6)?;
    let wall = textured(&mut b, "wallpaper", wallpaper, 0.8)?;
    let plain = |b: &mut GltfBuilder, name: &str, c: [f32; 3]| plain_material(b, name, c, 0.9);
    let white = plain(&mut b, "white", [0.75, 0.75, 0.73]);
    let dark = plain(&mut b, "shade", [0.05, 0.05, 0.05]);
    let (w, h) = (1.0f32, 2.0f32);
    let mut nodes = vec![
        panel(
            &mut b,
            "back",
            [[-w, 0.0, -w], [w, 0.0, -w], [w, h, -w], [-w, h, -w]],
            [0.0, 0.0, 1.0],
            true,
            wall,
        ),
        panel(
            &mut b,
            "floor",
            [[-w, 0.0, w], [w, 0.0, w], [w, 0.0, -w], [-w, 0.0, -w]],
            [0.0, 1.0, 0.0],
            true,
            floor,
        ),
    ];
    let sides = shell(
        &mut b,
        (w, h),
        Shell {
            back: white,
            back_uv: false,
            floor: white,
            ceiling: white,
            left: white,
            right: white,
        },
    );
    // The shell's ceiling and side walls (its back wall and floor are the textured ones).
    nodes.extend_from_slice(&sides[2..]);
    nodes.extend(shaded_lamp(&mut b, h, dark));
    nodes.push(camera(
        &mut b,
        "main",
        0.7,
        [0.0, 0.9, 3.2],
        [0.0, 0.75, -w],
    ));
    nodes.push(camera(
        &mut b,
        "low",
        0.65,
        [0.8, 0.55, 2.4],
        [-0.15, 0.45, -w],
    ));
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    write_task(
        dir,
        r#"# Benchmark scene "atelier": recover the base colors of a planked floor and a papered
# back wall, the wall lit only by the floor's bounce (the lamp's shade keeps its light on the
# floor), seen by two cameras, with paths of 3 vertices (max_depth).
# Written by `psrestir make-scenes`; paths are relative to this file.
scene = "scene.gltf"
cameras = ["main", "low"]
width = 128
height = 128
seed = 8
max_depth = 3
# Lit by its lamp alone: no default environment through the open front.
default_environment = false
output = "out/bench/atelier"
"#,
        r#"
[[textures]]
material = "planks"
slot = "base_color"
resolution = [256, 256]
init = [0.5, 0.5, 0.5]
learning_rate = 0.03

[[textures]]
material = "wallpaper"
slot = "base_color"
resolution = [256, 256]
init = [0.5, 0.5, 0.5]
learning_rate = 0.03
"#,
    )
}
