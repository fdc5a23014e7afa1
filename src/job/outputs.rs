//! What a run writes besides its metrics: the textures (EXR and PNG), `optimized.glb`, each
//! camera's result beside its target, the plot, the observed-texel masks, and the gradient
//! images of `psrestir gradient`.
use super::metrics::{exposed, write_metrics};
use super::problem::camera_file_name;
use super::Problem;
use crate::gpu::Gpu;
use crate::image_io::{self, Image};
use crate::optim::checkpoint::MetricRow;
use crate::optim::Optimizer;
use crate::render::params::ParamSet;
use crate::task::{task_method, task_settings, Task};
use crate::vocab::Slot;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Texture `i` of `values` as an image: RGB for base color and normal maps, gray for
/// scalars.
pub fn texture_image(set: &ParamSet, values: &[f32], i: usize) -> Image {
    let t = &set.textures[i];
    let v = &values[t.offset as usize..t.offset as usize + t.len()];
    let rgb = match t.channels() {
        3 => v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        _ => v.iter().map(|&x| [x; 3]).collect(),
    };
    Image {
        width: t.width,
        height: t.height,
        rgb,
    }
}

/// `bytes` (RGB8, `img`'s size) as a PNG at `path`, atomically.
fn save_png(path: &Path, img: &Image, bytes: Vec<u8>) -> Result<()> {
    let png = image::RgbImage::from_raw(img.width, img.height, bytes)
        .ok_or_else(|| Error::Invalid("texture size mismatch".into()))?;
    image_io::write_atomic_with(path, |tmp| {
        png.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
}

/// Save each texture as EXR (linear) and PNG (sRGB for base color, linear otherwise: a
/// normal map's RGB as glTF stores it, gray for scalars).
pub fn save_textures(dir: &Path, set: &ParamSet, values: &[f32]) -> Result<()> {
    for i in 0..set.textures.len() {
        let t = &set.textures[i];
        let img = texture_image(set, values, i);
        img.save(&dir.join(format!("{}.exr", t.name())))?;
        let bytes: Vec<u8> = match t.slot {
            Slot::BaseColor => img.to_srgb8(),
            _ => img
                .rgb
                .iter()
                .flat_map(|p| p.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
                .collect(),
        };
        save_png(&dir.join(format!("{}.png", t.name())), &img, bytes)?;
    }
    Ok(())
}

/// `uncertainty_<texture>.exr` and `.png`: each texel's standard deviation from
/// [`uncertainty::standard_deviations`](crate::optim::uncertainty::standard_deviations) (laid out like the values), -1 where the images tell nothing (no
/// camera observes the texel, or it never received a gradient). The PNG is a gray scale up to
/// the other texels' 99th percentile (white: at or above it), magenta where it is -1.
pub fn save_uncertainty(dir: &Path, set: &ParamSet, sigma: &[f32]) -> Result<()> {
    use crate::optim::uncertainty::UNOBSERVED;
    for i in 0..set.textures.len() {
        let t = &set.textures[i];
        let img = texture_image(set, sigma, i);
        img.save(&dir.join(format!("uncertainty_{}.exr", t.name())))?;
        let per_texel: Vec<Option<f32>> = img
            .rgb
            .iter()
            .map(|p| (p[0] != UNOBSERVED).then(|| (p[0] + p[1] + p[2]) / 3.0))
            .collect();
        let mut finite: Vec<f32> = per_texel
            .iter()
            .flatten()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        finite.sort_by(f32::total_cmp);
        let top = finite
            .get((finite.len() as f64 * 0.99) as usize)
            .or(finite.last())
            .copied()
            .filter(|v| *v > 0.0)
            .unwrap_or(1.0);
        let bytes: Vec<u8> = per_texel
            .iter()
            .flat_map(|v| match v {
                None => [255, 0, 255],
                Some(v) => [((v / top).min(1.0) * 255.0 + 0.5) as u8; 3],
            })
            .collect();
        save_png(
            &dir.join(format!("uncertainty_{}.png", t.name())),
            &img,
            bytes,
        )?;
    }
    Ok(())
}

pub(super) fn write_outputs(
    out: &Path,
    task: &Task,
    prep: &Problem,
    opt: &Optimizer,
    values: &[f32],
    rows: &[MetricRow],
) -> Result<()> {
    save_textures(out, &prep.set, values)?;
    write_metrics(&out.join("metrics.csv"), rows)?;
    plot_metrics(&out.join("plot.png"), task, rows, prep.reference.is_some())?;
    for (k, &cam) in prep.cameras.iter().enumerate() {
        let img = opt.render(
            k,
            task.target.spp.min(64),
            crate::optim::pass_seed(task.seed, u32::MAX - 1, k as u32, crate::optim::Seeds::EVAL),
        )?;
        let img = exposed(img, opt.fit().gains()[k]);
        img.save(&out.join(format!("final_{}.exr", camera_file_name(&prep.scene, cam))))?;
        image_io::side_by_side(&img, &prep.targets[k]).save(&out.join(format!(
            "final_vs_target_{}.png",
            camera_file_name(&prep.scene, cam)
        )))?;
    }
    crate::job::export::write_glb(
        &task.resolve(&task.scene),
        &out.join("optimized.glb"),
        &prep.scene,
        &prep.set,
        values,
    )
}

/// `plot.png`: the loss and the evaluation renders' image relMSE against time (log scale,
/// with the learning-rate schedule on the right axis), and the texture RMSE (all and
/// observed texels) when the ground truth is known.
pub fn plot_metrics(path: &Path, task: &Task, rows: &[MetricRow], truth: bool) -> Result<()> {
    use crate::job::plot::{Panel, Series};
    let series = |name: &str, color, f: &dyn Fn(&MetricRow) -> Option<f64>| Series {
        name: name.into(),
        color,
        points: rows
            .iter()
            .filter_map(|r| f(r).map(|y| (r.elapsed_s, y)))
            .collect(),
    };
    let mut panels = vec![Panel {
        title: format!(
            "loss ({}) and image relMSE of {}-spp evaluation renders",
            format!("{:?}", task.optimizer.loss).to_lowercase(),
            task.optimizer.eval_spp
        ),
        y_label: "error".into(),
        log_y: true,
        series: vec![
            series("loss", [30, 90, 200], &|r| r.loss),
            series("image relMSE", [20, 150, 60], &|r| r.image_relmse),
        ],
        secondary: Some((
            "learning rate".into(),
            vec![series("learning rate", [140, 140, 140], &|r| {
                r.learning_rate
            })],
        )),
    }];
    if truth {
        panels.push(Panel {
            title: "texture RMSE against the ground truth".into(),
            y_label: "RMSE".into(),
            log_y: true,
            series: vec![
                series("observed texels", [200, 50, 40], &|r| {
                    r.texture_rmse_observed
                }),
                series("all texels", [230, 150, 60], &|r| r.texture_rmse),
            ],
            secondary: None,
        });
    }
    crate::job::plot::plot(path, "seconds of optimization", &panels)
}

/// `observed_TEXTURE.png` per texture: white where a camera sample reaches the texel, black
/// where none does (those texels keep their initial values).
pub fn save_observed(dir: &Path, set: &ParamSet, observed: &[bool]) -> Result<()> {
    let mut first = 0usize;
    for t in &set.textures {
        let n = (t.width * t.height) as usize;
        let px: Vec<u8> = observed[first..first + n]
            .iter()
            .map(|&o| if o { 255 } else { 0 })
            .collect();
        first += n;
        let img = image::GrayImage::from_raw(t.width, t.height, px)
            .ok_or_else(|| Error::Invalid("observed mask size".into()))?;
        let path = dir.join(format!("observed_{}.png", t.name()));
        image_io::write_atomic_with(&path, |tmp| {
            img.save_with_format(tmp, image::ImageFormat::Png)
                .map_err(std::io::Error::other)
        })?;
    }
    Ok(())
}

/// One gradient estimate at the task's initial textures, written to `dir` per texture as
/// `<texture>_gradient.exr` (linear, signed) and `<texture>_gradient.png` (signed false color:
/// red positive, blue negative, scaled by the largest magnitude). Returns the files written.
pub fn write_gradient(
    gpu: &Gpu,
    task: &Task,
    dir: &Path,
    method: crate::optim::MethodChoice,
    options: &crate::optim::EstimatorOptions,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    let prep = Problem::from_task(gpu, task, dir, false)?;
    let choice = task_method(task, method, prep.cameras.len());
    if choice.automatic {
        log::info!("gradient estimator: {} ({})", choice.method, choice.reason);
    }
    let settings = task_settings(task, &prep.cameras, choice.method, options);
    let mut opt = Optimizer::for_problem(gpu, &prep, settings)?;
    let (grad, _) = opt.estimate_gradient(0)?;
    let mut written = Vec::new();
    for i in 0..prep.set.textures.len() {
        let t = &prep.set.textures[i];
        let img = texture_image(&prep.set, &grad, i);
        let exr = dir.join(format!("{}_gradient.exr", t.name()));
        img.save(&exr)?;
        let v = gradient_scalars(&prep.set, &grad, i);
        let scale = v.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-30);
        let bytes: Vec<u8> = v.iter().flat_map(|&x| false_color(x / scale)).collect();
        let png = dir.join(format!("{}_gradient.png", t.name()));
        let im = image::RgbImage::from_raw(img.width, img.height, bytes)
            .ok_or_else(|| Error::Invalid("size".into()))?;
        image_io::write_atomic_with(&png, |tmp| {
            im.save_with_format(tmp, image::ImageFormat::Png)
                .map_err(std::io::Error::other)
        })?;
        written.push(exr);
        written.push(png);
    }
    Ok(written)
}

/// One signed number per texel of texture `i` of a gradient: the luminance-weighted sum of
/// the channels for base color, their sum for a normal map, the value for scalar textures.
pub fn gradient_scalars(set: &ParamSet, g: &[f32], i: usize) -> Vec<f32> {
    let img = texture_image(set, g, i);
    let slot = set.textures[i].slot;
    img.rgb
        .iter()
        .map(|p| match slot {
            Slot::BaseColor => p[0] * 0.2126 + p[1] * 0.7152 + p[2] * 0.0722,
            Slot::Normal => p[0] + p[1] + p[2],
            _ => p[0],
        })
        .collect()
}

/// Signed value in [-1, 1] to a diverging color: blue (negative), white (0), red (positive).
pub fn false_color(v: f32) -> [u8; 3] {
    let a = v.clamp(-1.0, 1.0).abs().sqrt();
    let fade = ((1.0 - a) * 255.0) as u8;
    if v >= 0.0 {
        [255, fade, fade]
    } else {
        [fade, fade, 255]
    }
}
