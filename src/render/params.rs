//! Optimized textures ("parameter textures"): the values the optimizer changes, laid out as on
//! the GPU (all textures in one float array, `channels` floats per texel, row-major).
use crate::scene::{Material, Scene};
use crate::vocab::{Filter, Slot, TextureSpec};
use crate::{Error, Result};

/// One optimized texture.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamTexture {
    /// Material index in the scene.
    pub material: u32,
    /// Material name.
    pub material_name: String,
    /// Which input it replaces.
    pub slot: Slot,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Lookup filter.
    pub filter: Filter,
    /// First float in [`ParamSet::values`].
    pub offset: u32,
    /// Learning rate (None: the step's default for the slot, `optim::StepKind::learning_rate`).
    pub learning_rate: Option<f32>,
}

impl ParamTexture {
    /// Floats per texel.
    pub fn channels(&self) -> u32 {
        self.slot.channels()
    }
    /// Number of floats.
    pub fn len(&self) -> usize {
        (self.width * self.height * self.channels()) as usize
    }
    /// Whether the texture has no texels (never, for a checked task).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// `material_slot`, for file names.
    pub fn name(&self) -> String {
        format!(
            "{}_{}",
            crate::image_io::file_safe(&self.material_name),
            self.slot.name()
        )
    }
}

/// The optimized textures' values on the GPU: group 0, bindings 9 (`params`, current) and 10
/// (`params_prev`, the previous iteration's) of every tracing pass. Whoever changes them
/// owns them (the optimizer); the renderer only binds them.
pub struct ParamBuffers {
    /// The current values (Adam writes them).
    pub values: wgpu::Buffer,
    /// The values of the previous iteration (ReSTIR's merge and the control variate read
    /// them).
    pub previous: wgpu::Buffer,
}

impl ParamBuffers {
    /// Both buffers, holding `set.values`.
    pub fn new(gpu: &crate::gpu::Gpu, set: &ParamSet) -> ParamBuffers {
        let usage = wgpu::BufferUsages::COPY_SRC;
        ParamBuffers {
            values: gpu.storage("params", bytemuck::cast_slice(&set.values), usage),
            previous: gpu.storage("params_prev", bytemuck::cast_slice(&set.values), usage),
        }
    }

    /// Record the copy that makes the current values the previous ones.
    pub fn encode_copy_to_previous(&self, enc: &mut wgpu::CommandEncoder) {
        enc.copy_buffer_to_buffer(&self.values, 0, &self.previous, 0, self.values.size());
    }
}

/// All optimized textures and their current values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamSet {
    /// The textures.
    pub textures: Vec<ParamTexture>,
    /// Their values, concatenated.
    pub values: Vec<f32>,
}

