//! Broken and hostile scene files: each gets a clear error naming the file and the problem,
//! from the library and from the command line (non-zero exit, no panic). Also the command
//! line's environment: a machine without a driver, and lavapipe's SIMD width.
mod common;

use common::crc32;
use psrestir::assets::authoring::{png_bytes, GltfBuilder};
use psrestir::scene::load;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A PNG whose header declares width x height (and no pixel data).
fn png_header_only(width: u32, height: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
    out.extend_from_slice(&13u32.to_be_bytes());
    out.extend_from_slice(&ihdr);
    out.extend_from_slice(&crc32(&ihdr).to_be_bytes());
    // A token IDAT chunk: decoders read the header up to the first one.
    out.extend_from_slice(&2u32.to_be_bytes());
    out.extend_from_slice(b"IDAT\x78\x9c");
    out.extend_from_slice(&crc32(b"IDAT\x78\x9c").to_be_bytes());
    out.extend_from_slice(&0u32.to_be_bytes());
    out.extend_from_slice(b"IEND");
    out.extend_from_slice(&crc32(b"IEND").to_be_bytes());
    out
}

/// A one-triangle scene whose base color texture is `uri`.
fn textured(dir: &Path, uri: &str) -> PathBuf {
    let mut b = GltfBuilder::new();
    let img = b.add_image_uri("tex", uri);
    let tex = b.add_texture(img, None);
    let mat = b.add_material(json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": tex}}}));
    let mesh = b.add_mesh(
        "m",
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        None,
        None,
        None,
        Some(mat),
    );
    let node = b.add_node(json!({"mesh": mesh}));
    b.set_scene(&[node]);
    let path = dir.join("scene.gltf");
    b.write_gltf(&path, false).unwrap();
    path
}

/// Run the loader and the CLI on `path`; both must fail with every fragment in the message.
fn refused(path: &Path, fragments: &[&str]) {
    let err = load(path).expect_err("loading must fail").to_string();
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    assert!(
        err.contains(&name),
        "error does not name the file {name}: {err}"
    );
    for f in fragments {
        assert!(err.contains(f), "error lacks `{f}`: {err}");
    }
    let out = Command::new(env!("CARGO_BIN_EXE_psrestir"))
        .args(["info"])
        .arg(path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "CLI exited 0 for {}", path.display());
    assert_eq!(
        out.status.code(),
        Some(1),
        "CLI did not exit cleanly: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "CLI panicked: {stderr}");
    assert!(
        stderr.contains(&name) && fragments.iter().all(|f| stderr.contains(f)),
        "CLI message: {stderr}"
    );
}

#[test]
fn malformed_json() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("broken.gltf");
    std::fs::write(&p, br#"{"asset": {"version": "2.0"}, "nodes": [ "#).unwrap();
    refused(&p, &["malformed glTF JSON"]);
}

#[test]
fn malformed_glb() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("broken.glb");
    let mut bytes = b"glTF".to_vec();
    bytes.extend_from_slice(&2u32.to_le_bytes());
    bytes.extend_from_slice(&9999u32.to_le_bytes());
    bytes.extend_from_slice(b"garbage");
    std::fs::write(&p, bytes).unwrap();
    refused(&p, &["malformed GLB"]);
}

#[test]
fn invalid_gltf_reference() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("dangling.gltf");
    std::fs::write(
        &p,
        br#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": [3]}]}"#,
    )
    .unwrap();
    refused(&p, &["invalid glTF", "nodes"]);
}

#[test]
fn missing_buffer_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("scene.gltf");
    std::fs::write(
        &p,
        br#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "gone.bin", "byteLength": 12}]}"#,
    )
    .unwrap();
    refused(&p, &["buffer 0", "gone.bin"]);
}

#[test]
fn buffer_shorter_than_declared() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("short.bin"), [0u8; 4]).unwrap();
    let p = dir.path().join("scene.gltf");
    std::fs::write(
        &p,
        br#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "short.bin", "byteLength": 64}]}"#,
    )
    .unwrap();
    refused(&p, &["declares 64 bytes but holds 4"]);
}

#[test]
fn missing_image_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = textured(dir.path(), "nothere.png");
    refused(&p, &["image `tex`", "nothere.png"]);
}

#[test]
fn unsupported_texture_format() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("tex.gif"),
        b"GIF89a\x01\x00\x01\x00\x00\x00\x00;",
    )
    .unwrap();
    let p = textured(dir.path(), "tex.gif");
    refused(&p, &["unsupported texture format", "Gif"]);
    std::fs::write(dir.path().join("tex.png"), b"this is not an image at all").unwrap();
    let p = textured(dir.path(), "tex.png");
    refused(&p, &["unsupported texture format"]);
}

