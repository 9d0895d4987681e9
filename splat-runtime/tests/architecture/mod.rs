//! ARCHITECTURE.md as the tests that hold the code to it read it.

/// ARCHITECTURE.md's text.
pub fn text() -> String {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap();
    std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap()
}

/// The fenced block under the heading `## {heading}` of `doc`, from the end of its opening
/// fence's line.
pub fn fenced_block<'a>(doc: &'a str, heading: &str) -> &'a str {
    doc.split(&format!("## {heading}"))
        .nth(1)
        .and_then(|rest| rest.split("```").nth(1))
        .unwrap_or_else(|| panic!("ARCHITECTURE.md has a fenced block under `## {heading}`"))
}
