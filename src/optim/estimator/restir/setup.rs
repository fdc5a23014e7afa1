//! What ReSTIR allocates and binds: its memory plan, the compaction of observed texels, the
//! buffers both passes share, the merge's first uniform and each camera's candidate groups.
use super::{
    abi::claim, reservoir, CandidateParams, Confidence, MergeParams, RestirOptions, Setup,
    CANDIDATES_GROUP, MAX_CAMERAS,
};
use crate::optim::Scale;
use crate::render::WORKGROUP;

/// Bytes of ReSTIR state per observed texel: four reservoir slots (the kept positive and
/// negative reservoirs and the fresh ones, [`reservoir::WORDS`] words each), a header word
/// (slots and locks) and the texel's entry in the list of observed texels (with whole paths,
/// at depth 2 and 3, every texel counts as observed). Per texel of the
/// textures it also keeps [`STATE_BYTES_PER_32_TEXELS`] per 32 texels (the compaction map),
/// and per pixel of every camera [`STATE_BYTES_PER_PIXEL`].
pub const STATE_BYTES_PER_OBSERVED_TEXEL: u64 =
    reservoir::SLOTS as u64 * reservoir::WORDS as u64 * 4 + 4 + 4;

/// Bytes of ReSTIR's compaction map per 32 texels of the optimized textures: which are
/// observed (a bit each) and how many observed texels come before them.
pub const STATE_BYTES_PER_32_TEXELS: u64 = 8;

/// Bytes of ReSTIR state per pixel of every camera: the target adjoints of both parities
/// (RGBA f32 each).
pub const STATE_BYTES_PER_PIXEL: u64 = 2 * 16;

/// Entries of the claim log for `n_observed` texels with reservoirs and at most `offers`
/// offers in an iteration: the offers that lead a race when they enter it. A reservoir that
/// takes n offers in random order is led by H_n (about ln n + 0.58) of them in expectation,
/// by the one offer where n is 1 (the sparse regime), so R reservoirs (both signs) that
/// share N offers are led by at most min(N, R (1 + ln(N / R))) (concavity). The log holds a
/// quarter more than that, and at most one entry per reservoir, within one indirect dispatch
/// and `max_binding` bytes: measured, the bench scenes and the default task log 0.2 to 0.75
/// entries per reservoir and iteration (the most where a reservoir takes most offers, the
/// default task's 2 gradient spp over 18k texels). A log too small for an iteration costs a
/// second tracing of its samples (restir_candidates.wgsl, phase 1; counted in the ReSTIR
/// diagnostics as claims overflowed), never a sample. `asked`: the options' size instead
/// (within the same limits).
pub(super) fn claim_capacity(
    n_observed: u64,
    offers: u64,
    words: u32,
    max_binding: u64,
    asked: Option<u32>,
) -> u32 {
    let r = (2 * n_observed).max(1) as f64;
    let n = offers as f64;
    let leaders = if n <= r { n } else { r * (1.0 + (n / r).ln()) };
    let by_binding = (max_binding / 4).saturating_sub(u64::from(claim::HEADER_WORDS))
        / u64::from(claim::stride(words));
    asked
        .map_or((1.25 * leaders).min(r) as u64 + 1024, u64::from)
        .min(u64::from(claim::MAX_ENTRIES))
        .min(by_binding) as u32
}

/// The claim log's largest size: lavapipe's binding limit, the smallest of the adapters
/// psrestir runs on (the memory plan is the same on every adapter).
pub(super) const CLAIM_LOG_MAX_BYTES: u64 = 128 << 20;

/// The most offers the candidate pass makes in an iteration: every camera sample's paths
/// (its two techniques, or with whole paths up to 6 arrivals of up to
/// `MAX_PATH_VERTICES` vertices each), each to every optimized texture of a material
/// (`slots` at most) and every texel of its filter's footprint (`footprint`).
pub(super) fn max_offers(samples: u64, max_depth: u32, slots: u64, footprint: u64) -> u64 {
    let paths = if reservoir::whole_paths(max_depth) {
        6 * u64::from(reservoir::MAX_PATH_VERTICES)
    } else {
        2
    };
    samples * paths * slots * footprint
}