impl ParamSet {
    /// `values` (laid out like [`ParamSet::values`]) as a renderer sees them: each normal-map
    /// texel re-encoded from the unit normal it stands for ([`crate::vocab::decode_normal`];
    /// its length, which the renderer and glTF viewers normalize away, dropped), the other
    /// textures as they are. Errors of a normal map count its directions alone.
    pub fn as_seen<'a>(&self, values: &'a [f32]) -> std::borrow::Cow<'a, [f32]> {
        let normals = self
            .textures
            .iter()
            .filter(|t| t.slot == crate::vocab::Slot::Normal);
        let mut out = std::borrow::Cow::Borrowed(values);
        for t in normals {
            let v = out.to_mut();
            let start = t.offset as usize;
            let end = (start + 3 * (t.width * t.height) as usize).min(v.len());
            for c in v[start..end].chunks_exact_mut(3) {
                let n = crate::vocab::decode_normal([c[0], c[1], c[2]]);
                for k in 0..3 {
                    c[k] = 0.5 + 0.5 * n[k];
                }
            }
        }
        out
    }

    /// Textures as the task asks, at their initial values. Materials are found by name in
    /// `scene`; `task_path` names the task in errors.
    pub fn from_specs(
        scene: &Scene,
        specs: &[TextureSpec],
        filter: Filter,
        task_path: &std::path::Path,
    ) -> Result<ParamSet> {
        let mut set = ParamSet::default();
        for (i, spec) in specs.iter().enumerate() {
            let material = scene
                .materials
                .iter()
                .position(|m: &Material| m.name == spec.material)
                .ok_or_else(|| {
                    let names: Vec<&str> =
                        scene.materials.iter().map(|m| m.name.as_str()).collect();
                    Error::file(
                        task_path,
                        format!(
                            "`textures[{i}].material`: no material `{}` in {}; it has {}",
                            spec.material,
                            scene.source.display(),
                            names.join(", ")
                        ),
                    )
                })?;
            let tex = ParamTexture {
                material: material as u32,
                material_name: spec.material.clone(),
                slot: spec.slot,
                width: spec.resolution[0],
                height: spec.resolution[1],
                filter,
                offset: set.values.len() as u32,
                learning_rate: spec.learning_rate,
            };
            let init = spec.init_values();
            for _ in 0..tex.width * tex.height {
                set.values.extend_from_slice(&init);
            }
            set.textures.push(tex);
        }
        Ok(set)
    }

    /// The values of texture `i`.
    pub fn values_of(&self, i: usize) -> &[f32] {
        let t = &self.textures[i];
        &self.values[t.offset as usize..t.offset as usize + t.len()]
    }

    /// The first optimized texture replacing `slot` of any material, if any.
    pub fn find_slot(&self, slot: Slot) -> Option<usize> {
        self.textures.iter().position(|t| t.slot == slot)
    }

    /// The optimized texture replacing `slot` of `material`, if any.
    pub fn find(&self, material: u32, slot: Slot) -> Option<usize> {
        self.textures
            .iter()
            .position(|t| t.material == material && t.slot == slot)
    }

    /// What the slot holds in a reference scene (e.g. the ground truth), sampled at the
    /// centres of texture `i`'s texels with the same UV convention (UV0, no transform).
    pub fn reference_values(&self, i: usize, reference: &Scene) -> Option<Vec<f32>> {
        let t = &self.textures[i];
        let m = reference
            .materials
            .iter()
            .find(|m| m.name == t.material_name)?;
        Some(slot_values(reference, m, t.slot, t.width, t.height))
    }
}

/// What `slot` of material `m` holds (factor x texture, linear), sampled at the centres of a
/// `width` x `height` grid over UV0.
pub fn slot_values(scene: &Scene, m: &Material, slot: Slot, width: u32, height: u32) -> Vec<f32> {
    let mut out = Vec::with_capacity((width * height * slot.channels()) as usize);
    for y in 0..height {
        for x in 0..width {
            let uv = [
                (x as f32 + 0.5) / width as f32,
                (y as f32 + 0.5) / height as f32,
            ];
            let sample = |tex: &Option<crate::scene::TextureSlot>, srgb: bool| -> [f32; 4] {
                match tex {
                    None => [1.0; 4],
                    Some(s) => {
                        crate::scene::images::sample_bilinear(&scene.images[s.image], s, uv, srgb)
                    }
                }
            };
            match slot {
                Slot::BaseColor => {
                    let c = sample(&m.base_color_texture, true);
                    out.extend_from_slice(&[
                        m.base_color.x * c[0],
                        m.base_color.y * c[1],
                        m.base_color.z * c[2],
                    ]);
                }
                Slot::Roughness => out.push(
                    (m.roughness * sample(&m.metallic_roughness_texture, false)[1]).clamp(0.0, 1.0),
                ),
                Slot::Metallic => out.push(
                    (m.metallic * sample(&m.metallic_roughness_texture, false)[2]).clamp(0.0, 1.0),
                ),
                // The map's RGB as stored (its scale not applied); flat without one.
                Slot::Normal => match &m.normal_texture {
                    None => out.extend_from_slice(&[0.5, 0.5, 1.0]),
                    Some(_) => out.extend_from_slice(&sample(&m.normal_texture, false)[..3]),
                },
            }
        }
    }
    out
}
