//! The parameter-space ReSTIR estimator (`restir_candidates.wgsl`, `restir_merge.wgsl` in
//! this folder, reservoir.wgsl).
//!
//! Every optimized texel keeps two reservoirs, one over the positive and one over the negative
//! part of its target q = target_of(a x e) (shared/params.wgsl: for RGB textures the
//! luminance-weighted sum of the channels' magnitudes, signed by the luminance; the value for
//! scalar textures), where e is a path's factor
//! for the texel, d(BRDF cos L_i)/d(texel) per image channel, and a the pixel's target
//! adjoint, a moving average of the adjoints ([`RestirOptions::target_smoothing`]); the
//! path's value is v = adjoint x e. A reservoir stores a *path* (pixel and camera,
//! the camera ray's hit, the incident direction and radiance), not the random numbers that made
//! it: geometry, cameras and lights never change during a texture optimization, so a stored
//! path stays valid and its value under other textures and another adjoint is one BRDF
//! evaluation. Each iteration:
//!
//! 1. the candidate pass offers every camera sample's light- and BSDF-sampled paths to the
//!    reservoirs of the texels they touch (streaming RIS, weight |q| x MIS weight / density);
//! 2. the merge pass combines, per texel and sign, the fresh reservoir with both reservoirs
//!    kept from the last iteration by generalized RIS (balance heuristic with confidences,
//!    identity shift in path space, sign routing), writes the merged reservoirs and the
//!    gradient sum over signs of v(y) W. It traces no ray.
mod checkpoint;
pub mod compact;
mod diagnostics;
mod options;
mod params;
mod reservoir_test;
mod setup;

use super::{
    Conditions, Diagnostics, Estimator, EstimatorState, Frame, Kind, OptionsKind, Setup,
};
use crate::gpu::{encode_timed_pass, encode_timed_pass_indirect};
use crate::gpu::{grid_2d, Gpu};
use crate::optim::{pass_seed, FaultCounts, PassKind, PassTimer, Seeds};
use crate::render::WORKGROUP;
use crate::{Error, Result};

pub mod abi;
pub use abi::reservoir;
pub use diagnostics::{state_names, MergeDiagnostics};
pub use options::{Confidence, RestirOptions, TARGET_SMOOTHING_INDEPENDENT};
pub use params::{CandidateParams, MergeParams, MAX_CAMERAS};
pub use setup::{STATE_BYTES_PER_32_TEXELS, STATE_BYTES_PER_OBSERVED_TEXEL, STATE_BYTES_PER_PIXEL};
pub(crate) use params::{CANDIDATES_GROUP, CLAIM_GROUP, MERGE_GROUP};
pub use reservoir_test::selection_trial;
use setup::{
    candidate_camera, claim_capacity, claim_header, max_offers, memory, merge_params,
    variance_factor, Buffers, Camera, CLAIM_LOG_MAX_BYTES, FRESH_MOMENT_DECAY, PHASES,
};
use reservoir_test::RESERVOIR_TEST_GROUP;

use abi::merge_flag::{
    HAVE_PREV as FLAG_HAVE_PREV, POSITIVIZE as FLAG_POSITIVIZE, TEMPORAL as FLAG_TEMPORAL,
    VERIFY as FLAG_VERIFY,
};

