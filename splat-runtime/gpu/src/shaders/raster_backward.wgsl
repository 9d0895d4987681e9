// The hardware path's backward blend (after `quads.wgsl`; Yuan and He's differentiable
// hardware rasterization, backward half): the forward's draw replayed with programmable
// blending, front to back. Each fragment reads its pixel's state as the forward left it before
// this primitive (color and 1 - T, in the targets' format, rounding included), writes the
// forward's update (and stops the pixel where the forward did), and adds its primitive's
// gradient with global atomics: {{REDUCTION_NOTE}}
//
// Front to back, what lies behind the fragment is the final color less the color up to and
// including it, and only that difference is divided by 1 - alpha: back to front (the tile
// path's walk), T before each entry would come from dividing a stored, rounded T.

const NG: u32 = {{NG}}u; // gradient words per primitive: shade float slots, then depth
const CHANNELS: u32 = {{CHANNELS}}u;
// Whether a gradient asked for flows through alpha (`GradientSet::alpha_cotangent`).
const ALPHA_COTANGENT: bool = {{ALPHA_COTANGENT}};
const WANT_DEPTH: bool = {{WANT_DEPTH}};

// Per pixel, CHANNELS + 2 f32 words each: the forward's final outputs as stored (color, T,
// sum of weight * depth) and their gradients (color, alpha, depth).
@group(0) @binding(4) var<storage, read> pixel_final: array<f32>;
@group(0) @binding(5) var<storage, read> pixel_grad: array<f32>;
@group(0) @binding(6) var<storage, read_write> grads: array<{{GRAD_ATOMIC}}>;
// Global atomic adds issued (low word, high word).
@group(0) @binding(7) var<storage, read_write> issued: array<atomic<u32>, 2>;
{{SUM_BINDING}}
{{PIXEL_GRAD_BINDING}}

{{ADD_GRAD}}

struct Targets {
{{TARGETS}}
}

// No lane leaves before the gradients are summed over its quad or subgroup (a lane that
// discards early would leave the sums undefined): each decides what it adds and writes, and
// those that write nothing discard at the end. `helper` is set in helper invocations (the rewrite of
// `front_facing`, `programmable_blend::spirv`), which evaluate pixels their triangle does not
// cover: they add nothing.
@fragment
fn splat_backward(q: Quad, @builtin(front_facing) helper: bool) -> Targets {
    let px = q.position.x;
    let py = q.position.y;
    {{PIXEL}}
    let s = q.prim * STRIDE + SHADE_AT;
    let r = {{EVALUATE}};
    let a = r.{{ALPHA}};
    let depth = word(q.prim, 1u);
    let stopped_before = textureLoad(stop_mark, vec2<i32>(0, 0), 0).x != 0u;
{{READ}}
    // Whether the forward took this pair, stopped its pixel here, or blended it.
    let taken = !helper && r.{{VALID}} != 0u && a >= ALPHA_MIN && !stopped_before;
    let stops = taken && (1.0 - s0.a) * (1.0 - a) <= T_STOP;
    let live = taken && !stops;
    var out: Targets;
    if (stops) {
        out.stopped = vec4<u32>(1u, 0u, 0u, 0u);
{{KEEP}}
    } else {
        out.stopped = vec4<u32>(0u);
{{BLEND}}
    }
    // Helpers may lie past the image's edge: they read its last pixel and add nothing.
    let pix = min(u32(py), frame.height - 1u) * frame.width + min(u32(px), frame.width - 1u);
    let at = pix * (CHANNELS + 2u);
    let t = 1.0 - s0.a;
    let w = a * t;
    let one_minus = 1.0 - a;
    let t_final = pixel_final[at + CHANNELS];
    let d_final = pixel_final[at + CHANNELS + 1u];
    var d_alpha_out = pixel_grad[at + CHANNELS];
    // depth = D / A with D = sum of w z and A = 1 - T: split its gradient into D and A.
    var d_d = 0.0;
    let a_final = 1.0 - t_final;
    if (WANT_DEPTH && a_final > 0.0) {
        let gd = pixel_grad[at + CHANNELS + 1u];
        d_d = gd / a_final;
        d_alpha_out -= gd * d_final / (a_final * a_final);
    }
    // d blended / d alpha = T value - behind / (1 - alpha), behind = final - after.
    var d_alpha = 0.0;
    if (ALPHA_COTANGENT) {
{{COLOR_TERMS}}
        if (WANT_DEPTH) {
            d_alpha += d_d * (t * depth - (d_final - {{DEPTH_AFTER}}) / one_minus);
        }
        d_alpha += d_alpha_out * t_final / one_minus;
    }
    let ga = {{EVALUATE_ADJOINT}};
{{GRAD_DECL}}
    if (live) {
{{SHADE_GRADS}}
        {{DEPTH_GRAD}} = w * d_d;
{{PIXEL_GRADS}}
    }
    let prim = q.prim;
    var my_issued = 0u;
{{SCATTER}}
    if (my_issued != 0u) {
        let old = atomicAdd(&issued[0], my_issued);
        if (old + my_issued < old) {
            atomicAdd(&issued[1], 1u);
        }
    }
    if (!taken) {
        discard;
    }
    return out;
}
