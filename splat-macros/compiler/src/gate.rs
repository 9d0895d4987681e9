//! Gradient groups: an adjoint that computes only the cotangents asked for.
//!
//! The results of an adjoint are split into groups (a bit each: the fields of a method's
//! parameters, the camera). [`gate`] adds a `u32` parameter, the mask of wanted groups, and
//! puts every statement that feeds only some groups behind a branch on that mask, so a frozen
//! group's cotangents are never computed: dead-code elimination after AD, decided per call.
//! Results of groups not asked for are zero.
//!
//! A statement's *groups* are the union of the groups of its users (its result's groups for
//! the function's yields). Runs of consecutive statements with the same groups, fewer than the
//! enclosing block's, become one `If` on the mask (the order is kept; short runs run anyway).
//! If `a` feeds `b`, `a`'s groups contain `b`'s, so whenever `b` runs for a group asked for,
//! everything it reads was computed; a value read under a group not asked for may be a
//! placeholder, and so may a result: results are zeroed by their own group's bit. Branches of
//! the source are gated inside too, against their own groups.

use crate::flow::{self, Calls, Masks};
use crate::ir::{Binary, Block, Const, Function, Op, Scalar, Stmt, Var};
use crate::types::{Ty, is_camera};
use std::collections::{HashMap, HashSet};

/// The group bit of the camera's cotangent (the runtime's `GradientSet::CAMERA_BIT`).
pub const CAMERA_BIT: u32 = 31;

/// The bit of field `k` (of the parameters, or of the shade data): fields past the 31st share
/// bit 30 (the runtime's `GradientSet::field_bit`).
pub fn field_bit(k: usize) -> u32 {
    1 << k.min(CAMERA_BIT as usize - 1)
}

/// The group bits of `project`'s adjoint results (the float slots of its parameters and of
/// the camera): field `k` of the parameters is bit `min(k, 30)`, the camera [`CAMERA_BIT`].
pub fn project_groups(params: &Ty, camera: &Ty) -> Vec<u32> {
    let mut out = per_field(params);
    out.extend(std::iter::repeat_n(1 << CAMERA_BIT, float_slots(camera)));
    out
}

/// The group bits of `evaluate`'s adjoint results (the float slots of the pixel data and of the
/// shade data): field `k` of the shade data is bit `min(k, 30)`; the pixel data, whose
/// cotangent only the camera's gradient needs, is [`CAMERA_BIT`].
pub fn evaluate_groups(pixel: &Ty, shade: &Ty) -> Vec<u32> {
    let mut out = vec![1 << CAMERA_BIT; float_slots(pixel)];
    out.extend(per_field(shade));
    out
}

/// For each field of the shade data `project` returns, the groups of `project_groups` whose
/// gradient flows through it: `evaluate`'s adjoint needs the cotangent of a shade field only
/// when one of them is asked for.
pub fn shade_field_groups(project: &Function, params: &Ty, camera: &Ty, shade: &Ty) -> Vec<u32> {
    let mut inputs = per_field_slots(params, &|t| t.slot_count());
    inputs.extend(std::iter::repeat_n(1 << CAMERA_BIT, camera.slot_count()));
    let deps = dependencies(project, &inputs);
    let mut shade_slots = deps[deps.len() - shade.slot_count()..].iter();
    match shade {
        Ty::Struct(s) => s
            .fields
            .iter()
            .map(|(_, t)| {
                let field = shade_slots.by_ref().take(t.slot_count());
                field.fold(0, |a, d| a | d)
            })
            .collect(),
        _ => vec![shade_slots.fold(0, |a, d| a | d)],
    }
}

/// The groups of [`evaluate_groups`] that the cotangent of `evaluate`'s alpha reaches: the
/// shade fields alpha is computed from, and the pixel data's bit when it depends on the pixel.
/// When none is asked for, the blend need not compute alpha's cotangent at all.
pub fn alpha_groups(evaluate: &Function, pixel: &Ty, shade: &Ty) -> u32 {
    let mut inputs = vec![1 << CAMERA_BIT; pixel.slot_count()];
    inputs.extend(per_field_slots(shade, &|t| t.slot_count()));
    // Alpha is the first slot of the `Contribution` evaluate returns.
    dependencies(evaluate, &inputs)[0]
}

