//! WGSL composition and validation.
//!
//! Each pass is one file under `shaders/`, named after the pass. A line `#import shared/NAME`
//! pastes `shaders/shared/NAME.wgsl` in place, once per composed module (later imports of the
//! same file are dropped), so shared code stays in one place. A line `#import gen/NAME` pastes
//! WGSL generated from Rust ([`GENERATED`]): constants that both sides use are defined once,
//! in Rust. The composed source is validated with naga by `cargo test` without any GPU.
//!
//! `#import shared/bvh` is where rays are traced. With [`Tracer::RayQuery`] the composer
//! pastes `shared/bvh_ray_query` there instead (the same functions through hardware ray
//! queries) and starts the module with `enable wgpu_ray_query;`; every pass is validated in
//! both forms.
use crate::{Error, Result};
use std::borrow::Cow;

/// A generator of WGSL source.
pub type Generator = fn() -> String;

/// WGSL written by Rust: (name under `gen/`, generator). The estimators add theirs
/// (`optim::estimator::GENERATED`).
pub const GENERATED: &[(&str, Generator)] = &[("gen/abi", crate::gpu::abi::wgsl)];

/// WGSL declaring `constants` (WGSL name, value) as `u32`s, generated from the Rust file
/// `from`.
pub fn constants_wgsl(from: &str, constants: &[(&str, u32)]) -> String {
    let mut s = format!("// Generated from {from}; edit the Rust side.\n");
    for (name, v) in constants {
        s.push_str(&format!("const {name}: u32 = {v}u;\n"));
    }
    s
}

/// Every WGSL file under `shaders/`: (path under `shaders/` without extension, source).
pub const SHADERS: &[(&str, &str)] = &[
    (
        "shared/types",
        include_str!("../../shaders/shared/types.wgsl"),
    ),
    ("shared/rng", include_str!("../../shaders/shared/rng.wgsl")),
    (
        "shared/sampling",
        include_str!("../../shaders/shared/sampling.wgsl"),
    ),
    (
        "shared/scene",
        include_str!("../../shaders/shared/scene.wgsl"),
    ),
    (
        "shared/triangle",
        include_str!("../../shaders/shared/triangle.wgsl"),
    ),
    ("shared/bvh", include_str!("../../shaders/shared/bvh.wgsl")),
    (
        "shared/bvh_ray_query",
        include_str!("../../shaders/shared/bvh_ray_query.wgsl"),
    ),
    (
        "shared/wrap",
        include_str!("../../shaders/shared/wrap.wgsl"),
    ),
    (
        "shared/texture",
        include_str!("../../shaders/shared/texture.wgsl"),
    ),
    (
        "shared/brdf",
        include_str!("../../shaders/shared/brdf.wgsl"),
    ),
    (
        "shared/lights",
        include_str!("../../shaders/shared/lights.wgsl"),
    ),
    (
        "shared/camera",
        include_str!("../../shaders/shared/camera.wgsl"),
    ),
    (
        "shared/params",
        include_str!("../../shaders/shared/params.wgsl"),
    ),
    (
        "shared/integrator",
        include_str!("../../shaders/shared/integrator.wgsl"),
    ),
    (
        "shared/gradient_scatter",
        include_str!("../../shaders/shared/gradient_scatter.wgsl"),
    ),
    (
        "shared/adjoint_pixel",
        include_str!("../../shaders/shared/adjoint_pixel.wgsl"),
    ),
    (
        "shared/surface",
        include_str!("../../shaders/shared/surface.wgsl"),
    ),
    (
        "shared/path_encoding",
        include_str!("../../shaders/shared/path_encoding.wgsl"),
    ),
    ("render", include_str!("../../shaders/render.wgsl")),
    ("trace_rays", include_str!("../../shaders/trace_rays.wgsl")),
    ("loss", include_str!("../../shaders/loss.wgsl")),
    (
        "texture_wrap_test",
        include_str!("../../shaders/texture_wrap_test.wgsl"),
    ),
    (
        "texture_export",
        include_str!("../../shaders/texture_export.wgsl"),
    ),
    (
        "observed_texels",
        include_str!("../../shaders/observed_texels.wgsl"),
    ),
    ("primal_cv", include_str!("../../shaders/primal_cv.wgsl")),
];

