//! Scenes and captures from outside psrestir: a Blender-like GLB with no camera and no light
//! renders with the defaults; three views given as `transforms.json` recover a base color
//! texture; a COLMAP text model of the same views gives the same camera rays; masks keep
//! pixels out of the loss and the gradient; a per-camera exposure is recovered.
mod common;

use common::*;
use glam::{Mat3, Mat4, Quat, Vec3};
use psrestir::assets::authoring::{png_bytes, GltfBuilder};
use psrestir::image_io::{srgb_to_linear, Image};
use psrestir::job::run::{run, RunOptions};
use psrestir::optim::schedule::Schedule;
use psrestir::optim::{Method, Optimizer, Settings};
use psrestir::render::params::ParamSet;
use psrestir::render::{camera_info, RenderSettings, Renderer, Techniques};
use psrestir::scene::{capture, Camera, Intrinsics};
use psrestir::task::{Filter, Init, Slot, Task, TextureSpec};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::Command;

const W: u32 = 48;
const TEX: u32 = 16;

/// The ground-truth base color of the plane: a pattern of 16x16 sRGB texels.
fn truth_texels() -> Vec<[u8; 4]> {
    (0..TEX * TEX)
        .map(|i| {
            let (x, y) = (i % TEX, i / TEX);
            [
                (40 + 12 * x) as u8,
                (220 - 11 * y) as u8,
                if (x / 4 + y / 4) % 2 == 0 { 200 } else { 50 },
                255,
            ]
        })
        .collect()
}

fn jpeg_bytes(w: u32, h: u32, rgb: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
        .encode(rgb, w, h, image::ExtendedColorType::Rgb8)
        .unwrap();
    out
}

/// A scene as a modeling tool exports it: one mesh with two primitives and two materials
/// (a plane with a PNG base color texture, a box with a JPEG texture mirrored by
/// KHR_texture_transform's negative scale), no camera and no light. `plane_png` is the
/// plane's texture; with `glowing_box` the box's texture is its emissive texture as well.
fn blender_like_glb(path: &Path, plane_png: &[u8], glowing_box: bool) {
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_texture_transform");
    let s_nearest = b.add_sampler(json!({"magFilter": 9728, "minFilter": 9728}));
    let img_a = b.add_image_embedded("plane color", plane_png, "image/png");
    let tex_a = b.add_texture(img_a, Some(s_nearest));
    let stripes: Vec<u8> = (0..32 * 32)
        .flat_map(|i| {
            if (i % 32) / 8 % 2 == 0 {
                [200, 60, 40]
            } else {
                [30, 60, 190]
            }
        })
        .collect();
    let img_b = b.add_image_embedded("box color", &jpeg_bytes(32, 32, &stripes), "image/jpeg");
    let tex_b = b.add_texture(img_b, None);
    let mat_a = b.add_material(json!({
        "name": "planeA",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": tex_a}, "metallicFactor": 0.0, "roughnessFactor": 0.7}
    }));
    let mut box_material = json!({
        "name": "boxB",
        "pbrMetallicRoughness": {
            "baseColorTexture": {"index": tex_b, "extensions": {"KHR_texture_transform": {"scale": [-2.0, 1.0], "offset": [1.0, 0.0]}}},
            "metallicFactor": 0.0, "roughnessFactor": 0.5
        }
    });
    if glowing_box {
        box_material["emissiveTexture"] = json!({"index": tex_b});
        box_material["emissiveFactor"] = json!([1.0, 1.0, 1.0]);
    }
    let mat_b = b.add_material(box_material);
    // The plane y = 0, [-1, 1]^2, facing +y, u along +x, v along -z.
    let plane = [
        [-1.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 0.0, -1.0],
        [-1.0, 0.0, -1.0],
    ];
    let m0 = b.add_mesh(
        "export",
        &plane,
        Some(&[[0.0, 1.0, 0.0]; 4]),
        Some(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
        Some(&[0, 1, 2, 0, 2, 3]),
        Some(mat_a),
    );
    let cube = psrestir::assets::authoring::box_triangles([0.55, 0.2, -0.55], [0.2; 3]);
    let uvs: Vec<[f32; 2]> = (0..cube.len())
        .map(|i| [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]][i % 3])
        .collect();
    let m1 = b.add_mesh("box", &cube, None, Some(&uvs), None, Some(mat_b));
    // One mesh with both primitives, as an exporter writes a multi-material object.
    let prim = b.json["meshes"][m1]["primitives"][0].clone();
    b.json["meshes"][m0]["primitives"]
        .as_array_mut()
        .unwrap()
        .push(prim);
    b.json["meshes"].as_array_mut().unwrap().truncate(1);
    let n = b.add_node(json!({"mesh": m0, "name": "export"}));
    b.set_scene(&[n]);
    b.write_glb(path).unwrap();
}

