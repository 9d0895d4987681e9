// The forward blend: front to back, stop once T would fall to T_MIN or below (as on the CPU).

// Per pixel: color (CHANNELS), final T, sum of weight * depth and how many entries of the
// list the walk took in (its last taken one, plus one), stored as `gpu::state` packs them.
@group(0) @binding(5) var<storage, read_write> pixel_out: array<u32>;
{{CAMERA_BINDING}}

@compute @workgroup_size({{WG}})
fn shade_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let at = tile_pixel(wid, lid);
    let px = f32(at.x) + 0.5;
    let py = f32(at.y) + 0.5;
    {{PIXEL}}
    var t = 1.0;
    var depth_acc = 0.0;
    var walked = 0u;
    var color: array<f32, CHANNELS>;
    var done = !at.inside;
    start_walk(lid, done);
    for (var b = at.start; b < at.end; b += BATCH) {
        if (all_pixels_done(lid)) {
            break;
        }
        stage_batch(lid, b, at.end);
        workgroupBarrier();
        let m = min(BATCH, at.end - b);
        for (var j = 0u; j < m && !done; j++) {
            let s = j * NS;
            let r = {{EVALUATE}};
            if (r.{{VALID}} == 0u || r.{{ALPHA}} < ALPHA_MIN) {
                continue;
            }
            let next = t * (1.0 - r.{{ALPHA}});
            if (next <= T_MIN) {
                done = true;
                atomicAdd(&done_count, 1u);
                break;
            }
            let w = r.{{ALPHA}} * t;
{{ACCUMULATE}}
            {{DEPTH}}
            t = next;
            walked = b - at.start + j + 1u;
        }
    }
    if (at.inside) {
        let pix = at.y * frame.width + at.x;
        var v: array<f32, CHANNELS + 2u>;
        for (var c = 0u; c < CHANNELS; c++) {
            v[c] = color[c];
        }
        v[CHANNELS] = t;
        v[CHANNELS + 1u] = depth_acc;
        {{STORE}}
    }
}
