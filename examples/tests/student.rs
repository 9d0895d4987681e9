//! Student's t splats (a new falloff on splat's building blocks) through every public check in
//! one call: renders against the f64 reference, boxes and tile cull, gradients against finite
//! differences and the reference's adjoint, the extremes, the GPU against the CPU; and trained
//! by its one `like_3dgs!` line.

use splat_examples::student::student::Method;

#[test]
fn student_splats_pass_every_check() {
    splat_runtime::checks::check_method::<Method>("student");
}

/// Trained by its one `like_3dgs!` line: `splat fit` on the built-in dataset (300 steps on the
/// CPU) gains on the held-out views and writes the scene as a PLY.
#[test]
fn student_splats_train_through_the_command_line() {
    use splat_cli::{Instance, Method as Offered, run_with_args};
    let offered = [Offered::new(
        "student",
        "Student's t splats",
        Instance::trainable::<Method>(),
    )];
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit");
    let args = [
        "splat",
        "fit",
        "--backend",
        "cpu",
        "--steps",
        "300",
        "--eval-every",
        "0",
    ];
    let out_args = ["--out", out.to_str().unwrap()];
    run_with_args(&offered, args.iter().chain(&out_args)).unwrap();
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let psnr: Vec<f64> = (metrics.lines().skip(1))
        .filter_map(|l| l.split(',').nth(5)?.parse().ok())
        .collect();
    println!("test PSNR {psnr:?}");
    assert!(psnr.len() == 2 && psnr[1] > psnr[0] + 8.0, "{metrics}");
    let scene = splat_runtime::io::ply::read(&out.join("scene.ply")).unwrap();
    assert!(!scene.gaussians.is_empty());
}

/// The falloff as first written, `(1 + q / ν)^(-(ν + 2) / 2)` with ν a constant, costs what the
/// hand-written `rsqrt(r) / (r * r)` does: the compiler knows the exponent (-2.5) and computes
/// no `pow` (`codegen-tests/benches/powers.rs` times the forms).
#[test]
fn the_naive_falloff_calls_no_pow() {
    let wgsl = splat_examples::student::student::GENERATED_WGSL;
    let evaluate = wgsl.split("fn ").find(|f| f.starts_with("evaluate("));
    let evaluate = evaluate.expect("an evaluate kernel");
    assert!(!evaluate.contains("pow("), "{evaluate}");
    assert!(evaluate.contains("sqrt("), "{evaluate}");
}
