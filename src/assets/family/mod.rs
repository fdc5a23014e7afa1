//! The scene family (`psrestir make-scenes --family train|test`): tasks drawn from seeds,
//! varied the way users' scenes vary, to choose rules and constants on one range of seeds
//! ([`TRAIN`]) and to report them on another that is never tuned on ([`TEST`]). A member is
//! a shape (a sphere, a rounded box, a torus, a relief wall, a room lit through an opening,
//! a cube with a seamed UV atlas), one optimized slot with a procedural ground truth (base
//! color, roughness, metallic, or a normal map with relief), lights (point, spot, sun,
//! emissive area, environment; the room's back wall only by bounced light), a path depth of
//! 1 to 3, one to four cameras, and sampling from sparse to dense (texture size against
//! image size and samples per pixel). Everything is a pure function of the seed: a member is
//! the same files on every machine.
mod draw;
mod geometry;
mod truth;

pub use geometry::Shape;

use super::authoring::GltfBuilder;
use super::bench_scenes::{area_light, camera};
use super::bundled::{look_at, write_sky};
use crate::image_io::write_atomic;
use crate::vocab::Slot;
use crate::{Error, Result};
use draw::Draw;
use geometry::{panel, plain, room_shell, shape_mesh};
use glam::Vec3;
use serde_json::json;
use std::f32::consts::PI;
use std::path::{Path, PathBuf};
use truth::truth;

/// Seeds for choosing rules and constants.
pub const TRAIN: std::ops::Range<u32> = 0..1000;
/// Seeds only reported, never tuned on.
pub const TEST: std::ops::Range<u32> = 1000..2000;

/// Which range of seeds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// [`TRAIN`].
    Train,
    /// [`TEST`].
    Test,
}

impl Split {
    /// `train` or `test`.
    pub fn parse(s: &str) -> std::result::Result<Split, String> {
        match s {
            "train" => Ok(Split::Train),
            "test" => Ok(Split::Test),
            _ => Err(format!("`{s}` is not a split of the family (train, test)")),
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
        }
    }

    /// Its seeds.
    pub fn seeds(self) -> std::ops::Range<u32> {
        match self {
            Split::Train => TRAIN,
            Split::Test => TEST,
        }
    }
}

/// A kind of light.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Light {
    /// A point light.
    Point,
    /// A spot light aimed at the shape.
    Spot,
    /// A directional light.
    Sun,
    /// An emissive square.
    Area,
    /// The sky environment map.
    Environment,
}

/// One member of the family: what its seed drew.
#[derive(Clone, Debug, PartialEq)]
pub struct Member {
    /// Its seed.
    pub seed: u32,
    /// The shape.
    pub shape: Shape,
    /// The optimized slot.
    pub slot: Slot,
    /// Its lights.
    pub lights: Vec<Light>,
    /// Path vertices (max_depth).
    pub depth: u32,
    /// Cameras.
    pub cameras: u32,
    /// The optimized texture's side, texels.
    pub resolution: u32,
    /// The images' side, pixels.
    pub image: u32,
    /// Primal samples per pixel.
    pub primal_spp: u32,
    /// Gradient samples per pixel.
    pub gradient_spp: u32,
    /// The run's time budget, seconds of optimization.
    pub budget_s: f64,
}

impl Shape {
    /// Every shape.
    pub const ALL: [Shape; 6] = [
        Shape::Sphere,
        Shape::RoundedBox,
        Shape::Torus,
        Shape::Relief,
        Shape::Room,
        Shape::SeamedCube,
    ];
}

