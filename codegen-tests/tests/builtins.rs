//! The compiler's builtins as kernels see them (compiled from
//! `splat-macros/compiler/src/builtins.rs`): the camera models (`cam.project_point`,
//! `cam.pixel_ray`) equal to the runtime's plain-Rust `Camera` methods, inverse to each other
//! (also past 90° off axis for the fisheye), and differentiated correctly (f64 finite
//! differences) for every model, their Jacobians by `jacobian` too (and those Jacobians' own
//! gradients: second derivatives); the rolling shutter's pose per row likewise;
//! `spherical_harmonics` equal to the runtime prelude's.

use codegen_tests::check::{gradient, jacobian_vs_differences, uniform};
use splat_macros::splat_functions;
use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, CameraModel};

const FLOAT_SLOTS: usize = Camera::FLOAT_SLOTS;

#[splat_functions]
mod cameras {
    use splat_runtime::prelude::*;

    pub fn project_point(cam: &Camera, p: Vec3) -> Vec2 {
        cam.project_point(p)
    }

    pub fn pixel_ray(cam: &Camera, pixel: Vec2) -> Vec3 {
        cam.pixel_ray(pixel)
    }

    pub fn can_project(cam: &Camera, p: Vec3) -> bool {
        cam.can_project(p)
    }

    /// The gradients of the pixel's two coordinates by the camera-space point (`jacobian`).
    pub fn projection_jacobian(cam: &Camera, p: Vec3) -> (Vec3, Vec3) {
        let (_, j) = jacobian(|q| cam.project_point(q), p);
        (j[0], j[1])
    }

    /// The rolling shutter's pose at the pixel's row, applied to its ray (one output that
    /// depends on every shutter function).
    pub fn shutter_ray(cam: &Camera, pixel: Vec2) -> Vec3 {
        let t = cam.shutter_time(pixel);
        cam.rotation_at(t).transpose() * cam.pixel_ray(pixel) + cam.translation_at(t)
    }

    /// The pose at the pixel's row applied to a point made of the pixel: smooth in every
    /// input, and independent of the model (whose rays are checked on their own).
    pub fn shutter_pose(cam: &Camera, pixel: Vec2) -> Vec3 {
        let t = cam.shutter_time(pixel);
        cam.rotation_at(t) * Vec3::new(pixel.x, pixel.y, 1.0) + cam.translation_at(t)
    }

    pub fn sh3(sh: [Vec3; 16], dir: Vec3) -> Vec3 {
        spherical_harmonics(sh, dir)
    }
}

#[test]
fn spherical_harmonics_match_the_runtime_prelude() {
    let mut rng = fastrand::Rng::with_seed(5);
    for _ in 0..50 {
        let mut v = || Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5);
        let sh: [Vec3; 16] = std::array::from_fn(|_| v());
        let dir = v();
        let want = splat_runtime::prelude::spherical_harmonics(sh, dir);
        let got = cameras::sh3(sh, dir);
        assert!((got - want).length() < 1e-5, "{got} vs {want}");
    }
}

/// A small image keeps the inputs' magnitudes (and so the finite-difference step, relative
/// to the largest input) small: the Newton inverse of the fisheye is curved enough that a
/// 128-pixel camera's step leaves a truncation error of 3e-6 in the dot-product test.
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

/// Camera-space points up to `max_angle` radians off the optical axis.
fn points(max_angle: f32) -> Vec<Vec3> {
    let mut rng = fastrand::Rng::with_seed(3);
    (0..200)
        .map(|_| {
            let theta = max_angle * rng.f32();
            let phi = std::f32::consts::TAU * rng.f32();
            let r = 0.5 + 4.0 * rng.f32();
            Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ) * r
        })
        .collect()
}

fn max_angle(model: CameraModel) -> f32 {
    match model {
        // Pinhole and equiangular images cover less than a half space.
        CameraModel::Pinhole => 1.2,
        CameraModel::Equiangular => 1.0,
        // A fisheye sees past 90 degrees off axis (a field of view beyond 180 degrees).
        CameraModel::KannalaBrandt => 1.75,
    }
}

