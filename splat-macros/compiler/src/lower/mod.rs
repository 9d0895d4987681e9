//! Lowering: translates one type-checked function (`crate::typeck`) into the scalar SSA IR,
//! flattening every vector, matrix, array and struct into scalars, inlining helpers and
//! unrolling constant loops. The errors it reports are those that depend on values (see
//! `typeck`'s docs), with the span of the offending code.
//!
//! - `mod.rs`: the lowerer's state, the IR builder (with integer constant folding and activity
//!   tracking), statements, places and control flow.
//! - `expr.rs`: expressions (operators, literals, paths, casts, struct literals).
//! - `intrinsics.rs`: method calls on glam types and the free intrinsic functions.
//! - `jacobian.rs`: the `jacobian` intrinsic, forward-mode differentiation inside a kernel.

mod expr;
pub(crate) mod intrinsics;
mod jacobian;

use crate::diag::{Diag, Failed, R};
use crate::ir::{Binary, Block, Const, Function, Op, Scalar, Stmt, Unary, Var};
use crate::model::{FnDef, Module};
use crate::typeck::Typed;
use crate::types::Ty;
use proc_macro2::Span;
use std::collections::{HashMap, HashSet};
use syn::spanned::Spanned;

/// A typed source-level value: its type and the IR scalars it flattens to.
#[derive(Clone, Debug, PartialEq)]
pub struct Val {
    pub ty: Ty,
    pub comps: Vec<Var>,
}

impl Val {
    fn unit() -> Val {
        Val {
            ty: Ty::Tuple(vec![]),
            comps: vec![],
        }
    }
    fn error() -> Val {
        Val {
            ty: Ty::Error,
            comps: vec![],
        }
    }
}

/// A lowered function with its source-level signature.
pub struct Lowered {
    pub func: Function,
    pub params: Vec<(String, Ty)>,
    pub ret: Ty,
    /// Whether the function reads the camera model (`cam.project_point` / `cam.pixel_ray`).
    pub camera_model: bool,
    /// Whether the function reads the camera's rolling shutter (`builtins::shutter_aware`).
    pub rolling_shutter: bool,
    /// The parameter slot holding the camera's model code, if a parameter is a `Camera`.
    pub model_slot: Option<Var>,
}

/// Most iterations all unrolled loops of one function may have together.
const UNROLL_LIMIT: usize = 4096;

pub struct Lowerer<'m> {
    module: &'m Module,
    typed: &'m Typed,
    diag: &'m Diag,
    f: Function,
    consts: HashMap<Var, Const>,
    active: HashSet<Var>,
    scopes: Vec<HashMap<String, Val>>,
    stmts: Vec<Stmt>,
    call_stack: Vec<String>,
    unrolled: usize,
    /// Helpers with a user-written adjoint; the index is the `callee` of [`Stmt::Call`].
    custom: &'m [String],
    /// Set when a model-aware camera method is called.
    camera_model: bool,
    /// Set when a camera method reading the rolling shutter is called.
    rolling_shutter: bool,
}

/// The module being lowered, with what type checking found in it.
#[derive(Clone, Copy)]
pub struct Source<'m> {
    pub module: &'m Module,
    pub typed: &'m Typed,
}

/// Lowers one function of `src`. Returns `None` if it had errors (recorded in `diag`).
pub fn lower_fn(src: Source, diag: &Diag, def: &FnDef, custom: &[String]) -> Option<Lowered> {
    lower_for_model(src, diag, def, custom, None)
}

