//! Observed texels (src/optim/observed_texels.wgsl): which texels of the optimized textures a
//! camera sample of the task can reach, computed once per optimizer. The others get no
//! gradient, keep their initial values, and are not determined by the images, so texture
//! errors are reported over the observed ones as well ([`rmse_observed`]).
use crate::render::layout::GpuCameraInfo;
use crate::render::params::ParamSet;
use crate::render::WORKGROUP;
use crate::vocab::Slot;
use crate::Result;
use bytemuck::{Pod, Zeroable};

/// Group 1 of `observed_texels.wgsl`.
pub(crate) const OBSERVED_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "observed_texels",
    group: 1,
    names: &["op", "observed"],
};

/// `ObservedParams` in src/optim/observed_texels.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ObservedParams {
    pub camera: GpuCameraInfo,
    pub strata: u32,
    pub stride: u32,
    pub _pad: [u32; 2],
}

/// Rays per pixel side: 4 x 4 positions spread over each pixel.
pub const STRATA: u32 = 4;

/// Which texels of the optimized textures of `scene` the cameras `cameras` observe (tiled in
/// `grid` workgroups per image), and the GPU buffer the flags were read from (one `u32` per
/// texel, nonzero where observed).
pub(crate) fn observed_mask(
    gpu: &crate::gpu::Gpu,
    scene: &crate::render::GpuScene,
    cameras: &[GpuCameraInfo],
    grid: (u32, u32),
) -> Result<(Vec<bool>, wgpu::Buffer)> {
    let layout = gpu.pass_layout("observed_texels", 1)?;
    let pipeline = scene.pipeline(gpu, "observed_texels", &[&scene.layout, &layout])?;
    let n_texels = scene.n_texels as u64;
    let mask = gpu.storage_zeroed("observed texels", n_texels * 4);
    for (k, camera) in cameras.iter().enumerate() {
        let params = ObservedParams {
            camera: *camera,
            strata: STRATA,
            stride: grid.0 * WORKGROUP,
            _pad: [0; 2],
        };
        let uniform = gpu.uniform(
            &format!("observed_texels params {k}"),
            bytemuck::bytes_of(&params),
        );
        let group = gpu.bind(
            &OBSERVED_GROUP,
            "observed_texels",
            &layout,
            &[("op", &uniform), ("observed", &mask)],
        );
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("observed_texels"),
            });
        crate::gpu::encode_pass(
            &mut enc,
            "observed_texels",
            &pipeline,
            &[&scene.bind_group, &group],
            grid,
        );
        gpu.queue.submit([enc.finish()]);
    }
    let words: Vec<u32> = gpu.read_pod(&mask)?;
    gpu.check("observed_texels")?;
    let m = words[..n_texels as usize].iter().map(|&w| w != 0).collect();
    Ok((m, mask))
}

/// RMSE of `values` against `truth` (laid out like `set.values`) over every channel, normal
/// maps as the renderer sees them ([`ParamSet::as_seen`]).
pub fn texture_rmse(set: &ParamSet, values: &[f32], truth: &[f32]) -> f64 {
    let (a, b) = (set.as_seen(values), set.as_seen(truth));
    let s: f64 = a
        .iter()
        .zip(b.iter())
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum();
    (s / a.len().max(1) as f64).sqrt()
}

/// RMSE of `values` against `truth` (laid out like `set.values`) over the channels of the
/// texels marked in `observed` (one flag per texel, as
/// [`Optimizer::observed_texels`](crate::optim::Optimizer::observed_texels)); NaN when none is
/// observed.
pub fn rmse_observed(set: &ParamSet, values: &[f32], truth: &[f32], observed: &[bool]) -> f64 {
    let (s, n) = squared_errors_observed(set, values, truth, observed)
        .into_iter()
        .fold((0.0, 0usize), |(s, n), (ts, tn)| (s + ts, n + tn));
    if n == 0 {
        return f64::NAN;
    }
    (s / n as f64).sqrt()
}

/// [`rmse_observed`] of each texture of `set` alone, in order (NaN for a texture no camera
/// observes): which texture the error is in, where a task has several.
pub fn rmse_observed_per_texture(
    set: &ParamSet,
    values: &[f32],
    truth: &[f32],
    observed: &[bool],
) -> Vec<f64> {
    squared_errors_observed(set, values, truth, observed)
        .into_iter()
        .map(|(s, n)| {
            if n == 0 {
                f64::NAN
            } else {
                (s / n as f64).sqrt()
            }
        })
        .collect()
}

/// Per texture, for a normal map ([`Slot::Normal`]) the mean angle in degrees between the
/// normals that its observed texels and the truth's stand for
/// ([`crate::vocab::decode_normal`]); None for other slots or without an observed texel.
pub fn mean_angle_observed_per_texture(
    set: &ParamSet,
    values: &[f32],
    truth: &[f32],
    observed: &[bool],
) -> Vec<Option<f64>> {
    let mut texel = 0usize;
    let mut out = Vec::with_capacity(set.textures.len());
    for t in &set.textures {
        let n_texels = (t.width * t.height) as usize;
        let angles: Vec<f64> = (0..n_texels)
            .filter(|&local| {
                t.slot == Slot::Normal && observed.get(texel + local).copied().unwrap_or(false)
            })
            .map(|local| {
                let b = t.offset as usize + local * 3;
                let rgb = |v: &[f32]| [v[b], v[b + 1], v[b + 2]];
                crate::vocab::normal_angle_deg(rgb(values), rgb(truth))
            })
            .collect();
        texel += n_texels;
        out.push((!angles.is_empty()).then(|| angles.iter().sum::<f64>() / angles.len() as f64));
    }
    out
}

/// Per texture, the sum of squared errors over its observed texels' channels and their count
/// (normal maps as the renderer sees them, [`ParamSet::as_seen`]).
fn squared_errors_observed(
    set: &ParamSet,
    values: &[f32],
    truth: &[f32],
    observed: &[bool],
) -> Vec<(f64, usize)> {
    let (values, truth) = (&*set.as_seen(values), &*set.as_seen(truth));
    let mut texel = 0usize;
    let mut out = Vec::with_capacity(set.textures.len());
    for t in &set.textures {
        let (mut s, mut n) = (0.0, 0usize);
        let ch = t.channels() as usize;
        for local in 0..(t.width * t.height) as usize {
            if observed.get(texel + local).copied().unwrap_or(false) {
                let base = t.offset as usize + local * ch;
                for c in base..base + ch {
                    s += ((values[c] - truth[c]) as f64).powi(2);
                    n += 1;
                }
            }
        }
        texel += (t.width * t.height) as usize;
        out.push((s, n));
    }
    out
}

/// The number of observed texels and of all texels.
pub fn observed_count(observed: &[bool]) -> (usize, usize) {
    (observed.iter().filter(|&&o| o).count(), observed.len())
}
