//! The exchange folder a peer renderer reads: a bench task's ground-truth scene as psrestir
//! loaded it (world-space triangles per material, cameras, lights, the environment, decoded
//! images), the optimized textures with their start, truth and observed texels, psrestir's
//! targets, and the run's budget, schedule, learning rates and smoothness prior.
//!
//! Everything is written from psrestir's own loaded [`Scene`], so the peer reads the scene
//! exactly as psrestir reads it (node transforms baked, lights resolved, the default
//! environment added); only the mapping onto the peer's own scene description is the peer
//! script's. `scene.json` names every other file; arrays are raw little-endian (`f32` or
//! `u8`), row 0 first, their shapes in the JSON.
use crate::job::Problem;
use crate::scene::{PunctualKind, Scene, TextureSlot, Wrap};
use crate::task::Task;
use crate::{Error, Result};
use serde::Serialize;
use std::path::Path;

/// Version of the folder's layout, checked by the peer script.
pub const EXCHANGE_VERSION: u32 = 1;

/// `scene.json`.
#[derive(Serialize)]
pub struct Exchange {
    /// [`EXCHANGE_VERSION`].
    pub version: u32,
    /// Vertices of a camera path (1: direct light only), as psrestir counts them.
    pub max_depth: u32,
    /// Image size of every camera.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The cameras rendered every iteration, in the order of the targets.
    pub cameras: Vec<CameraOut>,
    /// Punctual lights.
    pub lights: Vec<LightOut>,
    /// The environment (its scale multiplied in), if any.
    pub environment: Option<EnvironmentOut>,
    /// Every material, by index.
    pub materials: Vec<MaterialOut>,
    /// Decoded images (RGBA8), by index.
    pub images: Vec<ArrayOut>,
    /// One triangle mesh per material that has triangles (`ply`, world space, unshared
    /// vertices with normals and texture coordinates).
    pub meshes: Vec<MeshOut>,
    /// The optimized textures, in task order.
    pub optimized: Vec<OptimizedOut>,
    /// psrestir's targets (linear RGB, `f32`, height x width x 3), per camera.
    pub targets: Vec<ArrayOut>,
    /// Samples per pixel of the targets.
    pub target_spp: u32,
    /// Samples per pixel of the renders that measure image error.
    pub eval_spp: u32,
    /// The task's primal and gradient samples per pixel.
    pub primal_spp: u32,
    /// Gradient samples per pixel.
    pub gradient_spp: u32,
    /// Seconds of optimization (step time).
    pub budget_s: f64,
    /// The run's seed.
    pub seed: u32,
    /// The learning-rate schedule (as in a task file).
    pub schedule: crate::optim::Schedule,
    /// The smoothness prior's weight of the task (0: off), for the peer's row with priors.
    pub smoothness: f32,
    /// The image loss (`l2`, `relmse`, `srgb`, `log`).
    pub loss: String,
}

/// A camera: its world matrix (column-major; glTF's, looking down -Z with +Y up).
#[derive(Serialize)]
pub struct CameraOut {
    /// Name.
    pub name: String,
    /// Column-major 4 x 4.
    pub world: [f32; 16],
    /// Vertical field of view (radians).
    pub yfov: f32,
    /// The punctual lights on in its capture (indices into `lights`); None: all of them.
    /// Emitting surfaces and the environment light every camera.
    pub lights: Option<Vec<usize>>,
}

/// A punctual light.
#[derive(Serialize)]
pub struct LightOut {
    /// `point`, `spot` or `directional`.
    pub kind: &'static str,
    /// World position.
    pub position: [f32; 3],
    /// The direction it points to.
    pub direction: [f32; 3],
    /// Colour x intensity (candela; lux for a directional light).
    pub intensity: [f32; 3],
    /// Spot cone angles (radians).
    pub inner_cone: f32,
    /// Outer cone angle.
    pub outer_cone: f32,
}

/// The environment: `f32` linear RGB, height x width x 3, row 0 at the zenith,
/// u = atan2(x, -z) / 2 pi, v = acos(y) / pi.
#[derive(Serialize)]
pub struct EnvironmentOut {
    /// The array.
    pub radiance: ArrayOut,
    /// Looked up bilinearly (else at the nearest texel).
    pub bilinear: bool,
}

/// A raw array file and its shape.
#[derive(Serialize)]
pub struct ArrayOut {
    /// File name in the folder.
    pub file: String,
    /// `f32` or `u8`.
    pub dtype: &'static str,
    /// Its shape (rows first).
    pub shape: Vec<usize>,
}

