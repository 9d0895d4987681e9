//! 3DGUT on every camera model: the CPU render against the f64 brute-force reference, render
//! gradients against finite differences (parameters and camera, fisheye coefficients
//! included), and the GPU backend against the CPU backend.

mod common;

use common::checks::{
    boxes_hold_every_contributing_pixel, forward_matches_reference, gpu_forward_matches_cpu,
    gpu_gradients_match_cpu, gradients_match_finite_differences,
};
use common::{CAMERA_GROUPS, GAUSSIAN_GROUPS, gaussian_toward, wide_camera};
use splat_methods::gut::{Method, Params};
use splat_runtime::glam::Vec2;
use splat_runtime::{Camera, CameraModel};

fn to_gut(p: splat_methods::gs3d::Params) -> Params {
    Params {
        mean: p.mean,
        log_scale: p.log_scale,
        rotation: p.rotation,
        opacity_logit: p.opacity_logit,
        sh: p.sh,
    }
}

/// Gaussians spread over the whole image (and past its edges), 1.5 to 6 units away; larger
/// on the wide cameras, which have fewer pixels per radian.
fn scene(cam: &Camera, count: usize) -> Vec<Params> {
    let log_scale = if cam.model == CameraModel::Pinhole {
        -2.5
    } else {
        -1.4
    };
    let mut rng = fastrand::Rng::with_seed(31);
    (0..count)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 1.2 - 0.1, rng.f32() * 1.2 - 0.1) * cam.size;
            let d = 1.5 + rng.f32() * 4.5;
            to_gut(gaussian_toward(&mut rng, cam, px, d, log_scale))
        })
        .collect()
}

fn twin() -> common::Twin {
    twin!(splat_methods::gut, pixel_info)
}

#[test]
fn forward_matches_the_reference_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        let params = scene(&cam, 60);
        let coverage =
            forward_matches_reference::<Method>(&format!("3dgut {model}"), &twin(), &params, &cam);
        assert!(
            coverage > 0.2,
            "{model}: the scene should cover the image ({coverage})"
        );
    }
}

/// Four large Gaussians that cover the small image with alpha above 2/255 everywhere.
fn covering_scene(cam: &Camera) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(9);
    (0..4)
        .map(|i| {
            let px = Vec2::new(8.0 + 3.0 * i as f32, 6.0 + 1.5 * i as f32);
            let mut p = gaussian_toward(&mut rng, cam, px, 3.0 + 0.5 * i as f32, 0.4);
            p.opacity_logit = -1.0 + 0.4 * rng.f32();
            to_gut(p)
        })
        .collect()
}

/// The camera's gradient includes the path through the pixel rays (`pixel_info`'s adjoint);
/// the fisheye's distortion coefficients too.
#[test]
fn render_gradients_match_finite_differences() {
    for model in CameraModel::ALL {
        let cam = wide_camera(24, 16, model);
        let cameras = if model == CameraModel::KannalaBrandt {
            &CAMERA_GROUPS[..]
        } else {
            &CAMERA_GROUPS[..4]
        };
        let label = format!("3dgut {model} covering");
        forward_matches_reference::<Method>(&label, &twin(), &covering_scene(&cam), &cam);
        gradients_match_finite_differences::<Method>(
            &format!("3dgut {model}"),
            &twin(),
            &covering_scene(&cam),
            &cam,
            &GAUSSIAN_GROUPS,
            cameras,
            1e-4,
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
            &twin(),
            &scene(&cam, 120),
            &cam,
            1.0 / 255.0,
        );
        println!("{label}: {checked} (primitive, pixel) pairs outside the boxes, all below 1/255");
    }
}

#[test]
fn the_pinhole_only_method_refuses_a_fisheye_by_name() {
    let cam = wide_camera(16, 16, CameraModel::KannalaBrandt);
    let Err(err) =
        splat_runtime::render::<splat_methods::gs3d::Method>(&[], &cam, &Default::default())
    else {
        panic!("3DGS rendered with a fisheye");
    };
    assert!(err.to_string().contains("pinhole camera only"), "{err}");
}
