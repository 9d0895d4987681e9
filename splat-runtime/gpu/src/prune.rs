//! Drops the functions no entry point reaches from a WGSL source before it is compiled. A
//! method's generated module holds every kernel with its adjoint and camera-model variants
//! (1.3 MB of WGSL for 3DGUT with a rolling shutter) and a pipeline calls one or two of them;
//! the shader compilers (naga's validator, the driver's) would otherwise translate all of them
//! for every pipeline.

use std::collections::HashSet;
use std::ops::Range;

/// A top-level function: its name, its text from `fn` to its closing brace, and whether an
/// entry-point attribute (`@compute`, `@vertex`, `@fragment`) marks it.
struct Function {
    name: String,
    span: Range<usize>,
    entry: bool,
}

/// `source` without the functions that no entry point calls, directly or through others.
/// Everything else (types, bindings, constants, comments) stays. A source it cannot split
/// into functions (unbalanced braces) comes back whole.
pub fn reachable_only(source: &str) -> String {
    let Some(functions) = top_level_functions(source) else {
        return source.to_string();
    };
    let names: HashSet<&str> = functions.iter().map(|f| f.name.as_str()).collect();
    let mut keep: HashSet<&str> = functions
        .iter()
        .filter(|f| f.entry)
        .map(|f| f.name.as_str())
        .collect();
    let mut todo: Vec<&Function> = functions.iter().filter(|f| f.entry).collect();
    while let Some(f) = todo.pop() {
        let body = &source[f.span.clone()];
        for word in identifiers(body) {
            if names.contains(word) && keep.insert(word) {
                todo.extend(functions.iter().filter(|g| g.name == word));
            }
        }
    }
    let mut out = String::with_capacity(source.len());
    let mut at = 0;
    for f in functions.iter().filter(|f| !keep.contains(f.name.as_str())) {
        out.push_str(&source[at..f.span.start]);
        at = f.span.end;
    }
    out.push_str(&source[at..]);
    out
}

/// The top-level functions in source order; `None` if the braces do not balance.
fn top_level_functions(source: &str) -> Option<Vec<Function>> {
    let bytes = source.as_bytes();
    let mut out = vec![];
    let (mut depth, mut i) = (0usize, 0usize);
    // Where the text before the next top-level item starts (after a `}` or `;` at depth 0).
    let mut item_start = 0;
    let mut open: Option<(String, usize, bool)> = None;
    while i < bytes.len() {
        match bytes[i] {
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                i = source[i..].find('\n').map_or(bytes.len(), |n| i + n);
                continue;
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                i = source[i + 2..].find("*/").map(|n| i + 2 + n + 2)?;
                continue;
            }
            b'{' => depth += 1,
            b'}' => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    if let Some((name, start, entry)) = open.take() {
                        out.push(Function {
                            name,
                            span: start..i + 1,
                            entry,
                        });
                    }
                    item_start = i + 1;
                }
            }
            b';' if depth == 0 => item_start = i + 1,
            b'f' if depth == 0 && open.is_none() && starts_word(source, i, "fn") => {
                let name = identifiers(&source[i + 2..]).next()?.to_string();
                let before = &source[item_start..i];
                let entry = ["@compute", "@vertex", "@fragment"]
                    .iter()
                    .any(|a| before.contains(a));
                open = Some((name, i, entry));
            }
            _ => {}
        }
        i += 1;
    }
    (depth == 0 && open.is_none()).then_some(out)
}

/// Whether the word `word` starts at byte `i` of `s` (not inside a longer identifier).
fn starts_word(s: &str, i: usize, word: &str) -> bool {
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let b = s.as_bytes();
    s[i..].starts_with(word)
        && (i == 0 || !ident(b[i - 1]))
        && b.get(i + word.len()).is_none_or(|c| !ident(*c))
}

/// The identifiers of `text`, in order.
fn identifiers(text: &str) -> impl Iterator<Item = &str> {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .filter(|w| w.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_'))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE: &str = "struct out_t { a: f32, }
// fn commented() { }
fn leaf(x: f32) -> f32 { /* } */ return x * 2.0; }
fn helper(x: f32) -> out_t {
    if (x > 0.0) { return out_t(leaf(x)); }
    return out_t(0.0);
}
fn unused_variant(x: f32) -> f32 { return leaf(x); }
@group(0) @binding(0) var<storage, read_write> data: array<f32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    data[id.x] = helper(data[id.x]).a;
}
@compute @workgroup_size(64)
fn other(@builtin(global_invocation_id) id: vec3<u32>) { data[id.x] = 1.0; }
";

    #[test]
    fn keeps_what_the_entry_points_reach() {
        let pruned = reachable_only(SOURCE);
        for kept in [
            "struct out_t",
            "fn leaf",
            "fn helper",
            "fn main",
            "fn other",
            "var<storage",
        ] {
            assert!(pruned.contains(kept), "`{kept}` was dropped:\n{pruned}");
        }
        assert!(!pruned.contains("fn unused_variant"), "{pruned}");
        assert!(pruned.contains("// fn commented() { }"));
    }

    #[test]
    fn unbalanced_sources_come_back_whole() {
        let broken = "fn a() { fn b() {";
        assert_eq!(reachable_only(broken), broken);
    }
}
