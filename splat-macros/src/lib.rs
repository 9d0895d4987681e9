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
