//! Dead-code elimination: drops every statement whose value no result depends on (after AD
//! this removes the parts of the recomputed primal that the reverse sweep does not need), and
//! the unused outputs of branches.

use crate::ir::{Block, Function, Stmt, Var};
use std::collections::HashSet;

pub fn dce(f: &mut Function) {
    let mut live = HashSet::new();
    dce_block(&mut f.body, &mut live);
}

fn dce_block(b: &mut Block, live: &mut HashSet<Var>) {
    live.extend(b.yields.iter().copied());
    let mut kept = vec![];
    for mut s in std::mem::take(&mut b.stmts).into_iter().rev() {
        let keep = match &mut s {
            Stmt::Let { var, op } => {
                let k = live.contains(var);
                if k {
                    live.extend(op.operands());
                }
                k
            }
            Stmt::If {
                cond,
                then_block,
                else_block,
                outs,
            } => {
                let used: Vec<usize> = (0..outs.len())
                    .filter(|&i| live.contains(&outs[i]))
                    .collect();
                if used.is_empty() {
                    false
                } else {
                    *outs = used.iter().map(|&i| outs[i]).collect();
                    then_block.yields = used.iter().map(|&i| then_block.yields[i]).collect();
                    else_block.yields = used.iter().map(|&i| else_block.yields[i]).collect();
                    dce_block(then_block, live);
                    dce_block(else_block, live);
                    live.insert(*cond);
                    true
                }
            }
            Stmt::Call { outs, body, .. } => {
                let used: Vec<usize> = (0..outs.len())
                    .filter(|&i| live.contains(&outs[i]))
                    .collect();
                if used.is_empty() {
                    false
                } else {
                    *outs = used.iter().map(|&i| outs[i]).collect();
                    body.yields = used.iter().map(|&i| body.yields[i]).collect();
                    dce_block(body, live);
                    true
                }
            }
        };
        if keep {
            kept.push(s);
        }
    }
    kept.reverse();
    b.stmts = kept;
}
