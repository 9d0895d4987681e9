//! Reverse-mode AD as an IR-to-IR transform.
//!
//! The adjoint of `f(x) -> y` is a function `(x, dy) -> dx` whose body is `f`'s body again
//! (the primal is recomputed, nothing is stored) followed by the reverse sweep: each scalar
//! operation is linearized and transposed in reverse order, and the adjoints of a value used
//! several times are summed. Branch choices come from the primal's boolean (the reverse of an
//! `If` is an `If` on the same condition that recomputes the taken side and differentiates
//! only it); `min`/`max` winners from one comparison. Every local derivative that would be
//! infinite at a singular point (division by 0, `sqrt`/`ln`/`rsqrt` at 0, ...) is replaced
//! by 0 through a select, so no NaN is created by a multiplication with 0.
//!
//! The result is ordinary IR, emitted by the same backends as the primal.

use crate::ir::{Binary, Block, Const, Function, Op, Scalar, Stmt, Unary, Var};
use crate::ops;
use std::collections::{BTreeMap, HashMap, HashSet};

/// The adjoint of `f`: parameters are `f`'s followed by one cotangent per `f32` result slot
/// (named by `out_names`); results are the cotangents of `f`'s `f32` parameter slots.
/// `custom[i]` is the user-written adjoint of the helper called by `Stmt::Call { callee: i }`.
pub fn adjoint(f: &Function, custom: &[Function], out_names: &[String]) -> Function {
    let consts = f.body.constants().into_keys().collect();
    let mut ad = Ad {
        g: f.clone(),
        custom,
        consts,
    };
    ad.g.name = format!("{}_adjoint", f.name);
    let mut rev = vec![];
    let mut adj = HashMap::new();
    let float_results: Vec<Var> = f
        .results()
        .iter()
        .copied()
        .filter(|r| f.ty(*r) == Scalar::F32)
        .collect();
    for (k, r) in float_results.iter().enumerate() {
        let name = out_names
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("d_out_{k}"));
        let bar = ad.g.new_var(Scalar::F32, name);
        ad.g.params.push(bar);
        ad.acc(&mut adj, *r, bar, &mut rev);
    }
    ad.reverse(&f.body.stmts, &mut adj, &mut rev);
    let mut yields = vec![];
    for p in f.params.clone() {
        if f.ty(p) != Scalar::F32 {
            continue;
        }
        let y = match adj.get(&p) {
            Some(v) => *v,
            None => ad.zero(&mut rev),
        };
        yields.push(y);
    }
    ad.g.body.stmts.extend(rev);
    ad.g.body.yields = yields;
    ad.g
}

struct Ad<'a> {
    g: Function,
    custom: &'a [Function],
    consts: HashSet<Var>,
}

