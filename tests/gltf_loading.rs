//! A glTF file built by hand (transform hierarchy, embedded and external textures,
//! KHR_texture_transform, KHR_materials_emissive_strength, a camera, lights) loads to the
//! expected world-space triangles, UVs and material values, in .gltf and .glb form alike.
use glam::{Vec2, Vec3, Vec4};
use psrestir::assets::authoring::{png_bytes, GltfBuilder};
use psrestir::scene::{load, PunctualKind, Scene, Wrap};
use serde_json::json;
use std::path::Path;

const A: [[u8; 4]; 4] = [
    [255, 0, 0, 255],
    [0, 255, 0, 255],
    [0, 0, 255, 255],
    [255, 255, 255, 255],
];
const B: [[u8; 4]; 8] = [
    [0, 10, 20, 255],
    [0, 30, 40, 255],
    [0, 50, 60, 255],
    [0, 70, 80, 255],
    [0, 90, 100, 255],
    [0, 110, 120, 255],
    [0, 130, 140, 255],
    [0, 150, 160, 255],
];

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-5
}

fn build(dir: &Path) -> GltfBuilder {
    std::fs::write(dir.join("ext tex.png"), png_bytes(4, 2, &B).unwrap()).unwrap();
    let mut b = GltfBuilder::new();
    b.use_extension("KHR_texture_transform");
    b.use_extension("KHR_materials_emissive_strength");
    let img_a = b.add_image_embedded("embedded", &png_bytes(2, 2, &A).unwrap(), "image/png");
    let img_b = b.add_image_uri("external", "ext%20tex.png");
    let s = b.add_sampler(json!({"wrapS": 33071, "wrapT": 33648, "magFilter": 9728}));
    let tex_a = b.add_texture(img_a, None);
    let tex_b = b.add_texture(img_b, Some(s));
    let mat = b.add_material(json!({
        "name": "painted",
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.5, 0.6, 0.7, 1.0],
            "baseColorTexture": {"index": tex_a, "extensions": {"KHR_texture_transform":
                {"offset": [0.25, 0.5], "rotation": 0.3, "scale": [2.0, 3.0]}}},
            "metallicFactor": 0.3, "roughnessFactor": 0.7,
            "metallicRoughnessTexture": {"index": tex_b}
        },
        "emissiveFactor": [0.1, 0.2, 0.3],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 2.0}},
        "doubleSided": true
    }));
    let tri = b.add_mesh(
        "tri",
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        Some(&[[0.0, 0.0, 1.0]; 3]),
        Some(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
        Some(&[0, 1, 2]),
        Some(mat),
    );
    // Not indexed, no normals, no material.
    let bare = b.add_mesh(
        "bare",
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        None,
        None,
        None,
        None,
    );
    let cam = b.add_camera("cam", 0.5, Some(1.5));
    let spot = b.add_light(
        json!({"type": "spot", "name": "spot", "color": [1.0, 0.5, 0.25], "intensity": 8.0,
        "range": 10.0, "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.5}}),
    );
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let child = b.add_node(json!({"name": "child", "mesh": tri, "rotation": [0.0, 0.0, h, h]}));
    let lamp = b.add_node(json!({"name": "lamp", "rotation": [-h, 0.0, 0.0, h],
        "extensions": {"KHR_lights_punctual": {"light": spot}}}));
    let parent = b.add_node(
        json!({"name": "parent", "translation": [1.0, 2.0, 3.0], "scale": [2.0, 2.0, 2.0],
        "children": [child, lamp]}),
    );
    let mirrored = b.add_node(json!({"name": "mirrored", "mesh": bare,
        "matrix": [-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 5.0, 1.0]}));
    let camera =
        b.add_node(json!({"name": "camnode", "camera": cam, "translation": [0.0, 0.0, 10.0]}));
    b.set_scene(&[parent, mirrored, camera]);
    b
}

fn check(s: &Scene) {
    assert_eq!(s.triangles.len(), 2);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    // Parent T(1,2,3) S(2) x child R_z(90): (x, y, z) -> (1 - 2y, 2 + 2x, 3 + 2z).
    let t = &s.triangles[0];
    assert!(close(t.p[0], Vec3::new(1.0, 2.0, 3.0)), "{:?}", t.p);
    assert!(close(t.p[1], Vec3::new(1.0, 4.0, 3.0)), "{:?}", t.p);
    assert!(close(t.p[2], Vec3::new(-1.0, 2.0, 3.0)), "{:?}", t.p);
    assert!(t.n.iter().all(|n| close(*n, Vec3::Z)));
    assert_eq!(
        t.uv,
        [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 1.0)
        ]
    );
    // Mirrored node: winding swapped so the front face keeps its normal (+Z), flat normals.
    let m = &s.triangles[1];
    let geo = (m.p[1] - m.p[0]).cross(m.p[2] - m.p[0]).normalize();
    assert!(close(geo, Vec3::Z), "mirrored triangle faces {geo}");
    assert!(m.n.iter().all(|n| close(*n, Vec3::Z)));
    assert!(m.p.iter().all(|p| (p.z - 5.0).abs() < 1e-6 && p.x <= 0.0));
    // Materials: the file's one, plus the default for the bare mesh.
    assert_eq!(s.materials.len(), 2);
    let mat = &s.materials[t.material as usize];
    assert_eq!(mat.name, "painted");
    assert_eq!(mat.base_color, Vec4::new(0.5, 0.6, 0.7, 1.0));
    assert!((mat.metallic - 0.3).abs() < 1e-6 && (mat.roughness - 0.7).abs() < 1e-6);
    assert!(close(mat.emissive, Vec3::new(0.2, 0.4, 0.6)));
    assert!(mat.double_sided);
    let bc = mat.base_color_texture.as_ref().unwrap();
    let (sn, cs) = 0.3f32.sin_cos();
    let want = [[cs * 2.0, -sn * 3.0, 0.25], [sn * 2.0, cs * 3.0, 0.5]];
    for (got, want) in bc.transform.iter().zip(&want) {
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "transform {:?}", bc.transform);
        }
    }
    assert_eq!(
        (bc.wrap_s, bc.wrap_t, bc.nearest),
        (Wrap::Repeat, Wrap::Repeat, false)
    );
    let mr = mat.metallic_roughness_texture.as_ref().unwrap();
    assert_eq!(
        (mr.wrap_s, mr.wrap_t, mr.nearest),
        (Wrap::Clamp, Wrap::Mirror, true)
    );
    assert_eq!(mr.transform, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let ia = &s.images[bc.image];
    assert_eq!((ia.width, ia.height, ia.rgba.as_slice()), (2, 2, &A[..]));
    let ib = &s.images[mr.image];
    assert_eq!((ib.width, ib.height, ib.rgba.as_slice()), (4, 2, &B[..]));
    assert_eq!(s.materials[m.material as usize].name, "default");
    // Camera and light in world space.
    assert_eq!(s.cameras.len(), 1);
    assert_eq!(s.camera(Some("cam")).unwrap(), 0);
    assert_eq!(s.camera(Some("0")).unwrap(), 0);
    assert!(s
        .camera(Some("nope"))
        .unwrap_err()
        .to_string()
        .contains("no camera `nope`"));
    assert_eq!(s.cameras[0].aspect, Some(1.5));
    assert!(close(
        s.cameras[0].world.transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 0.0, 10.0)
    ));
    let l = &s.lights[0];
    assert!(matches!(l.kind, PunctualKind::Spot { .. }));
    assert!(close(l.position, Vec3::new(1.0, 2.0, 3.0)));
    // Rotation -90 degrees about X turns -Z into -Y.
    assert!(close(l.direction, Vec3::NEG_Y), "{}", l.direction);
    assert!(close(l.intensity, Vec3::new(8.0, 4.0, 2.0)));
    assert_eq!(l.range, 10.0);
}

