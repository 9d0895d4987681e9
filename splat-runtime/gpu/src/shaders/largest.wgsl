// The largest magnitude of a frame's output gradients, as f32 bits (non-negative floats order
// as u32; NaN left out, as the CPU's `f32::max` leaves it): f16 gradient sums are scaled by it
// (`half.wgsl`'s `sum_scale`).

const WORDS: u32 = {{WORDS}}u; // gradient words per pixel: colors, alpha, depth

@group(0) @binding(0) var<storage, read> pixel_grad: array<u32>;
@group(0) @binding(1) var<storage, read_write> grad_largest: array<atomic<u32>, 1>;
// x = pixels, y = words read per pixel (depth's only when its gradient is given)
@group(0) @binding(2) var<uniform> info: vec4<u32>;

var<workgroup> group_largest: atomic<u32>;

@compute @workgroup_size(256)
fn largest_gradient(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (lid == 0u) {
        atomicStore(&group_largest, 0u);
    }
    workgroupBarrier();
    if (i < info.x) {
        var m = 0u;
        for (var k = 0u; k < info.y; k++) {
            let b = pixel_grad[i * WORDS + k] & 0x7fffffffu;
            if (b <= 0x7f800000u) {
                m = max(m, b);
            }
        }
        atomicMax(&group_largest, m);
    }
    workgroupBarrier();
    if (lid == 0u) {
        atomicMax(&grad_largest[0], atomicLoad(&group_largest));
    }
}
