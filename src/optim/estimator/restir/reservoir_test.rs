//! The reservoir selection test pass (`reservoir_test.wgsl` in this folder): the streaming update of
//! reservoir.wgsl run on the GPU, for the chi-square test of its selection.
use super::abi::reservoir;
use crate::gpu::{grid_2d, Gpu};
use crate::render::WORKGROUP;
use crate::{Error, Result};

/// Group 0 of `reservoir_test.wgsl`.
pub(crate) const RESERVOIR_TEST_GROUP: crate::gpu::GroupDecl = crate::gpu::GroupDecl {
    pass: "reservoir_test",
    group: 0,
    names: &[
        "tp", "weights", "slots0", "slots1", "slots2", "slots3", "headers", "failures",
    ],
};

/// Run the streaming reservoir update of reservoir.wgsl on the GPU for a test:
/// `reservoirs` reservoirs each receive every candidate k (weight `weights[k]`) `copies`
/// times, from concurrent invocations. Returns the index of the candidate each reservoir
/// selected (u32::MAX for none) and the number of offers that never got the lock.
pub fn selection_trial(
    gpu: &Gpu,
    weights: &[f32],
    copies: u32,
    reservoirs: u32,
    seed: u32,
) -> Result<(Vec<u32>, u32)> {
    let words = reservoir::WORDS as usize;
    let n_candidates = weights.len() as u32;
    let n_invocations = n_candidates * copies * reservoirs;
    let params: [u32; 4] = [n_candidates, copies, n_invocations, seed];
    let layout = gpu.pass_layout("reservoir_test", 0)?;
    let pipeline = gpu.compute_pipeline("reservoir_test", &[&layout])?;
    let uniform = gpu.uniform("reservoir_test params", bytemuck::cast_slice(&params));
    let w = gpu.storage(
        "reservoir_test weights",
        bytemuck::cast_slice(weights),
        wgpu::BufferUsages::empty(),
    );
    // Empty reservoirs select nothing: info words hold u32::MAX.
    let mut init = vec![0u32; reservoirs as usize * words];
    for r in 0..reservoirs as usize {
        init[r * words + reservoir::INFO as usize] = u32::MAX;
    }
    let res = gpu.storage(
        "reservoir_test reservoirs",
        bytemuck::cast_slice(&init),
        wgpu::BufferUsages::COPY_SRC,
    );
    // Slots 1 to 3 take no offers here; the headers hold the locks.
    let unused: Vec<wgpu::Buffer> = (1..4)
        .map(|k| gpu.storage_zeroed(&format!("reservoir_test slots{k}"), 16))
        .collect();
    let headers = gpu.storage_zeroed("reservoir_test headers", reservoirs as u64 * 4);
    let failures = gpu.storage_zeroed("reservoir_test failures", 16);
    let group = gpu.bind(
        &RESERVOIR_TEST_GROUP,
        "reservoir_test",
        &layout,
        &[
            ("tp", &uniform),
            ("weights", &w),
            ("slots0", &res),
            ("slots1", &unused[0]),
            ("slots2", &unused[1]),
            ("slots3", &unused[2]),
            ("headers", &headers),
            ("failures", &failures),
        ],
    );
    let max_dim = gpu.device.limits().max_compute_workgroups_per_dimension;
    let grid = grid_2d(n_invocations, WORKGROUP, max_dim);
    if grid.1 > 1 {
        return Err(Error::Invalid(
            "selection_trial: too many invocations".into(),
        ));
    }
    let mut enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("reservoir_test"),
        });
    crate::gpu::encode_pass(&mut enc, "reservoir_test", &pipeline, &[&group], grid);
    gpu.queue.submit([enc.finish()]);
    let out: Vec<u32> = gpu.read_pod(&res)?;
    let fails: Vec<u32> = gpu.read_pod(&failures)?;
    let selected = (0..reservoirs as usize)
        .map(|r| out[r * words + reservoir::INFO as usize])
        .collect();
    Ok((selected, fails[0]))
}
