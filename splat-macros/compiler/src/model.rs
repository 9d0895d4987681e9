//! The parsed model of an annotated module: its structs, constants, functions and their roles.
//! Everything downstream (lowering, emitters) reads this model, never the raw `syn` module.

use crate::diag::Diag;
use crate::types::{StructTy, TokenStreamEq, Ty, builtin_struct};
use quote::quote;
use std::collections::HashMap;
use std::rc::Rc;

pub struct Module {
    pub name: syn::Ident,
    pub vis: syn::Visibility,
    pub attrs: Vec<syn::Attribute>,
    /// `use` items, re-emitted as written.
    pub uses: Vec<syn::ItemUse>,
    pub structs: Vec<StructDef>,
    pub consts: HashMap<String, ConstDef>,
    const_items: Vec<syn::ItemConst>,
    pub fns: Vec<FnDef>,
}

pub struct StructDef {
    pub item: syn::ItemStruct,
    pub ty: Rc<StructTy>,
    /// One of the building blocks' structs (`blocks`): a value inside kernels, never emitted.
    pub library: bool,
}

pub struct ConstDef {
    pub ty: Ty,
    pub expr: syn::Expr,
}

pub struct Param {
    pub name: String,
    pub ident: syn::Ident,
    pub ty: Ty,
    pub by_ref: bool,
}

pub struct FnDef {
    pub item: syn::ItemFn,
    pub name: String,
    pub params: Vec<Param>,
    pub ret: Ty,
    /// `#[adjoint(other)]`: `other` is the user-written adjoint of this helper.
    pub adjoint: Option<syn::Ident>,
    /// One of the compiler's own helpers (`builtins`), not written by the user.
    pub builtin: bool,
}

impl Module {
    pub fn find_fn(&self, name: &str) -> Option<&FnDef> {
        self.fns.iter().find(|f| f.name == name)
    }

    /// Resolves a type written inside a function body against this module.
    pub fn resolve_type(&self, t: &syn::Type) -> Result<Ty, String> {
        let mut resolver = Resolver {
            items: &[],
            done: HashMap::new(),
            consts: &self.const_items,
        };
        for s in &self.structs {
            resolver.done.insert(s.item.ident.to_string(), s.ty.clone());
        }
        resolver.resolve(t)
    }

    /// The value of an array length written inside a function body (`[x; N]`).
    pub fn array_len(&self, e: &syn::Expr) -> Result<usize, String> {
        let resolver = Resolver {
            items: &[],
            done: HashMap::new(),
            consts: &self.const_items,
        };
        resolver.const_len(e)
    }

