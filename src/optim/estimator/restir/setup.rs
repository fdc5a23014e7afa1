//! What ReSTIR allocates and binds: its memory plan, the compaction of observed texels, the
//! buffers both passes share, the merge's first uniform and each camera's candidate groups.
use super::{
    reservoir, CandidateParams, Confidence, MergeParams, RestirOptions, Setup, CANDIDATES_GROUP,
    MAX_CAMERAS, STATE_BYTES_PER_32_TEXELS, STATE_BYTES_PER_PIXEL,
};
use crate::optim::Scale;
use crate::render::WORKGROUP;

/// The buffers ReSTIR allocates for `n_texels` texels of which `n_observed` are observed,
/// and `n_pixels` pixels (all cameras'), by label, size in bytes and what the size scales
/// with. Slot k of every observed texel lies in buffer `reservoir slots<k>`, so that each
/// binding holds a quarter of the reservoirs; `words` per reservoir.
pub(super) fn memory(
    n_texels: u64,
    n_observed: u64,
    n_pixels: u64,
    words: u32,
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
    ]);
    out
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

/// The candidate pass's phases (restir_candidates.wgsl, `phase`): the weights and the race,
/// then the winners' paths.
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
    pub(super) n_observed: u32,
    /// Pixels of all cameras.
    pub(super) n_all_pixels: u32,
}

impl Buffers {
    pub(super) fn new(s: &Setup) -> Buffers {
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
        let sizes = memory(s.scene.n_texels as u64, n_observed, n_all_pixels, words);
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
            candidate_stats: gpu.storage_zeroed("candidate stats", 16),
            merge_stats: gpu.storage_zeroed("merge stats", 16),
            targets: gpu.storage_zeroed("target adjoints", size("target adjoints")),
            n_observed: n_observed as u32,
            n_all_pixels: n_all_pixels as u32,
        }
    }
}

/// The merge's uniform before the first iteration.
pub(super) fn merge_params(s: &Setup, o: &RestirOptions, n_observed: u32, grid: (u32, u32)) -> MergeParams {
    let spp = s.settings.gradient_spp;
    let mut origins = [[0.0; 4]; MAX_CAMERAS];
    for (o, c) in origins.iter_mut().zip(s.cameras) {
        *o = [c.origin[0], c.origin[1], c.origin[2], 0.0];
    }
    MergeParams {
        n_observed,
        n_pixels: s.settings.width * s.settings.height,
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
        _pad: 0,
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
    let spp = s.settings.gradient_spp;
    let params = CandidateParams {
        camera: s.cameras[k],
        seed: 0,
        spp,
        stride: s.grid.0 * WORKGROUP,
        inv_spp: 1.0 / spp as f32,
        camera_index: k as u32,
        adjoint_offset: k as u32 * s.settings.width * s.settings.height,
        positivize: o.positivization as u32,
        prev_targets: 0,
        smoothing: 0.0,
        target_cur: 0,
        target_prev: 0,
        phase: 0,
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