/// ReSTIR as the registry knows it.
pub const KIND: Kind = Kind {
    name: "restir",
    summary: "parameter-space ReSTIR: two reservoirs per observed texel reused across iterations",
    options: OptionsKind::of::<RestirOptions>(),
    wgsl: &[
        ("restir_candidates", include_str!("restir_candidates.wgsl")),
        ("restir_merge", include_str!("restir_merge.wgsl")),
        ("restir_claim", include_str!("restir_claim.wgsl")),
        ("reservoir_test", include_str!("reservoir_test.wgsl")),
        ("restir/reservoir", include_str!("reservoir.wgsl")),
        (
            "restir/reservoir_slots",
            include_str!("reservoir_slots.wgsl"),
        ),
        ("restir/compact_path", include_str!("compact_path.wgsl")),
        ("restir/target", include_str!("target.wgsl")),
    ],
    generated: &[("gen/restir", abi::wgsl)],
    groups: &[CANDIDATES_GROUP, MERGE_GROUP, CLAIM_GROUP, RESERVOIR_TEST_GROUP],
    passes: |_| vec!["restir_candidates", "restir_merge", "restir_claim"],
    max_cameras: Some(MAX_CAMERAS),
    memory: |sizes, options| {
        let words = reservoir::words(sizes.max_depth);
        let offers = max_offers(
            sizes.gradient_samples,
            sizes.max_depth,
            sizes.slots_per_material,
            sizes.footprint,
        );
        let o: RestirOptions = options.get().unwrap_or_default();
        let capacity = claim_capacity(
            sizes.observed,
            offers,
            words,
            CLAIM_LOG_MAX_BYTES,
            o.claim_entries,
        );
        memory(
            (sizes.params, sizes.texels),
            sizes.observed,
            sizes.pixels,
            words,
            capacity,
            o.own_variance,
        )
    },
    warnings,
    every_texel: abi::reservoir::whole_paths,
    build: |setup| Ok(Box::new(Restir::new(setup)?)),
};

impl crate::optim::estimator::Options<crate::optim::estimator::EstimatorFamily> for RestirOptions {
    const KIND: &'static crate::optim::estimator::Kind = &KIND;
    const OPTIONAL: &'static [&'static str] = &["target_smoothing", "claim_entries"];

    fn check(&self) -> std::result::Result<(), (String, String)> {
        if !(self.m_cap.is_finite() && self.m_cap > 0.0) {
            return Err(("m_cap".into(), "must be a positive number".into()));
        }
        if self.claim_entries == Some(0) {
            return Err(("claim_entries".into(), "must be at least 1".into()));
        }
        if self
            .target_smoothing
            .is_some_and(|b| !(0.0..1.0).contains(&b))
        {
            return Err(("target_smoothing".into(), "must be in [0, 1)".into()));
        }
        Ok(())
    }

    fn describe(&self) -> String {
        format!(
            "M cap {}{}, target smoothing {}",
            self.m_cap,
            if self.m_cap_follows_schedule {
                " (follows the schedule)"
            } else {
                ""
            },
            self.target_smoothing
                .map_or("by primal".to_string(), |b| b.to_string())
        )
    }

    fn tuning(
        _: &crate::optim::estimator::TuningContext,
    ) -> Vec<crate::optim::estimator::TypedAxis<Self>> {
        tuning()
    }
}

/// What `bench --tune` searches for ReSTIR, in order: the M cap (2, 32), whether it follows
/// the learning-rate schedule, and the target smoothing (0, 0.9).
fn tuning() -> Vec<crate::optim::estimator::TypedAxis<RestirOptions>> {
    vec![
        |b| {
            [2.0, 32.0]
                .map(|m_cap| RestirOptions { m_cap, ..*b })
                .to_vec()
        },
        |b| {
            vec![RestirOptions {
                m_cap_follows_schedule: !b.m_cap_follows_schedule,
                ..*b
            }]
        },
        |b| {
            [0.0, TARGET_SMOOTHING_INDEPENDENT]
                .map(|s| RestirOptions {
                    target_smoothing: Some(s),
                    ..*b
                })
                .to_vec()
        },
    ]
}

/// What a run at `conditions` should know: beyond [`abi::reservoir::MAX_PATH_VERTICES`]
/// vertices, only the first vertex is reused.
fn warnings(conditions: &Conditions) -> Vec<String> {
    if conditions.max_depth <= abi::reservoir::MAX_PATH_VERTICES {
        return Vec::new();
    }
    vec![format!(
        "ReSTIR keeps whole paths of up to {} vertices; with paths of {} it reuses each path's \
         first vertex with the light the rest of the path brought back when it was drawn, \
         which the other surfaces' textures change since: its gradient lags them (the later \
         vertices' derivatives are plain Monte Carlo). The baseline and the recursive \
         estimator draw every vertex afresh",
        abi::reservoir::MAX_PATH_VERTICES,
        conditions.max_depth
    )]
}

