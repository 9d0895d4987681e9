//! The `jacobian` intrinsic: forward-mode differentiation inside a kernel.
//!
//! `let (value, j) = jacobian(|p| body, x);` evaluates `body` at `p = x` and returns its value
//! with its Jacobian there: `j[i]` is the gradient of the value's component `i` (of the type
//! of `x`), so `j: [Vec3; 2]` for a map from `Vec3` to `Vec2`. The closure reads the kernel's
//! other values (`|p| cam.project_point(p)`), which are constants of the differentiation.
//!
//! Why forward mode, and why this form: a Jacobian of a map from n <= 4 inputs is n tangent
//! sweeps riding along the primal, which fuse into one pass over the statements with no tape;
//! and the closure names exactly what is differentiated and at which point, without a second
//! function to declare. The lowering evaluates the body with `p` bound to fresh copies of
//! `x`'s components, then walks the statements it produced, emitting after each one the
//! linearization of its operation for every direction (tangents known to be zero are not
//! materialized). A branch gets its tangents inside each side, as extra outputs. The result is
//! ordinary IR: `project`'s reverse-mode adjoint differentiates through it (second derivatives
//! of the camera model). Each tangent is built by the same rule as the adjoint (`crate::ops`,
//! with its kink rules: a derivative that would be infinite at a singular point is 0; `min` /
//! `max` ties go to the first operand), so both modes agree where the function is smooth.

use super::{Lowerer, R, Val};
use crate::ir::{Binary, Block, Op, Scalar, Stmt, Unary, Var};
use crate::ops;
use crate::typeck::rules;
use std::collections::HashMap;
use syn::spanned::Spanned;

/// The tangent of a value in each direction; `None` is a tangent known to be zero.
type Tangent = Vec<Option<Var>>;

