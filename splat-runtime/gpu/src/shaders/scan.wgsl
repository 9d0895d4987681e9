// Exclusive prefix sum of u32 words in blocks of 256: `scan_blocks` scans each block in place
// and writes the block's total to `sums`; once `sums` is scanned the same way (recursively),
// `add_block_offsets` adds each block's offset to its words.

@group(0) @binding(0) var<storage, read_write> data: array<u32>;
@group(0) @binding(1) var<storage, read_write> sums: array<u32>;
@group(0) @binding(2) var<uniform> info: vec4<u32>; // x = number of words

var<workgroup> partial: array<u32, 256>;

@compute @workgroup_size(256)
fn scan_blocks(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * 65535u + wid.x;
    let i = block * 256u + lid;
    var v = 0u;
    if (i < info.x) {
        v = data[i];
    }
    partial[lid] = v;
    workgroupBarrier();
    // Hillis-Steele inclusive scan.
    for (var offset = 1u; offset < 256u; offset <<= 1u) {
        var add = 0u;
        if (lid >= offset) {
            add = partial[lid - offset];
        }
        workgroupBarrier();
        partial[lid] += add;
        workgroupBarrier();
    }
    if (i < info.x) {
        data[i] = partial[lid] - v;
    }
    // A dispatch past 65,535 blocks is rounded up to whole rows: blocks past the buffer's end
    // (all of whose words are past the data's) write nothing.
    if (lid == 255u && block < arrayLength(&sums)) {
        sums[block] = partial[255];
    }
}

@compute @workgroup_size(256)
fn add_block_offsets(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let block = wid.y * 65535u + wid.x;
    let i = block * 256u + lid;
    if (i < info.x) {
        data[i] += sums[block];
    }
}