const MERGE_STAT_EVALUATIONS: usize = abi::stat::MERGE_EVALUATIONS as usize;
const MERGE_STAT_DROPPED: usize = abi::stat::MERGE_DROPPED as usize;
const MERGE_STAT_VERIFIED: usize = abi::stat::MERGE_VERIFIED as usize;
const MERGE_STAT_VERIFY_MAX_ERROR: usize = abi::stat::MERGE_VERIFY_MAX_ERROR as usize;
const CANDIDATE_STAT_LOST: usize = abi::stat::CANDIDATE_LOST as usize;
const CANDIDATE_STAT_DROPPED: usize = abi::stat::CANDIDATE_DROPPED as usize;
const CANDIDATE_STAT_UNMAPPED: usize = abi::stat::CANDIDATE_UNMAPPED as usize;
const CANDIDATE_STAT_LOGGED: usize = abi::stat::CANDIDATE_LOGGED as usize;
const CANDIDATE_STAT_OVERFLOWED: usize = abi::stat::CANDIDATE_OVERFLOWED as usize;

/// The ReSTIR estimator's passes and buffers.
pub(crate) struct Restir {
    candidate_pipeline: wgpu::ComputePipeline,
    merge_pipeline: wgpu::ComputePipeline,
    claim_pipeline: wgpu::ComputePipeline,
    /// The claim log (restir_claim.wgsl) and the claim pass's bind group.
    claims: wgpu::Buffer,
    claim_group: wgpu::BindGroup,
    /// The retracing claim's dispatch, copied from the log's header (the candidate pass
    /// binds the log for writing, so it cannot also read its dispatch from it).
    fallback_args: wgpu::Buffer,
    cameras: Vec<Camera>,
    /// Reservoir slot k of every observed texel (`slots[k]`), and the headers that say which
    /// slots hold the kept reservoirs (reservoir_slots.wgsl).
    slots: Vec<wgpu::Buffer>,
    headers: wgpu::Buffer,
    merge_uniform: wgpu::Buffer,
    merge_params: MergeParams,
    merge_groups: [wgpu::BindGroup; 2],
    merge_grid: (u32, u32),
    candidate_stats: wgpu::Buffer,
    merge_stats: wgpu::Buffer,
    /// The target adjoints of both parities of the iteration, one after the other
    /// (reservoir.wgsl).
    targets: wgpu::Buffer,
    /// Pixels (vec4s) of one parity's target adjoints.
    target_len: u32,
    /// Bytes of the compaction map and the list of observed texels.
    map_bytes: u64,
    grid: (u32, u32),
    /// Words per reservoir at the scene's depth ([`reservoir::words`]).
    words: u32,
    options: RestirOptions,
    /// The target smoothing in use ([`RestirOptions::target_smoothing_for`]).
    smoothing: f32,
    /// Merges whose samples the kept reservoirs can hold (0: nothing to reuse).
    history: u32,
    queue: wgpu::Queue,
    /// The optimizer's gradient, which the merge writes (and, with indirect light, the
    /// candidates add the later vertices' derivatives into first).
    grad: wgpu::Buffer,
    /// Whether paths have more than one vertex.
    indirect: bool,
    /// The fresh estimates' moving moments and the merged estimate's variance
    /// (restir_merge.wgsl, write_entry), and the merges that updated the moments.
    fresh_moments: wgpu::Buffer,
    variance: wgpu::Buffer,
    moment_updates: u32,
}

impl Restir {
    /// An error naming what this estimator cannot handle in `s`.
    fn check_setup(s: &Setup) -> Result<()> {
        let n_cams = s.cameras.len();
        if n_cams > MAX_CAMERAS {
            return Err(Error::Invalid(format!(
                "ReSTIR handles at most {MAX_CAMERAS} cameras, the task has {n_cams}"
            )));
        }
        let n_pixels = s.width * s.height;
        if u64::from(n_pixels) > u64::from(reservoir::PIXEL_MASK) + 1 {
            return Err(Error::Invalid(format!(
                "ReSTIR handles images of at most 2^{} pixels, the task has {n_pixels}",
                reservoir::CAMERA_SHIFT
            )));
        }
        let n_tris = s.scene.info.n_tris;
        if u64::from(n_tris) > 1 << reservoir::TRI_BITS {
            return Err(Error::Invalid(format!(
                "ReSTIR handles scenes of at most 2^{} triangles, the scene has {n_tris}; use \
                 --method baseline",
                reservoir::TRI_BITS
            )));
        }
        Ok(())
    }

