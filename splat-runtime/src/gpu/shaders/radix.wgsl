// One pass of a stable LSD radix sort of (depth bits, tile) keys with u32 values, on a 4-bit
// digit of the key word `info.z` (0 = depth, 1 = tile) at bit `info.y`.
// `radix_histogram`: digit counts per block, digit-major (`hist[digit * blocks + block]`), so
// an exclusive scan of `hist` gives every (digit, block) its first output slot.
// `radix_scatter`: each chunk of 256 keys is sorted stably by digit in workgroup memory (four
// 1-bit splits), then each key goes to its block's slot for its digit plus its rank.

const WG: u32 = 256u;
const CHUNKS: u32 = 16u;
const BLOCK: u32 = 4096u; // WG * CHUNKS

@group(0) @binding(0) var<storage, read> keys_in: array<vec2<u32>>;
@group(0) @binding(1) var<storage, read_write> hist: array<u32>;
@group(0) @binding(2) var<uniform> info: vec4<u32>; // n, shift, key word, blocks
@group(0) @binding(3) var<storage, read> vals_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> vals_out: array<u32>;

var<workgroup> counts: array<atomic<u32>, 16>;
var<workgroup> split: array<u32, 256>;
var<workgroup> sorted_digit: array<u32, 256>;
var<workgroup> digit_start: array<u32, 16>;
var<workgroup> next_slot: array<u32, 16>;

fn digit_of(key: vec2<u32>) -> u32 {
    return (select(key.x, key.y, info.z == 1u) >> info.y) & 15u;
}

@compute @workgroup_size(256)
fn radix_histogram(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * 65535u + wid.x;
    if (lid < 16u) {
        atomicStore(&counts[lid], 0u);
    }
    workgroupBarrier();
    for (var c = 0u; c < CHUNKS; c++) {
        let i = block * BLOCK + c * WG + lid;
        if (i < info.x) {
            atomicAdd(&counts[digit_of(keys_in[i])], 1u);
        }
    }
    workgroupBarrier();
    if (lid < 16u) {
        hist[lid * info.w + block] = atomicLoad(&counts[lid]);
    }
}

@compute @workgroup_size(256)
fn radix_scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * 65535u + wid.x;
    if (lid < 16u) {
        next_slot[lid] = hist[lid * info.w + block];
    }
    for (var c = 0u; c < CHUNKS; c++) {
        let first = block * BLOCK + c * WG;
        if (first >= info.x) {
            break;
        }
        let valid_count = min(WG, info.x - first);
        let i = first + lid;
        let valid = lid < valid_count;
        var key = vec2<u32>(0u, 0u);
        var val = 0u;
        if (valid) {
            key = keys_in[i];
            val = vals_in[i];
        }
        // Keys past the end take the largest digit; being last already, they stay last.
        let d = select(15u, digit_of(key), valid);
        var pos = lid;
        for (var bit = 0u; bit < 4u; bit++) {
            let one = (d >> bit) & 1u;
            workgroupBarrier();
            split[pos] = 1u - one;
            workgroupBarrier();
            for (var offset = 1u; offset < WG; offset <<= 1u) {
                var add = 0u;
                if (pos >= offset) {
                    add = split[pos - offset];
                }
                workgroupBarrier();
                split[pos] += add;
                workgroupBarrier();
            }
            let zeros_before = split[pos] - (1u - one);
            let zeros = split[WG - 1u];
            pos = select(zeros_before, zeros + pos - zeros_before, one == 1u);
        }
        workgroupBarrier();
        sorted_digit[pos] = d;
        workgroupBarrier();
        if (pos == 0u || sorted_digit[pos - 1u] != d) {
            digit_start[d] = pos;
        }
        workgroupBarrier();
        if (valid) {
            let dst = next_slot[d] + pos - digit_start[d];
            keys_out[dst] = key;
            vals_out[dst] = val;
        }
        workgroupBarrier();
        // The last valid key of each digit moves that digit's next slot past the chunk.
        if (valid && (pos + 1u == valid_count || sorted_digit[pos + 1u] != d)) {
            next_slot[d] += pos - digit_start[d] + 1u;
        }
    }
}
