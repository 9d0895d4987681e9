//! LinPrim: the CPU render against the f64 brute-force reference, the tile cull conservative
//! (rendering with and without it gives the same image), render gradients against finite
//! differences, the GPU backend against the CPU backend, and the pinhole-only refusal.

use splat_runtime::checks;

use crate::common::{CAMERA_GROUPS, GAUSSIAN_GROUPS, camera, gaussian_at, wide_camera};
use splat_methods::linprim::{Method, Params};
use splat_runtime::checks::forward::{
    boxes_hold_every_contributing_pixel, forward_matches_reference, gpu_forward_matches_cpu,
    tile_cull_is_conservative,
};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gpu_gradients_match_cpu,
    gradients_match_finite_differences, gradients_match_reference_adjoint,
    invalid_pairs_leave_no_trace,
};
use splat_runtime::glam::Vec2;
use splat_runtime::{Camera, CameraModel, render};

fn to_linprim(p: splat_methods::gs3d::Params) -> Params {
    Params {
        mean: p.mean,
        log_scale: p.log_scale,
        rotation: p.rotation,
        opacity_logit: p.opacity_logit,
        sh: p.sh,
    }
}

/// Octahedra spread over the image (and past its edges), 2 to 8 units away.
fn scene(cam: &Camera, count: usize) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(41);
    (0..count)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 1.2 - 0.1, rng.f32() * 1.2 - 0.1) * cam.size;
            let z = 2.0 + rng.f32() * 6.0;
            to_linprim(gaussian_at(&mut rng, cam, px, z, -1.2))
        })
        .collect()
}

/// Four octahedra in front of a small, narrow image: every pixel's ray crosses each of them
/// with alpha above 2/255.
fn covering_scene(cam: &Camera) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(9);
    (0..4)
        .map(|i| {
            let px = Vec2::new(10.0 + 1.5 * i as f32, 7.0 + 1.0 * i as f32);
            let mut p = gaussian_at(&mut rng, cam, px, 3.0 + 0.5 * i as f32, 0.3);
            p.opacity_logit = -2.0 + 0.4 * rng.f32();
            to_linprim(p)
        })
        .collect()
}

/// 24 x 16 pixels over 17 x 11 degrees.
fn narrow_camera() -> Camera {
    Camera {
        focal: Vec2::splat(80.0),
        ..camera(24, 16)
    }
}

#[test]
fn forward_matches_the_reference() {
    let cam = camera(64, 48);
    let coverage = forward_matches_reference::<Method>("linprim", &scene(&cam, 80), &cam);
    assert!(
        coverage > 0.2,
        "the scene should cover the image ({coverage})"
    );
}

/// The boxes (the projected vertices) cut nothing off.
#[test]
fn the_boxes_hold_every_contributing_pixel() {
    let cam = camera(96, 64);
    let checked = boxes_hold_every_contributing_pixel::<Method>(
        "linprim",
        &scene(&cam, 120),
        &cam,
        1.0 / 255.0,
    );
    println!("linprim: {checked} (primitive, pixel) pairs outside the boxes, all below 1/255");
}

#[test]
fn the_tile_cull_is_conservative() {
    let cam = camera(96, 64);
    for (with, without) in tile_cull_is_conservative::<Method>("linprim", &scene(&cam, 120), &cam) {
        assert!(with < without, "the cull removes pairs");
    }
}

#[test]
fn render_gradients_match_finite_differences() {
    let cam = narrow_camera();
    let params = covering_scene(&cam);
    forward_matches_reference::<Method>("linprim covering", &params, &cam);
    let solo = checks::reference::render_words::<Method>(
        &[checks::words(&params[3])],
        &checks::camera_words(&cam),
        cam.model,
    );
    let min_alpha = solo.alpha.iter().fold(1.0f64, |m, a| m.min(*a));
    assert!(
        min_alpha > 2.0 / 255.0,
        "the farthest octahedron covers the image (min alpha {min_alpha})"
    );
    gradients_match_finite_differences::<Method>(
        "linprim",
        &params,
        &cam,
        &GAUSSIAN_GROUPS,
        &CAMERA_GROUPS[..4],
        FINITE_DIFFERENCES,
    );
}

#[test]
fn gpu_matches_cpu() {
    let cam = camera(48, 40);
    gpu_forward_matches_cpu::<Method>("linprim", &scene(&cam, 80), &cam);
    let cam = narrow_camera();
    gpu_gradients_match_cpu::<Method>("linprim", &covering_scene(&cam), &cam);
}

#[test]
fn a_fisheye_is_refused_by_name() {
    let cam = wide_camera(16, 16, CameraModel::KannalaBrandt);
    let Err(err) = render::<Method>(&[], &cam, &Default::default()) else {
        panic!("LinPrim rendered with a fisheye");
    };
    assert!(
        err.to_string()
            .contains("`linprim` projects with a pinhole camera only"),
        "{err}"
    );
}

/// A realistic scene: rays that miss or barely graze octahedra, lists that end at the T-stop.
#[test]
fn gradients_match_the_reference_adjoint_on_a_realistic_scene() {
    let cam = camera(64, 48);
    gradients_match_reference_adjoint::<Method>(
        "linprim",
        &scene(&cam, 1000),
        &cam,
        &GAUSSIAN_GROUPS,
        &CAMERA_GROUPS[..4],
        REFERENCE_ADJOINT,
    );
}

#[test]
fn an_octahedron_leaves_no_trace_where_it_is_invalid() {
    let cam = camera(16, 16);
    let mut rng = fastrand::Rng::with_seed(3);
    let extra = to_linprim(gaussian_at(&mut rng, &cam, Vec2::new(5.0, 4.0), 2.5, -2.0));
    let valid =
        invalid_pairs_leave_no_trace::<Method>("linprim", &scene(&cam, 40), extra, &cam, 16);
    println!("the extra octahedron is valid on {valid} pixels");
}

#[test]
fn gpu_gradients_match_cpu_on_a_realistic_scene() {
    let cam = camera(64, 48);
    gpu_gradients_match_cpu::<Method>("linprim realistic", &scene(&cam, 400), &cam);
}

/// Each gradient group alone, the camera alone and everything but the camera give the full
/// pass's gradients for what they name and zero for the rest, on both backends.
#[test]
fn gradient_subsets_match_the_full_pass() {
    let cam = narrow_camera();
    checks::gradients::gradient_subsets_match_the_full_pass::<Method>(
        "linprim",
        &covering_scene(&cam),
        &cam,
    );
}
