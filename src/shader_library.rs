//! The crate's shader library: every WGSL file, assembled from the folders that own them
//! (`shaders/shared/` for the shared modules; a pass's file lies beside its driver, named
//! after it: the renderer's in `src/render/`, the optimizer's in `src/optim/`, each step's,
//! prior's and estimator's in its folder) and the WGSL that Rust generates. The
//! GPU layer's composer ([`crate::gpu::shaders`]) knows none of them; the passes create
//! their pipelines through the methods here, which hand it this library.
use crate::gpu::shaders::{Generator, Library, Tracer};
use crate::gpu::{Binding, Gpu};
use crate::Result;
use std::sync::LazyLock;

/// The shared WGSL modules: `shaders/shared/NAME.wgsl`, imported as `shared/NAME`.
pub const SHARED: &[(&str, &str)] = &[
    ("shared/types", include_str!("../shaders/shared/types.wgsl")),
    ("shared/rng", include_str!("../shaders/shared/rng.wgsl")),
    (
        "shared/sampling",
        include_str!("../shaders/shared/sampling.wgsl"),
    ),
    ("shared/scene", include_str!("../shaders/shared/scene.wgsl")),
    (
        "shared/triangle",
        include_str!("../shaders/shared/triangle.wgsl"),
    ),
    ("shared/bvh", include_str!("../shaders/shared/bvh.wgsl")),
    (
        "shared/bvh_ray_query",
        include_str!("../shaders/shared/bvh_ray_query.wgsl"),
    ),
    ("shared/wrap", include_str!("../shaders/shared/wrap.wgsl")),
    (
        "shared/texture",
        include_str!("../shaders/shared/texture.wgsl"),
    ),
    ("shared/brdf", include_str!("../shaders/shared/brdf.wgsl")),
    (
        "shared/lights",
        include_str!("../shaders/shared/lights.wgsl"),
    ),
    (
        "shared/camera",
        include_str!("../shaders/shared/camera.wgsl"),
    ),
    (
        "shared/params",
        include_str!("../shaders/shared/params.wgsl"),
    ),
    (
        "shared/integrator",
        include_str!("../shaders/shared/integrator.wgsl"),
    ),
    (
        "shared/gradient_scatter",
        include_str!("../shaders/shared/gradient_scatter.wgsl"),
    ),
    (
        "shared/env_gradient",
        include_str!("../shaders/shared/env_gradient.wgsl"),
    ),
    (
        "shared/adjoint_pixel",
        include_str!("../shaders/shared/adjoint_pixel.wgsl"),
    ),
    (
        "shared/surface",
        include_str!("../shaders/shared/surface.wgsl"),
    ),
    (
        "shared/normal_map",
        include_str!("../shaders/shared/normal_map.wgsl"),
    ),
    (
        "shared/normal_map_off",
        include_str!("../shaders/shared/normal_map_off.wgsl"),
    ),
    (
        "shared/path_encoding",
        include_str!("../shaders/shared/path_encoding.wgsl"),
    ),
];

/// WGSL written by Rust: (name under `gen/`, generator).
pub const GENERATED: &[(&str, Generator)] = &[("gen/abi", crate::gpu::abi::wgsl)];

static LIBRARY: LazyLock<Library> = LazyLock::new(|| {
    let mut library = Library::new()
        .with_files(SHARED)
        .with_files(crate::render::WGSL)
        .with_files(crate::optim::WGSL)
        .with_generated(GENERATED);
    for files in crate::optim::step::wgsl() {
        library = library.with_files(files);
    }
    for files in crate::optim::prior::wgsl() {
        library = library.with_files(files);
    }
    for files in crate::optim::estimator::wgsl() {
        library = library.with_files(files);
    }
    for generated in crate::optim::estimator::generated() {
        library = library.with_generated(generated);
    }
    library
});

/// Every WGSL file of the crate: those under `shaders/`, then the steps', the priors' and
/// the estimators', which lie beside their drivers (a pass is named after its file; an
/// estimator's other modules are imported as `<method>/<file stem>`).
pub fn library() -> &'static Library {
    &LIBRARY
}

/// Every file of the library: (name, source).
pub fn sources() -> impl Iterator<Item = (&'static str, &'static str)> {
    library().sources()
}

/// The passes (top-level WGSL files with an entry point `main`).
pub fn passes() -> impl Iterator<Item = &'static str> {
    library().passes()
}

/// The full WGSL of a pass with its imports pasted in, tracing with the software BVH.
pub fn compose(pass: &str) -> Result<String> {
    library().compose(pass)
}

/// Parse and validate a composed pass with naga; errors carry the pass name and location.
pub fn validate(pass: &str) -> Result<naga::Module> {
    library().validate(pass)
}

