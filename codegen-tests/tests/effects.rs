//! An effect that is off costs nothing, checked on the code rather than timed: a method
//! instance with an effect's constant false (`ROLLING_SHUTTER` in 3DGUT and 3DGEER,
//! `ANTIALIASED` in 3DGS) compiles to exactly what the same source compiles to with every
//! `if FLAG { .. }` block cut out (and every `if FLAG { .. } else { e }` replaced by `{ e }`):
//! the same generated Rust kernels, twins and lane forms, and the same WGSL, token for token.
//! So the compiler folds the branch away before anything is emitted, and no kernel of the
//! plain instance carries a trace of the effect. And the instance with the constant true does
//! differ (the check can fail).
//!
//! The methods' files are read as they are, their `macro_rules!` arm instantiated here, and both
//! versions expanded by the compiler behind `#[splat_method]`.

use proc_macro2::{Delimiter, Group, TokenStream, TokenTree};
use splat_compiler::{Kind, expand};

/// The body of `file`'s `macro_rules! name` arm that binds `bindings`, its metavariables
/// replaced by them (and `$name` by `module`).
fn instantiate(file: &str, name: &str, module: &str, bindings: &[(&str, &str)]) -> TokenStream {
    let path = format!("{}/../methods/src/{file}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let tokens: TokenStream = text.parse().expect("the file's tokens");
    let tokens: Vec<TokenTree> = tokens.into_iter().collect();
    let at = tokens
        .windows(3)
        .position(|w| {
            matches!((&w[0], &w[1], &w[2]), (TokenTree::Ident(m), TokenTree::Punct(p), TokenTree::Ident(n))
                if m == "macro_rules" && p.as_char() == '!' && n == name)
        })
        .unwrap_or_else(|| panic!("{file}: no macro_rules! {name}"));
    let TokenTree::Group(rules) = &tokens[at + 3] else {
        panic!("{file}: macro_rules! {name} has no body");
    };
    // Arms: `(pattern) => { body };`: the one whose pattern binds every name given.
    let arms: Vec<TokenTree> = rules.stream().into_iter().collect();
    let binds = |pattern: &TokenStream, var: &str| {
        let t: Vec<TokenTree> = pattern.clone().into_iter().collect();
        t.windows(2).any(|w| {
            matches!((&w[0], &w[1]), (TokenTree::Punct(p), TokenTree::Ident(v)) if p.as_char() == '$' && v == var)
        })
    };
    let body = (0..arms.len().saturating_sub(3))
        .find_map(|k| match (&arms[k], &arms[k + 3]) {
            (TokenTree::Group(pattern), TokenTree::Group(body))
                if pattern.delimiter() == Delimiter::Parenthesis
                    && bindings
                        .iter()
                        .all(|(var, _)| binds(&pattern.stream(), var)) =>
            {
                Some(body.stream())
            }
            _ => None,
        })
        .unwrap_or_else(|| panic!("{file}: no arm of {name} binds {bindings:?}"));
    let mut all = vec![("name", module)];
    all.extend_from_slice(bindings);
    substitute(body, &all)
}

/// `tokens` with each `$var` replaced by its binding.
fn substitute(tokens: TokenStream, bindings: &[(&str, &str)]) -> TokenStream {
    let mut out = vec![];
    let mut it = tokens.into_iter().peekable();
    while let Some(t) = it.next() {
        match t {
            TokenTree::Punct(p) if p.as_char() == '$' => {
                let Some(TokenTree::Ident(var)) = it.next() else {
                    panic!("`$` without a metavariable");
                };
                let value = bindings
                    .iter()
                    .find(|(v, _)| var == v)
                    .unwrap_or_else(|| panic!("no binding for ${var}"))
                    .1;
                out.extend(value.parse::<TokenStream>().unwrap());
            }
            TokenTree::Group(g) => {
                let mut inner = Group::new(g.delimiter(), substitute(g.stream(), bindings));
                inner.set_span(g.span());
                out.push(TokenTree::Group(inner));
            }
            other => out.push(other),
        }
    }
    out.into_iter().collect()
}

/// The `#[splat_macros::splat_method] pub mod ..` in `items`, without its attribute.
fn method_module(items: TokenStream) -> TokenStream {
    let tokens: Vec<TokenTree> = items.into_iter().collect();
    let at = tokens
        .iter()
        .position(|t| matches!(t, TokenTree::Group(g) if g.delimiter() == Delimiter::Bracket && g.to_string().contains("splat_method")))
        .expect("a #[splat_method] module");
    let end = (at..tokens.len())
        .find(|&i| matches!(&tokens[i], TokenTree::Group(g) if g.delimiter() == Delimiter::Brace))
        .expect("the module's body");
    tokens[at + 1..=end].iter().cloned().collect()
}

/// `tokens` with every `if flag { .. }` removed and every `if flag { .. } else { e }` made the
/// block `{ e }`; how many were cut.
fn cut(tokens: TokenStream, flag: &str, count: &mut usize) -> TokenStream {
    let tokens: Vec<TokenTree> = tokens.into_iter().collect();
    let mut out = vec![];
    let mut i = 0;
    while i < tokens.len() {
        let is =
            |k: usize, word: &str| matches!(tokens.get(k), Some(TokenTree::Ident(w)) if w == word);
        if is(i, "if") && is(i + 1, flag) {
            *count += 1;
            assert!(
                matches!(tokens.get(i + 2), Some(TokenTree::Group(g)) if g.delimiter() == Delimiter::Brace)
            );
            i += 3;
            if is(i, "else") {
                let Some(TokenTree::Group(otherwise)) = tokens.get(i + 1) else {
                    panic!("`else if` after `if {flag}`: cut it by hand");
                };
                let inner = cut(otherwise.stream(), flag, count);
                out.push(TokenTree::Group(Group::new(Delimiter::Brace, inner)));
                i += 2;
            }
            continue;
        }
        match &tokens[i] {
            TokenTree::Group(g) => {
                let mut inner = Group::new(g.delimiter(), cut(g.stream(), flag, count));
                inner.set_span(g.span());
                out.push(TokenTree::Group(inner));
            }
            other => out.push(other.clone()),
        }
        i += 1;
    }
    out.into_iter().collect()
}

/// What the compiler emits for `module`, as text (spans do not print).
fn compiled(module: TokenStream) -> String {
    let out = expand(Kind::Method, TokenStream::new(), module).to_string();
    assert!(!out.contains("compile_error"), "{out}");
    out
}

/// The emitted code with the effect's constant declaration (the one line that must differ)
/// taken out, and the generated source strings kept (they hold the WGSL).
fn without_flag_declaration(code: &str, flag: &str, value: &str) -> String {
    let declaration = format!("pub const {flag} : bool = {value} ;");
    assert!(
        code.contains(&declaration),
        "{flag} is not declared in the output"
    );
    code.replace(&declaration, "")
        .replace(&format!("{flag}: bool = {value};"), "")
}

fn off_costs_nothing(file: &str, rules: &str, flag: &str, bindings: &[(&str, &str)]) {
    let instance = |value: &str| {
        let mut all = bindings.to_vec();
        let var = match flag {
            "ROLLING_SHUTTER" => "rs",
            _ => "aa",
        };
        all.push((var, value));
        method_module(instantiate(file, rules, "plain", &all))
    };
    let off = instance("false");
    let mut cuts = 0;
    let stripped = cut(off.clone(), flag, &mut cuts);
    assert!(cuts > 0, "{file}: no `if {flag}` to cut");
    let (with_branches, without) = (compiled(off), compiled(stripped));
    let (a, b) = (
        without_flag_declaration(&with_branches, flag, "false"),
        without_flag_declaration(&without, flag, "false"),
    );
    if a != b {
        let at = a
            .bytes()
            .zip(b.bytes())
            .position(|(x, y)| x != y)
            .unwrap_or(0);
        let from = at.saturating_sub(300);
        panic!(
            "{file}: with {flag} false, the emitted code differs from the build without its {cuts} branches at byte {at}:\n--- with the branches:\n{}\n--- without:\n{}",
            &a[from..(at + 300).min(a.len())],
            &b[from..(at + 300).min(b.len())]
        );
    }
    println!(
        "{file}: {flag} false compiles to the build without its {cuts} branches ({} bytes emitted)",
        a.len()
    );
    // The effect on is code: the same cut changes what is emitted.
    let on = compiled(instance("true"));
    assert_ne!(
        without_flag_declaration(&on, flag, "true"),
        a,
        "{file}: {flag} true emits nothing more"
    );
}

#[test]
fn a_global_shutter_costs_3dgut_nothing() {
    off_costs_nothing("gut.rs", "unscented", "ROLLING_SHUTTER", &[("n", "16")]);
}

#[test]
fn a_global_shutter_costs_3dgeer_nothing() {
    off_costs_nothing("geer.rs", "exact", "ROLLING_SHUTTER", &[("n", "16")]);
}

#[test]
fn no_antialiasing_costs_3dgs_nothing() {
    off_costs_nothing(
        "gs3d.rs",
        "gaussians_3d",
        "ANTIALIASED",
        &[("n", "16"), ("called", "\"3dgs\"")],
    );
}
