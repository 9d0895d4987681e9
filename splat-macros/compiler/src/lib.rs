//! The compiler behind `#[splat_method]` and `#[splat_functions]`.
//!
//! Pipeline (each stage a module, each unit-testable without going through a proc-macro):
//!
//! ```text
//! syn::ItemMod --model--> Module (structs, consts, fns, their resolved signatures)
//!              --check--> Checked (a method's roles against the runtime's contract, custom
//!                         adjoints' signatures)
//!              --typeck-> Typed (every body's expressions typed; the bodies that failed)
//!              --lower--> ir::Function per kernel (typed, scalar SSA, structured ifs,
//!                         loops unrolled, helpers inlined)
//!              --ad-----> adjoint ir::Function (recompute primal + reverse sweep)
//!              --opt----> dead code removed
//!              --emit---> Rust: typed f32 fns, flat f64 twin, flat 8-lane SIMD form,
//!                         and for methods the `SplatMethod` impl
//! ```
//!
//! The supported subset, the intrinsics and their derivative rules are listed in
//! `splat-macros/README.md`.

pub mod ad;
pub mod blocks;
pub mod builtins;
pub mod check;
pub mod diag;
pub mod emit;
pub mod flow;
pub mod gate;
pub mod ir;
pub mod lower;
pub mod model;
pub mod ops;
pub mod opt;
pub mod typeck;
pub mod types;

use check::Checked;
use diag::Diag;
use emit::api::Kernel;
use emit::body::Flavor;
use lower::Source;
use model::Module;
use proc_macro2::TokenStream;
use quote::quote;

/// What the attribute was.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `#[splat_method]`: the four-function method interface, implements `SplatMethod`.
    Method,
    /// `#[splat_functions]`: every function is a kernel (forward, adjoint, twin, lanes).
    Functions,
}

/// The compiled IR of a module, for tests and tools.
pub struct Compiled {
    pub kernels: Vec<(ir::Function, Option<ir::Function>)>,
}

/// Expands an annotated module; errors become `compile_error!`s at their spans.
pub fn expand(kind: Kind, attr: TokenStream, item: TokenStream) -> TokenStream {
    let diag = Diag::default();
    let name = method_name(kind, attr, &diag);
    let out = match syn::parse2::<syn::ItemMod>(item) {
        Ok(m) => expand_module(kind, m, name.as_deref(), &diag),
        Err(e) => {
            diag.push_error(e);
            None
        }
    };
    match diag.into_compile_errors() {
        Some(errors) => errors,
        None => out.unwrap_or_default(),
    }
}

/// The name `#[splat_method(name = "...")]` gives the method (what users see in messages,
/// `--explain` and checkpoints; the module's own name when none is given). `#[splat_functions]`
/// takes no arguments.
fn method_name(kind: Kind, attr: TokenStream, diag: &Diag) -> Option<String> {
    if attr.is_empty() {
        return None;
    }
    let usage = match kind {
        Kind::Functions => "this attribute takes no arguments",
        Kind::Method => {
            "`#[splat_method]` takes one optional argument, `name = \"...\"`: the method's name in messages and checkpoints (default: the module's)"
        }
    };
    let parsed = syn::parse2::<syn::MetaNameValue>(attr.clone()).ok();
    let name = parsed
        .filter(|_| kind == Kind::Method)
        .filter(|nv| nv.path.is_ident("name"))
        .and_then(|nv| {
            // A name passed through a `macro_rules!` arrives in an invisible group.
            let mut value = nv.value;
            while let syn::Expr::Group(g) = value {
                value = *g.expr;
            }
            match value {
                syn::Expr::Lit(syn::ExprLit {
                    lit: syn::Lit::Str(s),
                    ..
                }) => Some(s.value()),
                _ => None,
            }
        });
    match name {
        Some(n) if !n.is_empty() && !n.contains(char::is_whitespace) => Some(n),
        Some(_) => {
            diag.error_at(&attr, "a method's name must be non-empty, without spaces");
            None
        }
        None => {
            diag.error_at(&attr, usage);
            None
        }
    }
}

