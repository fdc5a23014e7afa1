//! glTF 2.0 loading (`.gltf` and `.glb`) into a world-space [`Scene`]: the reader of one
//! format, node hierarchy to lights and images (meshes in `load/mesh.rs`).
//!
//! External files are read only from the scene's folder and below: absolute paths, `..` and
//! URIs with a scheme other than `data:` are refused.
use super::files::{percent_decode, read_file, read_uri};
use super::{
    in_bounds, Camera, Material, PunctualKind, PunctualLight, Scene, TextureSlot, Wrap, MAX_COORD,
};
use crate::{Error, Result};
use glam::{Mat4, Vec3, Vec4};
use std::collections::HashMap;
use std::f32::consts::PI;
use std::path::{Path, PathBuf};

mod mesh;
/// Most triangles psrestir loads.
pub const MAX_TRIANGLES: usize = 64 << 20;

/// Load a `.gltf` or `.glb` file.
pub fn load(path: &Path) -> Result<Scene> {
    let bytes = read_file(path)?;
    crate::error::catch_panic(path, "the glTF reader", || load_bytes(path, &bytes))
}

fn load_bytes(path: &Path, bytes: &[u8]) -> Result<Scene> {
    let json: Option<serde_json::Value> = if bytes.starts_with(b"glTF") {
        gltf::binary::Glb::from_slice(bytes)
            .ok()
            .and_then(|glb| serde_json::from_slice(&glb.json).ok())
    } else {
        serde_json::from_slice(bytes).ok()
    };
    if let Some(json) = &json {
        precheck(json).map_err(|msg| Error::file(path, format!("invalid glTF: {msg}")))?;
    }
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| gltf_error(path, e))?;
    let base = path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let mut loader = Loader {
        path,
        base: &base,
        doc: &gltf.document,
        blob: gltf.blob.as_deref(),
        buffers: Vec::new(),
        scene: Scene {
            source: path.to_path_buf(),
            ..Default::default()
        },
        image_map: HashMap::new(),
        default_material: None,
    };
    loader.load_buffers()?;
    loader.load_materials()?;
    loader.load_nodes()?;
    for w in &loader.scene.warnings {
        log::warn!("{}: {w}", path.display());
    }
    Ok(loader.scene)
}

/// Checks of the JSON that the gltf crate's validation does not make and without which it
/// panics or misreads data (each found by fuzzing; the inputs are in
/// `tests/fuzz_regressions/`): accessor references of primitives in range, the accessor
/// types the specification requires for the attributes psrestir reads, and images in buffer
/// views with a MIME type.
fn precheck(json: &serde_json::Value) -> std::result::Result<(), String> {
    use serde_json::Value;
    let empty = Vec::new();
    let accessors = json["accessors"].as_array().unwrap_or(&empty);
    let n_views = json["bufferViews"].as_array().map_or(0, Vec::len);
    for (mi, mesh) in json["meshes"]
        .as_array()
        .unwrap_or(&empty)
        .iter()
        .enumerate()
    {
        for (pi, prim) in mesh["primitives"]
            .as_array()
            .unwrap_or(&empty)
            .iter()
            .enumerate()
        {
            let what = format!("mesh {mi} primitive {pi}");
            let mut refs: Vec<(String, &Value)> = Vec::new();
            if let Some(a) = prim["attributes"].as_object() {
                refs.extend(a.iter().map(|(k, v)| (k.clone(), v)));
            }
            for (t, target) in prim["targets"]
                .as_array()
                .unwrap_or(&empty)
                .iter()
                .enumerate()
            {
                if let Some(a) = target.as_object() {
                    refs.extend(a.iter().map(|(k, v)| (format!("target {t} {k}"), v)));
                }
            }
            if !prim["indices"].is_null() {
                refs.push(("indices".into(), &prim["indices"]));
            }
            for (name, v) in refs {
                let Some(acc) = v.as_u64().and_then(|i| accessors.get(i as usize)) else {
                    return Err(format!(
                        "{what}: {name} refers to accessor {v}, the file has {}",
                        accessors.len()
                    ));
                };
                let ty = acc["type"].as_str().unwrap_or("");
                let ct = acc["componentType"].as_u64().unwrap_or(0);
                let ok = match name.as_str() {
                    "POSITION" | "NORMAL" => ty == "VEC3" && ct == 5126,
                    "TEXCOORD_0" => ty == "VEC2" && matches!(ct, 5121 | 5123 | 5126),
                    "indices" => ty == "SCALAR" && matches!(ct, 5121 | 5123 | 5125),
                    _ => true,
                };
                if !ok {
                    return Err(format!(
                        "{what}: {name} accessor is {ty} of component type {ct}, which the \
                         glTF specification does not allow there"
                    ));
                }
            }
        }
    }
    for (i, img) in json["images"]
        .as_array()
        .unwrap_or(&empty)
        .iter()
        .enumerate()
    {
        match (img["bufferView"].as_u64(), img["uri"].is_string()) {
            (Some(v), false) => {
                if v as usize >= n_views {
                    return Err(format!("image {i} refers to buffer view {v} of {n_views}"));
                }
                if !img["mimeType"].is_string() {
                    return Err(format!("image {i} is in a buffer view but has no mimeType"));
                }
            }
            (None, true) => {}
            _ => return Err(format!("image {i} needs exactly one of uri and bufferView")),
        }
    }
    Ok(())
}

