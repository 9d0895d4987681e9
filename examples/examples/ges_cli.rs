//! A user crate's command line: every `splat` command (render, bench, tradeoff, inspect,
//! gallery, scene) for its own method, here GES.
//!
//! `cargo run --release -p splat-examples --example ges_cli -- render --out ges.png`

use splat_cli::{Instance, Method};
use splat_examples::generalized::generalized;

fn main() -> std::process::ExitCode {
    splat_cli::run(&[Method::new(
        "ges",
        "generalized exponential splats (a learnable falloff shape)",
        Instance::of::<generalized::Method>(),
    )])
}
