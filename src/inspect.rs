//! The commands that print what psrestir or a file holds: `info` (a scene file),
//! `estimators` (every estimator, step and prior with its options) and `adapter` (the GPU).
use anyhow::Result;
use psrestir::gpu::Gpu;
use psrestir::scene;

/// `psrestir info`: what a scene file holds.
pub(crate) fn cmd_info(path: &std::path::Path) -> Result<()> {
    let sc = scene::load(path)?;
    println!("{}", path.display());
    println!("  triangles: {}", sc.triangles.len());
    println!("  materials: {}", sc.materials.len());
    for m in &sc.materials {
        println!(
            "    {}: base color {:?}{}, metallic {}, roughness {}{}, emissive {:?}{}",
            m.name,
            m.base_color.to_array(),
            if m.base_color_texture.is_some() {
                " x texture"
            } else {
                ""
            },
            m.metallic,
            m.roughness,
            if m.metallic_roughness_texture.is_some() {
                " x texture"
            } else {
                ""
            },
            m.emissive.to_array(),
            if m.double_sided { ", double-sided" } else { "" },
        );
    }
    println!("  images: {}", sc.images.len());
    for i in &sc.images {
        println!("    {}: {}x{}", i.name, i.width, i.height);
    }
    println!("  cameras: {}", sc.cameras.len());
    for (i, c) in sc.cameras.iter().enumerate() {
        println!("    {i}: {} (yfov {:.3} rad)", c.name, c.yfov);
    }
    println!("  punctual lights: {}", sc.lights.len());
    for l in &sc.lights {
        println!(
            "    {}: {:?}, intensity {:?}",
            l.name,
            l.kind,
            l.intensity.to_array()
        );
    }
    for w in &sc.warnings {
        println!("  warning: {w}");
    }
    Ok(())
}

/// `psrestir estimators`: each estimator with its options at their defaults.
pub(crate) fn cmd_estimators() {
    println!(
        "Gradient estimators (`--method`; auto, the default: {})\n",
        psrestir::optim::estimator::auto_rule()
    );
    for m in psrestir::optim::Method::all() {
        let toml = psrestir::optim::EstimatorOptions::defaults_toml(m);
        print_kind(m.name(), m.summary(), m.name(), &toml);
    }
    println!("Steps (`--step`; absent: auto's, by the task's light and samples)\n");
    for k in psrestir::optim::step::REGISTRY {
        let cpu = match k.cpu {
            Some(_) => "",
            None => " (textures only: the environment and the cameras' gains then take Adam)",
        };
        print_kind(
            k.name,
            &format!("{}{cpu}", k.summary),
            k.table,
            &table_text(k.options.defaults()),
        );
    }
    println!("Priors (each off at these defaults)\n");
    for k in psrestir::optim::prior::REGISTRY {
        let mut summary = k.summary.to_string();
        if let Some((short, option)) = k.shorthand {
            summary += &format!(" (`{short} = ...` sets `{option}`)");
        }
        print_kind(k.name, &summary, k.name, &table_text(k.options.defaults()));
    }
    println!(
        "Set one with --set optimizer.TABLE.OPTION=VALUE (for an estimator, also with \
         --estimator-option METHOD.OPTION=VALUE), or in the task file's table; docs/guide.md \
         says what each option does."
    );
}

/// A kind of estimator, step or prior for `psrestir estimators`: its name, what it does and
/// its task-file table at its defaults.
fn print_kind(name: &str, summary: &str, table: &str, defaults: &str) {
    println!("{name}: {summary}");
    if defaults.is_empty() {
        println!("  no options\n");
        return;
    }
    println!("  [optimizer.{table}]");
    for line in defaults.lines() {
        println!("  {line}");
    }
    println!();
}

/// A table of options as TOML text.
fn table_text(table: toml::Table) -> String {
    toml::to_string(&table).unwrap_or_default()
}

/// `psrestir adapter`: the device psrestir runs on and what it offers.
pub(crate) fn cmd_adapter() -> Result<()> {
    let gpu = Gpu::new()?;
    println!("{}", gpu.describe());
    println!("device type: {:?}", gpu.info.device_type);
    println!("timestamp queries: {}", gpu.timestamps);
    let l = gpu.device.limits();
    println!(
        "max storage buffer binding: {} MiB, storage buffers per stage: {}, workgroups per dimension: {}",
        l.max_storage_buffer_binding_size >> 20,
        l.max_storage_buffers_per_shader_stage,
        l.max_compute_workgroups_per_dimension
    );
    let offered = gpu
        .adapter_features
        .is_some_and(|f| f.contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY));
    println!(
        "hardware ray queries: {}",
        if offered { "offered" } else { "not offered" }
    );
    println!(
        "tracing with: {} (PSRESTIR_TRACER=software|ray-query|auto chooses)",
        match gpu.tracer {
            psrestir::gpu::Tracer::Software => "the software BVH (binned SAH, in WGSL)",
            psrestir::gpu::Tracer::RayQuery => "ray queries",
        }
    );
    Ok(())
}
