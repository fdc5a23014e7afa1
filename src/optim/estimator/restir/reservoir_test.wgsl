// Test pass for the reservoir update: invocation i offers candidate i % n_candidates, with
// weight weights[i % n_candidates], to reservoir i / (n_candidates * copies), so that many
// invocations hit each reservoir at once (slot 0 of observed texel r), in the candidate
// pass's two phases (tp.phase: the race, then the winner's path). In phase 1 only the offers
// that led the race when they entered claim (`led`, as the claim log keeps only those). The
// test checks the selection frequencies.
#import shared/rng
#import gen/restir
#import restir/reservoir

struct ReservoirTestParams {
    n_candidates: u32,
    copies: u32,
    n_invocations: u32,
    seed: u32,
    phase: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> tp: ReservoirTestParams;
@group(0) @binding(1) var<storage, read> weights: array<f32>;
@group(0) @binding(2) var<storage, read_write> slots0: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> slots1: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> slots2: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read_write> slots3: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> headers: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read_write> failures: array<atomic<u32>>;
// Per invocation: whether its offer led the race when it entered (phase 0).
@group(0) @binding(8) var<storage, read_write> led: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let i = id.x;
    if i >= tp.n_invocations {
        return;
    }
    let c = i % tp.n_candidates;
    let r = i / (tp.n_candidates * tp.copies);
    let w = weights[c];
    if w <= 0.0 {
        return;
    }
    rng_init(tp.seed, i, 0u);
    let u = rand();
    if tp.phase == 0u {
        let e = reservoir_enter(0u, r, w, u);
        if e == ENTER_LOST {
            atomicAdd(&failures[0], 1u);
        }
        led[i] = u32(e == ENTER_LEADING);
    } else if led[i] != 0u {
        reservoir_claim(0u, r, w, u, Candidate(c, array<u32, RES_PATH_WORDS>(c, 0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u)));
    }
}
