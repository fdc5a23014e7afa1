//! A task file's optimization problem ([`Problem::from_task`], [`Problem::load`]): its scene
//! with what the task adds, its cameras, textures and targets (rendered from its ground truth
//! and cached, or its photos with their masks and exposures). The [`Problem`] itself, and
//! what an application builds one with, are the optimizer's (`optim/api/problem.rs`).
pub use crate::optim::Problem;

use crate::gpu::Gpu;
use crate::image_io;
use crate::render::params::ParamSet;
use crate::scene::{self, EnvMap, Scene};
use crate::task::Task;
use crate::{Error, Result};
use std::path::Path;

impl Problem {
    /// Load a task's scene with what the task adds (lights, cameras, a camera file's
    /// frames, and a default camera and light where the scene has none), find its cameras
    /// and lay out its textures, without targets (no GPU needed; [`Problem::from_task`] adds
    /// them).
    pub fn load(task: &Task) -> Result<Problem> {
        let (scene, added, frames) = task_scene(task, &task.scene)?;
        let cameras: Vec<usize> = match &task.cameras {
            Some(names) => names
                .iter()
                .map(|n| scene.camera(Some(n)))
                .collect::<Result<_>>()?,
            None if !added.is_empty() => added,
            None => {
                scene.camera(None)?;
                (0..scene.cameras.len()).collect()
            }
        };
        let mut set =
            ParamSet::from_specs(&scene, &task.textures, task.optimizer.filter, &task.path)?;
        // A texture that names no learning rate takes `auto`'s for the task's step and regime.
        let config = crate::task::task_configuration(task, task.optimizer.method, cameras.len());
        for t in &mut set.textures {
            t.learning_rate.get_or_insert_with(|| config.rate(t.slot));
        }
        let exposure = cameras
            .iter()
            .map(|&c| {
                let name = &scene.cameras[c].name;
                task.target
                    .exposure
                    .as_ref()
                    .and_then(|e| e.get(name).or_else(|| e.get(&c.to_string())))
                    .copied()
                    .unwrap_or(1.0)
            })
            .collect();
        let frame_images = cameras
            .iter()
            .map(|&c| frames.get(&scene.cameras[c].name).cloned().flatten())
            .collect();
        let mut p = Problem::without_targets(scene, cameras, set);
        p.exposure = exposure;
        p.frame_images = frame_images;
        p.white_balance_learning_rate = task
            .optimizer
            .optimize_white_balance
            .then_some(task.optimizer.white_balance_learning_rate);
        if let Some(spec) = &task.environment {
            let start = spec.start(&task.base)?;
            p.scene.env_bilinear = spec.filter == Some(crate::vocab::Filter::Bilinear);
            if spec.optimize {
                p.recover_environment(start, spec.fit.clone())
                    .map_err(|e| Error::file(&task.path, e.to_string()))?;
            } else {
                p.scene.env = Some(start);
            }
        }
        Ok(p)
    }

    /// Load a task's scenes, find its cameras, render or load its targets, and lay out its
    /// textures. Rendered targets are saved in `out` as `target_CAMERA.exr` with
    /// `targets.key`, a hash of everything they depend on (the task file, the ground-truth
    /// scene with its buffers and images, the environment, the camera file); with `reuse`
    /// they are read back from there when the key still matches, instead of rendered again.
    pub fn from_task(gpu: &Gpu, task: &Task, out: &Path, reuse: bool) -> Result<Problem> {
        let mut p = Problem::load(task)?;
        let (w, h) = (task.width, task.height);
        let cached: Vec<_> = p
            .cameras
            .iter()
            .map(|&cam| out.join(format!("target_{}.exr", camera_file_name(&p.scene, cam))))
            .collect();
        let in_task = |e: Error| match e {
            Error::Invalid(m) => Error::file(&task.path, m),
            e => e,
        };
        if let Some(path) = &task.target.scene {
            let (truth, _, _) = task_scene(task, path)?;
            let key = format!("{:016x}\n", targets_key(task, path)?);
            let key_path = out.join("targets.key");
            let fresh = std::fs::read_to_string(&key_path).is_ok_and(|k| k == key)
                && cached.iter().all(|c| c.exists());
            if reuse && fresh {
                log::info!("reading the rendered targets back from {}", out.display());
                p.set_truth(truth).map_err(in_task)?;
                for c in &cached {
                    p.targets.push(image_io::load_linear(c)?);
                }
            } else {
                p.render_targets(gpu, truth, w, h, task.target.spp, task.seed)
                    .map_err(in_task)?;
                for (img, c) in p.targets.iter().zip(&cached) {
                    img.save(c)?;
                }
                // The key last: a kill between the images and the key leaves no key.
                image_io::write_atomic(&key_path, key.as_bytes())?;
            }
        } else {
            for (k, &cam) in p.cameras.iter().enumerate() {
                let name = p.scene.cameras[cam].name.clone();
                let listed = task
                    .target
                    .images
                    .as_ref()
                    .and_then(|m| m.get(&name).or_else(|| m.get(&cam.to_string())))
                    .map(|f| task.resolve(f));
                let path = listed
                    .or_else(|| p.frame_images[k].clone())
                    .ok_or_else(|| {
                        Error::file(
                            &task.path,
                            format!(
                            "`target.images`: no image for camera `{name}` (and no camera-file \
                             frame gives one)"
                        ),
                        )
                    })?;
                let (img, alpha) = image_io::load_linear_alpha(&path)?;
                if (img.width, img.height) != (w, h) {
                    return Err(Error::file(
                        &path,
                        format!(
                            "target is {}x{}, the task renders {w}x{h} (set the task's width \
                             and height to the photos' size, or resize the photos)",
                            img.width, img.height
                        ),
                    ));
                }
                p.targets.push(img);
                if alpha.is_some() {
                    log::info!("{}: its alpha channel masks the loss", path.display());
                }
                p.masks[k] = alpha;
            }
        }
        // Explicit masks.
        if let Some(masks) = &task.target.masks {
            for (k, &cam) in p.cameras.iter().enumerate() {
                let name = &p.scene.cameras[cam].name;
                if let Some(f) = masks.get(name).or_else(|| masks.get(&cam.to_string())) {
                    let path = task.resolve(f);
                    let (mw, mh, m) = image_io::load_mask(&path)?;
                    if (mw, mh) != (w, h) {
                        return Err(Error::file(
                            &path,
                            format!("mask is {mw}x{mh}, the task renders {w}x{h}"),
                        ));
                    }
                    p.masks[k] = Some(m);
                }
            }
            for key in masks.keys() {
                if !p
                    .cameras
                    .iter()
                    .any(|&c| &p.scene.cameras[c].name == key || c.to_string() == *key)
                {
                    return Err(Error::file(
                        &task.path,
                        format!("`target.masks`: `{key}` is not a camera of the task"),
                    ));
                }
            }
        }
        Ok(p)
    }
}

