//! Writing glTF files from code: used by the tests (which build their scenes by hand) and by
//! the generator of the bundled scenes (`psrestir make-scenes`).
use crate::{Error, Result};
use base64::Engine;
use serde_json::{json, Value};
use std::path::Path;

/// A glTF document under construction: JSON plus one binary buffer.
#[derive(Clone, Debug)]
pub struct GltfBuilder {
    /// The JSON document; edit freely for cases the helpers do not cover.
    pub json: Value,
    /// The binary buffer (buffer 0).
    pub bin: Vec<u8>,
}

impl Default for GltfBuilder {
    fn default() -> Self {
        Self::new()
    }
}

fn push(json: &mut Value, key: &str, v: Value) -> usize {
    let arr = json
        .as_object_mut()
        .expect("glTF root is an object")
        .entry(key)
        .or_insert_with(|| json!([]));
    let a = arr.as_array_mut().expect("glTF arrays are arrays");
    a.push(v);
    a.len() - 1
}

impl GltfBuilder {
    /// An empty glTF 2.0 document.
    pub fn new() -> Self {
        GltfBuilder {
            json: json!({"asset": {"version": "2.0", "generator": "psrestir"}}),
            bin: Vec::new(),
        }
    }

    /// Append bytes (4-byte aligned) as a buffer view; returns its index.
    pub fn add_view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        let mut v = json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        push(&mut self.json, "bufferViews", v)
    }

    fn add_accessor_f32(&mut self, data: &[f32], comps: usize, ty: &str, minmax: bool) -> usize {
        let view = self.add_view(bytemuck::cast_slice(data), Some(34962));
        let count = data.len() / comps;
        let mut acc =
            json!({"bufferView": view, "componentType": 5126, "count": count, "type": ty});
        if minmax && count > 0 {
            let mut lo = vec![f32::INFINITY; comps];
            let mut hi = vec![f32::NEG_INFINITY; comps];
            for v in data.chunks_exact(comps) {
                for k in 0..comps {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        push(&mut self.json, "accessors", acc)
    }

    /// Add a mesh with one triangle primitive; returns the mesh index.
    pub fn add_mesh(
        &mut self,
        name: &str,
        positions: &[[f32; 3]],
        normals: Option<&[[f32; 3]]>,
        uvs: Option<&[[f32; 2]]>,
        indices: Option<&[u32]>,
        material: Option<usize>,
    ) -> usize {
        let pos = self.add_accessor_f32(bytemuck::cast_slice(positions), 3, "VEC3", true);
        let mut attrs = json!({"POSITION": pos});
        if let Some(n) = normals {
            attrs["NORMAL"] =
                json!(self.add_accessor_f32(bytemuck::cast_slice(n), 3, "VEC3", false));
        }
        if let Some(t) = uvs {
            attrs["TEXCOORD_0"] =
                json!(self.add_accessor_f32(bytemuck::cast_slice(t), 2, "VEC2", false));
        }
        let mut prim = json!({"attributes": attrs});
        if let Some(idx) = indices {
            let view = self.add_view(bytemuck::cast_slice(idx), Some(34963));
            let acc = push(
                &mut self.json,
                "accessors",
                json!({"bufferView": view, "componentType": 5125, "count": idx.len(), "type": "SCALAR"}),
            );
            prim["indices"] = json!(acc);
        }
        if let Some(m) = material {
            prim["material"] = json!(m);
        }
        push(
            &mut self.json,
            "meshes",
            json!({"name": name, "primitives": [prim]}),
        )
    }

    /// Add a material given as glTF JSON; returns its index.
    pub fn add_material(&mut self, m: Value) -> usize {
        push(&mut self.json, "materials", m)
    }

    /// Add an image stored in the binary buffer.
    pub fn add_image_embedded(&mut self, name: &str, bytes: &[u8], mime: &str) -> usize {
        let view = self.add_view(bytes, None);
        push(
            &mut self.json,
            "images",
            json!({"name": name, "bufferView": view, "mimeType": mime}),
        )
    }

    /// Add an image referenced by URI (a file beside the scene, or a data URI).
    pub fn add_image_uri(&mut self, name: &str, uri: &str) -> usize {
        push(&mut self.json, "images", json!({"name": name, "uri": uri}))
    }

    /// Add a sampler given as glTF JSON.
    pub fn add_sampler(&mut self, s: Value) -> usize {
        push(&mut self.json, "samplers", s)
    }

    /// Add a texture of `image` with an optional sampler.
    pub fn add_texture(&mut self, image: usize, sampler: Option<usize>) -> usize {
        let mut t = json!({"source": image});
        if let Some(s) = sampler {
            t["sampler"] = json!(s);
        }
        push(&mut self.json, "textures", t)
    }

    /// Add a node given as glTF JSON; returns its index.
    pub fn add_node(&mut self, n: Value) -> usize {
        push(&mut self.json, "nodes", n)
    }

    /// Add a perspective camera; returns its index.
    pub fn add_camera(&mut self, name: &str, yfov: f32, aspect: Option<f32>) -> usize {
        let mut p = json!({"yfov": yfov, "znear": 0.01});
        if let Some(a) = aspect {
            p["aspectRatio"] = json!(a);
        }
        push(
            &mut self.json,
            "cameras",
            json!({"name": name, "type": "perspective", "perspective": p}),
        )
    }

    /// Add a KHR_lights_punctual light given as JSON; returns its index.
    pub fn add_light(&mut self, l: Value) -> usize {
        self.use_extension("KHR_lights_punctual");
        if !self.json.get("extensions").is_some_and(Value::is_object) {
            self.json["extensions"] = json!({});
        }
        if self.json["extensions"].get("KHR_lights_punctual").is_none() {
            self.json["extensions"]["KHR_lights_punctual"] = json!({"lights": []});
        }
        let lights = self.json["extensions"]["KHR_lights_punctual"]["lights"]
            .as_array_mut()
            .expect("lights array");
        lights.push(l);
        lights.len() - 1
    }

    /// Declare an extension as used.
    pub fn use_extension(&mut self, name: &str) {
        let used = self
            .json
            .as_object_mut()
            .expect("root object")
            .entry("extensionsUsed")
            .or_insert_with(|| json!([]));
        let a = used.as_array_mut().expect("extensionsUsed array");
        if !a.iter().any(|v| v == name) {
            a.push(json!(name));
        }
    }

    /// Set the default scene to these root nodes.
    pub fn set_scene(&mut self, roots: &[usize]) {
        self.json["scenes"] = json!([{"nodes": roots}]);
        self.json["scene"] = json!(0);
    }

    fn json_with_buffer(&self, uri: Option<String>) -> Value {
        let mut j = self.json.clone();
        if !self.bin.is_empty() {
            let mut b = json!({"byteLength": self.bin.len()});
            if let Some(u) = uri {
                b["uri"] = json!(u);
            }
            j["buffers"] = json!([b]);
        }
        j
    }

    /// Write `NAME.gltf`; the buffer goes to `NAME.bin` beside it, or inline as a data URI.
    pub fn write_gltf(&self, path: &Path, embed_buffer: bool) -> Result<()> {
        let uri = if embed_buffer {
            Some(format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&self.bin)
            ))
        } else {
            let bin_path = path.with_extension("bin");
            crate::image_io::write_atomic(&bin_path, &self.bin)?;
            Some(
                bin_path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            )
        };
        let text = serde_json::to_string_pretty(&self.json_with_buffer(uri))
            .map_err(|e| Error::file(path, e.to_string()))?;
        crate::image_io::write_atomic(path, text.as_bytes())
    }

    /// Write a binary `.glb` with the buffer as its BIN chunk.
    pub fn write_glb(&self, path: &Path) -> Result<()> {
        let json = serde_json::to_vec(&self.json_with_buffer(None))
            .map_err(|e| Error::file(path, e.to_string()))?;
        crate::image_io::write_atomic(path, &glb_bytes(&json, &self.bin))
    }
}