    pub(crate) fn new(s: &Setup) -> Result<Restir> {
        Self::check_setup(s)?;
        let gpu = s.gpu;
        let o: RestirOptions = s
            
            .options
            .get()
            .map_err(|(key, msg)| Error::Invalid(format!("{key} {msg}")))?;
        let smoothing = o.target_smoothing_for(s.primal);
        let candidate_layout = gpu.pass_layout("restir_candidates", 1)?;
        let merge_layout = gpu.pass_layout("restir_merge", 1)?;
        let candidate_pipeline =
            s.scene.pipeline(gpu, "restir_candidates", &[&s.scene.layout, &candidate_layout])?;
        let merge_pipeline =
            s.scene.pipeline(gpu, "restir_merge", &[&s.scene.layout, &merge_layout])?;
        let claim_layout = gpu.pass_layout("restir_claim", 0)?;
        let claim_pipeline = gpu.compute_pipeline("restir_claim", &[&claim_layout])?;
        let b = Buffers::new(s, &o);
        let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
        let merge_grid = grid_2d(b.n_observed, WORKGROUP, max_dim);
        let merge_params = merge_params(s, &o, b.n_observed, merge_grid);
        let merge_uniform = gpu.uniform("merge params", bytemuck::bytes_of(&merge_params));
        let merge_groups = [0usize, 1].map(|p| {
            gpu.bind(
                &MERGE_GROUP,
                "restir_merge",
                &merge_layout,
                &[
                    ("mp", &merge_uniform),
                    ("adjoint", &s.adjoint[p]),
                    ("targets", &b.targets),
                    ("slots0", &b.slots[0]),
                    ("slots1", &b.slots[1]),
                    ("slots2", &b.slots[2]),
                    ("slots3", &b.slots[3]),
                    ("headers", &b.headers),
                    ("grad", s.grad),
                    ("mstats", &b.merge_stats),
                    ("observed_list", &b.observed_list),
                    ("fresh_moments", &b.fresh_moments),
                    ("variance", &b.variance),
                ],
            )
        });
        let claim_group = gpu.bind(
            &CLAIM_GROUP,
            "restir_claim",
            &claim_layout,
            &[
                ("slots0", &b.slots[0]),
                ("slots1", &b.slots[1]),
                ("slots2", &b.slots[2]),
                ("slots3", &b.slots[3]),
                ("claims", &b.claims),
            ],
        );
        let cameras = (0..s.cameras.len())
            .map(|k| candidate_camera(s, &o, k, &candidate_layout, &b))
            .collect();
        Ok(Restir {
            candidate_pipeline,
            merge_pipeline,
            claim_pipeline,
            claims: b.claims.clone(),
            claim_group,
            fallback_args: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("retracing claim dispatch"),
                size: 16,
                usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            cameras,
            merge_uniform,
            merge_params,
            merge_groups,
            merge_grid,
            target_len: b.n_all_pixels,
            map_bytes: b.observed_list.size() + b.observed_map.size(),
            slots: b.slots,
            headers: b.headers,
            candidate_stats: b.candidate_stats,
            merge_stats: b.merge_stats,
            targets: b.targets,
            grid: s.grid,
            words: reservoir::words(s.scene.info.max_depth),
            options: o,
            smoothing,
            history: 0,
            queue: gpu.queue.clone(),
            grad: s.grad.clone(),
            indirect: s.scene.info.max_depth > 1,
            fresh_moments: b.fresh_moments,
            variance: b.variance,
            moment_updates: 0,
        })
    }

