//! `powf` by a constant exponent: an integer or half an odd integer up to 4.5 in magnitude is
//! computed by multiplications, a square root and a division instead of `exp` and `ln`
//! (`Lowerer::power_of_constant`): each within 4 ulp of the exact power (f64), and none of
//! them calls `pow` in the generated WGSL. Their gradients are held to finite differences with
//! the corpus (`b.powf(1.5)`).

use splat_macros::splat_functions;

#[splat_functions]
mod powers {
    use splat_runtime::prelude::*;

    pub fn pow_m4_5(x: f32) -> f32 {
        x.powf(-4.5)
    }

    pub fn pow_m4_0(x: f32) -> f32 {
        x.powf(-4.0)
    }

    pub fn pow_m3_5(x: f32) -> f32 {
        x.powf(-3.5)
    }

    pub fn pow_m3_0(x: f32) -> f32 {
        x.powf(-3.0)
    }

    pub fn pow_m2_5(x: f32) -> f32 {
        x.powf(-2.5)
    }

    pub fn pow_m2_0(x: f32) -> f32 {
        x.powf(-2.0)
    }

    pub fn pow_m1_5(x: f32) -> f32 {
        x.powf(-1.5)
    }

    pub fn pow_m1_0(x: f32) -> f32 {
        x.powf(-1.0)
    }

    pub fn pow_m0_5(x: f32) -> f32 {
        x.powf(-0.5)
    }

    pub fn pow_p0_0(x: f32) -> f32 {
        x.powf(0.0)
    }

    pub fn pow_p0_5(x: f32) -> f32 {
        x.powf(0.5)
    }

    pub fn pow_p1_0(x: f32) -> f32 {
        x.powf(1.0)
    }

    pub fn pow_p1_5(x: f32) -> f32 {
        x.powf(1.5)
    }

    pub fn pow_p2_0(x: f32) -> f32 {
        x.powf(2.0)
    }

    pub fn pow_p2_5(x: f32) -> f32 {
        x.powf(2.5)
    }

    pub fn pow_p3_0(x: f32) -> f32 {
        x.powf(3.0)
    }

    pub fn pow_p3_5(x: f32) -> f32 {
        x.powf(3.5)
    }

    pub fn pow_p4_0(x: f32) -> f32 {
        x.powf(4.0)
    }

    pub fn pow_p4_5(x: f32) -> f32 {
        x.powf(4.5)
    }

    /// An exponent past the cheap ones: `powf` itself.
    pub fn pow_p6_25(x: f32) -> f32 {
        x.powf(6.25)
    }
}

/// A kernel of one `f32`.
type Power = fn(f32) -> f32;

const CHEAP: [(f64, Power); 19] = [
    (-4.5, powers::pow_m4_5 as Power),
    (-4.0, powers::pow_m4_0 as Power),
    (-3.5, powers::pow_m3_5 as Power),
    (-3.0, powers::pow_m3_0 as Power),
    (-2.5, powers::pow_m2_5 as Power),
    (-2.0, powers::pow_m2_0 as Power),
    (-1.5, powers::pow_m1_5 as Power),
    (-1.0, powers::pow_m1_0 as Power),
    (-0.5, powers::pow_m0_5 as Power),
    (0.0, powers::pow_p0_0 as Power),
    (0.5, powers::pow_p0_5 as Power),
    (1.0, powers::pow_p1_0 as Power),
    (1.5, powers::pow_p1_5 as Power),
    (2.0, powers::pow_p2_0 as Power),
    (2.5, powers::pow_p2_5 as Power),
    (3.0, powers::pow_p3_0 as Power),
    (3.5, powers::pow_p3_5 as Power),
    (4.0, powers::pow_p4_0 as Power),
    (4.5, powers::pow_p4_5 as Power),
];

/// How far `got` is from `exact`, in units in the last place of the f32 nearest `exact`.
fn ulps(got: f32, exact: f64) -> f64 {
    let nearest = exact as f32;
    let ulp = (f32::from_bits(nearest.abs().to_bits() + 1) - nearest.abs()) as f64;
    (got as f64 - exact).abs() / ulp
}

#[test]
fn cheap_powers_are_within_4_ulp() {
    let mut rng = fastrand::Rng::with_seed(7);
    let (mut worst, mut libm) = ((0.0f64, 0.0, 0.0f32), 0.0f64);
    for (e, f) in CHEAP {
        for _ in 0..20_000 {
            // Log-uniform over [1e-3, 1e3].
            let x = 10f32.powf(rng.f32() * 6.0 - 3.0);
            let exact = (x as f64).powf(e);
            let u = ulps(f(x), exact);
            if u > worst.0 {
                worst = (u, e, x);
            }
            libm = libm.max(ulps(x.powf(e as f32), exact));
        }
    }
    println!(
        "worst: {:.2} ulp (exponent {}, x = {}); libm's powf: {libm:.2} ulp",
        worst.0, worst.1, worst.2
    );
    assert!(worst.0 <= 4.0, "{worst:?}");
}

#[test]
fn cheap_powers_keep_powfs_values_at_the_edges() {
    for (e, f) in CHEAP {
        for x in [0.0f32, -0.0, f32::INFINITY, -2.0, 1.0] {
            let (got, want) = (f(x), x.powf(e as f32));
            let same = got == want || (got.is_nan() && want.is_nan());
            assert!(same, "{x}^{e}: {got}, powf says {want}");
        }
    }
}

#[test]
fn only_exponents_past_the_cheap_ones_call_pow() {
    let wgsl = powers::GENERATED_WGSL;
    let calls = wgsl.matches("pow(").count();
    assert!(calls >= 1, "x^6.25 calls pow");
    // naga writes a name that ends in a digit with a `_` after it.
    let body = |e: f64| {
        let n = name(e);
        let starts = |f: &&str| f.starts_with(&format!("{n}(")) || f.starts_with(&format!("{n}_("));
        wgsl.split("fn ").find(starts)
    };
    for (e, _) in CHEAP {
        assert_eq!(body(e).map(|f| f.contains("pow(")), Some(false), "x^{e}");
    }
}

fn name(e: f64) -> String {
    let sign = if e < 0.0 { "m" } else { "p" };
    format!("pow_{sign}{:.1}", e.abs()).replace('.', "_")
}
