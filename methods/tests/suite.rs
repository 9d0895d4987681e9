//! The public suite (`checks::check_method`) on the built-in methods whose parameters are a
//! PLY's Gaussian: what a method author's one call runs, held to the methods it is made from.

use splat_runtime::checks::check_method;

#[test]
fn three_dgs_passes_the_suite() {
    check_method::<splat_methods::gs3d_sh1::Method>("3dgs, degree 1");
}
