//! Unit tests of the compiler's passes on IR, without going through a proc-macro.

use crate::ir::{Function, Op, Stmt, Unary};
use crate::{Kind, compile_ir};

fn compile(src: &str) -> Vec<(Function, Option<Function>)> {
    let item: syn::ItemMod = syn::parse_str(src).expect("valid Rust");
    match compile_ir(Kind::Functions, item) {
        Ok(c) => c.kernels,
        Err(e) => panic!("compile errors: {e:?}"),
    }
}

fn errors(src: &str) -> Vec<String> {
    let item: syn::ItemMod = syn::parse_str(src).expect("valid Rust");
    compile_ir(Kind::Functions, item)
        .err()
        .expect("errors expected")
}

fn count(f: &Function, pred: &dyn Fn(&Stmt) -> bool) -> usize {
    let mut n = 0;
    f.body.visit(&mut |s| n += pred(s) as usize);
    n
}

fn is_unary(u: Unary) -> impl Fn(&Stmt) -> bool {
    move |s| matches!(s, Stmt::Let { op: Op::Unary(v, _), .. } if *v == u)
}

#[test]
fn values_are_flattened_to_scalar_slots() {
    let k = compile("mod m { fn f(a: Vec3, m: Mat3, q: Quat) -> Vec2 { (m * a).xy() * q.w } }");
    let (f, adj) = &k[0];
    assert_eq!(f.params.len(), 3 + 9 + 4);
    assert_eq!(f.results().len(), 2);
    // The adjoint takes the two result cotangents and returns one per input slot.
    let adj = adj.as_ref().unwrap();
    assert_eq!(adj.params.len(), 16 + 2);
    assert_eq!(adj.results().len(), 16);
}

#[test]
fn loops_unroll_and_branches_on_the_counter_fold_away() {
    let k = compile(
        "mod m { fn f(x: f32) -> f32 { let mut s = x; for i in 0..4 { if i == 2 { s = s * x; } else { s = s + x; } } s } }",
    );
    let (f, _) = &k[0];
    assert_eq!(count(f, &|s| matches!(s, Stmt::If { .. })), 0, "{f}");
}

#[test]
fn dead_primal_code_is_removed_from_the_adjoint() {
    let k =
        compile("mod m { fn f(x: f32, y: f32) -> f32 { let unused = y.sin(); x.exp() * 2.0 } }");
    let (f, adj) = &k[0];
    assert_eq!(count(f, &is_unary(Unary::Sin)), 0);
    let adj = adj.as_ref().unwrap();
    assert_eq!(count(adj, &is_unary(Unary::Sin)), 0);
    assert_eq!(
        count(adj, &is_unary(Unary::Exp)),
        1,
        "the primal exp is recomputed once: {adj}"
    );
}

#[test]
fn the_adjoint_of_a_branch_is_a_branch_on_the_same_condition() {
    let k = compile("mod m { fn f(x: f32) -> f32 { if x > 0.0 { x.ln() } else { x * x } } }");
    let (f, adj) = &k[0];
    let cond = |g: &Function| {
        g.body.stmts.iter().find_map(|s| {
            if let Stmt::If { cond, .. } = s {
                Some(*cond)
            } else {
                None
            }
        })
    };
    let adj = adj.as_ref().unwrap();
    // Only the reverse branch remains: it recomputes the side it takes, and the primal
    // branch's value is not needed by the adjoint, so DCE removed it.
    assert_eq!(count(adj, &|s| matches!(s, Stmt::If { .. })), 1, "{adj}");
    let reverse_conds: Vec<_> = adj
        .body
        .stmts
        .iter()
        .filter_map(|s| {
            if let Stmt::If { cond, .. } = s {
                Some(*cond)
            } else {
                None
            }
        })
        .collect();
    assert!(reverse_conds.iter().all(|c| Some(*c) == cond(f)), "{adj}");
}

#[test]
fn errors_are_collected_not_stopped_at_the_first() {
    let e = errors("mod m { fn f(x: f32) -> f32 { let a = x.nope(); let b = 1 + x; loop {} } }");
    assert_eq!(e.len(), 3, "{e:?}");
}

