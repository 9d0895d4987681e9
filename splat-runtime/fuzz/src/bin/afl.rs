//! The AFL++ harness: `cargo afl fuzz -i splat-runtime/fuzz/corpus/TARGET -o OUT
//! target/debug/splat-fuzz-afl TARGET`, TARGET one of `splat_fuzz::Target::ALL`'s names.

use splat_fuzz::{Scratch, Target};

fn main() {
    let name = std::env::args().nth(1).unwrap_or_default();
    let Some(target) = Target::from_name(&name) else {
        let names: Vec<&str> = Target::ALL.iter().map(|t| t.name()).collect();
        eprintln!(
            "usage: splat-fuzz-afl TARGET, TARGET one of {}",
            names.join(", ")
        );
        std::process::exit(2);
    };
    let scratch = Scratch::new().expect("a scratch folder in the temporary directory");
    afl::fuzz!(|data: &[u8]| {
        target.run(&scratch, data);
    });
}
