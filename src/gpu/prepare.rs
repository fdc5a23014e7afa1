//! Pipelines compiled when they are created, not at their first dispatch, and the time that
//! takes, recorded per pass.
//!
//! lavapipe (Mesa's CPU Vulkan driver) turns a compute shader into machine code at the first
//! dispatch that uses it, not in `vkCreateComputePipelines`: on the project's 2-core machine
//! the first iteration of the default task took 20.6 s instead of 0.1 s, inside the
//! optimization's clock, and every equal-time figure taken on a cold shader cache was off by
//! that much. [`Gpu::compute_pipeline_in`] therefore dispatches every new pipeline once with zero
//! workgroups, on placeholder resources of the layout reflected from its WGSL: the driver
//! compiles it (or loads it from Mesa's shader cache) and runs nothing. On a GPU, whose
//! driver compiles at creation, this costs one empty submission per pipeline.
use super::made::PipelineTime;
use super::{shaders::Library, Binding, Gpu};
use crate::Result;
use std::time::Instant;

/// Placeholder buffer size: enough for any uniform block and the fixed part of any storage
/// binding of the passes (wgpu checks a binding's size against the shader's even when no
/// workgroup runs).
const PLACEHOLDER_BYTES: u64 = 1 << 16;

impl Gpu {
    /// Every pipeline this device has been asked for so far, with the seconds each took, in
    /// order (one it had made before is reused: its seconds are those of the lookup).
    pub fn pipeline_times(&self) -> Vec<PipelineTime> {
        self.pipelines.lock().map(|v| v.clone()).unwrap_or_default()
    }

    /// Pipelines this device created since `since` entries of [`Gpu::pipeline_times`] and
    /// the seconds it spent on them (a second device's work ahead, done beside it, is not
    /// counted).
    pub fn pipeline_seconds_since(&self, since: usize) -> (usize, f64) {
        let all = self.pipeline_times();
        let new: Vec<&PipelineTime> = all
            .get(since..)
            .unwrap_or_default()
            .iter()
            .filter(|p| !p.ahead)
            .collect();
        (new.len(), new.iter().map(|p| p.seconds).sum())
    }

    /// The pipeline this device made from `source` with `layouts`, if any.
    pub(super) fn made_pipeline(
        &self,
        source: &str,
        layouts: &[&wgpu::BindGroupLayout],
    ) -> Option<wgpu::ComputePipeline> {
        let made = self.made.lock().ok()?;
        made.pipelines.get(source)?.iter().find_map(|(l, p)| {
            (l.len() == layouts.len() && l.iter().zip(layouts).all(|(a, b)| a == *b))
                .then(|| p.clone())
        })
    }

    pub(super) fn remember_pipeline(
        &self,
        source: String,
        layouts: &[&wgpu::BindGroupLayout],
        pipeline: &wgpu::ComputePipeline,
    ) {
        if let Ok(mut made) = self.made.lock() {
            let layouts = layouts.iter().map(|l| (*l).clone()).collect();
            made.pipelines
                .entry(source)
                .or_default()
                .push((layouts, pipeline.clone()));
        }
    }

    /// Whether this device has made a pipeline of `pass` (with any layouts).
    fn has_made(&self, library: &Library, pass: &str, off: &[&str]) -> bool {
        let Ok(source) = library.compose_without(pass, self.tracer, off) else {
            return false;
        };
        self.made
            .lock()
            .is_ok_and(|m| m.pipelines.contains_key(&source))
    }

    pub(super) fn record_pipeline(&self, pass: &str, start: Instant) {
        let seconds = start.elapsed().as_secs_f64();
        log::debug!("pipeline `{pass}` ready in {seconds:.2} s");
        if let Ok(mut v) = self.pipelines.lock() {
            v.push(PipelineTime {
                pass: pass.into(),
                seconds,
                ahead: self.compiles_ahead,
            });
        }
    }

