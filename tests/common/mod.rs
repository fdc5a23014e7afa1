//! Shared test harness: a device (skip with a reason when none exists outside CI, fail in CI),
//! scenes built in code, a CPU reference of the glTF BRDF, and noise-aware image comparisons.
#![allow(dead_code)]

use glam::{Vec2, Vec3, Vec4};
use psrestir::gpu::Gpu;
use psrestir::image_io::Image;
use psrestir::render::{RenderSettings, Renderer, Techniques};
use psrestir::scene::{Camera, Material, PunctualKind, PunctualLight, Scene, Triangle};
use std::f32::consts::PI;

/// The devices that the tests of one test binary share. A test takes one (or makes one when
/// none is free) and gives it back when it ends, so that each pass's pipeline is made once per
/// device, not once per test: an optimizer's passes take 0.6-1.6 s to create on lavapipe even
/// when Mesa's shader cache holds them, and a device reuses the pipelines it made
/// (`Gpu::compute_pipeline_in`). The test harness runs two tests at a time on two cores, so
/// there are about two devices, each with its own queue. A device that recorded an error or
/// was lost, or whose test panicked, is not given back. Tests that count pipelines, provoke
/// device errors or need a device of their own call `Gpu::new` instead.
static FREE_DEVICES: std::sync::Mutex<Vec<Gpu>> = std::sync::Mutex::new(Vec::new());

/// A device taken from [`FREE_DEVICES`], given back when dropped.
pub struct SharedGpu(Option<Gpu>);

impl std::ops::Deref for SharedGpu {
    type Target = Gpu;
    fn deref(&self) -> &Gpu {
        self.0
            .as_ref()
            .expect("a shared device is held until dropped")
    }
}

impl Drop for SharedGpu {
    fn drop(&mut self) {
        let Some(g) = self.0.take() else { return };
        if std::thread::panicking() || g.check("a test's end").is_err() {
            return;
        }
        if let Ok(mut free) = FREE_DEVICES.lock() {
            free.push(g);
        }
    }
}

/// A device on the machine's Vulkan driver, shared with the tests before and after this one
/// ([`FREE_DEVICES`]). Outside CI, a machine without one skips the test with a message; in CI
/// (CI=true) a missing driver fails the test.
pub fn gpu() -> Option<SharedGpu> {
    let free = FREE_DEVICES.lock().ok().and_then(|mut f| f.pop());
    match free.map(Ok).unwrap_or_else(Gpu::new) {
        Ok(g) => Some(SharedGpu(Some(g))),
        Err(e) if std::env::var_os("CI").is_none() => {
            eprintln!("skipped: no GPU adapter ({e})");
            None
        }
        Err(e) => panic!("CI must have a GPU adapter (lavapipe): {e}"),
    }
}

pub fn material(base: [f32; 3], metallic: f32, roughness: f32) -> Material {
    Material {
        name: "test".into(),
        base_color: Vec4::new(base[0], base[1], base[2], 1.0),
        metallic,
        roughness,
        ..Default::default()
    }
}

