//! 3DGUT on every camera model: the CPU render against the f64 brute-force reference, render
//! gradients against finite differences (parameters and camera, fisheye coefficients
//! included), and the GPU backend against the CPU backend.

use crate::common::{
    GAUSSIAN_GROUPS, as_method, camera_groups, covering_gaussians, gaussian_toward,
    spread_gaussians, wide_camera,
};
use splat_methods::gut::{Method, Params};
use splat_runtime::checks::forward::{
    boxes_hold_every_contributing_pixel, forward_matches_reference, gpu_forward_matches_cpu,
};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gpu_gradients_match_cpu,
    gradients_match_finite_differences, gradients_match_reference_adjoint,
    invalid_pairs_leave_no_trace,
};
use splat_runtime::glam::Vec2;
use splat_runtime::{Camera, CameraModel};

fn scene(cam: &Camera, count: usize) -> Vec<Params> {
    as_method(spread_gaussians(cam, count, 31))
}

#[test]
fn forward_matches_the_reference_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        let params = scene(&cam, 60);
        let coverage =
            forward_matches_reference::<Method>(&format!("3dgut {model}"), &params, &cam);
        assert!(
            coverage > 0.2,
            "{model}: the scene should cover the image ({coverage})"
        );
    }
}

fn covering_scene(cam: &Camera) -> Vec<Params> {
    as_method(covering_gaussians(cam))
}

/// The camera's gradient includes the path through the pixel rays (`pixel_info`'s adjoint);
/// the fisheye's distortion coefficients too.
#[test]
fn render_gradients_match_finite_differences() {
    for model in CameraModel::ALL {
        let cam = wide_camera(24, 16, model);
        let cameras = camera_groups(model);
        let label = format!("3dgut {model} covering");
        forward_matches_reference::<Method>(&label, &covering_scene(&cam), &cam);
        gradients_match_finite_differences::<Method>(
            &format!("3dgut {model}"),
            &covering_scene(&cam),
            &cam,
            &GAUSSIAN_GROUPS,
            cameras,
            FINITE_DIFFERENCES,
        );
    }
}

#[test]
fn gpu_matches_cpu_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(48, 40, model);
        gpu_forward_matches_cpu::<Method>(&format!("3dgut {model}"), &scene(&cam, 60), &cam);
        let cam = wide_camera(24, 16, model);
        gpu_gradients_match_cpu::<Method>(&format!("3dgut {model}"), &covering_scene(&cam), &cam);
    }
}

/// The box widens an approximate footprint (the UT's): no pixel outside it gets alpha 1/255
/// from the primitive, on every camera model.
#[test]
fn the_box_holds_every_contributing_pixel_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(96, 64, model);
        let label = format!("3dgut {model}");
        let checked = boxes_hold_every_contributing_pixel::<Method>(
            &label,
            &scene(&cam, 120),
            &cam,
            1.0 / 255.0,
        );
        println!("{label}: {checked} (primitive, pixel) pairs outside the boxes, all below 1/255");
    }
}

/// Realistic scenes: pairs below 1/255 at the footprints' edges, lists that end at the T-stop.
#[test]
fn gradients_match_the_reference_adjoint_on_realistic_scenes() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        gradients_match_reference_adjoint::<Method>(
            &format!("3dgut {model}"),
            &scene(&cam, 1000),
            &cam,
            &GAUSSIAN_GROUPS,
            camera_groups(model),
            REFERENCE_ADJOINT,
        );
    }
}

#[test]
fn a_particle_leaves_no_trace_where_it_is_invalid() {
    for model in CameraModel::ALL {
        let cam = wide_camera(16, 16, model);
        let mut rng = fastrand::Rng::with_seed(3);
        let extra = gaussian_toward(&mut rng, &cam, Vec2::new(5.0, 4.0), 2.5, -2.0);
        let extra = as_method::<Params>(vec![extra])[0];
        let label = format!("3dgut {model}");
        let valid =
            invalid_pairs_leave_no_trace::<Method>(&label, &scene(&cam, 40), extra, &cam, 16);
        println!("{label}: the extra particle is valid on {valid} pixels");
    }
}

#[test]
fn gpu_gradients_match_cpu_on_realistic_scenes() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        gpu_gradients_match_cpu::<Method>(
            &format!("3dgut {model} realistic"),
            &scene(&cam, 400),
            &cam,
        );
    }
}

/// Each gradient group alone, the camera alone and everything but the camera (training
/// without pose refinement: the rays' adjoint does not run) give the full pass's gradients for
/// what they name and zero for the rest, on both backends.
#[test]
fn gradient_subsets_match_the_full_pass() {
    let cam = wide_camera(24, 16, CameraModel::KannalaBrandt);
    splat_runtime::checks::gradients::gradient_subsets_match_the_full_pass::<Method>(
        "3dgut fisheye",
        &covering_scene(&cam),
        &cam,
    );
}