    /// The names of the constants that resolved, in source order (`consts` is for lookup; its
    /// order changes from one compilation to the next).
    pub fn const_names(&self) -> impl Iterator<Item = String> + '_ {
        (self.const_items.iter())
            .map(|c| c.ident.to_string())
            .filter(|name| self.consts.contains_key(name))
    }

    pub fn find_struct(&self, name: &str) -> Option<&Rc<StructTy>> {
        self.structs
            .iter()
            .find(|s| s.item.ident == name)
            .map(|s| &s.ty)
    }

    /// Parses an inline module. Errors are collected in `diag`; the model holds what parsed.
    pub fn parse(item: syn::ItemMod, diag: &Diag) -> Option<Module> {
        let Some((_, items)) = item.content else {
            diag.error_at(
                &item,
                "the annotated module must be inline: `mod name { ... }`",
            );
            return None;
        };
        let mut struct_items = vec![];
        let mut const_items = vec![];
        let mut fn_items = vec![];
        let mut uses = vec![];
        for it in items {
            match it {
                syn::Item::Struct(s) => struct_items.push(s),
                syn::Item::Const(c) => const_items.push(c),
                syn::Item::Fn(f) => fn_items.push(f),
                syn::Item::Use(u) => uses.push(u),
                other => diag.error_at(
                    &other,
                    "only `struct`, `const`, `fn` and `use` items are allowed in a splat module",
                ),
            }
        }
        // Rust's namespaces: types, and values (constants and functions).
        unique_names(struct_items.iter().map(|s| &s.ident), diag);
        let values = const_items.iter().map(|c| &c.ident);
        unique_names(values.chain(fn_items.iter().map(|f| &f.sig.ident)), diag);
        let (library_structs, library_fns) = crate::blocks::items();
        let user_structs = struct_items.len();
        struct_items.extend(library_structs);
        let mut resolver = Resolver {
            items: &struct_items,
            done: HashMap::new(),
            consts: &const_items,
        };
        let mut structs = vec![];
        for (i, s) in struct_items.iter().enumerate() {
            if let Some(ty) = resolver.resolve_struct(s, diag, &mut vec![]) {
                structs.push(StructDef {
                    item: s.clone(),
                    ty,
                    library: i >= user_structs,
                });
            }
        }
        let mut consts = HashMap::new();
        for c in &const_items {
            match resolver.resolve(&c.ty) {
                Ok(ty) => {
                    consts.insert(
                        c.ident.to_string(),
                        ConstDef {
                            ty,
                            expr: (*c.expr).clone(),
                        },
                    );
                }
                Err(msg) => diag.error_at(&c.ty, msg),
            }
        }
        let mut fns = vec![];
        for f in fn_items {
            if let Some(def) = parse_fn(f, &mut resolver, diag) {
                fns.push(def);
            }
        }
        let errors_before = diag.count();
        for f in crate::builtins::builtin_items()
            .into_iter()
            .chain(library_fns)
        {
            if let Some(def) = parse_fn(f, &mut resolver, diag) {
                fns.push(FnDef {
                    builtin: true,
                    ..def
                });
            }
        }
        debug_assert_eq!(
            diag.count(),
            errors_before,
            "the builtin source type-checks"
        );
        Some(Module {
            name: item.ident,
            vis: item.vis,
            attrs: item.attrs,
            uses,
            structs,
            consts,
            const_items,
            fns,
        })
    }
}

/// Reports each name met a second time (rustc would, at a span the user cannot see once the
/// module is expanded; the model would keep only one of them).
fn unique_names<'a>(names: impl Iterator<Item = &'a syn::Ident>, diag: &Diag) {
    let mut seen = std::collections::HashSet::new();
    for name in names {
        if !seen.insert(name) {
            diag.error_at(
                name,
                format!("`{name}` is defined more than once in this module"),
            );
        }
    }
}

fn parse_fn(mut item: syn::ItemFn, resolver: &mut Resolver, diag: &Diag) -> Option<FnDef> {
    let sig = &item.sig;
    let mut ok = true;
    if let Some(g) = sig.generics.params.first() {
        diag.error_at(
            g,
            "generic functions are not supported: write the concrete types",
        );
        ok = false;
    }
    for (kw, span) in [
        (sig.asyncness.is_some(), "async"),
        (sig.unsafety.is_some(), "unsafe"),
        (sig.constness.is_some(), "const"),
    ] {
        if kw {
            diag.error_at(
                &sig.fn_token,
                format!("`{span} fn` is not supported in a splat module"),
            );
            ok = false;
        }
    }
    let mut params = vec![];
    for input in &sig.inputs {
        match input {
            syn::FnArg::Receiver(r) => {
                diag.error_at(
                    r,
                    "methods with `self` are not supported: write a free function",
                );
                ok = false;
            }
            syn::FnArg::Typed(pt) => {
                let syn::Pat::Ident(pi) = &*pt.pat else {
                    diag.error_at(&pt.pat, "parameters must be plain names");
                    ok = false;
                    continue;
                };
                let (inner, by_ref) = match &*pt.ty {
                    syn::Type::Reference(r) if r.mutability.is_some() => {
                        diag.error_at(
                            &pt.ty,
                            "`&mut` parameters are not supported: kernels are pure, return the new value instead",
                        );
                        ok = false;
                        continue;
                    }
                    syn::Type::Reference(r) => (&*r.elem, true),
                    t => (t, false),
                };
                match resolver.resolve(inner) {
                    Ok(ty) if ty.contains_index() => {
                        diag.error_at(inner, "`usize` is only for compile-time constants; use u32");
                        ok = false;
                    }
                    Ok(ty) => params.push(Param {
                        name: pi.ident.to_string(),
                        ident: pi.ident.clone(),
                        ty,
                        by_ref,
                    }),
                    Err(msg) => {
                        diag.error_at(inner, msg);
                        ok = false;
                    }
                }
            }
        }
    }
    let ret = match &sig.output {
        syn::ReturnType::Default => {
            diag.error_at(&sig.ident, "a kernel function must return a value");
            ok = false;
            Ty::Error
        }
        syn::ReturnType::Type(_, t) => match resolver.resolve(t) {
            Ok(ty) if ty.contains_index() => {
                diag.error_at(t, "`usize` is only for compile-time constants; return u32");
                ok = false;
                Ty::Error
            }
            Ok(ty) => ty,
            Err(msg) => {
                diag.error_at(t, msg);
                ok = false;
                Ty::Error
            }
        },
    };
    let mut adjoint = None;
    let mut kept = vec![];
    for attr in item.attrs.drain(..) {
        if attr.path().is_ident("adjoint") {
            match attr.parse_args::<syn::Ident>() {
                Ok(id) => adjoint = Some(id),
                Err(_) => {
                    diag.error_at(&attr, "expected `#[adjoint(name_of_adjoint_fn)]`");
                    ok = false;
                }
            }
        } else {
            kept.push(attr);
        }
    }
    item.attrs = kept;
    ok.then(|| FnDef {
        name: item.sig.ident.to_string(),
        item,
        params,
        ret,
        adjoint,
        builtin: false,
    })
}