/// The bits of every field of `ty` (of the one group of any other type).
pub fn all_fields(ty: &Ty) -> u32 {
    let fields = match ty {
        Ty::Struct(s) if !is_camera(ty) => s.fields.len(),
        _ => 1,
    };
    (0..fields).fold(0, |a, k| a | field_bit(k))
}

/// A bit per field of a struct (one for the whole of any other type), for each float slot.
fn per_field(ty: &Ty) -> Vec<u32> {
    per_field_slots(ty, &float_slots)
}

/// A bit per field of a struct (one for the whole of any other type), repeated `slots(field)`
/// times.
fn per_field_slots(ty: &Ty, slots: &dyn Fn(&Ty) -> usize) -> Vec<u32> {
    match ty {
        Ty::Struct(s) if !is_camera(ty) => s
            .fields
            .iter()
            .enumerate()
            .flat_map(|(k, (_, t))| std::iter::repeat_n(field_bit(k), slots(t)))
            .collect(),
        t => vec![field_bit(0); slots(t)],
    }
}

fn float_slots(t: &Ty) -> usize {
    t.slots().iter().filter(|s| **s == Scalar::F32).count()
}

/// For each result of `f`, the union of `inputs[i]` over the parameters `i` it depends on
/// (through its operands, and through the conditions of the branches it is chosen by).
pub fn dependencies(f: &Function, inputs: &[u32]) -> Vec<u32> {
    let mut on: Masks = f
        .params
        .iter()
        .copied()
        .zip(inputs.iter().copied())
        .collect();
    flow::depends(&f.body, 0, &mut on);
    f.body.yields.iter().map(|y| flow::mask(&on, y)).collect()
}

/// Gates `f`'s results: `groups[i]` is the group bits of result `i`. Returns the mask
/// parameter (appended to `f.params`).
pub fn gate(f: &mut Function, groups: &[u32]) -> Var {
    assert_eq!(groups.len(), f.body.yields.len(), "one group per result");
    let mask = f.new_var(Scalar::U32, "grads");
    f.params.push(mask);
    let mut of = HashMap::new();
    for (y, g) in f.body.yields.iter().zip(groups) {
        *of.entry(*y).or_insert(0) |= *g;
    }
    // A helper's adjoint runs whole, for every group it serves.
    flow::needs(&f.body, &mut of, Calls::Whole);
    let all = groups.iter().fold(0, |a, g| a | g);
    let mut gates = Gates {
        mask,
        of,
        conds: HashMap::new(),
        prelude: vec![],
    };
    let mut body = std::mem::take(&mut f.body);
    gates.rewrite(f, &mut body, all);
    // A result is computed whenever a group sharing its work is asked for, or (in a run too
    // short to branch on) always: zero it unless its own group is asked for.
    let mut tail = vec![];
    for (y, &g) in body.yields.iter_mut().zip(groups) {
        if f.ty(*y) == Scalar::F32 && g != all {
            let cond = gates.cond(f, g);
            let zero = constant(f, Scalar::F32, &mut tail);
            let kept = f.new_var(Scalar::F32, f.name(*y).to_string());
            tail.push(Stmt::Let {
                var: kept,
                op: Op::Select(cond, *y, zero),
            });
            *y = kept;
        }
    }
    body.stmts.extend(tail);
    body.stmts.splice(0..0, std::mem::take(&mut gates.prelude));
    f.body = body;
    mask
}

fn constant(f: &mut Function, ty: Scalar, out: &mut Vec<Stmt>) -> Var {
    let c = match ty {
        Scalar::F32 => Const::F(0.0),
        Scalar::Bool => Const::B(false),
        Scalar::U32 => Const::U(0),
        Scalar::I32 => Const::I(0),
    };
    let var = f.new_var(ty, "zero");
    out.push(Stmt::Let {
        var,
        op: Op::Const(c),
    });
    var
}

