// The photometric loss of a rendered frame against its target on the device, as
// `train::loss` defines it on the CPU: (1 - λ) L1 + λ (1 - SSIM), SSIM with an 11 x 11 Gaussian
// window over the window positions inside the image ("valid"), C1 = 0.01², C2 = 0.03², means
// over pixels (L1) and positions (SSIM) and the 3 channels. The render is composited on the
// step's background first (x = color + T b), and so is the target where it has a coverage
// (alpha): stored on its own background b0, it becomes target + (1 - alpha)(b - b0); stored
// as 8-bit straight RGBA, c alpha + b (1 - alpha). Its
// gradient becomes the backward pass's output gradient: per pixel the color channels, then
// alpha (-Σ g_c b_c), then depth (zero).
//
// The 11 x 11 window is the product of two 11-tap filters, so it runs as two 11-tap passes,
// and so does its transpose (121 taps per window position would be 5.5x the work):
// - `ssim_rows`, per row and valid column: each channel's moments (x, y, x², y², x y) filtered
//   along the row, into `rows`;
// - `ssim_terms`, per window position: those filtered down the column, SSIM, and the
//   cotangents of the window's means (of x, of x² and y², of x y) into `terms`;
// - `ssim_spread`, per row and valid column: the cotangents of the windows holding it spread
//   down the column (the transposed filter), into `rows` again;
// - `loss_gradient`, per pixel: L1's gradient plus those spread along the row, applied to
//   the pixel's x and y.

struct LossInfo {
    // width, height, pixel state words per pixel (3 colors, T, the depth sum if kept; f32),
    // unused
    size: vec4<u32>,
    // valid window positions: width, height, count; 1 where the target has a coverage (0:
    // opaque)
    valid: vec4<u32>,
    // the step's background rgb, λ
    background: vec4<f32>,
    // the target's own background b0 (rgb)
    base: vec4<f32>,
    // 1: the target is 8-bit straight RGBA, a word per pixel (red in the low byte); 0: RGB f32
    format: vec4<u32>,
}

@group(0) @binding(0) var<storage, read> pixel_state: array<f32>;
@group(0) @binding(1) var<storage, read> target_image: array<u32>;
@group(0) @binding(2) var<storage, read> taps: array<f32, 11>;
@group(0) @binding(3) var<storage, read_write> terms: array<f32>;
// Per row y and valid column x: 15 words (5 moments per channel) after `ssim_rows`, 9 (3
// spread cotangents per channel) after `ssim_spread`.
@group(0) @binding(8) var<storage, read_write> rows: array<f32>;
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
    if (info.format.x == 1u) {
        let v = unpack4x8unorm(target_image[p]);
        return v[c] * v.w + info.background[c] * (1.0 - v.w);
    }
    let t = bitcast<f32>(target_image[p * 3u + c]);
    if (info.valid.w == 0u) {
        return t;
    }
    return t + (1.0 - coverage[p]) * (info.background[c] - info.base[c]);
}

// Sums `v` over the workgroup into sums[2 * group + slot]. (A dispatch past 65,535 groups is
// rounded up to whole rows: groups past the buffer's end, all of whose values are zero, write
// nothing.)
fn reduce(lid: u32, group: u32, slot: u32, v: f32) {
    partial[lid] = v;
    workgroupBarrier();
    for (var step = 32u; step > 0u; step = step / 2u) {
        if (lid < step) {
            partial[lid] += partial[lid + step];
        }
        workgroupBarrier();
    }
    if (lid == 0u && 2u * group + slot < arrayLength(&sums)) {
        sums[2u * group + slot] = partial[0];
    }
}

// One invocation per row and valid column, `info.valid.x` by `info.size.y`.
fn row_cell(wid: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * 65535u + wid.x) * 64u + lid;
}

