//! Crates outside this workspace, as a user's are (their own `[workspace]`, splat by path):
//! `examples/surfels`, and one made by `splat new` with a new falloff. Each must build and pass
//! its own tests, which run the checks, the GPU backend and the command line on its method.
//! They are built with the workspace's lockfile and target directory, so they reuse the
//! compiled dependencies.

use std::path::Path;
use std::process::Command;

#[test]
fn the_surfels_crate_builds_and_passes_its_tests() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let user_crate = root.join("examples/surfels");
    // The same dependency versions as the workspace (the copy is git-ignored there).
    std::fs::copy(root.join("Cargo.lock"), user_crate.join("Cargo.lock")).unwrap();
    let report = cargo_test(&user_crate);
    assert!(report.contains("test result: ok. 8 passed"), "{report}");
}

/// `splat new`, then a Student's t falloff in place of the Gaussian (its two lines): the crate
/// passes every check and trains.
#[test]
fn a_crate_made_by_splat_new_passes_its_checks_with_a_new_falloff() {
    let dir = tempfile::tempdir().unwrap();
    let made = dir.path().join("student-splats");
    let args = [
        "splat",
        "new",
        "student-splats",
        "--dir",
        made.to_str().unwrap(),
    ];
    let offered = [splat_cli::Method::new(
        "ges",
        "any method: `new` runs none",
        splat_cli::Instance::of::<splat_examples::generalized::generalized::Method>(),
    )];
    splat_cli::run_with_args(&offered, args).unwrap();
    let lib = made.join("src/lib.rs");
    let gaussian = std::fs::read_to_string(&lib).unwrap();
    let student = gaussian
        .replace("(-0.5 * q).exp()", "(1.0 + q / 3.0).powf(-2.5)")
        .replace(
            "1.001 * 2.0 * (opacity / ALPHA_MIN).ln().max(0.0)",
            "1.001 * 3.0 * ((opacity / ALPHA_MIN).max(1.0).powf(0.4) - 1.0)",
        );
    assert_eq!(student.lines().count(), gaussian.lines().count());
    assert_ne!(
        student, gaussian,
        "the template's falloff moved: update this test"
    );
    std::fs::write(&lib, student).unwrap();
    let report = cargo_test(&made);
    assert!(report.contains("test result: ok. 2 passed"), "{report}");
    // The falloff as first written costs what `rsqrt(r) / (r * r)` does: its kernel calls no
    // `pow` (`inspect --cost` of the crate's own binary, which `cargo test` built).
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).parent().unwrap();
    let cost = Command::new(target.join("debug/student-splats"))
        .args(["inspect", "--method", "student-splats", "--cost"])
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&cost.stdout);
    let evaluate = table.lines().find(|l| l.starts_with("| evaluate |"));
    // | kernel | runs per | exp | ln | pow | trig | sqrt | ...
    let cells: Vec<&str> = evaluate
        .expect("an evaluate row")
        .split('|')
        .map(str::trim)
        .collect();
    assert_eq!((cells[5], cells[7]), ("0", "1"), "{table}");
}

/// `cargo test` of the crate at `dir` with the workspace's target directory; its output.
fn cargo_test(dir: &Path) -> String {
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).parent().unwrap();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let run = Command::new(cargo)
        .args(["test", "--offline", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", target)
        .output()
        .unwrap();
    let report = format!(
        "{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "{report}");
    report
}
