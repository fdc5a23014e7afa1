//! Camera sets written by capture tools: NeRF-style `transforms.json` (instant-ngp,
//! nerfstudio) and COLMAP's text model (`cameras.txt` + `images.txt`).
//!
//! Axis conventions. psrestir's cameras follow glTF: camera-to-world matrices, the camera
//! looks down -Z with +Y up and +X right. `transforms.json` stores camera-to-world matrices
//! in the same (OpenGL) convention, so they are used as they are. COLMAP stores
//! world-to-camera rotations (quaternion QW QX QY QZ) and translations with the OpenCV camera
//! axes (+Z forward, +Y down): the camera-to-world matrix is `[R^T diag(1, -1, -1) | -R^T t]`.
//! Pixel coordinates in both put the origin at the top-left corner of the top-left pixel
//! (pixel centers at +0.5), as psrestir does, so principal points carry over unchanged.
//!
//! Lens distortion is refused with an error that names the file and the coefficients
//! (undistort the images first, e.g. with COLMAP's `image_undistorter`).
use super::{Camera, Intrinsics};
use crate::{Error, Result};
use glam::{Mat3, Mat4, Quat, Vec3};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// One view of a capture: its camera, and the image it was taken with.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The camera (named after the image's file stem, or `frame N`).
    pub camera: Camera,
    /// The image of this view, resolved against the camera file's folder (it may not
    /// exist; only tasks that use it as a target read it).
    pub image: Option<PathBuf>,
}

/// Load the frames of a camera file: a `.json` file in the `transforms.json` format, or a
/// COLMAP text model (its folder, or its `cameras.txt` or `images.txt`).
pub fn load_frames(path: &Path) -> Result<Vec<Frame>> {
    let frames = if path.is_dir() {
        load_colmap(path)?
    } else {
        match path.file_name().and_then(|n| n.to_str()) {
            Some("cameras.txt") | Some("images.txt") => {
                load_colmap(path.parent().unwrap_or(Path::new(".")))?
            }
            _ => {
                let text =
                    std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
                parse_transforms(&text, path)?
            }
        }
    };
    if frames.is_empty() {
        return Err(Error::file(path, "the camera file holds no frames"));
    }
    Ok(frames)
}

fn bad(path: &Path, msg: impl std::fmt::Display) -> Error {
    Error::file(path, msg.to_string())
}

fn num(v: &Value) -> Option<f32> {
    v.as_f64().map(|x| x as f32).filter(|x| x.is_finite())
}

/// Refuse non-zero distortion coefficients among `keys` of `obj`.
fn no_distortion(obj: &Value, path: &Path, keys: &[&str]) -> Result<()> {
    let present: Vec<String> = keys
        .iter()
        .filter_map(|k| {
            obj.get(*k)
                .and_then(num)
                .filter(|v| *v != 0.0)
                .map(|v| format!("{k} = {v}"))
        })
        .collect();
    if !present.is_empty() {
        return Err(bad(
            path,
            format!(
                "lens distortion ({}) is not supported: undistort the images and write a pinhole \
                 model",
                present.join(", ")
            ),
        ));
    }
    Ok(())
}

/// The size of an image file, from its header.
fn image_size(path: &Path) -> Result<(u32, u32)> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        let img = crate::image_io::load_linear(path)?;
        return Ok((img.width, img.height));
    }
    image::image_dimensions(path).map_err(|e| Error::file(path, e.to_string()))
}

/// `file_path` of a frame, resolved against `base`: as given, or with the usual extensions
/// (instant-ngp's files often omit them).
fn resolve_image(base: &Path, file: &str) -> PathBuf {
    let p = base.join(file);
    if p.is_file() {
        return p;
    }
    for ext in ["png", "jpg", "jpeg", "exr", "PNG", "JPG"] {
        let q = base.join(format!("{file}.{ext}"));
        if q.is_file() {
            return q;
        }
    }
    p
}

