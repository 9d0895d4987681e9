// One Adam step over every parameter word on the device (as `train::adam` on the CPU): a
// learning rate per word of `Params` (negative: the word is not trained yet, and neither it nor
// its moments move), bias-corrected moments. Words it cannot step are left as on the CPU
// (`train::adam::Fault`) and counted in `faults`: a non-finite gradient skips the word; a step
// that would make the word or its second moment non-finite is undone and its moments restart.
// A step from a frame whose tile lists were cut is held back whole (`frame_keys`).

struct AdamInfo {
    // parameter words in all, words per primitive, unused, unused
    size: vec4<u32>,
    // beta1, beta2, 1 - beta1^t, 1 - beta2^t
    beta: vec4<f32>,
    // epsilon, unused...
    eps: vec4<f32>,
}

@group(0) @binding(0) var<storage, read_write> params: array<f32>;
@group(0) @binding(1) var<storage, read> grads: array<f32>;
@group(0) @binding(2) var<storage, read_write> m: array<f32>;
@group(0) @binding(3) var<storage, read_write> v: array<f32>;
@group(0) @binding(4) var<storage, read> rates: array<f32>;
@group(0) @binding(5) var<uniform> info: AdamInfo;
// words with a non-finite gradient, steps undone, the lowest such word (cleared to 0, 0, ~0)
@group(0) @binding(6) var<storage, read_write> faults: array<atomic<u32>, 3>;
// The key count of the frame the gradients come from, [keys sorted, cut] (`settle.wgsl`).
@group(0) @binding(7) var<storage, read> frame_keys: array<u32, 2>;

fn fault(kind: u32, word: u32) {
    atomicAdd(&faults[kind], 1u);
    atomicMin(&faults[2], word);
}

@compute @workgroup_size(256)
fn adam_step(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= info.size.x || frame_keys[1] != 0u) {
        return;
    }
    let lr = rates[i % info.size.y];
    if (lr < 0.0) {
        return;
    }
    let g = grads[i];
    if (!finite(g)) {
        fault(0u, i);
        return;
    }
    let b = info.beta;
    let mi = b.x * m[i] + (1.0 - b.x) * g;
    let vi = b.y * v[i] + (1.0 - b.y) * g * g;
    let pi = params[i] - lr * (mi / b.z) / (sqrt(vi / b.w) + info.eps.x);
    if (!(finite(pi) && finite(vi))) {
        fault(1u, i);
        m[i] = 0.0;
        v[i] = 0.0;
        return;
    }
    m[i] = mi;
    v[i] = vi;
    params[i] = pi;
}
