//! 3DGUT and 3DGEER with a rolling shutter (`gut_rs`, `geer_rs`): rows read out top to bottom
//! while the camera moves. The pose per row against its definition written here independently (f64 axis-angle);
//! a thin vertical Gaussian seen by a camera sliding sideways leans by the slide, row by row;
//! a still camera renders exactly as `gut` (`geer`); then the shared checks with a moving camera on every
//! model (f64 reference, boxes, the tile cull against none, finite differences with the
//! shutter's own gradient, GPU parity). Methods without a rolling shutter refuse a moving camera.

use crate::common::{
    GAUSSIAN_GROUPS, SHUTTER_GROUPS, as_method, camera, camera_groups, covering_gaussians,
    spread_gaussians, wide_camera,
};
use splat_methods::{FromStored, geer, geer_rs, gut, gut_rs};
use splat_runtime::checks::forward::{
    boxes_hold_every_contributing_pixel, forward_matches_reference, gpu_forward_matches_cpu,
    tile_cull_is_conservative,
};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, gpu_gradients_match_cpu, gradients_match_finite_differences,
};
use splat_runtime::glam::{DMat3, DVec3, Mat3, Vec2, Vec3, Vec4};
use splat_runtime::io::camera::with_last_row_pose;
use splat_runtime::{Camera, CameraModel, RenderOptions, SplatMethod, render};

/// `cam` turning 3° about a tilted axis and sliding 0.15 sideways (and a little up) during
/// its readout: its last row's pose, given as such.
fn rolling(cam: Camera) -> Camera {
    let turn = Mat3::from_axis_angle(Vec3::new(0.3, 1.0, 0.1).normalize(), 3f32.to_radians());
    let last_rotation = turn * cam.rotation;
    let last_center = cam.center() + Vec3::new(0.15, -0.05, 0.0);
    with_last_row_pose(cam, last_rotation, -(last_rotation * last_center)).unwrap()
}

#[test]
fn the_pose_per_row_follows_its_definition() {
    let axis = DVec3::new(0.3, 1.0, 0.1).normalize();
    let angle = 3f64.to_radians();
    let first = Mat3::from_rotation_x(0.2) * Mat3::from_rotation_y(-0.4);
    let cam = rolling(Camera {
        rotation: first,
        translation: Vec3::new(0.1, 0.2, -0.3),
        ..camera(40, 30)
    });
    let c0 = cam.center().as_dvec3();
    for row in [0.0f32, 7.5, 15.0, 22.5, 30.0] {
        let t = cam.shutter_time(Vec2::new(3.5, row));
        assert_eq!(t, row / 30.0);
        // Turned by 2 atan(t tan(angle / 2)) about the axis, the centre moved by t * slide.
        let turned = 2.0 * (t as f64 * (angle / 2.0).tan()).atan();
        let want_rotation = DMat3::from_axis_angle(axis, turned) * first.as_dmat3();
        let want_center = c0 + DVec3::new(0.15, -0.05, 0.0) * t as f64;
        let got_rotation = cam.rotation_at(t).as_dmat3();
        let got_center = -(got_rotation.transpose() * cam.translation_at(t).as_dvec3());
        let off = (got_rotation - want_rotation).to_cols_array();
        assert!(
            off.iter().all(|v| v.abs() < 2e-6),
            "row {row}: rotation off by {off:?}"
        );
        assert!(
            (got_center - want_center).length() < 2e-6,
            "row {row}: centre {got_center} vs {want_center}"
        );
        // The method's ray for a pixel of this row is the ray of the camera posed there.
        let pixel = Vec2::new(11.5, row.min(29.5));
        let t = cam.shutter_time(pixel);
        let posed = Camera {
            rotation: cam.rotation_at(t),
            translation: cam.translation_at(t),
            shutter_turn: Vec3::ZERO,
            shutter_shift: Vec3::ZERO,
            ..cam
        };
        let ray = gut_rs::Method::pixel_info(pixel, &cam);
        let still = gut::Method::pixel_info(pixel, &posed);
        assert!((ray.dir - still.dir).length() < 1e-6);
        assert!((cam.center() + ray.shift - posed.center()).length() < 1e-5);
    }
}