/// Every WGSL file: those under `shaders/`, then the steps', the priors' and the
/// estimators', which lie beside their drivers (a pass is named after its file; an
/// estimator's other modules are imported as `<method>/<file stem>`).
pub fn sources() -> impl Iterator<Item = (&'static str, &'static str)> {
    let folders = [crate::optim::step::WGSL, crate::optim::prior::WGSL];
    SHADERS.iter().copied().chain(
        folders
            .into_iter()
            .chain(crate::optim::estimator::WGSL)
            .flat_map(|files| files.iter().copied()),
    )
}

/// The passes (top-level WGSL files with an entry point `main`).
pub fn passes() -> impl Iterator<Item = &'static str> {
    sources().map(|(n, _)| n).filter(|n| !n.contains('/'))
}

fn source(name: &str) -> Option<Cow<'static, str>> {
    if let Some((_, s)) = sources().find(|(n, _)| *n == name) {
        return Some(Cow::Borrowed(s));
    }
    GENERATED
        .iter()
        .chain(crate::optim::estimator::GENERATED)
        .find(|(n, _)| *n == name)
        .map(|(_, f)| Cow::Owned(f()))
}

/// How the passes trace rays: the WGSL BVH, or the device's ray queries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Tracer {
    /// The binned-SAH BVH built on the host, traversed in WGSL (`shared/bvh`).
    #[default]
    Software,
    /// Hardware ray queries against an acceleration structure (`shared/bvh_ray_query`;
    /// needs `Features::EXPERIMENTAL_RAY_QUERY`).
    RayQuery,
}

/// The full WGSL of a pass with its imports pasted in, tracing with the software BVH.
pub fn compose(pass: &str) -> Result<String> {
    compose_for(pass, Tracer::Software)
}

/// The full WGSL of a pass with its imports pasted in, tracing with `tracer`.
pub fn compose_for(pass: &str, tracer: Tracer) -> Result<String> {
    let mut out = String::new();
    let mut seen = Vec::new();
    include(pass, tracer, &mut out, &mut seen, 0)?;
    if tracer == Tracer::RayQuery && seen.iter().any(|s| s == "shared/bvh_ray_query") {
        out.insert_str(0, "enable wgpu_ray_query;\n");
    }
    Ok(out)
}

