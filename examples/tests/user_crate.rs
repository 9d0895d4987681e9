//! `examples/surfels` stands outside this workspace, as a user's crate does (its own
//! `[workspace]`, splat by path): it must build and pass its own tests, which run the checks,
//! the GPU backend and the command line on its method. It is built with the workspace's
//! lockfile and target directory, so it reuses the compiled dependencies.

use std::path::Path;
use std::process::Command;

#[test]
fn the_surfels_crate_builds_and_passes_its_tests() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let user_crate = root.join("examples/surfels");
    // The same dependency versions as the workspace (the copy is git-ignored there).
    std::fs::copy(root.join("Cargo.lock"), user_crate.join("Cargo.lock")).unwrap();
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).parent().unwrap();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let run = Command::new(cargo)
        .args(["test", "--offline", "--manifest-path"])
        .arg(user_crate.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", target)
        .output()
        .unwrap();
    let report = format!(
        "{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "{report}");
    assert!(report.contains("test result: ok. 8 passed"), "{report}");
}
