// Where a texel's reservoirs lie: RESERVOIR_SLOTS slots per observed texel and a header word
// (the layout is generated from abi.rs, gen/restir). The header names two distinct
// slots, those of the positive (sign 0) and the negative (sign 1) reservoir; the other two
// are free for the next iteration's fresh candidates.
#import gen/abi
#import gen/restir

// Words per reservoir in this run: RESERVOIR_WORDS, or RESERVOIR_WORDS_MAX with whole paths
// (the candidate and merge passes set it from the scene's depth, compact_path.wgsl).
var<private> res_stride: u32 = RESERVOIR_WORDS;

// The slot of sign s's reservoir in header h.
fn header_slot(h: u32, s: u32) -> u32 {
    return (h >> (HEADER_SLOT_BITS * s)) & HEADER_SLOT_MASK;
}

// The slot that sign s's fresh candidates go to: the s-th slot that header h leaves free.
fn fresh_slot(h: u32, s: u32) -> u32 {
    let free = ~((1u << header_slot(h, 0u)) | (1u << header_slot(h, 1u))) & ((1u << RESERVOIR_SLOTS) - 1u);
    return firstTrailingBit(select(free, free & (free - 1u), s == 1u));
}
