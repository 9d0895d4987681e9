// `pixel_info`'s adjoint per pixel: the camera's gradient through the pixel data (rays),
// given the pixel data's cotangent summed over the pixel's list by the backward blend. Summed
// over each workgroup in workgroup memory; the host adds the workgroups' partial sums.

const NCAM: u32 = {{NCAM}}u; // camera float slots (its gradient words)
const NPX: u32 = {{NPX}}u; // pixel data words

@group(0) @binding(0) var<storage, read> camera_words: array<u32>;
@group(0) @binding(1) var<storage, read> pixel_cotangent: array<u32>;
@group(0) @binding(2) var<storage, read_write> camera_partials: array<f32>;
@group(0) @binding(3) var<uniform> info: vec4<u32>; // x = width, y = height

var<workgroup> red: array<f32, {{RED_WORDS}}>; // 64 * NCAM

@compute @workgroup_size(64)
fn pixel_backward(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let group = wid.y * 65535u + wid.x;
    let i = group * 64u + lid;
    var cam: array<f32, NCAM>;
    if (i < info.x * info.y) {
        let px = f32(i % info.x) + 0.5;
        let py = f32(i / info.x) + 0.5;
        let a = {{PIXEL_INFO_ADJOINT}};
{{WRITE}}
    }
    for (var k = 0u; k < NCAM; k++) {
        red[k * 64u + lid] = cam[k];
    }
    workgroupBarrier();
    for (var s = 32u; s > 0u; s >>= 1u) {
        if (lid < s) {
            for (var k = 0u; k < NCAM; k++) {
                red[k * 64u + lid] += red[k * 64u + lid + s];
            }
        }
        workgroupBarrier();
    }
    // Dispatches past 65,535 groups are rounded up to whole rows: extra groups write nothing.
    if (lid < NCAM && group * 64u < info.x * info.y) {
        camera_partials[group * NCAM + lid] = red[lid * 64u];
    }
}