/// Compiles a module to IR only (no Rust), reporting errors as strings.
pub fn compile_ir(kind: Kind, item: syn::ItemMod) -> Result<Compiled, Vec<String>> {
    let diag = Diag::default();
    let r = Module::parse(item, &diag).and_then(|m| {
        let checked = check::check(kind, &m, &diag)?;
        let typed = typeck::typeck(&m, &diag);
        let src = Source {
            module: &m,
            typed: &typed,
        };
        let custom = custom_adjoints(&checked, src, &diag)?;
        let kernels = build_kernels(&checked, src, &custom, &diag)?;
        Some(Compiled {
            kernels: kernels.into_iter().map(|k| (k.primal, k.adjoint)).collect(),
        })
    });
    match (r, diag.into_messages()) {
        (Some(c), errors) if errors.is_empty() => Ok(c),
        (_, errors) => Err(errors),
    }
}

/// Helpers with `#[adjoint(f)]`: their names (the `callee` index of `Stmt::Call`) and the
/// lowered user adjoints.
struct Custom {
    names: Vec<String>,
    adjoints: Vec<ir::Function>,
}

fn custom_adjoints(c: &Checked, src: Source, diag: &Diag) -> Option<Custom> {
    let mut custom = Custom {
        names: vec![],
        adjoints: vec![],
    };
    for (helper, adjoint) in &c.adjoints {
        custom.names.push(helper.name.clone());
        custom
            .adjoints
            .push(lower::lower_fn(src, diag, adjoint, &[])?.func);
    }
    Some(custom)
}

fn build_kernels<'m>(
    c: &Checked<'m>,
    src: Source,
    custom: &Custom,
    diag: &Diag,
) -> Option<Vec<Kernel<'m>>> {
    let m = c.module;
    let defs: Vec<&model::FnDef> = match &c.roles {
        Some(r) => m.fns.iter().filter(|f| r.has(f)).collect(),
        None => m
            .fns
            .iter()
            .filter(|f| !f.builtin && !c.is_adjoint(f))
            .collect(),
    };
    let mut kernels = vec![];
    for def in defs {
        let groups = c.roles.as_ref().and_then(|r| gradient_groups(r, def));
        let gated = groups.as_deref();
        let Some((mut kernel, model_slot)) = build_kernel(src, def, custom, diag, None, gated)
        else {
            continue;
        };
        let reads_model = model_slot.is_some_and(|v| {
            kernel.primal.body.uses(v) || kernel.adjoint.as_ref().is_some_and(|g| g.body.uses(v))
        });
        if c.roles.is_some() && reads_model {
            for builtins::CameraModel {
                name: model, code, ..
            } in builtins::camera_models()
            {
                let Some((mut variant, _)) =
                    build_kernel(src, def, custom, diag, Some(code), gated)
                else {
                    continue;
                };
                variant.primal.name = format!("{}_{model}", def.name);
                for g in variant.adjoint.iter_mut().chain(&mut variant.gated) {
                    g.name = format!("{}_adjoint_{model}", def.name);
                }
                kernel.models.push((model, code, variant));
            }
        }
        kernels.push(kernel);
    }
    (!diag.has_errors()).then_some(kernels)
}

/// A method's `project` and `evaluate` adjoints compute only the gradient groups asked for:
/// the group of each of their results.
fn gradient_groups(r: &check::Roles, def: &model::FnDef) -> Option<Vec<u32>> {
    let (a, b) = (&def.params[0].ty, &def.params[1].ty);
    if std::ptr::eq(def, r.project) {
        Some(gate::project_groups(a, b))
    } else if std::ptr::eq(def, r.evaluate) {
        Some(gate::evaluate_groups(a, b))
    } else {
        None
    }
}

