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
        "tp", "weights", "slots0", "slots1", "slots2", "slots3", "headers", "failures", "led",
    ],
};

/// Run the reservoir update of reservoir.wgsl on the GPU for a test, both phases (in the
/// second, as the claim log, only the offers that led the race when they entered claim):
/// `reservoirs` reservoirs each receive every candidate k (weight `weights[k]`) `copies`
/// times, from concurrent invocations. Returns the index of the candidate each reservoir
/// selected (u32::MAX for none) and the number of offers whose weight was not added.
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
    let layout = gpu.pass_layout("reservoir_test", 0)?;
    let pipeline = gpu.compute_pipeline("reservoir_test", &[&layout])?;
    let uniforms: Vec<wgpu::Buffer> = (0..2u32)
        .map(|phase| {
            let params: [u32; 8] = [n_candidates, copies, n_invocations, seed, phase, 0, 0, 0];
            gpu.uniform(
                &format!("reservoir_test params phase {phase}"),
                bytemuck::cast_slice(&params),
            )
        })
        .collect();
    let w = gpu.storage(
        "reservoir_test weights",
        bytemuck::cast_slice(weights),
        wgpu::BufferUsages::empty(),
    );
    // Empty, as the merge leaves a free slot: weight sum and info word 0.
    let init = vec![0u32; reservoirs as usize * words];
    let res = gpu.storage(
        "reservoir_test reservoirs",
        bytemuck::cast_slice(&init),
        wgpu::BufferUsages::COPY_SRC,
    );
    // Slots 1 to 3 take no offers here.
    let unused: Vec<wgpu::Buffer> = (1..4)
        .map(|k| gpu.storage_zeroed(&format!("reservoir_test slots{k}"), 16))
        .collect();
    let headers = gpu.storage_zeroed("reservoir_test headers", reservoirs as u64 * 4);
    let failures = gpu.storage_zeroed("reservoir_test failures", 16);
    let led = gpu.storage_zeroed("reservoir_test leaders", n_invocations as u64 * 4);
    let groups: Vec<wgpu::BindGroup> = uniforms
        .iter()
        .map(|uniform| {
            gpu.bind(
                &RESERVOIR_TEST_GROUP,
                "reservoir_test",
                &layout,
                &[
                    ("tp", uniform),
                    ("weights", &w),
                    ("slots0", &res),
                    ("slots1", &unused[0]),
                    ("slots2", &unused[1]),
                    ("slots3", &unused[2]),
                    ("headers", &headers),
                    ("failures", &failures),
                    ("led", &led),
                ],
            )
        })
        .collect();
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
    for group in &groups {
        crate::gpu::encode_pass(&mut enc, "reservoir_test", &pipeline, &[group], grid);
    }
    gpu.queue.submit([enc.finish()]);
    let out: Vec<u32> = gpu.read_pod(&res)?;
    let fails: Vec<u32> = gpu.read_pod(&failures)?;
    // None: no weight (no offer), or an info word that still holds a race key (no offer
    // wrote its path).
    let selected = (0..reservoirs as usize)
        .map(|r| {
            let info = out[r * words + reservoir::INFO as usize];
            let w = f32::from_bits(out[r * words + reservoir::W as usize]);
            if w == 0.0 || info & reservoir::KEY_BIT != 0 {
                u32::MAX
            } else {
                info
            }
        })
        .collect();
    Ok((selected, fails[0]))
}
