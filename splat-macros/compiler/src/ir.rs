//! The compiler's IR: typed scalar SSA with structured control flow.
//!
//! Invariants (every pass relies on them, the lowering establishes them):
//! - Every value is a scalar of type [`Scalar`]; vectors, matrices, arrays and structs of the
//!   source are flattened into their components by the lowering, so AD and the emitters only
//!   ever see scalar operations.
//! - Every [`Var`] is defined exactly once: as a parameter of its [`Function`], by a
//!   [`Stmt::Let`], or as an output of a [`Stmt::If`] / [`Stmt::Call`].
//! - A block may use any variable defined before it in an enclosing block (dominance); values
//!   leave a block only through its `yields`, which become the outputs of the enclosing `If`
//!   (or the results of the function for its body).
//! - There are no loops: constant-trip-count loops are unrolled by the lowering, so the adjoint
//!   is straight-line code plus branches and needs no tape.
//! - Operations are pure; the only side effect of a function is its results.

use std::collections::{HashMap, HashSet};

/// An SSA value, an index into [`Function::vars`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Var(pub u32);

/// The scalar types of the IR. (`Default` is for strum: enumerating `Unary` yields
/// `Cast(Scalar::default())`.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, strum::EnumIter)]
pub enum Scalar {
    #[default]
    F32,
    Bool,
    U32,
    I32,
}

/// A constant; floats are kept in f64 so the f64 twin gets the source literal's full precision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Const {
    F(f64),
    B(bool),
    U(u32),
    I(i32),
}

impl Const {
    pub fn ty(self) -> Scalar {
        match self {
            Const::F(_) => Scalar::F32,
            Const::B(_) => Scalar::Bool,
            Const::U(_) => Scalar::U32,
            Const::I(_) => Scalar::I32,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, strum::EnumIter)]
pub enum Unary {
    Neg,
    Not,
    Exp,
    Ln,
    Ln1p,
    Sqrt,
    Rsqrt,
    Recip,
    Abs,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Tanh,
    /// The error function (`erf(x)`).
    Erf,
    Floor,
    Ceil,
    Round,
    Trunc,
    Fract,
    Signum,
    /// Identity whose derivative is zero (`no_diff`).
    NoDiff,
    /// Numeric conversion to the given scalar type (`as`).
    Cast(Scalar),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, strum::EnumIter)]
pub enum Binary {
    Add,
    Sub,
    Mul,
    Div,
    Rem,
    Min,
    Max,
    Atan2,
    Powf,
    And,
    Or,
    Xor,
    Shl,
    Shr,
    Lt,
    Le,
    Gt,
    Ge,
    Eq,
    Ne,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Op {
    Const(Const),
    Unary(Unary, Var),
    Binary(Binary, Var, Var),
    /// `if c { a } else { b }` with both operands already computed.
    Select(Var, Var, Var),
}

impl Op {
    /// The type of the operation's result, given its operands' (`ty`).
    pub fn result_ty(&self, ty: impl Fn(Var) -> Scalar) -> Scalar {
        match self {
            Op::Const(c) => c.ty(),
            Op::Unary(Unary::Cast(t), _) => *t,
            Op::Unary(_, a) => ty(*a),
            Op::Binary(b, _, _) if b.is_comparison() => Scalar::Bool,
            Op::Binary(_, a, _) => ty(*a),
            Op::Select(_, a, _) => ty(*a),
        }
    }

    /// The same operation on operands `f(operand)`.
    pub fn map_operands(&self, mut f: impl FnMut(Var) -> Var) -> Op {
        match *self {
            Op::Const(c) => Op::Const(c),
            Op::Unary(u, a) => Op::Unary(u, f(a)),
            Op::Binary(b, x, y) => Op::Binary(b, f(x), f(y)),
            Op::Select(c, x, y) => Op::Select(f(c), f(x), f(y)),
        }
    }

    pub fn operands(&self) -> Vec<Var> {
        match *self {
            Op::Const(_) => vec![],
            Op::Unary(_, a) => vec![a],
            Op::Binary(_, a, b) => vec![a, b],
            Op::Select(c, a, b) => vec![c, a, b],
        }
    }
}

#[derive(Clone, Debug)]
pub enum Stmt {
    Let {
        var: Var,
        op: Op,
    },
    If {
        cond: Var,
        then_block: Block,
        else_block: Block,
        outs: Vec<Var>,
    },
    /// A call to a helper with a user-written adjoint; `body` is the helper inlined (what the
    /// forward computes), `callee` names the helper for the adjoint rule.
    Call {
        callee: usize,
        args: Vec<Var>,
        outs: Vec<Var>,
        body: Block,
    },
}

/// How a variable occurs in a statement, for [`Block::rename`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Occurs {
    Read,
    Defined,
}