    /// What the merge pass counted so far.
    pub(crate) fn merge_diagnostics(&self, gpu: &Gpu) -> Result<MergeDiagnostics> {
        let m: Vec<u32> = gpu.read_pod(&self.merge_stats)?;
        let c: Vec<u32> = gpu.read_pod(&self.candidate_stats)?;
        Ok(MergeDiagnostics {
            evaluations: m[MERGE_STAT_EVALUATIONS] as u64,
            verified: m[MERGE_STAT_VERIFIED] as u64,
            max_relative_error: f32::from_bits(m[MERGE_STAT_VERIFY_MAX_ERROR]),
            unmapped: c[CANDIDATE_STAT_UNMAPPED] as u64,
            logged: c[CANDIDATE_STAT_LOGGED] as u64,
            overflowed: c[CANDIDATE_STAT_OVERFLOWED] as u64,
        })
    }
}

impl Estimator for Restir {
    fn encode(&mut self, enc: &mut wgpu::CommandEncoder, frame: &Frame, timer: &mut PassTimer) {
        let parity = frame.parity();
        // The free slots are empty already: the merge empties them. The gradient of a texel
        // no camera observes is never written: it stays 0 from the buffer's creation.
        let have_prev = self.history > 0;
        let reuse = self.options.temporal && have_prev;
        let target_cur = parity as u32 * self.target_len;
        let target_prev = (1 - parity as u32) * self.target_len;
        if self.indirect {
            // The candidates add the later vertices' derivatives into it; the merge adds the
            // reservoirs' estimates.
            enc.clear_buffer(&self.grad, 0, None);
        }
        // Every camera's offers enter the race before any winner writes its path: the same
        // texel's reservoir takes offers from several cameras. The winners among the logged
        // leaders claim in one pass; where the log overflowed, every camera's samples are
        // traced again and their winners claim (the retracing claim's dispatch is empty
        // otherwise).
        self.queue.write_buffer(
            &self.claims,
            0,
            bytemuck::cast_slice(&claim_header(self.words)),
        );
        for phase in 0..PHASES {
            if phase == 1 {
                enc.copy_buffer_to_buffer(
                    &self.claims,
                    4 * u64::from(abi::claim::FALLBACK_ARGS),
                    &self.fallback_args,
                    0,
                    12,
                );
                encode_timed_pass_indirect(
                    enc,
                    "restir_claim",
                    &self.claim_pipeline,
                    &[&self.claim_group],
                    (&self.claims, 4 * u64::from(abi::claim::ARGS)),
                    timer.next(PassKind::Gradient),
                );
            }
            for (k, cam) in self.cameras.iter_mut().enumerate() {
                cam.params.seed = pass_seed(frame.seed, frame.iteration, k as u32, Seeds::GRADIENT);
                cam.params.prev_targets = reuse as u32;
                cam.params.target_cur = target_cur;
                cam.params.target_prev = target_prev;
                cam.params.smoothing = if have_prev { self.smoothing } else { 0.0 };
                cam.params.phase = phase as u32;
                self.queue
                    .write_buffer(&cam.uniforms[phase], 0, bytemuck::bytes_of(&cam.params));
                let groups = [frame.scene_group, &cam.groups[phase][parity]];
                if phase == 0 {
                    encode_timed_pass(
                        enc,
                        "restir_candidates",
                        &self.candidate_pipeline,
                        &groups,
                        self.grid,
                        timer.next(PassKind::Gradient),
                    );
                } else {
                    encode_timed_pass_indirect(
                        enc,
                        "restir_candidates",
                        &self.candidate_pipeline,
                        &groups,
                        (&self.fallback_args, 0),
                        timer.next(PassKind::Gradient),
                    );
                }
            }
        }
        let o = &self.options;
        self.merge_params.seed = pass_seed(frame.seed, frame.iteration, 0, Seeds::MERGE);
        self.merge_params.flags = if o.temporal { FLAG_TEMPORAL } else { 0 }
            | if o.positivization { FLAG_POSITIVIZE } else { 0 }
            | if have_prev { FLAG_HAVE_PREV } else { 0 }
            | if o.verify_paths { FLAG_VERIFY } else { 0 };
        // Every kept reservoir has absorbed the fresh candidates of `history` iterations.
        let cap = if o.m_cap_follows_schedule {
            o.m_cap * frame.schedule_factor
        } else {
            o.m_cap
        };
        self.merge_params.m_kept = (self.merge_params.m_fresh * self.history as f32).min(cap);
        self.merge_params.target_cur = target_cur;
        self.merge_params.target_prev = target_prev;
        self.merge_params.moment_bias =
            1.0 - FRESH_MOMENT_DECAY.powi(self.moment_updates.saturating_add(1).min(1 << 16) as i32);
        self.merge_params.variance_factor = if o.own_variance {
            variance_factor(self.merge_params.m_fresh, self.merge_params.m_kept)
        } else {
            0.0
        };
        self.queue.write_buffer(
            &self.merge_uniform,
            0,
            bytemuck::bytes_of(&self.merge_params),
        );
        encode_timed_pass(
            enc,
            "restir_merge",
            &self.merge_pipeline,
            &[frame.scene_group, &self.merge_groups[parity]],
            self.merge_grid,
            timer.next(PassKind::Combine),
        );
    }

