//! Light sampling alone, BSDF sampling alone and their MIS combination estimate the same image,
//! block by block within the noise, for every light kind that both techniques sample (emissive
//! triangles, the environment map), on small glTF scenes that vary what such bugs hide in: node
//! transforms (with negative scales), single- and double-sided emitters facing towards and away
//! from the receiver, textured emitters with KHR_materials_emissive_strength, large, tiny and
//! several emitters, grazing angles, and the bundled scene's own area light. Each lit case also
//! checks that the light reaches the receiver at all (the techniques could agree on nothing), and
//! a single-sided emitter seen and lit only from behind leaves the image black. The baseline
//! gradient passes get the same check: light-sampled and BSDF-sampled gradients agree.
mod common;

use common::*;
use glam::{Quat, Vec3};
use psrestir::assets::authoring::{png_bytes, GltfBuilder};
use psrestir::render::{Renderer, Techniques};
use psrestir::scene::{load, EnvMap, Scene};
use serde_json::json;

const W: u32 = 64;

/// A glossy metal panel standing at the back of a diffuse floor (6 x 6 units at y = 0), as glTF.
fn base() -> (GltfBuilder, Vec<usize>) {
    let mut b = GltfBuilder::new();
    let floor = b.add_material(json!({"name": "floor",
        "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.6, 0.5, 1.0],
            "metallicFactor": 0.0, "roughnessFactor": 0.7}}));
    let metal = b.add_material(json!({"name": "panel",
        "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.8, 0.6, 1.0],
            "metallicFactor": 1.0, "roughnessFactor": 0.35}}));
    let f = add_quad(
        &mut b,
        "floor",
        [0.0; 3],
        [3.0, 0.0, 0.0],
        [0.0, 0.0, -3.0],
        floor,
    );
    let p = add_quad(
        &mut b,
        "panel",
        [0.0, 0.6, -1.4],
        [1.2, 0.0, 0.0],
        [0.0, 0.6, 0.0],
        metal,
    );
    let roots = vec![
        b.add_node(json!({"name": "floor", "mesh": f})),
        b.add_node(json!({"name": "panel", "mesh": p})),
    ];
    (b, roots)
}

/// A rectangle with centre `c` and half-edges `u`, `v`; its front face (counter-clockwise) looks
/// along u x v. UVs span 0..1.
fn add_quad(
    b: &mut GltfBuilder,
    name: &str,
    c: [f32; 3],
    u: [f32; 3],
    v: [f32; 3],
    material: usize,
) -> usize {
    let (c, u, v) = (Vec3::from(c), Vec3::from(u), Vec3::from(v));
    let p = [c - u - v, c + u - v, c + u + v, c - u + v].map(|q| q.to_array());
    let n = u.cross(v).normalize().to_array();
    b.add_mesh(
        name,
        &p,
        Some(&[n; 4]),
        Some(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
        Some(&[0, 1, 2, 0, 2, 3]),
        Some(material),
    )
}

fn lamp(b: &mut GltfBuilder, name: &str, emissive: [f32; 3], double_sided: bool) -> usize {
    b.add_material(
        json!({"name": name, "emissiveFactor": emissive, "doubleSided": double_sided,
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]}}),
    )
}

/// Write the document, load it through the glTF loader, and look at `target` from `eye`.
fn finish(mut b: GltfBuilder, roots: &[usize], eye: Vec3, target: Vec3) -> Scene {
    b.set_scene(roots);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.gltf");
    b.write_gltf(&path, false).unwrap();
    let mut s = load(&path).unwrap();
    s.cameras = vec![look_at(eye, target, Vec3::Y, 0.9)];
    s
}

/// The default view: from the front, above the lamps of most cases.
const EYE: Vec3 = Vec3::new(0.0, 2.6, 3.4);
/// A view from below a lamp plane at y >= 1.3, which sees only the lamp's lower face.
const LOW_EYE: Vec3 = Vec3::new(0.0, 1.0, 3.2);
const TARGET: Vec3 = Vec3::new(0.0, 0.2, -0.2);