fn strip(mut s: Scene) -> Scene {
    s.source = Default::default();
    s
}

#[test]
fn gltf_glb_and_embedded_forms_load_the_same_expected_scene() {
    let dir = tempfile::tempdir().unwrap();
    let b = build(dir.path());
    b.write_gltf(&dir.path().join("scene.gltf"), false).unwrap();
    b.write_gltf(&dir.path().join("inline.gltf"), true).unwrap();
    b.write_glb(&dir.path().join("scene.glb")).unwrap();
    let a = load(&dir.path().join("scene.gltf")).unwrap();
    check(&a);
    for other in ["inline.gltf", "scene.glb"] {
        let o = load(&dir.path().join(other)).unwrap();
        check(&o);
        let (x, y) = (strip(a.clone()), strip(o));
        assert_eq!(x.triangles, y.triangles, "{other}");
        assert_eq!(x.materials, y.materials, "{other}");
        assert_eq!(x.images, y.images, "{other}");
        assert_eq!(x.cameras, y.cameras, "{other}");
        assert_eq!(x.lights, y.lights, "{other}");
    }
}

#[test]
fn the_bundled_scene_has_every_light_type_textures_and_cameras() {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/default/scene.gltf"
    ));
    let s = load(path).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert!(s.lights.iter().any(|l| l.kind == PunctualKind::Point));
    assert!(s
        .lights
        .iter()
        .any(|l| matches!(l.kind, PunctualKind::Spot { .. })));
    assert!(s.lights.iter().any(|l| l.kind == PunctualKind::Directional));
    assert!(s.materials.iter().any(|m| m.emissive.max_element() > 0.0));
    assert!(s.images.len() >= 3);
    assert_eq!(
        s.cameras
            .iter()
            .map(|c| c.name.as_str())
            .collect::<Vec<_>>(),
        ["main", "top"]
    );
    // The committed files are what the generator writes today.
    let dir = tempfile::tempdir().unwrap();
    psrestir::assets::bundled::write_default_scene(dir.path()).unwrap();
    let fresh = load(&dir.path().join("scene.gltf")).unwrap();
    assert_eq!(strip(fresh).triangles, strip(s.clone()).triangles);
    let sky = psrestir::scene::EnvMap::load(&path.with_file_name("sky.exr")).unwrap();
    assert_eq!((sky.width, sky.height), (64, 32));
}

