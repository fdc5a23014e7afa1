#import shared/types
#import gen/abi
#import gen/restir
#import restir/reservoir_slots

// Streaming reservoir updates for parameter-space ReSTIR. A reservoir holds one path in
// RESERVOIR_WORDS words (the layout, RES_*, is generated from abi.rs): the camera
// sample that started it (pixel, camera, technique in RES_INFO), its weight sum (fresh
// reservoirs) or unbiased contribution weight W (merged), and the path in its compact form
// (compact_path.wgsl: the camera ray's hit, the incident direction in the hit's
// shading frame, the incident radiance) with the path's target under the previous state:
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
// i * RESERVOIR_WORDS of buffer `slots<k>`, and header word i, which says which slot holds
// its positive (sign 0) and its negative (sign 1) reservoir: two distinct slots, so two are
// free for the next iteration's fresh candidates (fresh_slot). The merge selects in place
// and rewrites the header: a kept sample is never copied. The header's lock bits
// (HEADER_LOCK_SHIFT + sign) guard the fresh reservoirs while the candidate pass writes them.
// Passes that offer candidates declare `slots0` .. `slots3` and `headers` as atomics.

// Tries before an offer gives up (and is counted as lost). Invocations of one SIMD group
// never wait on each other (the holder finishes in the iteration that took the lock), so the
// bound only matters when the OS preempts a lavapipe thread that holds a lock. With many test
// threads on 2 cores that lasts tens of ms: 1024 tries lost hundreds of offers per run, 2^18
// tries (about 5 ms) still lost a few in CI; 2^22 (about 80 ms) outlasts a scheduler period.
// A holder always releases in the same iteration, so the bound is never reached otherwise.
const LOCK_BOUND: u32 = 4194304u;

// A candidate path for one texel.
struct Candidate {
    // Pixel | camera << INFO_CAMERA_SHIFT | technique << INFO_TECH_SHIFT (0 light, 1 BSDF).
    info: u32,
    // The path's words after RES_W (compact_path.wgsl, path_words), with its target
    // under the previous iteration's textures and target adjoint (0 when the merge will not
    // reuse).
    words: array<u32, 5>,
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

// Streaming update from many invocations at once. Design: a per-reservoir lock bit in the
// texel's header, taken with atomicOr (test and set), the critical section and the release
// inside the loop iteration that took it (a lock that spins first and works after the loop
// deadlocks within a SIMD group on lavapipe). Chosen over order-independent selection
// (atomicMin on -ln(u)/w keys), which is deterministic but needs a second pass in which every
// candidate is traced again to write its payload: the candidate pass is the expensive part,
// and doubling it would cost more than determinism is worth here. Every word is accessed
// atomically so that the next holder sees it. The candidate replaces the sample with
// probability w / (Wsum_before + w), which makes the selection exactly proportional to
// weight. Offers go to slot k of observed texel i, sign `sign`'s lock.
// Returns false if the bounded loop never got the lock (the caller counts it).
fn reservoir_offer(k: u32, i: u32, sign: u32, w: f32, u: f32, c: Candidate) -> bool {
    let bit = 1u << (HEADER_LOCK_SHIFT + sign);
    for (var n = 0u; n < LOCK_BOUND; n++) {
        if (atomicOr(&headers[i], bit) & bit) == 0u {
            let base = i * RESERVOIR_WORDS;
            let before = bitcast<f32>(slot_load(k, base + RES_W));
            let wsum = before + w;
            slot_store(k, base + RES_W, bitcast<u32>(wsum));
            // The first offer to an empty reservoir is always taken (u * wsum < w can fail
            // for a denormal w), so that its weight never stands beside the payload of an
            // older sample left in a free slot.
            if before == 0.0 || u * wsum < w {
                slot_store(k, base + RES_INFO, c.info);
                for (var j = 0u; j < 5u; j++) {
                    slot_store(k, base + RES_TRI + j, c.words[j]);
                }
            }
            atomicAnd(&headers[i], ~bit);
            return true;
        }
    }
    return false;
}