/// The buffers ReSTIR allocates for `n_texels` texels of which `n_observed` are observed,
/// and `n_pixels` pixels (all cameras'), by label, size in bytes and what the size scales
/// with. Slot k of every observed texel lies in buffer `reservoir slots<k>`, so that each
/// binding holds a quarter of the reservoirs; `words` per reservoir. The fresh estimates'
/// moments and the variance only with `own_variance` (elsewhere a placeholder word each).
pub(super) fn memory(
    (n_params, n_texels): (u64, u64),
    n_observed: u64,
    n_pixels: u64,
    words: u32,
    claim_capacity: u32,
    own_variance: bool,
) -> Vec<(String, u64, Scale)> {
    let slot_bytes = n_observed * words as u64 * 4;
    let mut out: Vec<(String, u64, Scale)> = (0..reservoir::SLOTS)
        .map(|k| {
            (
                format!("reservoir slots{k}"),
                slot_bytes,
                Scale::ObservedTexel,
            )
        })
        .collect();
    out.extend([
        (
            "reservoir headers".to_string(),
            n_observed * 4,
            Scale::ObservedTexel,
        ),
        (
            "observed texel list".to_string(),
            n_observed * 4,
            Scale::ObservedTexel,
        ),
        (
            "observed texel map".to_string(),
            n_texels.div_ceil(32) * STATE_BYTES_PER_32_TEXELS,
            Scale::Texel,
        ),
        (
            "target adjoints".to_string(),
            STATE_BYTES_PER_PIXEL * n_pixels,
            Scale::Pixel,
        ),
        (
            "claim log".to_string(),
            claim_log_bytes(claim_capacity, words),
            // Sized by the offers an iteration makes where they are fewer than the
            // reservoirs (claim_capacity), by the reservoirs otherwise.
            if u64::from(claim_capacity) < 2 * n_observed {
                Scale::Pixel
            } else {
                Scale::ObservedTexel
            },
        ),
    ]);
    if own_variance {
        out.extend([
            (
                "restir fresh moments".to_string(),
                8 * n_params,
                Scale::Texel,
            ),
            ("restir variance".to_string(), 4 * n_params, Scale::Texel),
        ]);
    }
    out
}

/// Bytes of a claim log of `capacity` entries for reservoirs of `words` words.
pub(super) fn claim_log_bytes(capacity: u32, words: u32) -> u64 {
    4 * (u64::from(claim::HEADER_WORDS) + u64::from(capacity) * u64::from(claim::stride(words)))
}

/// The claim log's header at the start of an iteration: nothing logged, the claim pass's
/// dispatch of 0 x 1 x 1 workgroups (the candidate pass raises x), no retracing claim, and
/// the entries' stride.
pub(super) fn claim_header(words: u32) -> [u32; claim::HEADER_WORDS as usize] {
    let mut h = [0; claim::HEADER_WORDS as usize];
    h[claim::ARGS as usize + 1] = 1;
    h[claim::ARGS as usize + 2] = 1;
    h[claim::STRIDE as usize] = claim::stride(words);
    h
}

/// The compaction map of `observed` (one flag per texel): per 32 texels, which are observed
/// (bits) and how many observed texels come before them; and the list of observed texels.
pub(super) fn compaction_map(observed: &[bool]) -> (Vec<[u32; 2]>, Vec<u32>) {
    let mut map = Vec::with_capacity(observed.len().div_ceil(32));
    let mut list = Vec::new();
    for (w, chunk) in observed.chunks(32).enumerate() {
        let mut bits = 0u32;
        let before = list.len() as u32;
        for (b, &o) in chunk.iter().enumerate() {
            if o {
                bits |= 1 << b;
                list.push((w * 32 + b) as u32);
            }
        }
        map.push([bits, before]);
    }
    (map, list)
}

/// The candidate pass's phases (restir_candidates.wgsl, `phase`): the weights, the race and
/// the claim log, then (only where the log overflowed) the winners' paths.
pub(super) const PHASES: usize = 2;

pub(super) struct Camera {
    /// Per phase (a queue write lands before the whole submission, so each phase's
    /// parameters need their own buffer).
    pub(super) uniforms: [wgpu::Buffer; PHASES],
    pub(super) params: CandidateParams,
    /// Per phase, then per parity of the iteration (the adjoints alternate).
    pub(super) groups: [[wgpu::BindGroup; 2]; PHASES],
}

