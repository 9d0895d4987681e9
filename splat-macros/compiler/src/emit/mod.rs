//! Emission: function bodies in three Rust flavors (`body`), the items each kernel becomes
//! (`api`), the runtime contract of a method (`method`), WGSL through naga (`naga`), and the
//! module around them.

pub mod api;
pub mod body;
pub mod method;
pub mod naga;

use crate::model::Module;
use proc_macro2::TokenStream;
use quote::quote;

/// The user's structs, re-emitted with the derives the runtime needs and a `Flat` impl.
pub fn structs(module: &Module) -> TokenStream {
    let mut out = TokenStream::new();
    for s in module.structs.iter().filter(|s| !s.library) {
        let mut item = s.item.clone();
        item.attrs.retain(|a| !a.path().is_ident("derive"));
        if let syn::Fields::Named(named) = &mut item.fields {
            for (f, (_, ty)) in named.named.iter_mut().zip(&s.ty.fields) {
                let t = ty.rust();
                f.ty = syn::parse_quote!(#t);
            }
        }
        let ident = &item.ident;
        let mut writes = vec![];
        let mut finite = vec![];
        let mut reads = vec![];
        let mut at = 0usize;
        for (name, ty) in &s.ty.fields {
            let f = syn::Ident::new(name, proc_macro2::Span::call_site());
            let t = ty.rust();
            let at_lit = proc_macro2::Literal::usize_unsuffixed(at);
            writes.push(quote!(::splat_runtime::Flat::write_words(&self.#f, &mut out[#at_lit..]);));
            reads.push(quote!(#f: <#t as ::splat_runtime::Flat>::read_words(&words[#at_lit..])));
            finite.push(quote!(::splat_runtime::Flat::is_finite(&self.#f)));
            at += ty.slot_count(); // one 32-bit word per slot
        }
        let len = proc_macro2::Literal::usize_unsuffixed(at);
        out.extend(quote! {
            #[derive(Clone, Copy, Debug, Default, PartialEq)]
            #item

            impl ::splat_runtime::Flat for #ident {
                const LEN: usize = #len;
                fn write_words(&self, out: &mut [f32]) {
                    #(#writes)*
                }
                fn read_words(words: &[f32]) -> Self {
                    #ident { #(#reads),* }
                }
                fn is_finite(&self) -> bool {
                    true #(&& #finite)*
                }
            }
        });
    }
    out
}

/// Pretty-prints generated items (what `cargo expand` would show), for `GENERATED_RUST`.
pub fn pretty(items: &TokenStream) -> String {
    match syn::parse2::<syn::File>(items.clone()) {
        Ok(file) => prettyplease::unparse(&file),
        Err(_) => items.to_string(),
    }
}