/// FNV-1a, 64 bits: a cache key that stays the same across runs and builds.
fn fnv1a(h: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *h ^= b as u64;
        *h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    // Separate the parts, so that moving bytes between them changes the key.
    *h ^= bytes.len() as u64;
    *h = h.wrapping_mul(0x0000_0100_0000_01b3);
}

/// The key of a task's rendered targets: the task file, everything the ground-truth scene
/// at `truth` is made of (its JSON, buffers and images, the environment map, the camera file),
/// and the renderer that drew them (its WGSL sources): targets that an older renderer drew,
/// such as the one whose light sampling of emissive triangles was too dark, are drawn again.
fn targets_key(task: &Task, truth: &Path) -> Result<u64> {
    targets_key_with(task, truth, renderer_fingerprint())
}

/// A hash of every WGSL source the passes are built from.
fn renderer_fingerprint() -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for (name, source) in crate::shader_library::sources() {
        fnv1a(&mut h, name.as_bytes());
        fnv1a(&mut h, source.as_bytes());
    }
    h
}

fn targets_key_with(task: &Task, truth: &Path, renderer: u64) -> Result<u64> {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    fnv1a(&mut h, &renderer.to_le_bytes());
    let text = std::fs::read(&task.path).unwrap_or_default();
    fnv1a(&mut h, &text);
    // What the targets depend on as parsed too, for tasks built in code (their file may not
    // exist: a Python dict's cameras, lights or captures' lights would otherwise reuse
    // another task's targets). Not the optimizer's settings: a run resumed with other
    // limits reads its targets back.
    let t = task;
    let scene = (
        &t.scene,
        &t.env,
        t.env_scale,
        t.default_environment,
        &t.lights,
    );
    let views = (&t.cameras, &t.camera_defs, &t.cameras_file);
    let render = (t.width, t.height, t.seed, t.max_depth, &t.target);
    fnv1a(&mut h, format!("{scene:?}{views:?}{render:?}").as_bytes());
    let (json, buffers, images) = scene::load_source(&task.resolve(truth))?;
    fnv1a(&mut h, json.to_string().as_bytes());
    for b in &buffers {
        fnv1a(&mut h, b);
    }
    for i in images.iter().flatten() {
        fnv1a(&mut h, i);
    }
    for extra in [&task.env, &task.cameras_file].into_iter().flatten() {
        let p = task.resolve(extra);
        if p.is_file() {
            fnv1a(
                &mut h,
                &std::fs::read(&p).map_err(|e| Error::file(&p, e.to_string()))?,
            );
        } else if p.is_dir() {
            for f in ["cameras.txt", "images.txt"] {
                fnv1a(&mut h, &std::fs::read(p.join(f)).unwrap_or_default());
            }
        }
    }
    Ok(h)
}

/// Each camera-file frame's image (if it names one), by camera name.
type FrameImages = std::collections::BTreeMap<String, Option<std::path::PathBuf>>;