/// A texture as a material slot uses it.
#[derive(Serialize)]
pub struct TextureOut {
    /// Index into `images`.
    pub image: usize,
    /// Wrap in u and v (`repeat`, `clamp`, `mirror`).
    pub wrap: [&'static str; 2],
    /// Nearest texel (else bilinear).
    pub nearest: bool,
    /// KHR_texture_transform as a 2 x 3 matrix on (u, v, 1).
    pub transform: [[f32; 3]; 2],
}

/// A glTF material as psrestir reads it.
#[derive(Serialize)]
pub struct MaterialOut {
    /// Name.
    pub name: String,
    /// Base color factor (linear RGBA).
    pub base_color: [f32; 4],
    /// Base color texture (sRGB).
    pub base_color_texture: Option<TextureOut>,
    /// Metallic factor.
    pub metallic: f32,
    /// Roughness factor.
    pub roughness: f32,
    /// Metallic (B) and roughness (G) texture (linear).
    pub metallic_roughness_texture: Option<TextureOut>,
    /// Emitted radiance (factor x strength).
    pub emissive: [f32; 3],
    /// Emissive texture (sRGB).
    pub emissive_texture: Option<TextureOut>,
    /// Its normal map (linear, tangent space).
    pub normal_texture: Option<TextureOut>,
    /// The normal map's X and Y scale.
    pub normal_scale: f32,
    /// The handedness of its triangles' tangent frames (the bitangent is cross(n, t) times
    /// it): 1 or -1 where every vertex agrees, 0 where they differ or have no tangent.
    pub tangent_sign: f32,
    /// Seen and emitting from both sides.
    pub double_sided: bool,
}

/// A mesh file of one material.
#[derive(Serialize)]
pub struct MeshOut {
    /// Index into `materials`.
    pub material: usize,
    /// File name (`ply`).
    pub file: String,
    /// Triangles.
    pub triangles: usize,
}

/// An optimized texture: `f32` arrays height x width x channels (row 0 at v = 0), the
/// observed texels `u8` height x width (1: a camera sample reaches it).
#[derive(Serialize)]
pub struct OptimizedOut {
    /// Index into `materials`.
    pub material: usize,
    /// `base_color`, `roughness`, `metallic` or `normal`.
    pub slot: String,
    /// Looked up at the nearest texel (else bilinearly).
    pub nearest: bool,
    /// Its starting values.
    pub init: ArrayOut,
    /// The ground truth laid out the same way.
    pub truth: ArrayOut,
    /// Which texels the cameras observe (psrestir's mask, the one its runs are scored on).
    pub observed: ArrayOut,
    /// The baseline's Adam learning rate for it (the task's, or Adam's default for the slot).
    pub learning_rate: f32,
}

fn loss_name(l: crate::vocab::Loss) -> &'static str {
    use crate::vocab::Loss;
    match l {
        Loss::L2 => "l2",
        Loss::Relmse => "relmse",
        Loss::Srgb => "srgb",
        Loss::Log => "log",
    }
}

fn wrap_name(w: Wrap) -> &'static str {
    match w {
        Wrap::Repeat => "repeat",
        Wrap::Clamp => "clamp",
        Wrap::Mirror => "mirror",
    }
}

fn texture(t: &Option<TextureSlot>) -> Option<TextureOut> {
    t.as_ref().map(|t| TextureOut {
        image: t.image,
        wrap: [wrap_name(t.wrap_s), wrap_name(t.wrap_t)],
        nearest: t.nearest,
        transform: t.transform,
    })
}

/// Write `values` (raw `f32`, little-endian) as `file` in `dir`.
fn write_f32(dir: &Path, file: &str, shape: Vec<usize>, values: &[f32]) -> Result<ArrayOut> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    crate::image_io::write_atomic(&dir.join(file), &bytes)?;
    Ok(ArrayOut {
        file: file.into(),
        dtype: "f32",
        shape,
    })
}

fn write_u8(dir: &Path, file: &str, shape: Vec<usize>, bytes: &[u8]) -> Result<ArrayOut> {
    crate::image_io::write_atomic(&dir.join(file), bytes)?;
    Ok(ArrayOut {
        file: file.into(),
        dtype: "u8",
        shape,
    })
}

