//! Random inputs for each corpus function, away from its kinks and singular points: shared by
//! the CPU checks (`tests/corpus.rs`) and the GPU's (`tests/gpu.rs`), so both run every kernel
//! on the same kind of input.

use crate::check::uniform;
use fastrand::Rng;

/// Each input uniform in [lo, hi].
pub fn plain<const N: usize>(lo: f64, hi: f64) -> impl Fn(&mut Rng) -> ([f64; N], [u32; 0]) {
    move |r| (uniform(r, lo, hi), [])
}

/// Values of magnitude in [lo, hi] with a random sign.
pub fn signed<const N: usize>(lo: f64, hi: f64) -> impl Fn(&mut Rng) -> ([f64; N], [u32; 0]) {
    move |r| {
        let signed = |r: &mut Rng| (lo + (hi - lo) * r.f64()) * if r.bool() { 1.0 } else { -1.0 };
        (std::array::from_fn(|_| signed(r)), [])
    }
}

/// `minmax`: `clamp`'s bounds in order (x <= y), as Rust's `clamp` requires (it panics
/// otherwise); z anywhere.
pub fn minmax(r: &mut Rng) -> ([f64; 3], [u32; 0]) {
    let [a, b, z]: [f64; 3] = uniform(r, -1.0, 1.0);
    ([a.min(b), a.max(b), z], [])
}

/// `mat2`: a well-conditioned matrix (near 1.5 I) and a positive scale.
pub fn mat2(r: &mut Rng) -> ([f64; 5], [u32; 0]) {
    let mut x: [f64; 5] = uniform(r, -0.5, 0.5);
    x[0] += 1.5;
    x[3] += 1.5;
    x[4] = 0.5 + 0.5 * r.f64();
    (x, [])
}

/// `covariance`: a quaternion with a dominant w, log scales, a point in front of the camera.
pub fn covariance(r: &mut Rng) -> ([f64; 10], [u32; 0]) {
    let mut x: [f64; 10] = uniform(r, -1.0, 1.0);
    x[0] = 0.5 + 0.5 * r.f64();
    for s in &mut x[4..7] {
        *s = -1.0 + 1.5 * r.f64();
    }
    x[9] = 2.0 + 2.0 * r.f64();
    (x, [])
}

/// `flags`: a positive float, a bool and a small count.
pub fn flags(r: &mut Rng) -> ([f64; 1], [u32; 2]) {
    ([0.5 + 1.5 * r.f64()], [r.bool() as u32, r.u32(0..10)])
}

/// `splat_of`: a Gaussian in front of the eye, positive scales.
pub fn splat(r: &mut Rng) -> ([f64; 58], [u32; 0]) {
    let mut x: [f64; 58] = uniform(r, -1.0, 1.0);
    x[2] = 2.0 + r.f64(); // mean.z in front of the eye
    for s in &mut x[3..6] {
        *s = 0.1 + 0.9 * r.f64();
    }
    x[57] = -r.f64(); // eye.z
    (x, [])
}

/// `vector_loop`: a positive scale.
pub fn vector_loop(r: &mut Rng) -> ([f64; 4], [u32; 0]) {
    let mut x: [f64; 4] = uniform(r, -1.0, 1.0);
    x[3] = 0.5 + r.f64();
    (x, [])
}

/// `guarded`: both sides of each guard, y away from zero.
pub fn guarded(r: &mut Rng) -> ([f64; 2], [u32; 0]) {
    let y = (0.3 + 0.7 * r.f64()) * if r.bool() { 1.0 } else { -1.0 };
    ([-2.0 + 5.0 * r.f64(), y], [])
}

/// `branch_jacobian`: away from the branches' edges at 0.5.
pub fn branch_sides(r: &mut Rng) -> ([f64; 2], [u32; 0]) {
    let side = |r: &mut Rng| match r.bool() {
        true => 0.1 + 0.3 * r.f64(),
        false => 0.6 + 0.3 * r.f64(),
    };
    ([side(r), side(r)], [])
}

/// Calls `$callback! { $($args)* ENTRIES }` with every corpus function as an entry `module::f /
/// f_adjoint => sampler` (an expression of this module), each followed by `, inverse_trig` where
/// it calls inverse trigonometric functions (the GPU's Vulkan lets those be 4096 ulp off): the
/// one list both the CPU checks (`tests/corpus.rs`) and the GPU's (`tests/gpu.rs`) run.
#[macro_export]
macro_rules! with_corpus {
    ($callback:ident ! ($($args:tt)*)) => {
        $callback! {
            $($args)*
            scalars::arith / arith_adjoint => $crate::samples::plain::<2>(0.2, 1.5);
            scalars::transcendental / transcendental_adjoint => $crate::samples::plain::<2>(0.2, 2.0);
            scalars::trig / trig_adjoint => $crate::samples::plain::<2>(-0.9, 0.9), inverse_trig;
            scalars::powers / powers_adjoint => $crate::samples::plain::<2>(0.3, 2.0);
            scalars::minmax / minmax_adjoint => $crate::samples::minmax;
            scalars::rounding / rounding_adjoint => $crate::samples::plain::<1>(-3.0, 3.0);
            scalars::misc / misc_adjoint => $crate::samples::plain::<2>(0.2, 3.0);
            scalars::sincos / sincos_adjoint => $crate::samples::plain::<1>(-3.0, 3.0);
            vectors::geometry / geometry_adjoint => $crate::samples::plain::<6>(-1.0, 1.0);
            vectors::elementwise / elementwise_adjoint => $crate::samples::plain::<9>(0.2, 1.0);
            vectors::shape / shape_adjoint => $crate::samples::plain::<5>(-1.0, 1.0);
            vectors::rotate / rotate_adjoint => $crate::samples::signed::<7>(0.2, 1.0);
            vectors::components / components_adjoint => $crate::samples::plain::<3>(-1.0, 1.0);
            matrices::mat3 / mat3_adjoint => $crate::samples::plain::<12>(-1.0, 1.0);
            matrices::mat2 / mat2_adjoint => $crate::samples::mat2;
            matrices::covariance / covariance_adjoint => $crate::samples::covariance;
            control::nested / nested_adjoint => $crate::samples::plain::<2>(-2.0, 2.0);
            control::statements / statements_adjoint => $crate::samples::plain::<2>(-1.0, 1.5);
            control::vector_loop / vector_loop_adjoint => $crate::samples::vector_loop;
            control::array_loop / array_loop_adjoint => $crate::samples::plain::<5>(-1.0, 1.0);
            control::guarded / guarded_adjoint => $crate::samples::guarded;
            control::flags / flags_adjoint => $crate::samples::flags;
            structured::sh_color / sh_color_adjoint => $crate::samples::signed::<51>(0.05, 1.0);
            structured::splat_of / splat_of_adjoint => $crate::samples::splat;
            structured::uses_custom / uses_custom_adjoint => $crate::samples::plain::<2>(-1.0, 1.0);
            jacobians::every_op_jacobian / every_op_jacobian_adjoint => $crate::samples::plain::<2>(0.15, 0.85), inverse_trig;
            jacobians::scalar_jacobian / scalar_jacobian_adjoint => $crate::samples::plain::<1>(-1.5, 1.5);
            jacobians::branch_jacobian / branch_jacobian_adjoint => $crate::samples::branch_sides;
        }
    };
}