#[test]
fn uris_leaving_the_folder_or_pointing_at_the_network_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let inner = dir.path().join("inner");
    std::fs::create_dir(&inner).unwrap();
    // The file exists, so only the policy can refuse it.
    std::fs::write(
        dir.path().join("secret.png"),
        png_bytes(1, 1, &[[1, 2, 3, 255]]).unwrap(),
    )
    .unwrap();
    for uri in ["../secret.png", "%2e%2e/secret.png", "sub/../../secret.png"] {
        refused(&textured(&inner, uri), &["leaves the scene's folder"]);
    }
    let abs = dir.path().join("secret.png").to_string_lossy().to_string();
    refused(&textured(&inner, &abs), &["refused"]);
    for uri in [
        "http://example.com/tex.png",
        "https://example.com/tex.png",
        "file:///etc/passwd",
        "ftp://x/y.png",
    ] {
        refused(&textured(&inner, uri), &["refused", "data URIs"]);
    }
    // Buffers follow the same policy.
    let p = inner.join("buf.gltf");
    std::fs::write(
        &p,
        br#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "../x.bin", "byteLength": 4}]}"#,
    )
    .unwrap();
    refused(&p, &["buffer 0", "leaves the scene's folder"]);
}

#[cfg(unix)]
#[test]
fn symlinks_out_of_the_folder_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let inner = dir.path().join("inner");
    std::fs::create_dir(&inner).unwrap();
    std::fs::write(
        dir.path().join("secret.png"),
        png_bytes(1, 1, &[[1, 2, 3, 255]]).unwrap(),
    )
    .unwrap();
    std::os::unix::fs::symlink(dir.path().join("secret.png"), inner.join("link.png")).unwrap();
    refused(
        &textured(&inner, "link.png"),
        &["resolves outside the scene's folder"],
    );
}

#[test]
fn an_image_declaring_a_huge_size_is_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("huge.png"),
        png_header_only(100_000, 100_000),
    )
    .unwrap();
    let p = textured(dir.path(), "huge.png");
    refused(&p, &["100000x100000", "refused before decoding"]);
}

#[test]
fn non_triangle_primitives_are_skipped_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = GltfBuilder::new();
    let mesh = b.add_mesh(
        "wire",
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        None,
        None,
        None,
        None,
    );
    b.json["meshes"][mesh]["primitives"][0]["mode"] = json!(1);
    let tri = b.add_mesh(
        "solid",
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        None,
        None,
        None,
        None,
    );
    let n1 = b.add_node(json!({"mesh": mesh}));
    let n2 = b.add_node(json!({"mesh": tri}));
    b.set_scene(&[n1, n2]);
    let p = dir.path().join("lines.gltf");
    b.write_gltf(&p, false).unwrap();
    let s = load(&p).unwrap();
    assert_eq!(s.triangles.len(), 1);
    assert_eq!(s.warnings.len(), 1);
    assert!(
        s.warnings[0].contains("mesh `wire` primitive 0") && s.warnings[0].contains("Lines"),
        "{:?}",
        s.warnings
    );
    let out = Command::new(env!("CARGO_BIN_EXE_psrestir"))
        .arg("info")
        .arg(&p)
        .output()
        .unwrap();
    assert!(out.status.success());
    let all =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(
        all.contains("mesh `wire` primitive 0") && all.contains("skipped"),
        "{all}"
    );
}

#[test]
fn out_of_range_indices_are_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = GltfBuilder::new();
    let mesh = b.add_mesh(
        "m",
        &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        None,
        None,
        Some(&[0, 1, 7]),
        None,
    );
    let n = b.add_node(json!({"mesh": mesh}));
    b.set_scene(&[n]);
    let p = dir.path().join("idx.gltf");
    b.write_gltf(&p, false).unwrap();
    refused(&p, &["index 7 out of range"]);
}