impl Lowerer<'_> {
    /// `jacobian(|p| body, x)`.
    pub(super) fn jacobian(&mut self, c: &syn::ExprCall) -> R<Val> {
        let (Some(syn::Expr::Closure(closure)), Some(point)) = (c.args.first(), c.args.get(1))
        else {
            super::expr::unchecked("a `jacobian` without a closure and a point")
        };
        let x = self.expr(point)?;
        // Fresh copies (x * 1, exact), so each direction seeds one value even where `x`'s
        // components share one (`Vec3::splat(a)`).
        let one = self.fconst(1.0);
        let inputs: Vec<Var> = x
            .comps
            .iter()
            .map(|&v| self.bin(Binary::Mul, v, one))
            .collect();
        let p = Val {
            ty: x.ty.clone(),
            comps: inputs.clone(),
        };
        let pattern = match &closure.inputs[0] {
            syn::Pat::Type(typed) => &*typed.pat,
            pattern => pattern,
        };
        let outer = std::mem::take(&mut self.stmts);
        self.scopes.push(HashMap::new());
        self.bind_pattern(pattern, p);
        let value = self.expr(&closure.body);
        self.scopes.pop();
        let body = std::mem::replace(&mut self.stmts, outer);
        let value = value?;
        let n = inputs.len();
        let mut tangents: HashMap<Var, Tangent> = HashMap::new();
        for (k, v) in inputs.iter().enumerate() {
            tangents.insert(*v, (0..n).map(|j| (j == k).then_some(one)).collect());
        }
        if let Err(helper) = self.push_forward(body, &mut tangents) {
            return self.err(
                closure.body.span(),
                format!(
                    "`jacobian` cannot differentiate through `{helper}`: it has a hand-written adjoint, and forward mode would need its tangent rule"
                ),
            );
        }
        let mut comps = value.comps.clone();
        for out in &value.comps {
            let t = tangents.get(out).cloned().unwrap_or_default();
            for j in 0..n {
                let d = t.get(j).copied().flatten();
                comps.push(self.materialize(d));
            }
        }
        Ok(Val {
            ty: rules::jacobian(&x.ty, &value.ty),
            comps,
        })
    }

    fn materialize(&mut self, t: Option<Var>) -> Var {
        t.unwrap_or_else(|| self.fconst(0.0))
    }

    /// Re-emits `stmts` into the current block, each followed by its tangents (added to
    /// `tangents`). Fails with the helper's name at a call of a helper with a custom adjoint on
    /// values that vary with the point.
    fn push_forward(
        &mut self,
        stmts: Vec<Stmt>,
        tangents: &mut HashMap<Var, Tangent>,
    ) -> Result<(), String> {
        for s in stmts {
            match s {
                Stmt::Let { var, op } => {
                    self.stmts.push(Stmt::Let {
                        var,
                        op: op.clone(),
                    });
                    if self.f.ty(var) != Scalar::F32 {
                        continue;
                    }
                    let operands = op.operands();
                    let ts: Vec<Tangent> = operands
                        .iter()
                        .map(|o| tangents.get(o).cloned().unwrap_or_default())
                        .collect();
                    if ts.iter().all(|t| t.iter().all(Option::is_none)) {
                        continue;
                    }
                    let n = ts.iter().map(Vec::len).max().unwrap_or(0);
                    let at = |t: &Tangent, j: usize| t.get(j).copied().flatten();
                    let t: Tangent = (0..n)
                        .map(|j| {
                            let dirs: Vec<Option<Var>> = ts.iter().map(|t| at(t, j)).collect();
                            self.tangent_rule(var, &op, &dirs)
                        })
                        .collect();
                    tangents.insert(var, t);
                }
                Stmt::If {
                    cond,
                    then_block,
                    else_block,
                    mut outs,
                } => {
                    let outer = std::mem::take(&mut self.stmts);
                    let mut then_t = tangents.clone();
                    let then_r = self.push_forward(then_block.stmts, &mut then_t);
                    let then_stmts = std::mem::take(&mut self.stmts);
                    let mut else_t = tangents.clone();
                    let else_r = self.push_forward(else_block.stmts, &mut else_t);
                    let else_stmts = std::mem::replace(&mut self.stmts, outer);
                    then_r?;
                    else_r?;
                    let mut then_b = Block {
                        stmts: then_stmts,
                        yields: then_block.yields.clone(),
                    };
                    let mut else_b = Block {
                        stmts: else_stmts,
                        yields: else_block.yields.clone(),
                    };
                    let mut new_tangents = vec![];
                    for (k, out) in outs.clone().into_iter().enumerate() {
                        let (a, b) = (then_block.yields[k], else_block.yields[k]);
                        let (ta, tb) = (
                            then_t.get(&a).cloned().unwrap_or_default(),
                            else_t.get(&b).cloned().unwrap_or_default(),
                        );
                        let n = ta.len().max(tb.len());
                        let mut t = vec![];
                        for j in 0..n {
                            let (da, db) =
                                (ta.get(j).copied().flatten(), tb.get(j).copied().flatten());
                            if da.is_none() && db.is_none() {
                                t.push(None);
                                continue;
                            }
                            let da = self.in_block(&mut then_b, da);
                            let db = self.in_block(&mut else_b, db);
                            then_b.yields.push(da);
                            else_b.yields.push(db);
                            let o = self
                                .f
                                .new_var(Scalar::F32, format!("{}_tangent", self.f.name(out)));
                            if self.is_active(da) || self.is_active(db) {
                                self.active.insert(o);
                            }
                            outs.push(o);
                            t.push(Some(o));
                        }
                        // An output with no tangent in any direction stays out of the map.
                        if t.iter().any(Option::is_some) {
                            new_tangents.push((out, t));
                        }
                    }
                    self.stmts.push(Stmt::If {
                        cond,
                        then_block: then_b,
                        else_block: else_b,
                        outs,
                    });
                    tangents.extend(new_tangents);
                }
                Stmt::Call {
                    callee,
                    args,
                    outs,
                    body,
                } => {
                    // A helper with a hand-written adjoint has no tangent rule; called on
                    // values the point does not reach, it needs none.
                    let varying = |a: &Var| {
                        tangents
                            .get(a)
                            .is_some_and(|t| t.iter().any(Option::is_some))
                    };
                    if args.iter().any(varying) {
                        return Err(self.custom[callee].clone());
                    }
                    self.stmts.push(Stmt::Call {
                        callee,
                        args,
                        outs,
                        body,
                    });
                }
            }
        }
        Ok(())
    }

    /// `t`, or a zero constant appended to `block`.
    fn in_block(&mut self, block: &mut Block, t: Option<Var>) -> Var {
        if let Some(t) = t {
            return t;
        }
        let outer = std::mem::replace(&mut self.stmts, std::mem::take(&mut block.stmts));
        let z = self.fconst(0.0);
        block.stmts = std::mem::replace(&mut self.stmts, outer);
        z
    }

    /// The tangent of `r = op(..)` in one direction, given its operands' (`None`: zero).
    fn tangent_rule(&mut self, r: Var, op: &Op, d: &[Option<Var>]) -> Option<Var> {
        match *op {
            Op::Const(_) => None,
            Op::Unary(u, a) => ops::unary_derivative(self, u, a, r, d[0]?),
            Op::Binary(b, x, y) => {
                let mut e = ops::Shared::new(self);
                let mut part = |k: usize| ops::binary_derivative(&mut e, b, x, y, r, k, d[k]?);
                let (px, py) = (part(0), part(1));
                self.sum(px, py)
            }
            Op::Select(c, _, _) => {
                let (dx, dy) = (d[1], d[2]);
                if dx.is_none() && dy.is_none() {
                    return None;
                }
                let (a, b) = (self.materialize(dx), self.materialize(dy));
                Some(self.select(c, a, b))
            }
        }
    }

    fn sum(&mut self, a: Option<Var>, b: Option<Var>) -> Option<Var> {
        match (a, b) {
            (Some(a), Some(b)) => Some(self.bin(Binary::Add, a, b)),
            (a, None) => a,
            (None, b) => b,
        }
    }
}

/// Derivative rules write tangents as any other lowered code (names come from bindings).
impl ops::Emit for Lowerer<'_> {
    fn konst(&mut self, x: f64) -> Var {
        self.fconst(x)
    }
    fn un(&mut self, u: Unary, a: Var, _: &str) -> Var {
        Lowerer::un(self, u, a)
    }
    fn bin(&mut self, b: Binary, x: Var, y: Var, _: &str) -> Var {
        Lowerer::bin(self, b, x, y)
    }
    fn select(&mut self, c: Var, x: Var, y: Var, _: &str) -> Var {
        Lowerer::select(self, c, x, y)
    }
}
