//! `#[splat_method]` and `#[splat_functions]`: the attributes users put on a module of plain
//! Rust single-element functions. The compiler itself lives in `splat-compiler`
//! (`splat-macros/compiler`) so it can be tested without a proc-macro; this crate is only the
//! entry point. See `splat-macros/README.md` for the accepted subset and the intrinsics.

use proc_macro::TokenStream;

/// Compiles a method module (`project`, optional `tile_cull`, optional `pixel_info`,
/// `evaluate`, plus helpers and structs) into forward, adjoint, f64-twin and SIMD-lane
/// functions and an implementation of `splat_runtime::SplatMethod` named `Method`.
#[proc_macro_attribute]
pub fn splat_method(attr: TokenStream, item: TokenStream) -> TokenStream {
    splat_compiler::expand(splat_compiler::Kind::Method, attr.into(), item.into()).into()
}

/// Compiles every function of a module into forward, adjoint, f64-twin and SIMD-lane
/// functions, without the method contract (for libraries of differentiable helpers and tests).
#[proc_macro_attribute]
pub fn splat_functions(attr: TokenStream, item: TokenStream) -> TokenStream {
    splat_compiler::expand(splat_compiler::Kind::Functions, attr.into(), item.into()).into()
}

/// `#[adjoint(f)]` on a helper: inside a `#[splat_method]` or `#[splat_functions]` module the
/// compiler reads it (and differentiates the helper with `f`); anywhere else it only marks `f`
/// as used, so a module's source also compiles as ordinary Rust.
#[proc_macro_attribute]
pub fn adjoint(attr: TokenStream, item: TokenStream) -> TokenStream {
    let used: TokenStream = format!("const _: () = {{ let _ = {attr}; }};")
        .parse()
        .expect("a path");
    let mut out = item;
    out.extend(used);
    out
}
