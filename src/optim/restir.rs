//! Options of the parameter-space ReSTIR estimator (shaders restir_candidates.wgsl and
//! restir_merge.wgsl; the per-iteration driving is in [`super::Optimizer`]).

/// Words per reservoir. Keep in sync with RESERVOIR_WORDS in shaders/shared/types.wgsl.
pub const RESERVOIR_WORDS: u64 = 12;

/// Bytes of ReSTIR state per texel: two reservoirs (positive and negative) in each of two
/// buffers (kept and fresh/merged), and a lock word per reservoir.
pub const STATE_BYTES_PER_TEXEL: u64 = 2 * 2 * RESERVOIR_WORDS * 4 + 2 * 4;

/// How the ReSTIR estimator reuses samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestirOptions {
    /// Cap on the confidence of the kept sample (the knob between reuse and staleness).
    pub m_cap: f32,
    /// Temporal reuse across iterations; without it, resampling within the iteration only.
    pub temporal: bool,
    /// Two reservoirs per texel (positive and negative part of the target); without it, one
    /// over |target|.
    pub positivization: bool,
}

impl Default for RestirOptions {
    fn default() -> Self {
        RestirOptions {
            m_cap: 16.0,
            temporal: true,
            positivization: true,
        }
    }
}

/// The gradient estimator.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Method {
    /// Plain Monte Carlo: every candidate adds its value to the texels it touches.
    Baseline,
    /// Parameter-space ReSTIR.
    #[default]
    Restir,
}

/// Run the streaming reservoir update of shaders/shared/reservoir.wgsl on the GPU for a test:
/// `reservoirs` reservoirs each receive every candidate k (weight `weights[k]`) `copies`
/// times, from concurrent invocations. Returns the index of the candidate each reservoir
/// selected (u32::MAX for none) and the number of offers that never got the lock.
pub fn selection_trial(
    gpu: &crate::gpu::Gpu,
    weights: &[f32],
    copies: u32,
    reservoirs: u32,
    seed: u32,
) -> crate::Result<(Vec<u32>, u32)> {
    use crate::gpu::Binding::*;
    let n_candidates = weights.len() as u32;
    let n_invocations = n_candidates * copies * reservoirs;
    let params: [u32; 4] = [n_candidates, copies, n_invocations, seed];
    let layout = gpu.layout(
        "reservoir_test",
        &[Uniform, Storage, StorageRw, StorageRw, StorageRw],
    );
    let pipeline = gpu.compute_pipeline("reservoir_test", &[&layout])?;
    let uniform = gpu.uniform("reservoir_test params", bytemuck::cast_slice(&params));
    let w = gpu.storage(
        "reservoir_test weights",
        bytemuck::cast_slice(weights),
        wgpu::BufferUsages::empty(),
    );
    let res = gpu.storage_zeroed(
        "reservoir_test reservoirs",
        reservoirs as u64 * RESERVOIR_WORDS * 4,
    );
    // Empty reservoirs select nothing: info words hold NONE.
    let mut init = vec![0u32; (reservoirs as u64 * RESERVOIR_WORDS) as usize];
    for r in 0..reservoirs as usize {
        init[r * RESERVOIR_WORDS as usize] = u32::MAX;
    }
    gpu.queue.write_buffer(&res, 0, bytemuck::cast_slice(&init));
    let locks = gpu.storage_zeroed("reservoir_test locks", reservoirs as u64 * 4);
    let failures = gpu.storage_zeroed("reservoir_test failures", 16);
    let group = gpu.bind_group(
        "reservoir_test",
        &layout,
        &[&uniform, &w, &res, &locks, &failures],
    );
    let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
    let grid = crate::gpu::grid_2d(n_invocations, crate::render::WORKGROUP, max_dim);
    if grid.1 > 1 {
        return Err(crate::Error::Invalid(
            "selection_trial: too many invocations".into(),
        ));
    }
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("reservoir_test"),
        });
    crate::render::encode_pass(&mut enc, "reservoir_test", &pipeline, &[&group], grid);
    gpu.queue.submit([enc.finish()]);
    let out: Vec<u32> = gpu.read_pod(&res)?;
    let fails: Vec<u32> = gpu.read_pod(&failures)?;
    let selected = (0..reservoirs as usize)
        .map(|r| out[r * RESERVOIR_WORDS as usize])
        .collect();
    Ok((selected, fails[0]))
}
