//! Lowering of expressions. Their types were checked (`crate::typeck`); the types of results
//! come from `typeck::rules`, and what is reported here depends on values.

use super::{Failed, Lowerer, R, Val};
use crate::ir::{Binary, Scalar, Unary, Var};
use crate::typeck::rules::{self, CastTo};
use crate::types::{Ty, builtin_struct};
use syn::spanned::Spanned;

/// Lowering met what type checking refuses: a compiler bug.
pub(super) fn unchecked(what: &str) -> ! {
    unreachable!("{what} reached lowering: type checking accepts what lowering cannot build")
}

impl Lowerer<'_> {
    pub(super) fn expr(&mut self, e: &syn::Expr) -> R<Val> {
        use syn::Expr as E;
        match e {
            E::Lit(l) => {
                let (ty, c) = rules::literal(&l.lit).unwrap_or_else(|_| unchecked("a bad literal"));
                let v = self.konst(c);
                Ok(Val { ty, comps: vec![v] })
            }
            E::Paren(p) => self.expr(&p.expr),
            E::Group(g) => self.expr(&g.expr),
            E::Reference(r) if r.mutability.is_none() => self.expr(&r.expr),
            E::Unary(u) => self.unary(u),
            E::Binary(b) => self.binary_expr(b),
            E::Path(p) => self.path(p),
            E::Cast(c) => self.cast(c),
            E::Field(f) => {
                let base = self.expr(&f.base)?;
                let (ty, r) = member_of(&base.ty, &f.member);
                Ok(Val {
                    ty,
                    comps: base.comps[r].to_vec(),
                })
            }
            E::Index(ix) => {
                let base = self.expr(&ix.expr)?;
                let i = self.const_index(&ix.index)?;
                match rules::index_range(&base.ty, i) {
                    Some(r) => {
                        let ty = rules::element(&base.ty).expect("indexable");
                        Ok(Val {
                            ty,
                            comps: base.comps[r].to_vec(),
                        })
                    }
                    None => self.err(
                        ix.span(),
                        format!("index {i} is out of bounds for `{}`", base.ty),
                    ),
                }
            }
            E::Tuple(t) => {
                let vals = t
                    .elems
                    .iter()
                    .map(|e| self.expr(e))
                    .collect::<R<Vec<_>>>()?;
                Ok(Val {
                    ty: Ty::Tuple(vals.iter().map(|v| v.ty.clone()).collect()),
                    comps: vals.into_iter().flat_map(|v| v.comps).collect(),
                })
            }
            E::Array(a) => {
                let vals = a
                    .elems
                    .iter()
                    .map(|e| self.expr(e))
                    .collect::<R<Vec<_>>>()?;
                Ok(Val {
                    ty: Ty::Array(Box::new(vals[0].ty.clone()), vals.len()),
                    comps: vals.into_iter().flat_map(|v| v.comps).collect(),
                })
            }
            E::Repeat(r) => {
                let v = self.expr(&r.expr)?;
                let n = self
                    .module
                    .array_len(&r.len)
                    .unwrap_or_else(|_| unchecked("a bad array length"));
                Ok(Val {
                    ty: Ty::Array(Box::new(v.ty.clone()), n),
                    comps: v.comps.repeat(n),
                })
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
            _ => unchecked("an unsupported expression"),
        }
    }

    fn path(&mut self, p: &syn::ExprPath) -> R<Val> {
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        if let [name] = segs.as_slice() {
            if let Some(b) = self.lookup(name) {
                return if b.ty == Ty::Error {
                    Err(Failed)
                } else {
                    Ok(b.clone())
                };
            }
            let c = self
                .module
                .consts
                .get(name)
                .unwrap_or_else(|| unchecked("an unknown name"));
            if self.typed.const_failed(name) {
                return Err(Failed);
            }
            let (ty, expr) = (c.ty.clone(), c.expr.clone());
            let v = self.expr(&expr)?;
            return Ok(self.coerce(v, &ty));
        }
        let n = segs.len();
        let (ty, consts) = rules::assoc_const(&segs[n - 2], &segs[n - 1])
            .unwrap_or_else(|| unchecked("an unknown constant"));
        let comps = consts.into_iter().map(|c| self.konst(c)).collect();
        Ok(Val { ty, comps })
    }

    /// Converts an integer literal (`Ty::Index`) to the integer type expected of it.
    pub(super) fn coerce(&mut self, v: Val, want: &Ty) -> Val {
        match (&v.ty, want) {
            (Ty::Index, Ty::U32) => Val {
                ty: Ty::U32,
                comps: v.comps,
            },
            (Ty::Index, Ty::I32) => {
                let c = self.un(Unary::Cast(Scalar::I32), v.comps[0]);
                Val {
                    ty: Ty::I32,
                    comps: vec![c],
                }
            }
            _ => v,
        }
    }

    fn unary(&mut self, u: &syn::ExprUnary) -> R<Val> {
        let v = self.expr(&u.expr)?;
        Ok(match u.op {
            syn::UnOp::Deref(_) => v,
            syn::UnOp::Neg(_) if v.ty == Ty::Index => {
                let c = self.un(Unary::Cast(Scalar::I32), v.comps[0]);
                let n = self.un(Unary::Neg, c);
                Val {
                    ty: Ty::I32,
                    comps: vec![n],
                }
            }
            syn::UnOp::Neg(_) => self.map(&v, Unary::Neg),
            syn::UnOp::Not(_) => self.map(&v, Unary::Not),
            _ => unchecked("an unsupported operator"),
        })
    }

    pub(super) fn map(&mut self, v: &Val, op: Unary) -> Val {
        let comps = v.comps.iter().map(|&c| self.un(op, c)).collect();
        Val {
            ty: v.ty.clone(),
            comps,
        }
    }

    fn binary_expr(&mut self, b: &syn::ExprBinary) -> R<Val> {
        let l = self.expr(&b.left)?;
        let r = self.expr(&b.right)?;
        let (op, _, compound) =
            rules::binary_op(&b.op).unwrap_or_else(|| unchecked("an unsupported operator"));
        let v = self.binary(op, l, r);
        if compound {
            self.assign(&b.left, v)?;
            return Ok(Val::unit());
        }
        Ok(v)
    }

    /// Lowers `l op r` for an operand pair [`rules::binary`] accepts.
    pub(super) fn binary(&mut self, op: Binary, l: Val, r: Val) -> Val {
        use Ty::*;
        let (lt, rt) = rules::binary_operands(&l.ty, &r.ty);
        let (l, r) = (self.coerce(l, &lt), self.coerce(r, &rt));
        let ty = rules::binary(op, &l.ty, &r.ty).unwrap_or_else(|| unchecked("an operand pair"));
        let each = |s: &mut Self, a: &[Var], f: &dyn Fn(Var) -> (Var, Var)| -> std::vec::Vec<Var> {
            a.iter()
                .map(|&x| {
                    let (p, q) = f(x);
                    s.bin(op, p, q)
                })
                .collect()
        };
        let comps = match (&l.ty, &r.ty, op) {
            (Mat(_), Mat(_), Binary::Mul) => self.mat_mul(&l, &r).comps,
            (Mat(_), Vec(_), Binary::Mul) => self.mat_vec(&l, &r).comps,
            (Quat, Vec(_), Binary::Mul) => self.quat_rotate(&l, &r).comps,
            (Quat, Quat, Binary::Mul) => self.quat_mul(&l, &r).comps,
            (Vec(_) | Mat(_) | Quat, F32, _) => {
                let k = r.comps[0];
                each(self, &l.comps, &|x| (x, k))
            }
            (F32, Vec(_) | Mat(_), _) => {
                let k = l.comps[0];
                each(self, &r.comps, &|x| (k, x))
            }
            _ => l
                .comps
                .iter()
                .zip(&r.comps)
                .map(|(&x, &y)| self.bin(op, x, y))
                .collect(),
        };
        Val { ty, comps }
    }

    fn cast(&mut self, c: &syn::ExprCast) -> R<Val> {
        let v = self.expr(&c.expr)?;
        let to = rules::cast_target(&c.ty).unwrap_or_else(|_| unchecked("a cast target"));
        let ty = rules::cast(&v.ty, to).unwrap_or_else(|_| unchecked("a cast"));
        let to = match to {
            CastTo::Scalar(s) => s,
            CastTo::Index => {
                if self.const_of(v.comps[0]).is_none() {
                    return self.err(c.span(), "`as usize` needs a value known at compile time");
                }
                let k = self.un(Unary::Cast(Scalar::U32), v.comps[0]);
                return Ok(Val { ty, comps: vec![k] });
            }
        };
        // A cast to the type a value already has is the value itself (no operation whose
        // derivative would be taken as a cast's: zero).
        if v.ty == ty {
            return Ok(v);
        }
        if v.ty == Ty::F32 && self.is_active(v.comps[0]) {
            return self.err(
                c.span(),
                "cannot differentiate through a float-to-integer cast: the gradient would silently be \
                 zero; if that is intended, wrap the operand in `no_diff(..)`",
            );
        }
        let x = self.un(Unary::Cast(to), v.comps[0]);
        Ok(Val { ty, comps: vec![x] })
    }

    fn struct_lit(&mut self, s: &syn::ExprStruct) -> R<Val> {
        let name = s
            .path
            .segments
            .last()
            .map(|x| x.ident.to_string())
            .unwrap_or_default();
        let mut given = vec![];
        for f in &s.fields {
            let syn::Member::Named(id) = &f.member else {
                unchecked("a tuple struct")
            };
            given.push((id.to_string(), self.expr(&f.expr)?));
        }
        let field = |n: &str| given.iter().find(|g| g.0 == n).map(|g| g.1.ty.clone());
        let ty = match self.module.find_struct(&name) {
            Some(t) => Ty::Struct(t.clone()),
            None => {
                let args: Vec<Ty> = match name.as_str() {
                    "Projected" => vec![field("cull"), field("shade")],
                    "Contribution" => vec![field("color")],
                    _ => vec![],
                }
                .into_iter()
                .map(|t| t.unwrap_or_else(|| unchecked("a missing field")))
                .collect();
                match builtin_struct(&name, &args) {
                    Some(Ok(t)) => t,
                    _ => unchecked("an unknown struct"),
                }
            }
        };
        let Ty::Struct(st) = &ty else { unreachable!() };
        let mut comps = vec![];
        for (fname, fty) in &st.fields {
            let pos = given
                .iter()
                .position(|g| &g.0 == fname)
                .expect("type-checked");
            let (_, v) = given.remove(pos);
            comps.extend(self.coerce(v, fty).comps);
        }
        Ok(Val { ty, comps })
    }
}

/// The type and component range of `ty.member`.
pub(super) fn member_of(ty: &Ty, member: &syn::Member) -> (Ty, std::ops::Range<usize>) {
    let name = match member {
        syn::Member::Named(id) => id.to_string(),
        syn::Member::Unnamed(i) => i.index.to_string(),
    };
    rules::member(ty, &name).unwrap_or_else(|| unchecked("an unknown field"))
}