impl Member {
    /// What `seed` draws.
    pub fn draw(seed: u32) -> Member {
        let mut d = Draw(0x5EED_0000_0000 ^ seed as u64);
        let shape = d.pick(&Shape::ALL);
        let room = shape == Shape::Room;
        let slot = if room {
            d.pick(&[Slot::BaseColor, Slot::BaseColor, Slot::Roughness])
        } else {
            d.pick(&[
                Slot::BaseColor,
                Slot::BaseColor,
                Slot::Roughness,
                Slot::Metallic,
                Slot::Normal,
                Slot::Normal,
            ])
        };
        let lights = if room {
            vec![Light::Sun]
        } else {
            use Light::*;
            let first = d.pick(&[Point, Spot, Sun, Area, Environment]);
            let second = d.pick(&[Point, Spot, Sun, Area, Environment]);
            if d.unit() < 0.5 || first == second {
                vec![first]
            } else {
                vec![first, second]
            }
        };
        let depth = if room { 3 } else { d.pick(&[1, 1, 2, 3]) };
        let cameras = if room {
            d.pick(&[1, 2])
        } else {
            d.pick(&[1, 2, 3, 4])
        };
        let resolution = d.pick(&[64, 128, 128, 256, 256, 512]);
        let image = d.pick(&[64, 96, 128]);
        let primal_spp = d.pick(&[1, 2, 4]);
        let gradient_spp = d.pick(&[1, 1, 2, 4]);
        let budget_s =
            20.0 + if depth == 3 { 10.0 } else { 0.0 } + if resolution == 512 { 10.0 } else { 0.0 };
        Member {
            seed,
            shape,
            slot,
            lights,
            depth,
            cameras,
            resolution,
            image,
            primal_spp,
            gradient_spp,
            budget_s,
        }
    }

    /// Its folder's name: the seed and what it drew (`1003-torus-roughness-spot`).
    pub fn name(&self) -> String {
        let lights: Vec<&str> = self.lights.iter().map(|l| light_name(*l)).collect();
        format!(
            "{}-{}-{}-{}",
            self.seed,
            shape_name(self.shape),
            self.slot.name(),
            lights.join("+")
        )
    }
}

fn shape_name(s: Shape) -> &'static str {
    match s {
        Shape::Sphere => "sphere",
        Shape::RoundedBox => "rounded_box",
        Shape::Torus => "torus",
        Shape::Relief => "relief",
        Shape::Room => "room",
        Shape::SeamedCube => "seamed_cube",
    }
}

fn light_name(l: Light) -> &'static str {
    match l {
        Light::Point => "point",
        Light::Spot => "spot",
        Light::Sun => "sun",
        Light::Area => "area",
        Light::Environment => "environment",
    }
}

/// Write `count` members of `split` (its first seeds) into `dir/<split>/<name>/`; their
/// task files' paths.
pub fn write_split(dir: &Path, split: Split, count: u32) -> Result<Vec<PathBuf>> {
    let seeds = split.seeds();
    if count == 0 || count > seeds.len() as u32 {
        return Err(Error::Invalid(format!(
            "make-scenes --family: --count must be in [1, {}], not {count}",
            seeds.len()
        )));
    }
    let mut tasks = Vec::new();
    for seed in seeds.start..seeds.start + count {
        let m = Member::draw(seed);
        let d = dir.join(split.name()).join(m.name());
        write_member(&d, &m)?;
        tasks.push(d.join("task.toml"));
    }
    Ok(tasks)
}

/// How far the lights stand from the shape: beyond the cameras' ring (3.4 m), so that no
/// light's quad hides the shape from a camera.
const LIGHT_DISTANCE: f32 = 4.5;

