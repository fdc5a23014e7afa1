//! ReSTIR's part of the GPU contract: the reservoir layout, the camera limit, the merge flags
//! and the counter slots of its passes' statistics buffers, defined once, here, and generated
//! into WGSL as `gen/restir` (its passes and WGSL modules say `#import gen/restir`).

/// ReSTIR's reservoirs in their compact form: word offsets within a reservoir, the packing
/// of its words, a texel's slots and header (WGSL: `RES_*`, `INFO_*`, `RESERVOIR_WORDS`,
/// `RESERVOIR_SLOTS`, `HEADER_*`). A reservoir stores its path as its vertices (triangle
/// and barycentrics of each, up to `MAX_PATH_VERTICES`: the camera ray's hit first), the
/// incident direction at the last one in its shading frame, the radiance arriving along it,
/// and which vertex the texel's derivative is taken at; everything else the BRDFs need is
/// rebuilt from the scene
/// (`compact_path.wgsl` here, with `shared/path_encoding.wgsl`; the precision of each
/// encoding is stated in [`super::compact`]).
pub mod reservoir {
    /// Pixel | camera << CAMERA_SHIFT | technique << TECH_SHIFT.
    pub const INFO: u32 = 0;
    /// Weight sum (fresh reservoirs) or unbiased contribution weight W (merged), f32.
    pub const W: u32 = 1;
    /// Triangle index (TRI_BITS) and the low bits of the first barycentric.
    pub const TRI: u32 = 2;
    /// The high bits of the first barycentric and the second one.
    pub const BARY: u32 = 3;
    /// The incident direction's first octahedral coordinate (24 bits) and the low byte of
    /// the target under the previous state (bfloat16).
    pub const WI_X: u32 = 4;
    /// The second octahedral coordinate (24 bits) and the high byte of that target.
    pub const WI_Y: u32 = 5;
    /// Incident radiance at the last vertex, RGB with a shared exponent (RGBE, 8 bits each).
    pub const RADIANCE: u32 = 6;
    /// The second vertex's triangle and barycentrics, packed as at TRI and BARY.
    pub const TRI2: u32 = 7;
    /// The second vertex's barycentrics' high bits.
    pub const BARY2: u32 = 8;
    /// The third vertex's triangle and barycentrics.
    pub const TRI3: u32 = 9;
    /// The third vertex's barycentrics' high bits.
    pub const BARY3: u32 = 10;
    /// The path's shape: its vertex count less one (bits 0..2) and the index of the vertex,
    /// from 0, whose BRDF the texel's derivative is taken at (bits 2..4); 0 is the one-vertex
    /// path of direct light (or of the first vertex with the radiance arriving along its
    /// direction, beyond [`MAX_PATH_VERTICES`]).
    pub const SHAPE: u32 = 11;
    /// Words per reservoir without whole paths (depth 1, or beyond [`MAX_PATH_VERTICES`]):
    /// INFO to RADIANCE.
    pub const WORDS: u32 = 7;
    /// Words per reservoir with whole paths ([`whole_paths`]).
    pub const WHOLE_PATH_WORDS: u32 = 12;
    /// The path's words after W with whole paths (`Candidate.words` in `reservoir.wgsl`).
    pub const PATH_WORDS: u32 = WHOLE_PATH_WORDS - TRI;
    /// Vertices a stored path holds: with `max_depth` up to this, a reservoir keeps whole
    /// paths (every vertex re-evaluated under the current textures); beyond it, the first
    /// vertex with the radiance arriving along its direction, the later vertices' derivatives
    /// plain Monte Carlo.
    pub const MAX_PATH_VERTICES: u32 = 3;
    /// Bits of the triangle index (ReSTIR handles scenes of up to 2^24 triangles).
    pub const TRI_BITS: u32 = 24;
    pub use crate::gpu::abi::path_encoding::{BARY_BITS, OCT_BITS};
    /// Bits of the pixel index (images up to 8192 x 8192 = 2^26 pixels).
    pub const CAMERA_SHIFT: u32 = 26;
    /// Camera index mask after the shift.
    pub const CAMERA_MASK: u32 = 7;
    /// Pixel index mask.
    pub const PIXEL_MASK: u32 = (1 << CAMERA_SHIFT) - 1;
    /// The technique bit: 0 light sampling, 1 BSDF sampling.
    pub const TECH_SHIFT: u32 = 29;
    /// Reservoir slots per texel: its two kept reservoirs and the two fresh ones. Slot k of
    /// every observed texel lies in its own buffer (`slots<k>`), so that no binding holds
    /// more than a quarter of the state.
    pub const SLOTS: u32 = 4;
    /// Bits of a slot index in a texel's header (sign 0's slot, then sign 1's).
    pub const HEADER_SLOT_BITS: u32 = 2;
    /// Slot index mask after the shift.
    pub const HEADER_SLOT_MASK: u32 = (1 << HEADER_SLOT_BITS) - 1;
    /// Set in a fresh reservoir's info word while it holds the candidate pass's race key
    /// (the complement of a non-negative float's bits) instead of an info word
    /// (`reservoir.wgsl`); a free slot's info word is 0.
    pub const KEY_BIT: u32 = 1 << 31;
    /// The header of a texel whose reservoirs lie in slots 0 (sign 0) and 1 (sign 1).
    pub const HEADER_FIRST_TWO: u32 = 1 << HEADER_SLOT_BITS;
    /// Marks a texel no camera observes in the compaction map's lookups (u32::MAX).
    pub const UNOBSERVED: u32 = u32::MAX;