/// One case of the family: renders with each technique (two seeds each) and compares them.
struct Case {
    name: &'static str,
    scene: Scene,
    spp: u32,
    /// Pixels per side of a compared block.
    block: usize,
    /// The lowest image mean (luminance, MIS) that shows the light reaching the receiver;
    /// None: the image must be black.
    lit: Option<f64>,
}

fn run_case(gpu: &psrestir::Gpu, c: &Case) {
    let r = Renderer::new(gpu, &c.scene).unwrap();
    let render = |t: Techniques, seed: u32| render_image(&r, W, c.spp, seed, t).rgb;
    let nee = [
        render(Techniques::NeeOnly, 1),
        render(Techniques::NeeOnly, 2),
    ];
    let bsdf = [
        render(Techniques::BsdfOnly, 3),
        render(Techniques::BsdfOnly, 4),
    ];
    let mis = [render(Techniques::Mis, 5), render(Techniques::Mis, 6)];
    let means = [&nee, &bsdf, &mis].map(means_of);
    eprintln!(
        "{}: image mean NEE {:.5}, BSDF {:.5}, MIS {:.5}",
        c.name, means[0], means[1], means[2]
    );
    for img in nee.iter().chain(&bsdf).chain(&mis) {
        assert!(
            img.iter().flatten().all(|v| v.is_finite() && *v >= 0.0),
            "{}: a pixel is negative or not finite",
            c.name
        );
    }
    let Some(lit) = c.lit else {
        for (t, v) in [("NEE", &nee), ("BSDF", &bsdf), ("MIS", &mis)] {
            let bright = v[0].iter().chain(&v[1]).filter(|p| lum(**p) > 0.0).count();
            assert_eq!(
                bright, 0,
                "{}: {t} lit {bright} pixels, expected none",
                c.name
            );
        }
        return;
    };
    assert!(
        means[2] > lit,
        "{}: the image mean {:.5} is below {lit}: the light does not reach the receiver",
        c.name,
        means[2]
    );
    for (pair, a, b) in [
        ("NEE vs BSDF", &nee, &bsdf),
        ("MIS vs NEE", &mis, &nee),
        ("MIS vs BSDF", &mis, &bsdf),
    ] {
        // Per block: the difference of the two estimators' means, against five standard
        // errors (from each estimator's two renders) plus 1% of the image mean. The second
        // term covers blocks lit only by events rarer than two renders can show (BSDF samples
        // that find a small lamp from far away): there both renders may have drawn none, so
        // the variance estimate is zero while the true mean is not. The faults this family
        // is for move whole regions by a large fraction of the image mean.
        let image_mean = 0.5 * (means_of(a) + means_of(b));
        let blocks = block_diffs(a, b, c.block);
        let worst = blocks
            .iter()
            .map(|(d, se)| d.abs() / (5.0 * se + 0.01 * image_mean))
            .fold(0.0f64, f64::max);
        let (d, se) = block_diffs(a, b, W as usize)[0];
        eprintln!(
            "{}: {pair}: worst block |difference| / tolerance {worst:.2} over {} blocks, \
             whole image z {:.2}",
            c.name,
            blocks.len(),
            d / se
        );
        assert!(
            worst < 1.0,
            "{}: {pair}: a block differs by {worst:.2} times its tolerance",
            c.name
        );
        assert!(
            d.abs() < 5.0 * se,
            "{}: {pair}: image means differ by {:.2} standard errors",
            c.name,
            d / se
        );
    }
}

fn means_of(v: &[Vec<[f32; 3]>; 2]) -> f64 {
    let mean = |v: &[[f32; 3]]| v.iter().map(|p| lum(*p)).sum::<f64>() / v.len() as f64;
    0.5 * (mean(&v[0]) + mean(&v[1]))
}

