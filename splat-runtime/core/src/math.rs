//! Branch-free `exp`, `ln`, `ln_1p` and `erf` for `f32`.
//!
//! `f32::exp` and `f32::ln` call libm one value at a time, which stops LLVM from vectorizing
//! the lane loops of [`crate::lanes`]. These versions use only arithmetic, bit operations and
//! selects (Cephes-style range reduction and minimax polynomials), so a loop over eight lanes
//! becomes vector code. The scalar code paths call the same functions, keeping the scalar and
//! lane forms of generated code bit-identical. Accuracy against the correctly rounded result
//! is within 2 ulp for `exp` and `ln` and 3 ulp for `ln_1p` over the whole range (tested below); special values follow IEEE 754
//! (`exp(-inf) = 0`, `ln(0) = -inf`, `ln(x < 0) = NaN`, NaN in gives NaN out).

const LOG2_E: f32 = std::f32::consts::LOG2_E;
/// ln 2 split in a part exact in f32 and a remainder, for range reduction without rounding loss.
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
/// Adding and subtracting 1.5 * 2^23 rounds an f32 of magnitude below 2^22 to an integer.
const ROUND_MAGIC: f32 = 12_582_912.0;

#[inline(always)]
fn select(c: bool, a: f32, b: f32) -> f32 {
    let m = (c as u32).wrapping_neg();
    f32::from_bits((m & a.to_bits()) | (!m & b.to_bits()))
}

/// 2^n for integer n in [-252, 254], as a product of two normal powers of two.
#[inline(always)]
fn pow2i(n: i32) -> (f32, f32) {
    let h = n >> 1;
    let a = f32::from_bits(((h + 127) as u32) << 23);
    let b = f32::from_bits(((n - h + 127) as u32) << 23);
    (a, b)
}

/// e^x, within 2 ulp; overflows to +inf above ~88.72 and underflows through the subnormals.
#[inline(always)]
#[allow(clippy::excessive_precision)] // Cephes coefficients as published
pub fn exp(x: f32) -> f32 {
    let xc = x.clamp(-104.0, 89.0);
    let t = xc * LOG2_E + ROUND_MAGIC;
    let n = t - ROUND_MAGIC;
    let ni = (t.to_bits() as i32) - (ROUND_MAGIC.to_bits() as i32);
    let r = (xc - n * LN2_HI) - n * LN2_LO;
    let mut p = 1.987_569_1e-4;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 5.000_000_1e-1;
    let e = p * (r * r) + r + 1.0;
    let (a, b) = pow2i(ni);
    let y = (e * a) * b;
    select(x.is_nan(), x, y)
}

/// Natural logarithm, within 2 ulp for every positive finite input (subnormals included).
#[inline(always)]
#[allow(clippy::excessive_precision)] // Cephes coefficients as published
pub fn ln(x: f32) -> f32 {
    // Scale subnormals into the normal range first.
    let sub = x < f32::MIN_POSITIVE;
    let xs = select(sub, x * 8_388_608.0, x);
    let bits = xs.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 127 - if sub { 23 } else { 0 };
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    // Bring the mantissa into [sqrt(1/2), sqrt(2)) so that f = m - 1 is small.
    let big = m > std::f32::consts::SQRT_2;
    e += big as i32;
    let f = select(big, m * 0.5, m) - 1.0;
    let z = f * f;
    let mut p = 7.037_683_6e-2;
    p = p * f - 1.151_461e-1;
    p = p * f + 1.167_699_9e-1;
    p = p * f - 1.242_014_1e-1;
    p = p * f + 1.424_932_3e-1;
    p = p * f - 1.666_805_8e-1;
    p = p * f + 2.000_071_4e-1;
    p = p * f - 2.499_999_4e-1;
    p = p * f + 3.333_333_1e-1;
    let ef = e as f32;
    let y = p * f * z + ef * LN2_LO - 0.5 * z;
    let r = f + y + ef * LN2_HI;
    // IEEE special cases, as selects so the whole function stays branch-free.
    let r = select(x == f32::INFINITY, x, r);
    let r = select(x == 0.0, f32::NEG_INFINITY, r);
    select(x < 0.0 || x.is_nan(), f32::NAN, r)
}

/// ln(1 + x), accurate for small |x| (within 3 ulp) through the `u - 1` correction trick.
#[inline(always)]
pub fn ln_1p(x: f32) -> f32 {
    let u = 1.0 + x;
    let d = u - 1.0;
    // ln(u) * x / (u - 1) cancels the rounding error made when forming u.
    let corrected = ln(u) * (x / select(d == 0.0, 1.0, d));
    let r = select(d == 0.0, x, corrected);
    select(u == f32::INFINITY, u, r)
}

/// Maclaurin coefficients of erf(x) / (2 x / sqrt(pi)) in powers of x^2, highest first:
/// (-1)^n / (n! (2n + 1)) for n = 6..0. Used below |x| = 0.5, where the next term is < 1e-9.
pub const ERF_SERIES: [f32; 7] = [
    1.0 / 9360.0,
    -1.0 / 1320.0,
    1.0 / 216.0,
    -1.0 / 42.0,
    1.0 / 10.0,
    -1.0 / 3.0,
    1.0,
];

