// The backward blend (seed 001 eq. 5-7): re-walk each pixel's list front to back carrying T
// and the color prefix (the color behind an entry is the final color minus the prefix), call
// `evaluate`'s adjoint, and add each entry's gradient to the primitive's sums with global
// atomics: {{REDUCTION_NOTE}}

const NG: u32 = {{NG}}u; // gradient words per primitive: shade float slots, then depth
const RC: u32 = {{RC}}u; // gradient words reduced per round

// Per pixel: the forward output (color, final T, sum of weight * depth, as `gpu::state` packs
// them) and its gradient (color, alpha, depth, f32).
@group(0) @binding(5) var<storage, read> pixel_state: array<u32>;
@group(0) @binding(6) var<storage, read> pixel_grad: array<u32>;
@group(0) @binding(7) var<storage, read_write> grads: array<{{GRAD_ATOMIC}}>;
// Global atomic adds issued (low word, high word).
@group(0) @binding(8) var<storage, read_write> issued: array<atomic<u32>, 2>;
{{CAMERA_BINDING}}
{{PIXEL_GRAD_BINDING}}

{{STATE}}

var<workgroup> red: array<f32, {{RED_WORDS}}>;
var<workgroup> group_issued: atomic<u32>;

fn add_grad(i: u32, v: f32) {
{{ATOMIC_ADD}}
}

@compute @workgroup_size({{WG}})
fn backward_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32{{LANE}}) {
    let at = tile_pixel(wid, lid);
    let px = f32(at.x) + 0.5;
    let py = f32(at.y) + 0.5;
    {{PIXEL}}
    // Pixels past the image edge read pixel 0 and stay done.
    let pix = select(0u, at.y * frame[0].y + at.x, at.inside);
    let grad_at = pix * (CHANNELS + 2u);
    var c_final: array<f32, CHANNELS>;
    var d_color: array<f32, CHANNELS>;
    var c_acc: array<f32, CHANNELS>;
    for (var c = 0u; c < CHANNELS; c++) {
        c_final[c] = state_value(pix, c);
        d_color[c] = bitcast<f32>(pixel_grad[grad_at + c]);
    }
    let t_final = state_value(pix, CHANNELS);
    let d_final = {{D_FINAL}};
    var d_alpha_out = bitcast<f32>(pixel_grad[grad_at + CHANNELS]);
    // depth = D / A with D = sum of w z and A = 1 - T: split its gradient into D and A.
    var d_d = 0.0;
    let gd = bitcast<f32>(pixel_grad[grad_at + CHANNELS + 1u]);
    let a_final = 1.0 - t_final;
    if ({{WANT_DEPTH}} && a_final > 0.0) {
        d_d = gd / a_final;
        d_alpha_out -= gd * d_final / (a_final * a_final);
    }
    var t = 1.0;
    var d_acc = 0.0;
    var done = !at.inside;
    var my_issued = 0u;
{{PIXEL_GRAD_DECL}}
    if (lid == 0u) {
        atomicStore(&group_issued, 0u);
    }
    start_walk(lid, done);
    for (var b = at.start; b < at.end; b += BATCH) {
        if (all_pixels_done(lid)) {
            break;
        }
        stage_batch(lid, b, at.end);
        workgroupBarrier();
        let m = min(BATCH, at.end - b);
        for (var j = 0u; j < m; j++) {
            var g: array<f32, NG>;
            if (!done) {
                let s = j * NS;
                let r = {{EVALUATE}};
                if (r.{{VALID}} != 0u && r.{{ALPHA}} >= ALPHA_MIN) {
                    let alpha = r.{{ALPHA}};
                    let next = t * (1.0 - alpha);
                    if (next <= T_MIN) {
                        done = true;
                        atomicAdd(&done_count, 1u);
                    } else {
                        let w = alpha * t;
                        let one_minus = 1.0 - alpha;
                        var d_alpha = 0.0;
{{COLOR_TERMS}}
                        if ({{WANT_DEPTH}}) {
                            let z = batch_depth[j];
                            d_acc += w * z;
                            d_alpha += t * z * d_d - (d_final - d_acc) * d_d / one_minus;
                            g[NG - 1u] = w * d_d;
                        }
                        d_alpha += d_alpha_out * t_final / one_minus;
                        let a = {{EVALUATE_ADJOINT}};
{{SHADE_GRADS}}
{{PIXEL_GRADS}}
                        t = next;
                    }
                }
            }
            let prim = batch_prim[j];
{{SCATTER}}
        }
    }
{{PIXEL_GRAD_STORE}}
    atomicAdd(&group_issued, my_issued);
    workgroupBarrier();
    if (lid == 0u) {
        let s = atomicLoad(&group_issued);
        let old = atomicAdd(&issued[0], s);
        if (old + s < old) {
            atomicAdd(&issued[1], 1u);
        }
    }
}
