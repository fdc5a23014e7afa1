//! Random seeds of the passes: one independent stream per iteration, camera and kind.

fn mix64(mut x: u64) -> u64 {
    // splitmix64 finalizer
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The kinds of pass that [`pass_seed`] gives independent random streams.
pub struct Seeds;

impl Seeds {
    /// The primal render of an iteration.
    pub const PRIMAL: u32 = 0;
    /// The gradient (or ReSTIR candidate) pass.
    pub const GRADIENT: u32 = 1;
    /// Target renders.
    pub const TARGET: u32 = 2;
    /// Evaluation and final renders.
    pub const EVAL: u32 = 3;
    /// ReSTIR's merge.
    pub const MERGE: u32 = 4;
    /// The tile-grid shift of the multiscale gradient.
    pub const MULTISCALE: u32 = 5;
}

/// Seed of pass `kind` ([`Seeds`]) of camera `camera` at iteration `iteration`: independent
/// streams, so the adjoint never shares random numbers with the gradient samples.
pub fn pass_seed(seed: u32, iteration: u32, camera: u32, kind: u32) -> u32 {
    let x =
        mix64(mix64(mix64(seed as u64) ^ iteration as u64) ^ ((camera as u64) << 8 | kind as u64));
    x as u32
}