fn gltf_error(path: &Path, e: gltf::Error) -> Error {
    let msg = match e {
        gltf::Error::Validation(errs) => {
            let list: Vec<String> = errs
                .iter()
                .take(5)
                .map(|(p, err)| format!("{}: {err}", p.as_str()))
                .collect();
            format!("invalid glTF: {}", list.join("; "))
        }
        gltf::Error::Deserialize(e) => format!("malformed glTF JSON: {e}"),
        gltf::Error::Binary(e) => format!("malformed GLB: {e:?}"),
        other => format!("cannot read glTF: {other}"),
    };
    Error::file(path, msg)
}

/// The parts of a glTF file as stored: its JSON, every buffer's bytes, and the bytes of every
/// image stored by URI (None for images in buffer views). Used to write the scene back out.
#[allow(clippy::type_complexity)]
pub fn load_source(path: &Path) -> Result<(serde_json::Value, Vec<Vec<u8>>, Vec<Option<Vec<u8>>>)> {
    let bytes = read_file(path)?;
    let (json, blob): (serde_json::Value, Option<Vec<u8>>) = if bytes.starts_with(b"glTF") {
        let glb = gltf::binary::Glb::from_slice(&bytes).map_err(|e| gltf_error(path, e))?;
        let json = serde_json::from_slice(&glb.json)
            .map_err(|e| Error::file(path, format!("malformed glTF JSON: {e}")))?;
        (json, glb.bin.map(|b| b.into_owned()))
    } else {
        (
            serde_json::from_slice(&bytes)
                .map_err(|e| Error::file(path, format!("malformed glTF JSON: {e}")))?,
            None,
        )
    };
    let base = path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let mut buffers = Vec::new();
    for (i, b) in json["buffers"].as_array().into_iter().flatten().enumerate() {
        let what = format!("buffer {i}");
        buffers.push(match b["uri"].as_str() {
            Some(uri) => read_uri(path, &base, uri, &what)?,
            None => blob
                .clone()
                .ok_or_else(|| Error::file(path, format!("{what}: GLB binary chunk missing")))?,
        });
    }
    let mut images = Vec::new();
    for (i, img) in json["images"].as_array().into_iter().flatten().enumerate() {
        images.push(match img["uri"].as_str() {
            Some(uri) => Some(read_uri(path, &base, uri, &format!("image {i}"))?),
            None => None,
        });
    }
    Ok((json, buffers, images))
}

struct Loader<'a> {
    path: &'a Path,
    base: &'a Path,
    doc: &'a gltf::Document,
    blob: Option<&'a [u8]>,
    buffers: Vec<Vec<u8>>,
    scene: Scene,
    image_map: HashMap<usize, usize>,
    default_material: Option<u32>,
}

impl<'a> Loader<'a> {
    fn err(&self, msg: impl Into<String>) -> Error {
        Error::file(self.path, msg)
    }

    fn read_uri(&self, uri: &str, what: &str) -> Result<Vec<u8>> {
        read_uri(self.path, self.base, uri, what)
    }

    fn load_buffers(&mut self) -> Result<()> {
        for b in self.doc.buffers() {
            let what = format!("buffer {}", b.index());
            let data = match b.source() {
                gltf::buffer::Source::Bin => self
                    .blob
                    .ok_or_else(|| {
                        self.err(format!(
                            "{what} refers to a GLB binary chunk that is missing"
                        ))
                    })?
                    .to_vec(),
                gltf::buffer::Source::Uri(uri) => self.read_uri(uri, &what)?,
            };
            if data.len() < b.length() {
                return Err(self.err(format!(
                    "{what} declares {} bytes but holds {}",
                    b.length(),
                    data.len()
                )));
            }
            self.buffers.push(data);
        }
        Ok(())
    }

