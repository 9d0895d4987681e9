// Tile ranges from the first `key_count[0]` sorted keys: tile t's entries are
// [ranges[2t], ranges[2t + 1]). `ranges` is cleared to zero beforehand, so tiles without
// entries read as empty.

@group(0) @binding(0) var<storage, read> keys: array<u32>;
@group(0) @binding(1) var<storage, read_write> ranges: array<u32>;
@group(0) @binding(2) var<storage, read> key_count: array<u32>;

@compute @workgroup_size(256)
fn tile_ranges(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    let n = key_count[0];
    if (i >= n) {
        return;
    }
    let t = keys[i];
    if (i == 0u || keys[i - 1u] != t) {
        ranges[2u * t] = i;
    }
    if (i + 1u == n || keys[i + 1u] != t) {
        ranges[2u * t + 1u] = i + 1u;
    }
}