/// Parse `transforms.json` text; `path` names it in errors and anchors `file_path`s.
pub fn parse_transforms(text: &str, path: &Path) -> Result<Vec<Frame>> {
    let root: Value =
        serde_json::from_str(text).map_err(|e| bad(path, format!("not JSON: {e}")))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let frames = root
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| bad(path, "no `frames` array"))?;
    if let Some(model) = root.get("camera_model").and_then(Value::as_str) {
        if !matches!(model, "OPENCV" | "PINHOLE" | "SIMPLE_PINHOLE") {
            return Err(bad(
                path,
                format!("camera_model `{model}` is not a pinhole model"),
            ));
        }
    }
    let dist = ["k1", "k2", "k3", "k4", "p1", "p2"];
    no_distortion(&root, path, &dist)?;
    let mut out = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let at = |m: &str| bad(path, format!("frames[{i}]: {m}"));
        no_distortion(f, path, &dist)?;
        // Per-frame values override the file-wide ones (nerfstudio allows both).
        let get = |k: &str| f.get(k).and_then(num).or_else(|| root.get(k).and_then(num));
        let file = f.get("file_path").and_then(Value::as_str);
        let image = file.map(|p| resolve_image(base, p));
        let rows = f
            .get("transform_matrix")
            .and_then(Value::as_array)
            .filter(|r| r.len() == 4)
            .ok_or_else(|| at("no 4x4 `transform_matrix`"))?;
        let mut m = [[0f32; 4]; 4];
        for (r, row) in rows.iter().enumerate() {
            let row = row
                .as_array()
                .filter(|c| c.len() == 4)
                .ok_or_else(|| at("`transform_matrix` is not 4x4"))?;
            for (c, v) in row.iter().enumerate() {
                m[r][c] = num(v).ok_or_else(|| at("`transform_matrix` has a non-number"))?;
            }
        }
        // Rows in the file; glam takes columns.
        let world = Mat4::from_cols_array_2d(&m).transpose();
        let (w, h) = match (get("w"), get("h")) {
            (Some(w), Some(h)) => (w.round() as u32, h.round() as u32),
            _ => {
                let img = image
                    .as_ref()
                    .ok_or_else(|| at("no `w`/`h` and no `file_path` to take the size from"))?;
                image_size(img).map_err(|e| at(&format!("size of its image: {e}")))?
            }
        };
        let (fx, fy) = match (get("fl_x"), get("fl_y"), get("camera_angle_x")) {
            (Some(fx), fy, _) => (fx, fy.unwrap_or(fx)),
            (None, _, Some(ax)) => {
                let fx = 0.5 * w as f32 / (0.5 * ax).tan();
                let fy = get("camera_angle_y")
                    .map(|ay| 0.5 * h as f32 / (0.5 * ay).tan())
                    .unwrap_or(fx);
                (fx, fy)
            }
            _ => return Err(at("no focal length (`fl_x` or `camera_angle_x`)")),
        };
        let k = Intrinsics {
            fx,
            fy,
            cx: get("cx").unwrap_or(0.5 * w as f32),
            cy: get("cy").unwrap_or(0.5 * h as f32),
            width: w,
            height: h,
        };
        if !k.valid() || !world.is_finite() {
            return Err(at("invalid intrinsics or transform"));
        }
        let name = file
            .and_then(|p| Path::new(p).file_stem())
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_else(|| format!("frame {i}"));
        out.push(Frame {
            camera: Camera::with_intrinsics(&name, world, k),
            image,
        });
    }
    Ok(out)
}

/// Lines of a COLMAP text file without its comments (`#`).
fn colmap_lines(path: &Path) -> Result<Vec<(usize, String)>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
    Ok(text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#'))
        .map(|(i, l)| (i + 1, l.to_string()))
        .collect())
}

