// The shade data packed for the blends at a reduced precision (`gpu::shade_pack`, the CPU's
// `precision::PackedShade`): `shade_range` finds the range each float word spans over the
// primitives with a tile rectangle (the ones a blend can read; unorm formats only), and
// `shade_pack` codes every primitive's float words, several per word, the other words exact.
// Appended to `tiles.wgsl` (for `tile_rect`), with `finite.wgsl` and `half.wgsl`.

const SHADE_AT: u32 = {{SHADE_AT}}u;
const FLOATS: u32 = {{FLOATS}}u; // float words of the shade type
const PACKED: u32 = {{PACKED}}u; // packed words per primitive

// Per float word k: [2k] the largest complement of its values' keys (so their least), [2k + 1]
// the largest key; a cleared buffer holds neither. From 2 FLOATS on, per float word, the value
// coded as 0 and the span coded as 1, as f32 bits (`shade_pack` writes them).
@group(0) @binding(3) var<storage, read_write> shade_ranges: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> packed_shade: array<u32>;

var<workgroup> group_keys: array<atomic<u32>, {{KEY_WORDS}}>;

// A key of `x`'s bits that orders as u32 as the values do (negatives below positives).
fn order_key(x: f32) -> u32 {
    let b = bitcast<u32>(x);
    return select(b ^ 0x80000000u, ~b, (b >> 31u) == 1u);
}

fn from_key(k: u32) -> f32 {
    return bitcast<f32>(select(~k, k ^ 0x80000000u, (k >> 31u) == 1u));
}

fn widen(k: u32, x: f32) {
    if (finite(x)) {
        atomicMax(&group_keys[2u * k], ~order_key(x));
        atomicMax(&group_keys[2u * k + 1u], order_key(x));
    }
}

@compute @workgroup_size(256)
fn shade_range(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
    if (lid < 2u * FLOATS) {
        atomicStore(&group_keys[lid], 0u);
    }
    workgroupBarrier();
    if (i < frame.primitives) {
        let rect = tile_rect(i);
        if (rect.z > rect.x) {
{{WIDEN}}
        }
    }
    workgroupBarrier();
    // One global max per workgroup and word.
    if (lid < 2u * FLOATS) {
        let k = atomicLoad(&group_keys[lid]);
        if (k != 0u) {
            atomicMax(&shade_ranges[lid], k);
        }
    }
}

// Float word k's (value coded as 0, span coded as 1): its values' range, or (0, 1) where it
// has none or its span is not finite (the CPU's `PackedShade::new`).
fn coding_range(k: u32) -> vec2<f32> {
    let least = atomicLoad(&shade_ranges[2u * k]);
    let most = atomicLoad(&shade_ranges[2u * k + 1u]);
    if (least == 0u || most == 0u) {
        return vec2<f32>(0.0, 1.0);
    }
    let lo = from_key(~least);
    let span = from_key(most) - lo;
    if (!finite(span)) {
        return vec2<f32>(0.0, 1.0);
    }
    return vec2<f32>(lo, max(span, 1.17549435e-38));
}

// `x` (a value's place in its range) in `steps` steps, rounded half away from zero as Rust's
// `round` is (WGSL's `round` ties to even); saturating, NaN to 0 as Rust's `as u32` does.
fn unit_code(x: f32, steps: f32) -> u32 {
    if (!finite(x)) {
        let nan = (bitcast<u32>(x) & 0x7fffffu) != 0u;
        return select(0u, u32(steps), !nan && x > 0.0);
    }
    let y = clamp(x, 0.0, 1.0) * steps;
    let whole = floor(y);
    return u32(whole) + select(0u, 1u, y - whole >= 0.5);
}

@compute @workgroup_size(256)
fn shade_pack(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * 65535u + wid.x) * 256u + lid;
{{WRITE_RANGES}}
    if (i >= frame.primitives) {
        return;
    }
    let at = i * PACKED;
{{PACK}}
}
