// The photometric loss of a rendered frame against its target on the device, as
// `train::loss` defines it on the CPU: (1 - λ) L1 + λ (1 - SSIM), SSIM with an 11 x 11 Gaussian
// window over the window positions inside the image ("valid"), C1 = 0.01², C2 = 0.03², means
// over pixels (L1) and positions (SSIM) and the 3 channels. The render is composited on the
// step's background first (x = color + T b), and so is the target where it has a coverage
// (alpha): stored on its own background b0, it becomes target + (1 - alpha)(b - b0). Its gradient becomes the backward pass's output gradient:
// per pixel the color channels, then alpha (-Σ g_c b_c), then depth (zero).
//
// Two passes: `ssim_terms`, per window position, the cotangents of the window's filtered
// moments (mean of x, of x², of x y); `loss_gradient`, per pixel, L1's gradient plus those
// cotangents spread back over the windows holding the pixel (the transposed filter).

struct LossInfo {
    // width, height, pixel state words per pixel (3 colors, T, the depth sum if kept; f32),
    // target offset
    size: vec4<u32>,
    // valid window positions: width, height, count; the target's coverage offset (or
    // 0xffffffff: opaque)
    valid: vec4<u32>,
    // the step's background rgb, λ
    background: vec4<f32>,
    // the target's own background rgb, unused
    base: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> pixel_state: array<f32>;
@group(0) @binding(1) var<storage, read> targets: array<f32>;
@group(0) @binding(2) var<storage, read> taps: array<f32, 11>;
@group(0) @binding(3) var<storage, read_write> terms: array<f32>;
@group(0) @binding(4) var<storage, read_write> pixel_grad: array<f32>;
@group(0) @binding(5) var<storage, read_write> sums: array<f32>;
@group(0) @binding(6) var<uniform> info: LossInfo;
@group(0) @binding(7) var<storage, read> coverage: array<f32>;

const C1: f32 = 0.0001;
const C2: f32 = 0.0009;

var<workgroup> partial: array<f32, 64>;

// The composited render at pixel p, channel c.
fn render(p: u32, c: u32) -> f32 {
    let s = p * info.size.z;
    return pixel_state[s + c] + pixel_state[s + 3u] * info.background[c];
}

fn target_at(p: u32, c: u32) -> f32 {
    let t = targets[info.size.w + p * 3u + c];
    if (info.valid.w == 0xffffffffu) {
        return t;
    }
    return t + (1.0 - coverage[info.valid.w + p]) * (info.background[c] - info.base[c]);
}

// Sums `v` over the workgroup into sums[2 * group + slot].
fn reduce(lid: u32, group: u32, slot: u32, v: f32) {
    partial[lid] = v;
    workgroupBarrier();
    for (var step = 32u; step > 0u; step = step / 2u) {
        if (lid < step) {
            partial[lid] += partial[lid + step];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        sums[2u * group + slot] = partial[0];
    }
}

@compute @workgroup_size(64)
fn ssim_terms(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let group = wid.y * 65535u + wid.x;
    let i = group * 64u + lid;
    var s_sum = 0.0;
    if (i < info.valid.z) {
        let px = i % info.valid.x;
        let py = i / info.valid.x;
        let w = info.size.x;
        // d(λ (1 - mean SSIM)) / d(s at one position and channel).
        let scale = -info.background.w / (3.0 * f32(info.valid.z));
        for (var c = 0u; c < 3u; c++) {
            var mx = 0.0;
            var my = 0.0;
            var exx = 0.0;
            var eyy = 0.0;
            var exy = 0.0;
            for (var ky = 0u; ky < 11u; ky++) {
                for (var kx = 0u; kx < 11u; kx++) {
                    let g = taps[ky] * taps[kx];
                    let p = (py + ky) * w + px + kx;
                    let x = render(p, c);
                    let y = target_at(p, c);
                    mx += g * x;
                    my += g * y;
                    exx += g * x * x;
                    eyy += g * y * y;
                    exy += g * x * y;
                }
            }
            let vx = exx - mx * mx;
            let vy = eyy - my * my;
            let cxy = exy - mx * my;
            let a = 2.0 * mx * my + C1;
            let b = 2.0 * cxy + C2;
            let cc = mx * mx + my * my + C1;
            let d = vx + vy + C2;
            let s = a * b / (cc * d);
            s_sum += s;
            let t = (i * 3u + c) * 3u;
            terms[t] = scale * ((2.0 * my * b - 2.0 * my * a) / (cc * d) - s * (2.0 * mx / cc - 2.0 * mx / d));
            terms[t + 1u] = scale * (-s / d);
            terms[t + 2u] = scale * (2.0 * a / (cc * d));
        }
    }
    reduce(lid, group, 1u, s_sum);
}

@compute @workgroup_size(64)
fn loss_gradient(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let group = wid.y * 65535u + wid.x;
    let q = group * 64u + lid;
    let w = info.size.x;
    let pixels = w * info.size.y;
    var l1 = 0.0;
    if (q < pixels) {
        let qx = i32(q % w);
        let qy = i32(q / w);
        let l1_scale = (1.0 - info.background.w) / (3.0 * f32(pixels));
        var d_alpha = 0.0;
        for (var c = 0u; c < 3u; c++) {
            let x = render(q, c);
            let y = target_at(q, c);
            l1 += abs(x - y);
            var g = l1_scale * sign(x - y);
            // The windows at positions q - k (k = 0..10 per axis) that hold q, as tap k.
            for (var ky = 0; ky < 11; ky++) {
                let py = qy - ky;
                if (py < 0 || py >= i32(info.valid.y)) {
                    continue;
                }
                for (var kx = 0; kx < 11; kx++) {
                    let px = qx - kx;
                    if (px < 0 || px >= i32(info.valid.x)) {
                        continue;
                    }
                    let t = ((u32(py) * info.valid.x + u32(px)) * 3u + c) * 3u;
                    let wk = taps[ky] * taps[kx];
                    g += wk * (terms[t] + 2.0 * x * terms[t + 1u] + y * terms[t + 2u]);
                }
            }
            pixel_grad[q * 5u + c] = g;
            d_alpha -= g * info.background[c];
        }
        pixel_grad[q * 5u + 3u] = d_alpha;
        pixel_grad[q * 5u + 4u] = 0.0;
    }
    reduce(lid, group, 0u, l1);
}