#[test]
fn helpers_are_inlined_and_custom_adjoints_kept_as_calls() {
    let k = compile(
        "mod m {
            fn sq(x: f32) -> f32 { x * x }
            #[adjoint(cube_adjoint)]
            fn cube(x: f32) -> f32 { x * x * x }
            fn cube_adjoint(x: f32, d_out: f32) -> f32 { 3.0 * x * x * d_out }
            fn f(x: f32) -> f32 { sq(x) + cube(x) }
        }",
    );
    // Kernels: sq, cube and f (the adjoint function itself is not a kernel).
    assert_eq!(k.len(), 3);
    let (f, _) = &k[2];
    assert_eq!(count(f, &|s| matches!(s, Stmt::Call { .. })), 1, "{f}");
}

/// Every method the suggestions offer is one the lowering accepts on that type (a call with
/// the wrong arguments fails on its arguments, not as an unknown method); near misses and
/// other libraries' spellings get a suggestion.
#[test]
fn suggested_methods_exist_and_near_misses_get_one() {
    use crate::lower::intrinsics::method_names;
    use crate::types::Ty;
    let types = [
        ("f32", Ty::F32),
        ("u32", Ty::U32),
        ("i32", Ty::I32),
        ("Vec2", Ty::Vec(2)),
        ("Vec3", Ty::Vec(3)),
        ("Vec4", Ty::Vec(4)),
        ("Mat2", Ty::Mat(2)),
        ("Mat3", Ty::Mat(3)),
        ("Quat", Ty::Quat),
    ];
    for (written, ty) in types {
        for name in method_names(&ty) {
            let src =
                format!("mod m {{ fn f(x: {written}) -> f32 {{ let _y = x.{name}(); 0.0 }} }}");
            let item: syn::ItemMod = syn::parse_str(&src).expect("valid Rust");
            let unknown = match compile_ir(Kind::Functions, item) {
                Ok(_) => vec![],
                Err(e) => e.into_iter().filter(|m| m.contains("no method")).collect(),
            };
            assert!(unknown.is_empty(), "{written}::{name}: {unknown:?}");
        }
    }
    let hint = |src: &str| errors(src).join("\n");
    let vec3 = |call: &str| format!("mod m {{ fn f(v: Vec3) -> f32 {{ {call} }} }}");
    assert!(hint(&vec3("v.magnitude()")).contains("did you mean `length`?"));
    assert!(hint(&vec3("v.lenght()")).contains("did you mean `length`?"));
    assert!(hint(&vec3("v.normalise().x")).contains("did you mean `normalize`?"));
    // A spelling whose method the type lacks gets no suggestion.
    let m = hint("mod m { fn f(x: f32) -> f32 { x.magnitude() } }");
    assert!(
        m.contains("see the intrinsic list") && !m.contains("did you mean"),
        "{m}"
    );
}

#[test]
fn gating_puts_each_groups_own_work_behind_its_bit() {
    // d_x needs only p; d_y needs the chain's derivatives (the cosines): a long run of its own.
    let k = compile(
        "mod m { fn f(x: f32, y: f32) -> f32 { let mut p = y; for _i in 0..6 { p = (p * 1.5 + 0.5).sin(); } x.exp() * p } }",
    );
    let mut adj = k[0].1.clone().unwrap();
    let mask = crate::gate::gate(&mut adj, &[1, 2]);
    assert_eq!(adj.params.last(), Some(&mask));
    let top = |u: Unary| adj.body.stmts.iter().filter(|s| is_unary(u)(s)).count();
    assert_eq!(
        top(Unary::Exp),
        1,
        "shared work stays unconditional:\n{adj}"
    );
    assert_eq!(top(Unary::Sin), 6, "the primal chain feeds both:\n{adj}");
    assert_eq!(
        top(Unary::Cos),
        0,
        "d_y's own work is behind its bit:\n{adj}"
    );
    assert_eq!(count(&adj, &is_unary(Unary::Cos)), 6, "{adj}");
    assert_eq!(count(&adj, &|s| matches!(s, Stmt::If { .. })), 1, "{adj}");
}