/// A binary little-endian PLY of `tris` (three vertices each: position, normal, uv).
fn ply(tris: &[&crate::scene::Triangle]) -> Vec<u8> {
    let n = tris.len();
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property float u\nproperty float v\n\
         element face {n}\nproperty list uchar uint vertex_indices\nend_header\n",
        3 * n
    )
    .into_bytes();
    for t in tris {
        for k in 0..3 {
            let v = [
                t.p[k].x, t.p[k].y, t.p[k].z, t.n[k].x, t.n[k].y, t.n[k].z, t.uv[k].x, t.uv[k].y,
            ];
            out.extend(v.iter().flat_map(|f| f.to_le_bytes()));
        }
    }
    for i in 0..n as u32 {
        out.push(3);
        for k in 0..3 {
            out.extend((3 * i + k).to_le_bytes());
        }
    }
    out
}

/// Why `prep` cannot go to a peer, if it cannot: no ground-truth scene (photos), cameras
/// with pixel intrinsics, or a target scene whose geometry differs from the optimized one.
pub fn unsupported(prep: &Problem) -> Option<String> {
    let Some(truth) = &prep.truth else {
        return Some("its targets are photos (a peer needs the ground-truth scene)".into());
    };
    if truth.triangles.len() != prep.scene.triangles.len() {
        return Some("its target scene's geometry differs from the optimized scene's".into());
    }
    if prep
        .cameras
        .iter()
        .any(|&c| truth.cameras[c].intrinsics.is_some())
    {
        return Some("a camera has pixel intrinsics (only a field of view converts)".into());
    }
    None
}

fn lights(scene: &Scene) -> Vec<LightOut> {
    scene
        .lights
        .iter()
        .map(|l| {
            let (kind, inner_cone, outer_cone) = match l.kind {
                PunctualKind::Point => ("point", 0.0, 0.0),
                PunctualKind::Spot {
                    inner_cone,
                    outer_cone,
                } => ("spot", inner_cone, outer_cone),
                PunctualKind::Directional => ("directional", 0.0, 0.0),
            };
            LightOut {
                kind,
                position: l.position.to_array(),
                direction: l.direction.to_array(),
                intensity: l.intensity.to_array(),
                inner_cone,
                outer_cone,
            }
        })
        .collect()
}

/// The handedness of material `m`'s tangent frames in `scene` (see
/// [`MaterialOut::tangent_sign`]).
fn tangent_sign(scene: &Scene, m: usize) -> f32 {
    let mut signs = scene
        .triangles
        .iter()
        .filter(|t| t.material as usize == m)
        .flat_map(|t| {
            t.t.iter().map(|v| {
                if v.truncate() == glam::Vec3::ZERO {
                    0.0
                } else {
                    v.w.signum()
                }
            })
        });
    let Some(first) = signs.next() else {
        return 0.0;
    };
    if signs.all(|s| s == first) {
        first
    } else {
        0.0
    }
}

/// The materials of `truth`, the tangent frames those of `scene` (the optimized scene: it
/// has tangents where a normal map is optimized, the truth where its file has one).
fn materials(truth: &Scene, scene: &Scene) -> Vec<MaterialOut> {
    truth
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| MaterialOut {
            name: m.name.clone(),
            base_color: m.base_color.to_array(),
            base_color_texture: texture(&m.base_color_texture),
            metallic: m.metallic,
            roughness: m.roughness,
            metallic_roughness_texture: texture(&m.metallic_roughness_texture),
            emissive: m.emissive.to_array(),
            emissive_texture: texture(&m.emissive_texture),
            normal_texture: texture(&m.normal_texture),
            normal_scale: m.normal_scale,
            tangent_sign: match tangent_sign(scene, i) {
                0.0 => tangent_sign(truth, i),
                s => s,
            },
            double_sided: m.double_sided,
        })
        .collect()
}