/// Numerical Recipes' Chebyshev fit of erfc(z) = t exp(-z^2 + P(t)), t = 1 / (1 + z / 2),
/// fractional error below 1.2e-7 for z >= 0: P's coefficients, highest first.
#[allow(clippy::excessive_precision)] // as published
pub const ERFC_FIT: [f32; 10] = [
    0.170_872_77,
    -0.822_152_23,
    1.488_515_87,
    -1.135_203_98,
    0.278_868_07,
    -0.186_288_06,
    0.096_784_18,
    0.374_091_96,
    1.000_023_68,
    -1.265_512_23,
];

/// The error function: below |x| = 0.5 the Maclaurin series, above it 1 - erfc from
/// [`ERFC_FIT`]; within 4e-7 of the exact value relative to it (3.8e-7 just above 0.5,
/// falling below 2e-7 by 0.8); erf(-x) = -erf(x) (but erf(-0) = +0), NaN in gives NaN out.
/// The generated WGSL computes the same steps (`emit::naga`).
#[inline(always)]
pub fn erf(x: f32) -> f32 {
    let a = x.abs();
    let z = a * a;
    let series = ERF_SERIES.iter().fold(0.0, |p, c| p * z + c);
    let near = std::f32::consts::FRAC_2_SQRT_PI * a * series;
    let t = 1.0 / (1.0 + 0.5 * a);
    let fit = ERFC_FIT.iter().fold(0.0, |p, c| p * t + c);
    let far = 1.0 - t * exp(fit - z);
    let r = select(a < 0.5, near, far);
    select(x < 0.0, -r, r)
}

/// The error function in f64 (the `f64` twins of generated code call it).
pub fn erf_f64(x: f64) -> f64 {
    libm::erf(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps(a: f32, exact: f64) -> f64 {
        let e = exact as f32;
        if a == e || (a.is_nan() && e.is_nan()) {
            return 0.0;
        }
        let spacing = (f32::from_bits(e.abs().to_bits() + 1) - e.abs()) as f64;
        ((a as f64) - exact).abs() / spacing
    }

    fn samples(lo: f32, hi: f32, n: usize) -> impl Iterator<Item = f32> {
        let mut rng = fastrand::Rng::with_seed(7);
        (0..n).map(move |_| lo + (hi - lo) * rng.f32())
    }

    #[test]
    fn exp_is_within_two_ulp() {
        let mut worst: f64 = 0.0;
        for x in samples(-103.0, 88.7, 200_000).chain(samples(-1.0, 1.0, 100_000)) {
            let exact = (x as f64).exp();
            if exact < f32::MIN_POSITIVE as f64 {
                // Subnormal results carry fewer bits; require an absolute error of one spacing.
                assert!(((exp(x) as f64) - exact).abs() <= 2.0 * 1.4e-45, "exp({x})");
                continue;
            }
            worst = worst.max(ulps(exp(x), exact));
        }
        assert!(worst <= 2.0, "worst exp error {worst} ulp");
    }

    #[test]
    fn ln_is_within_two_ulp() {
        let mut worst: f64 = 0.0;
        let wide = samples(-126.0, 127.0, 200_000).map(|e| e.exp2());
        for x in wide
            .chain(samples(0.5, 2.0, 100_000))
            .chain([1e-44, 1e-40, f32::MAX])
        {
            worst = worst.max(ulps(ln(x), (x as f64).ln()));
        }
        assert!(worst <= 2.0, "worst ln error {worst} ulp");
    }

    #[test]
    fn erf_is_within_its_stated_relative_error() {
        let mut worst: f64 = 0.0;
        let tiny = samples(-40.0, -1.0, 50_000).map(|e| e.exp2());
        for x in tiny
            .chain(samples(-6.0, 6.0, 200_000))
            .chain([0.5, 10.0, 1e-30])
        {
            for x in [x, -x] {
                let exact = libm::erf(x as f64);
                worst = worst.max(((erf(x) as f64) - exact).abs() / exact.abs());
            }
        }
        println!("worst erf error {worst:.2e} of the value");
        assert!(worst <= 4e-7, "worst erf error {worst:.2e} of the value");
        assert!(erf(f32::NAN).is_nan() && erf(f32::INFINITY) == 1.0 && erf(0.0) == 0.0);
    }

    #[test]
    fn ln_1p_is_within_three_ulp() {
        let mut worst: f64 = 0.0;
        let small = samples(-30.0, 0.0, 100_000).map(|e| e.exp2());
        for x in small.chain(samples(-0.99, 100.0, 100_000)) {
            worst = worst.max(ulps(ln_1p(x), (x as f64).ln_1p()));
        }
        assert!(worst <= 3.0, "worst ln_1p error {worst} ulp");
    }

    #[test]
    fn special_values_follow_ieee() {
        assert_eq!(exp(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp(f32::INFINITY), f32::INFINITY);
        assert_eq!(exp(100.0), f32::INFINITY);
        assert_eq!(exp(-200.0), 0.0);
        assert!(exp(f32::NAN).is_nan());
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(ln(1.0), 0.0);
        assert_eq!(ln(0.0), f32::NEG_INFINITY);
        assert_eq!(ln(f32::INFINITY), f32::INFINITY);
        assert!(ln(-1.0).is_nan());
        assert!(ln(f32::NAN).is_nan());
        assert_eq!(ln_1p(0.0), 0.0);
        assert_eq!(ln_1p(-1.0), f32::NEG_INFINITY);
        assert!(ln_1p(-2.0).is_nan());
    }
}
