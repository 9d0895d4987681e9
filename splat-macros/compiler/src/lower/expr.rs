//! Lowering of expressions.

use super::{Failed, Lowerer, R, Val};
use crate::ir::{Binary, Const, Scalar, Unary, Var};
use crate::types::{Ty, builtin_struct};
use std::ops::Range;
use syn::spanned::Spanned;

/// The type and component range of `ty.member` (struct field, vector component, matrix
/// column, tuple element).
pub(super) fn member_range(ty: &Ty, member: &str) -> Option<(Ty, Range<usize>)> {
    match ty {
        Ty::Struct(s) => {
            let mut at = 0;
            for (name, t) in &s.fields {
                let n = t.slot_count();
                if name == member {
                    return Some((t.clone(), at..at + n));
                }
                at += n;
            }
            None
        }
        Ty::Vec(_) | Ty::Quat => {
            let n = if let Ty::Vec(n) = ty { *n } else { 4 };
            let i = ["x", "y", "z", "w"]
                .iter()
                .take(n)
                .position(|c| *c == member)?;
            Some((Ty::F32, i..i + 1))
        }
        Ty::Mat(n) => {
            let i = ["x_axis", "y_axis", "z_axis"]
                .iter()
                .take(*n)
                .position(|c| *c == member)?;
            Some((Ty::Vec(*n), i * n..(i + 1) * n))
        }
        Ty::Tuple(ts) => {
            let i: usize = member.parse().ok()?;
            let at: usize = ts.iter().take(i).map(Ty::slot_count).sum();
            let t = ts.get(i)?;
            Some((t.clone(), at..at + t.slot_count()))
        }
        _ => None,
    }
}

/// The type and component range of `ty[i]` (array element, vector component).
pub(super) fn index_range(ty: &Ty, i: usize) -> Option<(Ty, Range<usize>)> {
    match ty {
        Ty::Array(t, n) if i < *n => {
            let k = t.slot_count();
            Some(((**t).clone(), i * k..(i + 1) * k))
        }
        Ty::Vec(n) if i < *n => Some((Ty::F32, i..i + 1)),
        _ => None,
    }
}

/// The operation `op` computes (for `x += y`, that of `+`), and its spelling in messages.
fn ir_binop(op: &syn::BinOp) -> Option<(Binary, &'static str)> {
    use syn::BinOp::*;
    Some(match op {
        Add(_) | AddAssign(_) => (Binary::Add, "+"),
        Sub(_) | SubAssign(_) => (Binary::Sub, "-"),
        Mul(_) | MulAssign(_) => (Binary::Mul, "*"),
        Div(_) | DivAssign(_) => (Binary::Div, "/"),
        Rem(_) | RemAssign(_) => (Binary::Rem, "%"),
        And(_) => (Binary::And, "&&"),
        Or(_) => (Binary::Or, "||"),
        BitAnd(_) | BitAndAssign(_) => (Binary::And, "&"),
        BitOr(_) | BitOrAssign(_) => (Binary::Or, "|"),
        BitXor(_) | BitXorAssign(_) => (Binary::Xor, "^"),
        Shl(_) | ShlAssign(_) => (Binary::Shl, "<<"),
        Shr(_) | ShrAssign(_) => (Binary::Shr, ">>"),
        Eq(_) => (Binary::Eq, "=="),
        Lt(_) => (Binary::Lt, "<"),
        Le(_) => (Binary::Le, "<="),
        Ne(_) => (Binary::Ne, "!="),
        Ge(_) => (Binary::Ge, ">="),
        Gt(_) => (Binary::Gt, ">"),
        _ => return None,
    })
}