    /// Whether reservoirs keep whole paths at `max_depth` (from two vertices to
    /// [`MAX_PATH_VERTICES`]; `compact_path.wgsl`, `whole_paths`). Every texel of the
    /// optimized textures then has reservoirs, not only those a camera sees.
    pub fn whole_paths(max_depth: u32) -> bool {
        max_depth > 1 && max_depth <= MAX_PATH_VERTICES
    }

    /// Words per reservoir at `max_depth`.
    pub fn words(max_depth: u32) -> u32 {
        if whole_paths(max_depth) {
            WHOLE_PATH_WORDS
        } else {
            WORDS
        }
    }

    /// The slot of sign `sign`'s reservoir in header `h`.
    pub fn header_slot(h: u32, sign: u32) -> u32 {
        (h >> (HEADER_SLOT_BITS * sign)) & HEADER_SLOT_MASK
    }
}

/// The claim log (`claims`, `restir_claim.wgsl`): the offers that led their reservoir's race
/// when they entered it, written by the candidate pass so that the winners' paths are written
/// without tracing the samples again. A header of [`HEADER_WORDS`](claim::HEADER_WORDS) words, then entries of
/// `reservoir words + 1` words each (WGSL `CLAIM_*`).
pub mod claim {
    /// Header: entries appended this iteration (may exceed the capacity: then the log
    /// overflowed and the retracing claim runs).
    pub const COUNT: u32 = 0;
    /// Header: the claim pass's indirect dispatch (x, y, z): x = workgroups of its entries.
    pub const ARGS: u32 = 1;
    /// Header: the retracing claim's indirect dispatch (x, y, z) per camera, 0 unless the
    /// log overflowed.
    pub const FALLBACK_ARGS: u32 = 4;
    /// Header: words per entry (written by the host).
    pub const STRIDE: u32 = 7;
    /// Header words.
    pub const HEADER_WORDS: u32 = 8;
    /// Entry: the reservoir (observed texel << 2 | slot).
    pub const ADDR: u32 = 0;
    /// Entry: its race key when it entered (complemented, [`super::reservoir::KEY_BIT`] set).
    pub const KEY: u32 = 1;
    /// Entry: the candidate's info word.
    pub const INFO: u32 = 2;
    /// Entry: the candidate's path words (a reservoir's words from TRI on).
    pub const PATH: u32 = 3;
    /// Workgroup size of the claim pass.
    pub const WORKGROUP: u32 = 64;
    /// Entries a log can hold (one 1-D indirect dispatch of the claim pass).
    pub const MAX_ENTRIES: u32 = 65535 * WORKGROUP;