/// Per square block: (mean of `a` - mean of `b`, standard error of that difference), each
/// estimator given as two renders with independent seeds whose half-difference estimates the
/// per-pixel variance (as in `block_z_scores`).
fn block_diffs(a: &[Vec<[f32; 3]>; 2], b: &[Vec<[f32; 3]>; 2], block: usize) -> Vec<(f64, f64)> {
    let w = W as usize;
    let mut out = Vec::new();
    for by in (0..w).step_by(block) {
        for bx in (0..w).step_by(block) {
            let (mut d, mut var, mut k) = (0.0, 0.0, 0.0);
            for y in by..by + block {
                for x in bx..bx + block {
                    let i = y * w + x;
                    let (a1, a2, b1, b2) = (lum(a[0][i]), lum(a[1][i]), lum(b[0][i]), lum(b[1][i]));
                    d += 0.5 * (a1 + a2 - b1 - b2);
                    var += 0.25 * ((a1 - a2).powi(2) + (b1 - b2).powi(2));
                    k += 1.0;
                }
            }
            out.push((d / k, (var / (k * k)).sqrt()));
        }
    }
    out
}

fn lit_case(name: &'static str, scene: Scene, lit: f64) -> Case {
    Case {
        name,
        scene,
        spp: 64,
        block: 8,
        lit: Some(lit),
    }
}

/// An emitter under a translated, rotated and non-uniformly scaled node, and emitters whose
/// node transforms mirror them (negative determinant: the loader reverses their winding, so
/// that the face the normal points to stays the front).
#[test]
fn techniques_agree_under_node_transforms_and_mirrors() {
    let Some(gpu) = gpu() else { return };
    let local_down =
        |b: &mut GltfBuilder, m| add_quad(b, "lamp", [0.0; 3], [0.5, 0.0, 0.0], [0.0, 0.0, 0.5], m);
    let (mut b, mut roots) = base();
    let m = lamp(&mut b, "lamp", [6.0, 5.5, 5.0], false);
    let mesh = local_down(&mut b, m);
    let rot = Quat::from_axis_angle(Vec3::new(1.0, 0.0, 1.0).normalize(), 0.4);
    roots.push(b.add_node(json!({"name": "lamp", "mesh": mesh,
        "translation": [0.3, 1.6, -0.2], "rotation": rot.to_array(), "scale": [1.6, 1.0, 0.7]})));
    let transformed = finish(b, &roots, EYE, TARGET);

    // Facing up in its own frame, mirrored in y by its node: faces down in the world.
    let (mut b, mut roots) = base();
    let m = lamp(&mut b, "lamp", [6.0, 5.5, 5.0], false);
    let mesh = add_quad(
        &mut b,
        "lamp",
        [0.0; 3],
        [0.0, 0.0, 0.5],
        [0.5, 0.0, 0.0],
        m,
    );
    roots.push(b.add_node(json!({"name": "lamp", "mesh": mesh,
        "translation": [0.2, 1.5, 0.1], "scale": [1.0, -1.0, 1.2]})));
    let mirrored_y = finish(b, &roots, EYE, TARGET);

    // Facing down, under a parent that mirrors x and a child that rotates and translates.
    let (mut b, mut roots) = base();
    let m = lamp(&mut b, "lamp", [6.0, 5.5, 5.0], false);
    let mesh = local_down(&mut b, m);
    let child = b.add_node(
        json!({"name": "lamp", "mesh": mesh, "translation": [0.4, 1.5, 0.0],
        "rotation": Quat::from_rotation_y(0.5).to_array()}),
    );
    roots.push(
        b.add_node(json!({"name": "mirror", "children": [child], "scale": [-1.0, 1.0, 1.0]})),
    );
    let mirrored_x = finish(b, &roots, EYE, TARGET);

    for c in [
        lit_case("transformed", transformed, 0.03),
        lit_case("mirrored in y", mirrored_y, 0.03),
        lit_case("mirrored in x by a parent", mirrored_x, 0.03),
    ] {
        run_case(&gpu, &c);
    }
}

