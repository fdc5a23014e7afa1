//! Filtered moments (after Chang et al., "Spatiotemporal Bilateral Gradient Filtering for
//! Inverse Rendering", 2024): before each step, the pair of per-texel arrays the step divides
//! (Adam's first and second moments; the variance step's estimate and its variance) is
//! smoothed in texture space by an edge-stopping à-trous filter (moment_filter.wgsl,
//! levels at tap spacings 1, 2, 4, ...), guided by the current texture so that it does not
//! average across the texture's edges. Neighbouring texels of a real texture are alike, so a
//! texel that drew few or no samples this iteration steps with its neighbours, and one noisy
//! sample is averaged with theirs instead of being kept for many iterations. Texels no camera
//! observes take no part. The step uses `own_weight` x a texel's own pair + the rest x the
//! filtered one, for the step only, or with `write_back` also as Adam's moments.
//! [`reference()`] is the CPU twin that the tests compare against.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::gpu::{encode_timed_pass, Gpu, GroupDecl};
use crate::optim::{PassKind, PassTimer};
use crate::render::params::ParamSet;

/// The most levels (the widest tap spacing is 2^(levels - 1) texels).
pub const MAX_LEVELS: u32 = 8;
/// Levels where a contender of the bench asks for filtered moments and the task sets none
/// (with the default 3 x 3 taps: up to 16 texels apart, reaching 31).
pub const SUGGESTED_LEVELS: u32 = 5;
/// Taps of the cubic B-spline kernel at offsets 0, ±1, ±2 (`h` in the WGSL; 5 x 5 taps).
pub const KERNEL: [f32; 3] = [0.375, 0.25, 0.0625];
/// Taps of the linear B-spline kernel at offsets 0, ±1 (3 x 3 taps).
pub const KERNEL_3: [f32; 3] = [0.5, 0.25, 0.0];
/// Added to a value before its logarithm in log space (`LOG_FLOOR` in the WGSL).
pub const LOG_FLOOR: f32 = 1e-3;
/// A neighbour whose edge factor exp(-d / sigma) is below exp(-MAX_EXPONENT) (about 1e-7)
/// is left out (`MAX_EXPONENT` in the WGSL): it would change nothing, and its loads are
/// saved.
pub const MAX_EXPONENT: f32 = 16.0;

/// The moment filter's options (the task file's `[optimizer.moment_filter]`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct MomentFilterOptions {
    /// À-trous levels (0: off, at most [`MAX_LEVELS`]); level l has taps 2^l texels apart, so
    /// L levels of 5 x 5 taps reach 2^(L+1) - 2 texels, of 3 x 3 taps 2^L - 1.
    pub levels: u32,
    /// Taps per side of each level: 3 (the linear B-spline) or 5 (the cubic one). 3 x 3 taps
    /// are 9 instead of 25: one more level reaches as far for less than half the cost (on the
    /// default task, lavapipe: 9 ms per iteration for 5 levels of 3 x 3, 13-24 ms for 4 of
    /// 5 x 5, of about 100 ms).
    pub taps: u32,
    /// Edge-stopping scale (> 0): a neighbour whose texture values differ by d (the length
    /// over the channels) weighs exp(-d / sigma). Its default, 0.1, is in texture units; the
    /// paper's 0.02 blurred less but ended higher on the default task (measured: 0.120
    /// against 0.116 with 4 levels of 5 x 5 taps).
    pub sigma: f32,
    /// Measure the texture's differences between logarithms (relative differences).
    pub log_space: bool,
    /// Weight of a texel's own (unfiltered) pair in what the step uses, in (0, 1]; the
    /// filtered pair has the rest. Not 0: the filter's kernel passes no texture-wide
    /// checkerboard, so where the texture has no edge yet (a constant start), a filter alone
    /// would leave that part of the error without a step, and the texture could not grow the
    /// edges that stop it.
    pub own_weight: f32,
    /// The mix of own and filtered moments replaces Adam's moments (Adam only); otherwise it
    /// is used for the step alone.
    pub write_back: bool,
}

impl Default for MomentFilterOptions {
    fn default() -> Self {
        MomentFilterOptions {
            levels: 0,
            taps: 3,
            sigma: 0.1,
            log_space: false,
            own_weight: 0.25,
            write_back: false,
        }
    }
}

impl MomentFilterOptions {
    /// Whether the filter is on.
    pub fn enabled(&self) -> bool {
        self.levels > 0
    }