/// A GLB container of `json` and, when not empty, `bin` (chunks padded to 4 bytes).
pub fn glb_bytes(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut json = json.to_vec();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    out
}

/// Encode RGBA8 pixels as PNG bytes.
pub fn png_bytes(width: u32, height: u32, rgba: &[[u8; 4]]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    let img = image::RgbaImage::from_raw(width, height, bytemuck::cast_slice(rgba).to_vec())
        .ok_or_else(|| Error::Invalid("png_bytes: pixel count does not match the size".into()))?;
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .map_err(|e| Error::Invalid(format!("PNG encoding: {e}")))?;
    Ok(out)
}

/// Triangles of a UV sphere: (positions, normals, uvs, indices).
#[allow(clippy::type_complexity)]
pub fn uv_sphere(
    center: [f32; 3],
    radius: f32,
    segments: u32,
    rings: u32,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>) {
    let (mut p, mut n, mut t, mut idx) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for r in 0..=rings {
        let v = r as f32 / rings as f32;
        let theta = v * std::f32::consts::PI;
        for s in 0..=segments {
            let u = s as f32 / segments as f32;
            let phi = u * 2.0 * std::f32::consts::PI;
            let d = [
                theta.sin() * phi.cos(),
                theta.cos(),
                -theta.sin() * phi.sin(),
            ];
            p.push([
                center[0] + radius * d[0],
                center[1] + radius * d[1],
                center[2] + radius * d[2],
            ]);
            n.push(d);
            t.push([u, v]);
        }
    }
    let w = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let a = r * w + s;
            let b = a + w;
            if r != 0 {
                idx.extend_from_slice(&[a, b, a + 1]);
            }
            if r != rings - 1 {
                idx.extend_from_slice(&[a + 1, b, b + 1]);
            }
        }
    }
    (p, n, t, idx)
}

