//! Every corpus function as the compiler emits it against the same source compiled by rustc
//! alone (`codegen_tests::corpus::plain`, the intrinsics from the prelude's plain Rust): an
//! independent reference for the lowering. The corpus' other checks compare the compiler with
//! itself (its adjoint with finite differences of its own f64 twin, its lanes with its scalar
//! form), so a rule that changed an operator's meaning everywhere (a swapped operand, a wrong
//! constant) would pass them; here rustc's reading of the source decides.
//!
//! Left out: `jacobians` (`jacobian` is the compiler's alone) and `structured::splat_of` (its
//! structs are two types, one per build).

use codegen_tests::corpus::{self, plain};
use fastrand::Rng;
use splat_runtime::checks::bound::Bound;
use splat_runtime::glam::{Mat2, Mat3, Quat, Vec2, Vec3, Vec4};

const SEED: u64 = 0x91A1;
const TRIALS: usize = 50;

/// Each output within 1e-6 of rustc's (about 16 f32 roundings) plus as much of the largest
/// output: the compiler lowers glam's methods by formulas of its own (a quaternion's rotation,
/// a matrix inverse), which round otherwise. Measured: 0.47 of the bound (`vectors::rotate`,
/// 4.8e-7 off on 0.18); every function without such a method equal bit for bit or within an
/// ulp. With `atan2`'s and `powf`'s operands swapped in the lowering (which the corpus' other
/// checks, all the compiler's own, pass), `powers`, `trig` and `kinks` fail.
const PLAIN: Bound = Bound::new(1e-6, 1e-6);

/// An argument read from the sampler's words: floats from the floats, `u32` and `bool` from
/// the integers.
trait Arg: Sized {
    fn take(floats: &mut &[f32], ints: &mut &[u32]) -> Self;
}

fn split<'a, T>(words: &mut &'a [T], n: usize) -> &'a [T] {
    let (head, tail) = words.split_at(n);
    *words = tail;
    head
}

macro_rules! float_args {
    ($($t:ty),*) => {$(
        impl Arg for $t {
            fn take(floats: &mut &[f32], _: &mut &[u32]) -> Self {
                use splat_runtime::Flat;
                <$t>::read_words(split(floats, <$t as Flat>::LEN))
            }
        }
    )*};
}
float_args!(
    f32, Vec2, Vec3, Vec4, Quat, Mat2, Mat3, [f32; 4], [Vec3; 16]
);

impl Arg for u32 {
    fn take(_: &mut &[f32], ints: &mut &[u32]) -> Self {
        split(ints, 1)[0]
    }
}

impl Arg for bool {
    fn take(_: &mut &[f32], ints: &mut &[u32]) -> Self {
        split(ints, 1)[0] != 0
    }
}

/// A result as its f32 words.
trait Words {
    fn words(&self) -> Vec<f32>;
}

macro_rules! flat_words {
    ($($t:ty),*) => {$(
        impl Words for $t {
            fn words(&self) -> Vec<f32> {
                use splat_runtime::Flat;
                let mut w = vec![0.0; <$t as Flat>::LEN];
                self.write_words(&mut w);
                w
            }
        }
    )*};
}
flat_words!(f32, Vec2, Vec3, Vec4, Mat2, Mat3, [f32; 4]);

impl<A: Words, B: Words> Words for (A, B) {
    fn words(&self) -> Vec<f32> {
        [self.0.words(), self.1.words()].concat()
    }
}

impl<A: Words, B: Words, C: Words, D: Words> Words for (A, B, C, D) {
    fn words(&self) -> Vec<f32> {
        [
            self.0.words(),
            self.1.words(),
            self.2.words(),
            self.3.words(),
        ]
        .concat()
    }
}

/// A function of `Args` called on the sampler's words.
trait Kernel<Args> {
    fn call(&self, floats: &[f32], ints: &[u32]) -> Vec<f32>;
}

macro_rules! kernels {
    ($(($($a:ident),*)),*) => {$(
        impl<F, R, $($a),*> Kernel<($($a,)*)> for F
        where
            F: Fn($($a),*) -> R,
            R: Words,
            $($a: Arg,)*
        {
            #[allow(non_snake_case)]
            fn call(&self, mut floats: &[f32], mut ints: &[u32]) -> Vec<f32> {
                $(let $a = $a::take(&mut floats, &mut ints);)*
                assert!(floats.is_empty() && ints.is_empty(), "words left over");
                self($($a),*).words()
            }
        }
    )*};
}
kernels!((A), (A, B), (A, B, C));

/// `compiled` against `plain` on the sampler's inputs; the worst fit.
fn compare<Args, const N: usize, const K: usize>(
    name: &str,
    compiled: impl Kernel<Args>,
    plain: impl Kernel<Args>,
    sample: impl Fn(&mut Rng) -> ([f64; N], [u32; K]),
) -> f64 {
    let mut rng = Rng::with_seed(SEED);
    let mut worst: Option<(f64, String)> = None;
    for _ in 0..TRIALS {
        let (x, ints) = sample(&mut rng);
        let floats = x.map(|v| v as f32);
        let f64s = |w: Vec<f32>| w.into_iter().map(f64::from).collect::<Vec<f64>>();
        let (mut got, mut want) = (compiled.call(&floats, &ints), plain.call(&floats, &ints));
        // The same infinity or NaN on both sides is agreement (the bound takes finite values).
        for (g, w) in got.iter_mut().zip(&mut want) {
            if !g.is_finite() && (g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan())) {
                (*g, *w) = (0.0, 0.0);
            }
        }
        let (got, want) = (f64s(got), f64s(want));
        let fit = PLAIN.fit(&got, &want, None);
        if worst.as_ref().is_none_or(|(w, _)| fit.of_bound > *w) {
            let at = format!(
                "output word {} at {floats:?} {ints:?}: {:e} vs rustc's {:e}, largest {:e}",
                fit.at, fit.got, fit.want, fit.scale
            );
            worst = Some((fit.of_bound, at));
        }
    }
    let (worst, at) = worst.expect("trials");
    println!("{name}: worst {worst:.3} of the bound over {TRIALS} inputs, {at}");
    assert!(worst <= 1.0, "{name}: past the bound: {at}");
    worst
}

