//! Type checking of function bodies, the stage between the signature check and lowering: the
//! type of every expression of every function and constant, by the rules of [`rules`], with
//! each error at the span of the code at fault. Each body is checked once, whatever calls it.
//!
//! What it leaves to lowering are the facts that depend on values, which only lowering knows:
//! that an index, a loop bound or `powi`'s exponent is a compile-time constant (and in bounds),
//! that a float-to-integer cast does not cut a gradient, that no helper recurses, that the
//! unrolled loops stay within their budget, and that `jacobian` meets no hand-written adjoint.
//! Lowering reads types from the same rules and reports nothing this stage reports.

pub mod rules;

use crate::blocks;
use crate::builtins::{SH_COEFFICIENTS, camera_helper, sh_helper};
use crate::diag::{Diag, Failed, R};
use crate::ir::Unary;
use crate::model::{FnDef, Module};
use crate::types::{Ty, builtin_struct};
use proc_macro2::Span;
use rules::{Arg, Sig};
use std::collections::{HashMap, HashSet};
use syn::spanned::Spanned;

/// What type checking found: the functions and constants with errors (already reported),
/// which lowering skips, as it does every kernel that reaches one of them.
#[derive(Default)]
pub struct Typed {
    failed_fns: HashSet<String>,
    failed_consts: HashSet<String>,
}

impl Typed {
    pub fn fn_failed(&self, name: &str) -> bool {
        self.failed_fns.contains(name)
    }

    pub fn const_failed(&self, name: &str) -> bool {
        self.failed_consts.contains(name)
    }
}

/// Checks the body of every function and the value of every constant of `m`.
pub fn typeck(m: &Module, diag: &Diag) -> Typed {
    let mut typed = Typed::default();
    for name in m.const_names() {
        let c = &m.consts[&name];
        let before = diag.count();
        let mut t = Checker::new(m, diag);
        if let Ok(ty) = t.expr(&c.expr) {
            let _ = t.coerce(&ty, &c.ty, c.expr.span(), &format!("constant `{name}`"));
        }
        if diag.count() > before {
            typed.failed_consts.insert(name);
        }
    }
    for def in &m.fns {
        let before = diag.count();
        Checker::new(m, diag).function(def);
        if diag.count() > before {
            typed.failed_fns.insert(def.name.clone());
        }
    }
    typed
}

#[derive(Clone)]
struct Local {
    ty: Ty,
    mutable: bool,
}

struct Checker<'m> {
    module: &'m Module,
    diag: &'m Diag,
    scopes: Vec<HashMap<String, Local>>,
    /// Inside a `jacobian` closure, the index of its scope: names bound below it are read-only
    /// there (the closure is a map of its argument alone).
    closure_scope: Option<usize>,
}

fn unit() -> Ty {
    Ty::Tuple(vec![])
}

fn is_integer(t: &Ty) -> bool {
    matches!(t, Ty::Index | Ty::U32 | Ty::I32)
}

const INDEX_NOT_CONSTANT: &str =
    "this index must be known at compile time (a literal, a constant or a loop counter)";
const LOOP_BOUNDS: &str =
    "loop bounds must be compile-time constants (`for i in 0..N`): loops are unrolled";

impl<'m> Checker<'m> {
    fn new(module: &'m Module, diag: &'m Diag) -> Self {
        Checker {
            module,
            diag,
            scopes: vec![HashMap::new()],
            closure_scope: None,
        }
    }

    fn err<T>(&self, span: Span, msg: impl std::fmt::Display) -> R<T> {
        self.diag.error(span, msg);
        Err(Failed)
    }

    /// `got` must be `want` (or have failed already).
    fn check_ty(&self, got: &Ty, want: &Ty, span: Span, what: &str) -> R<()> {
        if got == want || *got == Ty::Error || *want == Ty::Error {
            return Ok(());
        }
        self.err(
            span,
            format!("mismatched types: {what} is expected to be `{want}`, found `{got}`"),
        )
    }

    /// `got` must stand where `want` is expected (an integer literal may be a `u32`).
    fn coerce(&self, got: &Ty, want: &Ty, span: Span, what: &str) -> R<()> {
        if rules::coerces(got, want) {
            return Ok(());
        }
        self.check_ty(got, want, span, what)
    }

