//! The Rust items a kernel becomes: its typed forward and adjoint functions, the flat `f64`
//! twin (module `twin`) and the flat eight-lane form (module `lanes`).

use super::body::{BodyEmitter, Flavor, lane_type};
use crate::ir::{Function, Scalar, Var};
use crate::model::FnDef;
use crate::types::Ty;
use proc_macro2::{Ident, Literal, TokenStream};
use quote::{format_ident, quote};

/// A kernel after lowering and AD.
pub struct Kernel<'m> {
    pub def: &'m FnDef,
    pub primal: Function,
    /// `None` when the kernel has no float input or no float output.
    pub adjoint: Option<Function>,
    /// The adjoint gated by gradient group (see `gate`): its last parameter is the mask of the
    /// groups to compute. The typed and WGSL adjoints are emitted from it; the twin and the
    /// lanes from `adjoint`.
    pub gated: Option<Function>,
    pub ret: Ty,
    /// Whether the kernel reads the camera model (see `builtins::model_aware`).
    pub camera_model: bool,
    /// Whether the kernel reads the camera's rolling shutter (see `builtins::shutter_aware`).
    pub rolling_shutter: bool,
    /// For a method kernel that reads the camera's model code: the kernel specialized to each
    /// model (`builtins::camera_models` order) with the model's code, its IR functions named
    /// `{kernel}_{model}` and `{kernel}_adjoint_{model}`.
    pub models: Vec<(String, u32, Kernel<'m>)>,
}

/// Expressions reading each slot of a value of type `ty` called `base`.
pub fn slot_access(ty: &Ty, base: TokenStream) -> Vec<TokenStream> {
    let mut out = vec![];
    push_access(ty, base, &mut out);
    out
}