/// Lowers one function with the camera's model code known to be `model` (when given): every
/// comparison with it folds, so only that model's branches are lowered (the specialized
/// variant of a model-aware kernel; the model slot stays a parameter).
pub fn lower_for_model(
    src: Source,
    diag: &Diag,
    def: &FnDef,
    custom: &[String],
    model: Option<u32>,
) -> Option<Lowered> {
    if src.typed.fn_failed(&def.name) {
        return None;
    }
    let mut l = Lowerer {
        module: src.module,
        typed: src.typed,
        diag,
        f: Function::new(def.name.clone()),
        consts: HashMap::new(),
        active: HashSet::new(),
        scopes: vec![HashMap::new()],
        stmts: vec![],
        call_stack: vec![def.name.clone()],
        unrolled: 0,
        custom,
        camera_model: false,
        rolling_shutter: false,
    };
    let mut params = vec![];
    let mut model_slot = None;
    for p in &def.params {
        let names = p.ty.slot_names(&p.name);
        let model_name = crate::types::is_camera(&p.ty).then(|| format!("{}_model", p.name));
        let comps: Vec<Var> =
            p.ty.slots()
                .into_iter()
                .zip(names)
                .map(|(s, n)| {
                    let is_model = model_name.as_ref() == Some(&n);
                    let v = l.f.new_var(s, n);
                    if s == Scalar::F32 {
                        l.active.insert(v);
                    }
                    if is_model {
                        model_slot = Some(v);
                        if let Some(code) = model {
                            l.consts.insert(v, Const::U(code));
                        }
                    }
                    v
                })
                .collect();
        l.f.params.extend(&comps);
        l.bind(
            &p.name,
            Val {
                ty: p.ty.clone(),
                comps,
            },
        );
        params.push((p.name.clone(), p.ty.clone()));
    }
    let errors_before = diag.count();
    let body = l.block(&def.item.block);
    match body {
        Ok(v) if diag.count() == errors_before => {
            l.f.body = Block {
                stmts: std::mem::take(&mut l.stmts),
                yields: v.comps,
            };
            Some(Lowered {
                func: l.f,
                params,
                ret: def.ret.clone(),
                camera_model: l.camera_model,
                rolling_shutter: l.rolling_shutter,
                model_slot,
            })
        }
        _ => None,
    }
}

impl<'m> Lowerer<'m> {
    // ---- the IR builder ----------------------------------------------------------------------

    fn err<T>(&self, span: Span, msg: impl std::fmt::Display) -> R<T> {
        self.diag.error(span, msg);
        Err(Failed)
    }

    fn konst(&mut self, c: Const) -> Var {
        let name = match c {
            Const::F(_) => "c",
            _ => "k",
        };
        let v = self.f.new_var(c.ty(), name);
        self.consts.insert(v, c);
        self.stmts.push(Stmt::Let {
            var: v,
            op: Op::Const(c),
        });
        v
    }

    fn fconst(&mut self, x: f64) -> Var {
        self.konst(Const::F(x))
    }

    fn const_of(&self, v: Var) -> Option<Const> {
        self.consts.get(&v).copied()
    }

    fn is_active(&self, v: Var) -> bool {
        self.active.contains(&v)
    }

    /// Appends `op` (folding integer and boolean constants) and returns its value.
    fn emit(&mut self, op: Op) -> Var {
        if let Some(v) = self.fold(&op) {
            return v;
        }
        let ty = op.result_ty(|v| self.f.ty(v));
        let v = self.f.new_var(ty, "t");
        let no_diff = matches!(op, Op::Unary(Unary::NoDiff, _));
        if ty == Scalar::F32 && !no_diff && op.operands().iter().any(|o| self.is_active(*o)) {
            self.active.insert(v);
        }
        self.stmts.push(Stmt::Let { var: v, op });
        v
    }