#[test]
fn render_cli_rejects_bad_arguments_clearly() {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/default/scene.gltf");
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_psrestir"))
            .args(args)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    let (code, err) = run(&["render", scene, "-o", "/tmp/x.jpg"]);
    assert_eq!(code, Some(1));
    assert!(err.contains("output must end in .exr"), "{err}");
    let (code, err) = run(&["render", scene, "--camera", "nope", "-o", "/tmp/x.png"]);
    assert_eq!(code, Some(1));
    assert!(
        err.contains("no camera `nope`") && err.contains("main"),
        "{err}"
    );
    let (code, err) = run(&["render", scene, "--size", "0x5", "-o", "/tmp/x.png"]);
    assert_ne!(code, Some(0));
    assert!(err.contains("out of range"), "{err}");
    let (code, err) = run(&[
        "render",
        scene,
        "--env",
        "/nonexistent/sky.exr",
        "-o",
        "/tmp/x.png",
    ]);
    assert_eq!(code, Some(1));
    assert!(err.contains("sky.exr"), "{err}");
    let (code, err) = run(&["render", scene, "--lights", "sun,lamp", "-o", "/tmp/x.png"]);
    assert_eq!(code, Some(1));
    assert!(
        err.contains(
            "scene.gltf: --lights: no punctual light `lamp` (there are: point, spot, sun)"
        ),
        "{err}"
    );
}

#[test]
fn output_into_a_closed_pipe_ends_quietly() {
    // The reader is gone before the program writes (as `psrestir estimators | head -1` once
    // head has its line): the writes fail with a broken pipe.
    let mut child = Command::new(env!("CARGO_BIN_EXE_psrestir"))
        .arg("estimators")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[cfg(target_os = "linux")]
#[test]
fn a_missing_gpu_driver_says_how_to_install_one() {
    // Asking for a backend that Linux builds do not have leaves no adapter, as on a machine
    // without a Vulkan driver.
    let out = Command::new(env!("CARGO_BIN_EXE_psrestir"))
        .arg("adapter")
        .env("WGPU_BACKEND", "metal")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("no GPU adapter") && err.contains("mesa-vulkan-drivers"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

/// The command line asks lavapipe for 4-lane SIMD code when the environment names no width,
/// and leaves a width the user names alone (lavapipe says its width in the adapter's name).
#[test]
fn the_command_line_asks_lavapipe_for_four_lanes_unless_told() {
    let adapter = |width: Option<&str>| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_psrestir"));
        c.arg("adapter")
            .env_remove(psrestir::gpu::CPU_SIMD_WIDTH_VAR);
        if let Some(w) = width {
            c.env(psrestir::gpu::CPU_SIMD_WIDTH_VAR, w);
        }
        let out = c.output().unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let default = adapter(None);
    if !default.contains("llvmpipe") {
        eprintln!("skipped: the adapter is not lavapipe: {default}");
        return;
    }
    assert!(default.contains("128 bits"), "{default}");
    let told = adapter(Some("256"));
    assert!(told.contains("256 bits"), "{told}");
}

/// The one-triangle scene of `textured`, with `edit` applied to its JSON.
fn edited(dir: &Path, name: &str, edit: impl Fn(&mut serde_json::Value)) -> PathBuf {
    let p = textured(dir, "tex.png");
    std::fs::write(
        dir.join("tex.png"),
        png_bytes(1, 1, &[[200, 100, 50, 255]]).unwrap(),
    )
    .unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    edit(&mut doc);
    let out = dir.join(name);
    std::fs::write(&out, serde_json::to_vec(&doc).unwrap()).unwrap();
    out
}

// Found by fuzzing (tests/fuzz.rs): each made the gltf crate panic before psrestir checked
// the JSON itself.

#[test]
fn an_accessor_reference_out_of_range_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = edited(dir.path(), "acc.gltf", |d| {
        d["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(34962)
    });
    refused(
        &p,
        &["mesh 0 primitive 0", "POSITION refers to accessor 34962"],
    );
}

#[test]
fn an_accessor_of_the_wrong_type_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = edited(dir.path(), "type.gltf", |d| {
        d["accessors"][0]["type"] = json!("VEC2")
    });
    refused(&p, &["POSITION accessor is VEC2", "does not allow"]);
    let p = edited(dir.path(), "idx.gltf", |d| {
        d["meshes"][0]["primitives"][0]["indices"] = json!(0)
    });
    refused(&p, &["indices accessor is VEC3 of component type 5126"]);
}

#[test]
fn an_image_in_a_buffer_view_without_a_mime_type_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = edited(dir.path(), "mime.gltf", |d| {
        d["images"][0] = json!({"bufferView": 0})
    });
    refused(&p, &["image 0 is in a buffer view but has no mimeType"]);
}

#[test]
fn a_jpeg_that_panics_the_decoder_is_refused() {
    // zune-jpeg 0.5.15 panics on this file (an unwrap in its AVX2 IDCT).
    let dir = tempfile::tempdir().unwrap();
    let p = textured(dir.path(), "tex.jpg");
    let bad = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fuzz_regressions/jpeg/c5bd64b4"
    );
    std::fs::copy(bad, dir.path().join("tex.jpg")).unwrap();
    refused(&p, &["tex.jpg", "the image decoder failed on this file"]);
}