/// The intrinsics of a COLMAP `cameras.txt`, by camera id: pinhole models, and the radial
/// and OpenCV ones without distortion.
fn colmap_cameras(cam_path: &Path) -> Result<std::collections::HashMap<String, Intrinsics>> {
    let mut cameras = std::collections::HashMap::new();
    for (line_no, line) in colmap_lines(cam_path)? {
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.is_empty() {
            continue;
        }
        let at = |m: String| bad(cam_path, format!("line {line_no}: {m}"));
        if t.len() < 4 {
            return Err(at("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS".into()));
        }
        let p: Vec<f32> = t[4..]
            .iter()
            .map(|v| v.parse::<f32>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| at("a parameter is not a number".into()))?;
        let (w, h) = match (t[2].parse::<u32>(), t[3].parse::<u32>()) {
            (Ok(w), Ok(h)) => (w, h),
            _ => return Err(at("WIDTH and HEIGHT must be whole numbers".into())),
        };
        let need = |n: usize| -> Result<()> {
            if p.len() < n {
                return Err(at(format!(
                    "{} takes {n} parameters, got {}",
                    t[1],
                    p.len()
                )));
            }
            Ok(())
        };
        let (fx, fy, cx, cy) = match t[1] {
            "SIMPLE_PINHOLE" => {
                need(3)?;
                (p[0], p[0], p[1], p[2])
            }
            "PINHOLE" => {
                need(4)?;
                (p[0], p[1], p[2], p[3])
            }
            "SIMPLE_RADIAL" | "RADIAL" | "OPENCV" | "FULL_OPENCV" => {
                let (f, first_dist) = match t[1] {
                    "SIMPLE_RADIAL" | "RADIAL" => {
                        need(4)?;
                        ((p[0], p[0], p[1], p[2]), 3)
                    }
                    _ => {
                        need(8)?;
                        ((p[0], p[1], p[2], p[3]), 4)
                    }
                };
                if p[first_dist..].iter().any(|&k| k != 0.0) {
                    return Err(at(format!(
                        "camera model {} with distortion {:?} is not supported: undistort the \
                         images (COLMAP's image_undistorter writes a PINHOLE model)",
                        t[1],
                        &p[first_dist..]
                    )));
                }
                f
            }
            other => {
                return Err(at(format!(
                    "camera model {other} is not supported (PINHOLE, SIMPLE_PINHOLE, and the \
                     radial and OpenCV models without distortion are)"
                )))
            }
        };
        let k = Intrinsics {
            fx,
            fy,
            cx,
            cy,
            width: w,
            height: h,
        };
        if !k.valid() {
            return Err(at("invalid focal length or size".into()));
        }
        cameras.insert(t[0].to_string(), k);
    }
    Ok(cameras)
}

/// Load a COLMAP text model from its folder (`cameras.txt`, `images.txt`). Images are
/// looked for in the usual places: `../../images/NAME` (a `sparse/0` model of a COLMAP
/// project), `images/NAME` and `NAME` beside the model.
pub fn load_colmap(dir: &Path) -> Result<Vec<Frame>> {
    let img_path = dir.join("images.txt");
    let cameras = colmap_cameras(&dir.join("cameras.txt"))?;
    let lines = colmap_lines(&img_path)?;
    let mut out = Vec::new();
    // Images come in pairs of lines: the pose, then the 2D points (possibly empty).
    let mut i = 0;
    while i < lines.len() {
        let (line_no, line) = &lines[i];
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.is_empty() {
            i += 1;
            continue;
        }
        let at = |m: &str| bad(&img_path, format!("line {line_no}: {m}"));
        if t.len() < 10 {
            return Err(at("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME"));
        }
        let v: Vec<f32> = t[1..8]
            .iter()
            .map(|x| x.parse::<f32>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| at("a pose value is not a number"))?;
        let q = Quat::from_xyzw(v[1], v[2], v[3], v[0]);
        if q.length() < 1e-6 {
            return Err(at("zero quaternion"));
        }
        let r = Mat3::from_quat(q.normalize());
        let tr = Vec3::new(v[4], v[5], v[6]);
        let k = *cameras
            .get(t[8])
            .ok_or_else(|| at(&format!("camera {} is not in cameras.txt", t[8])))?;
        // Camera-to-world, OpenCV axes to glTF axes (flip y and z).
        let rt = r.transpose();
        let center = -(rt * tr);
        let flip = Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0));
        let world = Mat4::from_mat3(rt * flip) * Mat4::IDENTITY;
        let world = Mat4::from_cols(world.x_axis, world.y_axis, world.z_axis, center.extend(1.0));
        let name = t[9..].join(" ");
        let stem = Path::new(&name)
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_else(|| name.clone());
        let candidates = [
            dir.join("..").join("..").join("images").join(&name),
            dir.join("images").join(&name),
            dir.join(&name),
        ];
        let image = candidates
            .iter()
            .find(|p| p.is_file())
            .cloned()
            .or_else(|| Some(candidates[0].clone()));
        out.push(Frame {
            camera: Camera::with_intrinsics(&stem, world, k),
            image,
        });
        i += 2;
    }
    // COLMAP lists images in any order; sort by name so that frame N is stable.
    out.sort_by(|a, b| a.camera.name.cmp(&b.camera.name));
    Ok(out)
}