    fn fold(&mut self, op: &Op) -> Option<Var> {
        use Const::*;
        match *op {
            Op::Select(c, a, b) => match self.const_of(c)? {
                B(true) => Some(a),
                B(false) => Some(b),
                _ => None,
            },
            Op::Unary(u, a) => {
                let c = self.const_of(a)?;
                let r = match (u, c) {
                    // Negation is exact, so folding it cannot change the f32 result.
                    (Unary::Neg, F(x)) => F(-x),
                    (Unary::Neg, I(x)) => I(x.wrapping_neg()),
                    (Unary::Not, B(x)) => B(!x),
                    (Unary::Not, U(x)) => U(!x),
                    (Unary::Not, I(x)) => I(!x),
                    (Unary::Cast(Scalar::F32), U(x)) => F(x as f64),
                    (Unary::Cast(Scalar::F32), I(x)) => F(x as f64),
                    (Unary::Cast(Scalar::U32), U(x)) => U(x),
                    (Unary::Cast(Scalar::U32), I(x)) => U(x as u32),
                    (Unary::Cast(Scalar::U32), B(x)) => U(x as u32),
                    (Unary::Cast(Scalar::I32), U(x)) => I(x as i32),
                    (Unary::Cast(Scalar::I32), I(x)) => I(x),
                    (Unary::Cast(Scalar::I32), B(x)) => I(x as i32),
                    _ => return None,
                };
                Some(self.konst(r))
            }
            Op::Binary(op, a, b) => {
                let (x, y) = (self.const_of(a)?, self.const_of(b)?);
                let r = match (x, y) {
                    (U(x), U(y)) => match op {
                        Binary::Add => U(x.wrapping_add(y)),
                        Binary::Sub => U(x.wrapping_sub(y)),
                        Binary::Mul => U(x.wrapping_mul(y)),
                        Binary::Div => U(x.checked_div(y).unwrap_or(0)),
                        Binary::Rem => U(x.checked_rem(y).unwrap_or(0)),
                        Binary::Min => U(x.min(y)),
                        Binary::Max => U(x.max(y)),
                        Binary::And => U(x & y),
                        Binary::Or => U(x | y),
                        Binary::Xor => U(x ^ y),
                        Binary::Shl => U(x.wrapping_shl(y)),
                        Binary::Shr => U(x.wrapping_shr(y)),
                        Binary::Lt => B(x < y),
                        Binary::Le => B(x <= y),
                        Binary::Gt => B(x > y),
                        Binary::Ge => B(x >= y),
                        Binary::Eq => B(x == y),
                        Binary::Ne => B(x != y),
                        _ => return None,
                    },
                    (I(x), I(y)) => match op {
                        Binary::Add => I(x.wrapping_add(y)),
                        Binary::Sub => I(x.wrapping_sub(y)),
                        Binary::Mul => I(x.wrapping_mul(y)),
                        Binary::Div => I(x.checked_div(y).unwrap_or(0)),
                        Binary::Rem => I(x.checked_rem(y).unwrap_or(0)),
                        Binary::Min => I(x.min(y)),
                        Binary::Max => I(x.max(y)),
                        Binary::And => I(x & y),
                        Binary::Or => I(x | y),
                        Binary::Xor => I(x ^ y),
                        Binary::Shl => I(x.wrapping_shl(y as u32)),
                        Binary::Shr => I(x.wrapping_shr(y as u32)),
                        Binary::Lt => B(x < y),
                        Binary::Le => B(x <= y),
                        Binary::Gt => B(x > y),
                        Binary::Ge => B(x >= y),
                        Binary::Eq => B(x == y),
                        Binary::Ne => B(x != y),
                        _ => return None,
                    },
                    // Float arithmetic folds only where it is exact in f32 (operands and
                    // result f32 values, the f64 result equal to the f32 one), so the f32
                    // kernels and their f64 twins compute what they did unfolded.
                    (F(x), F(y)) => {
                        let r = match op {
                            Binary::Add => x + y,
                            Binary::Sub => x - y,
                            Binary::Mul => x * y,
                            Binary::Div => x / y,
                            _ => return None,
                        };
                        let exact = |v: f64| v.is_finite() && (v as f32) as f64 == v;
                        if !(exact(x) && exact(y) && exact(r)) {
                            return None;
                        }
                        F(r)
                    }
                    (B(x), B(y)) => match op {
                        Binary::And => B(x & y),
                        Binary::Or => B(x | y),
                        Binary::Xor | Binary::Ne => B(x ^ y),
                        Binary::Eq => B(x == y),
                        _ => return None,
                    },
                    _ => return None,
                };
                Some(self.konst(r))
            }
            Op::Const(_) => None,
        }
    }

    fn un(&mut self, op: Unary, a: Var) -> Var {
        self.emit(Op::Unary(op, a))
    }

    fn bin(&mut self, op: Binary, a: Var, b: Var) -> Var {
        self.emit(Op::Binary(op, a, b))
    }

    fn select(&mut self, c: Var, a: Var, b: Var) -> Var {
        self.emit(Op::Select(c, a, b))
    }

    /// Builds `if cond { then() } else { els() }` as a structured branch whose blocks are only
    /// differentiated on the side taken, so an overflow on the other side cannot leak a NaN.
    fn branch(
        &mut self,
        cond: Var,
        then: impl FnOnce(&mut Self) -> R<Val>,
        els: impl FnOnce(&mut Self) -> R<Val>,
    ) -> R<Val> {
        let outer = std::mem::take(&mut self.stmts);
        let a = then(self);
        let then_stmts = std::mem::take(&mut self.stmts);
        let b = els(self);
        let else_stmts = std::mem::replace(&mut self.stmts, outer);
        let (a, b) = (a?, b?);
        let outs = self.join_branches(
            cond,
            Block {
                stmts: then_stmts,
                yields: a.comps,
            },
            Block {
                stmts: else_stmts,
                yields: b.comps,
            },
        );
        Ok(Val {
            ty: a.ty,
            comps: outs,
        })
    }