#[test]
fn compiled_camera_models_match_the_runtime_and_invert() {
    for model in CameraModel::ALL {
        let cam = camera(model);
        for p in points(max_angle(model)) {
            let want = cam.project_point(p);
            let got = cameras::project_point(&cam, p);
            assert!(
                (got - want).length() <= 1e-4 * want.length().max(1.0),
                "{model}: project_point({p}) = {got} vs runtime {want}"
            );
            let ray = cameras::pixel_ray(&cam, got);
            let runtime_ray = cam.pixel_ray(got);
            assert!(
                (ray - runtime_ray).length() < 1e-5,
                "{model}: {ray} vs {runtime_ray}"
            );
            let angle = ray.cross(p.normalize()).length(); // acos is imprecise near 0
            assert!(
                angle < 2e-4,
                "{model}: pixel_ray(project_point(p)) is {angle} rad off p = {p}"
            );
            assert!((ray.length() - 1.0).abs() < 1e-5, "{model}: ray not unit");
        }
    }
}

#[test]
fn the_fisheye_sees_behind_the_image_plane() {
    let cam = camera(CameraModel::KannalaBrandt);
    let p = Vec3::new(1.0, 0.3, -0.2); // 100 degrees off axis
    let px = cameras::project_point(&cam, p);
    assert!(px.is_finite() && px.x > cam.principal.x);
    assert!(cameras::pixel_ray(&cam, px).cross(p.normalize()).length() < 1e-4);
}

/// The fisheye projects up to its polynomial's fold, the first angle where r'(θ) vanishes,
/// compiled as in the runtime: with one fold (r = θ - 0.25 θ³, fold at 1.1547 rad), with
/// none before the 3-rad limit (the equidistant r = θ), and with the slope negative between
/// two folds, at θ² = 1.5 and 3, and positive again past them (r' = (1 - θ² / 1.5) (1 - θ² / 3)).
#[test]
fn the_fisheye_projects_up_to_its_fold() {
    let cases = [
        (Vec4::new(-0.25, 0.0, 0.0, 0.0), 1.1547f32),
        (Vec4::ZERO, 3.0),
        (Vec4::new(-1.0 / 3.0, 0.2 / 4.5, 0.0, 0.0), 1.2247),
    ];
    for (distortion, fold) in cases {
        let cam = Camera {
            distortion,
            ..camera(CameraModel::KannalaBrandt)
        };
        for theta in [0.0, 0.5, fold - 2e-3, fold + 2e-3, 2.0, 2.9, 3.1] {
            let p = Vec3::new(theta.sin() * 0.6, theta.sin() * 0.8, theta.cos()) * 2.0;
            let want = theta < fold;
            assert_eq!(cam.can_project(p), want, "{distortion}: {theta} rad");
            assert_eq!(
                cameras::can_project(&cam, p),
                want,
                "compiled, {distortion}: {theta}"
            );
        }
    }
}

/// A camera turning and moving during its readout.
fn rolling(model: CameraModel) -> Camera {
    Camera {
        shutter_turn: Vec3::new(0.02, -0.03, 0.01),
        shutter_shift: Vec3::new(0.05, 0.0, -0.02),
        ..camera(model)
    }
}

#[test]
fn compiled_shutter_pose_matches_the_runtime() {
    for model in CameraModel::ALL {
        let cam = rolling(model);
        for y in [0.0, 3.5, 12.0, 23.5, 24.0] {
            let pixel = Vec2::new(10.5, y);
            let t = cam.shutter_time(pixel);
            assert_eq!(t, y / 24.0);
            let want =
                cam.rotation_at(t).transpose() * cam.pixel_ray(pixel) + cam.translation_at(t);
            let got = cameras::shutter_ray(&cam, pixel);
            assert!((got - want).length() < 1e-5, "{model}: {got} vs {want}");
        }
    }
}