/// The bindings of group `group` of a pass, reflected from its WGSL ([`Library::bindings`]).
pub fn bindings(pass: &str, group: u32) -> Result<Vec<(String, Binding)>> {
    library().bindings(pass, group)
}

/// [`bindings`] of the form of the pass that traces with `tracer`.
pub fn bindings_for(pass: &str, group: u32, tracer: Tracer) -> Result<Vec<(String, Binding)>> {
    library().bindings_for(pass, group, tracer)
}

impl Gpu {
    /// Compile the crate's pass `pass` ([`Gpu::compute_pipeline_in`] with [`library`]).
    pub fn compute_pipeline(
        &self,
        pass: &str,
        layouts: &[&wgpu::BindGroupLayout],
    ) -> Result<wgpu::ComputePipeline> {
        self.compute_pipeline_in(library(), pass, layouts)
    }

    /// [`Gpu::compute_pipeline`] with the modules `off` names in their `_off` form.
    pub fn compute_pipeline_without(
        &self,
        pass: &str,
        layouts: &[&wgpu::BindGroupLayout],
        off: &[&str],
    ) -> Result<wgpu::ComputePipeline> {
        self.compute_pipeline_in_without(library(), pass, layouts, off)
    }

    /// The layout of bind group `group` of the crate's pass `pass` ([`Gpu::pass_layout_in`]).
    pub fn pass_layout(&self, pass: &str, group: u32) -> Result<wgpu::BindGroupLayout> {
        self.pass_layout_in(library(), pass, group)
    }

    /// Compile the crate's `passes` on a second device ([`Gpu::compile_elsewhere_in`]) in the
    /// form a task that does or does not optimize a normal map needs
    /// ([`crate::render::off_modules`]).
    pub fn compile_elsewhere(
        &self,
        passes: &[&str],
        normal_maps: bool,
    ) -> Option<std::thread::JoinHandle<()>> {
        self.compile_elsewhere_in(library(), passes, crate::render::off_modules(normal_maps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_pass_validates_with_naga() {
        let mut n = 0;
        for pass in passes() {
            for tracer in [Tracer::Software, Tracer::RayQuery] {
                if let Err(e) = library().validate_for(pass, tracer) {
                    panic!("{tracer:?}: {e}");
                }
            }
            // And without the normal-map code (GpuScene::off_modules).
            let off = ["shared/normal_map"];
            if let Err(e) = library().validate_without(pass, Tracer::Software, &off) {
                panic!("without shared/normal_map: {e}");
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
        assert_eq!(scene[7], ("scene".to_string(), Binding::Uniform));
        assert_eq!(bindings("loss", 0).unwrap()[6].0, "exposure_partial");
        // With ray queries the tracing passes add the acceleration structure after the
        // buffers; the merge, which traces nothing, is the same in both forms.
        let rq = bindings_for("render", 0, Tracer::RayQuery).unwrap();
        assert_eq!(rq.len(), scene.len() + 1);
        assert_eq!(
            rq.last().unwrap(),
            &("scene_tlas".to_string(), Binding::AccelerationStructure)
        );
        for pass in passes().filter(|&p| p != "texture_export") {
            for group in 0..2 {
                bindings_for(pass, group, Tracer::RayQuery)
                    .unwrap_or_else(|e| panic!("{pass} with ray queries: {e}"));
            }
        }
        assert_eq!(
            library()
                .compose_for("restir_merge", Tracer::RayQuery)
                .unwrap(),
            compose("restir_merge").unwrap()
        );
    }

    #[test]
    fn every_wgsl_file_is_registered() {
        use crate::layering_tests::files_under;
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut files = files_under(&root.join("shaders"), "wgsl");
        files.extend(files_under(&root.join("src"), "wgsl"));
        for p in &files {
            // A pass is named after its file; a shared module as `shared/<stem>`, an
            // estimator's other modules as `<folder>/<stem>`.
            let stem = p.file_stem().unwrap().to_string_lossy().to_string();
            let dir = p.parent().unwrap().file_name().unwrap().to_string_lossy();
            assert!(
                library().source(&stem).is_some()
                    || library().source(&format!("{dir}/{stem}")).is_some(),
                "{} is not in the shader library",
                p.display()
            );
        }
        assert!(files.len() > 30, "only {} WGSL files", files.len());
        // Nothing but the shared modules under shaders/.
        let top: Vec<_> = std::fs::read_dir(root.join("shaders"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        assert_eq!(top, ["shared"], "shaders/ holds the shared modules only");
    }

    /// The constants every generated module declares.
    fn generated_constants() -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        for (module, f) in library().generated() {
            for line in f().lines() {
                if let Some(rest) = line.strip_prefix("const ") {
                    out.push((module, rest.split(':').next().unwrap().to_string()));
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
}