/// Three views of the plane: glTF camera-to-world matrices, and pinhole intrinsics with an
/// off-center principal point.
fn views() -> Vec<(String, Mat4, Intrinsics)> {
    let k = Intrinsics {
        fx: 52.0,
        fy: 50.0,
        cx: 25.5,
        cy: 22.0,
        width: W,
        height: W,
    };
    [
        ("r_0", Vec3::new(0.0, 2.2, 1.2)),
        ("r_1", Vec3::new(1.6, 1.8, 0.4)),
        ("r_2", Vec3::new(-1.3, 1.7, -1.1)),
    ]
    .iter()
    .map(|(name, eye)| {
        let cam = Camera::look_at(name, *eye, Vec3::new(0.0, 0.0, -0.05), Vec3::Y, 1.0);
        (name.to_string(), cam.world, k)
    })
    .collect()
}

fn transforms_json(dir: &Path) -> PathBuf {
    let frames: Vec<serde_json::Value> = views()
        .iter()
        .map(|(name, m, _)| {
            let rows: Vec<Vec<f32>> = (0..4).map(|r| m.row(r).to_array().to_vec()).collect();
            json!({"file_path": format!("frames/{name}"), "transform_matrix": rows})
        })
        .collect();
    let k = views()[0].2;
    let j = json!({"fl_x": k.fx, "fl_y": k.fy, "cx": k.cx, "cy": k.cy, "w": k.width, "h": k.height, "frames": frames});
    let p = dir.join("transforms.json");
    std::fs::write(&p, serde_json::to_string_pretty(&j).unwrap()).unwrap();
    p
}

/// The same views as a COLMAP text model (world-to-camera, OpenCV axes).
fn colmap_model(dir: &Path) -> PathBuf {
    let d = dir.join("sparse/0");
    std::fs::create_dir_all(&d).unwrap();
    let k = views()[0].2;
    std::fs::write(
        d.join("cameras.txt"),
        format!(
            "# Camera list\n1 PINHOLE {} {} {} {} {} {}\n",
            k.width, k.height, k.fx, k.fy, k.cx, k.cy
        ),
    )
    .unwrap();
    let mut images = String::from("# Image list\n");
    for (i, (name, m, _)) in views().iter().enumerate() {
        let right = m.x_axis.truncate();
        let up = m.y_axis.truncate();
        let back = m.z_axis.truncate();
        let origin = m.w_axis.truncate();
        // OpenCV camera axes in world: x right, y down, z forward.
        let c2w = Mat3::from_cols(right, -up, -back);
        let r = c2w.transpose();
        let q = Quat::from_mat3(&r);
        let t = -(r * origin);
        images.push_str(&format!(
            "{} {} {} {} {} {} {} {} 1 {name}.exr\n\n",
            i + 1,
            q.w,
            q.x,
            q.y,
            q.z,
            t.x,
            t.y,
            t.z
        ));
    }
    std::fs::write(d.join("images.txt"), images).unwrap();
    d
}

#[test]
fn colmap_and_transforms_json_give_the_same_rays() {
    let dir = tempfile::tempdir().unwrap();
    let a = capture::load_frames(&transforms_json(dir.path())).unwrap();
    let b = capture::load_frames(&colmap_model(dir.path())).unwrap();
    assert_eq!(a.len(), 3);
    assert_eq!(b.len(), 3);
    for (fa, (name, m, _)) in a.iter().zip(views()) {
        let fb = b
            .iter()
            .find(|f| f.camera.name == name)
            .expect("frame by name");
        assert_eq!(fa.camera.name, name);
        assert!(fa.camera.world.abs_diff_eq(m, 1e-6));
        for (w, h) in [(W, W), (96, 96)] {
            let (ia, ib) = (camera_info(&fa.camera, w, h), camera_info(&fb.camera, w, h));
            for px in [
                [0.0, 0.0],
                [w as f32, 0.0],
                [17.3, 31.9],
                [w as f32, h as f32],
            ] {
                let (oa, da) = camera_dir(&fa.camera, w, h, glam::Vec2::from(px));
                let (ob, db) = camera_dir(&fb.camera, w, h, glam::Vec2::from(px));
                assert!(oa.abs_diff_eq(ob, 1e-5), "{name} origin {oa} vs {ob}");
                assert!(da.abs_diff_eq(db, 1e-5), "{name} ray {px:?}: {da} vs {db}");
            }
            assert!((ia.cx - ib.cx).abs() < 1e-4 && (ia.fy - ib.fy).abs() < 1e-4);
        }
    }
    // Radial distortion is refused with the model and its coefficients.
    let d = dir.path().join("sparse/0");
    std::fs::write(
        d.join("cameras.txt"),
        "1 SIMPLE_RADIAL 48 48 50 24 24 0.05\n",
    )
    .unwrap();
    let e = capture::load_frames(&d).unwrap_err().to_string();
    assert!(
        e.contains("cameras.txt") && e.contains("SIMPLE_RADIAL") && e.contains("0.05"),
        "{e}"
    );
}

