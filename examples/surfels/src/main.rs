//! `surfels render | fit | bench | inspect | gallery | scene` for 2D Gaussian surfels: the
//! `splat` command line with this crate's method.
//!
//! `cargo run --release -- render --out surfels.png`

fn main() -> std::process::ExitCode {
    splat_cli::run(&[surfels::method()])
}