/// The geometry, one PLY per material, and the decoded images.
fn geometry(dir: &Path, scene: &Scene) -> Result<(Vec<MeshOut>, Vec<ArrayOut>)> {
    let mut meshes = Vec::new();
    for m in 0..scene.materials.len() {
        let tris: Vec<_> = scene
            .triangles
            .iter()
            .filter(|t| t.material as usize == m)
            .collect();
        if tris.is_empty() {
            continue;
        }
        let file = format!("mesh_{m}.ply");
        crate::image_io::write_atomic(&dir.join(&file), &ply(&tris))?;
        meshes.push(MeshOut {
            material: m,
            file,
            triangles: tris.len(),
        });
    }
    let images = scene
        .images
        .iter()
        .enumerate()
        .map(|(i, im)| {
            let bytes: Vec<u8> = im.rgba.iter().flatten().copied().collect();
            let shape = vec![im.height as usize, im.width as usize, 4];
            write_u8(dir, &format!("image_{i}.bin"), shape, &bytes)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((meshes, images))
}

/// The optimized textures: start, truth and observed texels (`observed`: one flag per texel
/// of all textures, as the bench scores its runs).
fn optimized(
    dir: &Path,
    prep: &Problem,
    observed: &[bool],
    rate: impl Fn(&crate::render::params::ParamTexture) -> f32,
) -> Result<Vec<OptimizedOut>> {
    let truth = prep.reference.as_deref().ok_or_else(|| {
        Error::Invalid("a peer needs the optimized textures' ground truth".into())
    })?;
    let mut texel = 0usize;
    let mut out = Vec::new();
    for (i, t) in prep.set.textures.iter().enumerate() {
        let (w, h, c) = (t.width as usize, t.height as usize, t.channels() as usize);
        let range = t.offset as usize..t.offset as usize + w * h * c;
        let mask: Vec<u8> = observed[texel..texel + w * h]
            .iter()
            .map(|&b| b as u8)
            .collect();
        texel += w * h;
        out.push(OptimizedOut {
            material: t.material as usize,
            slot: t.slot.name().to_string(),
            nearest: t.filter == crate::vocab::Filter::Nearest,
            init: write_f32(
                dir,
                &format!("texture_{i}_init.bin"),
                vec![h, w, c],
                &prep.set.values[range.clone()],
            )?,
            truth: write_f32(
                dir,
                &format!("texture_{i}_truth.bin"),
                vec![h, w, c],
                &truth[range],
            )?,
            observed: write_u8(dir, &format!("texture_{i}_observed.bin"), vec![h, w], &mask)?,
            learning_rate: rate(t),
        });
    }
    Ok(out)
}

/// Write `prep` (a bench task at one seed, `observed` its observed texels) for a peer into
/// `dir`, with `budget_s` seconds of optimization and `settings` (the baseline's: schedule,
/// smoothness prior, learning rates).
pub fn write(
    dir: &Path,
    task: &Task,
    prep: &Problem,
    settings: &crate::optim::Settings,
    observed: &[bool],
    budget_s: f64,
    eval_spp: u32,
) -> Result<()> {
    if let Some(why) = unsupported(prep) {
        return Err(Error::Invalid(format!("not converted: {why}")));
    }
    let truth = prep.truth.as_ref().expect("checked by unsupported");
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let (meshes, images) = geometry(dir, truth)?;
    let environment = match &truth.env {
        Some(env) => {
            let rgb: Vec<f32> = env
                .rgb
                .iter()
                .flat_map(|p| p.map(|v| v * env.scale))
                .collect();
            let shape = vec![env.height as usize, env.width as usize, 3];
            Some(EnvironmentOut {
                radiance: write_f32(dir, "environment.bin", shape, &rgb)?,
                bilinear: truth.env_bilinear,
            })
        }
        None => None,
    };
    let targets = prep
        .targets
        .iter()
        .enumerate()
        .map(|(k, im)| {
            let rgb: Vec<f32> = im.rgb.iter().flatten().copied().collect();
            let shape = vec![im.height as usize, im.width as usize, 3];
            write_f32(dir, &format!("target_{k}.bin"), shape, &rgb)
        })
        .collect::<Result<Vec<_>>>()?;
    let step = crate::optim::StepKind::ADAM;
    let exchange = Exchange {
        version: EXCHANGE_VERSION,
        max_depth: truth.max_depth.get(),
        width: task.width,
        height: task.height,
        cameras: prep
            .cameras
            .iter()
            .map(|&c| {
                let cam = &truth.cameras[c];
                CameraOut {
                    name: cam.name.clone(),
                    world: cam.world.to_cols_array(),
                    yfov: cam.yfov,
                    lights: cam.lights.clone(),
                }
            })
            .collect(),
        lights: lights(truth),
        environment,
        materials: materials(truth, &prep.scene),
        images,
        meshes,
        optimized: optimized(dir, prep, observed, |t| step.texture_rate(t))?,
        targets,
        target_spp: task.target.spp,
        eval_spp,
        primal_spp: settings.primal_spp,
        gradient_spp: settings.gradient_spp,
        budget_s,
        seed: task.seed,
        schedule: settings.schedule.clone(),
        smoothness: settings
            .priors
            .of::<crate::optim::smoothness::SmoothnessOptions>()
            .weight,
        loss: loss_name(settings.loss).into(),
    };
    let json = serde_json::to_vec_pretty(&exchange).map_err(|e| Error::Invalid(e.to_string()))?;
    crate::image_io::write_atomic(&dir.join("scene.json"), &json)
}
