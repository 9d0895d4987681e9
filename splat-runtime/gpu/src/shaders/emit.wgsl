// keys = tile, vals = primitive; `counts` holds the scanned offsets of the primitives front to
// back, so the keys leave in depth order and a stable sort by tile makes each tile's list.
@group(0) @binding(3) var<storage, read_write> keys: array<u32>;
@group(0) @binding(4) var<storage, read_write> vals: array<u32>;
@group(0) @binding(5) var<storage, read> order: array<u32>;

@compute @workgroup_size(256)
fn emit_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let j = (wid.y * 65535u + wid.x) * 256u + lid;
    if (j >= frame.primitives) {
        return;
    }
    let i = order[j];
    let rect = tile_rect(i);
    if (rect.z > rect.x) {
        _ = kept_tiles(i, rect, counts[j]);
    }
}
