//! Dead-code elimination: drops every statement whose value no result depends on (after AD
//! this removes the parts of the recomputed primal that the reverse sweep does not need), and
//! the unused outputs of branches and calls.

use crate::flow::{self, Calls, Masks};
use crate::ir::{Block, Function, Stmt, Var};

pub fn dce(f: &mut Function) {
    let mut live: Masks = f.body.yields.iter().map(|y| (*y, 1)).collect();
    flow::needs(&f.body, &mut live, Calls::Inside);
    prune(&mut f.body, &|v| flow::mask(&live, v) != 0);
}

/// Removes from `b` what defines nothing `live`.
fn prune(b: &mut Block, live: &impl Fn(&Var) -> bool) {
    b.stmts.retain_mut(|s| match s {
        Stmt::Let { var, .. } => live(var),
        Stmt::If {
            then_block,
            else_block,
            outs,
            ..
        } => narrow(outs, [then_block, else_block], live),
        Stmt::Call { outs, body, .. } => narrow(outs, [body], live),
    });
}

/// Keeps the outputs that are `live` of a statement with nested `blocks` (and the yields that
/// give them) and prunes the blocks; false when none is live.
fn narrow<const N: usize>(
    outs: &mut Vec<Var>,
    blocks: [&mut Block; N],
    live: &impl Fn(&Var) -> bool,
) -> bool {
    let kept: Vec<usize> = (0..outs.len()).filter(|&i| live(&outs[i])).collect();
    if kept.is_empty() {
        return false;
    }
    *outs = kept.iter().map(|&i| outs[i]).collect();
    for b in blocks {
        b.yields = kept.iter().map(|&i| b.yields[i]).collect();
        prune(b, live);
    }
    true
}
