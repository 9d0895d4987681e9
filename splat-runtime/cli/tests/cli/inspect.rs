//! `splat inspect`: the generated Rust and WGSL.

use crate::common::*;

#[test]
fn inspect_prints_the_generated_rust_and_wgsl() {
    let dir = temp();
    let rust = ok(&splat(&["inspect", "--method", "3dgs"], dir.path()));
    assert!(
        rust.contains("pub fn evaluate_adjoint")
            && rust.contains("impl ::splat_runtime::SplatMethod for Method")
    );
    let wgsl = ok(&splat(
        &["inspect", "--method", "3dgs", "--lang", "wgsl"],
        dir.path(),
    ));
    assert!(wgsl.contains("fn evaluate(") && wgsl.contains("fn project_adjoint("));
    let geer = ok(&splat(&["inspect", "--method", "3dgeer"], dir.path()));
    assert!(geer.contains("pub fn pixel_info("));
}
