// A batch's parameter gradient on the device (as `train::fit` sums its views on the CPU): the
// first view's gradient is copied, each later one added, in view order. A frame whose tile
// lists were cut adds nothing (its view runs again).

struct SumInfo {
    // parameter words in all, whether this view adds to the sum (0: it starts it), unused...
    size: vec4<u32>,
}

@group(0) @binding(0) var<storage, read> grads: array<f32>;
@group(0) @binding(1) var<storage, read_write> sum: array<f32>;
@group(0) @binding(2) var<uniform> info: SumInfo;
// The key count of the frame the gradients come from, [keys sorted, cut] (`settle.wgsl`).
@group(0) @binding(3) var<storage, read> frame_keys: array<u32, 2>;

@compute @workgroup_size(256)
fn add_gradients(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= info.size.x || frame_keys[1] != 0u) {
        return;
    }
    if (info.size.y == 0u) {
        sum[i] = grads[i];
    } else {
        sum[i] = sum[i] + grads[i];
    }
}
