//! Adam: the constants, and a CPU reference of shaders/adam.wgsl.

/// First-moment decay.
pub const BETA1: f32 = 0.9;
/// Second-moment decay.
pub const BETA2: f32 = 0.999;
/// Denominator epsilon.
pub const EPS: f32 = 1e-8;

/// One Adam step at step number `t` (from 1) with clamping to `[lo, hi]`, on the CPU.
#[allow(clippy::too_many_arguments)]
pub fn step(
    params: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    grad: &[f32],
    lr: f32,
    t: u32,
    lo: f32,
    hi: f32,
) {
    step_masked(params, m, v, grad, lr, t, lo, hi, false)
}

/// [`step`], where with `mask` an entry whose gradient is exactly zero keeps its value and
/// moments (sparse Adam).
#[allow(clippy::too_many_arguments)]
pub fn step_masked(
    params: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    grad: &[f32],
    lr: f32,
    t: u32,
    lo: f32,
    hi: f32,
    mask: bool,
) {
    let bias1 = 1.0 - BETA1.powi(t as i32);
    let bias2 = 1.0 - BETA2.powi(t as i32);
    for i in 0..params.len() {
        let g = grad[i];
        if !g.is_finite() || (mask && g == 0.0) {
            continue;
        }
        m[i] = BETA1 * m[i] + (1.0 - BETA1) * g;
        v[i] = BETA2 * v[i] + (1.0 - BETA2) * g * g;
        let s = lr * (m[i] / bias1) / ((v[i] / bias2).sqrt() + EPS);
        params[i] = (params[i] - s).clamp(lo, hi);
    }
}

/// `AdamParams` in shaders/adam.wgsl (a test checks the layout).
/// The fields are documented in the WGSL twin.
#[allow(missing_docs)]
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AdamParams {
    pub offset: u32,
    pub count: u32,
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    pub bias1: f32,
    pub bias2: f32,
    pub lo: f32,
    pub hi: f32,
    pub mask: u32,
    pub _pad: u32,
}