    fn function(&mut self, def: &FnDef) {
        for p in &def.params {
            self.bind(&p.name, p.ty.clone(), false);
        }
        if let Ok(ty) = self.block(&def.item.block) {
            let last = def.item.block.stmts.last();
            let span = last.map(|s| s.span()).unwrap_or(def.item.sig.ident.span());
            let _ = self.check_ty(&ty, &def.ret, span, "the function's result");
        }
    }

    // ---- scopes ------------------------------------------------------------------------------

    fn bind(&mut self, name: &str, ty: Ty, mutable: bool) {
        let scope = self.scopes.last_mut().expect("a scope");
        scope.insert(name.to_string(), Local { ty, mutable });
    }

    fn lookup(&self, name: &str) -> Option<&Local> {
        self.scopes.iter().rev().find_map(|s| s.get(name))
    }

    fn scoped<T>(&mut self, f: impl FnOnce(&mut Self) -> T) -> T {
        self.scopes.push(HashMap::new());
        let r = f(self);
        self.scopes.pop();
        r
    }

    // ---- blocks and statements ---------------------------------------------------------------

    fn block(&mut self, b: &syn::Block) -> R<Ty> {
        self.scoped(|s| s.stmts_of(&b.stmts))
    }

    fn stmts_of(&mut self, stmts: &[syn::Stmt]) -> R<Ty> {
        let mut failed = false;
        let mut last = unit();
        for (i, s) in stmts.iter().enumerate() {
            let is_last = i + 1 == stmts.len();
            let r = match s {
                syn::Stmt::Local(local) => self.local(local).map(|_| unit()),
                syn::Stmt::Expr(e, semi) => match (self.expr(e), semi) {
                    (Ok(t), None) if is_last => Ok(t),
                    (Ok(t), None) if t != unit() && t != Ty::Error => self.err(
                        e.span(),
                        "a value in the middle of a block is discarded: add `;` or bind it with `let`",
                    ),
                    (Ok(_), _) => Ok(unit()),
                    (Err(f), _) => Err(f),
                },
                syn::Stmt::Item(it) => self.err(
                    it.span(),
                    "items inside functions are not supported: declare them in the module",
                ),
                syn::Stmt::Macro(m) => self.err(
                    m.span(),
                    format!(
                        "macro `{}!` is not supported inside a kernel: kernels compile to GPU code and \
                         SIMD lanes; debug with the generated f64 twin instead",
                        macro_name(&m.mac)
                    ),
                ),
            };
            match r {
                Ok(t) if is_last => last = t,
                Ok(_) => {}
                Err(_) => failed = true,
            }
        }
        if failed { Err(Failed) } else { Ok(last) }
    }

    fn local(&mut self, local: &syn::Local) -> R<()> {
        let Some(init) = &local.init else {
            return self.err(
                local.span(),
                "`let` without a value is not supported: give it a value, or use if/else as an expression",
            );
        };
        if let Some((_, e)) = &init.diverge {
            return self.err(e.span(), "`let ... else` is not supported");
        }
        let (pat, written) = match &local.pat {
            syn::Pat::Type(pt) => (&*pt.pat, Some(&*pt.ty)),
            p => (p, None),
        };
        let ty = match self.expr(&init.expr) {
            Ok(t) => t,
            Err(f) => {
                self.bind_poisoned(pat);
                return Err(f);
            }
        };
        if let Some(t) = written {
            let want = self.resolve_type(t)?;
            self.check_ty(&ty, &want, init.expr.span(), "the value")?;
        }
        self.bind_pattern(pat, ty)
    }

    fn bind_pattern(&mut self, pat: &syn::Pat, ty: Ty) -> R<()> {
        match pat {
            syn::Pat::Ident(pi) if pi.by_ref.is_none() && pi.subpat.is_none() => {
                self.bind(&pi.ident.to_string(), ty, pi.mutability.is_some());
                Ok(())
            }
            syn::Pat::Wild(_) => Ok(()),
            syn::Pat::Tuple(pt) => {
                let Ty::Tuple(tys) = &ty else {
                    return self.err(
                        pat.span(),
                        format!("expected a tuple to destructure, found `{ty}`"),
                    );
                };
                if tys.len() != pt.elems.len() {
                    return self.err(pat.span(), format!("the tuple has {} elements", tys.len()));
                }
                for (p, t) in pt.elems.iter().zip(tys.clone()) {
                    self.bind_pattern(p, t)?;
                }
                Ok(())
            }
            _ => self.err(
                pat.span(),
                "only names, `_` and tuples of them are supported in `let`",
            ),
        }
    }