/// The buffers both passes bind, sized by [`memory`].
pub(super) struct Buffers {
    pub(super) slots: Vec<wgpu::Buffer>,
    pub(super) headers: wgpu::Buffer,
    pub(super) observed_list: wgpu::Buffer,
    pub(super) observed_map: wgpu::Buffer,
    pub(super) candidate_stats: wgpu::Buffer,
    pub(super) merge_stats: wgpu::Buffer,
    pub(super) targets: wgpu::Buffer,
    /// The claim log (restir_claim.wgsl): its header, then the entries.
    pub(super) claims: wgpu::Buffer,
    /// The fresh estimates' moving moments and the merged estimate's variance, per gradient
    /// entry (restir_merge.wgsl, write_entry).
    pub(super) fresh_moments: wgpu::Buffer,
    pub(super) variance: wgpu::Buffer,
    pub(super) claim_capacity: u32,
    pub(super) n_observed: u32,
    /// Pixels of all cameras.
    pub(super) n_all_pixels: u32,
}

impl Buffers {
    pub(super) fn new(s: &Setup, o: &RestirOptions) -> Buffers {
        let gpu = s.gpu;
        // With whole paths, texels reached after a bounce get reservoirs too: every texel.
        let every;
        let mut observed = s.observed;
        if reservoir::whole_paths(s.scene.info.max_depth) {
            every = vec![true; s.observed.len()];
            observed = &every;
        }
        let (map, list) = compaction_map(observed);
        let n_observed = list.len() as u64;
        let n_all_pixels = s.adjoint[0].size() / 16;
        let words = reservoir::words(s.scene.info.max_depth);
        let max_binding =
            gpu.device.limits().max_storage_buffer_binding_size.min(CLAIM_LOG_MAX_BYTES);
        let claim_capacity = claim_capacity(
            n_observed,
            offers_of(s, n_all_pixels),
            words,
            max_binding,
            o.claim_entries,
        );
        let sizes = memory(
            (s.set.values.len() as u64, s.scene.n_texels as u64),
            n_observed,
            n_all_pixels,
            words,
            claim_capacity,
            o.own_variance,
        );
        let size = |label: &str| sizes.iter().find(|b| b.0 == label).map_or(0, |b| b.1);
        // wgpu binds no empty buffer: at least one word each.
        let slots: Vec<wgpu::Buffer> = (0..reservoir::SLOTS)
            .map(|k| {
                let label = format!("reservoir slots{k}");
                gpu.storage_zeroed(&label, size(&label).max(4))
            })
            .collect();
        let headers = gpu.storage(
            "reservoir headers",
            bytemuck::cast_slice(&vec![reservoir::HEADER_FIRST_TWO; list.len().max(1)]),
            wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        );
        let observed_list = gpu.storage(
            "observed texel list",
            bytemuck::cast_slice(if list.is_empty() { &[0u32][..] } else { &list }),
            wgpu::BufferUsages::empty(),
        );
        let observed_map = gpu.storage(
            "observed texel map",
            bytemuck::cast_slice(if map.is_empty() {
                &[[0u32; 2]][..]
            } else {
                &map
            }),
            wgpu::BufferUsages::empty(),
        );
        Buffers {
            slots,
            headers,
            observed_list,
            observed_map,
            candidate_stats: gpu.storage_zeroed(
                "candidate stats",
                4 * u64::from(super::abi::stat::CANDIDATE_SLOTS),
            ),
            merge_stats: gpu.storage_zeroed("merge stats", 16),
            targets: gpu.storage_zeroed("target adjoints", size("target adjoints")),
            claims: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("claim log"),
                size: size("claim log"),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::INDIRECT
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            claim_capacity,
            fresh_moments: gpu.storage_zeroed(
                "restir fresh moments",
                size("restir fresh moments").max(8),
            ),
            variance: gpu.storage_zeroed("restir variance", size("restir variance").max(4)),
            n_observed: n_observed as u32,
            n_all_pixels: n_all_pixels as u32,
        }
    }
}