    /// Dispatch `pipeline` of `pass` once with zero workgroups on placeholder resources, so
    /// that the driver compiles it now. A pass that binds an acceleration structure (ray
    /// queries, GPUs only, where creation compiles) is left alone.
    pub(super) fn compile_now(
        &self,
        library: &Library,
        pass: &str,
        pipeline: &wgpu::ComputePipeline,
        layouts: &[&wgpu::BindGroupLayout],
    ) -> Result<()> {
        let mut kinds = Vec::new();
        for g in 0..layouts.len() {
            kinds.push(library.bindings_for(pass, g as u32, self.tracer)?);
        }
        if kinds
            .iter()
            .flatten()
            .any(|(_, k)| *k == Binding::AccelerationStructure)
        {
            return Ok(());
        }
        let label = format!("{pass} placeholder");
        let resources: Vec<Vec<Placeholder>> = kinds
            .iter()
            .map(|group| {
                group
                    .iter()
                    .map(|(_, k)| self.placeholder(&label, *k))
                    .collect()
            })
            .collect();
        let groups: Vec<wgpu::BindGroup> = resources
            .iter()
            .zip(layouts)
            .map(|(group, layout)| {
                let entries: Vec<wgpu::BindGroupEntry> = group
                    .iter()
                    .enumerate()
                    .map(|(i, r)| wgpu::BindGroupEntry {
                        binding: i as u32,
                        resource: match r {
                            Placeholder::Buffer(b) => b.as_entire_binding(),
                            Placeholder::Texture(v) => wgpu::BindingResource::TextureView(v),
                        },
                    })
                    .collect();
                self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(&label),
                    layout,
                    entries: &entries,
                })
            })
            .collect();
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some(&label),
            });
        {
            let mut p = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(&label),
                timestamp_writes: None,
            });
            p.set_pipeline(pipeline);
            for (i, g) in groups.iter().enumerate() {
                p.set_bind_group(i as u32, g, &[]);
            }
            p.dispatch_workgroups(0, 1, 1);
        }
        self.queue.submit([enc.finish()]);
        self.wait(&label)
    }

    fn placeholder(&self, label: &str, kind: Binding) -> Placeholder {
        match kind {
            Binding::StorageTextureRgba32FloatWrite => {
                let t = self.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: 1,
                        height: 1,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::Rgba32Float,
                    usage: wgpu::TextureUsages::STORAGE_BINDING,
                    view_formats: &[],
                });
                Placeholder::Texture(t.create_view(&Default::default()))
            }
            _ => Placeholder::Buffer(self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: PLACEHOLDER_BYTES,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::UNIFORM,
                mapped_at_creation: false,
            })),
        }
    }
}

enum Placeholder {
    Buffer(wgpu::Buffer),
    Texture(wgpu::TextureView),
}

impl Gpu {
    /// Compile `passes` on a second device of the same adapter, on another thread, where this
    /// device's driver compiles at the first dispatch (a CPU driver: lavapipe compiles one
    /// pass at a time on its queue's thread) and keeps a shader cache: the second device's
    /// results land in the driver's cache, where this device's own creation of the same
    /// passes finds them. Join the handle before creating them here. `None` where it would
    /// not help: a GPU (creation compiles, in parallel already), or the cache switched off.
    /// The passes are composed with the modules `off` names in their `_off` form, as the
    /// passes over the task's scene will be.
    pub fn compile_elsewhere_in(
        &self,
        library: &'static Library,
        passes: &[&str],
        off: &'static [&'static str],
    ) -> Option<std::thread::JoinHandle<()>> {
        let cache_off = std::env::var("MESA_SHADER_CACHE_DISABLE")
            .is_ok_and(|v| matches!(v.as_str(), "1" | "true" | "TRUE" | "yes"));
        // Passes this device has made already need no compiling.
        let passes: Vec<String> = passes
            .iter()
            .filter(|p| !self.has_made(library, p, off))
            .map(|p| p.to_string())
            .collect();
        if self.info.device_type != wgpu::DeviceType::Cpu || cache_off || passes.is_empty() {
            return None;
        }
        let (tracer, name) = (self.tracer, self.info.name.clone());
        let record = self.pipelines.clone();
        let spawned = std::thread::Builder::new()
            .name("psrestir shader compilation".into())
            .spawn(move || {
                let mut helper = match Gpu::quiet(tracer) {
                    Ok(g) if g.info.name == name => g,
                    _ => return,
                };
                // Its pipelines are listed with this device's, marked as compiled ahead.
                helper.pipelines = record;
                helper.compiles_ahead = true;
                for pass in &passes {
                    let mut layouts = Vec::new();
                    for g in 0..4 {
                        match library.bindings_for(pass, g, tracer) {
                            Ok(b) if !b.is_empty() => {}
                            _ => break,
                        }
                        match helper.pass_layout_in(library, pass, g) {
                            Ok(l) => layouts.push(l),
                            Err(_) => return,
                        }
                    }
                    let refs: Vec<&wgpu::BindGroupLayout> = layouts.iter().collect();
                    if let Err(e) = helper.compute_pipeline_in_without(library, pass, &refs, off) {
                        log::debug!("compiling `{pass}` on a second device: {e}");
                        return;
                    }
                }
            });
        spawned.ok()
    }
}