/// A single-sided emitter emits from its front face only (the face its glTF winding and normal
/// define); a double-sided one from both. Facing away from the receiver and the camera, the
/// single-sided lamp leaves the image black; double-sided, it lights it.
#[test]
fn single_sided_emitters_emit_from_the_front_only() {
    let Some(gpu) = gpu() else { return };
    let scene = |facing_down: bool, double_sided: bool| {
        let (mut b, mut roots) = base();
        let m = lamp(&mut b, "lamp", [6.0, 5.5, 5.0], double_sided);
        let (u, v) = if facing_down {
            ([0.5, 0.0, 0.0], [0.0, 0.0, 0.5])
        } else {
            ([0.0, 0.0, 0.5], [0.5, 0.0, 0.0])
        };
        let mesh = add_quad(&mut b, "lamp", [0.0, 1.5, 0.0], u, v, m);
        roots.push(b.add_node(json!({"name": "lamp", "mesh": mesh})));
        finish(b, &roots, LOW_EYE, TARGET)
    };
    for c in [
        lit_case(
            "single-sided, facing the receiver",
            scene(true, false),
            0.03,
        ),
        Case {
            lit: None,
            ..lit_case("single-sided, facing away", scene(false, false), 0.0)
        },
        lit_case("double-sided, facing away", scene(false, true), 0.03),
    ] {
        run_case(&gpu, &c);
    }
}

