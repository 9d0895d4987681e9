//! Gradients exactly at non-differentiable and singular points follow the documented rules
//! (splat-macros/README.md, "Derivative rules") and are finite, in the f64 twin, the f32
//! functions and the lane form alike.

use codegen_tests::corpus::kinks::{self, lanes, twin};
use splat_runtime::F32x8;
use splat_runtime::glam::Vec3;

use codegen_tests::check::TwinAdjointFn;

fn twin1(adj: TwinAdjointFn<1, 0, 1>, x: f64) -> f64 {
    adj(&[x], &[], &[1.0])[0]
}

fn twin2(adj: TwinAdjointFn<2, 0, 1>, x: f64, y: f64) -> [f64; 2] {
    adj(&[x, y], &[], &[1.0])
}

#[test]
fn singular_points_have_zero_gradient() {
    assert_eq!(twin1(twin::sqrt_of_adjoint, 0.0), 0.0);
    assert_eq!(twin1(twin::sqrt_of_adjoint, -1.0), 0.0);
    assert_eq!(twin1(twin::rsqrt_of_adjoint, 0.0), 0.0);
    assert_eq!(twin1(twin::ln_of_adjoint, 0.0), 0.0);
    assert_eq!(twin1(twin::recip_of_adjoint, 0.0), 0.0);
    assert_eq!(twin1(twin::asin_of_adjoint, 1.0), 0.0);
    assert_eq!(twin2(twin::atan2_of_adjoint, 0.0, 0.0), [0.0, 0.0]);
    assert_eq!(kinks::sqrt_of_adjoint(0.0, 1.0), 0.0);
    assert_eq!(kinks::length_of_adjoint(Vec3::ZERO, 1.0), Vec3::ZERO);
}

#[test]
fn normalize_of_zero_is_zero_with_zero_gradient() {
    assert_eq!(kinks::normalize_of(Vec3::ZERO), Vec3::ZERO);
    assert_eq!(
        kinks::normalize_of_adjoint(Vec3::ZERO, Vec3::ONE),
        Vec3::ZERO
    );
    let d = twin::normalize_of_adjoint(&[0.0; 3], &[], &[1.0, -2.0, 3.0]);
    assert_eq!(d, [0.0; 3]);
}

#[test]
fn ties_send_the_gradient_to_the_first_argument() {
    assert_eq!(twin2(twin::max_of_adjoint, 1.0, 1.0), [1.0, 0.0]);
    assert_eq!(twin2(twin::min_of_adjoint, 1.0, 1.0), [1.0, 0.0]);
    // clamp = min(max(x, lo), hi): at either bound x keeps the gradient, outside it has none.
    assert_eq!(twin1(twin::clamp_of_adjoint, 0.0), 1.0);
    assert_eq!(twin1(twin::clamp_of_adjoint, 1.0), 1.0);
    assert_eq!(twin1(twin::clamp_of_adjoint, 2.0), 0.0);
    // abs takes the x >= 0 side at 0.
    assert_eq!(twin1(twin::abs_of_adjoint, 0.0), 1.0);
}

#[test]
fn division_guarded_by_select_has_zero_gradient_at_zero() {
    assert_eq!(twin::lazy_div(&[1.0, 0.0], &[]).0, [0.0]);
    assert_eq!(twin2(twin::lazy_div_adjoint, 1.0, 0.0), [0.0, 0.0]);
    assert_eq!(twin2(twin::eager_div_adjoint, 1.0, 0.0), [0.0, 0.0]);
    assert_eq!(kinks::eager_div_adjoint(1.0, 0.0, 1.0), (0.0, 0.0));
}

#[test]
fn untaken_nan_and_inf_sides_do_not_leak() {
    assert_eq!(twin1(twin::nan_branch_adjoint, -1.0), 0.5);
    assert_eq!(kinks::nan_branch_adjoint(-1.0, 1.0), 0.5);
    assert_eq!(twin1(twin::inf_branch_adjoint, 100.0), 1.0);
    assert_eq!(kinks::inf_branch_adjoint(100.0, 1.0), 1.0);
}

#[test]
fn lanes_do_not_leak_nan_from_the_side_other_lanes_take() {
    // Lanes run both sides of every branch; the NaN of ln(-x) must stay in its lane's
    // discarded value.
    let x = F32x8([-1.0, 2.0, -3.0, 0.5, -0.0, 4.0, -5.0, 1.0]);
    let d = lanes::nan_branch_adjoint(&[x], &[], &[F32x8::splat(1.0)]);
    for l in 0..8 {
        let xl = x.lane(l);
        let want = if xl > 0.0 { 2.0 / xl } else { 0.5 };
        assert_eq!(d[0].lane(l), want, "lane {l}");
    }
    let y = F32x8([0.0, 1.0, 0.0, 2.0, 0.0, -1.0, 0.0, 4.0]);
    let d = lanes::lazy_div_adjoint(&[F32x8::splat(1.0), y], &[], &[F32x8::splat(1.0)]);
    for l in 0..8 {
        assert!(
            d[0].lane(l).is_finite() && d[1].lane(l).is_finite(),
            "lane {l}"
        );
    }
}