    /// Binds every name of `pat` to an error type, so its uses report nothing more.
    fn bind_poisoned(&mut self, pat: &syn::Pat) {
        match pat {
            syn::Pat::Ident(pi) => self.bind(&pi.ident.to_string(), Ty::Error, true),
            syn::Pat::Tuple(t) => t.elems.iter().for_each(|p| self.bind_poisoned(p)),
            syn::Pat::Paren(p) => self.bind_poisoned(&p.pat),
            syn::Pat::Type(t) => self.bind_poisoned(&t.pat),
            _ => {}
        }
    }

    fn resolve_type(&self, t: &syn::Type) -> R<Ty> {
        match self.module.resolve_type(t) {
            Ok(t) => Ok(t),
            Err(msg) => self.err(t.span(), msg),
        }
    }

    // ---- places (targets of assignment) ------------------------------------------------------

    /// The root variable of a place and the place's type.
    fn place(&mut self, e: &syn::Expr) -> R<(String, Ty)> {
        let (root, ty) = match e {
            syn::Expr::Path(p) if p.path.get_ident().is_some() => {
                let name = p.path.get_ident().unwrap().to_string();
                let Some(local) = self.lookup(&name) else {
                    return self.err(e.span(), format!("cannot find variable `{name}`"));
                };
                if !local.mutable {
                    return self.err(
                        e.span(),
                        format!("cannot assign to immutable variable `{name}`: declare it with `let mut {name}`"),
                    );
                }
                let ty = local.ty.clone();
                (name, ty)
            }
            syn::Expr::Paren(p) => return self.place(&p.expr),
            syn::Expr::Field(f) => {
                let (root, ty) = self.place(&f.base)?;
                (root, self.member(&ty, &f.member)?)
            }
            syn::Expr::Index(ix) => {
                let (root, ty) = self.place(&ix.expr)?;
                (root, self.element(&ty, ix)?)
            }
            _ => {
                return self.err(
                    e.span(),
                    "this is not assignable: assign to a variable, its fields or elements",
                );
            }
        };
        if ty == Ty::Error {
            return Err(Failed);
        }
        Ok((root, ty))
    }

    fn assign(&mut self, target: &syn::Expr, ty: &Ty) -> R<()> {
        let (root, want) = self.place(target)?;
        let depth = self.scopes.iter().rposition(|s| s.contains_key(&root));
        if let (Some(floor), Some(depth)) = (self.closure_scope, depth)
            && depth < floor
        {
            return self.err(
                target.span(),
                format!(
                    "`jacobian`'s closure cannot assign to `{root}`, declared outside it: the closure is a map of its argument alone"
                ),
            );
        }
        self.check_ty(ty, &want, target.span(), "the assigned value")
    }

    // ---- expressions -------------------------------------------------------------------------