    /// Words per entry with reservoirs of `words` words: an address, a key, and the reservoir's
    /// words but its weight.
    pub fn stride(words: u32) -> u32 {
        words + 1
    }
}

/// Cameras a ReSTIR optimizer can use (the camera index has three bits in a reservoir).
pub const MAX_CAMERAS: u32 = reservoir::CAMERA_MASK + 1;

/// Flags of ReSTIR's merge pass (WGSL `MERGE_FLAG_*`).
pub mod merge_flag {
    /// Temporal reuse: the kept reservoirs take part.
    pub const TEMPORAL: u32 = 1;
    /// Two reservoirs per texel (positive and negative parts).
    pub const POSITIVIZE: u32 = 2;
    /// The previous iteration's state exists.
    pub const HAVE_PREV: u32 = 4;
    /// Check stored paths against their stored factors (tests).
    pub const VERIFY: u32 = 8;
}

/// Counter slots of the candidate pass's (`cstats`) and the merge's (`mstats`) statistics.
pub mod stat {
    /// `restir_candidates.wgsl`: candidates offered.
    pub const CANDIDATE_OFFERED: u32 = 0;
    /// `restir_candidates.wgsl`: offers whose lock loop ran out.
    pub const CANDIDATE_LOST: u32 = 1;
    /// `restir_candidates.wgsl`: non-finite candidates dropped.
    pub const CANDIDATE_DROPPED: u32 = 2;
    /// `restir_candidates.wgsl`: candidates for texels outside the compaction map (texels
    /// that the observed-texel pass's strata missed), dropped.
    pub const CANDIDATE_UNMAPPED: u32 = 3;
    /// `restir_candidates.wgsl`: offers entered in the claim log.
    pub const CANDIDATE_LOGGED: u32 = 4;
    /// `restir_candidates.wgsl`: offers the full claim log could not take (the retracing
    /// claim then writes the winners' paths).
    pub const CANDIDATE_OVERFLOWED: u32 = 5;
    /// Slots of the candidate pass's statistics.
    pub const CANDIDATE_SLOTS: u32 = 6;
    /// `restir_merge.wgsl`: kept paths evaluated.
    pub const MERGE_EVALUATIONS: u32 = 0;
    /// `restir_merge.wgsl`: non-finite values dropped.
    pub const MERGE_DROPPED: u32 = 1;
    /// `restir_merge.wgsl`: paths verified (tests).
    pub const MERGE_VERIFIED: u32 = 2;
    /// `restir_merge.wgsl`: largest verification error (f32 bits).
    pub const MERGE_VERIFY_MAX_ERROR: u32 = 3;
}