fn push_access(ty: &Ty, base: TokenStream, out: &mut Vec<TokenStream>) {
    match ty {
        Ty::Vec(n) => {
            for c in ["x", "y", "z", "w"].iter().take(*n) {
                let c = format_ident!("{c}");
                out.push(quote!(#base.#c));
            }
        }
        Ty::Quat => {
            for c in ["x", "y", "z", "w"] {
                let c = format_ident!("{c}");
                out.push(quote!(#base.#c));
            }
        }
        Ty::Mat(n) => {
            for axis in ["x_axis", "y_axis", "z_axis"].iter().take(*n) {
                for c in ["x", "y", "z"].iter().take(*n) {
                    let (a, c) = (format_ident!("{axis}"), format_ident!("{c}"));
                    out.push(quote!(#base.#a.#c));
                }
            }
        }
        Ty::Array(t, n) => {
            for i in 0..*n {
                let i = Literal::usize_unsuffixed(i);
                push_access(t, quote!(#base[#i]), out);
            }
        }
        Ty::Struct(s) => {
            for (f, t) in &s.fields {
                let is_enum = crate::types::builtin_enum_field(s, f).is_some();
                let f = format_ident!("{f}");
                if is_enum {
                    out.push(quote!((#base.#f as u32)));
                } else {
                    push_access(t, quote!(#base.#f), out);
                }
            }
        }
        Ty::Tuple(ts) => {
            for (i, t) in ts.iter().enumerate() {
                let i = syn::Index::from(i);
                push_access(t, quote!(#base.#i), out);
            }
        }
        _ => out.push(base),
    }
}

/// Builds a value of type `ty` from slot expressions.
pub fn pack(ty: &Ty, slots: &mut impl Iterator<Item = TokenStream>) -> TokenStream {
    let mut take =
        |n: usize| -> Vec<TokenStream> { (0..n).map(|_| slots.next().expect("slot")).collect() };
    match ty {
        Ty::Vec(n) => {
            let t = ty.rust();
            let s = take(*n);
            quote!(#t::new(#(#s),*))
        }
        Ty::Quat => {
            let s = take(4);
            quote!(::splat_runtime::glam::Quat::from_xyzw(#(#s),*))
        }
        Ty::Mat(n) => {
            let t = ty.rust();
            let s = take(n * n);
            quote!(#t::from_cols_array(&[#(#s),*]))
        }
        Ty::Array(t, n) => {
            let items: Vec<TokenStream> = (0..*n).map(|_| pack(t, slots)).collect();
            quote!([#(#items),*])
        }
        Ty::Struct(s) => {
            let path = strip_generics(&s.path.0);
            let fields: Vec<TokenStream> = s
                .fields
                .iter()
                .map(|(f, t)| {
                    let e = crate::types::builtin_enum_field(s, f);
                    let f = format_ident!("{f}");
                    let v = pack(t, slots);
                    match e {
                        Some(e) => quote!(#f: #e::from_code(#v).unwrap_or_default()),
                        None => quote!(#f: #v),
                    }
                })
                .collect();
            quote!(#path { #(#fields),* })
        }
        Ty::Tuple(ts) => {
            let items: Vec<TokenStream> = ts.iter().map(|t| pack(t, slots)).collect();
            quote!((#(#items,)*))
        }
        _ => take(1).remove(0),
    }
}

/// `::splat_runtime::Projected<A, B>` -> `::splat_runtime::Projected` for struct literals.
fn strip_generics(path: &TokenStream) -> TokenStream {
    let mut out = TokenStream::new();
    for t in path.clone() {
        if let proc_macro2::TokenTree::Punct(p) = &t
            && p.as_char() == '<'
        {
            break;
        }
        out.extend([t]);
    }
    out
}

fn zero_of(s: Scalar, flavor: Flavor) -> TokenStream {
    match (s, flavor) {
        (Scalar::F32, Flavor::F64) => quote!(0.0f64),
        (Scalar::F32, _) => quote!(0.0f32),
        (Scalar::Bool, _) => quote!(false),
        (Scalar::U32, _) => quote!(0u32),
        (Scalar::I32, _) => quote!(0i32),
    }
}

const ALLOW: &str = "#[allow(unused_variables, unused_parens, clippy::all, clippy::pedantic)]";

impl Kernel<'_> {
    fn name(&self) -> &Ident {
        &self.def.item.sig.ident
    }

    fn reserved(&self) -> Vec<String> {
        let mut r: Vec<String> = self.def.params.iter().map(|p| p.name.clone()).collect();
        r.push("d_out".into());
        r
    }

    fn typed_params(&self) -> Vec<TokenStream> {
        self.def
            .params
            .iter()
            .map(|p| {
                let (id, t) = (&p.ident, p.ty.rust());
                if p.by_ref {
                    quote!(#id: &#t)
                } else {
                    quote!(#id: #t)
                }
            })
            .collect()
    }

    /// Binds every parameter slot of `f` (the first slots of its params) to a typed access.
    fn typed_prologue(&self, em: &mut BodyEmitter, f: &Function) -> TokenStream {
        let mut out = TokenStream::new();
        let mut vars = f.params.iter();
        for p in &self.def.params {
            let id = &p.ident;
            let access = slot_access(&p.ty, quote!(#id));
            let scalar = p.ty.slots().len() == 1
                && !matches!(p.ty, Ty::Array(..) | Ty::Struct(_) | Ty::Tuple(_));
            for a in access {
                let v = *vars.next().expect("param slot");
                if scalar {
                    em.name_as(v, &p.name);
                } else {
                    let x = em.ident(v);
                    out.extend(quote!(let #x = #a;));
                }
            }
        }
        out
    }

    /// The typed `f32` forward function.
    pub fn forward(&self) -> TokenStream {
        let f = &self.primal;
        let mut em = BodyEmitter::new(f, Flavor::F32, &self.reserved());
        let prologue = self.typed_prologue(&mut em, f);
        let body = em.block(&f.body);
        let mut outs = f
            .results()
            .iter()
            .map(|r| em.val(*r))
            .collect::<Vec<_>>()
            .into_iter();
        let result = pack(&self.ret, &mut outs);
        let (name, params, ret) = (self.name(), self.typed_params(), self.ret.rust());
        let docs = self
            .def
            .item
            .attrs
            .iter()
            .filter(|a| a.path().is_ident("doc"));
        let allow: TokenStream = ALLOW.parse().unwrap();
        quote! {
            #(#docs)*
            #[inline]
            #allow
            pub fn #name(#(#params),*) -> #ret {
                #prologue
                #body
                #result
            }
        }
    }

    /// The typed `f32` adjoint: `(params..., d_out) -> cotangents of the params`; for a gated
    /// kernel also `{name}_adjoint_gated(params..., d_out, grads: u32)`, which computes only the
    /// groups in `grads` (see `gate`). Both are emitted: the plain one keeps the statement
    /// order the AD wrote, so computing everything costs what it did before gating.
    pub fn adjoint_fn(&self) -> Option<TokenStream> {
        let plain = self.typed_adjoint(self.adjoint.as_ref()?, false);
        let gated = self.gated.as_ref().map(|g| self.typed_adjoint(g, true));
        Some(quote!(#plain #gated))
    }

    fn typed_adjoint(&self, g: &Function, gated: bool) -> TokenStream {
        let mut reserved = self.reserved();
        reserved.push("grads".into());
        let mut em = BodyEmitter::new(g, Flavor::F32, &reserved);
        let mut prologue = self.typed_prologue(&mut em, g);
        let grads = gated.then(|| {
            em.name_as(*g.params.last().expect("the mask"), "grads");
            quote!(grads: u32)
        });
        let n_primal = self.primal.params.len();
        let ret_slots = self.ret.slots();
        let float_access = slot_access(&self.ret, quote!(d_out))
            .into_iter()
            .zip(&ret_slots)
            .filter(|(_, s)| **s == Scalar::F32);
        let scalar_ret = matches!(self.ret, Ty::F32);
        for (v, (a, _)) in g.params[n_primal..].iter().zip(float_access) {
            // (The gated adjoint's mask, its last parameter, is past the cotangent's slots.)
            if scalar_ret {
                em.name_as(*v, "d_out");
                continue;
            }
            let x = em.ident(*v);
            prologue.extend(quote!(let #x = #a;));
        }
        let body = em.block(&g.body);
        let mut bars = g
            .results()
            .iter()
            .map(|r| em.val(*r))
            .collect::<Vec<_>>()
            .into_iter();
        let mut cots = vec![];
        let mut cot_tys = vec![];
        for p in &self.def.params {
            let mut slots =
                p.ty.slots()
                    .into_iter()
                    .map(|s| {
                        if s == Scalar::F32 {
                            bars.next().expect("bar")
                        } else {
                            zero_of(s, Flavor::F32)
                        }
                    })
                    .collect::<Vec<_>>()
                    .into_iter();
            cots.push(pack(&p.ty, &mut slots));
            cot_tys.push(p.ty.rust());
        }
        let (result, result_ty) = if cots.len() == 1 {
            (cots.remove(0), cot_tys.remove(0))
        } else {
            (quote!((#(#cots),*)), quote!((#(#cot_tys),*)))
        };
        let plain = format_ident!("{}_adjoint", self.name());
        let name = match gated {
            true => format_ident!("{}_adjoint_gated", self.name()),
            false => plain.clone(),
        };
        let params = self.typed_params();
        let ret = self.ret.rust();
        let doc = match gated {
            true => format!(
                " [`{plain}`] computing only the gradient groups whose bits are set in `grads` (bit k: field k of the parameters, or of the shade data; bit 31: the camera, or the pixel data; see `splat_runtime::GradientSet`); the others are zero."
            ),
            false => format!(
                " Reverse-mode derivative of [`{}`]: given the cotangent `d_out` of its result, the cotangents of its parameters (zero for `bool` and integer fields).",
                self.name()
            ),
        };
        let allow: TokenStream = ALLOW.parse().unwrap();
        quote! {
            #[doc = #doc]
            #[inline]
            #allow
            pub fn #name(#(#params,)* d_out: #ret, #grads) -> #result_ty {
                #prologue
                #body
                #result
            }
        }
    }

    /// The flat forward and adjoint in `flavor` (`F64` for the twin, `Lanes` for SIMD):
    /// floats in one array, `bool`/integer slots as `u32` in another.
    pub fn flat(&self, flavor: Flavor) -> TokenStream {
        let (float_t, int_t) = match flavor {
            Flavor::F64 => (quote!(f64), quote!(u32)),
            Flavor::Lanes => (lane_type(Scalar::F32), lane_type(Scalar::U32)),
            Flavor::F32 => (quote!(f32), quote!(u32)),
        };
        let reserved = vec!["__in".to_string(), "__int".into(), "__d".into()];
        let allow: TokenStream = ALLOW.parse().unwrap();
        let name = self.name();
        // Lane code must inline into callers compiled with wider vector features.
        let inline = if flavor == Flavor::Lanes {
            quote!(#[inline(always)])
        } else {
            quote!(#[inline])
        };
        let read = |em: &mut BodyEmitter,
                    vars: &[Var],
                    f: &Function,
                    arr: TokenStream,
                    int_arr: TokenStream| {
            let (mut fi, mut ii) = (0usize, 0usize);
            let mut out = TokenStream::new();
            for v in vars {
                let x = em.ident(*v);
                let e = match f.ty(*v) {
                    Scalar::F32 => {
                        fi += 1;
                        let k = Literal::usize_unsuffixed(fi - 1);
                        quote!(#arr[#k])
                    }
                    s => {
                        ii += 1;
                        let k = Literal::usize_unsuffixed(ii - 1);
                        match (s, flavor) {
                            (Scalar::Bool, Flavor::Lanes) => quote!(#int_arr[#k].to_mask()),
                            (Scalar::I32, Flavor::Lanes) => quote!(#int_arr[#k].to_i32()),
                            (Scalar::Bool, _) => quote!((#int_arr[#k] != 0)),
                            (Scalar::I32, _) => quote!((#int_arr[#k] as i32)),
                            _ => quote!(#int_arr[#k]),
                        }
                    }
                };
                out.extend(quote!(let #x = #e;));
            }
            (out, fi, ii)
        };
        let write = |em: &mut BodyEmitter, vars: &[Var], f: &Function| {
            let (mut fl, mut it) = (vec![], vec![]);
            for v in vars {
                let e = em.val(*v);
                match (f.ty(*v), flavor) {
                    (Scalar::F32, _) => fl.push(e),
                    (Scalar::U32, _) => it.push(e),
                    (Scalar::Bool | Scalar::I32, Flavor::Lanes) => it.push(quote!(#e.to_u32())),
                    (Scalar::Bool | Scalar::I32, _) => it.push(quote!((#e as u32))),
                }
            }
            (fl, it)
        };
        let f = &self.primal;
        let mut em = BodyEmitter::new(f, flavor, &reserved);
        let (prologue, nf, ni) = read(&mut em, &f.params, f, quote!(__in), quote!(__int));
        let body = em.block(&f.body);
        let (fl, it) = write(&mut em, f.results(), f);
        let (mf, mi) = (
            Literal::usize_unsuffixed(fl.len()),
            Literal::usize_unsuffixed(it.len()),
        );
        let (nf_l, ni_l) = (Literal::usize_unsuffixed(nf), Literal::usize_unsuffixed(ni));
        let fwd_doc = format!(" Flat form of [`super::{name}`].");
        let mut out = quote! {
            #[doc = #fwd_doc]
            #inline
            #allow
            pub fn #name(__in: &[#float_t; #nf_l], __int: &[#int_t; #ni_l]) -> ([#float_t; #mf], [#int_t; #mi]) {
                #prologue
                #body
                ([#(#fl),*], [#(#it),*])
            }
        };
        // Lane code of a gated kernel also comes gated (its mask one for all lanes); the twin
        // is the whole adjoint only.
        let gated = self.gated.as_ref().filter(|_| flavor == Flavor::Lanes);
        let adjoints = self.adjoint.iter().map(|g| (g, false));
        for (g, gated) in adjoints.chain(gated.map(|g| (g, true))) {
            let mut reserved = reserved.clone();
            reserved.push("grads".into());
            let mut em = BodyEmitter::new(g, flavor, &reserved);
            let n = f.params.len();
            let cotangents = g.params.len() - gated as usize;
            let (mut prologue, _, _) =
                read(&mut em, &g.params[..n], g, quote!(__in), quote!(__int));
            let (bars, _, _) = read(
                &mut em,
                &g.params[n..cotangents],
                g,
                quote!(__d),
                quote!(__int),
            );
            prologue.extend(bars);
            let grads = gated.then(|| {
                let mask = g.params[cotangents];
                em.name_as(mask, "grads");
                em.set_uniform(mask);
                quote!(grads: u32)
            });
            let body = em.block(&g.body);
            let (fl, _) = write(&mut em, g.results(), g);
            let (adj, doc) = match gated {
                false => (
                    format_ident!("{}_adjoint", name),
                    format!(
                        " Flat form of [`super::{name}_adjoint`]: the cotangents of the float inputs."
                    ),
                ),
                true => (
                    format_ident!("{}_adjoint_gated", name),
                    format!(
                        " Flat form of [`super::{name}_adjoint_gated`]: the cotangents of the groups in `grads`."
                    ),
                ),
            };
            out.extend(quote! {
                #[doc = #doc]
                #inline
                #allow
                pub fn #adj(__in: &[#float_t; #nf_l], __int: &[#int_t; #ni_l], __d: &[#float_t; #mf], #grads) -> [#float_t; #nf_l] {
                    #prologue
                    #body
                    [#(#fl),*]
                }
            });
        }
        out
    }
}