/// Write member `m` into `dir`: `scene.gltf` (the truth's textures in it), its textures,
/// `sky.exr` where it is lit by the environment, and `task.toml`, which starts the optimized
/// texture at a constant and leaves every choice to `auto`.
pub fn write_member(dir: &Path, m: &Member) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let mut d = Draw(0xFA11_0000_0000 ^ m.seed as u64);
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_materials_emissive_strength");
    let c = if m.shape == Shape::Relief || m.shape == Shape::Room {
        Vec3::new(0.0, 1.3, 0.0)
    } else {
        Vec3::new(0.0, 0.95, 0.0)
    };
    let target = target_material(&mut b, m, &mut d, dir)?;
    let (p, n, uv, idx) = shape_mesh(m.shape, c);
    let mesh = b.add_mesh("target", &p, Some(&n), Some(&uv), Some(&idx), Some(target));
    let mut nodes = vec![b.add_node(json!({"name": "target", "mesh": mesh}))];
    let cameras_from = d.range(0.0, 2.0 * PI);
    let environment = add_lights(&mut b, m, &mut d, (c, cameras_from), &mut nodes);
    let names = add_cameras(&mut b, m, &mut d, (c, cameras_from), &mut nodes);
    b.set_scene(&nodes);
    b.write_gltf(&dir.join("scene.gltf"), false)?;
    if environment {
        write_sky(&dir.join("sky.exr"))?;
    }
    write_atomic(
        &dir.join("task.toml"),
        task_text(m, &names, environment).as_bytes(),
    )
}

/// The optimized material: the truth (written to `truth.png`) in its slot, constants drawn
/// from `d` in the others.
fn target_material(b: &mut GltfBuilder, m: &Member, d: &mut Draw, dir: &Path) -> Result<usize> {
    let texels = truth(m.slot, m.resolution, d);
    let png = super::authoring::png_bytes(m.resolution, m.resolution, &texels)?;
    write_atomic(&dir.join("truth.png"), &png)?;
    let ti = b.add_image_uri("truth", "truth.png");
    let tex = json!({"index": b.add_texture(ti, None)});
    let base = [d.range(0.2, 0.8), d.range(0.2, 0.8), d.range(0.2, 0.8)];
    let mut pbr = json!({"baseColorFactor": [base[0], base[1], base[2], 1.0],
        "metallicFactor": 0.0, "roughnessFactor": d.range(0.3, 0.7)});
    let mut mat = json!({"name": "target", "doubleSided": true});
    match m.slot {
        Slot::BaseColor => pbr["baseColorTexture"] = tex,
        Slot::Roughness => {
            pbr["metallicRoughnessTexture"] = tex;
            pbr["roughnessFactor"] = json!(1.0);
        }
        Slot::Metallic => {
            pbr["metallicRoughnessTexture"] = tex;
            pbr["metallicFactor"] = json!(1.0);
            pbr["roughnessFactor"] = json!(1.0);
        }
        Slot::Normal => mat["normalTexture"] = tex,
    }
    mat["pbrMetallicRoughness"] = pbr;
    Ok(b.add_material(mat))
}

