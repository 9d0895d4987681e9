//! Error collection: every error found while compiling a module is gathered with its span, and
//! all of them are reported together. As serde_derive's `Ctxt`, a collector must be consumed
//! ([`Diag::check`] or one of its forms) or explicitly [`Diag::discard`]ed: dropping one
//! unchecked panics, so no path can lose the errors it gathered. Errors come out in source
//! order, whichever stage found them.

use proc_macro2::{Span, TokenStream};
use std::cell::RefCell;

/// Failure of a step whose error is already recorded in a [`Diag`].
pub struct Failed;
pub type R<T> = Result<T, Failed>;

pub struct Diag {
    /// `None` once consumed.
    errors: RefCell<Option<Vec<syn::Error>>>,
}

impl Default for Diag {
    fn default() -> Self {
        Diag {
            errors: RefCell::new(Some(vec![])),
        }
    }
}

impl Diag {
    /// Adds an error made elsewhere (a parse error).
    pub fn push_error(&self, e: syn::Error) {
        self.errors
            .borrow_mut()
            .as_mut()
            .expect("the collector is not consumed while in use")
            .push(e);
    }

    pub fn error(&self, span: Span, msg: impl std::fmt::Display) {
        self.push_error(syn::Error::new(span, msg));
    }

    pub fn error_at(&self, node: &impl quote::ToTokens, msg: impl std::fmt::Display) {
        self.push_error(syn::Error::new_spanned(node, msg));
    }

    /// Errors gathered so far.
    pub fn count(&self) -> usize {
        self.errors.borrow().as_ref().map_or(0, Vec::len)
    }

    pub fn has_errors(&self) -> bool {
        self.count() > 0
    }

    /// Consumes the collector: its errors, if any, in source order.
    pub fn check(self) -> Result<(), Vec<syn::Error>> {
        let mut errors = self.errors.borrow_mut().take().unwrap_or_default();
        errors.sort_by_key(|e| {
            let at = e.span().start();
            (at.line, at.column)
        });
        match errors.is_empty() {
            true => Ok(()),
            false => Err(errors),
        }
    }

    /// All errors as `compile_error!` invocations, or `None` if there were none.
    pub fn into_compile_errors(self) -> Option<TokenStream> {
        let errors = self.check().err()?;
        Some(errors.into_iter().map(|e| e.to_compile_error()).collect())
    }

    /// The messages, for tests and tools.
    pub fn into_messages(self) -> Vec<String> {
        let errors = self.check().err().unwrap_or_default();
        errors.iter().map(|e| e.to_string()).collect()
    }

    /// Drops the errors on purpose (a scratch collector whose errors were reported elsewhere).
    pub fn discard(self) {
        self.errors.borrow_mut().take();
    }
}

impl Drop for Diag {
    fn drop(&mut self) {
        if self.errors.get_mut().is_some() && !std::thread::panicking() {
            panic!("an error collector was dropped without being checked");
        }
    }
}

/// Levenshtein distance between two names.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let next = (diagonal + usize::from(ca != *cb))
                .min(row[j] + 1)
                .min(row[j + 1] + 1);
            diagonal = row[j + 1];
            row[j + 1] = next;
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::{Diag, edit_distance};
    use proc_macro2::Span;

    #[test]
    #[should_panic(expected = "dropped without being checked")]
    fn a_collector_dropped_unchecked_panics() {
        let diag = Diag::default();
        diag.error(Span::call_site(), "lost");
    }

    #[test]
    fn a_checked_collector_hands_over_every_error() {
        let diag = Diag::default();
        diag.error(Span::call_site(), "first");
        diag.error(Span::call_site(), "second");
        assert_eq!(diag.count(), 2);
        assert_eq!(diag.into_messages(), ["first", "second"]);
        Diag::default().check().unwrap();
    }

    #[test]
    fn errors_come_out_in_source_order_whichever_stage_found_them() {
        // The value error (a dynamic index, found by lowering) comes before the type error
        // (found by type checking, which runs first) because its function comes first.
        let item: syn::ItemMod = syn::parse_str(
            "mod m { fn f(a: [f32; 2], i: u32) -> f32 { a[i] } fn g(x: f32) -> f32 { x.frobnicate() } }",
        )
        .unwrap();
        let errors = crate::compile_ir(crate::Kind::Functions, item)
            .err()
            .unwrap();
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors[0].contains("known at compile time"), "{errors:?}");
        assert!(errors[1].contains("frobnicate"), "{errors:?}");
    }

    #[test]
    fn an_attribute_error_survives_an_unparsable_module() {
        let out = crate::expand(
            crate::Kind::Method,
            quote::quote!(oops),
            quote::quote!(
                fn not_a_module() {}
            ),
        )
        .to_string();
        assert!(out.contains("takes one optional argument"), "{out}");
        assert!(out.contains("expected `mod`"), "{out}");
    }

    #[test]
    fn a_method_takes_only_a_name() {
        let expand = |kind, attr: proc_macro2::TokenStream| {
            crate::expand(
                kind,
                attr,
                quote::quote!(
                    mod m {}
                ),
            )
            .to_string()
        };
        for (kind, attr, error) in [
            (
                crate::Kind::Method,
                quote::quote!(label = "x"),
                "takes one optional argument, `name = \\\"...\\\"`",
            ),
            (
                crate::Kind::Method,
                quote::quote!(name = 3),
                "takes one optional argument",
            ),
            (
                crate::Kind::Method,
                quote::quote!(name = "two words"),
                "non-empty, without spaces",
            ),
            (
                crate::Kind::Functions,
                quote::quote!(name = "x"),
                "this attribute takes no arguments",
            ),
        ] {
            let out = expand(kind, attr);
            assert!(out.contains(error), "{out}");
        }
        // A good name is no error (the module's own errors aside: it has no functions).
        let out = expand(crate::Kind::Method, quote::quote!(name = "3dgs-aa"));
        assert!(!out.contains("optional argument"), "{out}");
    }

    #[test]
    fn edit_distance_counts_insertions_deletions_and_substitutions() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("evalute", "evaluate"), 1);
        assert_eq!(edit_distance("project", "project"), 0);
        assert_eq!(edit_distance("", "abc"), 3);
        assert!(edit_distance("shade", "evaluate") > 2);
    }
}
