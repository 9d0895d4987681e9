//! splat's building blocks (`splat-macros/compiler/src/blocks/library.rs`) as kernels see
//! them: the rotation against glam's, the footprint's conic the inverse of its covariance,
//! and every block listed, with its signature, in the method-writing guide. Their gradients
//! are held to finite differences through the methods built on them (3DGS, GES, the
//! Student's t example), and 3DGS's renders and gradients to gsplat's.

use splat_macros::splat_functions;
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, CameraModel};

#[splat_functions]
mod kernels {
    use splat_runtime::prelude::*;

    pub fn rotation(q: Vec4) -> Mat3 {
        blocks::rotation_matrix(q)
    }

    /// The footprint's covariance, conic and centre.
    pub fn footprint(
        mean: Vec3,
        log_scale: Vec3,
        rotation: Vec4,
        cam: &Camera,
    ) -> (Vec3, Vec3, Vec2) {
        let g = blocks::gaussian_footprint(mean, log_scale, rotation, cam, 0.01, 0.3);
        (g.cov, g.conic, g.center)
    }
}

#[test]
fn rotation_matrix_is_glams_of_the_normalized_quaternion() {
    let mut rng = fastrand::Rng::with_seed(1);
    for _ in 0..100 {
        let q = Vec4::new(rng.f32(), rng.f32(), rng.f32(), rng.f32()) * 2.0 - 1.0;
        let want = Mat3::from_quat(Quat::from_xyzw(q.y, q.z, q.w, q.x).normalize());
        let got = kernels::rotation(q);
        assert!(got.abs_diff_eq(want, 1e-6), "{q}: {got} vs {want}");
    }
}

#[test]
fn a_footprints_conic_inverts_its_covariance_and_its_centre_is_the_projected_mean() {
    let mut rng = fastrand::Rng::with_seed(2);
    for model in CameraModel::ALL {
        let cam = Camera {
            rotation: Mat3::from_rotation_y(0.1),
            translation: Vec3::new(0.1, -0.05, 0.2),
            focal: Vec2::splat(40.0),
            principal: Vec2::new(32.0, 24.0),
            size: Vec2::new(64.0, 48.0),
            model,
            ..Default::default()
        };
        for _ in 0..50 {
            let mean = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, 3.0 + rng.f32());
            let log_scale = Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 2.0;
            let rotation = Vec4::new(rng.f32(), rng.f32(), rng.f32(), rng.f32()) - 0.5;
            let (cov, conic, center) = kernels::footprint(mean, log_scale, rotation, &cam);
            let (c, k) = (
                Mat3::from_cols(
                    Vec3::new(cov.x, cov.y, 0.0),
                    Vec3::new(cov.y, cov.z, 0.0),
                    Vec3::Z,
                ),
                Mat3::from_cols(
                    Vec3::new(conic.x, conic.y, 0.0),
                    Vec3::new(conic.y, conic.z, 0.0),
                    Vec3::Z,
                ),
            );
            assert!(
                (c * k).abs_diff_eq(Mat3::IDENTITY, 1e-4),
                "{model}: {c} * {k}"
            );
            let want = cam.project_point(cam.rotation * mean + cam.translation);
            assert!(
                (center - want).length() < 1e-3,
                "{model}: {center} vs {want}"
            );
        }
    }
}

#[test]
fn the_method_guide_lists_every_block() {
    let guide = include_str!("../../docs/writing-a-method.md");
    for signature in splat_compiler::blocks::signatures() {
        let listed = format!("blocks::{signature}");
        assert!(
            guide.contains(&listed),
            "docs/writing-a-method.md does not list `{listed}`"
        );
    }
}
