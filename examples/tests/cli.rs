//! The `splat` command line offered from a user crate (as `examples/ges_cli.rs` does): its
//! method renders, benches and prints its generated code through the same commands, and what
//! it cannot do is refused by name.

use splat_cli::{Instance, Method, run_with_args};
use splat_examples::generalized::generalized;

fn offered() -> [Method; 1] {
    [Method::new(
        "ges",
        "generalized exponential splats",
        Instance::of::<generalized::Method>(),
    )]
}

#[test]
fn a_user_method_gets_the_commands() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ges.png");
    let out = out.to_str().unwrap();
    let size = ["--width", "48", "--height", "32"];
    let run = |args: &[&str]| run_with_args(&offered(), ["splat"].iter().chain(args));
    run(&[&["render", "--backend", "cpu", "--out", out][..], &size].concat()).unwrap();
    assert!(std::fs::metadata(out).unwrap().len() > 0);
    run(&[&["bench", "--backend", "cpu", "--iters", "1"][..], &size].concat()).unwrap();
    run(&["inspect", "--method", "ges", "--lang", "wgsl"]).unwrap();

    let err = run(&["render", "--method", "3dgs"])
        .unwrap_err()
        .to_string();
    assert!(err.contains("[possible values: ges]"), "{err}");
    let err = run(&["fit", "nowhere"]).unwrap_err().to_string();
    assert!(err.contains("ges cannot be trained"), "{err}");
}