/// Lowers, differentiates and cleans one kernel, for every camera model or for the one with
/// code `model` (and with `gated`, the group of each adjoint result, gates its adjoint by
/// gradient group: `Kernel::gated`); also returns the parameter slot of the camera's model
/// code.
fn build_kernel<'m>(
    src: Source,
    def: &'m model::FnDef,
    custom: &Custom,
    diag: &Diag,
    model: Option<u32>,
    gated: Option<&[u32]>,
) -> Option<(Kernel<'m>, Option<ir::Var>)> {
    let l = lower::lower_for_model(src, diag, def, &custom.names, model)?;
    let mut primal = l.func;
    let has_float_in = primal
        .params
        .iter()
        .any(|p| primal.ty(*p) == ir::Scalar::F32);
    let out_names: Vec<String> = l
        .ret
        .slot_names("d_out")
        .into_iter()
        .zip(l.ret.slots())
        .filter(|(_, s)| *s == ir::Scalar::F32)
        .map(|(n, _)| n)
        .collect();
    let adjoint = (has_float_in && !out_names.is_empty()).then(|| {
        let mut g = ad::adjoint(&primal, &custom.adjoints, &out_names);
        opt::dce(&mut g);
        g
    });
    opt::dce(&mut primal);
    let gated = adjoint.as_ref().zip(gated).map(|(g, groups)| {
        let mut g = g.clone();
        gate::gate(&mut g, groups);
        g
    });
    let kernel = Kernel {
        def,
        primal,
        adjoint,
        gated,
        ret: l.ret,
        camera_model: l.camera_model,
        rolling_shutter: l.rolling_shutter,
        models: vec![],
    };
    Some((kernel, l.model_slot))
}

