// A sharded run's records (resident/records.rs): the primitives `project` saw whose box holds
// a pixel centre (the CPU's filter, through `pixel_span`), compacted in order with their
// places for the host to read back; and the gradients of the records that come back, written
// beside their primitives. Needs `fn finite` and `fn pixel_span`.

// mark_kept, gather_kept: (primitives, stride, width, height);
// scatter_gradients: (records, gradient words per record, 0, 0).
@group(0) @binding(0) var<uniform> info: vec4<u32>;
@group(0) @binding(1) var<storage, read> projected: array<u32>;
// Per primitive 1 where it is kept, then (scanned in place) its place among the kept.
@group(0) @binding(2) var<storage, read_write> places: array<u32>;
@group(0) @binding(3) var<storage, read_write> kept: array<atomic<u32>, 1>;
@group(0) @binding(4) var<storage, read_write> records: array<u32>;
@group(0) @binding(5) var<storage, read_write> index: array<u32>;
@group(0) @binding(6) var<storage, read> record_grads: array<u32>;
@group(0) @binding(7) var<storage, read_write> grads: array<u32>;

fn word(i: u32, k: u32) -> f32 {
    return bitcast<f32>(projected[i * info.y + k]);
}

fn keeps(i: u32) -> bool {
    let lo = vec2<f32>(word(i, 2u), word(i, 3u));
    let hi = vec2<f32>(word(i, 4u), word(i, 5u));
    let size = vec2<f32>(f32(info.z), f32(info.w));
    return spans_a_pixel(pixel_span(projected[i * info.y], word(i, 1u), lo, hi, size));
}

@compute @workgroup_size(256)
fn mark_kept(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= info.x) {
        return;
    }
    let k = u32(keeps(i));
    places[i] = k;
    if (k == 1u) {
        atomicAdd(&kept[0], 1u);
    }
}

@compute @workgroup_size(256)
fn gather_kept(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= info.x || !keeps(i)) {
        return;
    }
    let at = places[i];
    index[at] = i;
    for (var k = 0u; k < info.y; k++) {
        records[at * info.y + k] = projected[i * info.y + k];
    }
}

// One invocation per record word; `grads` cleared before.
@compute @workgroup_size(256)
fn scatter_gradients(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let w = (wid.y * 65535u + wid.x) * 256u + lid;
    if (w >= info.x * info.y) {
        return;
    }
    let r = w / info.y;
    grads[index[r] * info.y + w % info.y] = record_grads[w];
}
