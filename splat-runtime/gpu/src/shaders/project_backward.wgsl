// `project`'s adjoint per primitive, from the summed gradient of its shade words and depth.
// The camera's gradient (when asked for: SUM_CAMERA) is summed over each workgroup in
// workgroup memory; the host adds the workgroups' partial sums.

const NP: u32 = {{NP}}u; // parameter words per primitive
const NPF: u32 = {{NPF}}u; // parameter float slots (gradient words)
const NCAM: u32 = {{NCAM}}u; // camera float slots (its gradient words)
const NG: u32 = {{NG}}u;
const STRIDE: u32 = {{STRIDE}}u;
const SUM_CAMERA: bool = {{SUM_CAMERA}};

@group(0) @binding(0) var<storage, read> params: array<u32>;
@group(0) @binding(1) var<storage, read> camera_words: array<u32>;
@group(0) @binding(2) var<storage, read> projected: array<u32>;
@group(0) @binding(3) var<storage, read> grads: array<u32>;
@group(0) @binding(4) var<storage, read_write> param_grads: array<u32>;
@group(0) @binding(5) var<storage, read_write> camera_partials: array<f32>;
@group(0) @binding(6) var<uniform> info: vec4<u32>; // x = primitives
{{SUM_BINDING}}

// Each primitive's summed gradient words, as the backward blend held them (`gpu::sums`).
{{GRAD_READ}}

var<workgroup> red: array<f32, {{RED_WORDS}}>; // 64 * NCAM

@compute @workgroup_size(64)
fn project_backward(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let group = wid.y * 65535u + wid.x;
    let i = group * 64u + lid;
    var cam: array<f32, NCAM>;
    if (i < info.x) {
        var touched = false;
        for (var k = 0u; k < NG; k++) {
            touched = touched || grad_bits(i * NG + k) != 0u;
        }
        if (projected[i * STRIDE] != 0u && touched) {
            let a = {{PROJECT_ADJOINT}};
{{WRITE}}
        } else {
            for (var k = 0u; k < NPF; k++) {
                param_grads[i * NPF + k] = 0u;
            }
        }
    }
    if (!SUM_CAMERA) {
        return;
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
    if (lid < NCAM && group * 64u < max(info.x, 1u)) {
        camera_partials[group * NCAM + lid] = red[lid * 64u];
    }
}
