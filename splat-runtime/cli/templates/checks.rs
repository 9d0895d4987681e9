//! Every check splat holds its own methods to, in one call (the render against an f64
//! reference, boxes and tile cull, gradients against finite differences and the reference's
//! adjoint, extreme parameters, the GPU against the CPU), and a short training run.

use {{crate}}::{{module}}::Method;

#[test]
fn passes_every_check() {
    splat_runtime::checks::check_method::<Method>("{{name}}");
}

#[test]
fn trains_on_the_built_in_dataset() {
    let dir = std::env::temp_dir().join(format!("{{name}}-fit-{}", std::process::id()));
    let out = dir.to_str().expect("a UTF-8 temporary folder");
    let args = ["{{name}}", "fit", "--backend", "cpu", "--steps", "200", "--eval-every", "0"];
    let run = splat_cli::run_with_args(&[{{crate}}::method()], args.iter().chain(&["--out", out]));
    let metrics = run.and_then(|()| Ok(std::fs::read_to_string(dir.join("metrics.csv"))?));
    std::fs::remove_dir_all(&dir).ok();
    let metrics = metrics.unwrap();
    // Test PSNR before and after training (the sixth column).
    let psnr: Vec<f64> = (metrics.lines().skip(1))
        .filter_map(|l| l.split(',').nth(5)?.parse().ok())
        .collect();
    assert!(psnr.len() == 2 && psnr[1] > psnr[0] + 5.0, "{metrics}");
}
