//! 3DGS (EWA splatting) on every camera model from one source: `project` takes the Jacobian
//! of `cam.project_point` at the mean from the compiler (`jacobian`), so the fisheye and
//! equiangular cameras need no hand-written derivative. Checked like every method: the CPU
//! render against the f64 brute-force reference (the same EWA approximation, evaluated in
//! f64), render gradients against finite differences (parameters and camera, fisheye
//! coefficients included: second derivatives of the projection), boxes, the GPU against the
//! CPU. EWA's own error on the wide cameras, against 3DGEER's exact integral, is measured by
//! `cargo bench -p splat-methods --bench methods`.

use crate::common::{
    GAUSSIAN_GROUPS, camera_groups, covering_gaussians, spread_gaussians, wide_camera,
};
use splat_methods::gs3d::Method;
use splat_runtime::CameraModel;
use splat_runtime::checks::forward::{
    boxes_hold_every_contributing_pixel, forward_matches_reference, gpu_forward_matches_cpu,
};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gpu_gradients_match_cpu,
    gradients_match_finite_differences, gradients_match_reference_adjoint,
};

#[test]
fn forward_matches_the_reference_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        let params = spread_gaussians(&cam, 60, 31);
        let coverage = forward_matches_reference::<Method>(&format!("3dgs {model}"), &params, &cam);
        assert!(
            coverage > 0.2,
            "{model}: the scene should cover the image ({coverage})"
        );
    }
}

#[test]
fn render_gradients_match_finite_differences() {
    for model in CameraModel::ALL {
        let cam = wide_camera(24, 16, model);
        let scene = covering_gaussians(&cam);
        forward_matches_reference::<Method>(&format!("3dgs {model} covering"), &scene, &cam);
        gradients_match_finite_differences::<Method>(
            &format!("3dgs {model}"),
            &scene,
            &cam,
            &GAUSSIAN_GROUPS,
            camera_groups(model),
            FINITE_DIFFERENCES,
        );
    }
}

/// Realistic scenes: pairs below 1/255 at the footprints' edges, lists that end at the T-stop.
#[test]
fn gradients_match_the_reference_adjoint_on_realistic_scenes() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        gradients_match_reference_adjoint::<Method>(
            &format!("3dgs {model}"),
            &spread_gaussians(&cam, 1000, 31),
            &cam,
            &GAUSSIAN_GROUPS,
            camera_groups(model),
            REFERENCE_ADJOINT,
        );
    }
}

#[test]
fn the_box_holds_every_contributing_pixel_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(96, 64, model);
        let label = format!("3dgs {model}");
        let scene = spread_gaussians(&cam, 120, 31);
        let checked =
            boxes_hold_every_contributing_pixel::<Method>(&label, &scene, &cam, 1.0 / 255.0);
        println!("{label}: {checked} (primitive, pixel) pairs outside the boxes, all below 1/255");
    }
}

/// The GPU against the CPU on every camera model: the forward on a spread scene (seed 31 has
/// a pair within an ulp of 1/255 on the equiangular camera, which the clear-pixel rule leaves
/// out), the gradients on a covering scene and on the same dense spread scene (gradients summed
/// over pixels whose terms cancel).
#[test]
fn gpu_matches_cpu_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(48, 40, model);
        let label = format!("3dgs {model}");
        let spread = spread_gaussians(&cam, 60, 31);
        gpu_forward_matches_cpu::<Method>(&label, &spread, &cam);
        gpu_gradients_match_cpu::<Method>(&format!("{label} dense"), &spread, &cam);
        let cam = wide_camera(24, 16, model);
        gpu_gradients_match_cpu::<Method>(&label, &covering_gaussians(&cam), &cam);
    }
}