/// One test per corpus entry, but for those the module doc leaves out.
macro_rules! against_plain {
    () => {};
    (jacobians :: $f:ident / $adj:ident => $sample:expr $(, $mark:ident)?; $($rest:tt)*) => {
        against_plain!($($rest)*);
    };
    (structured :: splat_of / $adj:ident => $sample:expr $(, $mark:ident)?; $($rest:tt)*) => {
        against_plain!($($rest)*);
    };
    ($m:ident :: $f:ident / $adj:ident => $sample:expr $(, $mark:ident)?; $($rest:tt)*) => {
        #[test]
        fn $f() {
            compare(
                concat!(stringify!($m), "::", stringify!($f)),
                corpus::$m::$f,
                plain::$m::$f,
                $sample,
            );
        }
        against_plain!($($rest)*);
    };
}

mod entries {
    use super::*;
    codegen_tests::with_corpus!(against_plain!());
}

/// The kinks module's functions, on both sides of each kink (the GPU's list; not in the
/// corpus list, whose checks need gradients).
#[test]
fn kinks() {
    use codegen_tests::samples::plain as uniform;
    compare(
        "sqrt_of",
        corpus::kinks::sqrt_of,
        plain::kinks::sqrt_of,
        uniform::<1>(0.0, 4.0),
    );
    compare(
        "rsqrt_of",
        corpus::kinks::rsqrt_of,
        plain::kinks::rsqrt_of,
        uniform::<1>(0.01, 4.0),
    );
    compare(
        "ln_of",
        corpus::kinks::ln_of,
        plain::kinks::ln_of,
        uniform::<1>(0.01, 4.0),
    );
    compare(
        "recip_of",
        corpus::kinks::recip_of,
        plain::kinks::recip_of,
        uniform::<1>(0.1, 4.0),
    );
    compare(
        "asin_of",
        corpus::kinks::asin_of,
        plain::kinks::asin_of,
        uniform::<1>(-1.0, 1.0),
    );
    compare(
        "atan2_of",
        corpus::kinks::atan2_of,
        plain::kinks::atan2_of,
        uniform::<2>(-1.0, 1.0),
    );
    compare(
        "length_of",
        corpus::kinks::length_of,
        plain::kinks::length_of,
        uniform::<3>(-1.0, 1.0),
    );
    compare(
        "normalize_of",
        corpus::kinks::normalize_of,
        plain::kinks::normalize_of,
        uniform::<3>(-1.0, 1.0),
    );
    compare(
        "max_of",
        corpus::kinks::max_of,
        plain::kinks::max_of,
        uniform::<2>(-1.0, 1.0),
    );
    compare(
        "min_of",
        corpus::kinks::min_of,
        plain::kinks::min_of,
        uniform::<2>(-1.0, 1.0),
    );
    compare(
        "clamp_of",
        corpus::kinks::clamp_of,
        plain::kinks::clamp_of,
        uniform::<1>(-0.5, 1.5),
    );
    compare(
        "abs_of",
        corpus::kinks::abs_of,
        plain::kinks::abs_of,
        uniform::<1>(-1.0, 1.0),
    );
    compare(
        "lazy_div",
        corpus::kinks::lazy_div,
        plain::kinks::lazy_div,
        uniform::<2>(-1.0, 1.0),
    );
    compare(
        "eager_div",
        corpus::kinks::eager_div,
        plain::kinks::eager_div,
        uniform::<2>(-1.0, 1.0),
    );
    compare(
        "nan_branch",
        corpus::kinks::nan_branch,
        plain::kinks::nan_branch,
        uniform::<1>(-2.0, 2.0),
    );
    compare(
        "inf_branch",
        corpus::kinks::inf_branch,
        plain::kinks::inf_branch,
        uniform::<1>(0.0, 60.0),
    );
}

/// Every free intrinsic the compiler reads as a method (`exp(x)` for `x.exp()`) has its plain
/// form in the prelude: a method's source compiles as ordinary Rust.
#[test]
fn every_free_intrinsic_has_a_plain_form() {
    macro_rules! plain_forms {
        ($($name:ident),*) => {{
            $(
                #[allow(unused_imports)]
                use splat_runtime::prelude::$name;
            )*
            [$(stringify!($name)),*]
        }};
    }
    // Naming one the prelude lacks fails to compile; leaving one out fails below.
    let mut names = plain_forms!(
        exp,
        log,
        ln,
        log1p,
        sqrt,
        abs,
        min,
        max,
        clamp,
        sin,
        cos,
        tan,
        atan2,
        dot,
        cross,
        length,
        normalize,
        transpose,
        inverse,
        determinant
    )
    .to_vec();
    let mut compiler: Vec<&str> = splat_compiler::typeck::rules::FREE_AS_METHOD
        .iter()
        .map(|(free, _)| *free)
        .collect();
    names.sort_unstable();
    compiler.sort_unstable();
    assert_eq!(names, compiler);
}
