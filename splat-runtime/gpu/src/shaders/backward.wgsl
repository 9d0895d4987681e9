// The backward blend: walk each pixel's list back to front from the last entry its forward
// walk took, recovering T before each entry from the final one (T after / (1 - alpha)) and
// summing the color behind it as the walk goes (as the CPU's `pipeline::backward` does, which
// says why), call `evaluate`'s adjoint, and add each entry's gradient to the primitive's sums
// with global atomics: {{REDUCTION_NOTE}}

const NG: u32 = {{NG}}u; // gradient words per primitive: shade float slots, then depth
// Whether a gradient asked for flows through alpha (`GradientSet::alpha_cotangent`).
const ALPHA_COTANGENT: bool = {{ALPHA_COTANGENT}};

// Per pixel: the forward output (color, final T, sum of weight * depth, the walk's end, as
// `gpu::state` packs them) and its gradient (color, alpha, depth, f32).
@group(0) @binding(5) var<storage, read> pixel_state: array<u32>;
@group(0) @binding(6) var<storage, read> pixel_grad: array<u32>;
@group(0) @binding(7) var<storage, read_write> grads: array<{{GRAD_ATOMIC}}>;
// Global atomic adds issued (low word, high word).
@group(0) @binding(8) var<storage, read_write> issued: array<atomic<u32>, 2>;
{{SUM_BINDING}}
{{CAMERA_BINDING}}
{{PIXEL_GRAD_BINDING}}

{{STATE}}

var<workgroup> red: array<f32, {{RED_WORDS}}>;
var<workgroup> group_issued: atomic<u32>;
var<workgroup> walk_max: atomic<u32>;
var<workgroup> walk_len: u32;

// The derivative by an entry's alpha of a blended channel (a color channel or the depth sum)
// where the entry's value is `v`, kept relative to the pixel's reference value `r` to avoid
// cancellation (the CPU's `pipeline::backward::Entry::blend` says how), and what lies
// `behind` the entry before it, the entry added.
fn blend_term(v: f32, r: f32, behind: f32, t: f32, w: f32, one_minus: f32, t_final: f32) -> vec2<f32> {
    let d = v - r;
    return vec2<f32>(t * d + (r * t_final - behind) / one_minus, behind + w * d);
}

// The longest walk of any pixel of the tile (`end` is this invocation's): how many entries of
// the list the backward pass visits. Also zeroes `group_issued`.
fn longest_walk(lid: u32, end: u32) -> u32 {
    if (lid == 0u) {
        atomicStore(&walk_max, 0u);
        atomicStore(&group_issued, 0u);
    }
    workgroupBarrier();
    atomicMax(&walk_max, end);
    workgroupBarrier();
    if (lid == 0u) {
        walk_len = atomicLoad(&walk_max);
    }
    return workgroupUniformLoad(&walk_len);
}

{{ADD_GRAD}}

@compute @workgroup_size({{WG}})
fn backward_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32{{LANE}}) {
    let at = tile_pixel(wid, lid);
    let px = f32(at.x) + 0.5;
    let py = f32(at.y) + 0.5;
    {{PIXEL}}
    // Pixels past the image edge read pixel 0 and stay done.
    let pix = select(0u, at.y * frame.width + at.x, at.inside);
    let grad_at = pix * (CHANNELS + 2u);
    var d_color: array<f32, CHANNELS>;
    for (var c = 0u; c < CHANNELS; c++) {
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
    let end = select(0u, state_end(pix), at.inside);
    var t = t_final;
    var seen = false;
    var behind: array<f32, CHANNELS>;
    var reference: array<f32, CHANNELS>;
    var depth_behind = 0.0;
    var depth_reference = 0.0;
    var my_issued = 0u;
{{PIXEL_GRAD_DECL}}
    let walk = longest_walk(lid, end);
    for (var nb = (walk + BATCH - 1u) / BATCH; nb > 0u; nb--) {
        let b = at.start + (nb - 1u) * BATCH;
        // Every invocation is done with the previous batch before it is overwritten.
        workgroupBarrier();
        stage_batch(lid, b, at.end);
        workgroupBarrier();
        for (var j = min(BATCH, at.end - b); j > 0u; j--) {
            let i = j - 1u;
            // The entry's gradient words, one scalar each (`gpu::scatter` says why).
{{GRAD_DECL}}
            // Whether the entry reaches this pixel: with the subgroup reduction, a subgroup none
            // of whose pixels it reaches skips it.
            var hit = false;
            if (b - at.start + i < end) {
                let s = i * NS;
                let r = {{EVALUATE}};
                if (r.{{VALID}} != 0u && r.{{ALPHA}} >= ALPHA_MIN) {
                    let alpha = r.{{ALPHA}};
                    hit = true;
                    let one_minus = 1.0 - alpha;
                    t = t / one_minus;
                    let w = alpha * t;
                    let first = !seen;
                    seen = true;
                    if ({{WANT_DEPTH}}) {
                        {{DEPTH_GRAD}} = w * d_d;
                    }
                    var d_alpha = 0.0;
                    if (ALPHA_COTANGENT) {
{{COLOR_TERMS}}
                        if ({{WANT_DEPTH}}) {
                            let z = batch_depth[i];
                            if (first) {
                                depth_reference = z;
                            }
                            let bz = blend_term(z, depth_reference, depth_behind, t, w, one_minus, t_final);
                            d_alpha += bz.x * d_d;
                            depth_behind = bz.y;
                        }
                        d_alpha += d_alpha_out * t_final / one_minus;
                    }
                    let a = {{EVALUATE_ADJOINT}};
{{SHADE_GRADS}}
{{PIXEL_GRADS}}
                }
            }
            let prim = batch_prim[i];
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