/// A textured emitter with KHR_materials_emissive_strength; a large one close to the floor; a
/// tiny, bright one (BSDF sampling rarely finds it: more samples and larger blocks); several of
/// different power; one standing on the floor, lighting it and seen at grazing angles.
#[test]
fn techniques_agree_on_textured_large_tiny_several_and_grazing_emitters() {
    let Some(gpu) = gpu() else { return };
    let (mut b, mut roots) = base();
    b.use_extension("KHR_materials_emissive_strength");
    let texels = [
        [255, 40, 40, 255],
        [40, 255, 40, 255],
        [60, 60, 255, 255],
        [255, 255, 255, 255],
    ];
    let img = b.add_image_embedded("emission", &png_bytes(2, 2, &texels).unwrap(), "image/png");
    let s = b.add_sampler(json!({"magFilter": 9728, "minFilter": 9728}));
    let tex = b.add_texture(img, Some(s));
    let m = b.add_material(json!({"name": "lamp", "emissiveFactor": [1.0, 0.9, 0.8],
        "emissiveTexture": {"index": tex},
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 7.0}},
        "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]}}));
    let mesh = add_quad(
        &mut b,
        "lamp",
        [0.0, 1.5, 0.0],
        [0.6, 0.0, 0.0],
        [0.0, 0.0, 0.6],
        m,
    );
    roots.push(b.add_node(json!({"name": "lamp", "mesh": mesh})));
    let textured = finish(b, &roots, EYE, TARGET);
    assert!(
        textured.materials.iter().any(|m| m.emissive.x > 6.9),
        "the emissive strength was not applied"
    );

    let (mut b, mut roots) = base();
    let m = lamp(&mut b, "lamp", [1.0, 0.95, 0.9], false);
    let mesh = add_quad(
        &mut b,
        "lamp",
        [0.0, 1.3, 0.0],
        [2.5, 0.0, 0.0],
        [0.0, 0.0, 2.5],
        m,
    );
    roots.push(b.add_node(json!({"name": "lamp", "mesh": mesh})));
    let large = finish(b, &roots, LOW_EYE, TARGET);

    let (mut b, mut roots) = base();
    let m = lamp(&mut b, "lamp", [1500.0, 1400.0, 1300.0], false);
    let mesh = add_quad(
        &mut b,
        "lamp",
        [0.2, 1.2, 0.0],
        [0.03, 0.0, 0.0],
        [0.0, 0.0, 0.03],
        m,
    );
    roots.push(b.add_node(json!({"name": "lamp", "mesh": mesh})));
    let tiny = finish(b, &roots, EYE, TARGET);

    let (mut b, mut roots) = base();
    for (k, (c, half, e)) in [
        ([-1.2, 1.4, 0.3], 0.25, 40.0),
        ([0.6, 1.8, -0.4], 0.5, 5.0),
        ([1.4, 1.0, 0.8], 0.15, 120.0),
    ]
    .into_iter()
    .enumerate()
    {
        let m = lamp(&mut b, &format!("lamp{k}"), [e, e * 0.9, e * 0.8], false);
        let mesh = add_quad(&mut b, "lamp", c, [half, 0.0, 0.0], [0.0, 0.0, half], m);
        roots.push(b.add_node(json!({"name": format!("lamp{k}"), "mesh": mesh})));
    }
    let several = finish(b, &roots, EYE, TARGET);

    // A low wall lamp at the floor's left edge, facing +x along the floor.
    let (mut b, mut roots) = base();
    let m = lamp(&mut b, "lamp", [8.0, 7.5, 7.0], false);
    let mesh = add_quad(
        &mut b,
        "lamp",
        [-2.4, 0.3, 0.0],
        [0.0, 0.25, 0.0],
        [0.0, 0.0, 1.5],
        m,
    );
    roots.push(b.add_node(json!({"name": "lamp", "mesh": mesh})));
    let grazing = finish(
        b,
        &roots,
        Vec3::new(1.5, 0.6, 3.0),
        Vec3::new(-1.0, 0.2, -0.5),
    );

    for c in [
        lit_case("textured, with emissive strength", textured, 0.03),
        lit_case("large", large, 0.03),
        Case {
            spp: 1024,
            block: 16,
            ..lit_case("tiny", tiny, 0.01)
        },
        lit_case("several of different power", several, 0.03),
        lit_case("grazing", grazing, 0.01),
    ] {
        run_case(&gpu, &c);
    }
}

/// An environment map with a bright patch and a colour gradient over a box that shadows the
/// floor: its importance sampling and the BSDF's hits on it agree.
#[test]
fn techniques_agree_under_an_environment_map() {
    let Some(gpu) = gpu() else { return };
    let (mut b, mut roots) = base();
    let grey = b.add_material(json!({"name": "box",
        "pbrMetallicRoughness": {"baseColorFactor": [0.4, 0.4, 0.4, 1.0],
            "metallicFactor": 0.0, "roughnessFactor": 0.5}}));
    let tris = psrestir::assets::authoring::box_triangles([0.3, 0.35, 0.2], [0.35; 3]);
    let mesh = b.add_mesh("box", &tris, None, None, None, Some(grey));
    roots.push(b.add_node(json!({"name": "box", "mesh": mesh})));
    let mut scene = finish(b, &roots, EYE, TARGET);
    let (w, h) = (32u32, 16u32);
    let mut rgb = Vec::new();
    for j in 0..h {
        for i in 0..w {
            let sky = [0.2 + 0.3 * i as f32 / w as f32, 0.3, 0.5 - 0.02 * j as f32];
            let sun = (9..12).contains(&i) && (3..5).contains(&j);
            rgb.push(if sun { [40.0, 36.0, 30.0] } else { sky });
        }
    }
    scene.env = Some(EnvMap {
        width: w,
        height: h,
        rgb,
        scale: 1.0,
    });
    run_case(&gpu, &lit_case("environment map", scene, 0.05));
}

/// The bundled scene lit by its area light alone (its punctual lights and no environment):
/// the three techniques' image means agree within 2% and their blocks within the noise.
#[test]
fn the_bundled_scenes_area_light_agrees_across_techniques() {
    let Some(gpu) = gpu() else { return };
    let path = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/default/scene.gltf"
    ));
    let mut scene = load(path).unwrap();
    scene.lights.clear();
    let top = scene.cameras.iter().position(|c| c.name == "top").unwrap();
    scene.cameras = vec![scene.cameras[top].clone()];
    let c = Case {
        spp: 128,
        ..lit_case("bundled scene, area light", scene, 0.03)
    };
    run_case(&gpu, &c);
}

