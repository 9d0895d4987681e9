//! Each construct outside the supported subset is a compile error on its span, with a message
//! that says what to write instead (`tests/ui/*.rs` with their expected `.stderr`).

#[test]
fn rejected_constructs_have_clear_diagnostics() {
    trybuild::TestCases::new().compile_fail("tests/ui/*.rs");
}