/// A narrow vertical Gaussian 2 units ahead of a camera sliding 0.2 right during its readout:
/// each row sees it where the camera was when that row was read, `focal * -slide * t / 2`
/// pixels left of where the first row does. Measured as each row's color centroid.
#[test]
fn a_vertical_line_leans_by_the_slide() {
    let cam = camera(64, 64);
    let (focal, depth, slide) = (64.0f64, 2.0f64, 0.2f64);
    let moving = Camera {
        shutter_shift: Vec3::new(slide as f32, 0.0, 0.0),
        ..cam
    };
    let mut line = crate::common::gaussian_at(
        &mut fastrand::Rng::with_seed(1),
        &cam,
        Vec2::new(32.0, 32.0),
        2.0,
        0.0,
    );
    line.log_scale = Vec3::new(-3.0, 1.0, -3.0); // 1.6 px wide, taller than the image
    line.rotation = Vec4::new(1.0, 0.0, 0.0, 0.0);
    line.opacity_logit = 4.0;
    line.sh = [Vec3::ZERO; 16];
    line.sh[0] = Vec3::splat(1.0);
    let params = as_method::<gut_rs::Params>(vec![line]);
    let frame = render::<gut_rs::Method>(&params, &moving, &RenderOptions::default()).unwrap();
    for row in (4..60).step_by(5) {
        let (mut sum, mut weight) = (0.0f64, 0.0f64);
        for col in 0..64 {
            let v = frame.color.data[(row * 64 + col) * 3] as f64;
            sum += v * (col as f64 + 0.5);
            weight += v;
        }
        let t = (row as f64 + 0.5) / 64.0;
        let want = 32.0 - focal * slide * t / depth;
        let got = sum / weight;
        assert!(
            (got - want).abs() < 0.05,
            "row {row}: the line is at x = {got:.3}, want {want:.3}"
        );
    }
}

/// `Rolling` renders a still camera exactly as `Still`, its global-shutter twin.
fn a_still_camera_renders_exactly_as<Still: SplatMethod, Rolling: SplatMethod>()
where
    Still::Params: FromStored,
    Rolling::Params: FromStored,
{
    let opts = RenderOptions {
        alpha: true,
        depth: true,
        ..RenderOptions::default()
    };
    for model in CameraModel::ALL {
        let cam = wide_camera(48, 32, model);
        let gaussians = spread_gaussians(&cam, 200, 5);
        let still = render::<Still>(&as_method(gaussians.clone()), &cam, &opts).unwrap();
        let rs = render::<Rolling>(&as_method(gaussians), &cam, &opts).unwrap();
        let label = format!("{} {model}", Rolling::NAME);
        assert_eq!(rs.color.data, still.color.data, "{label}");
        assert_eq!(rs.alpha, still.alpha, "{label}");
        assert_eq!(rs.depth, still.depth, "{label}");
    }
}

#[test]
fn a_still_camera_renders_exactly_as_3dgut() {
    a_still_camera_renders_exactly_as::<gut::Method, gut_rs::Method>();
}

#[test]
fn a_still_camera_renders_exactly_as_3dgeer() {
    a_still_camera_renders_exactly_as::<geer::Method, geer_rs::Method>();
}

/// The shared checks with a moving camera on every model: the f64 reference, boxes, finite
/// differences (the shutter's own gradient too), GPU parity.
fn shared_checks_on_every_camera_model<M: SplatMethod>()
where
    M::Params: FromStored,
{
    for model in CameraModel::ALL {
        let label = format!("{} {model}", M::NAME);
        let cam = rolling(wide_camera(64, 48, model));
        let scene: Vec<M::Params> = as_method(spread_gaussians(&cam, 120, 31));
        let coverage = forward_matches_reference::<M>(&label, &scene, &cam);
        assert!(coverage > 0.2, "{label}: the scene should cover the image");
        let outside = boxes_hold_every_contributing_pixel::<M>(&label, &scene, &cam, 1.0 / 255.0);
        println!("{label}: {outside} (primitive, pixel) pairs outside the boxes, all below 1/255");
        gpu_forward_matches_cpu::<M>(&label, &scene, &cam);
        tile_cull_is_conservative::<M>(&label, &scene, &cam);

        let small = rolling(wide_camera(24, 16, model));
        let covering: Vec<M::Params> = as_method(covering_gaussians(&small));
        let cameras: Vec<_> = camera_groups(model)
            .iter()
            .chain(&SHUTTER_GROUPS)
            .cloned()
            .collect();
        gradients_match_finite_differences::<M>(
            &label,
            &covering,
            &small,
            &GAUSSIAN_GROUPS,
            &cameras,
            FINITE_DIFFERENCES,
        );
        gpu_gradients_match_cpu::<M>(&label, &covering, &small);
    }
}

#[test]
fn rolling_shutter_3dgut_passes_the_shared_checks_on_every_camera_model() {
    shared_checks_on_every_camera_model::<gut_rs::Method>();
}

#[test]
fn rolling_shutter_3dgeer_passes_the_shared_checks_on_every_camera_model() {
    shared_checks_on_every_camera_model::<geer_rs::Method>();
}

#[test]
fn global_shutter_methods_refuse_a_moving_camera() {
    let cam = rolling(camera(16, 16));
    let Err(err) = render::<gut::Method>(&[], &cam, &RenderOptions::default()) else {
        panic!("3DGUT rendered a rolling shutter as a global one");
    };
    assert!(err.to_string().contains("global shutters only"), "{err}");
    const { assert!(gut_rs::Method::ROLLING_SHUTTER && !gut::Method::ROLLING_SHUTTER) };
    const { assert!(geer_rs::Method::ROLLING_SHUTTER && !geer::Method::ROLLING_SHUTTER) };
}
