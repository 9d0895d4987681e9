//! `{{name}} render | fit | eval | bench | tradeoff | inspect | gallery | scene | dataset`: the
//! `splat` command line with this crate's method.
//!
//! `cargo run --release -- render --out render.png`

fn main() -> std::process::ExitCode {
    splat_cli::run(&[{{crate}}::method()])
}
