//! Bit-mask data flow over the structured IR: the two analyses the passes share. Each bit
//! stands for a source (an input, a result, a gradient group); a variable's mask is the union
//! over every path that links it to a source, through operands and through the conditions of
//! the branches that choose a value.
//!
//! - [`depends`], forward: what each variable is computed from (the gradient groups that flow
//!   through each shade field and through alpha, `gate::dependencies`);
//! - [`needs`], backward: what each variable is needed for (dead-code elimination, with one bit;
//!   gating by gradient group, with one bit per group).
//!
//! Both are one walk, with no fixed point, because of the IR's invariants (`ir.rs`): each
//! variable is defined once, before every use.

use crate::ir::{Block, Stmt, Var};
use std::collections::{HashMap, HashSet};

/// A mask per variable; a variable absent has none.
pub type Masks = HashMap<Var, u32>;

/// The mask of `v` in `m`.
pub fn mask(m: &Masks, v: &Var) -> u32 {
    m.get(v).copied().unwrap_or(0)
}

/// The union of the masks of what `s` defines (at its own level).
pub fn defined_mask(s: &Stmt, m: &Masks) -> u32 {
    s.defines().iter().fold(0, |a, v| a | mask(m, v))
}

fn add(m: &mut Masks, v: Var, bits: u32) {
    *m.entry(v).or_insert(0) |= bits;
}

/// How [`needs`] sees a helper with its own adjoint (`Stmt::Call`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Calls {
    /// As one operation: its user-written adjoint runs whole, so everything the call reads is
    /// needed by each of its outputs (gating).
    Whole,
    /// Through its body, the inlined helper the forward pass computes: only the parts of the
    /// body that an output needs are needed (dead-code elimination). The call's `args` are
    /// not marked: the body reads what it needs.
    Inside,
}

/// Sets in `on` the mask of every variable `b` defines, nested ones too: the union of its
/// operands' masks and `under`, the masks of the conditions of the branches enclosing `b`.
/// `on` holds the masks of what `b` reads from outside. A call's outputs depend on everything
/// it reads (its adjoint is a user's, opaque to the analysis).
pub fn depends(b: &Block, under: u32, on: &mut Masks) {
    for s in &b.stmts {
        match s {
            Stmt::Let { var, op } => {
                let d = op.operands().iter().fold(under, |a, o| a | mask(on, o));
                on.insert(*var, d);
            }
            Stmt::If {
                cond,
                then_block,
                else_block,
                outs,
            } => {
                let inner = under | mask(on, cond);
                depends(then_block, inner, on);
                depends(else_block, inner, on);
                for (k, o) in outs.iter().enumerate() {
                    let sides = mask(on, &then_block.yields[k]) | mask(on, &else_block.yields[k]);
                    on.insert(*o, inner | sides);
                }
            }
            Stmt::Call {
                args, body, outs, ..
            } => {
                depends(body, under, on);
                let mut read = HashSet::new();
                body.reads(&mut read);
                let d = args.iter().chain(&read).fold(under, |a, v| a | mask(on, v));
                for o in outs {
                    on.insert(*o, d);
                }
            }
        }
    }
}