#[test]
fn a_gltf_without_camera_or_light_renders_with_defaults() {
    if gpu().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("model.glb");
    blender_like_glb(&glb, &png_bytes(TEX, TEX, &truth_texels()).unwrap(), false);
    let out = dir.path().join("x.png");
    let o = Command::new(env!("CARGO_BIN_EXE_psrestir"))
        .args(["render", glb.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args(["--size", "64x64", "--spp", "8"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains("no camera") && stderr.contains("no light"),
        "{stderr}"
    );
    let img = image::open(&out).unwrap().to_rgb8();
    let mean: f64 = img
        .pixels()
        .map(|p| p.0.iter().map(|&c| c as f64).sum::<f64>())
        .sum::<f64>()
        / (3 * 64 * 64) as f64;
    // The plane fills the view under the white environment: a lit, textured image.
    assert!(mean > 40.0 && mean < 250.0, "mean sRGB value {mean}");
    let distinct: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(
        distinct.len() > 50,
        "a flat image ({} colors)",
        distinct.len()
    );
}

/// An asset without camera and punctual light whose only light is a glowing (emissive
/// textured) part: the default environment lights the rest of it, and the notice says why;
/// `--no-default-env` leaves it lit by the glowing part alone, far darker.
#[test]
fn a_light_less_asset_with_a_glowing_part_gets_the_default_environment() {
    if gpu().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("glowing.glb");
    blender_like_glb(&glb, &png_bytes(TEX, TEX, &truth_texels()).unwrap(), true);
    let render = |extra: &[&str], out: &str| {
        let out = dir.path().join(out);
        let o = Command::new(env!("CARGO_BIN_EXE_psrestir"))
            .args(["render", glb.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .args(["--size", "64x64", "--spp", "16"])
            .args(extra)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(o.status.success(), "{stderr}");
        let img = image::open(&out).unwrap().to_rgb8();
        // The plane's pixels: the bottom rows, in front of the box.
        let plane: Vec<f64> = img
            .enumerate_pixels()
            .filter(|(_, y, _)| *y >= 56)
            .map(|(_, _, p)| p.0.iter().map(|&c| c as f64).sum::<f64>() / 3.0)
            .collect();
        (stderr, plane.iter().sum::<f64>() / plane.len() as f64)
    };
    let (stderr, lit) = render(&[], "lit.png");
    assert!(stderr.contains("only emissive surfaces"), "{stderr}");
    // The plane under the white environment (its texture averages about sRGB 120).
    assert!(lit > 40.0, "the plane is dark: mean sRGB value {lit}");
    let (stderr, dark) = render(&["--no-default-env"], "dark.png");
    assert!(!stderr.contains("environment"), "{stderr}");
    assert!(
        dark < 0.5 * lit,
        "lit by the glowing box alone: {dark} vs {lit}"
    );
}

#[test]
fn three_transforms_json_views_recover_the_base_color() {
    let Some(gpu) = gpu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The ground truth renders the targets; the model starts from gray.
    let truth_png = png_bytes(TEX, TEX, &truth_texels()).unwrap();
    blender_like_glb(&d.join("truth.glb"), &truth_png, false);
    let gray = png_bytes(TEX, TEX, &vec![[128, 128, 128, 255]; (TEX * TEX) as usize]).unwrap();
    blender_like_glb(&d.join("model.glb"), &gray, false);
    std::fs::create_dir_all(d.join("frames")).unwrap();
    let mut truth = psrestir::scene::load(&d.join("truth.glb")).unwrap();
    truth.add_defaults(true);
    truth.cameras.clear();
    for (name, m, k) in views() {
        truth.cameras.push(Camera::with_intrinsics(&name, m, k));
    }
    let r = Renderer::new(&gpu, &truth).unwrap();
    for (i, (name, _, _)) in views().iter().enumerate() {
        let img = r
            .render(
                &RenderSettings {
                    width: W,
                    height: W,
                    spp: 512,
                    seed: 9,
                    camera: i,
                    techniques: Techniques::Mis,
                },
                |_| {},
            )
            .unwrap()
            .image;
        img.save(&d.join(format!("frames/{name}.exr"))).unwrap();
    }
    transforms_json(d);
    let task_path = d.join("task.toml");
    std::fs::write(
        &task_path,
        r#"
scene = "model.glb"
cameras_file = "transforms.json"
width = 48
height = 48
[target]
[optimizer]
iterations = 160
primal_spp = 2
gradient_spp = 2
filter = "nearest"
eval_every = 0
checkpoint_every = 0
[optimizer.schedule]
kind = "cosine"
final = 0.1
[[textures]]
material = "planeA"
slot = "base_color"
resolution = [16, 16]
init = [0.5, 0.5, 0.5]
learning_rate = 0.05
"#,
    )
    .unwrap();
    let task = Task::load(&task_path).unwrap();
    let out = d.join("out");
    let summary = run(
        &gpu,
        &task,
        &RunOptions {
            method: Method::RESTIR.into(),
            out: Some(out.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(summary.iterations, 160);
    // The recovered texture against the truth (linear), over the observed texels.
    let got = psrestir::image_io::load_linear(&out.join("planeA_base_color.exr")).unwrap();
    let seen = image::open(out.join("observed_planeA_base_color.png"))
        .unwrap()
        .to_luma8();
    let want: Vec<[f32; 3]> = truth_texels()
        .iter()
        .map(|p| [0, 1, 2].map(|c| srgb_to_linear(p[c] as f32 / 255.0)))
        .collect();
    let rmse = |v: &[[f32; 3]]| -> f64 {
        let (mut s, mut n) = (0.0, 0);
        for (i, p) in v.iter().enumerate() {
            // Texel row 0 is v = 0; the PNG's row 0 is its top (glTF: v = 0 at the top).
            if seen.as_raw()[i] > 0 {
                for c in 0..3 {
                    s += ((p[c] - want[i][c]) as f64).powi(2);
                    n += 1;
                }
            }
        }
        assert!(n > 3 * 100, "only {} observed texels", n / 3);
        (s / n as f64).sqrt()
    };
    let before = rmse(&vec![[0.5; 3]; (TEX * TEX) as usize]);
    let after = rmse(&got.rgb);
    eprintln!("observed-texel RMSE {before:.4} -> {after:.4}");
    // Three 48x48 views of 16x16 texels determine the texture well: a factor of 4.
    assert!(after < before / 4.0, "RMSE {before} -> {after}");
}

/// The shadow scene with a 2x2 base color texture on the plane.
fn masked_optimizer(gpu: &psrestir::gpu::Gpu, target: &Image) -> Optimizer {
    let settings = Settings {
        method: Method::BASELINE,
        primal_spp: 4,
        gradient_spp: 4,
        ..Settings::new(16, 16, vec![0])
    };
    plane_optimizer(gpu, settings, target)
}

/// The shadow scene with a 2x2 base color texture on the plane, with `settings`.
fn plane_optimizer(gpu: &psrestir::gpu::Gpu, settings: Settings, target: &Image) -> Optimizer {
    let scene = shadow_scene();
    let spec = TextureSpec {
        material: "plane".into(),
        slot: Slot::BaseColor,
        resolution: [2, 2],
        init: Init::Vector(vec![0.5; 3]),
        learning_rate: Some(0.0),
    };
    let set = ParamSet::from_specs(&scene, &[spec], Filter::Bilinear, Path::new("t")).unwrap();
    Optimizer::new(gpu, &scene, set, settings, std::slice::from_ref(target)).unwrap()
}

#[test]
fn masked_pixels_add_neither_loss_nor_gradient() {
    let Some(gpu) = gpu() else { return };
    let base = masked_optimizer(&gpu, &Image::new(16, 16));
    base.write_params(&[0.9, 0.2, 0.2, 0.2, 0.8, 0.3, 0.7, 0.7, 0.1, 0.3, 0.3, 0.9])
        .unwrap();
    let t1 = base.render(0, 256, 3).unwrap();
    // t2 differs from t1 only in the right half, which the mask leaves out.
    let mut t2 = t1.clone();
    let mask: Vec<f32> = (0..256)
        .map(|i| if i % 16 < 8 { 1.0 } else { 0.0 })
        .collect();
    for (i, p) in t2.rgb.iter_mut().enumerate() {
        if mask[i] == 0.0 {
            *p = [5.0, 0.0, 3.0];
        }
    }
    let mut a = masked_optimizer(&gpu, &t1);
    let mut b = masked_optimizer(&gpu, &t2);
    // Without the mask, the changed pixels change the loss and the gradient (so the check
    // below can fail).
    let (ga0, la0) = a.estimate_gradient(7).unwrap();
    let (gb0, lb0) = b.estimate_gradient(7).unwrap();
    assert!(lb0 > 10.0 * la0, "loss {la0} vs {lb0}");
    let scale0 = ga0.iter().fold(0f32, |m, v| m.max(v.abs()));
    assert!(ga0
        .iter()
        .zip(&gb0)
        .any(|(x, y)| (x - y).abs() > 0.1 * scale0));
    // With it, the same random numbers give the same loss and gradient.
    a.set_masks(&[Some(mask.clone())]).unwrap();
    b.set_masks(&[Some(mask)]).unwrap();
    let (ga, la) = a.estimate_gradient(8).unwrap();
    let (gb, lb) = b.estimate_gradient(8).unwrap();
    assert_eq!(la, lb, "the masked pixels changed the loss");
    let scale = ga.iter().fold(0f32, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    for (x, y) in ga.iter().zip(&gb) {
        // The same additions in another order: float rounding only.
        assert!((x - y).abs() <= 1e-5 * scale, "{x} vs {y}");
    }
}

#[test]
fn the_exposure_of_a_camera_is_recovered() {
    let Some(gpu) = gpu() else { return };
    let truth = [0.6, 0.4, 0.3, 0.5, 0.5, 0.2, 0.3, 0.6, 0.4, 0.7, 0.3, 0.5];
    let base = masked_optimizer(&gpu, &Image::new(16, 16));
    base.write_params(&truth).unwrap();
    // A photo taken 1.4x brighter than the render.
    let mut target = base.render(0, 512, 3).unwrap();
    for p in &mut target.rgb {
        *p = p.map(|v| 1.4 * v);
    }
    let settings = Settings {
        method: Method::BASELINE,
        primal_spp: 4,
        exposure_learning_rate: Some(0.05),
        // Adam's steps do not shrink with the gradient: the schedule ends the walk.
        schedule: Schedule::cosine(0.05),
        ..Settings::new(16, 16, vec![0])
    };
    let mut opt = plane_optimizer(&gpu, settings, &target);
    opt.write_params(&truth).unwrap();
    for i in 0..120 {
        opt.set_progress(i as f64 / 120.0);
        opt.step().unwrap();
    }
    let e = opt.fit().exposure()[0];
    eprintln!("exposure {e}");
    assert!((e - 1.4).abs() < 0.03, "exposure {e}, the photo's is 1.4");
    // It is part of the state.
    assert_eq!(opt.state().unwrap().groups["exposure"].values, vec![e]);
}

/// A photo whose channels are scaled unequally (a white balance of 1.3, 1.0, 0.7): the
/// per-channel gains are recovered, each within 3%, with the textures held at the truth.
#[test]
fn the_white_balance_of_a_camera_is_recovered() {
    let Some(gpu) = gpu() else { return };
    let truth = [0.6, 0.4, 0.3, 0.5, 0.5, 0.2, 0.3, 0.6, 0.4, 0.7, 0.3, 0.5];
    let base = masked_optimizer(&gpu, &Image::new(16, 16));
    base.write_params(&truth).unwrap();
    let wb = [1.3f32, 1.0, 0.7];
    let mut target = base.render(0, 512, 3).unwrap();
    for p in &mut target.rgb {
        *p = std::array::from_fn(|c| wb[c] * p[c]);
    }
    let settings = Settings {
        method: Method::BASELINE,
        primal_spp: 4,
        schedule: Schedule::cosine(0.05),
        ..Settings::new(16, 16, vec![0])
    };
    let mut opt = plane_optimizer(&gpu, settings, &target);
    opt.write_params(&truth).unwrap();
    opt.fit_mut().optimize_white_balance(0.05).unwrap();
    for i in 0..120 {
        opt.set_progress(i as f64 / 120.0);
        opt.step().unwrap();
    }
    let got = opt.fit().gains()[0];
    eprintln!("gains {got:?}");
    for c in 0..3 {
        assert!(
            (got[c] / wb[c] - 1.0).abs() < 0.03,
            "channel {c}: gain {}, the photo's is {}",
            got[c],
            wb[c]
        );
    }
    assert_eq!(opt.state().unwrap().groups["white_balance"].values, got);
}