    /// An error naming the field that is out of range.
    pub fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        if self.levels > MAX_LEVELS {
            return Err(("levels", format!("must be between 0 and {MAX_LEVELS}")));
        }
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            return Err(("sigma", "must be a positive number".into()));
        }
        if self.taps != 3 && self.taps != 5 {
            return Err(("taps", "must be 3 or 5".into()));
        }
        if !(self.own_weight > 0.0 && self.own_weight <= 1.0) {
            return Err(("own_weight", "must be in (0, 1]".into()));
        }
        Ok(())
    }
}

/// Group 0 of `moment_filter.wgsl`.
pub(crate) const MOMENT_FILTER_GROUP: GroupDecl = GroupDecl {
    pass: "moment_filter",
    group: 0,
    names: &[
        "fp",
        "src_first",
        "src_second",
        "dst_first",
        "dst_second",
        "params",
        "observed",
    ],
};

/// Workgroup side of the pass (8 x 8 texels).
const WORKGROUP_SIDE: u32 = 8;

/// `MomentFilterParams` in moment_filter.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct MomentFilterParams {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub texel_offset: u32,
    pub spacing: u32,
    pub sigma: f32,
    pub log_space: u32,
    pub radius: i32,
    pub variance_of_mean: u32,
    pub _pad: [u32; 2],
}

/// The pass's parameters for each texture of `set` (`texel_offset` counts the texels of the
/// textures before it) and each level; with `variance_of_mean` the second array is a variance
/// (the variance step's), filtered as the variance of the weighted mean.
pub fn params(
    set: &ParamSet,
    o: &MomentFilterOptions,
    variance_of_mean: bool,
) -> Vec<Vec<MomentFilterParams>> {
    let mut texel_offset = 0;
    set.textures
        .iter()
        .map(|t| {
            let levels = (0..o.levels)
                .map(|l| MomentFilterParams {
                    offset: t.offset,
                    width: t.width,
                    height: t.height,
                    channels: t.channels(),
                    texel_offset,
                    spacing: 1 << l,
                    sigma: o.sigma,
                    log_space: o.log_space as u32,
                    radius: o.taps as i32 / 2,
                    variance_of_mean: variance_of_mean as u32,
                    _pad: [0; 2],
                })
                .collect();
            texel_offset += t.width * t.height;
            levels
        })
        .collect()
}

/// CPU twin of one level on one texture: `first` and `second` hold the pair
/// (`width * height * channels` floats each, filtered in place), `guide` the texture's
/// values laid out alike, `observed` one flag per texel.
pub fn reference(
    p: &MomentFilterParams,
    first: &mut [f32],
    second: &mut [f32],
    guide: &[f32],
    observed: &[bool],
) {
    let (w, h, ch) = (p.width as i64, p.height as i64, p.channels as usize);
    let seen =
        |x: i64, y: i64| x >= 0 && y >= 0 && x < w && y < h && observed[(y * w + x) as usize];
    let g = |t: usize, c: usize| {
        let v = guide[t * ch + c];
        if p.log_space != 0 {
            (v.max(0.0) + LOG_FLOOR).ln()
        } else {
            v
        }
    };
    let (src1, src2) = (first.to_vec(), second.to_vec());
    let s = p.spacing as i64;
    let (r, kernel) = if p.radius == 1 {
        (1i64, KERNEL_3)
    } else {
        (2i64, KERNEL)
    };
    for y in 0..h {
        for x in 0..w {
            if !seen(x, y) {
                continue;
            }
            let t = (y * w + x) as usize;
            let (mut a, mut b, mut weights) = ([0.0f32; 3], [0.0f32; 3], 0.0f32);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (nx, ny) = (x + dx * s, y + dy * s);
                    if !seen(nx, ny) {
                        continue;
                    }
                    let n = (ny * w + nx) as usize;
                    let d2: f32 = (0..ch).map(|c| (g(n, c) - g(t, c)).powi(2)).sum();
                    let e = d2.sqrt() / p.sigma;
                    if e > MAX_EXPONENT {
                        continue;
                    }
                    let wt = kernel[dx.unsigned_abs() as usize]
                        * kernel[dy.unsigned_abs() as usize]
                        * (-e).exp();
                    let wt2 = if p.variance_of_mean != 0 { wt * wt } else { wt };
                    for c in 0..ch {
                        a[c] += wt * src1[n * ch + c];
                        b[c] += wt2 * src2[n * ch + c];
                    }
                    weights += wt;
                }
            }
            let norm = if p.variance_of_mean != 0 {
                weights * weights
            } else {
                weights
            };
            for c in 0..ch {
                first[t * ch + c] = a[c] / weights;
                second[t * ch + c] = b[c] / norm;
            }
        }
    }
}

