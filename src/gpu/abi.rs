//! The GPU contract: every constant that Rust and the WGSL passes share, defined once, here,
//! and generated into WGSL as `gen/abi` (a pass or shared file says `#import gen/abi`). Light
//! kinds, sampling techniques, ReSTIR's reservoir layout, camera limit and merge flags, the
//! control variate's state size, and the counter slot of every pass's statistics buffer.
//! This module imports nothing, so every layer can use it; a test checks that no WGSL file
//! defines one of these names itself or indexes a statistics buffer by a literal.

/// Light kinds (`Light.kind`; WGSL `LIGHT_*`).
pub mod light {
    /// Point light.
    pub const POINT: u32 = 0;
    /// Spot light.
    pub const SPOT: u32 = 1;
    /// Directional light.
    pub const DIRECTIONAL: u32 = 2;
    /// Emissive triangle.
    pub const AREA: u32 = 3;
    /// Environment map.
    pub const ENV: u32 = 4;
}

/// Which techniques sample area and environment lights (WGSL `TECH_*`; delta lights always
/// use light sampling).
pub mod technique {
    /// Light sampling (next-event estimation) only.
    pub const NEE: u32 = 1;
    /// BSDF sampling only.
    pub const BSDF: u32 = 2;
    /// Both, combined by MIS.
    pub const MIS: u32 = 3;
}