/// A task's scene: the file at `path`, the task's environment, lights and cameras, the
/// frames of its camera file, and defaults for what is still missing. Also returns the
/// indices of the cameras the task added and each camera-file frame's image by camera name.
fn task_scene(task: &Task, path: &Path) -> Result<(Scene, Vec<usize>, FrameImages)> {
    let mut s = scene::load(&task.resolve(path))?;
    s.max_depth = scene::MaxDepth::new(task.max_depth)
        .map_err(|m| Error::file(&task.path, format!("`max_depth`: {m}")))?;
    if let Some(env) = &task.env {
        let mut e = EnvMap::load(&task.resolve(env))?;
        e.scale = task.env_scale;
        s.env = Some(e);
    }
    for (i, l) in task.lights.iter().enumerate() {
        s.lights.push(l.light(i));
    }
    let first = s.cameras.len();
    for c in &task.camera_defs {
        s.cameras.push(c.camera(task.width, task.height));
    }
    let mut frames = std::collections::BTreeMap::new();
    if let Some(f) = &task.cameras_file {
        for fr in scene::capture::load_frames(&task.resolve(f))? {
            frames.insert(fr.camera.name.clone(), fr.image);
            s.cameras.push(fr.camera);
        }
    }
    let added: Vec<usize> = (first..s.cameras.len()).collect();
    capture_lights(task, &mut s)?;
    // Camera names must be unique: targets, masks and `cameras` refer to them.
    for (i, c) in s.cameras.iter().enumerate() {
        if s.cameras[..i].iter().any(|o| o.name == c.name) {
            return Err(Error::file(
                &task.path,
                format!(
                    "two cameras are named `{}` (the scene's, the task's `[[camera]]` tables \
                     and the camera file's frames share one namespace)",
                    c.name
                ),
            ));
        }
    }
    for note in s.add_defaults(task.default_environment) {
        log::warn!("{}: {note}", s.source.display());
    }
    Ok((s, added, frames))
}

/// The lights of each camera's capture that `target.lights` names.
fn capture_lights(task: &Task, s: &mut Scene) -> Result<()> {
    for (cam, names) in task.target.lights.iter().flatten() {
        let key = format!("target.lights.{cam}");
        let bad = |m: String| Error::file(&task.path, format!("`{key}`: {m}"));
        let c = s
            .cameras
            .iter()
            .position(|c| &c.name == cam)
            .ok_or_else(|| bad(format!("the scene and the task have no camera `{cam}`")))?;
        let lights = s.light_indices(names).map_err(bad)?;
        s.cameras[c].lights = Some(lights);
    }
    Ok(())
}

/// `<index>_<name>` of a camera, safe in file names.
pub(crate) fn camera_file_name(scene: &Scene, cam: usize) -> String {
    format!("{cam}_{}", image_io::file_safe(&scene.cameras[cam].name))
}

impl crate::optim::DiffRender {
    /// A differentiable render of `task`'s scene, cameras, image size, depth and parameters
    /// (the textures at their initial values, the environment when the task recovers it,
    /// the cameras' exposures and white balances), with the task's gradient samples per
    /// pixel, seed, primal, step, priors and schedule and the estimator `method` (`auto`
    /// resolves the whole configuration as for an optimization of the task) with the
    /// task's estimator options over `extra`. The task's targets are not loaded: the loss is
    /// the caller's ([`Problem::from_task`] gives them). Returns the problem it was made
    /// from too (its scene, cameras and texture layout).
    pub fn for_task(
        gpu: &Gpu,
        task: &Task,
        method: crate::optim::MethodChoice,
        extra: &crate::optim::EstimatorOptions,
    ) -> Result<(crate::optim::DiffRender, Problem)> {
        let problem = Problem::load(task)?;
        let choice = crate::task::task_method(task, method, problem.cameras.len());
        if choice.automatic {
            log::info!(
                "gradient estimator: {} ({})",
                choice.method.name(),
                choice.reason
            );
        }
        let settings = crate::task::task_settings(task, &problem.cameras, choice.method, extra);
        let mut op =
            crate::optim::DiffRender::new(gpu, &problem.scene, problem.set.clone(), settings)?;
        // The targets and their masks belong to the caller's loss.
        problem.set_camera_and_light(op.optimizer_mut())?;
        Ok((op, problem))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_targets_key_changes_with_the_renderer() {
        let task = Task::load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenes/default/task.toml"
        )))
        .unwrap();
        let truth = task.target.scene.clone().unwrap();
        let now = targets_key(&task, &truth).unwrap();
        assert_eq!(now, targets_key(&task, &truth).unwrap());
        assert_eq!(
            now,
            targets_key_with(&task, &truth, renderer_fingerprint()).unwrap()
        );
        // Any other renderer (here: a fingerprint with one bit flipped) keys other targets.
        let other = targets_key_with(&task, &truth, renderer_fingerprint() ^ 1).unwrap();
        assert_ne!(now, other);
    }
}