/// CPU twin of every level on one texture (`levels`: one texture's parameters from
/// [`params()`]), in order.
pub fn reference_levels(
    levels: &[MomentFilterParams],
    first: &mut [f32],
    second: &mut [f32],
    guide: &[f32],
    observed: &[bool],
) {
    for p in levels {
        reference(p, first, second, guide, observed);
    }
}

/// The filter's scratch buffers for `set` (label, bytes), in the order of its two pairs
/// (first, second): each as long as the largest texture. The memory plan counts them and
/// [`MomentFilter::new`] allocates them.
pub(crate) fn memory(set: &ParamSet) -> Vec<(String, u64)> {
    let longest = set.textures.iter().map(|t| t.len()).max().unwrap_or(1) as u64;
    (0..2)
        .flat_map(|k| {
            ["first", "second"].map(|half| (format!("moment filter pair {k} {half}"), 4 * longest))
        })
        .collect()
}

/// The filter over every optimized texture: its pipeline, the two pairs of scratch arrays it
/// ping-pongs between (each as long as the largest texture), and per texture and level a
/// uniform and bind group.
pub(crate) struct MomentFilter {
    pipeline: wgpu::ComputePipeline,
    /// Level l reads pair l % 2 and writes pair (l + 1) % 2.
    pairs: [[wgpu::Buffer; 2]; 2],
    /// Per texture, per level: the bind group (it keeps its uniform alive) and parameters.
    levels: Vec<Vec<(wgpu::BindGroup, MomentFilterParams)>>,
    /// Its options (the step mixes and writes back as they say).
    pub options: MomentFilterOptions,
}

impl MomentFilter {
    /// The filter for `set` with options `o` (levels > 0), guided by the textures in
    /// `params_buf`, over the texels marked in `mask` (the observed-texel buffer: one word
    /// per texel, in the order of `set.textures`); `variance_of_mean` as in [`params()`].
    pub fn new(
        gpu: &Gpu,
        set: &ParamSet,
        (o, variance_of_mean): (&MomentFilterOptions, bool),
        params_buf: &wgpu::Buffer,
        mask: &wgpu::Buffer,
    ) -> Result<MomentFilter> {
        let layout = gpu.pass_layout("moment_filter", 0)?;
        let pipeline = gpu.compute_pipeline("moment_filter", &[&layout])?;
        let b: Vec<wgpu::Buffer> = memory(set)
            .iter()
            .map(|(label, bytes)| gpu.storage_zeroed(label, *bytes))
            .collect();
        let pairs = [[b[0].clone(), b[1].clone()], [b[2].clone(), b[3].clone()]];
        let levels = params(set, o, variance_of_mean)
            .into_iter()
            .zip(&set.textures)
            .map(|(ps, t)| {
                ps.into_iter()
                    .enumerate()
                    .map(|(l, p)| {
                        let u = gpu.uniform(
                            &format!("moment_filter params {} level {l}", t.name()),
                            bytemuck::bytes_of(&p),
                        );
                        let (src, dst) = (&pairs[l % 2], &pairs[(l + 1) % 2]);
                        let g = gpu.bind(
                            &MOMENT_FILTER_GROUP,
                            "moment_filter",
                            &layout,
                            &[
                                ("fp", &u),
                                ("src_first", &src[0]),
                                ("src_second", &src[1]),
                                ("dst_first", &dst[0]),
                                ("dst_second", &dst[1]),
                                ("params", params_buf),
                                ("observed", mask),
                            ],
                        );
                        (g, p)
                    })
                    .collect()
            })
            .collect();
        Ok(MomentFilter {
            pipeline,
            levels,
            options: *o,
            pairs,
        })
    }

    /// The pair a step writes for the filter.
    pub fn input(&self) -> &[wgpu::Buffer; 2] {
        &self.pairs[0]
    }

    /// The pair that holds the filtered values after [`MomentFilter::encode`].
    pub fn output(&self) -> &[wgpu::Buffer; 2] {
        let levels = self.levels.first().map_or(0, |l| l.len());
        &self.pairs[levels % 2]
    }

    /// Record every level on texture `k` (whose pair the step wrote into
    /// [`MomentFilter::input`]).
    pub fn encode(&self, enc: &mut wgpu::CommandEncoder, k: usize, timer: &mut PassTimer) {
        for (g, p) in &self.levels[k] {
            let grid = (
                p.width.div_ceil(WORKGROUP_SIDE),
                p.height.div_ceil(WORKGROUP_SIDE),
            );
            let timing = timer.next(PassKind::Filter);
            encode_timed_pass(enc, "moment_filter", &self.pipeline, &[g], grid, timing);
        }
    }

    /// Dispatches per iteration over all textures.
    pub fn dispatches(&self) -> u32 {
        self.levels.iter().map(|l| l.len() as u32).sum()
    }
}
