//! The `jacobian` intrinsic (forward mode inside a kernel) against central differences of the
//! f64 twin of the map it differentiates, through every differentiable operation. Its adjoint
//! (reverse over forward: second derivatives) is checked against differences of the Jacobian
//! by the corpus (`tests/corpus.rs`); the camera models' projection Jacobians are checked in
//! `tests/builtins.rs`.

use codegen_tests::check::{jacobian_vs_differences, uniform};
use codegen_tests::corpus::jacobians;
use splat_runtime::glam::Vec4;

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
