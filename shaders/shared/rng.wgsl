// Counter-based random numbers: a sample is fully determined by (seed, sample index, dimension),
// so a pass can draw the same samples as another from the same camera-sample index.

var<private> rng_state: u32;

fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rng_init(seed: u32, sample_index: u32, stream: u32) {
    rng_state = pcg_hash(seed ^ pcg_hash(sample_index ^ pcg_hash(stream)));
}

fn rand_u32() -> u32 {
    rng_state = rng_state * 747796405u + 2891336453u;
    let s = rng_state;
    let word = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    return (word >> 22u) ^ word;
}

// Uniform in [0, 1).
fn rand() -> f32 {
    return f32(rand_u32() >> 8u) * (1.0 / 16777216.0);
}

fn rand2() -> vec2f {
    let a = rand();
    let b = rand();
    return vec2f(a, b);
}