/// Adds to `of` the mask of every variable a statement of `b` (or one nested in it) reads: the
/// union of the masks of what reads it, a branch's condition taking those of the branch's
/// outputs. `of` holds the masks of `b`'s yields (and of what follows `b`). A statement whose
/// outputs have no mask needs nothing.
pub fn needs(b: &Block, of: &mut Masks, calls: Calls) {
    for s in b.stmts.iter().rev() {
        let bits = defined_mask(s, of);
        if bits == 0 {
            continue;
        }
        match s {
            Stmt::Let { op, .. } => {
                for o in op.operands() {
                    add(of, o, bits);
                }
            }
            Stmt::If {
                cond,
                then_block,
                else_block,
                outs,
            } => {
                for side in [then_block, else_block] {
                    for (y, o) in side.yields.iter().zip(outs) {
                        add(of, *y, mask(of, o));
                    }
                    needs(side, of, calls);
                }
                add(of, *cond, bits);
            }
            Stmt::Call {
                args, body, outs, ..
            } => match calls {
                Calls::Whole => {
                    let mut read = HashSet::new();
                    body.reads(&mut read);
                    for v in args.iter().copied().chain(read) {
                        add(of, v, bits);
                    }
                }
                Calls::Inside => {
                    for (y, o) in body.yields.iter().zip(outs) {
                        add(of, *y, mask(of, o));
                    }
                    needs(body, of, calls);
                }
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Calls, Masks, depends, mask, needs};
    use crate::ir::{Binary, Block, Const, Function, Op, Scalar, Stmt, Var};

    fn add(f: &mut Function, a: Var, b: Var) -> (Var, Stmt) {
        let var = f.new_var(Scalar::F32, "s");
        let op = Op::Binary(Binary::Add, a, b);
        (var, Stmt::Let { var, op })
    }

    /// `f(x, y, z)`: `c = x < z`; `(r, s) = if c { (y, y + y) } else { (z, z + z) }`; returns
    /// `(r, s)`, or only `r` when `both` is false. Also returns `[t, zz, c]`, the two sums
    /// and the condition.
    fn branchy(both: bool) -> (Function, [Var; 3]) {
        let mut f = Function::new("f");
        let [x, y, z] = ["x", "y", "z"].map(|n| f.new_var(Scalar::F32, n));
        f.params = vec![x, y, z];
        let c = f.new_var(Scalar::Bool, "c");
        let let_c = Stmt::Let {
            var: c,
            op: Op::Binary(Binary::Lt, x, z),
        };
        let (t, let_t) = add(&mut f, y, y);
        let (zz, let_zz) = add(&mut f, z, z);
        let outs = vec![f.new_var(Scalar::F32, "r"), f.new_var(Scalar::F32, "s")];
        let branch = Stmt::If {
            cond: c,
            then_block: Block {
                stmts: vec![let_t],
                yields: vec![y, t],
            },
            else_block: Block {
                stmts: vec![let_zz],
                yields: vec![z, zz],
            },
            outs: outs.clone(),
        };
        f.body = Block {
            stmts: vec![let_c, branch],
            yields: if both { outs } else { vec![outs[0]] },
        };
        (f, [t, zz, c])
    }

    #[test]
    fn a_value_depends_on_its_operands_and_on_the_conditions_that_choose_it() {
        let (f, [t, zz, c]) = branchy(true);
        let mut on: Masks = f
            .params
            .iter()
            .zip([1, 2, 4])
            .map(|(v, m)| (*v, m))
            .collect();
        depends(&f.body, 0, &mut on);
        let [r, s] = [f.body.yields[0], f.body.yields[1]];
        assert_eq!(mask(&on, &c), 1 | 4);
        // Computed inside the branch: on the condition too.
        assert_eq!([t, zz].map(|v| mask(&on, &v)), [1 | 2 | 4, 1 | 4]);
        // `r` is `y` or `z`: it reaches `x` only through the condition.
        assert_eq!([r, s].map(|v| mask(&on, &v)), [1 | 2 | 4, 1 | 2 | 4]);
    }

    #[test]
    fn a_value_is_needed_by_what_reads_it_and_a_condition_by_what_its_branch_chooses() {
        let (f, [t, zz, c]) = branchy(true);
        let [x, y, z] = [f.params[0], f.params[1], f.params[2]];
        let mut of: Masks = f
            .body
            .yields
            .iter()
            .zip([1, 2])
            .map(|(v, m)| (*v, m))
            .collect();
        needs(&f.body, &mut of, Calls::Inside);
        assert_eq!([t, zz, c].map(|v| mask(&of, &v)), [2, 2, 1 | 2]);
        assert_eq!([x, y, z].map(|v| mask(&of, &v)), [1 | 2, 1 | 2, 1 | 2]);
        // With `s` gone, what only it chose is not needed.
        let (f, [t, zz, c]) = branchy(false);
        let mut of: Masks = [(f.body.yields[0], 1)].into();
        needs(&f.body, &mut of, Calls::Inside);
        assert_eq!([t, zz, c].map(|v| mask(&of, &v)), [0, 0, 1]);
    }

    #[test]
    fn dead_code_elimination_narrows_a_branch_to_the_outputs_needed() {
        let (mut f, [t, zz, _]) = branchy(false);
        crate::opt::dce(&mut f);
        let Stmt::If {
            then_block,
            else_block,
            outs,
            ..
        } = &f.body.stmts[1]
        else {
            panic!("the branch is kept: {f}");
        };
        assert_eq!(
            (outs.len(), then_block.yields.len(), else_block.yields.len()),
            (1, 1, 1)
        );
        assert!(
            !f.body.defined().contains(&t) && !f.body.defined().contains(&zz),
            "{f}"
        );
    }

    #[test]
    fn a_call_is_needed_whole_or_through_its_body() {
        // `[o1, o2] = call(x, y)` whose body yields `(x + x, y + y)`; only `o1` is needed.
        let mut f = Function::new("f");
        let [x, y] = ["x", "y"].map(|n| f.new_var(Scalar::F32, n));
        f.params = vec![x, y];
        let (xx, let_xx) = add(&mut f, x, x);
        let (yy, let_yy) = add(&mut f, y, y);
        let outs = vec![f.new_var(Scalar::F32, "o1"), f.new_var(Scalar::F32, "o2")];
        let one = f.new_var(Scalar::F32, "one");
        let call = Stmt::Call {
            callee: 0,
            args: vec![x, y],
            outs: outs.clone(),
            body: Block {
                stmts: vec![let_xx, let_yy],
                yields: vec![xx, yy],
            },
        };
        let konst = Stmt::Let {
            var: one,
            op: Op::Const(Const::F(1.0)),
        };
        f.body = Block {
            stmts: vec![konst, call],
            yields: vec![outs[0]],
        };
        let needed = |calls| {
            let mut of: Masks = [(outs[0], 1)].into();
            needs(&f.body, &mut of, calls);
            [x, y, xx, yy, one].map(|v| mask(&of, &v))
        };
        assert_eq!(needed(Calls::Whole), [1, 1, 1, 1, 0]);
        assert_eq!(needed(Calls::Inside), [1, 0, 1, 0, 0]);
        // Seen from outside, each output depends on all the call reads.
        let mut on: Masks = [(x, 1), (y, 2)].into();
        depends(&f.body, 0, &mut on);
        assert_eq!([outs[0], outs[1]].map(|o| mask(&on, &o)), [1 | 2, 1 | 2]);
    }
}
