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
    use crate::typeck::rules::method_names;
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

/// Every method, constructor and operator the type rules accept lowers: a rule without its
/// lowering would panic there.
#[test]
fn everything_the_type_rules_accept_lowers() {
    use crate::typeck::rules::{self, Arg};
    use crate::types::Ty;
    let types = [
        Ty::F32,
        Ty::Bool,
        Ty::U32,
        Ty::I32,
        Ty::Vec(2),
        Ty::Vec(3),
        Ty::Vec(4),
        Ty::Mat(2),
        Ty::Mat(3),
        Ty::Quat,
    ];
    let lowers = |params: &[Ty], call: &str| {
        let params: Vec<String> = params
            .iter()
            .enumerate()
            .map(|(i, t)| format!("a{i}: {t}"))
            .collect();
        compile(&format!(
            "mod m {{ fn f({}) -> f32 {{ let _y = {call}; 0.0 }} }}",
            params.join(", ")
        ));
    };
    let with_args = |recv: Option<&Ty>, sig: &rules::Sig| {
        let mut params: Vec<Ty> = recv.into_iter().cloned().collect();
        let mut args = vec![];
        for a in &sig.args {
            match a {
                Arg::Is(t, _) => {
                    args.push(format!("a{}", params.len()));
                    params.push(t.clone());
                }
                Arg::Integer(_) => args.push("1".into()),
            }
        }
        (params, args.join(", "))
    };
    for t in &types {
        let swizzles = matches!(t, Ty::Vec(_)).then_some(["xy", "yx", "xyz", "zyx"]);
        let names = rules::method_names(t)
            .into_iter()
            .chain(swizzles.into_iter().flatten());
        for name in names {
            let Some(sig) = rules::method(t, name) else {
                continue;
            };
            let (params, args) = with_args(Some(t), &sig);
            lowers(&params, &format!("a0.{name}({args})"));
        }
    }
    let constructors = [
        ("Vec2", "new"),
        ("Vec3", "new"),
        ("Vec4", "new"),
        ("Vec3", "splat"),
        ("Mat2", "from_cols"),
        ("Mat3", "from_cols"),
        ("Mat2", "from_diagonal"),
        ("Mat3", "from_diagonal"),
        ("Mat3", "from_quat"),
        ("Quat", "from_xyzw"),
    ];
    for (owner, item) in constructors {
        let Some(rules::Path::Constructor(sig)) = rules::path_call(owner, item) else {
            panic!("{owner}::{item} is a constructor");
        };
        let (params, args) = with_args(None, &sig);
        lowers(&params, &format!("{owner}::{item}({args})"));
    }
    let ops = [
        "+", "-", "*", "/", "%", "&", "|", "^", "<<", ">>", "==", "!=", "<", "<=", ">", ">=", "&&",
        "||",
    ];
    let mut pairs = 0;
    for sym in ops {
        let op: syn::BinOp = syn::parse_str(sym).unwrap();
        let (op, _, _) = rules::binary_op(&op).unwrap();
        for l in &types {
            for r in &types {
                if rules::binary(op, l, r).is_some() {
                    lowers(&[l.clone(), r.clone()], &format!("a0 {sym} a1"));
                    pairs += 1;
                }
            }
        }
    }
    assert!(pairs > 60, "{pairs}");
}

#[test]
fn expansion_is_the_same_every_time_with_constants_in_source_order() {
    let src = quote::quote!(
        mod m {
            const E: f32 = 5.0;
            const B: f32 = 2.0;
            const D: f32 = 4.0;
            const A: f32 = 1.0;
            const C: f32 = 3.0;
            fn f(x: f32) -> f32 {
                x * (A + B + C + D + E)
            }
        }
    );
    let expand = || crate::expand(Kind::Functions, quote::quote!(), src.clone()).to_string();
    let out = expand();
    let at = |name: &str| out.find(&format!("pub const {name} :")).expect(name);
    let order = ["E", "B", "D", "A", "C"].map(at);
    assert!(
        order.is_sorted(),
        "constants out of source order: {order:?}\n{out}"
    );
    assert_eq!(out, expand());
}

#[test]
fn a_name_defined_twice_is_an_error_at_the_second() {
    let e = errors(
        "mod m { const A: f32 = 1.0; fn f(x: f32) -> f32 { x * A } const A: f32 = 2.0; fn f() {} struct S { a: f32 } struct S { b: f32 } }",
    );
    let twice = |name: &str| format!("`{name}` is defined more than once in this module");
    for name in ["A", "f", "S"] {
        assert_eq!(e.iter().filter(|m| **m == twice(name)).count(), 1, "{e:?}");
    }
}
