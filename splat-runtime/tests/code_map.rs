//! ARCHITECTURE.md's code map names every source file: a file added under a `src/` folder
//! without a line there fails here, naming it.
//!
//! The map is a tree of entries (a path at the start of a line, indented under its parent)
//! with descriptions that may run on over lines; a file is named when an entry whose path is
//! the file's, or a folder holding it, mentions the rest of its path in its description (a
//! crate's `src/` may be left out). `lib.rs`, `main.rs` and `mod.rs` stand for their folder.

mod architecture;

use std::path::{Path, PathBuf};

/// Each entry's full path (with `/` for folders) and its text, path and description together.
fn entries(map: &str) -> Vec<(String, String)> {
    let block = architecture::fenced_block(map, "Code map");
    // The parents of the current entry: (indent, full path).
    let mut parents: Vec<(usize, String)> = vec![];
    let mut out: Vec<(String, String)> = vec![];
    for line in block.lines() {
        let indent = line.len() - line.trim_start().len();
        let Some(token) = line.split_whitespace().next() else {
            continue;
        };
        // A description's continuation sits far to the right, under the first entry's text.
        let is_entry = indent < 24 && (token.ends_with('/') || token.ends_with(".rs"));
        if !is_entry {
            if let Some(last) = out.last_mut() {
                last.1.push(' ');
                last.1.push_str(line.trim());
            }
            continue;
        }
        parents.retain(|(i, _)| *i < indent);
        let base = parents.last().map_or(String::new(), |(_, p)| p.clone());
        let path = format!("{base}{token}");
        if token.ends_with('/') {
            parents.push((indent, path.clone()));
        }
        out.push((path, line.trim().to_string()));
    }
    out
}

/// Whether `file` (relative to the repository, `/`-separated) is named by one of `entries`.
fn named(file: &str, entries: &[(String, String)]) -> bool {
    let mentions = |text: &str, rest: &str| {
        text.split(|c: char| c.is_whitespace() || "(),;:".contains(c))
            .any(|word| word == rest)
    };
    entries.iter().any(|(path, text)| {
        if path == file {
            return true;
        }
        let Some(rest) = file
            .strip_prefix(path.as_str())
            .filter(|_| path.ends_with('/'))
        else {
            return false;
        };
        let short = rest.strip_prefix("src/").unwrap_or(rest);
        mentions(text, rest) || mentions(text, short)
    })
}

/// Every `.rs` file under a `src/` folder of the repository, but build output.
fn sources(root: &Path) -> Vec<String> {
    let mut out = vec![];
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path: PathBuf = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                if !name.starts_with('.') && name != "target" {
                    stack.push(path);
                }
                continue;
            }
            let rel = path
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            let in_src = rel.split('/').any(|part| part == "src");
            let folder = matches!(name.as_str(), "lib.rs" | "main.rs" | "mod.rs");
            if in_src && name.ends_with(".rs") && !folder {
                out.push(rel);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn the_code_map_names_every_source_file() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let entries = entries(&architecture::text());
    let files = sources(root);
    assert!(files.len() > 90, "{} source files found", files.len());
    let missing: Vec<&String> = files.iter().filter(|f| !named(f, &entries)).collect();
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md's code map does not name {missing:#?}"
    );
}

#[test]
fn a_file_is_named_by_its_folders_entry() {
    let map = "## Code map\n```\nsplat-runtime/   the runtime\n  src/gpu/       front.rs (the front)\n                 sums.rs\n  cli/           fit.rs\n```\n";
    let entries = entries(map);
    assert!(named("splat-runtime/src/gpu/front.rs", &entries));
    assert!(named("splat-runtime/src/gpu/sums.rs", &entries));
    assert!(named("splat-runtime/cli/src/fit.rs", &entries));
    assert!(!named("splat-runtime/src/gpu/raster.rs", &entries));
    assert!(!named("splat-runtime/cli/src/front.rs", &entries));
}
