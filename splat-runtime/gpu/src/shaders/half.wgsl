// IEEE half-precision conversions written on the bits, so every adapter rounds as the CPU's
// `half` crate does (to nearest, ties to even, subnormals kept, NaN kept quiet): WGSL leaves
// `pack2x16float`'s rounding and its handling of subnormals to the implementation.

const F16_MAX: f32 = 65504.0;

// `x` clamped to f16's finite range if finite (an infinity or NaN is a fault to pass on).
fn saturate_half(x: f32) -> f32 {
    return select(x, clamp(x, -F16_MAX, F16_MAX), finite(x));
}

// The f16 bits (low 16 of the result) nearest `x`; past f16's range, infinity.
fn to_half(x: f32) -> u32 {
    let b = bitcast<u32>(x);
    let sign = (b >> 16u) & 0x8000u;
    let e = (b >> 23u) & 0xffu;
    let m = b & 0x7fffffu;
    if (e == 0xffu) {
        return sign | 0x7c00u | select(0u, 0x200u | (m >> 13u), m != 0u);
    }
    let he = i32(e) - 112; // f16's biased exponent
    if (he >= 31) {
        return sign | 0x7c00u;
    }
    if (he <= 0) {
        // A subnormal f16 (or zero): the mantissa with its leading bit, shifted into place.
        if (he < -10) {
            return sign;
        }
        let full = m | 0x800000u;
        let shift = u32(14 - he);
        let kept = full >> shift;
        let rest = full & ((1u << shift) - 1u);
        let halfway = 1u << (shift - 1u);
        let up = rest > halfway || (rest == halfway && (kept & 1u) == 1u);
        return sign | (kept + select(0u, 1u, up));
    }
    let kept = m >> 13u;
    let rest = m & 0x1fffu;
    let up = rest > 0x1000u || (rest == 0x1000u && (kept & 1u) == 1u);
    // A carry out of the mantissa moves into the exponent, as rounding should.
    return (sign | (u32(he) << 10u) | kept) + select(0u, 1u, up);
}

// The value of the f16 bits `h` (its low 16), exactly.
fn from_half(h: u32) -> f32 {
    let sign = (h & 0x8000u) << 16u;
    let e = (h >> 10u) & 0x1fu;
    let m = h & 0x3ffu;
    if (e == 0u) {
        // Zero or subnormal: m x 2^-24, a normal f32.
        return bitcast<f32>(sign | bitcast<u32>(ldexp(f32(m), -24)));
    }
    if (e == 31u) {
        // Infinity, or NaN made quiet (as the `half` crate does).
        return bitcast<f32>(sign | 0x7f800000u | select(0u, 0x400000u | (m << 13u), m != 0u));
    }
    return bitcast<f32>(sign | ((e + 112u) << 23u) | (m << 13u));
}

// The power of two f16 gradient sums are scaled by (`precision::sum_scale`): the largest
// output gradient, whose bits are `largest`, brought to 1 to 2 (its exponent cancelled, within
// +-100); 1 where it is zero or not finite.
fn sum_scale(largest: u32) -> f32 {
    if (largest == 0u || largest >= 0x7f800000u) {
        return 1.0;
    }
    let e = clamp(i32(largest >> 23u) - 127, -100, 100);
    return ldexp(1.0, -e);
}