    fn join_branches(&mut self, cond: Var, then_block: Block, else_block: Block) -> Vec<Var> {
        let outs: Vec<Var> = then_block
            .yields
            .iter()
            .zip(&else_block.yields)
            .map(|(a, b)| {
                let v = self.f.new_var(self.f.ty(*a), self.f.name(*a).to_string());
                if self.is_active(*a) || self.is_active(*b) {
                    self.active.insert(v);
                }
                v
            })
            .collect();
        self.stmts.push(Stmt::If {
            cond,
            then_block,
            else_block,
            outs: outs.clone(),
        });
        outs
    }

    // ---- scopes ------------------------------------------------------------------------------

    fn bind(&mut self, name: &str, val: Val) {
        // Give temporaries the readable name of the binding they end up in.
        let names = val.ty.slot_names(name);
        for (v, n) in val.comps.iter().zip(names) {
            let info = &mut self.f.vars[v.0 as usize];
            if info.name == "t" {
                info.name = n;
            }
        }
        self.scopes
            .last_mut()
            .expect("a scope")
            .insert(name.to_string(), val);
    }

    fn lookup(&self, name: &str) -> Option<&Val> {
        self.scopes.iter().rev().find_map(|s| s.get(name))
    }

    fn lookup_mut(&mut self, name: &str) -> Option<&mut Val> {
        self.scopes.iter_mut().rev().find_map(|s| s.get_mut(name))
    }

    // ---- blocks and statements ---------------------------------------------------------------

    fn block(&mut self, b: &syn::Block) -> R<Val> {
        self.scopes.push(HashMap::new());
        let r = self.stmts_of(&b.stmts);
        self.scopes.pop();
        r
    }

    fn stmts_of(&mut self, stmts: &[syn::Stmt]) -> R<Val> {
        let mut failed = false;
        let mut last = Val::unit();
        for (i, s) in stmts.iter().enumerate() {
            let is_last = i + 1 == stmts.len();
            let r = match s {
                syn::Stmt::Local(local) => self.local(local).map(|_| Val::unit()),
                syn::Stmt::Expr(e, semi) => match (self.expr(e), semi) {
                    (Ok(v), None) if is_last => Ok(v),
                    (r, _) => r.map(|_| Val::unit()),
                },
                _ => expr::unchecked("an item or macro statement"),
            };
            match r {
                Ok(v) if is_last => last = v,
                Ok(_) => {}
                Err(_) => failed = true,
            }
        }
        if failed { Err(Failed) } else { Ok(last) }
    }

    fn local(&mut self, local: &syn::Local) -> R<()> {
        let init = local
            .init
            .as_ref()
            .expect("type-checked: `let` has a value");
        let pat = match &local.pat {
            syn::Pat::Type(pt) => &*pt.pat,
            p => p,
        };
        match self.expr(&init.expr) {
            Ok(v) => {
                self.bind_pattern(pat, v);
                Ok(())
            }
            Err(f) => {
                self.bind_pattern_poisoned(pat);
                Err(f)
            }
        }
    }

    fn bind_pattern(&mut self, pat: &syn::Pat, val: Val) {
        match pat {
            syn::Pat::Ident(pi) => self.bind(&pi.ident.to_string(), val),
            syn::Pat::Wild(_) => {}
            syn::Pat::Tuple(pt) => {
                let Ty::Tuple(tys) = &val.ty else {
                    expr::unchecked("a tuple pattern on a non-tuple")
                };
                let mut at = 0;
                for (p, t) in pt.elems.iter().zip(tys.clone()) {
                    let n = t.slot_count();
                    let comps = val.comps[at..at + n].to_vec();
                    self.bind_pattern(p, Val { ty: t, comps });
                    at += n;
                }
            }
            _ => expr::unchecked("an unsupported pattern"),
        }
    }

    /// Binds every name of `pat` to an error value, so its uses report nothing more.
    fn bind_pattern_poisoned(&mut self, pat: &syn::Pat) {
        match pat {
            syn::Pat::Ident(pi) => self.bind(&pi.ident.to_string(), Val::error()),
            syn::Pat::Tuple(t) => t.elems.iter().for_each(|p| self.bind_pattern_poisoned(p)),
            syn::Pat::Paren(p) => self.bind_pattern_poisoned(&p.pat),
            syn::Pat::Type(t) => self.bind_pattern_poisoned(&t.pat),
            _ => {}
        }
    }

