// keys = (depth bits, tile), vals = primitive; `counts` holds the scanned offsets.
@group(0) @binding(3) var<storage, read_write> keys: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> vals: array<u32>;

@compute @workgroup_size(256)
fn emit_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= frame[0].x) {
        return;
    }
    let rect = tile_rect(i);
    if (rect.z > rect.x) {
        _ = kept_tiles(i, rect, counts[i]);
    }
}