    fn finish_iteration(&mut self) {
        self.moment_updates = self.moment_updates.saturating_add(1);
        self.history = if self.options.temporal {
            self.history.saturating_add(1)
        } else {
            0
        };
    }

    fn uses_previous_state(&self) -> bool {
        self.options.temporal
    }

    fn faults(&self, gpu: &Gpu, f: &mut FaultCounts) -> Result<()> {
        let c: Vec<u32> = gpu.read_pod(&self.candidate_stats)?;
        let m: Vec<u32> = gpu.read_pod(&self.merge_stats)?;
        f.lost_kept += c[CANDIDATE_STAT_LOST];
        f.dropped_gradient += c[CANDIDATE_STAT_DROPPED];
        f.dropped_kept += m[MERGE_STAT_DROPPED];
        Ok(())
    }

    fn snapshot(&self, gpu: &Gpu, _iteration: u32) -> Result<EstimatorState> {
        self.save(gpu)
    }

    fn restore(
        &mut self,
        gpu: &Gpu,
        state: Option<&EstimatorState>,
        _iteration: u32,
    ) -> Result<()> {
        self.load(gpu, state)
    }

    fn state_bytes(&self) -> u64 {
        self.slots.iter().map(|b| b.size()).sum::<u64>()
            + self.headers.size()
            + self.map_bytes
            + if self.options.own_variance {
                self.fresh_moments.size() + self.variance.size()
            } else {
                0
            }
    }

    fn variance(&self) -> Option<&wgpu::Buffer> {
        self.options.own_variance.then_some(&self.variance)
    }

    fn diagnostics(&self, gpu: &Gpu) -> Result<Diagnostics> {
        Ok(self.merge_diagnostics(gpu)?.named())
    }

    fn counters(&self) -> &'static [&'static str] {
        &[
            MergeDiagnostics::EVALUATIONS,
            MergeDiagnostics::UNMAPPED,
            MergeDiagnostics::LOGGED,
            MergeDiagnostics::OVERFLOWED,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::setup::compaction_map;

    #[test]
    fn the_compaction_map_counts_the_observed_texels_before_each_word() {
        let observed: Vec<bool> = (0..100).map(|t| t % 3 == 0 || t == 40).collect();
        let (map, list) = compaction_map(&observed);
        assert_eq!(map.len(), 4);
        let expected: Vec<u32> = (0..100).filter(|&t| observed[t as usize]).collect();
        assert_eq!(list, expected);
        // The WGSL lookup (restir_candidates.wgsl, observed_index) on the CPU.
        for (t, &o) in observed.iter().enumerate() {
            let [bits, before] = map[t / 32];
            let bit = 1u32 << (t % 32);
            if o {
                let i = before + (bits & (bit - 1)).count_ones();
                assert_eq!(list[i as usize], t as u32);
            } else {
                assert_eq!(bits & bit, 0);
            }
        }
    }
}
