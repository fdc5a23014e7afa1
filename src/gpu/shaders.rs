//! WGSL composition and validation.
//!
//! A pass is one WGSL file named after it, found in a [`Library`] that the code creating
//! pipelines assembles. A line `#import shared/NAME` pastes the library's `shared/NAME` in
//! place, once per composed module (later imports of the same file are dropped), so shared
//! code stays in one place. A line `#import gen/NAME` pastes WGSL generated from Rust (a
//! [`Generator`]): constants that both sides use are defined once, in Rust. The composed
//! source is validated with naga by `cargo test` without any GPU. This module knows no file
//! of its own: it is the composer, below everything that owns WGSL.
//!
//! `#import shared/bvh` is where rays are traced. With [`Tracer::RayQuery`] the composer
//! pastes `shared/bvh_ray_query` there instead (the same functions through hardware ray
//! queries) and starts the module with `enable wgpu_ray_query;`; every pass is validated in
//! both forms.
use crate::{Error, Result};
use std::borrow::Cow;

/// A generator of WGSL source.
pub type Generator = fn() -> String;

/// WGSL declaring `constants` (WGSL name, value) as `u32`s, generated from the Rust file
/// `from`.
pub fn constants_wgsl(from: &str, constants: &[(&str, u32)]) -> String {
    let mut s = format!("// Generated from {from}; edit the Rust side.\n");
    for (name, v) in constants {
        s.push_str(&format!("const {name}: u32 = {v}u;\n"));
    }
    s
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

/// A library of WGSL files that passes are composed from: (name, source) pairs, a pass named
/// after its file and every other module by the path `#import` names, and generators of WGSL
/// from Rust (`gen/<name>`). Whoever creates the pipelines assembles it (the crate's is
/// `psrestir::shader_library`).
#[derive(Clone, Default)]
pub struct Library {
    files: Vec<(&'static str, &'static str)>,
    generated: Vec<(&'static str, Generator)>,
}

impl Library {
    /// An empty library.
    pub fn new() -> Library {
        Library::default()
    }

    /// This library with `files` added: (name, source); a pass is a name without `/`.
    pub fn with_files(mut self, files: &[(&'static str, &'static str)]) -> Library {
        self.files.extend_from_slice(files);
        self
    }

    /// This library with generated modules added: (name under `gen/`, generator).
    pub fn with_generated(mut self, generated: &[(&'static str, Generator)]) -> Library {
        self.generated.extend_from_slice(generated);
        self
    }

    /// Every file: (name, source).
    pub fn sources(&self) -> impl Iterator<Item = (&'static str, &'static str)> + '_ {
        self.files.iter().copied()
    }

    /// Every generated module: (name, generator).
    pub fn generated(&self) -> impl Iterator<Item = (&'static str, Generator)> + '_ {
        self.generated.iter().copied()
    }

    /// The passes (top-level files, each with an entry point `main`).
    pub fn passes(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.sources().map(|(n, _)| n).filter(|n| !n.contains('/'))
    }

    /// The source of the file or generated module `name`.
    pub fn source(&self, name: &str) -> Option<Cow<'static, str>> {
        if let Some((_, s)) = self.sources().find(|(n, _)| *n == name) {
            return Some(Cow::Borrowed(s));
        }
        self.generated
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, f)| Cow::Owned(f()))
    }

    /// The full WGSL of a pass with its imports pasted in, tracing with the software BVH.
    pub fn compose(&self, pass: &str) -> Result<String> {
        self.compose_for(pass, Tracer::Software)
    }

    /// The full WGSL of a pass with its imports pasted in, tracing with `tracer`.
    pub fn compose_for(&self, pass: &str, tracer: Tracer) -> Result<String> {
        self.compose_without(pass, tracer, &[])
    }

    /// [`Library::compose_for`] with each module that `off` names pasted in its `_off` form
    /// (`shared/normal_map` as `shared/normal_map_off`): the same functions doing nothing, for
    /// a feature the pass's scene does not use.
    pub fn compose_without(&self, pass: &str, tracer: Tracer, off: &[&str]) -> Result<String> {
        let mut out = String::new();
        let mut seen = Vec::new();
        self.include(pass, (tracer, off), &mut out, &mut seen, 0)?;
        if tracer == Tracer::RayQuery && seen.iter().any(|s| s == "shared/bvh_ray_query") {
            out.insert_str(0, "enable wgpu_ray_query;\n");
        }
        Ok(out)
    }

    fn include(
        &self,
        name: &str,
        form: (Tracer, &[&str]),
        out: &mut String,
        seen: &mut Vec<String>,
        depth: u32,
    ) -> Result<()> {
        let off_name;
        let name = match (name, form.0) {
            ("shared/bvh", Tracer::RayQuery) => "shared/bvh_ray_query",
            _ if form.1.contains(&name) => {
                off_name = format!("{name}_off");
                off_name.as_str()
            }
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
        let src = self.source(name).ok_or_else(|| Error::Shader {
            name: name.into(),
            msg: "no such WGSL file in the shader library (nor a generated gen/ module)".into(),
        })?;
        out.push_str(&format!("// ---- {name}.wgsl\n"));
        for line in src.lines() {
            if let Some(dep) = line.trim().strip_prefix("#import ") {
                self.include(dep.trim(), form, out, seen, depth + 1)?;
                out.push_str(&format!("// ---- (back in) {name}.wgsl\n"));
            } else {
                out.push_str(line);
                out.push('\n');
            }
        }
        Ok(())
    }

    /// Parse and validate a composed pass with naga; errors carry the pass name and location.
    pub fn validate(&self, pass: &str) -> Result<naga::Module> {
        self.validate_for(pass, Tracer::Software)
    }

    /// [`Library::validate`] for the form of the pass that traces with `tracer`.
    pub fn validate_for(&self, pass: &str, tracer: Tracer) -> Result<naga::Module> {
        self.validate_without(pass, tracer, &[])
    }

    /// [`Library::validate_for`] of the form [`Library::compose_without`] composes.
    pub fn validate_without(
        &self,
        pass: &str,
        tracer: Tracer,
        off: &[&str],
    ) -> Result<naga::Module> {
        let src = self.compose_without(pass, tracer, off)?;
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
    pub fn bindings(&self, pass: &str, group: u32) -> Result<Vec<(String, Binding)>> {
        self.bindings_for(pass, group, Tracer::Software)
    }

    /// [`Library::bindings`] of the form of the pass that traces with `tracer`.
    pub fn bindings_for(
        &self,
        pass: &str,
        group: u32,
        tracer: Tracer,
    ) -> Result<Vec<(String, Binding)>> {
        let module = self.validate_for(pass, tracer)?;
        let mut found: Vec<(u32, String, Binding)> = Vec::new();
        for (_, var) in module.global_variables.iter() {
            let Some(rb) = &var.binding else { continue };
            if rb.group != group {
                continue;
            }
            let kind = match var.space {
                naga::AddressSpace::Uniform => Binding::Uniform,
                naga::AddressSpace::Handle
                    if matches!(
                        module.types[var.ty].inner,
                        naga::TypeInner::AccelerationStructure { .. }
                    ) =>
                {
                    Binding::AccelerationStructure
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
                    Binding::StorageTextureRgba32FloatWrite
                }
                naga::AddressSpace::Storage { access } => {
                    if access.contains(naga::StorageAccess::STORE) {
                        Binding::StorageRw
                    } else {
                        Binding::Storage
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
                    msg: format!(
                        "group {group} has no binding {i} (bindings must be 0, 1, 2, ...)"
                    ),
                });
            }
        }
        Ok(found.into_iter().map(|(_, n, k)| (n, k)).collect())
    }
}

/// Kind of a binding in a pass layout (`Gpu::layout`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Binding {
    /// `var<uniform>`.
    Uniform,
    /// `var<storage, read>`.
    Storage,
    /// `var<storage, read_write>`.
    StorageRw,
    /// `var: acceleration_structure` (the scene's, with ray queries).
    AccelerationStructure,
    /// `var: texture_storage_2d<rgba32float, write>` (what the export pass writes).
    StorageTextureRgba32FloatWrite,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toy() -> Library {
        Library::new()
            .with_files(&[
                ("shared/a", "fn a() -> u32 { return K; }"),
                (
                    "shared/b",
                    "#import shared/a\nfn b() -> u32 { return a(); }",
                ),
                ("shared/bvh", "fn trace() {}"),
                ("shared/bvh_ray_query", "fn trace() {}"),
                (
                    "pass",
                    "#import gen/k\n#import shared/a\n#import shared/b\n#import shared/bvh\n\
                     @compute @workgroup_size(1) fn main() { trace(); _ = b(); }",
                ),
            ])
            .with_generated(&[("gen/k", || constants_wgsl("test", &[("K", 7)]))])
    }

    #[test]
    fn imports_are_pasted_once_and_generated_modules_found() {
        let lib = toy();
        assert_eq!(lib.passes().collect::<Vec<_>>(), ["pass"]);
        let src = lib.compose("pass").unwrap();
        assert_eq!(src.matches("fn a()").count(), 1, "{src}");
        assert!(src.contains("const K: u32 = 7u;"));
        lib.validate("pass").unwrap();
        let rq = lib.compose_for("pass", Tracer::RayQuery).unwrap();
        assert!(rq.starts_with("enable wgpu_ray_query;"));
        assert!(rq.contains("shared/bvh_ray_query.wgsl"));
    }

    #[test]
    fn a_broken_shader_is_reported_with_its_name() {
        let src = "fn main( { }";
        assert!(naga::front::wgsl::parse_str(src).is_err());
        let lib = toy().with_files(&[("broken", src)]);
        match lib.validate("broken") {
            Err(Error::Shader { name, .. }) => assert_eq!(name, "broken"),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            lib.compose("no_such_pass"),
            Err(Error::Shader { .. })
        ));
    }
}