struct Resolver<'a> {
    items: &'a [syn::ItemStruct],
    done: HashMap<String, Rc<StructTy>>,
    consts: &'a [syn::ItemConst],
}

pub const SUPPORTED_TYPES: &str = "f32, bool, u32, i32, Vec2, Vec3, Vec4, Mat2, Mat3, Quat, [T; N], tuples, and the module's structs";

impl Resolver<'_> {
    fn resolve_struct(
        &mut self,
        s: &syn::ItemStruct,
        diag: &Diag,
        stack: &mut Vec<String>,
    ) -> Option<Rc<StructTy>> {
        let name = s.ident.to_string();
        if let Some(t) = self.done.get(&name) {
            return Some(t.clone());
        }
        if stack.contains(&name) {
            diag.error_at(&s.ident, "recursive structs are not supported");
            return None;
        }
        if !s.generics.params.is_empty() {
            diag.error_at(
                &s.generics,
                "generic structs are not supported in a splat module",
            );
            return None;
        }
        let syn::Fields::Named(fields) = &s.fields else {
            diag.error_at(&s.ident, "only structs with named fields are supported");
            return None;
        };
        stack.push(name.clone());
        let mut out = vec![];
        let mut ok = true;
        for f in &fields.named {
            let fname = f.ident.as_ref().expect("named field").to_string();
            let ty = match self.resolve_with_structs(&f.ty, diag, stack) {
                Ok(t) => t,
                Err(msg) => {
                    diag.error_at(&f.ty, msg);
                    ok = false;
                    continue;
                }
            };
            if let Some(block) = crate::blocks::struct_in(&ty)
                && crate::blocks::display(&name).is_none()
            {
                let why = "a building block's struct lives only inside kernels, not in a module's";
                diag.error_at(&f.ty, format!("`{block}`: {why} structs"));
                ok = false;
                continue;
            }
            out.push((fname, ty));
        }
        stack.pop();
        if !ok {
            return None;
        }
        let ident = &s.ident;
        let ty = Rc::new(StructTy {
            display: crate::blocks::display(&name).unwrap_or_else(|| name.clone()),
            path: TokenStreamEq(quote!(#ident)),
            fields: out,
        });
        self.done.insert(name, ty.clone());
        Some(ty)
    }

    fn resolve(&mut self, t: &syn::Type) -> Result<Ty, String> {
        // Struct errors were already reported when the struct itself was parsed.
        let scratch = Diag::default();
        let ty = self.resolve_with_structs(t, &scratch, &mut vec![]);
        scratch.discard();
        ty
    }

    fn resolve_with_structs(
        &mut self,
        t: &syn::Type,
        diag: &Diag,
        stack: &mut Vec<String>,
    ) -> Result<Ty, String> {
        match t {
            syn::Type::Paren(p) => self.resolve_with_structs(&p.elem, diag, stack),
            syn::Type::Group(g) => self.resolve_with_structs(&g.elem, diag, stack),
            syn::Type::Tuple(tt) => {
                let ts: Result<Vec<Ty>, String> = tt
                    .elems
                    .iter()
                    .map(|e| self.resolve_with_structs(e, diag, stack))
                    .collect();
                Ok(Ty::Tuple(ts?))
            }
            syn::Type::Array(a) => {
                let elem = self.resolve_with_structs(&a.elem, diag, stack)?;
                let n = self.const_len(&a.len)?;
                Ok(Ty::Array(Box::new(elem), n))
            }
            syn::Type::Reference(_) => {
                Err("references are only allowed as the outermost type of a parameter".into())
            }
            syn::Type::Path(p) if p.qself.is_none() => {
                let seg = p.path.segments.last().expect("non-empty path");
                let name = match p.path.segments.first() {
                    Some(owner)
                        if p.path.segments.len() == 2 && owner.ident == crate::blocks::PATH =>
                    {
                        crate::blocks::internal(&seg.ident.to_string())
                    }
                    _ => seg.ident.to_string(),
                };
                let args: Vec<Ty> = match &seg.arguments {
                    syn::PathArguments::None => vec![],
                    syn::PathArguments::AngleBracketed(a) => {
                        let mut v = vec![];
                        for arg in &a.args {
                            match arg {
                                syn::GenericArgument::Type(t) => {
                                    v.push(self.resolve_with_structs(t, diag, stack)?)
                                }
                                _ => return Err("only type arguments are supported".into()),
                            }
                        }
                        v
                    }
                    syn::PathArguments::Parenthesized(_) => {
                        return Err("function types are not supported".into());
                    }
                };
                let simple = match name.as_str() {
                    "f32" => Some(Ty::F32),
                    "bool" => Some(Ty::Bool),
                    "u32" => Some(Ty::U32),
                    "i32" => Some(Ty::I32),
                    "Vec2" => Some(Ty::Vec(2)),
                    "Vec3" => Some(Ty::Vec(3)),
                    "Vec4" => Some(Ty::Vec(4)),
                    "Mat2" => Some(Ty::Mat(2)),
                    "Mat3" => Some(Ty::Mat(3)),
                    "Quat" => Some(Ty::Quat),
                    "usize" => Some(Ty::Index),
                    "f64" => {
                        return Err(
                            "`f64` is not supported in kernels: write f32; the f64 twin \
                                    of every function is generated for you"
                                .into(),
                        );
                    }
                    _ => None,
                };
                if let Some(t) = simple {
                    if !args.is_empty() {
                        return Err(format!("`{name}` takes no type arguments"));
                    }
                    return Ok(t);
                }
                if let Some(r) = builtin_struct(&name, &args) {
                    return r;
                }
                if let Some(t) = self.done.get(&name) {
                    return Ok(Ty::Struct(t.clone()));
                }
                if let Some(s) = self.items.iter().find(|s| s.ident == name) {
                    return self
                        .resolve_struct(s, diag, stack)
                        .map(Ty::Struct)
                        .ok_or_else(|| format!("struct `{name}` has errors"));
                }
                Err(format!(
                    "type `{name}` is not supported; supported types: {SUPPORTED_TYPES}"
                ))
            }
            _ => Err(format!(
                "this type is not supported; supported types: {SUPPORTED_TYPES}"
            )),
        }
    }

    fn const_len(&self, e: &syn::Expr) -> Result<usize, String> {
        match e {
            // Tokens from a `macro_rules!` expansion arrive in invisible groups.
            syn::Expr::Group(g) => self.const_len(&g.expr),
            syn::Expr::Paren(p) => self.const_len(&p.expr),
            syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Int(i),
                ..
            }) => i.base10_parse::<usize>().map_err(|e| e.to_string()),
            syn::Expr::Path(p) if p.path.get_ident().is_some() => {
                let name = p.path.get_ident().unwrap();
                let c = self
                    .consts
                    .iter()
                    .find(|c| &c.ident == name)
                    .ok_or_else(|| {
                        format!("array length `{name}` is not a constant of this module")
                    })?;
                self.const_len(&c.expr)
            }
            _ => Err("array lengths must be integer literals or constants of this module".into()),
        }
    }
}