#[derive(Clone, Debug, Default)]
pub struct Block {
    pub stmts: Vec<Stmt>,
    pub yields: Vec<Var>,
}

impl Stmt {
    /// What the statement defines at its own level (not what its nested blocks define).
    pub fn defines(&self) -> &[Var] {
        match self {
            Stmt::Let { var, .. } => std::slice::from_ref(var),
            Stmt::If { outs, .. } | Stmt::Call { outs, .. } => outs,
        }
    }

    /// What the statement reads at its own level: an operation's operands, a branch's
    /// condition and its blocks' yields, a call's arguments and its body's yields.
    pub fn reads(&self) -> Vec<Var> {
        match self {
            Stmt::Let { op, .. } => op.operands(),
            Stmt::If {
                cond,
                then_block,
                else_block,
                ..
            } => std::iter::once(*cond)
                .chain(then_block.yields.iter().chain(&else_block.yields).copied())
                .collect(),
            Stmt::Call { args, body, .. } => args.iter().chain(&body.yields).copied().collect(),
        }
    }

    /// The blocks nested in the statement.
    pub fn blocks(&self) -> Vec<&Block> {
        match self {
            Stmt::Let { .. } => vec![],
            Stmt::If {
                then_block,
                else_block,
                ..
            } => vec![then_block, else_block],
            Stmt::Call { body, .. } => vec![body],
        }
    }

    /// Every variable the statement or a statement nested in it reads.
    pub fn reads_nested(&self, out: &mut HashSet<Var>) {
        out.extend(self.reads());
        for b in self.blocks() {
            b.visit(&mut |s| out.extend(s.reads()));
        }
    }
}

impl Block {
    /// Visits every statement of the block and of the blocks nested in it, outer first.
    pub fn visit(&self, f: &mut impl FnMut(&Stmt)) {
        for s in &self.stmts {
            f(s);
            for b in s.blocks() {
                b.visit(f);
            }
        }
    }

    /// The block with each variable `v` replaced by `f(v, how it occurs)`, met in the order the
    /// code runs: a statement's reads, its nested blocks, then what it defines; yields last.
    pub fn rename(&self, f: &mut impl FnMut(Var, Occurs) -> Var) -> Block {
        let stmts = (self.stmts.iter())
            .map(|s| match s {
                Stmt::Let { var, op } => {
                    let op = op.map_operands(|v| f(v, Occurs::Read));
                    Stmt::Let {
                        var: f(*var, Occurs::Defined),
                        op,
                    }
                }
                Stmt::If {
                    cond,
                    then_block,
                    else_block,
                    outs,
                } => Stmt::If {
                    cond: f(*cond, Occurs::Read),
                    then_block: then_block.rename(f),
                    else_block: else_block.rename(f),
                    outs: outs.iter().map(|o| f(*o, Occurs::Defined)).collect(),
                },
                Stmt::Call {
                    callee,
                    args,
                    outs,
                    body,
                } => Stmt::Call {
                    callee: *callee,
                    args: args.iter().map(|a| f(*a, Occurs::Read)).collect(),
                    body: body.rename(f),
                    outs: outs.iter().map(|o| f(*o, Occurs::Defined)).collect(),
                },
            })
            .collect();
        let yields = self.yields.iter().map(|v| f(*v, Occurs::Read)).collect();
        Block { stmts, yields }
    }

    /// Whether `v` is read anywhere in the block or nested in it.
    pub fn uses(&self, v: Var) -> bool {
        let mut used = self.yields.contains(&v);
        self.visit(&mut |s| used |= s.reads().contains(&v));
        used
    }

    /// Every variable read in the block or nested in it (its yields too).
    pub fn reads(&self, out: &mut HashSet<Var>) {
        out.extend(self.yields.iter().copied());
        self.visit(&mut |s| out.extend(s.reads()));
    }

    /// The operations (not constants) in the block and nested in it.
    pub fn operations(&self) -> usize {
        let mut n = 0;
        self.visit(&mut |s| {
            n += !matches!(
                s,
                Stmt::Let {
                    op: Op::Const(_),
                    ..
                }
            ) as usize
        });
        n
    }

    /// Every constant defined in the block or nested in it.
    pub fn constants(&self) -> HashMap<Var, Const> {
        let mut out = HashMap::new();
        self.visit(&mut |s| {
            if let Stmt::Let {
                var,
                op: Op::Const(c),
            } = s
            {
                out.insert(*var, *c);
            }
        });
        out
    }

