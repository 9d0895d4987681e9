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
        let ty = match &op {
            Op::Const(c) => c.ty(),
            Op::Binary(b, _, _) if b.is_comparison() => Scalar::Bool,
            _ => Scalar::F32,
        };
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
        use Binary as B;
        use Unary as U;
        match *op {
            Op::Const(_) => {}
            Op::Unary(u, a) => {
                let n = self.d_name(a);
                let mut e = |s: &mut Self, op: Op| s.emit(out, op, &n);
                let c = match u {
                    U::Neg => Some(e(self, Op::Unary(U::Neg, g))),
                    U::NoDiff
                    | U::Floor
                    | U::Ceil
                    | U::Round
                    | U::Trunc
                    | U::Signum
                    | U::Cast(_)
                    | U::Not => None,
                    U::Fract => Some(g),
                    U::Exp => Some(e(self, Op::Binary(B::Mul, g, r))),
                    U::Ln => {
                        let z = self.zero(out);
                        let pos = self.emit(out, Op::Binary(B::Gt, a, z), "pos");
                        let d = self.emit(out, Op::Binary(B::Div, g, a), &n);
                        Some(self.guard(out, pos, d, false, &n))
                    }
                    U::Ln1p => {
                        let one = self.konst(out, 1.0);
                        let m1 = self.konst(out, -1.0);
                        let ok = self.emit(out, Op::Binary(B::Gt, a, m1), "ok");
                        let den = self.emit(out, Op::Binary(B::Add, one, a), "den");
                        let d = self.emit(out, Op::Binary(B::Div, g, den), &n);
                        Some(self.guard(out, ok, d, false, &n))
                    }
                    U::Sqrt => {
                        let z = self.zero(out);
                        let pos = self.emit(out, Op::Binary(B::Gt, a, z), "pos");
                        let half = self.konst(out, 0.5);
                        let hg = self.emit(out, Op::Binary(B::Mul, half, g), &n);
                        let d = self.emit(out, Op::Binary(B::Div, hg, r), &n);
                        Some(self.guard(out, pos, d, false, &n))
                    }
                    U::Rsqrt => {
                        let z = self.zero(out);
                        let pos = self.emit(out, Op::Binary(B::Gt, a, z), "pos");
                        let k = self.konst(out, -0.5);
                        let r2 = self.emit(out, Op::Binary(B::Mul, r, r), "r2");
                        let r3 = self.emit(out, Op::Binary(B::Mul, r2, r), "r3");
                        let kg = self.emit(out, Op::Binary(B::Mul, k, g), &n);
                        let d = self.emit(out, Op::Binary(B::Mul, kg, r3), &n);
                        Some(self.guard(out, pos, d, false, &n))
                    }
                    U::Recip => {
                        let z = self.zero(out);
                        let nz = self.emit(out, Op::Binary(B::Ne, a, z), "nz");
                        let r2 = self.emit(out, Op::Binary(B::Mul, r, r), "r2");
                        let gr = self.emit(out, Op::Binary(B::Mul, g, r2), &n);
                        let d = self.emit(out, Op::Unary(U::Neg, gr), &n);
                        Some(self.guard(out, nz, d, false, &n))
                    }
                    U::Abs => {
                        let z = self.zero(out);
                        let nonneg = self.emit(out, Op::Binary(B::Ge, a, z), "nonneg");
                        let ng = self.emit(out, Op::Unary(U::Neg, g), &n);
                        Some(self.emit(out, Op::Select(nonneg, g, ng), &n))
                    }
                    U::Sin => {
                        let c = self.emit(out, Op::Unary(U::Cos, a), "cos");
                        Some(self.emit(out, Op::Binary(B::Mul, g, c), &n))
                    }
                    U::Cos => {
                        let s = self.emit(out, Op::Unary(U::Sin, a), "sin");
                        let gs = self.emit(out, Op::Binary(B::Mul, g, s), &n);
                        Some(self.emit(out, Op::Unary(U::Neg, gs), &n))
                    }
                    U::Tan => {
                        let one = self.konst(out, 1.0);
                        let r2 = self.emit(out, Op::Binary(B::Mul, r, r), "r2");
                        let d = self.emit(out, Op::Binary(B::Add, one, r2), "sec2");
                        Some(self.emit(out, Op::Binary(B::Mul, g, d), &n))
                    }
                    U::Tanh => {
                        let one = self.konst(out, 1.0);
                        let r2 = self.emit(out, Op::Binary(B::Mul, r, r), "r2");
                        let d = self.emit(out, Op::Binary(B::Sub, one, r2), "sech2");
                        Some(self.emit(out, Op::Binary(B::Mul, g, d), &n))
                    }
                    U::Atan => {
                        let one = self.konst(out, 1.0);
                        let a2 = self.emit(out, Op::Binary(B::Mul, a, a), "a2");
                        let d = self.emit(out, Op::Binary(B::Add, one, a2), "den");
                        Some(self.emit(out, Op::Binary(B::Div, g, d), &n))
                    }
                    U::Asin | U::Acos => {
                        let one = self.konst(out, 1.0);
                        let z = self.zero(out);
                        let a2 = self.emit(out, Op::Binary(B::Mul, a, a), "a2");
                        let t = self.emit(out, Op::Binary(B::Sub, one, a2), "t");
                        let inside = self.emit(out, Op::Binary(B::Gt, t, z), "inside");
                        let s = self.emit(out, Op::Unary(U::Sqrt, t), "s");
                        let d = self.emit(out, Op::Binary(B::Div, g, s), &n);
                        let d = if u == U::Acos {
                            self.emit(out, Op::Unary(U::Neg, d), &n)
                        } else {
                            d
                        };
                        Some(self.guard(out, inside, d, false, &n))
                    }
                };
                if let Some(c) = c {
                    self.acc(adj, a, c, out);
                }
            }
            Op::Binary(b, x, y) => {
                let (nx, ny) = (self.d_name(x), self.d_name(y));
                match b {
                    B::Add => {
                        self.acc(adj, x, g, out);
                        self.acc(adj, y, g, out);
                    }
                    B::Sub => {
                        self.acc(adj, x, g, out);
                        let ng = self.emit(out, Op::Unary(U::Neg, g), &ny);
                        self.acc(adj, y, ng, out);
                    }
                    B::Mul => {
                        let dx = self.emit(out, Op::Binary(B::Mul, g, y), &nx);
                        self.acc(adj, x, dx, out);
                        let dy = self.emit(out, Op::Binary(B::Mul, g, x), &ny);
                        self.acc(adj, y, dy, out);
                    }
                    B::Div => {
                        let z = self.zero(out);
                        let nz = self.emit(out, Op::Binary(B::Ne, y, z), "nz");
                        let q = self.emit(out, Op::Binary(B::Div, g, y), &nx);
                        let dx = self.guard(out, nz, q, false, &nx);
                        self.acc(adj, x, dx, out);
                        let qr = self.emit(out, Op::Binary(B::Mul, q, r), &ny);
                        let nqr = self.emit(out, Op::Unary(U::Neg, qr), &ny);
                        let dy = self.guard(out, nz, nqr, false, &ny);
                        self.acc(adj, y, dy, out);
                    }
                    B::Rem => {
                        self.acc(adj, x, g, out);
                        let z = self.zero(out);
                        let nz = self.emit(out, Op::Binary(B::Ne, y, z), "nz");
                        let q = self.emit(out, Op::Binary(B::Div, x, y), "q");
                        let t = self.emit(out, Op::Unary(U::Trunc, q), "q");
                        let gt = self.emit(out, Op::Binary(B::Mul, g, t), &ny);
                        let ngt = self.emit(out, Op::Unary(U::Neg, gt), &ny);
                        let dy = self.guard(out, nz, ngt, false, &ny);
                        self.acc(adj, y, dy, out);
                    }
                    B::Min | B::Max => {
                        // Ties go to the first operand.
                        let cmp = if b == B::Min { B::Le } else { B::Ge };
                        let first = self.emit(out, Op::Binary(cmp, x, y), "first");
                        let dx = self.guard(out, first, g, false, &nx);
                        self.acc(adj, x, dx, out);
                        let dy = self.guard(out, first, g, true, &ny);
                        self.acc(adj, y, dy, out);
                    }
                    B::Atan2 => {
                        let z = self.zero(out);
                        let x2 = self.emit(out, Op::Binary(B::Mul, x, x), "y2");
                        let y2 = self.emit(out, Op::Binary(B::Mul, y, y), "x2");
                        let den = self.emit(out, Op::Binary(B::Add, x2, y2), "den");
                        let pos = self.emit(out, Op::Binary(B::Gt, den, z), "pos");
                        let gy = self.emit(out, Op::Binary(B::Mul, g, y), &nx);
                        let dx = self.emit(out, Op::Binary(B::Div, gy, den), &nx);
                        let dx = self.guard(out, pos, dx, false, &nx);
                        self.acc(adj, x, dx, out);
                        let gx = self.emit(out, Op::Binary(B::Mul, g, x), &ny);
                        let dy = self.emit(out, Op::Binary(B::Div, gx, den), &ny);
                        let dy = self.emit(out, Op::Unary(U::Neg, dy), &ny);
                        let dy = self.guard(out, pos, dy, false, &ny);
                        self.acc(adj, y, dy, out);
                    }
                    B::Powf => {
                        let z = self.zero(out);
                        let nz = self.emit(out, Op::Binary(B::Ne, x, z), "nz");
                        let gy = self.emit(out, Op::Binary(B::Mul, g, y), &nx);
                        let gyr = self.emit(out, Op::Binary(B::Mul, gy, r), &nx);
                        let dx = self.emit(out, Op::Binary(B::Div, gyr, x), &nx);
                        let dx = self.guard(out, nz, dx, false, &nx);
                        self.acc(adj, x, dx, out);
                        let pos = self.emit(out, Op::Binary(B::Gt, x, z), "pos");
                        let l = self.emit(out, Op::Unary(U::Ln, x), "ln");
                        let gr = self.emit(out, Op::Binary(B::Mul, g, r), &ny);
                        let dy = self.emit(out, Op::Binary(B::Mul, gr, l), &ny);
                        let dy = self.guard(out, pos, dy, false, &ny);
                        self.acc(adj, y, dy, out);
                    }
                    // Comparisons and bit operations have no float result.
                    _ => {}
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
    let m = |v: &Var| params.get(v).copied().unwrap_or(Var(v.0 + base));
    let stmts = b
        .stmts
        .iter()
        .map(|s| match s {
            Stmt::Let { var, op } => Stmt::Let {
                var: m(var),
                op: match *op {
                    Op::Const(c) => Op::Const(c),
                    Op::Unary(u, a) => Op::Unary(u, m(&a)),
                    Op::Binary(o, a, c) => Op::Binary(o, m(&a), m(&c)),
                    Op::Select(c, a, d) => Op::Select(m(&c), m(&a), m(&d)),
                },
            },
            Stmt::If {
                cond,
                then_block,
                else_block,
                outs,
            } => Stmt::If {
                cond: m(cond),
                then_block: shift_block(then_block, base, params),
                else_block: shift_block(else_block, base, params),
                outs: outs.iter().map(m).collect(),
            },
            Stmt::Call {
                callee,
                args,
                outs,
                body,
            } => Stmt::Call {
                callee: *callee,
                args: args.iter().map(m).collect(),
                outs: outs.iter().map(m).collect(),
                body: shift_block(body, base, params),
            },
        })
        .collect();
    Block {
        stmts,
        yields: b.yields.iter().map(m).collect(),
    }
}