    fn expr(&mut self, e: &syn::Expr) -> R<Ty> {
        use syn::Expr as E;
        match e {
            E::Lit(l) => match rules::literal(&l.lit) {
                Ok((ty, _)) => Ok(ty),
                Err(e) => {
                    self.diag.push_error(e);
                    Err(Failed)
                }
            },
            E::Paren(p) => self.expr(&p.expr),
            E::Group(g) => self.expr(&g.expr),
            E::Reference(r) if r.mutability.is_none() => self.expr(&r.expr),
            E::Unary(u) => self.unary(u),
            E::Binary(b) => self.binary_expr(b),
            E::Path(p) => self.path(p),
            E::Cast(c) => self.cast(c),
            E::Field(f) => {
                let base = self.expr(&f.base)?;
                self.member(&base, &f.member)
            }
            E::Index(ix) => {
                let base = self.expr(&ix.expr)?;
                self.element(&base, ix)
            }
            E::Tuple(t) => {
                let tys = t.elems.iter().map(|e| self.expr(e)).collect::<Vec<_>>();
                Ok(Ty::Tuple(tys.into_iter().collect::<R<_>>()?))
            }
            E::Array(a) => {
                let tys = a.elems.iter().map(|e| self.expr(e)).collect::<Vec<_>>();
                let tys = tys.into_iter().collect::<R<Vec<_>>>()?;
                let Some(first) = tys.first() else {
                    return self.err(a.span(), "empty arrays are not supported");
                };
                for (t, e) in tys.iter().zip(&a.elems) {
                    self.check_ty(t, first, e.span(), "an array element")?;
                }
                Ok(Ty::Array(Box::new(first.clone()), tys.len()))
            }
            E::Repeat(r) => {
                let t = self.expr(&r.expr)?;
                match self.module.array_len(&r.len) {
                    Ok(n) => Ok(Ty::Array(Box::new(t), n)),
                    Err(msg) => self.err(r.len.span(), msg),
                }
            }
            E::Struct(s) => self.struct_lit(s),
            E::Block(b) if b.label.is_none() => self.block(&b.block),
            E::If(i) => self.if_expr(i),
            E::ForLoop(f) => self.for_loop(f),
            E::Assign(a) => {
                let t = self.expr(&a.right)?;
                self.assign(&a.left, &t)?;
                Ok(unit())
            }
            E::MethodCall(m) => self.method_call(m),
            E::Call(c) => self.call(c),
            E::While(_) | E::Loop(_) => self.err(
                e.span(),
                "`while` and `loop` are not supported: use `for i in 0..N` with a constant N (loops are unrolled)",
            ),
            E::Match(_) => self.err(e.span(), "`match` is not supported: use `if` / `else if` / `else`"),
            E::Return(_) => self.err(
                e.span(),
                "`return` is not supported: make the value the last expression of the function, using if/else as an expression",
            ),
            E::Break(_) | E::Continue(_) => {
                self.err(e.span(), "`break` and `continue` are not supported: loops always run all N iterations")
            }
            E::Closure(_) => self.err(
                e.span(),
                "closures are not supported (but as the map of `jacobian(|p| body, x)`): write a helper `fn` in the same module",
            ),
            E::Macro(m) => self.err(
                e.span(),
                format!("macro `{}!` is not supported inside a kernel", macro_name(&m.mac)),
            ),
            E::Try(_) => self.err(e.span(), "the `?` operator is not supported: kernels cannot fail"),
            E::Unsafe(_) => self.err(e.span(), "`unsafe` is not supported in kernels"),
            E::Reference(_) => self.err(e.span(), "`&mut` is not supported: kernels are pure"),
            E::Range(_) => self.err(e.span(), "ranges are only supported as the bounds of a `for` loop"),
            _ => self.err(e.span(), "this expression is not supported in a splat kernel"),
        }
    }

    fn member(&self, base: &Ty, member: &syn::Member) -> R<Ty> {
        let name = match member {
            syn::Member::Named(id) => id.to_string(),
            syn::Member::Unnamed(i) => i.index.to_string(),
        };
        match rules::member(base, &name) {
            Some((ty, _)) => Ok(ty),
            None if *base == Ty::Error => Err(Failed),
            None => self.err(member.span(), format!("no field `{name}` on type `{base}`")),
        }
    }

    /// The type of `base[i]`; the index is an integer (lowering checks it is a constant).
    fn element(&mut self, base: &Ty, ix: &syn::ExprIndex) -> R<Ty> {
        let index = self.expr(&ix.index)?;
        if !is_integer(&index) {
            return self.err(ix.index.span(), INDEX_NOT_CONSTANT);
        }
        match rules::element(base) {
            Some(t) => Ok(t),
            None if *base == Ty::Error => Err(Failed),
            None => self.err(
                ix.span(),
                format!("cannot index into a value of type `{base}`"),
            ),
        }
    }

    fn path(&mut self, p: &syn::ExprPath) -> R<Ty> {
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        if let [name] = segs.as_slice() {
            if let Some(local) = self.lookup(name) {
                return match local.ty {
                    Ty::Error => Err(Failed),
                    ref t => Ok(t.clone()),
                };
            }
            if let Some(c) = self.module.consts.get(name) {
                return Ok(c.ty.clone());
            }
            return self.err(
                p.span(),
                format!("cannot find `{name}` in this function or module"),
            );
        }
        let n = segs.len();
        match rules::assoc_const(&segs[n - 2], &segs[n - 1]) {
            Some((ty, _)) => Ok(ty),
            None => self.err(p.span(), format!("unknown constant `{}`", segs.join("::"))),
        }
    }