/// The member's lights (and the room's shell, or the floor) into `nodes`, around the
/// shape's centre `c`, on the side `cameras_from` of the cameras' ring; whether it is lit by
/// the sky.
fn add_lights(
    b: &mut GltfBuilder,
    m: &Member,
    d: &mut Draw,
    (c, cameras_from): (Vec3, f32),
    nodes: &mut Vec<usize>,
) -> bool {
    let mut environment = false;
    if m.shape == Shape::Room {
        nodes.extend(room_shell(b));
        let sun = b.add_light(
            json!({"name": "sun", "type": "directional", "color": [1.0, 0.95, 0.85], "intensity": 40.0}),
        );
        // Travelling in the plane z = 0 (−x, down): it never reaches the back wall.
        nodes.push(b.add_node(json!({"name": "sun",
            "matrix": look_at(Vec3::new(4.0, 4.8, 0.0), Vec3::ZERO, Vec3::Y),
            "extensions": {"KHR_lights_punctual": {"light": sun}}})));
    } else {
        if m.shape != Shape::Relief {
            let floor = plain(b, "floor", [0.45, 0.45, 0.45], 0.9);
            let s = 4.0;
            let (x, z) = (Vec3::X, Vec3::Z);
            nodes.push(panel(
                b,
                "floor",
                (Vec3::new(-s, 0.0, s), 2.0 * s * x, -2.0 * s * z),
                floor,
            ));
        }
        for (k, l) in m.lights.iter().enumerate() {
            // On the side the cameras' ring starts from, so that the first camera sees lit
            // texels.
            let az = cameras_from + d.range(-1.2, 1.2);
            let el = d.range(0.5, 1.2);
            // In front of the relief wall (+z), anywhere above the others.
            let az = if m.shape == Shape::Relief {
                PI / 2.0 + 0.9 * (az / PI - 1.0)
            } else {
                az
            };
            let dir_to = Vec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin());
            let name = format!("light{k}");
            match l {
                Light::Point | Light::Spot | Light::Sun => {
                    let (kind, intensity, at) = match l {
                        Light::Point => ("point", 30.0, c + LIGHT_DISTANCE * dir_to),
                        Light::Spot => ("spot", 60.0, c + LIGHT_DISTANCE * dir_to),
                        _ => ("directional", 2.5, c + LIGHT_DISTANCE * dir_to),
                    };
                    let mut light = json!({"name": name, "type": kind,
                        "color": [1.0, d.range(0.85, 1.0), d.range(0.75, 1.0)],
                        "intensity": intensity});
                    if kind == "spot" {
                        light["spot"] = json!({"innerConeAngle": 0.3, "outerConeAngle": 0.6});
                    }
                    let li = b.add_light(light);
                    nodes.push(b.add_node(json!({"name": name,
                        "matrix": look_at(at, c, if dir_to.y > 0.99 { Vec3::Z } else { Vec3::Y }),
                        "extensions": {"KHR_lights_punctual": {"light": li}}})));
                }
                Light::Area => nodes.push(area_light(
                    b,
                    &name,
                    (c + LIGHT_DISTANCE * dir_to).to_array(),
                    c.to_array(),
                    1.0,
                    [1.0, 0.95, 0.9],
                    45.0,
                )),
                Light::Environment => environment = true,
            }
        }
    }
    environment
}

/// The member's cameras into `nodes`: inside the room facing the back wall; in front of the
/// relief; else on a ring around the shape's centre `c` from `cameras_from`. Their names,
/// quoted for the task file.
fn add_cameras(
    b: &mut GltfBuilder,
    m: &Member,
    d: &mut Draw,
    (c, start): (Vec3, f32),
    nodes: &mut Vec<usize>,
) -> Vec<String> {
    let mut names = Vec::new();
    for k in 0..m.cameras {
        let name = format!("camera{k}");
        let (eye, look) = match m.shape {
            Shape::Room => (
                Vec3::new(d.range(-0.8, 0.8), d.range(1.2, 1.8), 1.8),
                Vec3::new(0.0, 1.4, -2.0),
            ),
            Shape::Relief => {
                let az = PI / 2.0 + d.range(-0.7, 0.7);
                let el = d.range(-0.3, 0.5);
                (
                    c + 3.3 * Vec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin()),
                    c,
                )
            }
            _ => {
                let az = start + k as f32 * 2.0 * PI / m.cameras as f32 + d.range(-0.3, 0.3);
                let el = d.range(0.15, 0.8);
                (
                    c + 3.4 * Vec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin()),
                    c,
                )
            }
        };
        let fov = if m.shape == Shape::Room { 1.1 } else { 0.7 };
        nodes.push(camera(b, &name, fov, eye.to_array(), look.to_array()));
        names.push(format!("\"{name}\""));
    }
    names
}

