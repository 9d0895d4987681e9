// Trip-count binning: tiles grouped by the bit length of their (P_max-capped) list length,
// longest bins first, so the workgroups with the most work are dispatched first. One
// workgroup orders all tiles (a few thousand to a few hundred thousand).

@group(0) @binding(0) var<storage, read> ranges: array<u32>;
@group(0) @binding(1) var<storage, read_write> order: array<u32>;
@group(0) @binding(2) var<uniform> info: vec4<u32>; // tiles, p_max

var<workgroup> bin_count: array<atomic<u32>, 33>;
var<workgroup> bin_next: array<atomic<u32>, 33>;

fn bin_of(t: u32) -> u32 {
    let len = min(ranges[2u * t + 1u] - ranges[2u * t], info.y);
    return 32u - countLeadingZeros(len);
}

@compute @workgroup_size(256)
fn bin_tiles(@builtin(local_invocation_index) lid: u32) {
    if (lid < 33u) {
        atomicStore(&bin_count[lid], 0u);
    }
    workgroupBarrier();
    for (var t = lid; t < info.x; t += 256u) {
        atomicAdd(&bin_count[bin_of(t)], 1u);
    }
    workgroupBarrier();
    if (lid == 0u) {
        var first = 0u;
        for (var b = 33u; b > 0u; b--) {
            atomicStore(&bin_next[b - 1u], first);
            first += atomicLoad(&bin_count[b - 1u]);
        }
    }
    workgroupBarrier();
    for (var t = lid; t < info.x; t += 256u) {
        order[atomicAdd(&bin_next[bin_of(t)], 1u)] = t;
    }
}