impl Lowerer<'_> {
    pub(super) fn expr(&mut self, e: &syn::Expr) -> R<Val> {
        use syn::Expr as E;
        match e {
            E::Lit(l) => self.lit(&l.lit),
            E::Paren(p) => self.expr(&p.expr),
            E::Group(g) => self.expr(&g.expr),
            E::Reference(r) if r.mutability.is_none() => self.expr(&r.expr),
            E::Unary(u) => self.unary(u),
            E::Binary(b) => self.binary_expr(b),
            E::Path(p) => self.path(p),
            E::Cast(c) => self.cast(c),
            E::Field(f) => {
                let base = self.expr(&f.base)?;
                let member = match &f.member {
                    syn::Member::Named(id) => id.to_string(),
                    syn::Member::Unnamed(i) => i.index.to_string(),
                };
                match member_range(&base.ty, &member) {
                    Some((ty, r)) => Ok(Val { ty, comps: base.comps[r].to_vec() }),
                    None if base.ty == Ty::Error => Err(Failed),
                    None => self.err(f.member.span(), format!("no field `{member}` on type `{}`", base.ty)),
                }
            }
            E::Index(ix) => {
                let base = self.expr(&ix.expr)?;
                let i = self.const_index(&ix.index)?;
                match index_range(&base.ty, i) {
                    Some((ty, r)) => Ok(Val { ty, comps: base.comps[r].to_vec() }),
                    None => self.err(ix.span(), format!("index {i} is out of bounds for `{}`", base.ty)),
                }
            }
            E::Tuple(t) => {
                let vals = t.elems.iter().map(|e| self.expr(e)).collect::<R<Vec<_>>>()?;
                Ok(Val {
                    ty: Ty::Tuple(vals.iter().map(|v| v.ty.clone()).collect()),
                    comps: vals.into_iter().flat_map(|v| v.comps).collect(),
                })
            }
            E::Array(a) => {
                let vals = a.elems.iter().map(|e| self.expr(e)).collect::<R<Vec<_>>>()?;
                let Some(first) = vals.first() else {
                    return self.err(a.span(), "empty arrays are not supported");
                };
                let t = first.ty.clone();
                for (v, e) in vals.iter().zip(&a.elems) {
                    self.check_ty(v, &t, e.span(), "an array element")?;
                }
                Ok(Val {
                    ty: Ty::Array(Box::new(t), vals.len()),
                    comps: vals.into_iter().flat_map(|v| v.comps).collect(),
                })
            }
            E::Repeat(r) => {
                let v = self.expr(&r.expr)?;
                let n = self.const_index(&r.len)?;
                Ok(Val { ty: Ty::Array(Box::new(v.ty.clone()), n), comps: v.comps.repeat(n) })
            }
            E::Struct(s) => self.struct_lit(s),
            E::Block(b) if b.label.is_none() => self.block(&b.block),
            E::If(i) => self.if_expr(i),
            E::ForLoop(f) => self.for_loop(f),
            E::Assign(a) => {
                let v = self.expr(&a.right)?;
                self.assign(&a.left, v)?;
                Ok(Val::unit())
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
            E::Closure(_) => {
                self.err(e.span(), "closures are not supported (but as the map of `jacobian(|p| body, x)`): write a helper `fn` in the same module")
            }
            E::Macro(m) => self.err(
                e.span(),
                format!(
                    "macro `{}!` is not supported inside a kernel",
                    m.mac.path.segments.last().map(|s| s.ident.to_string()).unwrap_or_default()
                ),
            ),
            E::Try(_) => self.err(e.span(), "the `?` operator is not supported: kernels cannot fail"),
            E::Unsafe(_) => self.err(e.span(), "`unsafe` is not supported in kernels"),
            E::Reference(_) => self.err(e.span(), "`&mut` is not supported: kernels are pure"),
            E::Range(_) => self.err(e.span(), "ranges are only supported as the bounds of a `for` loop"),
            _ => self.err(e.span(), "this expression is not supported in a splat kernel"),
        }
    }

    fn lit(&mut self, l: &syn::Lit) -> R<Val> {
        match l {
            syn::Lit::Float(f) => {
                if f.suffix() == "f64" {
                    return self.err(
                        f.span(),
                        "`f64` literals are not supported: write f32 (the f64 twin is generated)",
                    );
                }
                let x: f64 = f.base10_digits().parse().map_err(|_| Failed)?;
                let v = self.fconst(x);
                Ok(Val {
                    ty: Ty::F32,
                    comps: vec![v],
                })
            }
            syn::Lit::Int(i) => {
                let (ty, c) = match i.suffix() {
                    "" | "usize" => (Ty::Index, i.base10_parse::<u32>().map(Const::U)),
                    "u32" => (Ty::U32, i.base10_parse::<u32>().map(Const::U)),
                    "i32" => (Ty::I32, i.base10_parse::<i32>().map(Const::I)),
                    "f32" => {
                        let x: f64 = i.base10_digits().parse().map_err(|_| Failed)?;
                        (Ty::F32, Ok(Const::F(x)))
                    }
                    other => {
                        return self
                            .err(i.span(), format!("integer type `{other}` is not supported"));
                    }
                };
                match c {
                    Ok(c) => {
                        let v = self.konst(c);
                        Ok(Val { ty, comps: vec![v] })
                    }
                    Err(e) => self.err(i.span(), e),
                }
            }
            syn::Lit::Bool(b) => {
                let v = self.konst(Const::B(b.value));
                Ok(Val {
                    ty: Ty::Bool,
                    comps: vec![v],
                })
            }
            other => self.err(
                other.span(),
                "only numeric and boolean literals are supported",
            ),
        }
    }

    fn path(&mut self, p: &syn::ExprPath) -> R<Val> {
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        if segs.len() == 1 {
            let name = &segs[0];
            if let Some(b) = self.lookup(name) {
                return if b.val.ty == Ty::Error {
                    Err(Failed)
                } else {
                    Ok(b.val.clone())
                };
            }
            if let Some(c) = self.module.consts.get(name) {
                let (ty, expr) = (c.ty.clone(), c.expr.clone());
                let v = self.expr(&expr)?;
                return self.coerce(v, &ty, p.span(), &format!("constant `{name}`"));
            }
            return self.err(
                p.span(),
                format!("cannot find `{name}` in this function or module"),
            );
        }
        let tail: Vec<&str> = segs.iter().map(String::as_str).collect();
        let n = tail.len();
        let (owner, item) = (tail[n - 2], tail[n - 1]);
        if let Some(v) = self.assoc_const(owner, item) {
            return Ok(v);
        }
        self.err(p.span(), format!("unknown constant `{}`", segs.join("::")))
    }

    /// `Vec3::ZERO`, `Mat3::IDENTITY`, `f32::consts::PI`, `f32::EPSILON`, ...
    fn assoc_const(&mut self, owner: &str, item: &str) -> Option<Val> {
        let fl = |x: f64| (Ty::F32, vec![x]);
        let (ty, vals) = match (owner, item) {
            ("consts", c) => fl(match c {
                "PI" => std::f64::consts::PI,
                "TAU" => std::f64::consts::TAU,
                "E" => std::f64::consts::E,
                "FRAC_PI_2" => std::f64::consts::FRAC_PI_2,
                "FRAC_PI_4" => std::f64::consts::FRAC_PI_4,
                "FRAC_1_PI" => std::f64::consts::FRAC_1_PI,
                "SQRT_2" => std::f64::consts::SQRT_2,
                "LN_2" => std::f64::consts::LN_2,
                _ => return None,
            }),
            ("f32", "EPSILON") => fl(f32::EPSILON as f64),
            ("f32", "MAX") => fl(f32::MAX as f64),
            ("f32", "MIN") => fl(f32::MIN as f64),
            ("f32", "MIN_POSITIVE") => fl(f32::MIN_POSITIVE as f64),
            ("f32", "INFINITY") => fl(f64::INFINITY),
            ("f32", "NEG_INFINITY") => fl(f64::NEG_INFINITY),
            ("u32", "MAX") => {
                let v = self.konst(Const::U(u32::MAX));
                return Some(Val {
                    ty: Ty::U32,
                    comps: vec![v],
                });
            }
            (v, c) if v.starts_with("Vec") => {
                let n: usize = v[3..].parse().ok().filter(|n| (2..=4).contains(n))?;
                let mut out = vec![0.0; n];
                match c {
                    "ZERO" => {}
                    "ONE" => out.fill(1.0),
                    "X" | "Y" | "Z" | "W" | "NEG_X" | "NEG_Y" | "NEG_Z" | "NEG_W" => {
                        let axis = ["X", "Y", "Z", "W"].iter().position(|a| c.ends_with(a))?;
                        *out.get_mut(axis)? = if c.starts_with("NEG") { -1.0 } else { 1.0 };
                    }
                    _ => return None,
                }
                (Ty::Vec(n), out)
            }
            ("Mat2" | "Mat3", c) => {
                let n = if owner == "Mat2" { 2 } else { 3 };
                let mut out = vec![0.0; n * n];
                match c {
                    "ZERO" => {}
                    "IDENTITY" => (0..n).for_each(|i| out[i * n + i] = 1.0),
                    _ => return None,
                }
                (Ty::Mat(n), out)
            }
            ("Quat", "IDENTITY") => (Ty::Quat, vec![0.0, 0.0, 0.0, 1.0]),
            _ => return None,
        };
        let comps = vals.into_iter().map(|x| self.fconst(x)).collect();
        Some(Val { ty, comps })
    }

    /// Converts integer literals (`Ty::Index`) to the expected integer type; checks the rest.
    pub(super) fn coerce(
        &mut self,
        v: Val,
        want: &Ty,
        span: proc_macro2::Span,
        what: &str,
    ) -> R<Val> {
        match (&v.ty, want) {
            (Ty::Index, Ty::U32) => Ok(Val {
                ty: Ty::U32,
                comps: v.comps,
            }),
            (Ty::Index, Ty::I32) => {
                let c = self.un(Unary::Cast(Scalar::I32), v.comps[0]);
                Ok(Val {
                    ty: Ty::I32,
                    comps: vec![c],
                })
            }
            _ => {
                self.check_ty(&v, want, span, what)?;
                Ok(v)
            }
        }
    }

    fn unary(&mut self, u: &syn::ExprUnary) -> R<Val> {
        let v = self.expr(&u.expr)?;
        match u.op {
            syn::UnOp::Deref(_) => Ok(v),
            syn::UnOp::Neg(_) => match v.ty {
                Ty::F32 | Ty::Vec(_) | Ty::Mat(_) | Ty::Quat | Ty::I32 => {
                    Ok(self.map(&v, Unary::Neg))
                }
                Ty::Index => {
                    let c = self.un(Unary::Cast(Scalar::I32), v.comps[0]);
                    let n = self.un(Unary::Neg, c);
                    Ok(Val {
                        ty: Ty::I32,
                        comps: vec![n],
                    })
                }
                _ => self.err(
                    u.span(),
                    format!("cannot negate a value of type `{}`", v.ty),
                ),
            },
            syn::UnOp::Not(_) => match v.ty {
                Ty::Bool | Ty::U32 | Ty::I32 => Ok(self.map(&v, Unary::Not)),
                _ => self.err(
                    u.span(),
                    format!("cannot apply `!` to a value of type `{}`", v.ty),
                ),
            },
            _ => self.err(u.span(), "this operator is not supported"),
        }
    }

    pub(super) fn map(&mut self, v: &Val, op: Unary) -> Val {
        let comps = v.comps.iter().map(|&c| self.un(op, c)).collect();
        Val {
            ty: v.ty.clone(),
            comps,
        }
    }

    fn binary_expr(&mut self, b: &syn::ExprBinary) -> R<Val> {
        use syn::BinOp::*;
        let compound = matches!(
            b.op,
            AddAssign(_)
                | SubAssign(_)
                | MulAssign(_)
                | DivAssign(_)
                | RemAssign(_)
                | BitXorAssign(_)
                | BitAndAssign(_)
                | BitOrAssign(_)
                | ShlAssign(_)
                | ShrAssign(_)
        );
        let l = self.expr(&b.left)?;
        let r = self.expr(&b.right)?;
        let Some((op, spelled)) = ir_binop(&b.op) else {
            return self.err(b.op.span(), "this operator is not supported");
        };
        let v = self.binary(op, spelled, l, r, b.span())?;
        if compound {
            self.assign(&b.left, v)?;
            return Ok(Val::unit());
        }
        Ok(v)
    }

    /// Type-checks and lowers `l op r` for every supported operand pair.
    pub(super) fn binary(
        &mut self,
        op: Binary,
        sym: &str,
        l: Val,
        r: Val,
        span: proc_macro2::Span,
    ) -> R<Val> {
        use Binary::*;
        use Ty::*;
        let arith = matches!(op, Add | Sub | Mul | Div | Rem);
        // Integer literals take the type of the other operand.
        let (l, r) = match (&l.ty, &r.ty) {
            (Index, U32 | I32) => (self.coerce(l, &r.ty.clone(), span, "")?, r),
            (U32 | I32, Index) => {
                let t = l.ty.clone();
                (l, self.coerce(r, &t, span, "")?)
            }
            _ => (l, r),
        };
        let zip = |s: &mut Self, a: &[Var], b: &[Var]| -> std::vec::Vec<Var> {
            a.iter().zip(b).map(|(&x, &y)| s.bin(op, x, y)).collect()
        };
        let bcast = |s: &mut Self, a: &[Var], k: Var, k_left: bool| -> std::vec::Vec<Var> {
            a.iter()
                .map(|&x| {
                    if k_left {
                        s.bin(op, k, x)
                    } else {
                        s.bin(op, x, k)
                    }
                })
                .collect()
        };
        let v = match (&l.ty, &r.ty) {
            (Error, _) | (_, Error) => return Err(Failed),
            (F32, F32) | (U32, U32) | (I32, I32) | (Index, Index) if arith => Val {
                ty: l.ty.clone(),
                comps: zip(self, &l.comps, &r.comps),
            },
            (U32, U32) | (I32, I32) | (Index, Index) | (Bool, Bool)
                if matches!(op, And | Or | Xor) =>
            {
                Val {
                    ty: l.ty.clone(),
                    comps: zip(self, &l.comps, &r.comps),
                }
            }
            (U32, U32) | (I32, I32) | (Index, Index) if matches!(op, Shl | Shr) => Val {
                ty: l.ty.clone(),
                comps: zip(self, &l.comps, &r.comps),
            },
            (F32, F32) | (U32, U32) | (I32, I32) | (Index, Index) if op.is_comparison() => Val {
                ty: Bool,
                comps: zip(self, &l.comps, &r.comps),
            },
            (Bool, Bool) if matches!(op, Eq | Ne) => Val {
                ty: Bool,
                comps: zip(self, &l.comps, &r.comps),
            },
            (Vec(a), Vec(b)) if a == b && arith => Val {
                ty: l.ty.clone(),
                comps: zip(self, &l.comps, &r.comps),
            },
            (Vec(_), F32) if arith => Val {
                ty: l.ty.clone(),
                comps: bcast(self, &l.comps, r.comps[0], false),
            },
            (F32, Vec(_)) if arith => Val {
                ty: r.ty.clone(),
                comps: bcast(self, &r.comps, l.comps[0], true),
            },
            (Mat(a), Mat(b)) if a == b && matches!(op, Add | Sub) => Val {
                ty: l.ty.clone(),
                comps: zip(self, &l.comps, &r.comps),
            },
            (Mat(a), Mat(b)) if a == b && op == Mul => self.mat_mul(&l, &r),
            (Mat(a), Vec(b)) if a == b && op == Mul => self.mat_vec(&l, &r),
            (Mat(_), F32) if matches!(op, Mul | Div) => Val {
                ty: l.ty.clone(),
                comps: bcast(self, &l.comps, r.comps[0], false),
            },
            (F32, Mat(_)) if op == Mul => Val {
                ty: r.ty.clone(),
                comps: bcast(self, &r.comps, l.comps[0], true),
            },
            (Quat, Vec(3)) if op == Mul => self.quat_rotate(&l, &r),
            (Quat, Quat) if op == Mul => self.quat_mul(&l, &r),
            (Quat, Quat) if matches!(op, Add | Sub) => Val {
                ty: Quat,
                comps: zip(self, &l.comps, &r.comps),
            },
            (Quat, F32) if matches!(op, Mul | Div) => Val {
                ty: Quat,
                comps: bcast(self, &l.comps, r.comps[0], false),
            },
            (F32, U32 | I32 | Index) | (U32 | I32 | Index, F32) => {
                return self.err(
                    span,
                    format!(
                        "mismatched types: cannot apply `{sym}` to `{}` and `{}`; convert the integer with `as f32` (and write float literals with a dot: `2.0`)",
                        l.ty, r.ty
                    ),
                );
            }
            _ => {
                return self.err(
                    span,
                    format!(
                        "mismatched types: cannot apply `{sym}` to `{}` and `{}`",
                        l.ty, r.ty
                    ),
                );
            }
        };
        Ok(v)
    }

    fn cast(&mut self, c: &syn::ExprCast) -> R<Val> {
        let v = self.expr(&c.expr)?;
        let target = match &*c.ty {
            syn::Type::Path(p) if p.path.get_ident().is_some() => {
                p.path.get_ident().unwrap().to_string()
            }
            t => {
                return self.err(
                    t.span(),
                    "only casts between f32, u32, i32, usize and bool are supported",
                );
            }
        };
        let to = match target.as_str() {
            "f32" => Scalar::F32,
            "u32" => Scalar::U32,
            "i32" => Scalar::I32,
            "usize" => {
                if let Some(Const::U(_) | Const::I(_)) =
                    v.comps.first().and_then(|x| self.const_of(*x))
                {
                    let k = self.un(Unary::Cast(Scalar::U32), v.comps[0]);
                    return Ok(Val {
                        ty: Ty::Index,
                        comps: vec![k],
                    });
                }
                return self.err(c.span(), "`as usize` needs a value known at compile time");
            }
            other => return self.err(c.ty.span(), format!("casts to `{other}` are not supported")),
        };
        match v.ty {
            Ty::F32 | Ty::U32 | Ty::I32 | Ty::Index | Ty::Bool => {}
            _ => return self.err(c.span(), format!("cannot cast a `{}`", v.ty)),
        }
        // A cast to the type a value already has is the value itself (no operation whose
        // derivative would be taken as a cast's: zero).
        let same = matches!(
            (&v.ty, to),
            (Ty::F32, Scalar::F32) | (Ty::U32, Scalar::U32) | (Ty::I32, Scalar::I32)
        );
        if same {
            return Ok(v);
        }
        if v.ty == Ty::Bool && to == Scalar::F32 {
            return self.err(
                c.span(),
                "cannot cast `bool` to `f32`: use `select(b, 1.0, 0.0)`",
            );
        }
        if v.ty == Ty::F32 && to != Scalar::F32 && self.is_active(v.comps[0]) {
            return self.err(
                c.span(),
                "cannot differentiate through a float-to-integer cast: the gradient would silently be \
                 zero; if that is intended, wrap the operand in `no_diff(..)`",
            );
        }
        let x = self.un(Unary::Cast(to), v.comps[0]);
        let ty = match to {
            Scalar::F32 => Ty::F32,
            Scalar::U32 => Ty::U32,
            Scalar::I32 => Ty::I32,
            Scalar::Bool => Ty::Bool,
        };
        Ok(Val { ty, comps: vec![x] })
    }

    fn struct_lit(&mut self, s: &syn::ExprStruct) -> R<Val> {
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
            given
                .iter()
                .find(|g| g.0 == n)
                .map(|g| g.1.ty.clone())
                .unwrap_or(Ty::Error)
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
        let mut comps = vec![];
        for (fname, fty) in &st.fields {
            let Some(pos) = given.iter().position(|g| &g.0 == fname) else {
                return self.err(s.span(), format!("missing field `{fname}` in `{name}`"));
            };
            let (_, v, span) = given.remove(pos);
            let v = self.coerce(v, fty, span, &format!("field `{fname}`"))?;
            comps.extend(v.comps);
        }
        if let Some((extra, _, span)) = given.first() {
            return self.err(*span, format!("`{name}` has no field `{extra}`"));
        }
        Ok(Val { ty, comps })
    }
}
