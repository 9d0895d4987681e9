// totals = (intersections low word, high word, primitives with a tile rectangle)
@group(0) @binding(3) var<storage, read_write> totals: array<atomic<u32>, 3>;
// The primitives front to back (`depth_keys`, then sorted): slot j counts primitive order[j].
@group(0) @binding(4) var<storage, read> order: array<u32>;

var<workgroup> group_sum: atomic<u32>;
var<workgroup> group_visible: atomic<u32>;

@compute @workgroup_size(256)
fn count_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let j = (wid.y * 65535u + wid.x) * 256u + lid;
    if (lid == 0u) {
        atomicStore(&group_sum, 0u);
        atomicStore(&group_visible, 0u);
    }
    workgroupBarrier();
    if (j < frame.primitives) {
        let i = order[j];
        let rect = tile_rect(i);
        var n = 0u;
        if (rect.z > rect.x) {
            atomicAdd(&group_visible, 1u);
            n = kept_tiles(i, rect, 0u);
        }
        counts[j] = n;
        atomicAdd(&group_sum, n);
    }
    workgroupBarrier();
    // One global add per workgroup; the carry makes the total 64-bit.
    if (lid == 0u) {
        let s = atomicLoad(&group_sum);
        let old = atomicAdd(&totals[0], s);
        if (old + s < old) {
            atomicAdd(&totals[1], 1u);
        }
        atomicAdd(&totals[2], atomicLoad(&group_visible));
    }
}
