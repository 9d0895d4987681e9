//! Student's t splats (a new falloff on splat's building blocks) through every public check in
//! one call: renders against the f64 reference, boxes and tile cull, gradients against finite
//! differences and the reference's adjoint, the extremes, the GPU against the CPU.

use splat_examples::student::student::Method;
use splat_runtime::checks::{check_method_with, suite};

#[test]
fn student_splats_pass_every_check() {
    // 1,000 on one pixel instead of 10,000: the heavy tails stack into a wide ring of pixels
    // whose transmittance ends near the T-stop, which the reference cannot call either way
    // (10,000: 15 of 384 pixels, past the 2% a check accepts).
    let suite = suite::Suite {
        stack: 1000,
        ..suite::gaussian_suite::<Method>()
    };
    check_method_with::<Method>("student", &suite);
}