fn include(
    name: &str,
    tracer: Tracer,
    out: &mut String,
    seen: &mut Vec<String>,
    depth: u32,
) -> Result<()> {
    let name = match (name, tracer) {
        ("shared/bvh", Tracer::RayQuery) => "shared/bvh_ray_query",
        _ => name,
    };
    if seen.iter().any(|s| s == name) {
        return Ok(());
    }
    if depth > 16 {
        return Err(Error::Shader {
            name: name.into(),
            msg: "imports nested more than 16 deep".into(),
        });
    }
    seen.push(name.to_string());
    let src = source(name).ok_or_else(|| Error::Shader {
        name: name.into(),
        msg: "no such WGSL file under shaders/ (nor a generated gen/ module)".into(),
    })?;
    out.push_str(&format!("// ---- {name}.wgsl\n"));
    for line in src.lines() {
        if let Some(dep) = line.trim().strip_prefix("#import ") {
            include(dep.trim(), tracer, out, seen, depth + 1)?;
            out.push_str(&format!("// ---- (back in) {name}.wgsl\n"));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    Ok(())
}

/// Parse and validate a composed pass with naga; errors carry the pass name and location.
pub fn validate(pass: &str) -> Result<naga::Module> {
    validate_for(pass, Tracer::Software)
}

/// [`validate`] for the form of the pass that traces with `tracer`.
pub fn validate_for(pass: &str, tracer: Tracer) -> Result<naga::Module> {
    let src = compose_for(pass, tracer)?;
    let module = naga::front::wgsl::parse_str(&src).map_err(|e| Error::Shader {
        name: pass.into(),
        msg: e.emit_to_string(&src),
    })?;
    let mut validator = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        match tracer {
            Tracer::Software => naga::valid::Capabilities::empty(),
            Tracer::RayQuery => naga::valid::Capabilities::RAY_QUERY,
        },
    );
    validator.validate(&module).map_err(|e| Error::Shader {
        name: pass.into(),
        msg: e.emit_to_string(&src),
    })?;
    if !module.entry_points.iter().any(|e| e.name == "main") {
        return Err(Error::Shader {
            name: pass.into(),
            msg: "no entry point `main`".into(),
        });
    }
    Ok(module)
}

/// The bindings of group `group` of a pass, reflected from its composed WGSL by naga:
/// (variable name, kind) in binding order. Bind group layouts are built from this, so they
/// cannot disagree with the shader; the bindings must be numbered 0, 1, 2, ... without gaps.
pub fn bindings(pass: &str, group: u32) -> Result<Vec<(String, super::Binding)>> {
    bindings_for(pass, group, Tracer::Software)
}

/// [`bindings`] of the form of the pass that traces with `tracer`.
pub fn bindings_for(
    pass: &str,
    group: u32,
    tracer: Tracer,
) -> Result<Vec<(String, super::Binding)>> {
    let module = validate_for(pass, tracer)?;
    let mut found: Vec<(u32, String, super::Binding)> = Vec::new();
    for (_, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        if rb.group != group {
            continue;
        }
        let kind = match var.space {
            naga::AddressSpace::Uniform => super::Binding::Uniform,
            naga::AddressSpace::Handle
                if matches!(
                    module.types[var.ty].inner,
                    naga::TypeInner::AccelerationStructure { .. }
                ) =>
            {
                super::Binding::AccelerationStructure
            }
            naga::AddressSpace::Handle
                if matches!(
                    module.types[var.ty].inner,
                    naga::TypeInner::Image {
                        dim: naga::ImageDimension::D2,
                        arrayed: false,
                        class: naga::ImageClass::Storage {
                            format: naga::StorageFormat::Rgba32Float,
                            access: naga::StorageAccess::STORE,
                        },
                    }
                ) =>
            {
                super::Binding::StorageTextureRgba32FloatWrite
            }
            naga::AddressSpace::Storage { access } => {
                if access.contains(naga::StorageAccess::STORE) {
                    super::Binding::StorageRw
                } else {
                    super::Binding::Storage
                }
            }
            other => {
                return Err(Error::Shader {
                    name: pass.into(),
                    msg: format!(
                        "binding {} of group {group}: unsupported {other:?}",
                        rb.binding
                    ),
                })
            }
        };
        found.push((rb.binding, var.name.clone().unwrap_or_default(), kind));
    }
    found.sort_by_key(|b| b.0);
    for (i, b) in found.iter().enumerate() {
        if b.0 != i as u32 {
            return Err(Error::Shader {
                name: pass.into(),
                msg: format!("group {group} has no binding {i} (bindings must be 0, 1, 2, ...)"),
            });
        }
    }
    Ok(found.into_iter().map(|(_, n, k)| (n, k)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_pass_validates_with_naga() {
        let mut n = 0;
        for pass in passes() {
            for tracer in [Tracer::Software, Tracer::RayQuery] {
                if let Err(e) = validate_for(pass, tracer) {
                    panic!("{tracer:?}: {e}");
                }
            }
            n += 1;
        }
        assert!(n >= 2);
    }

    #[test]
    fn every_pass_has_contiguous_reflected_bindings() {
        // texture_export binds a storage texture, which texture_export.rs lays out itself.
        for pass in passes().filter(|&p| p != "texture_export") {
            for group in 0..2 {
                bindings(pass, group).unwrap_or_else(|e| panic!("{pass}: {e}"));
            }
        }
        // The scene group as every tracing pass declares it (shared/scene.wgsl).
        let scene = bindings("render", 0).unwrap();
        assert_eq!(scene[0].0, "nodes");
        assert_eq!(
            scene[7],
            ("scene".to_string(), crate::gpu::Binding::Uniform)
        );
        assert_eq!(bindings("loss", 0).unwrap()[6].0, "exposure_partial");
        // With ray queries the tracing passes add the acceleration structure after the
        // buffers; the merge, which traces nothing, is the same in both forms.
        let rq = bindings_for("render", 0, Tracer::RayQuery).unwrap();
        assert_eq!(rq.len(), scene.len() + 1);
        assert_eq!(
            rq.last().unwrap(),
            &(
                "scene_tlas".to_string(),
                crate::gpu::Binding::AccelerationStructure
            )
        );
        for pass in passes().filter(|&p| p != "texture_export") {
            for group in 0..2 {
                bindings_for(pass, group, Tracer::RayQuery)
                    .unwrap_or_else(|e| panic!("{pass} with ray queries: {e}"));
            }
        }
        assert_eq!(
            compose_for("restir_merge", Tracer::RayQuery).unwrap(),
            compose("restir_merge").unwrap()
        );
    }

    #[test]
    fn every_wgsl_file_is_registered() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/shaders");
        let mut files = Vec::new();
        for sub in ["", "shared/"] {
            for e in std::fs::read_dir(format!("{dir}/{sub}")).unwrap() {
                let p = e.unwrap().path();
                if p.extension().is_some_and(|x| x == "wgsl") {
                    let stem = p.file_stem().unwrap().to_string_lossy().to_string();
                    files.push(format!("{sub}{stem}"));
                }
            }
        }
        for f in files {
            assert!(source(&f).is_some(), "shaders/{f}.wgsl is not in SHADERS");
        }
        // The passes in the estimators' folders (a pass's name is its file's stem).
        let estimators = concat!(env!("CARGO_MANIFEST_DIR"), "/src/optim/estimator");
        let mut found = 0;
        for e in std::fs::read_dir(estimators).unwrap() {
            let d = e.unwrap().path();
            if !d.is_dir() {
                continue;
            }
            for f in std::fs::read_dir(&d).unwrap() {
                let p = f.unwrap().path();
                if p.extension().is_some_and(|x| x == "wgsl") {
                    let stem = p.file_stem().unwrap().to_string_lossy().to_string();
                    let dir = d.file_name().unwrap().to_string_lossy().to_string();
                    assert!(
                        source(&stem).is_some() || source(&format!("{dir}/{stem}")).is_some(),
                        "{} is not in its estimator's WGSL list",
                        p.display()
                    );
                    found += 1;
                }
            }
        }
        assert!(
            found >= 6,
            "only {found} WGSL files in the estimators' folders"
        );
    }

    /// The constants every generated module declares.
    fn generated_constants() -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        for (module, f) in GENERATED.iter().chain(crate::optim::estimator::GENERATED) {
            for line in f().lines() {
                if let Some(rest) = line.strip_prefix("const ") {
                    out.push((*module, rest.split(':').next().unwrap().to_string()));
                }
            }
        }
        out
    }

    #[test]
    fn generated_constants_are_unique_and_no_wgsl_file_defines_one() {
        let consts = generated_constants();
        assert!(consts.len() > 40, "{} constants", consts.len());
        let mut names: Vec<&str> = consts.iter().map(|(_, n)| n.as_str()).collect();
        names.sort();
        let n = names.len();
        names.dedup();
        assert_eq!(names.len(), n, "a constant is generated twice");
        for (file, source) in sources() {
            for (module, name) in &consts {
                assert!(
                    !source.contains(&format!("const {name}:")),
                    "{file}.wgsl defines {name}, which {module} generates"
                );
            }
            // A statistics buffer (`stats`, `gstats`, `loss_stats`, ...) indexed by a digit.
            for (i, _) in source.match_indices("stats[") {
                let next = source[i + 6..].chars().next().unwrap_or(' ');
                assert!(
                    !next.is_ascii_digit(),
                    "{file}.wgsl indexes a statistics buffer by a literal: {}",
                    &source[i.saturating_sub(20)..(i + 10).min(source.len())]
                );
            }
        }
    }

    #[test]
    fn a_broken_shader_is_reported_with_its_name() {
        let src = "fn main( { }";
        assert!(naga::front::wgsl::parse_str(src).is_err());
        assert!(matches!(compose("no_such_pass"), Err(Error::Shader { .. })));
    }
}
