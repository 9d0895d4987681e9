//! The `jacobian` intrinsic (forward mode inside a kernel) against central differences of the
//! f64 twin of the map it differentiates, through every differentiable operation. Its adjoint
//! (reverse over forward: second derivatives) is checked against differences of the Jacobian
//! by the corpus (`tests/corpus.rs`); the camera models' projection Jacobians are checked in
//! `tests/builtins.rs`.

use codegen_tests::check::{jacobian_vs_differences, uniform};
use codegen_tests::corpus::jacobians;
use splat_macros::splat_functions;
use splat_runtime::glam::{Vec2, Vec4};

#[splat_functions]
mod constant_helpers {
    use splat_runtime::prelude::*;

    #[adjoint(soft_adjoint)]
    fn soft(x: f32) -> f32 {
        (x * x + 0.01).sqrt()
    }

    fn soft_adjoint(x: f32, d_out: f32) -> f32 {
        d_out * x / (x * x + 0.01).sqrt()
    }

    /// A helper with a hand-written adjoint, on a value the point does not reach.
    pub fn scaled_by_a_helper(x: f32, c: f32) -> Vec2 {
        let (v, j) = jacobian(|p| p * p * soft(c), x);
        Vec2::new(v, j[0])
    }

    /// A float cast to `f32`: the value itself, in forward mode ...
    pub fn cast_to_itself(x: f32) -> Vec2 {
        let (v, j) = jacobian(|p| (p * p) as f32, x);
        Vec2::new(v, j[0])
    }

    /// ... and in reverse mode.
    pub fn squared_then_cast(x: f32) -> f32 {
        (x * x) as f32
    }
}

const TOL: f64 = 1e-6;

/// `every_op` as a function of two scalars, the form `jacobian_vs_differences` differences.
fn every_op(x: &[f64; 2], ints: &[u32; 0]) -> ([f64; 4], [u32; 0]) {
    jacobians::twin::every_op(x, ints)
}

#[test]
fn the_jacobian_of_every_operation_matches_differences() {
    let sample = |r: &mut fastrand::Rng| (uniform(r, 0.15, 0.85), []);
    let err = jacobian_vs_differences(
        every_op,
        jacobians::twin::every_op_jacobian,
        0..2,
        sample,
        11,
        40,
    );
    println!("every_op: Jacobian {err:.2e} off differences");
    assert!(err <= TOL, "{err}");
}

/// A branch with constant sides has a zero Jacobian; the other side's is the bend's.
#[test]
fn branches_without_tangents_keep_their_place() {
    for (x, y) in [(0.2f32, 0.3f32), (0.7, 0.3), (0.2, 0.8), (0.7, 0.8)] {
        let step = if x > 0.5 { 1.0 } else { -1.0 };
        let (bend, d_bend) = match y > 0.5 {
            true => (x * y, (y, x)),
            false => (y - x, (-1.0, 1.0)),
        };
        let want = Vec4::new(step + bend * step, 0.0, d_bend.0 * step, d_bend.1 * step);
        let got = jacobians::branch_jacobian(x, y);
        assert!((got - want).length() <= 1e-6, "({x}, {y}): {got} vs {want}");
    }
}

#[test]
fn the_value_comes_with_its_jacobian() {
    for t in [-1.2f32, 0.0, 0.4, 1.3] {
        let got = jacobians::scalar_jacobian(t);
        let want = Vec4::new(t * t, t.sin() + t * t.exp(), 2.0 * t, t.cos() + t * t.exp());
        assert!(
            (got - want).length() <= 1e-5 * want.length(),
            "{got} vs {want}"
        );
    }
}

/// A helper with a hand-written adjoint has no tangent rule, but needs none on values the
/// point does not reach: the call stays a constant of the differentiation.
#[test]
fn a_helper_with_its_own_adjoint_is_a_constant_where_the_point_does_not_reach_it() {
    for (x, c) in [(0.3f32, -0.5f32), (1.7, 0.0), (-2.0, 3.0)] {
        let soft = (c * c + 0.01).sqrt();
        let want = Vec2::new(x * x * soft, 2.0 * x * soft);
        let got = constant_helpers::scaled_by_a_helper(x, c);
        assert!(
            (got - want).length() <= 1e-6 * want.length().max(1.0),
            "{got} vs {want}"
        );
    }
}

/// `x as f32` of a float is `x`: its derivative passes through (it was a cast's, zero).
#[test]
fn a_cast_of_a_float_to_f32_keeps_its_derivative() {
    for x in [-1.5f32, 0.25, 3.0] {
        let want = Vec2::new(x * x, 2.0 * x);
        assert_eq!(constant_helpers::cast_to_itself(x), want);
        assert_eq!(constant_helpers::squared_then_cast_adjoint(x, 1.0), 2.0 * x);
    }
}
