//! The WGSL of every module (compiler corpus, examples, methods): it was validated by naga when
//! the macro expanded; here the text naga wrote is parsed again (naga's WGSL front end) and
//! validated again, since the validator alone does not catch every emit mistake. The WGSL of
//! one small method is snapshot-tested.

use codegen_tests::corpus;

fn reparse(name: &str, wgsl: &str, kernels: &[&str]) {
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
    }
}

#[test]
fn every_module_reparses_and_validates() {
    let modules: &[(&str, &str, &[&str])] = &[
        (
            "scalars",
            corpus::scalars::GENERATED_WGSL,
            &["arith", "arith_adjoint", "trig", "misc_adjoint", "sincos"],
        ),
        (
            "vectors",
            corpus::vectors::GENERATED_WGSL,
            &["geometry", "rotate_adjoint", "components"],
        ),
        (
            "matrices",
            corpus::matrices::GENERATED_WGSL,
            &["mat3", "mat2_adjoint", "covariance_adjoint"],
        ),
        (
            "control",
            corpus::control::GENERATED_WGSL,
            &["nested", "statements_adjoint", "array_loop", "flags"],
        ),
        (
            "structured",
            corpus::structured::GENERATED_WGSL,
            &["sh_color", "splat_of_adjoint", "uses_custom_adjoint"],
        ),
        (
            "kinks",
            corpus::kinks::GENERATED_WGSL,
            &["nan_branch_adjoint", "inf_branch", "normalize_of_adjoint"],
        ),
        (
            "isotropic",
            splat_examples::isotropic::isotropic::GENERATED_WGSL,
            &["project", "tile_cull", "evaluate_adjoint"],
        ),
        (
            "features",
            splat_examples::features::features::GENERATED_WGSL,
            &["project_adjoint", "evaluate"],
        ),
        (
            "gs3d",
            splat_methods::gs3d::GENERATED_WGSL,
            &[
                "project",
                "project_adjoint",
                "tile_cull",
                "evaluate",
                "evaluate_adjoint",
            ],
        ),
    ];
    for (name, wgsl, kernels) in modules {
        reparse(name, wgsl, kernels);
    }
}

#[test]
fn generated_wgsl_snapshot() {
    insta::assert_snapshot!(splat_examples::isotropic::isotropic::GENERATED_WGSL);
}