/// Two triangles of a quad with corner `c` and edges `u`, `v` (front face along u x v).
pub fn quad(c: Vec3, u: Vec3, v: Vec3, material: u32) -> Vec<Triangle> {
    let n = u.cross(v).normalize();
    let p = [c, c + u, c + u + v, c + v];
    let uv = [
        Vec2::new(0.0, 0.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(0.0, 1.0),
    ];
    vec![
        Triangle {
            p: [p[0], p[1], p[2]],
            n: [n; 3],
            uv: [uv[0], uv[1], uv[2]],
            t: Default::default(),
            material,
        },
        Triangle {
            p: [p[0], p[2], p[3]],
            n: [n; 3],
            uv: [uv[0], uv[2], uv[3]],
            t: Default::default(),
            material,
        },
    ]
}

pub fn look_at(eye: Vec3, target: Vec3, up: Vec3, yfov: f32) -> Camera {
    Camera {
        aspect: Some(1.0),
        ..Camera::look_at("test", eye, target, up, yfov)
    }
}

/// A large horizontal plane (y = 0, facing +y) of the given material, seen from above.
pub fn plane_scene(mat: Material, half: f32) -> Scene {
    Scene {
        triangles: quad(
            Vec3::new(-half, 0.0, half),
            Vec3::new(2.0 * half, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -2.0 * half),
            0,
        ),
        materials: vec![mat],
        cameras: vec![look_at(Vec3::new(0.0, 2.0, 2.0), Vec3::ZERO, Vec3::Y, 0.8)],
        ..Default::default()
    }
}

// ---- CPU reference of shaders/shared/brdf.wgsl (glTF metallic-roughness BRDF).

pub fn brdf_eval_cos(
    base: Vec3,
    metallic: f32,
    roughness: f32,
    n: Vec3,
    wo: Vec3,
    wi: Vec3,
) -> Vec3 {
    let (nv, nl) = (n.dot(wo), n.dot(wi));
    if nv <= 0.0 || nl <= 0.0 {
        return Vec3::ZERO;
    }
    let h = (wo + wi).normalize();
    let a = (roughness * roughness).max(4e-4);
    let a2 = a * a;
    let nh = n.dot(h);
    let d = {
        let t = nh * nh * (a2 - 1.0) + 1.0;
        a2 / (PI * t * t)
    };
    let vis =
        0.5 / (nl * (nv * nv * (1.0 - a2) + a2).sqrt() + nv * (nl * nl * (1.0 - a2) + a2).sqrt());
    let f0 = Vec3::splat(0.04).lerp(base, metallic);
    let f = f0 + (Vec3::ONE - f0) * (1.0 - wo.dot(h)).clamp(0.0, 1.0).powi(5);
    let diffuse = (Vec3::ONE - f) * (1.0 - metallic) * base / PI;
    (diffuse + f * d * vis) * nl
}

/// Directional albedo: integral of f cos over the hemisphere, by a midpoint rule.
pub fn directional_albedo(base: Vec3, metallic: f32, roughness: f32, wo: Vec3) -> Vec3 {
    let n = Vec3::Y;
    let (nt, np) = (512, 256);
    let mut sum = Vec3::ZERO;
    for i in 0..nt {
        let theta = (i as f32 + 0.5) / nt as f32 * 0.5 * PI;
        for j in 0..np {
            let phi = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
            let wi = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            sum += brdf_eval_cos(base, metallic, roughness, n, wo, wi) * theta.sin();
        }
    }
    sum * (0.5 * PI / nt as f32) * (2.0 * PI / np as f32)
}

/// Continuous pixel position -> camera ray direction, as shaders/shared/camera.wgsl.
pub fn camera_dir(cam: &Camera, w: u32, h: u32, px: Vec2) -> (Vec3, Vec3) {
    let info = psrestir::render::camera_info(cam, w, h);
    let _ = (w, h);
    let sx = (px.x - info.cx) / info.fx;
    let sy = (info.cy - px.y) / info.fy;
    let d = (Vec3::from(info.forward) + sx * Vec3::from(info.right) + sy * Vec3::from(info.up))
        .normalize();
    (Vec3::from(info.origin), d)
}

pub fn lum(c: [f32; 3]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

/// Mean and standard deviation.
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, var.sqrt())
}

/// z-scores of the difference of two estimators over square blocks of pixels. Each estimator
/// comes as two renders with independent seeds: their half-difference estimates the per-pixel
/// variance, summed over the block's pixels (many degrees of freedom per block).
pub fn block_z_scores(
    a: [&[[f32; 3]]; 2],
    b: [&[[f32; 3]]; 2],
    width: usize,
    block: usize,
) -> Vec<f64> {
    let height = a[0].len() / width;
    let mut out = Vec::new();
    for by in (0..height).step_by(block) {
        for bx in (0..width).step_by(block) {
            let (mut da, mut db, mut va, mut vb, mut k) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for y in by..(by + block).min(height) {
                for x in bx..(bx + block).min(width) {
                    let i = y * width + x;
                    let (a1, a2) = (lum(a[0][i]), lum(a[1][i]));
                    let (b1, b2) = (lum(b[0][i]), lum(b[1][i]));
                    da += 0.5 * (a1 + a2);
                    db += 0.5 * (b1 + b2);
                    va += 0.25 * (a1 - a2) * (a1 - a2);
                    vb += 0.25 * (b1 - b2) * (b1 - b2);
                    k += 1.0;
                }
            }
            let var = (va + vb) / (k * k);
            let diff = (da - db) / k;
            out.push(if var > 0.0 {
                diff / var.sqrt()
            } else if diff.abs() < 1e-9 {
                0.0
            } else {
                f64::INFINITY
            });
        }
    }
    out
}

