// One pass of a stable LSD radix sort of the first `key_count[0]` u32 keys with u32 values, on
// the 8-bit digit at bit `info.x`. The count is read on the device (for a frame's tile keys,
// `settle.wgsl` writes it), so a frame is recorded before it is known; `info.y` blocks cover
// the buffers, and blocks past the count find no keys.
// `radix_histogram`: digit counts per block, digit-major (`hist[digit * blocks + block]`), so
// an exclusive scan of `hist` gives every (digit, block) its first output slot.
// `radix_scatter`: a block's keys go out a chunk of 256 at a time. Each invocation sets its
// bit in its digit's 256-bit member mask; its rank among the chunk's keys of that digit is the
// number of member bits below its own, so keys leave in input order (stable) after three
// barriers per chunk. Invocation `d` also owns digit `d`'s mask and next output slot, so
// RADIX must equal WG.

const WG: u32 = 256u;
const CHUNKS: u32 = 16u;
const BLOCK: u32 = 4096u; // WG * CHUNKS
const RADIX: u32 = 256u;
const MASK_WORDS: u32 = WG / 32u;

@group(0) @binding(0) var<storage, read> keys_in: array<u32>;
@group(0) @binding(1) var<storage, read_write> hist: array<u32>;
@group(0) @binding(2) var<uniform> info: vec4<u32>; // shift, blocks
@group(0) @binding(3) var<storage, read> vals_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> vals_out: array<u32>;
@group(0) @binding(6) var<storage, read> key_count: array<u32>;

var<workgroup> counts: array<atomic<u32>, RADIX>;
// Bit `lid % 32` of word `digit * MASK_WORDS + lid / 32`: invocation `lid` holds `digit`.
var<workgroup> members: array<atomic<u32>, RADIX * MASK_WORDS>;
var<workgroup> next_slot: array<u32, RADIX>;

fn digit_of(key: u32) -> u32 {
    return (key >> info.x) & (RADIX - 1u);
}

@compute @workgroup_size(256)
fn radix_histogram(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * 65535u + wid.x;
    // A dispatch of more than 65,535 blocks is a grid with spare workgroups at its end.
    if (block >= info.y) {
        return;
    }
    atomicStore(&counts[lid], 0u);
    workgroupBarrier();
    let n = key_count[0];
    for (var c = 0u; c < CHUNKS; c++) {
        let i = block * BLOCK + c * WG + lid;
        if (i < n) {
            atomicAdd(&counts[digit_of(keys_in[i])], 1u);
        }
    }
    workgroupBarrier();
    hist[lid * info.y + block] = atomicLoad(&counts[lid]);
}

// Invocation `lid` owns digit `lid`'s mask: it clears it, and counts it into `next_slot`.
fn clear_own_mask(lid: u32) {
    for (var w = 0u; w < MASK_WORDS; w++) {
        atomicStore(&members[lid * MASK_WORDS + w], 0u);
    }
}

@compute @workgroup_size(256)
fn radix_scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * 65535u + wid.x;
    if (block >= info.y) {
        return;
    }
    next_slot[lid] = hist[lid * info.y + block];
    clear_own_mask(lid);
    let word = lid / 32u;
    let bit = lid % 32u;
    let n = key_count[0];
    for (var c = 0u; c < CHUNKS; c++) {
        let first = block * BLOCK + c * WG;
        if (first >= n) {
            break;
        }
        workgroupBarrier();
        let i = first + lid;
        let valid = i < n;
        var d = 0u;
        if (valid) {
            d = digit_of(keys_in[i]);
            atomicOr(&members[d * MASK_WORDS + word], 1u << bit);
        }
        workgroupBarrier();
        if (valid) {
            var rank = countOneBits(atomicLoad(&members[d * MASK_WORDS + word]) & ((1u << bit) - 1u));
            for (var w = 0u; w < word; w++) {
                rank += countOneBits(atomicLoad(&members[d * MASK_WORDS + w]));
            }
            let dst = next_slot[d] + rank;
            keys_out[dst] = keys_in[i];
            vals_out[dst] = vals_in[i];
        }
        workgroupBarrier();
        var total = 0u;
        for (var w = 0u; w < MASK_WORDS; w++) {
            total += countOneBits(atomicLoad(&members[lid * MASK_WORDS + w]));
        }
        next_slot[lid] += total;
        clear_own_mask(lid);
    }
}