/// (WGSL name, value) of every constant.
pub const CONSTANTS: &[(&str, u32)] = &[
    ("RESERVOIR_WORDS", reservoir::WORDS),
    ("RESERVOIR_WORDS_MAX", reservoir::WHOLE_PATH_WORDS),
    ("RES_INFO", reservoir::INFO),
    ("RES_W", reservoir::W),
    ("RES_TRI", reservoir::TRI),
    ("RES_BARY", reservoir::BARY),
    ("RES_WI_X", reservoir::WI_X),
    ("RES_WI_Y", reservoir::WI_Y),
    ("RES_RADIANCE", reservoir::RADIANCE),
    ("RES_TRI2", reservoir::TRI2),
    ("RES_BARY2", reservoir::BARY2),
    ("RES_TRI3", reservoir::TRI3),
    ("RES_BARY3", reservoir::BARY3),
    ("RES_SHAPE", reservoir::SHAPE),
    ("RES_PATH_WORDS", reservoir::PATH_WORDS),
    ("MAX_PATH_VERTICES", reservoir::MAX_PATH_VERTICES),
    ("RES_TRI_BITS", reservoir::TRI_BITS),
    ("RESERVOIR_SLOTS", reservoir::SLOTS),
    ("HEADER_SLOT_BITS", reservoir::HEADER_SLOT_BITS),
    ("HEADER_SLOT_MASK", reservoir::HEADER_SLOT_MASK),
    ("INFO_KEY_BIT", reservoir::KEY_BIT),
    ("INFO_CAMERA_SHIFT", reservoir::CAMERA_SHIFT),
    ("INFO_CAMERA_MASK", reservoir::CAMERA_MASK),
    ("INFO_PIXEL_MASK", reservoir::PIXEL_MASK),
    ("INFO_TECH_SHIFT", reservoir::TECH_SHIFT),
    ("UNOBSERVED", reservoir::UNOBSERVED),
    ("MAX_CAMERAS", MAX_CAMERAS),
    ("MERGE_FLAG_TEMPORAL", merge_flag::TEMPORAL),
    ("MERGE_FLAG_POSITIVIZE", merge_flag::POSITIVIZE),
    ("MERGE_FLAG_HAVE_PREV", merge_flag::HAVE_PREV),
    ("MERGE_FLAG_VERIFY", merge_flag::VERIFY),
    ("CANDIDATE_STAT_OFFERED", stat::CANDIDATE_OFFERED),
    ("CANDIDATE_STAT_LOST", stat::CANDIDATE_LOST),
    ("CANDIDATE_STAT_DROPPED", stat::CANDIDATE_DROPPED),
    ("CANDIDATE_STAT_UNMAPPED", stat::CANDIDATE_UNMAPPED),
    ("CANDIDATE_STAT_LOGGED", stat::CANDIDATE_LOGGED),
    ("CANDIDATE_STAT_OVERFLOWED", stat::CANDIDATE_OVERFLOWED),
    ("CANDIDATE_STAT_SLOTS", stat::CANDIDATE_SLOTS),
    ("CLAIM_COUNT", claim::COUNT),
    ("CLAIM_ARGS", claim::ARGS),
    ("CLAIM_FALLBACK_ARGS", claim::FALLBACK_ARGS),
    ("CLAIM_STRIDE", claim::STRIDE),
    ("CLAIM_HEADER_WORDS", claim::HEADER_WORDS),
    ("CLAIM_ADDR", claim::ADDR),
    ("CLAIM_KEY", claim::KEY),
    ("CLAIM_INFO", claim::INFO),
    ("CLAIM_PATH", claim::PATH),
    ("CLAIM_WORKGROUP", claim::WORKGROUP),
    ("MERGE_STAT_EVALUATIONS", stat::MERGE_EVALUATIONS),
    ("MERGE_STAT_DROPPED", stat::MERGE_DROPPED),
    ("MERGE_STAT_VERIFIED", stat::MERGE_VERIFIED),
    ("MERGE_STAT_VERIFY_MAX_ERROR", stat::MERGE_VERIFY_MAX_ERROR),
];

/// The WGSL of `gen/restir`.
pub fn wgsl() -> String {
    crate::gpu::shaders::constants_wgsl("src/optim/estimator/restir/abi.rs", CONSTANTS)
}

// The layout fits its words.
const _: () = {
    assert!(MAX_CAMERAS == 8);
    assert!(reservoir::TRI_BITS + 2 * reservoir::BARY_BITS == 64);
    assert!(reservoir::TECH_SHIFT > reservoir::CAMERA_SHIFT + 2);
    // Info words never have the key bit.
    assert!(reservoir::TECH_SHIFT + 1 < 32);
    assert!(reservoir::PATH_WORDS == 10 && reservoir::MAX_PATH_VERTICES == 3);
    // An entry holds the reservoir's words from TRI on after ADDR, KEY and INFO.
    assert!(claim::PATH == 3 && reservoir::TRI == 2);
    assert!(claim::FALLBACK_ARGS + 3 <= claim::STRIDE && claim::STRIDE < claim::HEADER_WORDS);
};
