#import shared/types

// Streaming reservoir updates for parameter-space ReSTIR. Layout of a reservoir
// (RESERVOIR_WORDS = 12 words, 48 bytes, in types.wgsl):
//   [0] camera-sample index   [1] seed of the gradient pass that drew it
//   [2] info: bit 0 technique (0 light sampling, 1 BSDF sampling), bits 1-7 camera; NONE = empty
//   [3] weight sum (fresh reservoirs) or unbiased contribution weight W (merged)
//   [4] confidence M          [5-7] the sample's value v (RGB; scalars use x)
//   [8-11] the camera ray's hit (t, triangle, b1, b2): replays start from it instead of
//   tracing the camera ray again (geometry and cameras do not change)
// Texel t owns reservoirs 2t (positive part of the target) and 2t + 1 (negative part).
// Passes that offer candidates declare `fresh` (the reservoirs, as atomics) and `locks`.

// Tries before an offer gives up (and is counted as lost). Invocations of one SIMD group
// never wait on each other (the holder finishes in the iteration that took the lock), so the
// bound only matters when the OS preempts a lavapipe thread that holds a lock. With many test
// threads on 2 cores that lasts tens of ms: 1024 tries lost hundreds of offers per run, 2^18
// tries (about 5 ms) still lost a few in CI; 2^22 (about 80 ms) outlasts a scheduler period.
// A holder always releases in the same iteration, so the bound is never reached otherwise.
const LOCK_BOUND: u32 = 4194304u;

// Streaming update from many invocations at once. Design: a per-reservoir lock taken with
// atomicCompareExchangeWeak, the critical section and the release inside the loop iteration
// that took it (a lock that spins first and works after the loop deadlocks within a SIMD group
// on lavapipe). Chosen over order-independent selection (atomicMin on -ln(u)/w keys), which
// is deterministic but needs a second pass in which every candidate is traced again to write
// its payload: the candidate pass is the expensive part, and doubling it would cost more than
// determinism is worth here. Every word is accessed atomically so that the next holder sees it. The
// candidate replaces the sample with probability w / (Wsum_before + w), which makes the
// selection exactly proportional to weight. Returns false if the bounded loop never got the
// lock (the caller counts it).
fn reservoir_offer(r: u32, w: f32, u: f32, sample: u32, seed: u32, info: u32, v: vec3f, hit: Hit) -> bool {
    for (var k = 0u; k < LOCK_BOUND; k++) {
        if atomicCompareExchangeWeak(&locks[r], 0u, 1u).exchanged {
            let base = r * RESERVOIR_WORDS;
            let wsum = bitcast<f32>(atomicLoad(&fresh[base + 3u])) + w;
            atomicStore(&fresh[base + 3u], bitcast<u32>(wsum));
            if u * wsum < w {
                atomicStore(&fresh[base], sample);
                atomicStore(&fresh[base + 1u], seed);
                atomicStore(&fresh[base + 2u], info);
                atomicStore(&fresh[base + 5u], bitcast<u32>(v.x));
                atomicStore(&fresh[base + 6u], bitcast<u32>(v.y));
                atomicStore(&fresh[base + 7u], bitcast<u32>(v.z));
                atomicStore(&fresh[base + 8u], bitcast<u32>(hit.t));
                atomicStore(&fresh[base + 9u], hit.tri);
                atomicStore(&fresh[base + 10u], bitcast<u32>(hit.b1));
                atomicStore(&fresh[base + 11u], bitcast<u32>(hit.b2));
            }
            atomicStore(&locks[r], 0u);
            return true;
        }
    }
    return false;
}
