//! 3DGEER on every camera model: the CPU render against the f64 brute-force reference, the
//! PBF tile association conservative, render gradients against finite differences, the GPU
//! backend against the CPU backend, the boxes conservative, and the hard cases (flat
//! Gaussians, a fisheye past 180 degrees, the camera inside a particle, rays that must not
//! pick up particles behind the camera).

use crate::common::{
    GAUSSIAN_GROUPS, as_method, camera_groups, covering_gaussians, gaussian_toward,
    spread_gaussians, wide_camera,
};
use splat_methods::geer::{Method, Params};
use splat_runtime::checks::forward::{
    boxes_hold_every_contributing_pixel, forward_matches_reference, gpu_forward_matches_cpu,
    tile_cull_is_conservative,
};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gpu_gradients_match_cpu,
    gradients_match_finite_differences, gradients_match_reference_adjoint,
    invalid_pairs_leave_no_trace,
};
use splat_runtime::glam::{Vec2, Vec3};
use splat_runtime::{Camera, CameraModel, RenderOptions, render};

fn scene(cam: &Camera, count: usize) -> Vec<Params> {
    as_method(spread_gaussians(cam, count, 51))
}

fn covering_scene(cam: &Camera) -> Vec<Params> {
    as_method(covering_gaussians(cam))
}

#[test]
fn forward_matches_the_reference_on_every_camera_model() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        let label = format!("3dgeer {model}");
        let coverage = forward_matches_reference::<Method>(&label, &scene(&cam, 60), &cam);
        assert!(
            coverage > 0.2,
            "{model}: the scene should cover the image ({coverage})"
        );
    }
}

#[test]
fn the_tile_association_is_conservative() {
    for model in CameraModel::ALL {
        let cam = wide_camera(96, 64, model);
        tile_cull_is_conservative::<Method>(&format!("3dgeer {model}"), &scene(&cam, 120), &cam);
    }
}

#[test]
fn render_gradients_match_finite_differences() {
    for model in CameraModel::ALL {
        let cam = wide_camera(24, 16, model);
        let cameras = camera_groups(model);
        let params = covering_scene(&cam);
        let label = format!("3dgeer {model}");
        forward_matches_reference::<Method>(&label, &params, &cam);
        gradients_match_finite_differences::<Method>(
            &label,
            &params,
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
        let label = format!("3dgeer {model}");
        let cam = wide_camera(48, 40, model);
        gpu_forward_matches_cpu::<Method>(&label, &scene(&cam, 60), &cam);
        let cam = wide_camera(24, 16, model);
        gpu_gradients_match_cpu::<Method>(&label, &covering_scene(&cam), &cam);
    }
}

fn gaussian(mean: Vec3, log_scale: Vec3) -> Params {
    Params {
        mean,
        log_scale,
        rotation: splat_runtime::glam::Vec4::new(0.9, 0.3, -0.2, 0.1),
        opacity_logit: 2.0,
        sh: [Vec3::splat(0.3); 16],
    }
}

#[test]
fn hard_cases_stay_finite_and_exact() {
    let fisheye = wide_camera(64, 48, CameraModel::KannalaBrandt);
    let cases: [(&str, Camera, Vec<Params>); 4] = [
        (
            "flat and needle Gaussians (scale 1e-7 on one axis)",
            wide_camera(64, 48, CameraModel::Pinhole),
            vec![
                gaussian(Vec3::new(0.1, 0.0, 3.0), Vec3::new(-0.5, -0.7, -16.1)),
                gaussian(Vec3::new(-0.3, 0.1, 4.0), Vec3::new(-16.1, -16.1, -0.5)),
            ],
        ),
        (
            "the camera inside a Gaussian",
            wide_camera(64, 48, CameraModel::Equiangular),
            vec![gaussian(Vec3::new(0.1, 0.0, 0.2), Vec3::splat(0.5))],
        ),
        (
            "a fisheye past 180 degrees: a particle 100 degrees off axis, one straight behind (culled: past can_project's 172 degrees)",
            fisheye,
            vec![
                gaussian(Vec3::new(2.9, 0.2, -0.5), Vec3::splat(-1.0)),
                gaussian(Vec3::new(0.0, 0.0, -3.0), Vec3::splat(-1.0)),
            ],
        ),
        (
            "a particle at the near plane",
            wide_camera(64, 48, CameraModel::Pinhole),
            vec![gaussian(Vec3::new(0.0, 0.0, 0.011), Vec3::splat(-4.0))],
        ),
    ];
    for (name, cam, params) in cases {
        let frame = render::<Method>(
            &params,
            &cam,
            &RenderOptions {
                alpha: true,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(
            frame.color.data.iter().all(|v| v.is_finite()),
            "{name}: non-finite color"
        );
        forward_matches_reference::<Method>(name, &params, &cam);
    }
}

/// The PBF boxes (exact for pinhole and BEAP, a cone image for the fisheye) cut nothing off.
#[test]
fn the_boxes_hold_every_contributing_pixel() {
    for model in CameraModel::ALL {
        let cam = wide_camera(96, 64, model);
        let label = format!("3dgeer {model}");
        let checked = boxes_hold_every_contributing_pixel::<Method>(
            &label,
            &scene(&cam, 120),
            &cam,
            1.0 / 255.0,
        );
        println!("{label}: {checked} (primitive, pixel) pairs outside the boxes, all below 1/255");
    }
}

/// A ray starts at the camera: a particle behind its origin, which the whole-line integral
/// exp(-D²/2) would count in full, contributes only its tail at the camera (here nothing);
/// the ray turned around sees it.
#[test]
fn rays_do_not_pick_up_particles_behind_the_camera() {
    use splat_methods::geer::{Ray, Shade, evaluate};
    use splat_runtime::glam::Mat3;
    let shade = Shade {
        // A unit particle 4 units behind the camera on the optical axis, seen from the camera.
        origin: Vec3::new(0.0, 0.0, 4.0),
        whiten: Mat3::IDENTITY,
        opacity: 0.9,
        color: Vec3::ONE,
    };
    let forward = evaluate(
        Ray {
            dir: Vec3::Z,
            shift: Vec3::ZERO,
        },
        &shade,
    );
    let backward = evaluate(
        Ray {
            dir: -Vec3::Z,
            shift: Vec3::ZERO,
        },
        &shade,
    );
    assert!(
        !forward.valid && forward.alpha < 1e-4,
        "forward ray: alpha {}",
        forward.alpha
    );
    assert!(
        // Φ(4) = 0.99997: the closest point is four standard deviations down the ray.
        backward.valid && (backward.alpha - 0.9 * 0.999_968).abs() < 1e-6,
        "backward ray: alpha {}",
        backward.alpha
    );
}

/// Realistic scenes: pairs below 1/255 at the footprints' edges, lists that end at the T-stop.
#[test]
fn gradients_match_the_reference_adjoint_on_realistic_scenes() {
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        gradients_match_reference_adjoint::<Method>(
            &format!("3dgeer {model}"),
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
        let label = format!("3dgeer {model}");
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
            &format!("3dgeer {model} realistic"),
            &scene(&cam, 400),
            &cam,
        );
    }
}

/// Each gradient group alone, the camera alone and everything but the camera give the full
/// pass's gradients for what they name and zero for the rest, on both backends.
#[test]
fn gradient_subsets_match_the_full_pass() {
    let cam = wide_camera(24, 16, CameraModel::KannalaBrandt);
    splat_runtime::checks::gradients::gradient_subsets_match_the_full_pass::<Method>(
        "3dgeer fisheye",
        &covering_scene(&cam),
        &cam,
    );
}
