//! The GPU contract: every constant that Rust and the WGSL passes share, defined once, here,
//! and generated into WGSL as `gen/abi` (a pass or shared file says `#import gen/abi`). Light
//! kinds, sampling techniques, the compact path encoding, the control variate's state size,
//! the step phases and the counter slot of the core passes' statistics buffers. An
//! estimator's own constants live in its folder and are generated as `gen/<its name>`.
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

/// The compact path encoding (`shared/path_encoding.wgsl`, WGSL `PATH_*`): what an estimator
/// that stores paths keeps of one (fixed-point barycentrics, an octahedral direction), and
/// what the integrator rounds to when it samples such paths.
pub mod path_encoding {
    /// Bits of each barycentric (fixed point in [0, 1)).
    pub const BARY_BITS: u32 = 20;
    /// Bits of each octahedral coordinate (fixed point in [-1, 1)).
    pub const OCT_BITS: u32 = 24;
}

/// vec4s of control-variate state per pixel (`primal_cv.wgsl`).
pub const CV_VEC4S: u32 = 8;

/// The path cache's layout (`primal/path_cache.wgsl`, WGSL `CACHE_*`): words of a stored
/// path's header, of each of its vertices and of each arrival (two per vertex), and the
/// most vertices a path keeps (the integrator's `PATH_RECORD_VERTICES`).
pub mod path_cache {
    /// The header, and the radiance along the camera ray.
    pub const HEADER_WORDS: u32 = 4;
    /// Triangle, barycentrics, material, uv, position, two directions, the glTF inputs.
    pub const VERTEX_WORDS: u32 = 20;
    /// Tag, two directions, radiance, factor.
    pub const ARRIVAL_WORDS: u32 = 11;
    /// Vertices of the deepest path kept.
    pub const MAX_VERTICES: u32 = 3;
}

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
    /// The step passes (`adam.wgsl`, `variance_step.wgsl`): non-finite gradients, whose
    /// parameter was left unchanged.
    pub const STEP_SKIPPED: u32 = 0;
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
    ("PATH_BARY_BITS", path_encoding::BARY_BITS),
    ("PATH_OCT_BITS", path_encoding::OCT_BITS),
    ("CV_VEC4S", CV_VEC4S),
    ("CACHE_HEADER_WORDS", path_cache::HEADER_WORDS),
    ("CACHE_VERTEX_WORDS", path_cache::VERTEX_WORDS),
    ("CACHE_ARRIVAL_WORDS", path_cache::ARRIVAL_WORDS),
    ("CACHE_MAX_VERTICES", path_cache::MAX_VERTICES),
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
    ("STEP_STAT_SKIPPED", stat::STEP_SKIPPED),
];

/// The WGSL of `gen/abi`.
pub fn wgsl() -> String {
    crate::gpu::shaders::constants_wgsl("src/gpu/abi.rs", CONSTANTS)
}