/// An optimized normal map is exported as the material's normalTexture: loaded back, its
/// texels are the normals that the optimized values stand for, stored as glTF stores them.
#[test]
fn an_optimized_normal_map_is_exported_as_the_materials_normal_texture() {
    use psrestir::render::params::ParamSet;
    use psrestir::task::{Filter, Init, Slot, TextureSpec};
    let source = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/default/scene.gltf");
    let scene = psrestir::scene::load(&source).unwrap();
    let spec = TextureSpec {
        material: "sphere".into(),
        slot: Slot::Normal,
        resolution: [4, 2],
        init: Init::Vector(vec![0.5, 0.5, 1.0]),
        learning_rate: None,
    };
    let set = ParamSet::from_specs(&scene, &[spec], Filter::Bilinear, &source).unwrap();
    // A tilt towards +X on every texel, its Z under the floor on the last one.
    let mut values = [0.7, 0.5, 0.9].repeat(8);
    values[23] = 0.52;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("optimized.glb");
    psrestir::job::export::write_glb(&source, &out, &scene, &set, &values).unwrap();
    let back = psrestir::scene::load(&out).unwrap();
    let m = back.materials.iter().find(|m| m.name == "sphere").unwrap();
    let slot = m.normal_texture.as_ref().expect("no normalTexture");
    let img = &back.images[slot.image];
    assert_eq!((img.width, img.height), (4, 2));
    for (k, px) in img.rgba.iter().enumerate() {
        let n =
            psrestir::vocab::decode_normal([values[3 * k], values[3 * k + 1], values[3 * k + 2]]);
        for c in 0..3 {
            let stored = px[c] as f32 / 255.0;
            assert!(
                (stored - (0.5 + 0.5 * n[c])).abs() <= 0.5 / 255.0 + 1e-6,
                "texel {k}: {px:?} vs {n:?}"
            );
        }
    }
}
