// The forward blend: front to back, stop once T would fall to 1e-4 or below (as on the CPU).

// Per pixel: color (CHANNELS), final T, sum of weight * depth.
@group(0) @binding(5) var<storage, read_write> pixel_out: array<u32>;
{{CAMERA_BINDING}}

@compute @workgroup_size({{WG}})
fn shade_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let tile = tile_order[wid.y * 65535u + wid.x];
    let x = (tile % frame[1].x) * TILE + lid % TILE;
    let y = (tile / frame[1].x) * TILE + lid / TILE;
    let inside = x < frame[0].y && y < frame[0].z;
    let start = tile_ranges[2u * tile];
    let end = start + min(tile_ranges[2u * tile + 1u] - start, frame[1].y);
    let px = f32(x) + 0.5;
    let py = f32(y) + 0.5;
    {{PIXEL}}
    var t = 1.0;
    var depth_acc = 0.0;
    var color: array<f32, CHANNELS>;
    var done = !inside;
    if (lid == 0u) {
        atomicStore(&done_count, 0u);
    }
    workgroupBarrier();
    if (done) {
        atomicAdd(&done_count, 1u);
    }
    for (var b = start; b < end; b += BATCH) {
        if (all_pixels_done(lid)) {
            break;
        }
        stage_batch(lid, b, end);
        workgroupBarrier();
        let m = min(BATCH, end - b);
        for (var j = 0u; j < m && !done; j++) {
            let s = j * NS;
            let r = {{EVALUATE}};
            if (r.{{VALID}} == 0u) {
                continue;
            }
            let next = t * (1.0 - r.{{ALPHA}});
            if (next <= 1e-4) {
                done = true;
                atomicAdd(&done_count, 1u);
                break;
            }
            let w = r.{{ALPHA}} * t;
{{ACCUMULATE}}
            {{DEPTH}}
            t = next;
        }
    }
    if (inside) {
        let out = (y * frame[0].y + x) * (CHANNELS + 2u);
        for (var c = 0u; c < CHANNELS; c++) {
            pixel_out[out + c] = bitcast<u32>(color[c]);
        }
        pixel_out[out + CHANNELS] = bitcast<u32>(t);
        pixel_out[out + CHANNELS + 1u] = bitcast<u32>(depth_acc);
    }
}