fn expand_module(
    kind: Kind,
    item: syn::ItemMod,
    name: Option<&str>,
    diag: &Diag,
) -> Option<TokenStream> {
    let m = Module::parse(item, diag)?;
    let checked = check::check(kind, &m, diag)?;
    let typed = typeck::typeck(&m, diag);
    let src = Source {
        module: &m,
        typed: &typed,
    };
    let custom = custom_adjoints(&checked, src, diag)?;
    let kernels = build_kernels(&checked, src, &custom, diag)?;
    let lanes_for =
        |k: &Kernel| (checked.roles.as_ref()).is_none_or(|r| std::ptr::eq(k.def, r.evaluate));
    let mut items = TokenStream::new();
    items.extend(m.uses.iter().map(|u| quote!(#[allow(unused_imports)] #u)));
    items.extend(emit::structs(&m));
    for c in m.const_names() {
        // Re-emit constants as written: users may refer to them outside the kernels.
        if let Some(item) = const_item(&m, &c) {
            items.extend(item);
        }
    }
    let mut twin = TokenStream::new();
    let mut lanes = TokenStream::new();
    let mut scalar = TokenStream::new();
    let mut by_model: Vec<(&str, TokenStream)> = vec![];
    for k in &kernels {
        items.extend(k.forward());
        items.extend(k.adjoint_fn());
        for (model, _, v) in &k.models {
            let at = match by_model.iter().position(|(m, _)| *m == model.as_str()) {
                Some(at) => at,
                None => {
                    by_model.push((model, TokenStream::new()));
                    by_model.len() - 1
                }
            };
            by_model[at].1.extend(v.forward());
            by_model[at].1.extend(v.adjoint_fn());
        }
        twin.extend(k.flat(Flavor::F64));
        if lanes_for(k) {
            lanes.extend(k.flat(Flavor::Lanes));
        }
        if kind == Kind::Functions {
            scalar.extend(k.flat(Flavor::F32));
        }
    }
    for (model, fns) in by_model {
        let doc = format!(
            " The kernels that read the camera model, compiled for the {model} camera only: the other models' branches are not in them."
        );
        let module = quote::format_ident!("{model}");
        items.extend(quote! {
            #[doc = #doc]
            pub mod #module {
                #[allow(unused_imports)]
                use super::*;
                #fns
            }
        });
    }
    items.extend(quote! {
        /// The f64 twin of every kernel, in flat form, for finite-difference tests.
        pub mod twin { #twin }
        /// The eight-lane SIMD form of the kernels, in flat form.
        pub mod lanes { #lanes }
    });
    if kind == Kind::Functions {
        items.extend(quote! {
            /// The f32 kernels in the flat form of `lanes`, to compare the two lane by lane.
            pub mod scalar { #scalar }
        });
    }
    if let Some(roles) = &checked.roles {
        let name = name.map_or_else(|| m.name.to_string(), str::to_string);
        items.extend(emit::method::method_impl(&name, roles, &kernels));
    }
    let (wgsl, signatures) = match emit::naga::wgsl(&wgsl_kernels(&kernels)) {
        Ok(w) => w,
        Err(e) => {
            diag.error_at(
                &m.name,
                format!("the WGSL backend rejected this module: {e}"),
            );
            return None;
        }
    };
    let source = emit::pretty(&items);
    let functions = signatures.iter().map(function_literal);
    let (attrs, vis, name) = (&m.attrs, &m.vis, &m.name);
    Some(quote! {
        #(#attrs)*
        #vis mod #name {
            #items
            /// The Rust this module's attribute generated, pretty-printed.
            pub const GENERATED_RUST: &str = #source;
            /// WGSL of every kernel and adjoint (built as a naga module, validated, written by naga).
            pub const GENERATED_WGSL: &str = #wgsl;
            /// The signature of every function in `GENERATED_WGSL`.
            pub const GENERATED_FUNCTIONS: &[::splat_runtime::WgslFunction] = &[#(#functions),*];
        }
    })
}

/// A `splat_runtime::WgslFunction` literal.
fn function_literal(f: &emit::naga::Signature) -> TokenStream {
    let scalar = |s: &ir::Scalar| match s {
        ir::Scalar::F32 => quote!(::splat_runtime::WgslScalar::F32),
        ir::Scalar::U32 => quote!(::splat_runtime::WgslScalar::U32),
        ir::Scalar::I32 => quote!(::splat_runtime::WgslScalar::I32),
        ir::Scalar::Bool => quote!(::splat_runtime::WgslScalar::Bool),
    };
    let (kernel, name) = (&f.kernel, &f.name);
    let args = f.args.iter().map(scalar);
    let results = f.results.iter().map(|(m, s)| {
        let s = scalar(s);
        quote!((#m, #s))
    });
    quote! {
        ::splat_runtime::WgslFunction {
            kernel: #kernel,
            name: #name,
            args: &[#(#args),*],
            results: &[#(#results),*],
        }
    }
}

/// Each kernel's IR with the names of its result slots (`alpha`, `color_x`, ...; the
/// adjoint's are `d_` + the parameter slots).
fn wgsl_kernels<'k>(kernels: &'k [Kernel]) -> Vec<(&'k ir::Function, Vec<String>)> {
    let mut out = vec![];
    for k in kernels.iter().chain(
        kernels
            .iter()
            .flat_map(|k| k.models.iter().map(|(_, _, v)| v)),
    ) {
        out.push((&k.primal, k.ret.slot_names("")));
        if let Some(adj) = k.gated.as_ref().or(k.adjoint.as_ref()) {
            let names = k
                .def
                .params
                .iter()
                .flat_map(|p| {
                    p.ty.slot_names(&format!("d_{}", p.name))
                        .into_iter()
                        .zip(p.ty.slots())
                })
                .filter(|(_, s)| *s == ir::Scalar::F32)
                .map(|(n, _)| n)
                .collect();
            out.push((adj, names));
        }
    }
    out
}

fn const_item(m: &Module, name: &str) -> Option<TokenStream> {
    let c = m.consts.get(name)?;
    let (ident, ty, expr) = (
        syn::Ident::new(name, proc_macro2::Span::call_site()),
        c.ty.rust(),
        &c.expr,
    );
    Some(quote!(#[allow(dead_code, clippy::excessive_precision)] pub const #ident: #ty = #expr;))
}

#[cfg(test)]
mod tests;