/// ReSTIR's reservoirs in their compact form: word offsets within a reservoir, the packing
/// of its words, a texel's slots and header (WGSL: `RES_*`, `INFO_*`, `RESERVOIR_WORDS`,
/// `RESERVOIR_SLOTS`, `HEADER_*`). A reservoir stores its path as the camera ray's hit
/// (triangle and barycentrics), the incident direction in the hit's shading frame and the
/// incident radiance; everything else the BRDF needs is rebuilt from the scene
/// (shaders/shared/compact_path.wgsl; the precision of each encoding is stated in
/// `crate::optim::estimator::compact`).
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
    /// Incident radiance, RGB with a shared exponent (RGBE, 8 bits each).
    pub const RADIANCE: u32 = 6;
    /// Words per reservoir.
    pub const WORDS: u32 = 7;
    /// Bits of the triangle index (ReSTIR handles scenes of up to 2^24 triangles).
    pub const TRI_BITS: u32 = 24;
    /// Bits of each barycentric (fixed point in [0, 1)).
    pub const BARY_BITS: u32 = 20;
    /// Bits of each octahedral coordinate (fixed point in [-1, 1)).
    pub const OCT_BITS: u32 = 24;
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
    /// The header's lock bit of sign 0's fresh reservoir (sign 1's is the next bit): the
    /// candidate pass takes it while it writes that reservoir.
    pub const HEADER_LOCK_SHIFT: u32 = 2 * HEADER_SLOT_BITS;
    /// The header of a texel whose reservoirs lie in slots 0 (sign 0) and 1 (sign 1).
    pub const HEADER_FIRST_TWO: u32 = 1 << HEADER_SLOT_BITS;
    /// Marks a texel no camera observes in the compaction map's lookups (u32::MAX).
    pub const UNOBSERVED: u32 = u32::MAX;

    /// The slot of sign `sign`'s reservoir in header `h`.
    pub fn header_slot(h: u32, sign: u32) -> u32 {
        (h >> (HEADER_SLOT_BITS * sign)) & HEADER_SLOT_MASK
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

/// vec4s of control-variate state per pixel (`primal_cv.wgsl`).
pub const CV_VEC4S: u32 = 8;

/// The phases of a step pass (WGSL `STEP_PHASE_*`).
pub mod step_phase {
    //! What a step pass (`adam.wgsl`, `variance_step.wgsl`) does in one dispatch: the whole
    //! step (no moment filter), or, around the moment filter (`moment_filter.wgsl`), first
    //! the pair it filters and then the step from the filtered pair.
    /// Update the moments and step, in one dispatch.
    pub const FUSED: u32 = 0;
    /// Update the moments and write the pair that the moment filter smooths.
    pub const PAIR: u32 = 1;
    /// Step from the filtered pair.
    pub const FILTERED: u32 = 2;
}

/// Counter slots of each pass's statistics buffer (WGSL `<PASS>_STAT_*`).
pub mod stat {
    /// `render.wgsl`: camera rays.
    pub const RENDER_CAMERA_RAYS: u32 = 0;
    /// `render.wgsl`: shadow rays.
    pub const RENDER_SHADOW_RAYS: u32 = 1;
    /// `render.wgsl`: BSDF rays.
    pub const RENDER_BSDF_RAYS: u32 = 2;
    /// `render.wgsl`: non-finite samples dropped.
    pub const RENDER_DROPPED: u32 = 3;
    /// `gradient.wgsl`: camera samples.
    pub const GRADIENT_SAMPLES: u32 = 0;
    /// `gradient.wgsl`: float additions whose compare-and-swap loop ran out.
    pub const GRADIENT_LOST: u32 = 1;
    /// `gradient.wgsl`: non-finite contributions dropped.
    pub const GRADIENT_DROPPED: u32 = 2;
    /// `loss.wgsl`: non-finite pixels dropped.
    pub const LOSS_DROPPED: u32 = 0;
    /// `adam.wgsl`: non-finite gradients, whose parameter was left unchanged.
    pub const ADAM_SKIPPED: u32 = 0;
    /// `restir_candidates.wgsl`: candidates offered.
    pub const CANDIDATE_OFFERED: u32 = 0;
    /// `restir_candidates.wgsl`: offers whose lock loop ran out.
    pub const CANDIDATE_LOST: u32 = 1;
    /// `restir_candidates.wgsl`: non-finite candidates dropped.
    pub const CANDIDATE_DROPPED: u32 = 2;
    /// `restir_candidates.wgsl`: candidates for texels outside the compaction map (texels
    /// that the observed-texel pass's strata missed), dropped.
    pub const CANDIDATE_UNMAPPED: u32 = 3;
    /// `restir_merge.wgsl`: kept paths evaluated.
    pub const MERGE_EVALUATIONS: u32 = 0;
    /// `restir_merge.wgsl`: non-finite values dropped.
    pub const MERGE_DROPPED: u32 = 1;
    /// `restir_merge.wgsl`: paths verified (tests).
    pub const MERGE_VERIFIED: u32 = 2;
    /// `restir_merge.wgsl`: largest verification error (f32 bits).
    pub const MERGE_VERIFY_MAX_ERROR: u32 = 3;
}

/// Every constant above, as (WGSL name, value).
pub const CONSTANTS: &[(&str, u32)] = &[
    ("LIGHT_POINT", light::POINT),
    ("LIGHT_SPOT", light::SPOT),
    ("LIGHT_DIRECTIONAL", light::DIRECTIONAL),
    ("LIGHT_AREA", light::AREA),
    ("LIGHT_ENV", light::ENV),
    ("TECH_NEE", technique::NEE),
    ("TECH_BSDF", technique::BSDF),
    ("TECH_MIS", technique::MIS),
    ("RESERVOIR_WORDS", reservoir::WORDS),
    ("RES_INFO", reservoir::INFO),
    ("RES_W", reservoir::W),
    ("RES_TRI", reservoir::TRI),
    ("RES_BARY", reservoir::BARY),
    ("RES_WI_X", reservoir::WI_X),
    ("RES_WI_Y", reservoir::WI_Y),
    ("RES_RADIANCE", reservoir::RADIANCE),
    ("RES_TRI_BITS", reservoir::TRI_BITS),
    ("RES_BARY_BITS", reservoir::BARY_BITS),
    ("RES_OCT_BITS", reservoir::OCT_BITS),
    ("RESERVOIR_SLOTS", reservoir::SLOTS),
    ("HEADER_SLOT_BITS", reservoir::HEADER_SLOT_BITS),
    ("HEADER_SLOT_MASK", reservoir::HEADER_SLOT_MASK),
    ("HEADER_LOCK_SHIFT", reservoir::HEADER_LOCK_SHIFT),
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
    ("CV_VEC4S", CV_VEC4S),
    ("STEP_PHASE_FUSED", step_phase::FUSED),
    ("STEP_PHASE_PAIR", step_phase::PAIR),
    ("STEP_PHASE_FILTERED", step_phase::FILTERED),
    ("RENDER_STAT_CAMERA_RAYS", stat::RENDER_CAMERA_RAYS),
    ("RENDER_STAT_SHADOW_RAYS", stat::RENDER_SHADOW_RAYS),
    ("RENDER_STAT_BSDF_RAYS", stat::RENDER_BSDF_RAYS),
    ("RENDER_STAT_DROPPED", stat::RENDER_DROPPED),
    ("GRADIENT_STAT_SAMPLES", stat::GRADIENT_SAMPLES),
    ("GRADIENT_STAT_LOST", stat::GRADIENT_LOST),
    ("GRADIENT_STAT_DROPPED", stat::GRADIENT_DROPPED),
    ("LOSS_STAT_DROPPED", stat::LOSS_DROPPED),
    ("ADAM_STAT_SKIPPED", stat::ADAM_SKIPPED),
    ("CANDIDATE_STAT_OFFERED", stat::CANDIDATE_OFFERED),
    ("CANDIDATE_STAT_LOST", stat::CANDIDATE_LOST),
    ("CANDIDATE_STAT_DROPPED", stat::CANDIDATE_DROPPED),
    ("CANDIDATE_STAT_UNMAPPED", stat::CANDIDATE_UNMAPPED),
    ("MERGE_STAT_EVALUATIONS", stat::MERGE_EVALUATIONS),
    ("MERGE_STAT_DROPPED", stat::MERGE_DROPPED),
    ("MERGE_STAT_VERIFIED", stat::MERGE_VERIFIED),
    ("MERGE_STAT_VERIFY_MAX_ERROR", stat::MERGE_VERIFY_MAX_ERROR),
];

/// The WGSL of `gen/abi`.
pub fn wgsl() -> String {
    let mut s = String::from("// Generated from src/gpu/abi.rs; edit the Rust side.\n");
    for (name, v) in CONSTANTS {
        s.push_str(&format!("const {name}: u32 = {v}u;\n"));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_wgsl_file_defines_a_shared_constant_or_indexes_a_counter_by_a_literal() {
        for (file, source) in crate::gpu::shaders::SOURCES {
            for (name, _) in CONSTANTS {
                assert!(
                    !source.contains(&format!("const {name}:")),
                    "shaders/{file}.wgsl defines {name}, which src/gpu/abi.rs generates"
                );
            }
            // A statistics buffer (`stats`, `gstats`, `loss_stats`, ...) indexed by a digit.
            for (i, _) in source.match_indices("stats[") {
                let next = source[i + 6..].chars().next().unwrap_or(' ');
                assert!(
                    !next.is_ascii_digit(),
                    "shaders/{file}.wgsl indexes a statistics buffer by a literal: {}",
                    &source[i.saturating_sub(20)..(i + 10).min(source.len())]
                );
            }
        }
    }

    #[test]
    fn the_constants_are_unique_and_generated() {
        let mut names: Vec<&str> = CONSTANTS.iter().map(|(n, _)| *n).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), CONSTANTS.len(), "a name is listed twice");
        let w = wgsl();
        for (name, v) in CONSTANTS {
            assert!(w.contains(&format!("const {name}: u32 = {v}u;")));
        }
        assert_eq!(MAX_CAMERAS, 8);
        assert_eq!(reservoir::TRI_BITS + 2 * reservoir::BARY_BITS, 64);
        assert!(reservoir::HEADER_LOCK_SHIFT + 2 <= 32);
    }
}
