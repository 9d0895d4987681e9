// The depth sort's keys: each primitive's depth bits (clamped at zero: positive floats' bit
// patterns sort as their values) with its index, so a stable sort orders the primitives front
// to back, ties by index (the CPU's `rasterize::entry`).
@group(0) @binding(3) var<storage, read_write> keys: array<u32>;
@group(0) @binding(4) var<storage, read_write> order: array<u32>;

@compute @workgroup_size(256)
fn depth_keys(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= frame.primitives) {
        return;
    }
    keys[i] = bitcast<u32>(max(word(i, 1u), 0.0));
    order[i] = i;
}