    /// Every variable defined in the block or nested in it.
    pub fn defined(&self) -> HashSet<Var> {
        let mut out = HashSet::new();
        self.visit(&mut |s| out.extend(s.defines()));
        out
    }

    /// The variables the block's own statements define (not those nested in its branches).
    pub fn defined_here(&self) -> Vec<Var> {
        self.stmts
            .iter()
            .flat_map(|s| s.defines())
            .copied()
            .collect()
    }
}

#[derive(Clone, Debug)]
pub struct VarInfo {
    pub ty: Scalar,
    /// Readable name hint for the emitters (made unique there).
    pub name: String,
}

#[derive(Clone, Debug)]
pub struct Function {
    pub name: String,
    pub vars: Vec<VarInfo>,
    pub params: Vec<Var>,
    /// `body.yields` are the results.
    pub body: Block,
}

impl Function {
    pub fn new(name: impl Into<String>) -> Self {
        Function {
            name: name.into(),
            vars: vec![],
            params: vec![],
            body: Block::default(),
        }
    }

    pub fn new_var(&mut self, ty: Scalar, name: impl Into<String>) -> Var {
        self.vars.push(VarInfo {
            ty,
            name: name.into(),
        });
        Var(self.vars.len() as u32 - 1)
    }

    pub fn ty(&self, v: Var) -> Scalar {
        self.vars[v.0 as usize].ty
    }

    pub fn name(&self, v: Var) -> &str {
        &self.vars[v.0 as usize].name
    }

    pub fn results(&self) -> &[Var] {
        &self.body.yields
    }

    /// Copies `block` with every variable it defines renamed to a fresh one; uses of variables
    /// defined outside it are kept. `remap` receives the renaming.
    pub fn clone_fresh(&mut self, block: &Block, remap: &mut HashMap<Var, Var>) -> Block {
        block.rename(&mut |v, occurs| match occurs {
            Occurs::Read => *remap.get(&v).unwrap_or(&v),
            Occurs::Defined => {
                let info = self.vars[v.0 as usize].clone();
                let n = self.new_var(info.ty, info.name);
                remap.insert(v, n);
                n
            }
        })
    }
}

/// A readable dump of a function, for tests and debugging.
impl std::fmt::Display for Function {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = |x: &Var| format!("%{}", x.0);
        let params: Vec<String> = self
            .params
            .iter()
            .map(|p| format!("{}: {:?}", v(p), self.ty(*p)))
            .collect();
        writeln!(f, "fn {}({}) {{", self.name, params.join(", "))?;
        fn block(
            func: &Function,
            b: &Block,
            depth: usize,
            f: &mut std::fmt::Formatter<'_>,
        ) -> std::fmt::Result {
            let pad = "  ".repeat(depth);
            let v = |x: &Var| format!("%{}", x.0);
            for s in &b.stmts {
                match s {
                    Stmt::Let { var, op } => {
                        let rhs = match op {
                            Op::Const(c) => format!("{c:?}"),
                            Op::Unary(u, a) => format!("{u:?} {}", v(a)),
                            Op::Binary(o, a, b) => format!("{o:?} {} {}", v(a), v(b)),
                            Op::Select(c, a, b) => format!("select {} {} {}", v(c), v(a), v(b)),
                        };
                        writeln!(f, "{pad}{}: {:?} = {rhs}", v(var), func.ty(*var))?;
                    }
                    Stmt::If {
                        cond,
                        then_block,
                        else_block,
                        outs,
                    } => {
                        let outs: Vec<String> = outs.iter().map(v).collect();
                        writeln!(f, "{pad}[{}] = if {} {{", outs.join(", "), v(cond))?;
                        block(func, then_block, depth + 1, f)?;
                        writeln!(f, "{pad}}} else {{")?;
                        block(func, else_block, depth + 1, f)?;
                        writeln!(f, "{pad}}}")?;
                    }
                    Stmt::Call {
                        callee, args, outs, ..
                    } => {
                        let outs: Vec<String> = outs.iter().map(v).collect();
                        let args: Vec<String> = args.iter().map(v).collect();
                        writeln!(
                            f,
                            "{pad}[{}] = call #{callee}({})",
                            outs.join(", "),
                            args.join(", ")
                        )?;
                    }
                }
            }
            let ys: Vec<String> = b.yields.iter().map(v).collect();
            writeln!(f, "{pad}yield {}", ys.join(", "))
        }
        block(self, &self.body, 1, f)?;
        writeln!(f, "}}")
    }
}
