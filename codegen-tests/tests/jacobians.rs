//! The `jacobian` intrinsic (forward mode inside a kernel) against central differences of the
//! f64 twin of the map it differentiates: every differentiable operation, and every camera
//! model's projection. Its adjoint (reverse over forward: second derivatives) is checked
//! against differences of the Jacobian by the corpus (`tests/corpus.rs`) and below for the
//! cameras.

use codegen_tests::check::{gradient, jacobian_vs_differences, uniform};
use codegen_tests::corpus::jacobians;
use splat_macros::splat_functions;
use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, CameraModel};

const TOL: f64 = 1e-6;

/// `every_op` as a function of two scalars, the form `jacobian_vs_differences` differences.
fn every_op(x: &[f64; 2], ints: &[u32; 0]) -> ([f64; 4], [u32; 0]) {
    jacobians::twin::every_op(x, ints)
}

#[test]
fn the_jacobian_of_every_operation_matches_differences() {
    let sample = |r: &mut fastrand::Rng| (uniform(r, 0.15, 0.85), []);
    let err = jacobian_vs_differences(
        every_op,
        jacobians::twin::every_op_jacobian,
        0..2,
        sample,
        11,
        40,
    );
    println!("every_op: Jacobian {err:.2e} off differences");
    assert!(err <= TOL, "{err}");
}

#[test]
fn the_value_comes_with_its_jacobian() {
    for t in [-1.2f32, 0.0, 0.4, 1.3] {
        let got = jacobians::scalar_jacobian(t);
        let want = Vec4::new(t * t, t.sin() + t * t.exp(), 2.0 * t, t.cos() + t * t.exp());
        assert!(
            (got - want).length() <= 1e-5 * want.length(),
            "{got} vs {want}"
        );
    }
}

#[splat_functions]
mod projections {
    use splat_runtime::prelude::*;

    pub fn project_point(cam: &Camera, p: Vec3) -> Vec2 {
        cam.project_point(p)
    }

    /// The gradients of the pixel's two coordinates by the camera-space point.
    pub fn projection_jacobian(cam: &Camera, p: Vec3) -> (Vec3, Vec3) {
        let (_, j) = jacobian(|q| cam.project_point(q), p);
        (j[0], j[1])
    }
}

const FLOAT_SLOTS: usize = Camera::FLOAT_SLOTS;

fn camera(model: CameraModel) -> Camera {
    Camera {
        rotation: Mat3::from_rotation_y(0.2) * Mat3::from_rotation_x(-0.1),
        translation: Vec3::new(0.1, -0.2, 0.5),
        focal: Vec2::new(15.0, 14.5),
        principal: Vec2::new(16.0, 12.0),
        size: Vec2::new(32.0, 24.0),
        distortion: Vec4::new(0.04, -0.01, 0.002, -0.0005),
        model,
        ..Default::default()
    }
}

/// The camera's float slots, each perturbed by up to 1%, and a camera-space point up to
/// `angle` radians off the axis; the model is the integer slot.
fn sample(
    model: CameraModel,
    angle: f64,
) -> impl Fn(&mut fastrand::Rng) -> ([f64; FLOAT_SLOTS + 3], [u32; 1]) {
    move |r| {
        let cam = camera(model);
        let mut x = [0.0; FLOAT_SLOTS + 3];
        for (v, slot) in x.iter_mut().zip(cam.float_slots()) {
            *v = slot as f64 * (1.0 + 0.02 * (r.f64() - 0.5));
        }
        let (theta, phi) = (
            0.05 + (angle - 0.05) * r.f64(),
            std::f64::consts::TAU * r.f64(),
        );
        let d = 1.0 + 3.0 * r.f64();
        x[FLOAT_SLOTS..].copy_from_slice(&[
            d * theta.sin() * phi.cos(),
            d * theta.sin() * phi.sin(),
            d * theta.cos(),
        ]);
        (x, [cam.model as u32])
    }
}

/// Up to 0.9 of what each model sees off axis (the fisheye past 90 degrees).
fn angle(model: CameraModel) -> f64 {
    match model {
        CameraModel::Pinhole => 1.1,
        CameraModel::Equiangular => 0.9,
        CameraModel::KannalaBrandt => 1.6,
    }
}

#[test]
fn every_camera_model_s_projection_jacobian_matches_differences() {
    for model in CameraModel::ALL {
        let err = jacobian_vs_differences(
            projections::twin::project_point,
            projections::twin::projection_jacobian,
            FLOAT_SLOTS..FLOAT_SLOTS + 3,
            sample(model, angle(model)),
            12,
            40,
        );
        println!("{model}: projection Jacobian {err:.2e} off differences");
        assert!(err <= TOL, "{model}: {err}");
    }
}

/// Reverse over forward: the adjoint of the projection's Jacobian (by the camera and the
/// point: second derivatives of each model) against differences of the Jacobian.
#[test]
fn the_projection_jacobian_s_gradients_match_second_differences() {
    for model in CameraModel::ALL {
        let report = gradient(
            projections::twin::projection_jacobian,
            projections::twin::projection_jacobian_adjoint,
            sample(model, angle(model)),
            13,
            30,
        );
        println!("{model}: {report:?}");
        assert!(
            report.jacobian <= TOL && report.dot_product <= TOL,
            "{model}: {report:?}"
        );
    }
}
