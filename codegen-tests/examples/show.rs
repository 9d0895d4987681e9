fn main() { print!("{}", codegen_tests::corpus::basic::GENERATED_RUST); }
