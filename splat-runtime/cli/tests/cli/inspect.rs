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

/// `--cost` counts each kernel's expensive operations: 3DGS's `evaluate` runs one `exp` per
/// pair and no `pow`; its generic `project` calls trigonometry (the fisheye and equiangular
/// models), the pinhole's own none.
#[test]
fn inspect_cost_counts_each_kernels_operations() {
    let dir = temp();
    let table = ok(&splat(
        &["inspect", "--method", "3dgs", "--cost"],
        dir.path(),
    ));
    let row = |kernel: &str| -> Vec<String> {
        let line = table
            .lines()
            .find(|l| l.starts_with(&format!("| {kernel} |")));
        let line = line.unwrap_or_else(|| panic!("no {kernel} in\n{table}"));
        line.split('|').map(|c| c.trim().to_string()).collect()
    };
    // | kernel | runs per | exp | ln | pow | trig | sqrt | div | all ops |
    let evaluate = row("evaluate");
    assert_eq!(&evaluate[2..6], ["pair", "1", "0", "0"], "{table}");
    assert_ne!(row("project")[6], "0", "{table}");
    assert_eq!(row("project_pinhole")[6], "0", "{table}");
}

/// A user crate's binary names itself in its help texts, not `splat`.
#[test]
fn a_binary_of_another_name_says_its_own_in_help() {
    let dir = temp();
    let own = std::path::Path::new(env!("CARGO_BIN_EXE_splat"));
    let renamed = dir.path().join("my-splat");
    std::fs::copy(own, &renamed).unwrap();
    let out = std::process::Command::new(&renamed)
        .args(["dataset", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains("`my-splat fit`"), "{help}");
    assert!(!help.contains("`splat "), "{help}");
}