struct Gates {
    mask: Var,
    /// The groups of every variable.
    of: Masks,
    /// `mask & groups != 0`, computed once per set of groups...
    conds: HashMap<u32, Var>,
    /// ...in statements that go at the top of the body, so they dominate every use.
    prelude: Vec<Stmt>,
}

impl Gates {
    /// The condition "one of `groups` is asked for".
    fn cond(&mut self, f: &mut Function, groups: u32) -> Var {
        if let Some(c) = self.conds.get(&groups) {
            return *c;
        }
        let bits = f.new_var(Scalar::U32, "group_bits");
        let picked = f.new_var(Scalar::U32, "groups_asked");
        let zero = f.new_var(Scalar::U32, "none");
        let cond = f.new_var(Scalar::Bool, "wanted");
        self.prelude.extend([
            Stmt::Let {
                var: bits,
                op: Op::Const(Const::U(groups)),
            },
            Stmt::Let {
                var: picked,
                op: Op::Binary(Binary::And, self.mask, bits),
            },
            Stmt::Let {
                var: zero,
                op: Op::Const(Const::U(0)),
            },
            Stmt::Let {
                var: cond,
                op: Op::Binary(Binary::Ne, picked, zero),
            },
        ]);
        self.conds.insert(groups, cond);
        cond
    }

    /// Puts each run of consecutive statements of `b` that feed the same groups, fewer than
    /// `enclosing`, behind a branch (runs of fewer than [`MIN_GATED`] operations run anyway);
    /// recurses into the source's own branches. The order is kept: moving statements apart
    /// to make longer runs keeps values live longer, which cost more than the branches saved
    /// (measured: 3DGUT's `project` adjoint 1.7x slower with everything asked for).
    fn rewrite(&mut self, f: &mut Function, b: &mut Block, enclosing: u32) {
        let mut runs: Vec<(u32, Vec<Stmt>)> = vec![];
        for mut s in std::mem::take(&mut b.stmts) {
            let g = flow::defined_mask(&s, &self.of) & enclosing;
            if let Stmt::If {
                then_block,
                else_block,
                ..
            } = &mut s
            {
                self.rewrite(f, then_block, g);
                self.rewrite(f, else_block, g);
            }
            match runs.last_mut() {
                Some((h, run)) if *h == g => run.push(s),
                _ => runs.push((g, vec![s])),
            }
        }
        // Walking back, `later` holds what the statements after the run (and the yields) read.
        let mut later = HashSet::new();
        later.extend(b.yields.iter().copied());
        let mut out: Vec<Vec<Stmt>> = vec![];
        for (g, run) in runs.into_iter().rev() {
            let mut read = HashSet::new();
            for s in &run {
                s.reads_nested(&mut read);
            }
            let run = Block {
                stmts: run,
                yields: vec![],
            };
            if g == enclosing || g == 0 || run.operations() < MIN_GATED {
                later.extend(read);
                out.push(run.stmts);
                continue;
            }
            let mut outs: Vec<Var> = run.defined_here();
            outs.retain(|v| later.contains(v));
            later.extend(read);
            let cond = self.cond(f, g);
            let mut remap = HashMap::new();
            let mut then_block = f.clone_fresh(&run, &mut remap);
            then_block.yields = outs.iter().map(|v| remap[v]).collect();
            let mut else_block = Block::default();
            for v in &outs {
                let zero = constant(f, f.ty(*v), &mut else_block.stmts);
                else_block.yields.push(zero);
            }
            out.push(vec![Stmt::If {
                cond,
                then_block,
                else_block,
                outs,
            }]);
        }
        b.stmts = out.into_iter().rev().flatten().collect();
    }
}

/// The fewest operations worth a branch.
const MIN_GATED: usize = 8;