    fn unary(&mut self, u: &syn::ExprUnary) -> R<Ty> {
        let t = self.expr(&u.expr)?;
        match u.op {
            syn::UnOp::Deref(_) => Ok(t),
            syn::UnOp::Neg(_) => match rules::neg(&t) {
                Some(t) => Ok(t),
                None => self.err(u.span(), format!("cannot negate a value of type `{t}`")),
            },
            syn::UnOp::Not(_) if rules::not(&t) => Ok(t),
            syn::UnOp::Not(_) => self.err(
                u.span(),
                format!("cannot apply `!` to a value of type `{t}`"),
            ),
            _ => self.err(u.span(), "this operator is not supported"),
        }
    }

    fn binary_expr(&mut self, b: &syn::ExprBinary) -> R<Ty> {
        let l = self.expr(&b.left)?;
        let r = self.expr(&b.right)?;
        let Some((op, sym, compound)) = rules::binary_op(&b.op) else {
            return self.err(b.op.span(), "this operator is not supported");
        };
        if l == Ty::Error || r == Ty::Error {
            return Err(Failed);
        }
        let (lo, ro) = rules::binary_operands(&l, &r);
        let Some(t) = rules::binary(op, &lo, &ro) else {
            return self.err(b.span(), rules::binary_error(sym, &l, &r));
        };
        if compound {
            self.assign(&b.left, &t)?;
            return Ok(unit());
        }
        Ok(t)
    }

    fn cast(&mut self, c: &syn::ExprCast) -> R<Ty> {
        let from = self.expr(&c.expr)?;
        let to = match rules::cast_target(&c.ty) {
            Ok(to) => to,
            Err(msg) => return self.err(c.ty.span(), msg),
        };
        match rules::cast(&from, to) {
            Ok(t) => Ok(t),
            Err(msg) => self.err(c.span(), msg),
        }
    }

    fn struct_lit(&mut self, s: &syn::ExprStruct) -> R<Ty> {
        if let Some(rest) = &s.rest {
            return self.err(rest.span(), "`..base` is not supported: list every field");
        }
        let name = s
            .path
            .segments
            .last()
            .map(|x| x.ident.to_string())
            .unwrap_or_default();
        let mut given = vec![];
        for f in &s.fields {
            let syn::Member::Named(id) = &f.member else {
                return self.err(f.span(), "tuple structs are not supported");
            };
            given.push((id.to_string(), self.expr(&f.expr)?, f.span()));
        }
        let field = |n: &str| {
            let g = given.iter().find(|g| g.0 == n);
            g.map(|g| g.1.clone()).unwrap_or(Ty::Error)
        };
        let ty = if let Some(t) = self.module.find_struct(&name) {
            Ty::Struct(t.clone())
        } else {
            let args = match name.as_str() {
                "Projected" => vec![field("cull"), field("shade")],
                "Contribution" => vec![field("color")],
                _ => vec![],
            };
            match builtin_struct(&name, &args) {
                Some(Ok(t)) => t,
                Some(Err(m)) => return self.err(s.path.span(), m),
                None => return self.err(s.path.span(), format!("unknown struct `{name}`")),
            }
        };
        let Ty::Struct(st) = &ty else { unreachable!() };
        for (fname, fty) in &st.fields {
            let Some(pos) = given.iter().position(|g| &g.0 == fname) else {
                return self.err(s.span(), format!("missing field `{fname}` in `{name}`"));
            };
            let (_, t, span) = given.remove(pos);
            self.coerce(&t, fty, span, &format!("field `{fname}`"))?;
        }
        if let Some((extra, _, span)) = given.first() {
            return self.err(*span, format!("`{name}` has no field `{extra}`"));
        }
        Ok(ty)
    }

    // ---- control flow ------------------------------------------------------------------------

