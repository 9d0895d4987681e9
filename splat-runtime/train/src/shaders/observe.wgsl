// Density control's statistics on the device (as `train::densify::screen_gradient` and
// `Densifier::observe`): for each primitive the image shows, the norm of its screen-space
// position gradient in NDC units, summed, and the number of views that saw it. The gradient
// is read from the shade data's gradient where the method's shade data holds the screen
// position, else recovered from the world-space one through the pinhole Jacobian
// (dL/du = z / f dL/dx_cam).

struct ObserveInfo {
    // primitives, projected words per primitive, parameter words per primitive, shade
    // gradient words per primitive
    size: vec4<u32>,
    // the position's first word in `Params` (its 3 words are consecutive), the screen
    // position's first slot in the shade gradient (2 consecutive), whether to read that
    // (1) or the position's (0), unused
    position: vec4<u32>,
}

@group(0) @binding(0) var<storage, read> projected: array<u32>;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> param_grads: array<f32>;
@group(0) @binding(3) var<storage, read> camera_words: array<f32>;
@group(0) @binding(4) var<storage, read> shade_grads: array<u32>;
@group(0) @binding(5) var<storage, read_write> grad2d: array<f32>;
@group(0) @binding(6) var<storage, read_write> seen: array<u32>;
@group(0) @binding(7) var<uniform> info: ObserveInfo;
// The frame's key count, [keys sorted, cut] (`settle.wgsl`): a cut frame is not counted.
@group(0) @binding(8) var<storage, read> frame_keys: array<u32, 2>;

fn vec_at(a: u32) -> vec3<f32> {
    return vec3<f32>(camera_words[a], camera_words[a + 1u], camera_words[a + 2u]);
}

@compute @workgroup_size(256)
fn observe(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= info.size.x || frame_keys[1] != 0u) {
        return;
    }
    // Seen as the CPU's `pipeline::filter` sees it (and gsplat, whose radii are 0 off the
    // image): marked visible, a finite depth, a box over at least one pixel centre.
    // Camera words: rotation by columns (0..9), translation, focal, principal, size.
    let w = i * info.size.y;
    let depth = bitcast<f32>(projected[w + 1u]);
    let lo = vec2<f32>(bitcast<f32>(projected[w + 2u]), bitcast<f32>(projected[w + 3u]));
    let hi = vec2<f32>(bitcast<f32>(projected[w + 4u]), bitcast<f32>(projected[w + 5u]));
    let image = vec2<f32>(camera_words[16], camera_words[17]);
    if (!spans_a_pixel(pixel_span(projected[w], depth, lo, hi, image))) {
        return;
    }
    let half = image * 0.5;
    var d: vec2<f32>;
    if (info.position.z == 1u) {
        let at = i * info.size.w + info.position.y;
        d = vec2<f32>(bitcast<f32>(shade_grads[at]), bitcast<f32>(shade_grads[at + 1u])) * half;
    } else {
        let r = mat3x3<f32>(vec_at(0u), vec_at(3u), vec_at(6u));
        let at = i * info.size.z + info.position.x;
        let p = vec3<f32>(params[at], params[at + 1u], params[at + 2u]);
        let g = vec3<f32>(param_grads[at], param_grads[at + 1u], param_grads[at + 2u]);
        let z = max((r * p + vec_at(9u)).z, 1e-6);
        let focal = vec2<f32>(camera_words[12], camera_words[13]);
        d = (r * g).xy * z / focal * half;
    }
    let norm = length(d);
    // A gradient Adam skips (not finite) does not count either.
    if (finite(norm)) {
        grad2d[i] += norm;
        seen[i] += 1u;
    }
}
