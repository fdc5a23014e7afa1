#import shared/types
#import gen/abi
#import gen/restir
#import restir/reservoir_slots

// Streaming reservoir updates for parameter-space ReSTIR. A reservoir holds one path in
// res_stride words (the layout, RES_*, is generated from abi.rs): the camera
// sample that started it (pixel, camera, technique in RES_INFO), its weight sum (fresh
// reservoirs) or unbiased contribution weight W (merged), and the path in its compact form
// (compact_path.wgsl: the path's vertices, the incident direction at the last one in its
// shading frame, the radiance arriving there, the vertex of the texel's derivative) with the
// path's target under the previous state:
// for a fresh path the candidate pass computes it, for a merged one the merge stores the
// target it had there, which is its target under the previous state at the next merge.
// The path's factor for a texel (d(BRDF cos L_i)/d(texel) per image channel) is re-evaluated
// from these by the merge; its value is the pixel's adjoint times the factor, its target the
// luminance of the target adjoint times it.
// Target adjoint: the resampling targets use an exponential moving average of the adjoints,
// per pixel, a_t = s a_{t-1} + (1 - s) adjoint_t (s: RestirOptions::target_smoothing), which
// changes less between iterations than a noisy primal's adjoint; the values use the
// iteration's own adjoint. Any target that is non-zero wherever the value is keeps the
// estimate unbiased, and a_t is fixed before the gradient samples are drawn.
// Only texels that a camera observes have reservoirs: observed texel i (the compaction map,
// src/optim/estimator/restir/mod.rs) owns RESERVOIR_SLOTS slots, slot k at word
// i * res_stride of buffer `slots<k>`, and header word i, which says which slot holds
// its positive (sign 0) and its negative (sign 1) reservoir: two distinct slots, so two are
// free for the next iteration's fresh candidates (fresh_slot). The merge selects in place
// and rewrites the header: a kept sample is never copied.
// Passes that offer candidates declare `slots0` .. `slots3` as atomics.

// Selection without locks: an exponential race (weighted sampling by keys, Efraimidis and
// Spirakis). An offer of weight w with uniform u has key -ln(1 - u) / w, an exponential
// variable of rate w, and the smallest key among a reservoir's offers is offer j's with
// probability w_j / sum(w): exactly proportional to weight. Every offer adds its weight to
// the fresh reservoir's sum (RES_W) and enters its key into RES_INFO with atomicMax,
// complemented (the complement of a non-negative float's bits has the top bit, INFO_KEY_BIT,
// set, which no info word has; a free slot's info word is 0). Once every offer has entered,
// the offer whose key is the reservoir's swaps it for its info word with a compare-and-
// exchange (one offer wins even on a tie) and writes its path. An offer that found a smaller
// key in place when it entered can never win; the others (the race's leaders at the moment
// they entered, a few per reservoir) are appended to the claim log with their paths
// (restir_candidates.wgsl), and the claim pass (restir_claim.wgsl) lets each swap, without
// tracing its sample again. Where the log is full, the candidate pass runs a second time over
// the same samples with the same random numbers (CandidateParams.phase 1), and every offer
// whose key won claims as above: the same winners. No invocation waits for another. The lock
// this replaces (tested and set in the header, the critical section inside the loop iteration
// that took it) worked on lavapipe and starved on an NVIDIA H100, whose SIMD groups need not
// run the lane that holds a lock while its neighbours spin: 26 s per iteration, most offers
// lost.

// Tries of a compare-and-swap loop. A retry follows another invocation's success on the same
// word (a preempted thread delays only itself), so the bound would take that many updates of
// one reservoir in one iteration; an exhausted one is counted as lost.
const RESERVOIR_CAS_BOUND: u32 = 65536u;

// A candidate path for one texel.
struct Candidate {
    // Pixel | camera << INFO_CAMERA_SHIFT | technique << INFO_TECH_SHIFT (0 light, 1 BSDF).
    info: u32,
    // The path's words after RES_W (compact_path.wgsl, path_words), with its target
    // under the previous iteration's textures and target adjoint (0 when the merge will not
    // reuse).
    words: array<u32, RES_PATH_WORDS>,
}