#[test]
fn a_small_jpeg_declaring_a_huge_image_is_refused_before_decoding() {
    // 1.8 GiB were allocated for this file before the expansion limit.
    let dir = tempfile::tempdir().unwrap();
    let p = textured(dir.path(), "tex.jpg");
    let bad = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fuzz_regressions/jpeg/2bced699"
    );
    std::fs::copy(bad, dir.path().join("tex.jpg")).unwrap();
    refused(&p, &["more than a file of", "refused before decoding"]);
}

#[test]
fn degenerate_triangles_and_missing_uvs_are_skipped_or_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = GltfBuilder::new();
    let img = b.add_image_embedded(
        "tex",
        &png_bytes(1, 1, &[[9, 9, 9, 255]]).unwrap(),
        "image/png",
    );
    let tex = b.add_texture(img, None);
    let mat = b.add_material(
        json!({"name": "painted", "pbrMetallicRoughness": {"baseColorTexture": {"index": tex}}}),
    );
    // Two triangles: one proper, one with all three vertices on a line.
    let mesh = b.add_mesh(
        "m",
        &[
            [0.0; 3],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0; 3],
            [1.0, 1.0, 1.0],
            [2.0, 2.0, 2.0],
        ],
        None,
        None,
        None,
        Some(mat),
    );
    let n = b.add_node(json!({"mesh": mesh}));
    b.set_scene(&[n]);
    let p = dir.path().join("degenerate.gltf");
    b.write_gltf(&p, false).unwrap();
    let s = load(&p).unwrap();
    assert_eq!(s.triangles.len(), 1, "the degenerate triangle is skipped");
    s.validate().unwrap();
    let all = s.warnings.join("\n");
    assert!(
        all.contains("1 degenerate (zero-area) triangles skipped"),
        "{all}"
    );
    assert!(
        all.contains("no TEXCOORD_0 but material `painted` is textured"),
        "{all}"
    );
}

/// `[target] lights` (the punctual lights of each camera's capture) names the task file, the
/// key and what is wrong: a light or a camera the scene and the task do not have.
#[test]
fn a_captures_lights_must_exist() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/default/scene.gltf");
    let task = |lights: &str| {
        let path = dir.path().join("lit.toml");
        let text = format!(
            "scene = {scene:?}\nwidth = 16\nheight = 16\n\n[target]\nscene = {scene:?}\n\
             lights = {{ {lights} }}\n\n[optimizer]\niterations = 1\n\n[[textures]]\n\
             material = \"floor\"\nslot = \"base_color\"\nresolution = [4, 4]\n\
             init = [0.5, 0.5, 0.5]\n"
        );
        std::fs::write(&path, text).unwrap();
        let t = psrestir::task::Task::load(&path).unwrap();
        psrestir::Problem::load(&t).map(|p| p.scene.cameras)
    };
    let cams = task("main = [\"sun\", \"point\"], top = []").unwrap();
    assert_eq!(cams[0].lights, Some(vec![2, 0]));
    assert_eq!(cams[1].lights, Some(vec![]));
    for (lights, says) in [
        (
            "main = [\"lamp\"]",
            "`target.lights.main`: no punctual light `lamp` (there are: point, spot, sun)",
        ),
        (
            "side = [\"sun\"]",
            "`target.lights.side`: the scene and the task have no camera `side`",
        ),
    ] {
        let e = task(lights).unwrap_err().to_string();
        assert!(e.contains("lit.toml") && e.contains(says), "{e}");
    }
}

/// `optimize --set` with a key the task file does not have, or a bad value: exit 1, no panic,
/// the file, the key and the `--set` it came from named, before any GPU work.
#[test]
fn optimize_cli_names_a_bad_set() {
    let task = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/default/task.toml");
    for (set, says) in [
        (
            "optimizer.smoothnes=0.1",
            "`optimizer.smoothnes`: unknown key",
        ),
        (
            "optimizer.smoothness=-1",
            "`optimizer.smoothness`: must be a number",
        ),
        ("width.x=1", "`width` is a value (integer), not a table"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_psrestir"))
            .args(["optimize", task, "--iterations", "1", "--set", set])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.contains("task.toml")
                && err.contains(says)
                && err.contains(&format!("--set {set}")),
            "{err}"
        );
    }
}
