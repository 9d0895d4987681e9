//! Camera models as compiled variants: each model-aware kernel is also compiled once per
//! camera model, with the other models' branches folded away. The variants the runtime calls
//! equal the generic kernels bit for bit, and the other models' code is not in them (neither
//! in the Rust nor in the WGSL). Likewise the SH degree: a method's instance for a lower degree
//! renders and differentiates a scene without higher terms as the full instance does.

use crate::common::{as_method, spread_gaussians, wide_camera};
use splat_methods::FromStored;
use splat_methods::{
    geer, geer_sh0, geer_sh1, geer_sh2, gs3d, gs3d_sh0, gs3d_sh1, gs3d_sh2, gut, gut_sh0, gut_sh1,
    gut_sh2, linprim,
};
use splat_runtime::checks::variants::{
    lower_sh_degree_matches_full, specialized_kernels_match_generic,
};
use splat_runtime::io::ply::sh_coefficients;
use splat_runtime::{CameraModel, SplatMethod};

#[test]
fn specialized_kernels_equal_the_generic_ones_on_every_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        let gaussians = spread_gaussians(&cam, 40, 5);
        specialized_kernels_match_generic::<gut::Method>(
            "3dgut",
            &as_method(gaussians.clone()),
            &cam,
        );
        specialized_kernels_match_generic::<geer::Method>(
            "3dgeer",
            &as_method(gaussians.clone()),
            &cam,
        );
        specialized_kernels_match_generic::<gs3d::Method>("3dgs", &gaussians, &cam);
    }
}

#[test]
fn each_sh_degree_instance_renders_as_the_full_method() {
    matches_full::<gs3d::Method, gs3d_sh0::Method>(0);
    matches_full::<gs3d::Method, gs3d_sh1::Method>(1);
    matches_full::<gs3d::Method, gs3d_sh2::Method>(2);
    matches_full::<gut::Method, gut_sh0::Method>(0);
    matches_full::<gut::Method, gut_sh1::Method>(1);
    matches_full::<gut::Method, gut_sh2::Method>(2);
    matches_full::<geer::Method, geer_sh0::Method>(0);
    matches_full::<geer::Method, geer_sh1::Method>(1);
    matches_full::<geer::Method, geer_sh2::Method>(2);
}

/// `Low`, the instance for SH degree `degree`, against `Full` on Gaussians of that degree.
fn matches_full<Full: SplatMethod, Low: SplatMethod>(degree: u32)
where
    Full::Params: FromStored,
{
    let cam = wide_camera(40, 32, CameraModel::Pinhole);
    let mut gaussians = spread_gaussians(&cam, 60, 6);
    for g in &mut gaussians {
        g.sh[sh_coefficients(degree)..].fill(Default::default());
    }
    let label = format!("degree {degree}");
    lower_sh_degree_matches_full::<Full, Low>(&label, &as_method(gaussians), &cam);
}

/// The text of the item that starts with `start` in `source`, up to its closing brace at the
/// start of a line (generated Rust and WGSL are both formatted that way).
fn item<'s>(source: &'s str, start: &str) -> &'s str {
    let at = source
        .find(start)
        .unwrap_or_else(|| panic!("`{start}` is not in the generated source"));
    let rest = &source[at..];
    let indent = source[..at].len() - source[..at].trim_end_matches(' ').len();
    let close = format!("\n{}}}", " ".repeat(indent));
    &rest[..rest.find(&close).expect("a closing brace") + close.len()]
}

#[test]
fn a_models_variant_holds_none_of_the_other_models_code() {
    // The fisheye's and the equiangular camera's projections take atan2; the pinhole's does not.
    let rust = gut::GENERATED_RUST;
    let wgsl = gut::GENERATED_WGSL;
    let generic = item(rust, "pub fn project(");
    assert!(
        generic.contains("atan2"),
        "the generic kernel branches on the model"
    );
    let pinhole = item(rust, "pub mod pinhole {");
    assert!(pinhole.contains("pub fn project("), "{pinhole}");
    assert!(!pinhole.contains("atan2"), "pinhole variant:\n{pinhole}");
    assert!(item(rust, "pub mod kannala_brandt {").contains("atan2"));
    assert!(!item(wgsl, "fn project_pinhole(").contains("atan2"));
    assert!(!item(wgsl, "fn project_adjoint_pinhole(").contains("atan2"));
    assert!(item(wgsl, "fn project_equiangular(").contains("atan2"));
    // Variants exist only for kernels that read the model.
    assert!(!linprim::GENERATED_RUST.contains("pub mod pinhole"));
    assert!(
        gut::Method::SOURCE
            .function("pixel_info_kannala_brandt")
            .is_some()
    );
    assert!(gut::Method::SOURCE.function("evaluate_pinhole").is_none());
}

/// The runtime finds a model's kernels by the model's name: every model of `cameras.rs` has
/// them, named as `CameraModel::name` says.
#[test]
fn every_camera_model_has_its_kernels_under_its_name() {
    for model in CameraModel::ALL {
        for kernel in [
            "project",
            "project_adjoint",
            "pixel_info",
            "pixel_info_adjoint",
        ] {
            let name = format!("{kernel}_{model}");
            assert!(
                gut::Method::SOURCE.function(&name).is_some(),
                "3DGUT has no `{name}`"
            );
        }
    }
}
