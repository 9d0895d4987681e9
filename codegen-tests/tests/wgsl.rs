//! The WGSL of every module (compiler corpus, examples, methods): it was validated by naga when
//! the macro expanded; here the text naga wrote is parsed again (naga's WGSL front end) and
//! validated again, since the validator alone does not catch every emit mistake; the signature
//! table the compiler emits beside it (what the GPU runtime builds its entry points from) is
//! checked against the parsed functions. The WGSL of one small method is snapshot-tested.

use codegen_tests::corpus;
use splat_runtime::{WgslFunction, WgslScalar};

fn scalar(module: &naga::Module, ty: naga::Handle<naga::Type>) -> WgslScalar {
    match module.types[ty].inner {
        naga::TypeInner::Scalar(s) => match s.kind {
            naga::ScalarKind::Float => WgslScalar::F32,
            naga::ScalarKind::Uint => WgslScalar::U32,
            naga::ScalarKind::Sint => WgslScalar::I32,
            _ => WgslScalar::Bool,
        },
        ref other => panic!("unexpected argument type {other:?}"),
    }
}

fn reparse(name: &str, wgsl: &str, table: &[WgslFunction], kernels: &[&str]) {
    let module = naga::front::wgsl::parse_str(wgsl)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(wgsl)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(wgsl)));
    let names: Vec<&str> = module
        .functions
        .iter()
        .filter_map(|(_, f)| f.name.as_deref())
        .collect();
    for k in kernels {
        // naga's namer appends `_` to names that are WGSL keywords or built-ins (`mat3`).
        let renamed = format!("{k}_");
        assert!(
            names.contains(k) || names.contains(&renamed.as_str()),
            "{name}: no function `{k}` in {names:?}"
        );
        assert!(
            table.iter().any(|f| f.kernel == *k),
            "{name}: `{k}` missing from the signature table"
        );
    }
    assert_eq!(
        table.len(),
        module.functions.len(),
        "{name}: one entry per function"
    );
    for entry in table {
        let (_, f) = module
            .functions
            .iter()
            .find(|(_, f)| f.name.as_deref() == Some(entry.name))
            .unwrap_or_else(|| panic!("{name}: the table names `{}`, not in the WGSL", entry.name));
        let args: Vec<WgslScalar> = f.arguments.iter().map(|a| scalar(&module, a.ty)).collect();
        assert_eq!(args, entry.args, "{name}: arguments of `{}`", entry.name);
        let result = f.result.as_ref().expect("a struct result");
        let naga::TypeInner::Struct { members, .. } = &module.types[result.ty].inner else {
            panic!("{name}: `{}` does not return a struct", entry.name);
        };
        let results: Vec<(&str, WgslScalar)> = members
            .iter()
            .map(|m| (m.name.as_deref().unwrap_or(""), scalar(&module, m.ty)))
            .collect();
        assert_eq!(
            results, entry.results,
            "{name}: results of `{}`",
            entry.name
        );
    }
}

#[test]
fn every_module_reparses_and_validates() {
    let modules: &[(&str, &str, &[WgslFunction], &[&str])] = &[
        (
            "scalars",
            corpus::scalars::GENERATED_WGSL,
            corpus::scalars::GENERATED_FUNCTIONS,
            &["arith", "arith_adjoint", "trig", "misc_adjoint", "sincos"],
        ),
        (
            "vectors",
            corpus::vectors::GENERATED_WGSL,
            corpus::vectors::GENERATED_FUNCTIONS,
            &["geometry", "rotate_adjoint", "components"],
        ),
        (
            "matrices",
            corpus::matrices::GENERATED_WGSL,
            corpus::matrices::GENERATED_FUNCTIONS,
            &["mat3", "mat2_adjoint", "covariance_adjoint"],
        ),
        (
            "control",
            corpus::control::GENERATED_WGSL,
            corpus::control::GENERATED_FUNCTIONS,
            &["nested", "statements_adjoint", "array_loop", "flags"],
        ),
        (
            "structured",
            corpus::structured::GENERATED_WGSL,
            corpus::structured::GENERATED_FUNCTIONS,
            &["sh_color", "splat_of_adjoint", "uses_custom_adjoint"],
        ),
        (
            "kinks",
            corpus::kinks::GENERATED_WGSL,
            corpus::kinks::GENERATED_FUNCTIONS,
            &["nan_branch_adjoint", "inf_branch", "normalize_of_adjoint"],
        ),
        (
            "isotropic",
            splat_examples::isotropic::isotropic::GENERATED_WGSL,
            splat_examples::isotropic::isotropic::GENERATED_FUNCTIONS,
            &["project", "tile_cull", "evaluate_adjoint"],
        ),
        (
            "features",
            splat_examples::features::features::GENERATED_WGSL,
            splat_examples::features::features::GENERATED_FUNCTIONS,
            &["project_adjoint", "evaluate"],
        ),
        (
            "gs3d",
            splat_methods::gs3d::GENERATED_WGSL,
            splat_methods::gs3d::GENERATED_FUNCTIONS,
            &[
                "project",
                "project_adjoint",
                "tile_cull",
                "evaluate",
                "evaluate_adjoint",
            ],
        ),
    ];
    for (name, wgsl, table, kernels) in modules {
        reparse(name, wgsl, table, kernels);
    }
}

#[test]
fn generated_wgsl_snapshot() {
    insta::assert_snapshot!(splat_examples::isotropic::isotropic::GENERATED_WGSL);
}

/// The WGSL `erf` is written with the compiler's copy of the runtime's coefficients (the
/// compiler cannot depend on the runtime): the two must be the same numbers.
#[test]
fn wgsl_erf_uses_the_runtime_coefficients() {
    use splat_compiler::emit::naga as wgsl;
    use splat_runtime::math;
    assert_eq!(wgsl::ERF_SERIES, math::ERF_SERIES);
    assert_eq!(wgsl::ERFC_FIT, math::ERFC_FIT);
}