    fn if_expr(&mut self, e: &syn::ExprIf) -> R<Ty> {
        let c = self.expr(&e.cond)?;
        self.check_ty(&c, &Ty::Bool, e.cond.span(), "an `if` condition")?;
        let then_ty = self.block(&e.then_branch);
        let else_ty = match &e.else_branch {
            Some((_, els)) => self.expr(els),
            None => Ok(unit()),
        };
        let (then_ty, else_ty) = (then_ty?, else_ty?);
        if e.else_branch.is_none() && then_ty != unit() {
            return self.err(
                e.then_branch.span(),
                "an `if` without `else` cannot produce a value: add an `else` branch",
            );
        }
        if then_ty != else_ty && then_ty != Ty::Error && else_ty != Ty::Error {
            return self.err(
                e.span(),
                format!("`if` and `else` have different types: `{then_ty}` and `{else_ty}`"),
            );
        }
        Ok(then_ty)
    }

    fn for_loop(&mut self, f: &syn::ExprForLoop) -> R<Ty> {
        let syn::Expr::Range(r) = &*f.expr else {
            return self.err(
                f.expr.span(),
                "only `for i in A..B` with constant A and B is supported",
            );
        };
        if let Some(start) = &r.start {
            self.bound(start)?;
        }
        let Some(end) = &r.end else {
            return self.err(r.span(), "loops need an upper bound: `for i in 0..N`");
        };
        self.bound(end)?;
        self.scoped(|s| {
            s.bind_pattern(&f.pat, Ty::Index)?;
            let body = s.block(&f.body)?;
            if body != unit() && body != Ty::Error {
                return s.err(
                    f.body.span(),
                    "a loop body cannot produce a value: end it with `;`",
                );
            }
            Ok(unit())
        })
    }

    /// A loop bound: an integer (lowering checks it is a constant).
    fn bound(&mut self, e: &syn::Expr) -> R<()> {
        let t = self.expr(e)?;
        if !is_integer(&t) {
            return self.err(e.span(), LOOP_BOUNDS);
        }
        Ok(())
    }

    // ---- calls -------------------------------------------------------------------------------

    fn args_of(
        &mut self,
        args: &syn::punctuated::Punctuated<syn::Expr, syn::Token![,]>,
    ) -> R<Vec<Ty>> {
        let tys: Vec<R<Ty>> = args.iter().map(|a| self.expr(a)).collect();
        tys.into_iter().collect()
    }

    /// Checks `args` (written at `spans`) against `sig`; `callee` names it in messages and
    /// `what` is the default name of an argument.
    fn apply(
        &self,
        sig: Sig,
        args: &[Ty],
        spans: &[Span],
        callee: &str,
        what: &str,
        span: Span,
    ) -> R<Ty> {
        let n = sig.args.len();
        if args.len() != n {
            return self.err(
                span,
                format!("`{callee}` takes {n} argument(s), found {}", args.len()),
            );
        }
        for ((want, got), at) in sig.args.iter().zip(args).zip(spans) {
            match want {
                Arg::Is(t, name) => self.check_ty(got, t, span, name.as_deref().unwrap_or(what))?,
                Arg::Integer(msg) if !is_integer(got) && *got != Ty::Error => {
                    return self.err(*at, msg);
                }
                Arg::Integer(_) => {}
            }
        }
        Ok(sig.ret)
    }

    fn method_call(&mut self, m: &syn::ExprMethodCall) -> R<Ty> {
        if m.turbofish.is_some() {
            return self.err(m.span(), "turbofish arguments are not supported");
        }
        let recv = self.expr(&m.receiver)?;
        let args = self.args_of(&m.args)?;
        let spans: Vec<Span> = m.args.iter().map(|a| a.span()).collect();
        let name = m.method.to_string();
        self.method(&name, recv, &args, &spans, m.method.span())
    }

    fn method(&self, name: &str, recv: Ty, args: &[Ty], spans: &[Span], span: Span) -> R<Ty> {
        if recv == Ty::Error {
            return Err(Failed);
        }
        if crate::types::is_camera(&recv)
            && let Some(helper) = camera_helper(name)
        {
            let def = self
                .module
                .find_fn(&helper)
                .expect("builtin camera helpers are in every module");
            let all: Vec<Ty> = std::iter::once(recv).chain(args.iter().cloned()).collect();
            return self.call_helper(def, &all, span);
        }
        match rules::method(&recv, name) {
            Some(sig) => self.apply(
                sig,
                args,
                spans,
                name,
                &format!("the argument of `{name}`"),
                span,
            ),
            None => {
                let hint = match rules::suggestion(&recv, name) {
                    Some(s) => format!(": did you mean `{s}`?"),
                    None => " (see the intrinsic list in the splat-macros docs)".to_string(),
                };
                self.err(
                    span,
                    format!("no method `{name}` on `{recv}` in the supported subset{hint}"),
                )
            }
        }
    }

