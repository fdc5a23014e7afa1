#import shared/types
#import gen/abi
#import shared/reservoir_slots

// Streaming reservoir updates for parameter-space ReSTIR. A reservoir holds one path (the
// layout, RES_* and RESERVOIR_WORDS, is generated from src/optim/estimator/restir.rs): the
// camera sample that started it (pixel, camera, technique in RES_INFO), what the BRDF needs of
// the camera ray's hit (material, texture coordinates, the outgoing and incident directions
// in its shading frame, octahedral, and the material inputs no optimized texture replaces)
// and the radiance arriving along the incident direction, with its factor under the
// iteration's textures (the derivative d(BRDF cos L_i)/d(texel) per image channel: the value
// is the pixel's adjoint times it, the target the luminance of the target adjoint times it),
// and the weight sum (fresh reservoirs) or unbiased contribution weight W (merged).
// Target adjoint: the resampling targets use an exponential moving average of the adjoints,
// per pixel, a_t = s a_{t-1} + (1 - s) adjoint_t (s: RestirOptions::target_smoothing), which
// changes less between iterations than a noisy primal's adjoint; the values use the
// iteration's own adjoint. Any target that is non-zero wherever the value is keeps the
// estimate unbiased, and a_t is fixed before the gradient samples are drawn.
// Texel t owns RESERVOIR_SLOTS reservoir slots, 4t to 4t + 3, and a header word that says
// which slot holds its positive (sign 0) and its negative (sign 1) reservoir: two distinct
// slots, so two are free for the next iteration's fresh candidates (fresh_slot). The merge
// selects in place and rewrites the header: a kept sample is never copied.
// Passes that offer candidates declare `fresh` (the slots, as atomics) and `locks` (one word
// per texel and sign).

// Tries before an offer gives up (and is counted as lost). Invocations of one SIMD group
// never wait on each other (the holder finishes in the iteration that took the lock), so the
// bound only matters when the OS preempts a lavapipe thread that holds a lock. With many test
// threads on 2 cores that lasts tens of ms: 1024 tries lost hundreds of offers per run, 2^18
// tries (about 5 ms) still lost a few in CI; 2^22 (about 80 ms) outlasts a scheduler period.
// A holder always releases in the same iteration, so the bound is never reached otherwise.
const LOCK_BOUND: u32 = 4194304u;

// A candidate path and its factor for one texel.
struct Candidate {
    // Pixel | camera << INFO_CAMERA_SHIFT | technique << INFO_TECH_SHIFT (0 light, 1 BSDF).
    info: u32,
    // d(BRDF cos L_i)/d(texel) per image channel, before the adjoint (RES_VALUE).
    value: vec3f,
    // The path's first vertex as path_factor (shared/surface.wgsl) evaluates it.
    vertex: PathVertex,
    radiance: vec3f,
    // Target of the path for this texel under the previous iteration's textures and target
    // adjoint (0 when the merge will not reuse; RES_Q_PREV).
    q_prev: f32,
}

// Streaming update from many invocations at once. Design: a per-reservoir lock taken with
// atomicCompareExchangeWeak, the critical section and the release inside the loop iteration
// that took it (a lock that spins first and works after the loop deadlocks within a SIMD group
// on lavapipe). Chosen over order-independent selection (atomicMin on -ln(u)/w keys), which
// is deterministic but needs a second pass in which every candidate is traced again to write
// its payload: the candidate pass is the expensive part, and doubling it would cost more than
// determinism is worth here. Every word is accessed atomically so that the next holder sees it. The
// candidate replaces the sample with probability w / (Wsum_before + w), which makes the
// selection exactly proportional to weight. Offers to reservoir r hold lock word `lock`.
// Returns false if the bounded loop never got the lock (the caller counts it).
fn reservoir_offer(r: u32, lock: u32, w: f32, u: f32, c: Candidate) -> bool {
    for (var k = 0u; k < LOCK_BOUND; k++) {
        if atomicCompareExchangeWeak(&locks[lock], 0u, 1u).exchanged {
            let base = r * RESERVOIR_WORDS;
            let before = bitcast<f32>(atomicLoad(&fresh[base + RES_W]));
            let wsum = before + w;
            atomicStore(&fresh[base + RES_W], bitcast<u32>(wsum));
            // The first offer to an empty reservoir is always taken (u * wsum < w can fail
            // for a denormal w), so that its weight never stands beside the payload of an
            // older sample left in a free slot.
            if before == 0.0 || u * wsum < w {
                atomicStore(&fresh[base + RES_INFO], c.info);
                atomicStore(&fresh[base + RES_VALUE], bitcast<u32>(c.value.x));
                atomicStore(&fresh[base + RES_VALUE + 1u], bitcast<u32>(c.value.y));
                atomicStore(&fresh[base + RES_VALUE + 2u], bitcast<u32>(c.value.z));
                atomicStore(&fresh[base + RES_MATERIAL], c.vertex.material);
                atomicStore(&fresh[base + RES_UV], bitcast<u32>(c.vertex.uv.x));
                atomicStore(&fresh[base + RES_UV + 1u], bitcast<u32>(c.vertex.uv.y));
                atomicStore(&fresh[base + RES_WI], bitcast<u32>(c.vertex.wi.x));
                atomicStore(&fresh[base + RES_WI + 1u], bitcast<u32>(c.vertex.wi.y));
                atomicStore(&fresh[base + RES_WO], bitcast<u32>(c.vertex.wo.x));
                atomicStore(&fresh[base + RES_WO + 1u], bitcast<u32>(c.vertex.wo.y));
                atomicStore(&fresh[base + RES_RADIANCE], bitcast<u32>(c.radiance.x));
                atomicStore(&fresh[base + RES_RADIANCE + 1u], bitcast<u32>(c.radiance.y));
                atomicStore(&fresh[base + RES_RADIANCE + 2u], bitcast<u32>(c.radiance.z));
                atomicStore(&fresh[base + RES_Q_PREV], bitcast<u32>(c.q_prev));
                atomicStore(&fresh[base + RES_FIXED], bitcast<u32>(c.vertex.fixed.x));
                atomicStore(&fresh[base + RES_FIXED + 1u], bitcast<u32>(c.vertex.fixed.y));
                atomicStore(&fresh[base + RES_FIXED + 2u], bitcast<u32>(c.vertex.fixed.z));
                atomicStore(&fresh[base + RES_FIXED + 3u], bitcast<u32>(c.vertex.fixed.w));
            }
            atomicStore(&locks[lock], 0u);
            return true;
        }
    }
    return false;
}
