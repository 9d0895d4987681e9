//! Anti-aliased 3DGS (`gs3d_aa`, Mip-Splatting's 2D filter as gsplat's `antialiased` mode):
//! the opacity scaled by sqrt(det(cov) / det(cov + 0.3 I)), checked against that formula
//! written here independently (the EWA covariance in f64), then through the shared checks:
//! the f64 reference, finite differences, the reference adjoint on a dense scene, and GPU
//! parity. The plain method is untouched: its alpha is the opacity itself.

use crate::common::{
    CAMERA_GROUPS, GAUSSIAN_GROUPS, as_method, camera, gaussian_at, spread_gaussians,
};
use splat_methods::{gs3d, gs3d_aa};
use splat_runtime::checks::forward::{forward_matches_reference, gpu_forward_matches_cpu};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gpu_gradients_match_cpu,
    gradients_match_finite_differences, gradients_match_reference_adjoint,
};
use splat_runtime::glam::{DMat3, DQuat, DVec3, Vec2, Vec3};
use splat_runtime::{RenderOptions, render};

/// The compensation of a Gaussian seen by the camera at the origin looking down +z: the
/// 2D covariance J R S S^T R^T J^T (pinhole Jacobian at the mean, in f64), before and after
/// the 0.3 px dilation.
fn compensation(p: &gs3d::Params, focal: f64) -> f64 {
    let m = p.mean.as_dvec3();
    let r = p.rotation.as_dvec4();
    let q = DQuat::from_xyzw(r.y, r.z, r.w, r.x).normalize();
    let s = DMat3::from_diagonal(p.log_scale.as_dvec3().exp());
    let rs = DMat3::from_quat(q) * s;
    let cov3 = rs * rs.transpose();
    let j = DMat3::from_cols(
        DVec3::new(focal / m.z, 0.0, 0.0),
        DVec3::new(0.0, focal / m.z, 0.0),
        DVec3::new(-focal * m.x / (m.z * m.z), -focal * m.y / (m.z * m.z), 0.0),
    );
    let c = j * cov3 * j.transpose();
    let (a, b, d) = (c.x_axis.x, c.y_axis.x, c.y_axis.y);
    ((a * d - b * b) / ((a + 0.3) * (d + 0.3) - b * b)).sqrt()
}

#[test]
fn small_gaussians_fade_by_the_filters_area_ratio() {
    let cam = camera(32, 24);
    let mut rng = fastrand::Rng::with_seed(3);
    let opts = RenderOptions {
        alpha: true,
        ..RenderOptions::default()
    };
    // From a fifth of a pixel to several pixels across, centred on pixel (12, 9)'s centre.
    for log_scale in [-6.0, -5.0, -4.0, -3.0] {
        let mut g = gaussian_at(&mut rng, &cam, Vec2::new(12.5, 9.5), 3.0, log_scale);
        g.opacity_logit = 2.0;
        let want_plain = 1.0 / (1.0 + (-2.0f64).exp());
        let want = want_plain * compensation(&g, 32.0);
        let alpha = |image: &splat_runtime::Frame| image.alpha.as_ref().unwrap().data[9 * 32 + 12];
        let plain = render::<gs3d::Method>(&[g], &cam, &opts).unwrap();
        let aa = render::<gs3d_aa::Method>(&as_method(vec![g]), &cam, &opts).unwrap();
        println!(
            "log scale {log_scale}: compensation {:.4}",
            want / want_plain
        );
        assert!((alpha(&plain) as f64 - want_plain.min(0.99)).abs() < 1e-6);
        assert!(
            (alpha(&aa) as f64 - want.min(0.99)).abs() < 1e-5 + 1e-4 * want,
            "log scale {log_scale}: alpha {} for {want}",
            alpha(&aa)
        );
        // Nowhere brighter than without the filter.
        let pairs = aa.color.data.iter().zip(&plain.color.data);
        assert!(pairs.into_iter().all(|(a, p)| *a <= *p + 1e-6));
    }
}

#[test]
fn antialiased_3dgs_passes_the_shared_checks() {
    let cam = camera(24, 16);
    let mut rng = fastrand::Rng::with_seed(9);
    let covering: Vec<gs3d_aa::Params> = as_method(
        (0..5)
            .map(|i| {
                let px = Vec2::new(6.0 + 3.0 * i as f32, 5.0 + 1.5 * i as f32);
                let mut p = gaussian_at(&mut rng, &cam, px, 3.0 + 0.5 * i as f32, 0.3);
                p.opacity_logit = -1.0 + 0.4 * rng.f32();
                p.sh[0] += Vec3::splat(0.2);
                p
            })
            .collect(),
    );
    let coverage = forward_matches_reference::<gs3d_aa::Method>("3dgs-aa", &covering, &cam);
    assert!(coverage > 0.2, "the scene should cover the image");
    gradients_match_finite_differences::<gs3d_aa::Method>(
        "3dgs-aa",
        &covering,
        &cam,
        &GAUSSIAN_GROUPS,
        &CAMERA_GROUPS[..4],
        FINITE_DIFFERENCES,
    );
    let dense_cam = camera(64, 48);
    let dense: Vec<gs3d_aa::Params> = as_method(spread_gaussians(&dense_cam, 1000, 12));
    gradients_match_reference_adjoint::<gs3d_aa::Method>(
        "3dgs-aa dense",
        &dense,
        &dense_cam,
        &GAUSSIAN_GROUPS,
        &CAMERA_GROUPS[..4],
        REFERENCE_ADJOINT,
    );
    gpu_forward_matches_cpu::<gs3d_aa::Method>("3dgs-aa", &dense, &dense_cam);
    gpu_gradients_match_cpu::<gs3d_aa::Method>("3dgs-aa", &dense, &dense_cam);
}
