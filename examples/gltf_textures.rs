//! Load a glTF scene, recover a texture from renders of the file's own materials, and write
//! the recovered texture as EXR (linear) and PNG.
//!
//!     cargo run --release --example gltf_textures [SCENE.gltf [OUT_DIR [ITERATIONS]]]
//!
//! Defaults: the bundled scene (`scenes/default/scene.gltf`), `out/gltf_textures`, 100
//! iterations. The file's materials are the ground truth; the sphere's base color starts
//! gray at 64x32 texels and is recovered from the camera `main` at 64x64.
use psrestir::job::run::save_textures;
use psrestir::{Filter, Gpu, Init, Optimizer, Problem, Settings, Slot, Stop, TextureSpec};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// What a run wrote and how close it came.
pub struct Outcome {
    /// Texture RMSE against the file's material, before and after.
    pub rmse: (f64, f64),
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Recover the base color of material `sphere` of `scene_path` in `iterations` and write it
/// to `out`.
pub fn run(scene_path: &Path, out: &Path, iterations: u32) -> psrestir::Result<Outcome> {
    let gpu = Gpu::new()?;
    let scene = psrestir::scene::load(scene_path)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let main = scene.camera(Some("main"))?;
    let texture = TextureSpec {
        material: "sphere".into(),
        slot: Slot::BaseColor,
        resolution: [64, 32],
        init: Init::Vector(vec![0.5; 3]),
        learning_rate: Some(0.03),
    };
    let mut problem = Problem::new(scene.clone(), vec![main], &[texture], Filter::Bilinear)?;
    // The file itself is the truth: render the targets from it.
    problem.render_targets(&gpu, scene, 64, 64, 128, 1)?;
    let reference = problem
        .reference
        .clone()
        .expect("rendered from a truth scene");
    let settings = Settings {
        primal_spp: 2,
        primal: Default::default(),
        cv_max_weight: psrestir::optim::primal::DEFAULT_MAX_WEIGHT,
        path_cache: None,
        gradient_spp: 2,
        ..Settings::new(64, 64, vec![main])
    };
    let mut opt = Optimizer::for_problem(&gpu, &problem, settings)?;
    let rmse = |v: &[f32]| psrestir::job::run::rmse(v, &reference);
    let before = rmse(&opt.texture_values(0)?);
    opt.run(Stop::iterations(iterations), |p| {
        if p.iteration % 25 == 0 {
            println!("iteration {:4}: loss {:.3e}", p.iteration, p.loss);
        }
        ControlFlow::Continue(())
    })?;
    let values = opt.texture_values(0)?;
    let after = rmse(&values);
    std::fs::create_dir_all(out).map_err(|e| psrestir::Error::file(out, e.to_string()))?;
    save_textures(out, &opt.set, &values)?;
    let name = opt.set.textures[0].name();
    let files = vec![
        out.join(format!("{name}.exr")),
        out.join(format!("{name}.png")),
    ];
    println!(
        "texture RMSE {before:.4} -> {after:.4}; wrote {}",
        files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(Outcome {
        rmse: (before, after),
        files,
    })
}

#[allow(dead_code)]
fn main() -> psrestir::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args
        .first()
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/default/scene.gltf"));
    let out = args
        .get(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("out/gltf_textures"));
    let iterations = match args.get(2) {
        Some(a) => a
            .parse()
            .map_err(|_| psrestir::Error::Invalid(format!("ITERATIONS: `{a}` is not a count")))?,
        None => 100,
    };
    run(&scene, &out, iterations)?;
    Ok(())
}
