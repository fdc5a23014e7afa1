//! Bind groups by name: each pass's layouts reflected from its WGSL by naga
//! ([`Gpu::pass_layout_in`]), the groups declared beside the code that drives a pass
//! ([`GroupDecl`]) and bound by WGSL name ([`Gpu::bind`]).
use super::shaders::{Binding, Library};
use super::Gpu;
use crate::Result;

impl Gpu {
    /// The layout of bind group `group` of `pass`, reflected from its WGSL in `library`
    /// ([`Library::bindings`]): the only way the passes build their layouts. A layout this
    /// device already made for the same pass and bindings is returned again, so that the
    /// pipelines made with it are found again ([`Gpu::compute_pipeline_in`]).
    pub fn pass_layout_in(
        &self,
        library: &Library,
        pass: &str,
        group: u32,
    ) -> Result<wgpu::BindGroupLayout> {
        let kinds: Vec<Binding> = library
            .bindings_for(pass, group, self.tracer)?
            .into_iter()
            .map(|(_, k)| k)
            .collect();
        let key = (format!("{pass} group {group}"), kinds);
        let made = self.made.lock().ok();
        if let Some(layout) = made.and_then(|m| m.layouts.get(&key).cloned()) {
            return Ok(layout);
        }
        let layout = self.layout(&key.0, &key.1);
        if let Ok(mut m) = self.made.lock() {
            m.layouts.insert(key, layout.clone());
        }
        Ok(layout)
    }

    /// A bind group layout of buffers (and an acceleration structure), bindings numbered in
    /// order.
    fn layout(&self, label: &str, kinds: &[Binding]) -> wgpu::BindGroupLayout {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = kinds
            .iter()
            .enumerate()
            .map(|(i, k)| wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: match k {
                    Binding::AccelerationStructure => wgpu::BindingType::AccelerationStructure {
                        vertex_return: false,
                    },
                    Binding::StorageTextureRgba32FloatWrite => wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::Rgba32Float,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                    _ => wgpu::BindingType::Buffer {
                        ty: match k {
                            Binding::Uniform => wgpu::BufferBindingType::Uniform,
                            Binding::StorageRw => {
                                wgpu::BufferBindingType::Storage { read_only: false }
                            }
                            _ => wgpu::BufferBindingType::Storage { read_only: true },
                        },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                },
                count: None,
            })
            .collect();
        self.device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: &entries,
            })
    }

    /// A bind group of the group that `decl` declares, from whole buffers given by their
    /// WGSL names in any order. Every declared name must be given once, and nothing else:
    /// a mismatch is a bug in psrestir and panics naming the pass and both lists.
    pub fn bind(
        &self,
        decl: &GroupDecl,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        named: &[(&str, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let named: Vec<(&str, wgpu::BindingResource)> = named
            .iter()
            .map(|(n, b)| (*n, b.as_entire_binding()))
            .collect();
        self.bind_resources(decl, label, layout, &named)
    }

    /// [`Gpu::bind`] for any resources (texture views too).
    pub fn bind_resources(
        &self,
        decl: &GroupDecl,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        named: &[(&str, wgpu::BindingResource)],
    ) -> wgpu::BindGroup {
        let given: Vec<&str> = named.iter().map(|(n, _)| *n).collect();
        let mut sorted_given = given.clone();
        sorted_given.sort_unstable();
        let mut sorted_declared = decl.names.to_vec();
        sorted_declared.sort_unstable();
        assert!(
            sorted_given == sorted_declared,
            "{label}: group {} of pass `{}` binds {:?}, given {:?}",
            decl.group,
            decl.pass,
            decl.names,
            given
        );
        let entries: Vec<wgpu::BindGroupEntry> = decl
            .names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let (_, resource) = named.iter().find(|(m, _)| m == n).expect("checked above");
                wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: resource.clone(),
                }
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout,
            entries: &entries,
        })
    }

    /// A bind group binding whole buffers in order, then the acceleration structure if any.
    pub fn bind_group_with_tlas(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
        tlas: Option<&wgpu::Tlas>,
    ) -> wgpu::BindGroup {
        let mut entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        if let Some(t) = tlas {
            entries.push(wgpu::BindGroupEntry {
                binding: buffers.len() as u32,
                resource: t.as_binding(),
            });
        }
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout,
            entries: &entries,
        })
    }
}

/// The bindings of one bind group of a pass, by WGSL name in binding order, declared beside
/// the code that drives the pass. [`Gpu::bind`] binds buffers to them by name; a test checks
/// every declaration against naga's reflection of the pass's WGSL, without a GPU.
#[derive(Clone, Copy, Debug)]
pub struct GroupDecl {
    /// The pass (its WGSL file under `shaders/`).
    pub pass: &'static str,
    /// The bind group index.
    pub group: u32,
    /// Variable names in binding order.
    pub names: &'static [&'static str],
}