@compute @workgroup_size(64)
fn ssim_rows(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = row_cell(wid, lid);
    if (i >= info.valid.x * info.size.y) {
        return;
    }
    let x0 = i % info.valid.x;
    let y = i / info.valid.x;
    for (var c = 0u; c < 3u; c++) {
        var m = array<f32, 5>(0.0, 0.0, 0.0, 0.0, 0.0);
        for (var k = 0u; k < 11u; k++) {
            let p = y * info.size.x + x0 + k;
            let x = render(p, c);
            let t = target_at(p, c);
            let g = taps[k];
            m[0] += g * x;
            m[1] += g * t;
            m[2] += g * x * x;
            m[3] += g * t * t;
            m[4] += g * x * t;
        }
        let o = (i * 3u + c) * 5u;
        rows[o] = m[0];
        rows[o + 1u] = m[1];
        rows[o + 2u] = m[2];
        rows[o + 3u] = m[3];
        rows[o + 4u] = m[4];
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
        // d(λ (1 - mean SSIM)) / d(s at one position and channel).
        let scale = -info.background.w / (3.0 * f32(info.valid.z));
        for (var c = 0u; c < 3u; c++) {
            var m = array<f32, 5>(0.0, 0.0, 0.0, 0.0, 0.0);
            for (var k = 0u; k < 11u; k++) {
                let o = (((py + k) * info.valid.x + px) * 3u + c) * 5u;
                let g = taps[k];
                m[0] += g * rows[o];
                m[1] += g * rows[o + 1u];
                m[2] += g * rows[o + 2u];
                m[3] += g * rows[o + 3u];
                m[4] += g * rows[o + 4u];
            }
            let mx = m[0];
            let my = m[1];
            let vx = m[2] - mx * mx;
            let vy = m[3] - my * my;
            let cxy = m[4] - mx * my;
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
fn ssim_spread(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = row_cell(wid, lid);
    if (i >= info.valid.x * info.size.y) {
        return;
    }
    let px = i % info.valid.x;
    let qy = i / info.valid.x;
    // The window positions py = qy - k (k = 0..10) inside the valid rows hold row qy as tap k.
    let first = u32(max(i32(qy) - i32(info.valid.y) + 1, 0));
    let last = min(qy, 10u);
    for (var c = 0u; c < 3u; c++) {
        var s = array<f32, 3>(0.0, 0.0, 0.0);
        for (var k = first; k <= last; k++) {
            let t = (((qy - k) * info.valid.x + px) * 3u + c) * 3u;
            let g = taps[k];
            s[0] += g * terms[t];
            s[1] += g * terms[t + 1u];
            s[2] += g * terms[t + 2u];
        }
        let o = (i * 3u + c) * 3u;
        rows[o] = s[0];
        rows[o + 1u] = s[1];
        rows[o + 2u] = s[2];
    }
}

@compute @workgroup_size(64)
fn loss_gradient(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let group = wid.y * 65535u + wid.x;
    let q = group * 64u + lid;
    let w = info.size.x;
    let pixels = w * info.size.y;
    var l1 = 0.0;
    if (q < pixels) {
        let qx = q % w;
        let qy = q / w;
        // The columns px = qx - k (k = 0..10) inside the valid ones hold column qx as tap k.
        let first = u32(max(i32(qx) - i32(info.valid.x) + 1, 0));
        let last = min(qx, 10u);
        let l1_scale = (1.0 - info.background.w) / (3.0 * f32(pixels));
        var d_alpha = 0.0;
        for (var c = 0u; c < 3u; c++) {
            let x = render(q, c);
            let y = target_at(q, c);
            l1 += abs(x - y);
            var s = array<f32, 3>(0.0, 0.0, 0.0);
            for (var k = first; k <= last; k++) {
                let o = ((qy * info.valid.x + qx - k) * 3u + c) * 3u;
                let g = taps[k];
                s[0] += g * rows[o];
                s[1] += g * rows[o + 1u];
                s[2] += g * rows[o + 2u];
            }
            let g = l1_scale * sign(x - y) + s[0] + 2.0 * x * s[1] + y * s[2];
            pixel_grad[q * 5u + c] = g;
            d_alpha -= g * info.background[c];
        }
        pixel_grad[q * 5u + 3u] = d_alpha;
        pixel_grad[q * 5u + 4u] = 0.0;
    }
    reduce(lid, group, 0u, l1);
}
