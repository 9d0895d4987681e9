//! splat's building blocks (`library.rs`): functions and structs in the accepted subset that
//! every module calls as `blocks::name(..)`, parsed from that file's text into each module
//! like its own code, under internal names (`__blocks_name`) no user item can take.

use crate::types::Ty;
use quote::format_ident;
use syn::visit_mut::VisitMut;

/// The library's text (a file of the accepted subset, not a module of this crate).
pub const SOURCE: &str = include_str!("library.rs");

/// What user code writes before a block's name: `blocks::gaussian_footprint(..)`.
pub const PATH: &str = "blocks";

const PREFIX: &str = "__blocks_";

/// The internal name of the block `name`.
pub fn internal(name: &str) -> String {
    format!("{PREFIX}{name}")
}

/// How messages name a type or function of the library (`blocks::Footprint`), or `None` when
/// `internal` is not one of its names.
pub fn display(internal: &str) -> Option<String> {
    internal
        .strip_prefix(PREFIX)
        .map(|name| format!("{PATH}::{name}"))
}

/// The building block struct `t` holds (itself, an element, a field), for a message: such a
/// type lives only inside kernels, never in a method's data.
pub fn struct_in(t: &Ty) -> Option<&str> {
    match t {
        Ty::Struct(s)
            if s.display.starts_with(PATH) && s.display[PATH.len()..].starts_with("::") =>
        {
            Some(&s.display)
        }
        Ty::Struct(s) => s.fields.iter().find_map(|(_, f)| struct_in(f)),
        Ty::Array(e, _) => struct_in(e),
        Ty::Tuple(ts) => ts.iter().find_map(struct_in),
        _ => None,
    }
}

/// The library's structs and functions, each renamed to its internal name, and so every use
/// of one inside another.
pub fn items() -> (Vec<syn::ItemStruct>, Vec<syn::ItemFn>) {
    let mut file: syn::File = syn::parse_str(SOURCE).expect("the building blocks parse");
    let names = names_in(&file);
    Rename(&names).visit_file_mut(&mut file);
    let (mut structs, mut fns) = (vec![], vec![]);
    for item in file.items {
        match item {
            syn::Item::Struct(s) => structs.push(s),
            syn::Item::Fn(f) => fns.push(f),
            _ => panic!("the building blocks are structs and functions"),
        }
    }
    (structs, fns)
}

/// The library's functions, as `name(parameters) -> result`, for messages and docs.
pub fn signatures() -> Vec<String> {
    let file: syn::File = syn::parse_str(SOURCE).expect("the building blocks parse");
    let structs: Vec<String> = (file.items.iter())
        .filter_map(|item| match item {
            syn::Item::Struct(s) => Some(s.ident.to_string()),
            _ => None,
        })
        .collect();
    let mut out = vec![];
    for item in &file.items {
        if let syn::Item::Fn(f) = item {
            let mut sig = f.sig.clone();
            for s in &structs {
                let path: syn::Path = syn::parse_str(&format!("{PATH}::{s}")).expect("a path");
                ReplaceType(s, &path).visit_signature_mut(&mut sig);
            }
            out.push(signature(&sig));
        }
    }
    out
}

fn signature(sig: &syn::Signature) -> String {
    let params: Vec<String> = sig.inputs.iter().map(tokens).collect();
    let ret = match &sig.output {
        syn::ReturnType::Default => String::new(),
        syn::ReturnType::Type(_, t) => format!(" -> {}", tokens(t)),
    };
    format!("{}({}){ret}", sig.ident, params.join(", "))
}

/// Tokens as Rust is written (`&Camera`, not `& Camera`).
fn tokens(t: &impl quote::ToTokens) -> String {
    let text = t.to_token_stream().to_string();
    text.replace("& ", "&")
        .replace(" :: ", "::")
        .replace(" :", ":")
        .replace(" ,", ",")
}

/// The names of the library's structs and functions.
fn names_in(file: &syn::File) -> Vec<String> {
    file.items
        .iter()
        .filter_map(|item| match item {
            syn::Item::Struct(s) => Some(s.ident.to_string()),
            syn::Item::Fn(f) => Some(f.sig.ident.to_string()),
            _ => None,
        })
        .collect()
}

/// Writes the type `name` as `path` (`blocks::Footprint`).
struct ReplaceType<'a>(&'a str, &'a syn::Path);

impl VisitMut for ReplaceType<'_> {
    fn visit_type_path_mut(&mut self, t: &mut syn::TypePath) {
        if t.path.is_ident(self.0) {
            t.path = self.1.clone();
        }
    }
}

/// Renames every identifier that names a block (its definition, its calls, its type).
struct Rename<'a>(&'a [String]);

impl VisitMut for Rename<'_> {
    fn visit_ident_mut(&mut self, ident: &mut syn::Ident) {
        if self.0.iter().any(|n| ident == n) {
            *ident = format_ident!("{PREFIX}{ident}", span = ident.span());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_and_their_uses_get_internal_names() {
        let (structs, fns) = items();
        let footprint = fns
            .iter()
            .find(|f| f.sig.ident == "__blocks_gaussian_footprint")
            .expect("gaussian_footprint is a block");
        let text = quote::quote!(#footprint).to_string();
        assert!(
            text.contains("__blocks_rotation_matrix (rotation)"),
            "{text}"
        );
        assert!(text.contains("-> __blocks_Footprint"), "{text}");
        assert!(structs.iter().any(|s| s.ident == "__blocks_Footprint"));
        assert_eq!(
            display("__blocks_Footprint").as_deref(),
            Some("blocks::Footprint")
        );
        assert_eq!(display("Footprint"), None);
    }

    #[test]
    fn signatures_read_as_written() {
        let all = signatures();
        assert!(
            all.contains(&"rotation_matrix(q: Vec4) -> Mat3".to_string()),
            "{all:?}"
        );
        assert!(
            all.iter()
                .any(|s| s.starts_with("conic_tile_cull(tile: &Tile, center: Vec2")),
            "{all:?}"
        );
    }
}