/// Light-sampled and BSDF-sampled baseline gradients agree in expectation: under one fixed
/// adjoint, the means of K estimates of each differ per texel by less than five standard
/// errors, for base color, roughness and a normal map (tilted against a flat start), on a
/// plane lit by an area light and a blocker's soft shadow.
#[test]
fn light_and_bsdf_sampled_gradients_agree() {
    use psrestir::optim::{Method, Optimizer, Settings};
    use psrestir::render::params::ParamSet;
    use psrestir::task::{Filter, Init, Slot, TextureSpec};
    let Some(gpu) = gpu() else { return };
    let mut scene = shadow_scene();
    scene.lights.clear();
    // The lamp 1.0 above the plane instead of 1.5: brighter, and closer than the rest of the
    // scene is wide, as in the bundled scene.
    for t in scene.triangles.iter_mut().filter(|t| t.material == 2) {
        for p in &mut t.p {
            p.y = 1.0;
        }
    }
    let w = 16;
    for slot in [Slot::BaseColor, Slot::Roughness, Slot::Normal] {
        let spec = TextureSpec {
            material: "plane".into(),
            slot,
            resolution: [2, 2],
            init: Init::Vector(vec![0.5; slot.channels() as usize]),
            learning_rate: Some(0.0),
        };
        let set = ParamSet::from_specs(&scene, &[spec], Filter::Nearest, std::path::Path::new("t"))
            .unwrap();
        let settings = Settings {
            gradient_spp: 32,
            seed: 11,
            method: Method::BASELINE,
            ..Settings::new(w, w, vec![0])
        };
        // Target: darker than the current textures, so every observed texel has a gradient.
        let blank = psrestir::Image::new(w, w);
        let opt = Optimizer::new(&gpu, &scene, set.clone(), settings.clone(), &[blank]).unwrap();
        let n = set.values.len();
        // (A normal map: tilted towards +X and +Y, against the flat one below.)
        let (dark, start) = match slot {
            Slot::Normal => ([0.65, 0.6, 0.9], vec![0.5, 0.5, 1.0]),
            _ => ([0.2; 3], vec![0.5; slot.channels() as usize]),
        };
        opt.write_params(&dark[..slot.channels() as usize].repeat(n / slot.channels() as usize))
            .unwrap();
        let target = opt.render(0, 1024, 5).unwrap();
        let mut opt =
            Optimizer::new(&gpu, &scene, set, settings, std::slice::from_ref(&target)).unwrap();
        opt.write_params(&start.repeat(n / start.len())).unwrap();
        let (adjoint, _) = opt.converged_adjoint(256, 9).unwrap();
        let k = 96;
        let mut stats = Vec::new();
        for t in [Techniques::NeeOnly, Techniques::BsdfOnly] {
            opt.set_gradient_techniques(t).unwrap();
            let (mut sum, mut sum2) = (vec![0f64; n], vec![0f64; n]);
            for it in 0..k {
                let g = opt
                    .estimate_gradient_with_adjoint(100 + it, &adjoint)
                    .unwrap();
                for i in 0..n {
                    sum[i] += g[i] as f64;
                    sum2[i] += (g[i] as f64).powi(2);
                }
            }
            let mean: Vec<f64> = sum.iter().map(|s| s / k as f64).collect();
            let var: Vec<f64> = (0..n)
                .map(|i| (sum2[i] / k as f64 - mean[i] * mean[i]).max(0.0) / (k - 1) as f64)
                .collect();
            stats.push((mean, var));
        }
        let (nee, bsdf) = (&stats[0], &stats[1]);
        let scale = nee.0.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0, "{slot:?}: the gradient is zero");
        for i in 0..n {
            let se = (nee.1[i] + bsdf.1[i]).sqrt();
            let z = (nee.0[i] - bsdf.0[i]) / se.max(1e-12 * scale);
            eprintln!(
                "{slot:?} [{i}]: NEE {:.4e}, BSDF {:.4e}, z {z:.2}",
                nee.0[i], bsdf.0[i]
            );
            assert!(
                z.abs() < 5.0,
                "{slot:?} entry {i}: light-sampled {} vs BSDF-sampled {} ({z:.2} standard errors)",
                nee.0[i],
                bsdf.0[i]
            );
        }
    }
}