/// The most offers the candidate pass of `s` makes in an iteration over `n_pixels` pixels.
fn offers_of(s: &Setup, n_pixels: u64) -> u64 {
    let (slots, footprint) = super::super::Sizes::lookups(s.set);
    max_offers(
        n_pixels * u64::from(s.gradient_spp),
        s.scene.info.max_depth,
        slots,
        footprint,
    )
}

/// Decay of the moving moments of the fresh estimates (restir_merge.wgsl, write_entry): as
/// the variance-scaled step's own moving variance.
pub(super) const FRESH_MOMENT_DECAY: f32 = 0.9;

/// The merged estimate's variance over a fresh estimate's, where the merge weighs the fresh
/// candidates by `m_fresh` against the kept ones' `m_kept`: a moving average that gives each
/// iteration's independent estimate the share a = m_fresh / (m_fresh + m_kept) has variance
/// a / (2 - a) times theirs (1 without reuse; 1/17 at the default M cap of 8 with one sample
/// per pixel).
pub(super) fn variance_factor(m_fresh: f32, m_kept: f32) -> f32 {
    let a = m_fresh / (m_fresh + m_kept).max(1e-30);
    a / (2.0 - a)
}

/// The merge's uniform before the first iteration.
pub(super) fn merge_params(s: &Setup, o: &RestirOptions, n_observed: u32, grid: (u32, u32)) -> MergeParams {
    let spp = s.gradient_spp;
    let mut origins = [[0.0; 4]; MAX_CAMERAS];
    for (o, c) in origins.iter_mut().zip(s.cameras) {
        *o = [c.origin[0], c.origin[1], c.origin[2], 0.0];
    }
    MergeParams {
        n_observed,
        n_pixels: s.width * s.height,
        seed: 0,
        flags: 0,
        m_fresh: match o.confidence {
            Confidence::Samples => spp as f32,
            Confidence::Candidates => (2 * spp * s.cameras.len() as u32) as f32,
        },
        m_kept: 0.0,
        inv_spp: 1.0 / spp as f32,
        n_textures: s.set.textures.len() as u32,
        stride: grid.0 * WORKGROUP,
        target_cur: 0,
        target_prev: 0,
        moment_decay: FRESH_MOMENT_DECAY,
        moment_bias: 1.0,
        variance_factor: 0.0,
        _pad0: 0,
        _pad1: 0,
        origins,
    }
}

/// Camera `k`'s candidate uniforms and bind groups (per phase and parity).
pub(super) fn candidate_camera(
    s: &Setup,
    o: &RestirOptions,
    k: usize,
    layout: &wgpu::BindGroupLayout,
    b: &Buffers,
) -> Camera {
    let spp = s.gradient_spp;
    let params = CandidateParams {
        camera: s.cameras[k],
        seed: 0,
        spp,
        stride: s.grid.0 * WORKGROUP,
        inv_spp: 1.0 / spp as f32,
        camera_index: k as u32,
        adjoint_offset: k as u32 * s.width * s.height,
        positivize: o.positivization as u32,
        prev_targets: 0,
        smoothing: 0.0,
        target_cur: 0,
        target_prev: 0,
        phase: 0,
        claim_capacity: b.claim_capacity,
        grid_x: s.grid.0,
        grid_y: s.grid.1,
        _pad0: 0,
    };
    let uniforms: [wgpu::Buffer; PHASES] = std::array::from_fn(|phase| {
        s.gpu.uniform(
            &format!("candidate params {k} phase {phase}"),
            bytemuck::bytes_of(&params),
        )
    });
    let groups = std::array::from_fn(|phase| {
        [0usize, 1].map(|p| {
            s.gpu.bind(
                &CANDIDATES_GROUP,
                "restir_candidates",
                layout,
                &[
                    ("cp", &uniforms[phase]),
                    ("adjoint", &s.adjoint[p]),
                    ("slots0", &b.slots[0]),
                    ("slots1", &b.slots[1]),
                    ("slots2", &b.slots[2]),
                    ("slots3", &b.slots[3]),
                    ("headers", &b.headers),
                    ("cstats", &b.candidate_stats),
                    ("targets", &b.targets),
                    ("observed_map", &b.observed_map),
                    ("grad", s.grad),
                    ("env_grad", s.env_grad),
                    ("claims", &b.claims),
                ],
            )
        })
    });
    Camera {
        uniforms,
        params,
        groups,
    }
}