    fn call_helper(&self, def: &FnDef, args: &[Ty], span: Span) -> R<Ty> {
        if args.len() != def.params.len() {
            return self.err(
                span,
                format!(
                    "`{}` takes {} argument(s), found {}",
                    def.name,
                    def.params.len(),
                    args.len()
                ),
            );
        }
        for (a, p) in args.iter().zip(&def.params) {
            self.check_ty(a, &p.ty, span, &format!("argument `{}`", p.name))?;
        }
        Ok(def.ret.clone())
    }

    fn call(&mut self, c: &syn::ExprCall) -> R<Ty> {
        let syn::Expr::Path(p) = &*c.func else {
            return self.err(c.func.span(), "only calls of named functions are supported");
        };
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        let span = p.span();
        if let [name] = segs.as_slice() {
            if let Some(local) = self.lookup(name) {
                if local.ty == Ty::Error {
                    return Err(Failed);
                }
                return self.err(span, format!("`{name}` is a value, not a function"));
            }
            if let Some(def) = self.module.find_fn(name) {
                let args = self.args_of(&c.args)?;
                return self.call_helper(def, &args, span);
            }
            return self.free_intrinsic(name, c, span);
        }
        let (owner, item) = (&segs[segs.len() - 2], &segs[segs.len() - 1]);
        if let [blocks::PATH, name] = [owner.as_str(), item.as_str()] {
            return match self.module.find_fn(&blocks::internal(name)) {
                Some(def) => {
                    let args = self.args_of(&c.args)?;
                    self.call_helper(def, &args, span)
                }
                None => self.err(span, unknown_block(name)),
            };
        }
        let args = self.args_of(&c.args)?;
        let spans: Vec<Span> = c.args.iter().map(|a| a.span()).collect();
        match rules::path_call(owner, item) {
            Some(rules::Path::Constructor(sig)) => {
                let callee = format!("{owner}::{item}");
                self.apply(
                    sig,
                    &args,
                    &spans,
                    &callee,
                    &format!("an argument of `{callee}`"),
                    span,
                )
            }
            Some(rules::Path::Method) if args.is_empty() => {
                self.err(span, format!("`{owner}::{item}` needs an argument"))
            }
            Some(rules::Path::Method) => {
                let recv = args[0].clone();
                self.method(item, recv, &args[1..], &spans[1..], span)
            }
            None => self.err(span, unknown_path(owner, item)),
        }
    }

    fn free_intrinsic(&mut self, name: &str, c: &syn::ExprCall, span: Span) -> R<Ty> {
        match name {
            "select" => {
                if c.args.len() != 3 {
                    return self.err(span, "`select(cond, a, b)` takes 3 arguments");
                }
                let cond = self.expr(&c.args[0])?;
                self.check_ty(
                    &cond,
                    &Ty::Bool,
                    c.args[0].span(),
                    "the condition of `select`",
                )?;
                let (a, b) = (self.expr(&c.args[1]), self.expr(&c.args[2]));
                let (a, b) = (a?, b?);
                if a != b {
                    return self.err(
                        span,
                        format!("the two values have different types: `{a}` and `{b}`"),
                    );
                }
                Ok(a)
            }
            _ if matches!(name, "no_diff" | "sigmoid") || Unary::function(name).is_some() => {
                let args = self.args_of(&c.args)?;
                let [t] = args.as_slice() else {
                    return self.err(span, format!("`{name}` takes 1 argument"));
                };
                match name {
                    "no_diff" => Ok(t.clone()),
                    _ if *t != Ty::F32 => {
                        self.err(span, format!("`{name}` takes an `f32`, found `{t}`"))
                    }
                    _ => Ok(Ty::F32),
                }
            }
            "jacobian" => self.jacobian(c, span),
            "spherical_harmonics" => {
                let args = self.args_of(&c.args)?;
                let n = match args.first() {
                    Some(Ty::Array(t, n)) if **t == Ty::Vec(3) && SH_COEFFICIENTS.contains(n) => *n,
                    _ => {
                        return self.err(
                            span,
                            "`spherical_harmonics(sh, dir)` takes `[Vec3; N]` with N = 1, 4, 9 or 16 (degree 0 to 3) and a `Vec3`",
                        );
                    }
                };
                let def = self
                    .module
                    .find_fn(&sh_helper(n))
                    .expect("builtin SH helpers are in every module");
                self.call_helper(def, &args, span)
            }
            _ => {
                if let Some(m) = rules::free_as_method(name) {
                    let args = self.args_of(&c.args)?;
                    if args.is_empty() {
                        return self.err(span, format!("`{name}` needs an argument"));
                    }
                    let spans: Vec<Span> = c.args.iter().map(|a| a.span()).collect();
                    return self.method(m, args[0].clone(), &args[1..], &spans[1..], span);
                }
                self.err(
                    span,
                    format!(
                        "cannot find function `{name}`: a kernel may call helpers of the same module and the \
                         intrinsics {}",
                        rules::INTRINSIC_LIST
                    ),
                )
            }
        }
    }