    fn image(&mut self, img: gltf::Image) -> Result<usize> {
        if let Some(&i) = self.image_map.get(&img.index()) {
            return Ok(i);
        }
        let name = img
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("image {}", img.index()));
        let (bytes, what) = match img.source() {
            gltf::image::Source::View { view, .. } => {
                let buf = &self.buffers[view.buffer().index()];
                let end = view.offset() + view.length();
                if end > buf.len() {
                    return Err(self.err(format!("image `{name}`: buffer view out of range")));
                }
                (buf[view.offset()..end].to_vec(), format!("image `{name}`"))
            }
            gltf::image::Source::Uri { uri, .. } => {
                let what = if uri.starts_with("data:") {
                    format!("image `{name}`")
                } else {
                    format!(
                        "image `{name}` ({})",
                        self.base.join(percent_decode(uri)).display()
                    )
                };
                (self.read_uri(uri, &format!("image `{name}`"))?, what)
            }
        };
        let decoded = crate::image_io::decode::decode_texture(&bytes, self.path, &what, &name)?;
        self.scene.images.push(decoded);
        let i = self.scene.images.len() - 1;
        self.image_map.insert(img.index(), i);
        Ok(i)
    }

    fn slot(
        &mut self,
        tex: gltf::Texture,
        xf: Option<gltf::texture::TextureTransform>,
    ) -> Result<TextureSlot> {
        let sampler = tex.sampler();
        let wrap = |w: gltf::texture::WrappingMode| match w {
            gltf::texture::WrappingMode::ClampToEdge => Wrap::Clamp,
            gltf::texture::WrappingMode::MirroredRepeat => Wrap::Mirror,
            gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
        };
        let mut transform = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        if let Some(t) = xf {
            let [ox, oy] = t.offset();
            let [sx, sy] = t.scale();
            let (s, c) = t.rotation().sin_cos();
            // KHR_texture_transform: T * R * S with R = [[c, -s], [s, c]] (GLSL column order
            // cos, sin / -sin, cos).
            transform = [[c * sx, -s * sy, ox], [s * sx, c * sy, oy]];
        }
        Ok(TextureSlot {
            image: self.image(tex.source())?,
            wrap_s: wrap(sampler.wrap_s()),
            wrap_t: wrap(sampler.wrap_t()),
            nearest: matches!(
                sampler.mag_filter(),
                Some(gltf::texture::MagFilter::Nearest)
            ),
            transform,
        })
    }

    fn load_materials(&mut self) -> Result<()> {
        let doc = self.doc;
        for m in doc.materials() {
            let pbr = m.pbr_metallic_roughness();
            let name = m
                .name()
                .map(str::to_string)
                .unwrap_or_else(|| format!("material {}", m.index().unwrap_or(0)));
            // Every texture is read with TEXCOORD_0; a texture that names another set is
            // read with it all the same, with a warning.
            let sets = [
                (
                    "baseColorTexture",
                    pbr.base_color_texture().map(|i| i.tex_coord()),
                ),
                (
                    "metallicRoughnessTexture",
                    pbr.metallic_roughness_texture().map(|i| i.tex_coord()),
                ),
                (
                    "emissiveTexture",
                    m.emissive_texture().map(|i| i.tex_coord()),
                ),
                ("normalTexture", m.normal_texture().map(|i| i.tex_coord())),
            ];
            for (slot, set) in sets {
                if let Some(k) = set.filter(|&k| k != 0) {
                    self.scene.warnings.push(format!(
                        "material `{name}`: {slot} uses TEXCOORD_{k}, which psrestir does not \
                         read: it is read with TEXCOORD_0"
                    ));
                }
            }
            let base_color_texture = match pbr.base_color_texture() {
                Some(info) => Some(self.slot(info.texture(), info.texture_transform())?),
                None => None,
            };
            let metallic_roughness_texture = match pbr.metallic_roughness_texture() {
                Some(info) => Some(self.slot(info.texture(), info.texture_transform())?),
                None => None,
            };
            let emissive_texture = match m.emissive_texture() {
                Some(info) => Some(self.slot(info.texture(), info.texture_transform())?),
                None => None,
            };
            let (normal_texture, normal_scale) = match m.normal_texture() {
                Some(info) => (Some(self.slot(info.texture(), None)?), info.scale()),
                None => (None, 1.0),
            };
            let strength = m.emissive_strength().unwrap_or(1.0);
            let mat = Material {
                name,
                base_color: Vec4::from(pbr.base_color_factor()),
                base_color_texture,
                metallic: pbr.metallic_factor(),
                roughness: pbr.roughness_factor(),
                metallic_roughness_texture,
                emissive: Vec3::from(m.emissive_factor()) * strength,
                emissive_texture,
                normal_texture,
                normal_scale,
                double_sided: m.double_sided(),
            };
            if !mat.factors_valid() {
                return Err(self.err(format!(
                    "material `{}` has non-finite or negative factors",
                    mat.name
                )));
            }
            self.scene.materials.push(mat);
        }
        Ok(())
    }

    fn material_index(&mut self, m: Option<usize>) -> u32 {
        if let Some(i) = m {
            return i as u32;
        }
        *self.default_material.get_or_insert_with(|| {
            self.scene.materials.push(Material::default());
            (self.scene.materials.len() - 1) as u32
        })
    }

    fn load_nodes(&mut self) -> Result<()> {
        let doc = self.doc;
        let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
            Some(s) => s.nodes().collect(),
            None => {
                // No scene: every node that is nobody's child is a root.
                let mut is_child = vec![false; doc.nodes().len()];
                for n in doc.nodes() {
                    for c in n.children() {
                        is_child[c.index()] = true;
                    }
                }
                doc.nodes().filter(|n| !is_child[n.index()]).collect()
            }
        };
        // Iterative walk; glTF validation rejects cycles, the depth bound guards the rest.
        let mut stack: Vec<(gltf::Node, Mat4, usize)> = roots
            .into_iter()
            .rev()
            .map(|n| (n, Mat4::IDENTITY, 0))
            .collect();
        let mut visits = 0usize;
        while let Some((node, parent, depth)) = stack.pop() {
            visits += 1;
            if depth > 256 || visits > 1 << 22 {
                return Err(self.err("node hierarchy too deep or cyclic"));
            }
            let local = Mat4::from_cols_array_2d(&node.transform().matrix());
            let world = parent * local;
            if !world.is_finite() {
                return Err(self.err(format!("node {} has a non-finite transform", node.index())));
            }
            if let Some(mesh) = node.mesh() {
                self.load_mesh(&mesh, world)?;
            }
            if let Some(cam) = node.camera() {
                self.load_camera(&cam, &node, world);
            }
            if let Some(light) = node.light() {
                self.load_light(&light, world)?;
            }
            // Reversed, so that nodes are visited in document order.
            let children: Vec<gltf::Node> = node.children().collect();
            for c in children.into_iter().rev() {
                stack.push((c, world, depth + 1));
            }
        }
        Ok(())
    }

    fn load_camera(&mut self, cam: &gltf::Camera, node: &gltf::Node, world: Mat4) {
        let name = cam
            .name()
            .or(node.name())
            .map(str::to_string)
            .unwrap_or_else(|| format!("camera {}", self.scene.cameras.len()));
        match cam.projection() {
            gltf::camera::Projection::Perspective(p) => {
                if !Camera::projection_valid(p.yfov(), p.aspect_ratio()) {
                    self.scene.warnings.push(format!(
                        "camera `{name}` has a field of view outside (0, pi) or a \
                         non-positive aspect ratio, skipped"
                    ));
                    return;
                }
                self.scene.cameras.push(Camera {
                    name,
                    world,
                    yfov: p.yfov(),
                    aspect: p.aspect_ratio(),
                    intrinsics: None,
                    lights: None,
                })
            }
            gltf::camera::Projection::Orthographic(_) => self.scene.warnings.push(format!(
                "camera `{name}` is orthographic, skipped (perspective only)"
            )),
        }
    }

    fn load_light(&mut self, light: &gltf::khr_lights_punctual::Light, world: Mat4) -> Result<()> {
        use gltf::khr_lights_punctual::Kind;
        let name = light
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("light {}", light.index()));
        let kind = match light.kind() {
            Kind::Point => PunctualKind::Point,
            Kind::Directional => PunctualKind::Directional,
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => PunctualKind::Spot {
                inner_cone: inner_cone_angle,
                outer_cone: outer_cone_angle,
            },
        };
        let intensity = Vec3::from(light.color()) * light.intensity();
        if !intensity.is_finite() || intensity.min_element() < 0.0 {
            return Err(self.err(format!(
                "light `{name}` has a negative or non-finite intensity"
            )));
        }
        if let PunctualKind::Spot {
            inner_cone,
            outer_cone,
        } = kind
        {
            // glTF: 0 <= inner < outer <= pi/2.
            if !(0.0..PI / 2.0 + 1e-6).contains(&outer_cone)
                || !(0.0..=outer_cone).contains(&inner_cone)
            {
                return Err(self.err(format!(
                    "spot light `{name}`: cone angles must satisfy 0 <= inner ({inner_cone}) \
                     <= outer ({outer_cone}) <= pi/2"
                )));
            }
        }
        let position = world.transform_point3(Vec3::ZERO);
        if !in_bounds(position) {
            return Err(self.err(format!("light `{name}` is placed beyond ±{MAX_COORD:e}")));
        }
        self.scene.lights.push(PunctualLight {
            name,
            kind,
            position,
            direction: world
                .transform_vector3(Vec3::NEG_Z)
                .normalize_or(Vec3::NEG_Z),
            intensity,
            range: light.range().unwrap_or(0.0).max(0.0),
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::percent_decode;

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("my%20tex.png"), "my tex.png");
        assert_eq!(percent_decode("a%2"), "a%2");
        assert_eq!(percent_decode("%2e%2e/x"), "../x");
    }
}