/// A 2x2-unit plane (UV 0..1) under a point light and an emissive quad, with a floating
/// blocker that casts a hard shadow (point light) and a soft one (area light).
/// Give material 0 (the plane of [`shadow_scene`]) a tangent-space normal map of 4x4 bumps
/// that tilt its normal by up to about 0.6 rad in varying directions.
#[allow(dead_code)]
pub fn with_normal_map(s: &mut Scene) {
    let rgba: Vec<[u8; 4]> = (0..16)
        .map(|i| {
            let (x, y) = ((i % 4) as f32 - 1.5, (i / 4) as f32 - 1.5);
            let n = Vec3::new(0.35 * x, -0.25 * y, 1.0).normalize();
            let c = |v: f32| ((v + 1.0) * 0.5 * 255.0).round() as u8;
            [c(n.x), c(n.y), c(n.z), 255]
        })
        .collect();
    s.images.push(psrestir::scene::Image8 {
        name: "bumps".into(),
        width: 4,
        height: 4,
        rgba,
    });
    s.materials[0].normal_texture = Some(texture_slot(s.images.len() - 1, false));
    s.materials[0].normal_scale = 1.2;
}

/// A texture slot reading scene image `image`, repeating, untransformed; nearest lookups or
/// bilinear ones.
pub fn texture_slot(image: usize, nearest: bool) -> psrestir::scene::TextureSlot {
    psrestir::scene::TextureSlot {
        image,
        wrap_s: psrestir::scene::Wrap::Repeat,
        wrap_t: psrestir::scene::Wrap::Repeat,
        nearest,
        transform: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    }
}

pub fn shadow_scene() -> Scene {
    let mut s = Scene::default();
    s.materials.push(Material {
        name: "plane".into(),
        ..material([0.5, 0.4, 0.3], 0.2, 0.5)
    });
    s.materials.push(Material {
        name: "blocker".into(),
        ..material([0.3, 0.3, 0.3], 0.0, 0.8)
    });
    s.materials.push(Material {
        name: "lamp".into(),
        emissive: Vec3::splat(8.0),
        ..material([0.0; 3], 0.0, 1.0)
    });
    s.triangles.extend(quad(
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -2.0),
        0,
    ));
    s.triangles.extend(quad(
        Vec3::new(-0.3, 0.5, 0.3),
        Vec3::new(0.5, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -0.5),
        1,
    ));
    // The lamp faces down (u x v = -y).
    s.triangles.extend(quad(
        Vec3::new(0.2, 1.5, -0.8),
        Vec3::new(0.6, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 0.6),
        2,
    ));
    s.lights.push(PunctualLight {
        name: "p".into(),
        kind: PunctualKind::Point,
        position: Vec3::new(-0.4, 1.6, 0.5),
        direction: Vec3::NEG_Y,
        intensity: Vec3::splat(2.0),
        range: 0.0,
    });
    s.cameras
        .push(look_at(Vec3::new(0.0, 2.2, 1.2), Vec3::ZERO, Vec3::Y, 0.9));
    s
}