/// `task.toml` of member `m` with its cameras' `names`: the scene, sampling and budget, the
/// texture from a constant, nothing else (every other choice `auto`'s).
fn task_text(m: &Member, names: &[String], environment: bool) -> String {
    let init = match m.slot {
        Slot::BaseColor => "[0.5, 0.5, 0.5]",
        Slot::Roughness | Slot::Metallic => "0.5",
        Slot::Normal => "[0.5, 0.5, 1.0]",
    };
    let lights: Vec<&str> = m.lights.iter().map(|l| light_name(*l)).collect();
    format!(
        "# Scene family member {seed} ({split} split): a {shape}, its {slot} recovered, lit by \
         {lights}; paths of {depth} vertices.\n# Written by `psrestir make-scenes --family`; \
         paths are relative to this file. Every choice the task leaves out is `auto`'s.\n\
         scene = \"scene.gltf\"\ncameras = [{cameras}]\nwidth = {image}\nheight = {image}\n\
         seed = {seed}\nmax_depth = {depth}\n{env}\
         output = \"out/family/{name}\"\n\n[target]\nscene = \"scene.gltf\"\nspp = 256\n\n\
         [optimizer]\ntime_budget_s = {budget}\nprimal_spp = {primal}\ngradient_spp = {grad}\n\n\
         [[textures]]\nmaterial = \"target\"\nslot = \"{slot}\"\nresolution = [{res}, {res}]\n\
         init = {init}\n",
        seed = m.seed,
        split = if TEST.contains(&m.seed) {
            "test"
        } else {
            "train"
        },
        shape = shape_name(m.shape).replace('_', " "),
        slot = m.slot.name(),
        lights = lights.join(" and "),
        depth = m.depth,
        cameras = names.join(", "),
        image = m.image,
        env = if environment {
            "env = \"sky.exr\"\n"
        } else {
            "default_environment = false\n"
        },
        name = m.name(),
        budget = m.budget_s,
        primal = m.primal_spp,
        grad = m.gradient_spp,
        res = m.resolution,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seed draws the same member every time, the splits do not overlap, and the first
    /// seeds of each split cover every shape, slot and light kind.
    #[test]
    fn members_are_deterministic_and_varied() {
        assert_eq!(Member::draw(1003), Member::draw(1003));
        assert!(TRAIN.end <= TEST.start);
        for split in [Split::Train, Split::Test] {
            let members: Vec<Member> = split.seeds().take(60).map(Member::draw).collect();
            for shape in Shape::ALL {
                assert!(
                    members.iter().any(|m| m.shape == shape),
                    "{split:?} lacks {shape:?}"
                );
            }
            for slot in [
                Slot::BaseColor,
                Slot::Roughness,
                Slot::Metallic,
                Slot::Normal,
            ] {
                assert!(
                    members.iter().any(|m| m.slot == slot),
                    "{split:?} lacks {slot:?}"
                );
            }
            for l in [
                Light::Point,
                Light::Spot,
                Light::Sun,
                Light::Area,
                Light::Environment,
            ] {
                assert!(
                    members.iter().any(|m| m.lights.contains(&l)),
                    "{split:?} lacks {l:?}"
                );
            }
            for depth in 1..=3 {
                assert!(members.iter().any(|m| m.depth == depth));
            }
            assert!(members
                .iter()
                .all(|m| m.shape != Shape::Room || m.depth == 3));
        }
    }

    /// Every triangle of every shape is wound counter-clockwise about its normals.
    #[test]
    fn meshes_are_wound_about_their_normals() {
        for shape in Shape::ALL {
            let (p, n, uv, idx) = shape_mesh(shape, Vec3::ONE);
            assert!(!idx.is_empty() && idx.len() % 3 == 0, "{shape:?}");
            assert_eq!(p.len(), uv.len());
            for t in idx.chunks(3) {
                let v = |k: usize| Vec3::from(p[t[k] as usize]);
                let face = (v(1) - v(0)).cross(v(2) - v(0));
                let mean: Vec3 = t.iter().map(|&k| Vec3::from(n[k as usize])).sum();
                assert!(face.dot(mean) > 0.0, "{shape:?}: {t:?}");
            }
        }
    }

    /// The first members of each split load as tasks whose scene and truth load.
    #[test]
    fn members_load_as_tasks() {
        let dir = tempfile::tempdir().unwrap();
        for split in [Split::Train, Split::Test] {
            for task in write_split(dir.path(), split, 8).unwrap() {
                let t = crate::task::Task::load(&task).unwrap();
                assert_eq!(t.textures.len(), 1);
                crate::scene::load(&t.resolve(&t.scene)).unwrap();
                assert!(task.with_file_name("truth.png").exists());
            }
        }
        assert!(write_split(dir.path(), Split::Test, 0).is_err());
    }
}