/// Inputs: the camera's float slots (rotation 9, translation 3, focal 2, principal 2, size 2,
/// distortion 4, shutter turn 3 and shift 3) and a point or pixel; the model is the integer
/// slot.
fn sample<const N: usize>(
    cam: Camera,
    tail: impl Fn(&mut fastrand::Rng) -> Vec<f64>,
) -> impl Fn(&mut fastrand::Rng) -> ([f64; N], [u32; 1]) {
    move |r: &mut fastrand::Rng| {
        let mut x: [f64; N] = uniform(r, -0.1, 0.1);
        let slots = cam.float_slots();
        for (v, slot) in x.iter_mut().zip(slots) {
            // Perturb every camera slot by up to 1% (rotation off orthogonality included).
            *v = slot as f64 * (1.0 + 0.02 * (*v));
        }
        for (d, s) in x[FLOAT_SLOTS..].iter_mut().zip(tail(r)) {
            *d = s;
        }
        (x, [cam.model as u32])
    }
}

#[test]
fn camera_model_gradients_match_finite_differences() {
    for model in CameraModel::ALL {
        let point = point_toward(model);
        let report = gradient(
            cameras::twin::project_point,
            cameras::twin::project_point_adjoint,
            sample::<{ FLOAT_SLOTS + 3 }>(camera(model), point),
            7,
            30,
        );
        println!("{model} project_point: {report:?}");
        assert!(
            report.jacobian <= 1e-6 && report.dot_product <= 1e-6,
            "{model}: {report:?}"
        );

        let pixel = |r: &mut fastrand::Rng| vec![1.0 + 30.0 * r.f64(), 1.0 + 22.0 * r.f64()];
        let report = gradient(
            cameras::twin::pixel_ray,
            cameras::twin::pixel_ray_adjoint,
            sample::<{ FLOAT_SLOTS + 2 }>(camera(model), pixel),
            8,
            30,
        );
        println!("{model} pixel_ray: {report:?}");
        assert!(
            report.jacobian <= 1e-6 && report.dot_product <= 1e-6,
            "{model}: {report:?}"
        );
    }
}

/// Camera-space points up to 0.9 of what `model` sees off axis, 1 to 4 units away.
fn point_toward(model: CameraModel) -> impl Fn(&mut fastrand::Rng) -> Vec<f64> + Copy {
    let angle = max_angle(model) as f64 * 0.9;
    move |r: &mut fastrand::Rng| {
        let (theta, phi) = (
            0.05 + (angle - 0.05) * r.f64(),
            std::f64::consts::TAU * r.f64(),
        );
        let d = 1.0 + 3.0 * r.f64();
        vec![
            d * theta.sin() * phi.cos(),
            d * theta.sin() * phi.sin(),
            d * theta.cos(),
        ]
    }
}

/// `jacobian(|q| cam.project_point(q), p)` (forward mode inside the kernel) against central
/// differences of `project_point`'s f64 twin; and its adjoint by the camera and the point
/// (reverse over forward: second derivatives of each model) against differences of the
/// Jacobian.
#[test]
fn projection_jacobians_match_differences_on_every_model() {
    for model in CameraModel::ALL {
        let sample = sample::<{ FLOAT_SLOTS + 3 }>(camera(model), point_toward(model));
        let err = jacobian_vs_differences(
            cameras::twin::project_point,
            cameras::twin::projection_jacobian,
            FLOAT_SLOTS..FLOAT_SLOTS + 3,
            &sample,
            12,
            40,
        );
        println!("{model}: projection Jacobian {err:.2e} off differences");
        assert!(err <= 1e-6, "{model}: {err}");
        let report = gradient(
            cameras::twin::projection_jacobian,
            cameras::twin::projection_jacobian_adjoint,
            sample,
            13,
            30,
        );
        println!("{model} projection Jacobian's adjoint: {report:?}");
        assert!(
            report.jacobian <= 1e-6 && report.dot_product <= 1e-6,
            "{model}: {report:?}"
        );
    }
}

#[test]
fn shutter_pose_gradients_match_finite_differences() {
    let pixel = |r: &mut fastrand::Rng| vec![1.0 + 30.0 * r.f64(), 1.0 + 22.0 * r.f64()];
    let report = gradient(
        cameras::twin::shutter_pose,
        cameras::twin::shutter_pose_adjoint,
        sample::<{ FLOAT_SLOTS + 2 }>(rolling(CameraModel::Pinhole), pixel),
        9,
        30,
    );
    println!("shutter_pose: {report:?}");
    assert!(
        report.jacobian <= 1e-6 && report.dot_product <= 1e-6,
        "{report:?}"
    );
}