    /// `jacobian(|p| body, x)`.
    fn jacobian(&mut self, c: &syn::ExprCall, span: Span) -> R<Ty> {
        let usage = "`jacobian(|p| body, x)` takes a closure of one argument and the point to differentiate it at";
        let (Some(syn::Expr::Closure(closure)), Some(point), 2) =
            (c.args.first(), c.args.get(1), c.args.len())
        else {
            return self.err(span, usage);
        };
        if closure.inputs.len() != 1 {
            return self.err(closure.span(), usage);
        }
        let x = self.expr(point)?;
        if !rules::differentiable(&x) {
            return self.err(
                point.span(),
                format!(
                    "`jacobian` differentiates at an `f32`, `Vec2`, `Vec3` or `Vec4`, found `{x}`"
                ),
            );
        }
        let pattern = match &closure.inputs[0] {
            syn::Pat::Type(typed) => {
                let written = self.resolve_type(&typed.ty)?;
                self.check_ty(&x, &written, typed.ty.span(), "the closure's argument")?;
                &*typed.pat
            }
            pattern => pattern,
        };
        let value = self.scoped(|s| {
            let enclosing = s.closure_scope.replace(s.scopes.len() - 1);
            let value = s
                .bind_pattern(pattern, x.clone())
                .and_then(|_| s.expr(&closure.body));
            s.closure_scope = enclosing;
            value
        })?;
        if let syn::ReturnType::Type(_, written) = &closure.output {
            let want = self.resolve_type(written)?;
            self.check_ty(&value, &want, written.span(), "the closure's result")?;
        }
        if !rules::differentiable(&value) {
            return self.err(
                closure.body.span(),
                format!("`jacobian` differentiates a map to an `f32`, `Vec2`, `Vec3` or `Vec4`, found `{value}`"),
            );
        }
        Ok(rules::jacobian(&x, &value))
    }
}

fn macro_name(m: &syn::Macro) -> String {
    m.path
        .segments
        .last()
        .map(|s| s.ident.to_string())
        .unwrap_or_default()
}

/// `blocks::name` where the library has no `name`: what it has.
fn unknown_block(name: &str) -> String {
    format!(
        "splat's building blocks have no `{name}`; they are:\n{}",
        block_list()
    )
}

/// A call of `owner::item` that is neither a constructor, a method in path form nor a block:
/// usually a function of another module, which a kernel cannot see.
fn unknown_path(owner: &str, item: &str) -> String {
    format!(
        "unknown function `{owner}::{item}`: a kernel calls only the functions of its own \
         module, the intrinsics (`sqrt(x)`, `sigmoid(x)`, `spherical_harmonics(sh, dir)`, ...), \
         the camera's methods (`cam.project_point(p)`, ...) and splat's building blocks:\n{}\n\
         To share functions of your own between methods, write the modules with one \
         `macro_rules!` that emits both (as `methods/src/gs3d.rs` does for its five variants).",
        block_list()
    )
}

fn block_list() -> String {
    let lines: Vec<String> = (blocks::signatures().iter())
        .map(|s| format!("    {}::{s}", blocks::PATH))
        .collect();
    lines.join("\n")
}