/// The inside of a corner: a floor of material "plane" and two white walls, under a lamp and
/// a point light, rendered with paths of `depth` vertices. The camera sees mostly the walls,
/// whose light from the floor reaches it after a bounce on the floor: with indirect light,
/// the derivatives at later vertices carry much of the floor's gradient.
pub fn corner_scene(depth: u32) -> Scene {
    let mut s = Scene::default();
    s.materials.push(Material {
        name: "plane".into(),
        ..material([0.6, 0.5, 0.4], 0.2, 0.5)
    });
    s.materials.push(Material {
        name: "lamp".into(),
        emissive: Vec3::splat(6.0),
        ..material([0.0; 3], 0.0, 1.0)
    });
    s.materials.push(Material {
        name: "wall".into(),
        ..material([0.8, 0.8, 0.8], 0.0, 0.7)
    });
    s.triangles.extend(quad(
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -2.0),
        0,
    ));
    s.triangles.extend(quad(
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        2,
    ));
    s.triangles.extend(quad(
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, -2.0),
        Vec3::new(0.0, 2.0, 0.0),
        2,
    ));
    // The lamp faces down (u x v = -y).
    s.triangles.extend(quad(
        Vec3::new(-0.2, 1.6, -0.6),
        Vec3::new(0.5, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 0.5),
        1,
    ));
    s.lights.push(PunctualLight::point(
        "p",
        Vec3::new(0.5, 1.2, 0.4),
        Vec3::splat(1.5),
    ));
    s.cameras.push(look_at(
        Vec3::new(0.7, 0.9, 1.8),
        Vec3::new(-0.6, 1.0, -0.8),
        Vec3::Y,
        0.9,
    ));
    s.max_depth = psrestir::scene::MaxDepth::new(depth).unwrap();
    s
}

/// CRC-32 (IEEE) as PNG chunks use it.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A square render of camera 0 with the given techniques.
pub fn render_image(r: &Renderer, size: u32, spp: u32, seed: u32, t: Techniques) -> Image {
    r.render(
        &RenderSettings {
            width: size,
            height: size,
            spp,
            seed,
            camera: 0,
            techniques: t,
        },
        |_| {},
    )
    .unwrap()
    .image
}

/// A glTF (GLB) of a lit plane seen from above by camera `top`: material `plane` gray, or
/// with a 4x4 base color texture (a ground truth for optimization tests).
pub fn write_plane_scene(path: &std::path::Path, textured: bool) {
    let mut b = psrestir::assets::authoring::GltfBuilder::new();
    let mut pbr = serde_json::json!({"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6});
    if textured {
        let px: Vec<[u8; 4]> = (0..16u8)
            .map(|k| [40 + 13 * k, 200 - 11 * k, 60 + 7 * (k % 5), 255])
            .collect();
        let img = b.add_image_embedded(
            "truth",
            &psrestir::assets::authoring::png_bytes(4, 4, &px).unwrap(),
            "image/png",
        );
        let tex = b.add_texture(img, None);
        pbr = serde_json::json!({"baseColorTexture": {"index": tex}, "metallicFactor": 0.0, "roughnessFactor": 0.6});
    }
    let mat = b.add_material(serde_json::json!({"name": "plane", "pbrMetallicRoughness": pbr}));
    let mesh = b.add_mesh(
        "plane",
        &[
            [-1.0, 0.0, -1.0],
            [1.0, 0.0, -1.0],
            [1.0, 0.0, 1.0],
            [-1.0, 0.0, 1.0],
        ],
        Some(&[[0.0, 1.0, 0.0]; 4]),
        Some(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
        Some(&[0, 2, 1, 0, 3, 2]),
        Some(mat),
    );
    let cam = b.add_camera("top", 0.8, Some(1.0));
    let light = b.add_light(serde_json::json!({"type": "point", "intensity": 6.0}));
    let n = vec![
        b.add_node(serde_json::json!({"mesh": mesh})),
        // Looking straight down (-90 degrees about X).
        b.add_node(serde_json::json!({"camera": cam, "translation": [0.0, 2.6, 0.0], "rotation": [-std::f32::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2]})),
        b.add_node(serde_json::json!({"translation": [0.3, 2.0, 0.4], "extensions": {"KHR_lights_punctual": {"light": light}}})),
    ];
    b.set_scene(&n);
    b.write_glb(path).unwrap();
}
