// ReSTIR claim pass: the winners of the candidate pass's races write their paths. One
// invocation per entry of the claim log, which the candidate pass filled with every offer
// that led its reservoir's race when it entered (the only offers that can win: a key is
// final once every offer has entered, and an offer that found a larger complemented key in
// place was beaten for good). The entry whose key is its reservoir's swaps it for its info
// word and writes its path (reservoir.wgsl, reservoir_claim_key): the same winners, and the
// same words, as tracing every sample again would write. Dispatched indirectly with the
// workgroups the candidate pass counted (the log's header); entries the full log could not
// take are claimed by the retracing claim (restir_candidates.wgsl, phase 1). The log is bound
// read-only here, as it holds this pass's dispatch arguments.
#import gen/restir
#import restir/reservoir

// Slot k of every observed texel's reservoirs (reservoir.wgsl).
@group(0) @binding(0) var<storage, read_write> slots0: array<atomic<u32>>;
@group(0) @binding(1) var<storage, read_write> slots1: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read_write> slots2: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> slots3: array<atomic<u32>>;
// The claim log (abi.rs, claim).
@group(0) @binding(4) var<storage, read> claims: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let stride = claims[CLAIM_STRIDE];
    let capacity = (arrayLength(&claims) - CLAIM_HEADER_WORDS) / max(stride, 1u);
    let e = id.x;
    if e >= min(claims[CLAIM_COUNT], capacity) {
        return;
    }
    res_stride = stride - 1u;
    let b = CLAIM_HEADER_WORDS + e * stride;
    var c: Candidate;
    c.info = claims[b + CLAIM_INFO];
    for (var j = 0u; j < res_stride - RES_TRI; j++) {
        c.words[j] = claims[b + CLAIM_PATH + j];
    }
    let addr = claims[b + CLAIM_ADDR];
    reservoir_claim_key(addr & 3u, addr >> 2u, claims[b + CLAIM_KEY], c);
}