impl Ad<'_> {
    fn emit(&mut self, out: &mut Vec<Stmt>, op: Op, name: &str) -> Var {
        let ty = op.result_ty(|v| self.g.ty(v));
        let v = self.g.new_var(ty, name);
        out.push(Stmt::Let { var: v, op });
        v
    }

    fn zero(&mut self, out: &mut Vec<Stmt>) -> Var {
        let v = self.emit(out, Op::Const(Const::F(0.0)), "c");
        self.consts.insert(v);
        v
    }

    fn konst(&mut self, out: &mut Vec<Stmt>, x: f64) -> Var {
        let v = self.emit(out, Op::Const(Const::F(x)), "c");
        self.consts.insert(v);
        v
    }

    fn d_name(&self, v: Var) -> String {
        format!("d_{}", self.g.name(v))
    }

    /// adj[v] += c
    fn acc(&mut self, adj: &mut HashMap<Var, Var>, v: Var, c: Var, out: &mut Vec<Stmt>) {
        if self.g.ty(v) != Scalar::F32 || self.consts.contains(&v) {
            return;
        }
        let new = match adj.get(&v) {
            Some(&old) => {
                let name = self.d_name(v);
                self.emit(out, Op::Binary(Binary::Add, old, c), &name)
            }
            None => c,
        };
        adj.insert(v, new);
    }

    /// `select(cond, value, 0)`, or `select(cond, 0, value)` when `zero_if_true`.
    fn guard(
        &mut self,
        out: &mut Vec<Stmt>,
        cond: Var,
        value: Var,
        zero_if_true: bool,
        name: &str,
    ) -> Var {
        let z = self.zero(out);
        let op = if zero_if_true {
            Op::Select(cond, z, value)
        } else {
            Op::Select(cond, value, z)
        };
        self.emit(out, op, name)
    }

    fn reverse(&mut self, stmts: &[Stmt], adj: &mut HashMap<Var, Var>, out: &mut Vec<Stmt>) {
        for s in stmts.iter().rev() {
            match s {
                Stmt::Let { var, op } => {
                    if let Some(&g) = adj.get(var) {
                        self.rule(*var, op, g, adj, out);
                    }
                }
                Stmt::If {
                    cond,
                    then_block,
                    else_block,
                    outs,
                } => {
                    let seeds: Vec<(usize, Var)> = outs
                        .iter()
                        .enumerate()
                        .filter_map(|(k, o)| adj.get(o).map(|g| (k, *g)))
                        .collect();
                    if seeds.is_empty() {
                        continue;
                    }
                    let (then_stmts, then_c) = self.reverse_branch(then_block, &seeds);
                    let (else_stmts, else_c) = self.reverse_branch(else_block, &seeds);
                    // Outer values that receive a contribution on either side.
                    let mut keys: BTreeMap<Var, ()> = BTreeMap::new();
                    keys.extend(then_c.keys().map(|k| (*k, ())));
                    keys.extend(else_c.keys().map(|k| (*k, ())));
                    let (mut tb, mut eb) = (
                        Block {
                            stmts: then_stmts,
                            yields: vec![],
                        },
                        Block {
                            stmts: else_stmts,
                            yields: vec![],
                        },
                    );
                    let mut new_outs = vec![];
                    for k in keys.keys() {
                        let ty_ = match then_c.get(k) {
                            Some(v) => *v,
                            None => self.zero(&mut tb.stmts),
                        };
                        let ey = match else_c.get(k) {
                            Some(v) => *v,
                            None => self.zero(&mut eb.stmts),
                        };
                        tb.yields.push(ty_);
                        eb.yields.push(ey);
                        let name = self.d_name(*k);
                        new_outs.push(self.g.new_var(Scalar::F32, name));
                    }
                    out.push(Stmt::If {
                        cond: *cond,
                        then_block: tb,
                        else_block: eb,
                        outs: new_outs.clone(),
                    });
                    for (k, o) in keys.keys().zip(new_outs) {
                        self.acc(adj, *k, o, out);
                    }
                }
                Stmt::Call {
                    callee, args, outs, ..
                } => {
                    if !outs.iter().any(|o| adj.contains_key(o)) {
                        continue;
                    }
                    let callee_fn = &self.custom[*callee];
                    let mut remap = HashMap::new();
                    let n_args = args.len();
                    for (p, a) in callee_fn.params.iter().zip(args) {
                        remap.insert(*p, *a);
                    }
                    let bars: Vec<Var> = callee_fn.params[n_args..].to_vec();
                    let mut bar_outs = outs.iter();
                    for p in bars {
                        let v = match callee_fn.ty(p) {
                            Scalar::F32 => match bar_outs.find(|o| self.g.ty(**o) == Scalar::F32) {
                                Some(o) if adj.contains_key(o) => adj[o],
                                _ => self.zero(out),
                            },
                            Scalar::Bool => self.emit(out, Op::Const(Const::B(false)), "k"),
                            Scalar::U32 => self.emit(out, Op::Const(Const::U(0)), "k"),
                            Scalar::I32 => self.emit(out, Op::Const(Const::I(0)), "k"),
                        };
                        remap.insert(p, v);
                    }
                    // Import the callee's variables into this function, then inline it.
                    let base = self.g.vars.len() as u32;
                    let callee_fn = callee_fn.clone();
                    self.g.vars.extend(callee_fn.vars.iter().cloned());
                    let shifted = shift_block(&callee_fn.body, base, &remap);
                    let mut remap2 = HashMap::new();
                    let body = self.g.clone_fresh(&shifted, &mut remap2);
                    out.extend(body.stmts);
                    for (a, d) in args.iter().zip(body.yields) {
                        if self.g.ty(*a) == Scalar::F32 {
                            self.acc(adj, *a, d, out);
                        }
                    }
                }
            }
        }
    }

    /// The reverse of one side of a branch: its primal recomputed (fresh names), the seeds
    /// added to the adjoints of its yields, and the sweep. Returns the statements and the
    /// contributions to values defined outside the block.
    fn reverse_branch(
        &mut self,
        block: &Block,
        seeds: &[(usize, Var)],
    ) -> (Vec<Stmt>, HashMap<Var, Var>) {
        let mut remap = HashMap::new();
        let fresh = self.g.clone_fresh(block, &mut remap);
        let inner = fresh.defined();
        let mut stmts = fresh.stmts.clone();
        let mut local = HashMap::new();
        let mut rev = vec![];
        for (k, g) in seeds {
            self.acc(&mut local, fresh.yields[*k], *g, &mut rev);
        }
        self.reverse(&fresh.stmts, &mut local, &mut rev);
        stmts.extend(rev);
        let contribs = local
            .into_iter()
            .filter(|(v, _)| !inner.contains(v))
            .collect();
        (stmts, contribs)
    }

    /// Transposes one operation: `g` is the adjoint of its result `r`.
    fn rule(&mut self, r: Var, op: &Op, g: Var, adj: &mut HashMap<Var, Var>, out: &mut Vec<Stmt>) {
        match *op {
            Op::Const(_) => {}
            Op::Unary(u, a) => {
                let name = self.d_name(a);
                let mut e = Reverse {
                    ad: self,
                    out,
                    name,
                };
                if let Some(c) = ops::unary_derivative(&mut e, u, a, r, g) {
                    self.acc(adj, a, c, out);
                }
            }
            Op::Binary(b, x, y) => {
                let (nx, ny) = (self.d_name(x), self.d_name(y));
                let mut rev = Reverse {
                    ad: self,
                    out,
                    name: nx,
                };
                let mut e = ops::Shared::new(&mut rev);
                let cx = ops::binary_derivative(&mut e, b, x, y, r, 0, g);
                e.inner.name = ny;
                let cy = ops::binary_derivative(&mut e, b, x, y, r, 1, g);
                for (v, c) in [(x, cx), (y, cy)] {
                    if let Some(c) = c {
                        self.acc(adj, v, c, out);
                    }
                }
            }
            Op::Select(c, x, y) => {
                let (nx, ny) = (self.d_name(x), self.d_name(y));
                let dx = self.guard(out, c, g, false, &nx);
                self.acc(adj, x, dx, out);
                let dy = self.guard(out, c, g, true, &ny);
                self.acc(adj, y, dy, out);
            }
        }
    }
}