/// Triangles of a surface of revolution about +Y: `profile` is a list of (radius, height)
/// points, swept through `segments` steps. Normals point to the left of the direction of
/// travel along the profile in the (radius, height) plane (outward for a profile that goes
/// up on the outside), U runs around the axis and V along the profile by arc length.
/// Returns (positions, normals, uvs, indices), triangles wound counter-clockwise about the
/// normals.
#[allow(clippy::type_complexity)]
pub fn lathe(
    profile: &[[f32; 2]],
    segments: u32,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>) {
    let (mut p, mut n, mut t, mut idx) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let m = profile.len();
    let mut arc = vec![0f32; m];
    for i in 1..m {
        let d = [
            profile[i][0] - profile[i - 1][0],
            profile[i][1] - profile[i - 1][1],
        ];
        arc[i] = arc[i - 1] + (d[0] * d[0] + d[1] * d[1]).sqrt();
    }
    let total = arc[m - 1].max(1e-12);
    for (i, &[r, y]) in profile.iter().enumerate() {
        let a = profile[i.saturating_sub(1)];
        let b = profile[(i + 1).min(m - 1)];
        let (dr, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = (dr * dr + dy * dy).sqrt().max(1e-12);
        let (nr, ny) = (dy / len, -dr / len);
        for s in 0..=segments {
            let u = s as f32 / segments as f32;
            let phi = u * 2.0 * std::f32::consts::PI;
            let (c, sn) = (phi.cos(), -phi.sin());
            p.push([r * c, y, r * sn]);
            n.push([nr * c, ny, nr * sn]);
            t.push([u, arc[i] / total]);
        }
    }
    let w = segments + 1;
    for i in 0..m as u32 - 1 {
        for s in 0..segments {
            let a = i * w + s;
            let b = a + w;
            for tri in [[a, a + 1, b], [a + 1, b + 1, b]] {
                // Wind counter-clockwise about the mean normal (skip degenerate triangles).
                let [v0, v1, v2] = tri.map(|k| glam::Vec3::from(p[k as usize]));
                let cross = (v1 - v0).cross(v2 - v0);
                if cross.length_squared() < 1e-14 {
                    continue;
                }
                let nm: glam::Vec3 = tri.iter().map(|&k| glam::Vec3::from(n[k as usize])).sum();
                if cross.dot(nm) >= 0.0 {
                    idx.extend_from_slice(&tri);
                } else {
                    idx.extend_from_slice(&[tri[0], tri[2], tri[1]]);
                }
            }
        }
    }
    (p, n, t, idx)
}

/// A square of side `size` centred at `center`, facing `toward` (its front side, counter-
/// clockwise, looks at that point): (positions, normals, indices).
#[allow(clippy::type_complexity)]
pub fn quad_facing(
    center: [f32; 3],
    toward: [f32; 3],
    size: f32,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<u32>) {
    let c = glam::Vec3::from(center);
    let f = (glam::Vec3::from(toward) - c).normalize();
    let helper = if f.y.abs() > 0.9 {
        glam::Vec3::X
    } else {
        glam::Vec3::Y
    };
    let u = helper.cross(f).normalize() * 0.5 * size;
    let v = f.cross(u);
    let p = [c - u - v, c + u - v, c + u + v, c - u + v].map(|q| q.to_array());
    (p.to_vec(), vec![f.to_array(); 4], vec![0, 1, 2, 0, 2, 3])
}

/// Triangles (non-indexed, no normals: flat normals come from the loader) of an axis-aligned
/// box, wound counter-clockwise seen from outside.
pub fn box_triangles(center: [f32; 3], half: [f32; 3]) -> Vec<[f32; 3]> {
    let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
        ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
        ([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
        ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]),
        ([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
    ];
    let (c, h) = (glam::Vec3::from(center), glam::Vec3::from(half));
    let mut out = Vec::with_capacity(36);
    for (nrm, u, v) in faces {
        let (nrm, u, v) = (
            glam::Vec3::from(nrm),
            glam::Vec3::from(u),
            glam::Vec3::from(v),
        );
        let q = |a: f32, b: f32| (c + h * (nrm + a * u + b * v)).to_array();
        // Counter-clockwise seen from outside: u x v = n.
        out.extend_from_slice(&[q(-1.0, -1.0), q(1.0, -1.0), q(1.0, 1.0)]);
        out.extend_from_slice(&[q(-1.0, -1.0), q(1.0, 1.0), q(-1.0, 1.0)]);
    }
    out
}
