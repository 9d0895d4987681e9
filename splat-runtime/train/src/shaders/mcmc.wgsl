// MCMC's per-step terms on the device (as `train::mcmc::Mcmc` on the host): the opacity and
// scale penalties' gradients, added before Adam (`regularize`), and the position noise shaped
// by each primitive's covariance, after it (`perturb`), drawn from the same hash as the host.

struct McmcInfo {
    // primitives, parameter words per primitive, the step's seed, unused
    size: vec4<u32>,
    // the first word of: the position, the log scales, the (w, x, y, z) rotation, the
    // opacity logit
    words: vec4<u32>,
    // opacity_reg / n, scale_reg / (3 n), noise_lr * the position's learning rate, unused
    weights: vec4<f32>,
}

@group(0) @binding(0) var<storage, read_write> params: array<f32>;
@group(0) @binding(1) var<storage, read_write> grads: array<f32>;
@group(0) @binding(2) var<uniform> info: McmcInfo;

fn sigmoid(x: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x));
}

@compute @workgroup_size(256)
fn regularize(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= info.size.x) {
        return;
    }
    let base = i * info.size.y;
    let o = base + info.words.w;
    let s = sigmoid(params[o]);
    grads[o] += info.weights.x * s * (1.0 - s);
    for (var k = 0u; k < 3u; k++) {
        let at = base + info.words.y + k;
        grads[at] += info.weights.y * exp(params[at]);
    }
}

// PCG's RXS-M-XS hash of one word.
fn pcg(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

@compute @workgroup_size(256)
fn perturb(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (i >= info.size.x) {
        return;
    }
    let base = i * info.size.y;
    let opacity = sigmoid(params[base + info.words.w]);
    let gate = 1.0 / (1.0 + exp(-100.0 * (1.0 - opacity - 0.995)));
    let scaler = gate * info.weights.z;
    if (scaler == 0.0) {
        return;
    }
    let ls = base + info.words.y;
    let scale = exp(vec3<f32>(params[ls], params[ls + 1u], params[ls + 2u]));
    let r = base + info.words.z;
    let q = normalize(vec4<f32>(params[r], params[r + 1u], params[r + 2u], params[r + 3u]));
    let w = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    let rot = mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
    var state = pcg(info.size.z ^ pcg(i));
    var e = vec3<f32>(0.0);
    for (var k = 0u; k < 3u; k++) {
        state = pcg(state);
        let u = 1.0 - f32(state >> 8u) / 16777216.0;
        state = pcg(state);
        let v = f32(state >> 8u) / 16777216.0;
        e[k] = sqrt(-2.0 * log(u)) * cos(6.2831855 * v);
    }
    // Covariance R S^2 R^T times the draw.
    let step = rot * (scale * scale * (transpose(rot) * e)) * scaler;
    let p = base + info.words.x;
    params[p] += step.x;
    params[p + 1u] += step.y;
    params[p + 2u] += step.z;
}