    // ---- places (targets of assignment) ------------------------------------------------------

    /// The root variable of a place and the range of its components the place covers.
    fn place(&mut self, e: &syn::Expr) -> R<(String, Ty, std::ops::Range<usize>)> {
        match e {
            syn::Expr::Path(p) => {
                let name = p.path.get_ident().expect("type-checked place").to_string();
                let b = self.lookup(&name).expect("type-checked place");
                Ok((name, b.ty.clone(), 0..b.comps.len()))
            }
            syn::Expr::Paren(p) => self.place(&p.expr),
            syn::Expr::Field(f) => {
                let (root, ty, range) = self.place(&f.base)?;
                let (t, r) = expr::member_of(&ty, &f.member);
                Ok((root, t, range.start + r.start..range.start + r.end))
            }
            syn::Expr::Index(ix) => {
                let (root, ty, range) = self.place(&ix.expr)?;
                let i = self.const_index(&ix.index)?;
                match crate::typeck::rules::index_range(&ty, i) {
                    Some(r) => {
                        let t = crate::typeck::rules::element(&ty).expect("indexable");
                        Ok((root, t, range.start + r.start..range.start + r.end))
                    }
                    None => self.err(ix.span(), format!("index {i} out of bounds for `{ty}`")),
                }
            }
            _ => expr::unchecked("an unassignable place"),
        }
    }

    fn assign(&mut self, target: &syn::Expr, val: Val) -> R<()> {
        let (root, ty, range) = self.place(target)?;
        let names = ty.slot_names(&root);
        for (v, n) in val.comps.iter().zip(names) {
            let info = &mut self.f.vars[v.0 as usize];
            if info.name == "t" {
                info.name = n;
            }
        }
        let b = self.lookup_mut(&root).expect("place resolved");
        b.comps.splice(range, val.comps);
        Ok(())
    }

    /// Evaluates an expression that must be a compile-time integer (index, loop bound).
    fn const_index(&mut self, e: &syn::Expr) -> R<usize> {
        self.const_int(
            e,
            "this index must be known at compile time (a literal, a constant or a loop counter)",
        )
    }

    /// Evaluates an expression that must be a non-negative compile-time integer.
    fn const_int(&mut self, e: &syn::Expr, msg: &str) -> R<usize> {
        let v = self.expr(e)?;
        match (&v.ty, v.comps.first().and_then(|c| self.const_of(*c))) {
            (Ty::Index | Ty::U32 | Ty::I32, Some(Const::U(x))) => Ok(x as usize),
            (Ty::Index | Ty::U32 | Ty::I32, Some(Const::I(x))) if x >= 0 => Ok(x as usize),
            _ => self.err(e.span(), msg),
        }
    }

    // ---- control flow ------------------------------------------------------------------------

    fn if_expr(&mut self, e: &syn::ExprIf) -> R<Val> {
        let cond = self.expr(&e.cond)?.comps[0];
        // A condition known at compile time (e.g. on a loop counter) keeps only one side.
        if let Some(Const::B(k)) = self.const_of(cond) {
            return match (k, &e.else_branch) {
                (true, _) => self.block(&e.then_branch),
                (false, Some((_, els))) => self.expr(els),
                (false, None) => Ok(Val::unit()),
            };
        }
        let snapshot = self.scopes.clone();
        let outer = std::mem::take(&mut self.stmts);
        let then_val = self.block(&e.then_branch);
        let then_stmts = std::mem::take(&mut self.stmts);
        let then_scopes = std::mem::replace(&mut self.scopes, snapshot.clone());
        let else_val = match &e.else_branch {
            Some((_, els)) => self.expr(els),
            None => Ok(Val::unit()),
        };
        let else_stmts = std::mem::replace(&mut self.stmts, outer);
        let else_scopes = std::mem::replace(&mut self.scopes, snapshot.clone());
        let (then_val, else_val) = (then_val?, else_val?);
        // Variables assigned in either branch leave it as outputs of the branch.
        let mut changed = vec![];
        for (depth, scope) in snapshot.iter().enumerate() {
            for (name, b) in scope {
                let t = &then_scopes[depth][name];
                let el = &else_scopes[depth][name];
                if t.comps != b.comps || el.comps != b.comps {
                    changed.push((depth, name.clone(), t.comps.clone(), el.comps.clone()));
                }
            }
        }
        changed.sort_by(|a, b| (a.0, &a.1).cmp(&(b.0, &b.1)));
        let mut ty_ = then_val.comps.clone();
        let mut ey = else_val.comps.clone();
        for (_, _, t, el) in &changed {
            ty_.extend(t);
            ey.extend(el);
        }
        let outs = self.join_branches(
            cond,
            Block {
                stmts: then_stmts,
                yields: ty_,
            },
            Block {
                stmts: else_stmts,
                yields: ey,
            },
        );
        let n = then_val.comps.len();
        let mut at = n;
        for (depth, name, t, _) in &changed {
            let k = t.len();
            self.scopes[*depth]
                .get_mut(name)
                .expect("snapshot binding")
                .comps = outs[at..at + k].to_vec();
            at += k;
        }
        Ok(Val {
            ty: then_val.ty,
            comps: outs[..n].to_vec(),
        })
    }