fn slot_store(k: u32, i: u32, x: u32) {
    switch k {
        case 0u: {
            atomicStore(&slots0[i], x);
        }
        case 1u: {
            atomicStore(&slots1[i], x);
        }
        case 2u: {
            atomicStore(&slots2[i], x);
        }
        default: {
            atomicStore(&slots3[i], x);
        }
    }
}

fn slot_load(k: u32, i: u32) -> u32 {
    switch k {
        case 0u: {
            return atomicLoad(&slots0[i]);
        }
        case 1u: {
            return atomicLoad(&slots1[i]);
        }
        case 2u: {
            return atomicLoad(&slots2[i]);
        }
        default: {
            return atomicLoad(&slots3[i]);
        }
    }
}

// The word before the max.
fn slot_max(k: u32, i: u32, x: u32) -> u32 {
    switch k {
        case 0u: {
            return atomicMax(&slots0[i], x);
        }
        case 1u: {
            return atomicMax(&slots1[i], x);
        }
        case 2u: {
            return atomicMax(&slots2[i], x);
        }
        default: {
            return atomicMax(&slots3[i], x);
        }
    }
}

// Word i of slot k becomes x if it holds `old`; whether it did (a weak exchange may fail
// spuriously: callers retry).
fn slot_exchange(k: u32, i: u32, old: u32, x: u32) -> bool {
    switch k {
        case 0u: {
            return atomicCompareExchangeWeak(&slots0[i], old, x).exchanged;
        }
        case 1u: {
            return atomicCompareExchangeWeak(&slots1[i], old, x).exchanged;
        }
        case 2u: {
            return atomicCompareExchangeWeak(&slots2[i], old, x).exchanged;
        }
        default: {
            return atomicCompareExchangeWeak(&slots3[i], old, x).exchanged;
        }
    }
}

// The complemented race key of an offer of weight w > 0 with uniform u in [0, 1): larger wins.
// abs, not negation: -ln(1) would be -0.0, whose complement lacks the top bit.
fn race_key(w: f32, u: f32) -> u32 {
    return ~bitcast<u32>(abs(log(1.0 - u)) / w);
}

// What entering a race did.
const ENTER_LOST: u32 = 0u;
const ENTER_BEHIND: u32 = 1u;
const ENTER_LEADING: u32 = 2u;

// An offer to slot k of observed texel i: w into the weight sum, then the key into the race
// (only an offer whose weight was added can win). ENTER_LEADING if its key was the largest in
// place when it entered (it may win), ENTER_BEHIND if not (it cannot), ENTER_LOST if the
// addition ran out of tries (the caller counts it).
fn reservoir_enter(k: u32, i: u32, w: f32, u: f32) -> u32 {
    let base = i * res_stride;
    var old = slot_load(k, base + RES_W);
    for (var n = 0u; n < RESERVOIR_CAS_BOUND; n++) {
        if slot_exchange(k, base + RES_W, old, bitcast<u32>(bitcast<f32>(old) + w)) {
            let key = race_key(w, u);
            return select(ENTER_BEHIND, ENTER_LEADING, slot_max(k, base + RES_INFO, key) < key);
        }
        old = slot_load(k, base + RES_W);
    }
    return ENTER_LOST;
}

// The same offer (same w and u) once every offer has entered: if its key won, it takes the
// reservoir (its info word for the key) and writes its path.
fn reservoir_claim(k: u32, i: u32, w: f32, u: f32, c: Candidate) {
    reservoir_claim_key(k, i, race_key(w, u), c);
}

// reservoir_claim by the offer's race key.
fn reservoir_claim_key(k: u32, i: u32, key: u32, c: Candidate) {
    let base = i * res_stride;
    for (var n = 0u; n < RESERVOIR_CAS_BOUND; n++) {
        if slot_load(k, base + RES_INFO) != key {
            return;
        }
        if slot_exchange(k, base + RES_INFO, key, c.info) {
            for (var j = 0u; j < res_stride - RES_TRI; j++) {
                slot_store(k, base + RES_TRI + j, c.words[j]);
            }
            return;
        }
    }
}