/// Renumbers a callee's variables by `base` (after appending its variable table to the
/// caller's), then substitutes its parameters.
fn shift_block(b: &Block, base: u32, params: &HashMap<Var, Var>) -> Block {
    b.rename(&mut |v, _| params.get(&v).copied().unwrap_or(Var(v.0 + base)))
}

/// Writes a derivative rule into the reverse sweep, naming its result after the operand.
struct Reverse<'a, 'b> {
    ad: &'a mut Ad<'b>,
    out: &'a mut Vec<Stmt>,
    /// The adjoint's name (`d_x`).
    name: String,
}

impl Reverse<'_, '_> {
    fn emit(&mut self, op: Op, name: &str) -> Var {
        let name = if name == ops::DERIVATIVE {
            &self.name
        } else {
            name
        };
        self.ad.emit(self.out, op, name)
    }
}

impl ops::Emit for Reverse<'_, '_> {
    fn konst(&mut self, x: f64) -> Var {
        self.ad.konst(self.out, x)
    }
    fn un(&mut self, u: Unary, a: Var, name: &str) -> Var {
        self.emit(Op::Unary(u, a), name)
    }
    fn bin(&mut self, b: Binary, x: Var, y: Var, name: &str) -> Var {
        self.emit(Op::Binary(b, x, y), name)
    }
    fn select(&mut self, c: Var, x: Var, y: Var, name: &str) -> Var {
        self.emit(Op::Select(c, x, y), name)
    }
}