    fn for_loop(&mut self, f: &syn::ExprForLoop) -> R<Val> {
        const BOUNDS: &str =
            "loop bounds must be compile-time constants (`for i in 0..N`): loops are unrolled";
        let syn::Expr::Range(r) = &*f.expr else {
            expr::unchecked("a loop over a non-range")
        };
        let lo = match &r.start {
            Some(s) => self.const_int(s, BOUNDS)?,
            None => 0,
        };
        let end = r
            .end
            .as_ref()
            .expect("type-checked: the loop has an upper bound");
        let hi = self.const_int(end, BOUNDS)?;
        let hi = match r.limits {
            syn::RangeLimits::HalfOpen(_) => hi,
            syn::RangeLimits::Closed(_) => hi + 1,
        };
        self.unrolled += hi.saturating_sub(lo);
        if self.unrolled > UNROLL_LIMIT {
            return self.err(
                f.span(),
                format!("loops are unrolled, and this function's loops exceed {UNROLL_LIMIT} iterations in total"),
            );
        }
        for i in lo..hi {
            self.scopes.push(HashMap::new());
            let k = self.konst(Const::U(i as u32));
            let iv = Val {
                ty: Ty::Index,
                comps: vec![k],
            };
            self.bind_pattern(&f.pat, iv);
            let body = self.block(&f.body);
            self.scopes.pop();
            body?;
        }
        Ok(Val::unit())
    }

    /// Inlines a call to a helper of the module; a helper with `#[adjoint(..)]` becomes a
    /// [`Stmt::Call`] so that AD uses the user's adjoint instead of differentiating the body.
    fn call_helper(&mut self, def: &'m FnDef, args: Vec<Val>, span: Span) -> R<Val> {
        if self.call_stack.contains(&def.name) {
            return self.err(
                span,
                format!("recursive call to `{}` is not supported", def.name),
            );
        }
        if self.typed.fn_failed(&def.name) {
            return Err(Failed);
        }
        let saved_scopes = std::mem::replace(&mut self.scopes, vec![HashMap::new()]);
        for (a, p) in args.iter().zip(&def.params) {
            self.scopes[0].insert(p.name.clone(), a.clone());
        }
        self.call_stack.push(def.name.clone());
        let custom = self.custom.iter().position(|c| *c == def.name);
        let outer = custom.map(|_| std::mem::take(&mut self.stmts));
        let r = self.block(&def.item.block);
        self.call_stack.pop();
        self.scopes = saved_scopes;
        let v = r?;
        let (Some(callee), Some(outer)) = (custom, outer) else {
            return Ok(v);
        };
        let body = Block {
            stmts: std::mem::replace(&mut self.stmts, outer),
            yields: v.comps.clone(),
        };
        let outs: Vec<Var> = v
            .comps
            .iter()
            .map(|c| {
                let o = self.f.new_var(self.f.ty(*c), format!("{}_out", def.name));
                if self.is_active(*c) {
                    self.active.insert(o);
                }
                o
            })
            .collect();
        let args = args.iter().flat_map(|a| a.comps.iter().copied()).collect();
        self.stmts.push(Stmt::Call {
            callee,
            args,
            outs: outs.clone(),
            body,
        });
        Ok(Val {
            ty: v.ty,
            comps: outs,
        })
    }
}
