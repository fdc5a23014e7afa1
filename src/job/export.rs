//! The optimized scene as a self-contained `.glb`: the source scene with every buffer and
//! image embedded, and the optimized textures written into its materials.
use crate::assets::authoring::{png_bytes, GltfBuilder};
use crate::image_io::linear_to_srgb;
use crate::render::params::{slot_values, ParamSet, ParamTexture};
use crate::scene::Scene;
use crate::vocab::Slot;
use crate::{Error, Result};
use serde_json::{json, Value};
use std::path::Path;

fn mime(bytes: &[u8]) -> &'static str {
    if bytes.starts_with(b"\x89PNG") {
        "image/png"
    } else {
        "image/jpeg"
    }
}

fn resample(values: &[f32], w: u32, h: u32, nw: u32, nh: u32) -> Vec<f32> {
    if (w, h) == (nw, nh) {
        return values.to_vec();
    }
    let mut out = Vec::with_capacity((nw * nh) as usize);
    for y in 0..nh {
        for x in 0..nw {
            let sx = ((x as f32 + 0.5) / nw as f32 * w as f32) as u32;
            let sy = ((y as f32 + 0.5) / nh as f32 * h as f32) as u32;
            out.push(values[(sy.min(h - 1) * w + sx.min(w - 1)) as usize]);
        }
    }
    out
}

/// A builder holding the glTF `json` whose `buffers` are merged into one binary chunk,
/// with the images stored by URI (`image_bytes`) moved into it too.
fn single_buffer(
    mut json: Value,
    buffers: &[Vec<u8>],
    image_bytes: &[Option<Vec<u8>>],
) -> GltfBuilder {
    let mut b = GltfBuilder {
        json: Value::Null,
        bin: Vec::new(),
    };
    let mut base = Vec::new();
    for data in buffers {
        while b.bin.len() % 4 != 0 {
            b.bin.push(0);
        }
        base.push(b.bin.len());
        b.bin.extend_from_slice(data);
    }
    if let Some(views) = json["bufferViews"].as_array_mut() {
        for v in views {
            let old = v["buffer"].as_u64().unwrap_or(0) as usize;
            let off = v["byteOffset"].as_u64().unwrap_or(0) as usize;
            v["buffer"] = json!(0);
            v["byteOffset"] = json!(base.get(old).copied().unwrap_or(0) + off);
        }
    }
    if let Some(obj) = json.as_object_mut() {
        obj.remove("buffers");
    }
    b.json = json;
    // Images stored by URI move into the binary chunk.
    for (i, bytes) in image_bytes.iter().enumerate() {
        if let Some(bytes) = bytes {
            let view = b.add_view(bytes, None);
            let img = &mut b.json["images"][i];
            if let Some(o) = img.as_object_mut() {
                o.remove("uri");
            }
            img["bufferView"] = json!(view);
            img["mimeType"] = json!(mime(bytes));
        }
    }
    b
}

/// Texture `t` of `values` (three channels) embedded in `b` as an RGB8 PNG, each texel
/// encoded by `encode`; returns the glTF texture's index.
fn embed_rgb(
    b: &mut GltfBuilder,
    t: &ParamTexture,
    values: &[f32],
    sampler: usize,
    encode: impl Fn([f32; 3]) -> [u8; 3],
) -> Result<usize> {
    let v = &values[t.offset as usize..t.offset as usize + t.len()];
    let px: Vec<[u8; 4]> = v
        .chunks_exact(3)
        .map(|c| {
            let [r, g, bl] = encode([c[0], c[1], c[2]]);
            [r, g, bl, 255]
        })
        .collect();
    let img = b.add_image_embedded(
        &format!("{} optimized", t.name()),
        &png_bytes(t.width, t.height, &px)?,
        "image/png",
    );
    Ok(b.add_texture(img, Some(sampler)))
}

/// Write `out` (.glb): the scene at `source` with the textures of `set` set to `values`.
pub fn write_glb(
    source: &Path,
    out: &Path,
    scene: &Scene,
    set: &ParamSet,
    values: &[f32],
) -> Result<()> {
    let (json, buffers, image_bytes) = crate::scene::load_source(source)?;
    let mut b = single_buffer(json, &buffers, &image_bytes);
    let sampler = b
        .add_sampler(json!({"wrapS": 10497, "wrapT": 10497, "magFilter": 9729, "minFilter": 9729}));
    let n_json_materials = b.json["materials"].as_array().map(|a| a.len()).unwrap_or(0);
    let mut done_mr = Vec::new();
    for t in &set.textures {
        let m = t.material as usize;
        if m >= n_json_materials {
            log::warn!(
                "{}: material `{}` is not in the file; its texture is not exported",
                out.display(),
                t.material_name
            );
            continue;
        }
        let mat = &scene.materials[m];
        let values_of = |slot: Slot, w: u32, h: u32| -> Vec<f32> {
            match set.find(t.material, slot) {
                Some(i) => {
                    let o = &set.textures[i];
                    let v = &values[o.offset as usize..o.offset as usize + o.len()];
                    if o.channels() == 1 {
                        resample(v, o.width, o.height, w, h)
                    } else {
                        v.to_vec()
                    }
                }
                None => slot_values(scene, mat, slot, w, h),
            }
        };
        match t.slot {
            Slot::BaseColor => {
                let e = |x: f32| (linear_to_srgb(x) * 255.0 + 0.5) as u8;
                let tex = embed_rgb(&mut b, t, values, sampler, |c| c.map(e))?;
                let pbr = &mut b.json["materials"][m]["pbrMetallicRoughness"];
                let alpha = pbr["baseColorFactor"][3].as_f64().unwrap_or(1.0);
                pbr["baseColorFactor"] = json!([1.0, 1.0, 1.0, alpha]);
                pbr["baseColorTexture"] = json!({"index": tex});
            }
            Slot::Normal => {
                let e = |x: f32| ((x * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                let tex = embed_rgb(&mut b, t, values, sampler, |c| {
                    crate::vocab::decode_normal(c).map(e)
                })?;
                b.json["materials"][m]["normalTexture"] = json!({"index": tex});
            }
            Slot::Roughness | Slot::Metallic => {
                if done_mr.contains(&m) {
                    continue;
                }
                done_mr.push(m);
                // One metallicRoughness texture at the larger of the optimized resolutions.
                let (mut w, mut h) = (t.width, t.height);
                for o in set
                    .textures
                    .iter()
                    .filter(|o| o.material == t.material && o.channels() == 1)
                {
                    if o.width * o.height > w * h {
                        (w, h) = (o.width, o.height);
                    }
                }
                let rough = values_of(Slot::Roughness, w, h);
                let metal = values_of(Slot::Metallic, w, h);
                let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                let px: Vec<[u8; 4]> = rough
                    .iter()
                    .zip(&metal)
                    .map(|(r, mt)| [255, q(*r), q(*mt), 255])
                    .collect();
                let img = b.add_image_embedded(
                    &format!("{} optimized", t.material_name),
                    &png_bytes(w, h, &px)?,
                    "image/png",
                );
                let tex = b.add_texture(img, Some(sampler));
                let pbr = &mut b.json["materials"][m]["pbrMetallicRoughness"];
                pbr["metallicFactor"] = json!(1.0);
                pbr["roughnessFactor"] = json!(1.0);
                pbr["metallicRoughnessTexture"] = json!({"index": tex});
            }
        }
    }
    b.write_glb(out).map_err(|e| match e {
        Error::File { msg, .. } => Error::file(out, msg),
        other => other,
    })
}
