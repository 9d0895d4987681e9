//! 2D Gaussian surfels, tested with `splat_runtime::checks` as a method author would: renders
//! against the f64 reference (disks at every tilt, edge-on included), boxes that hold every
//! pixel a disk reaches, gradients against finite differences and the reference's adjoint, the
//! GPU against the CPU, images and gradients against gsplat's 2DGS, the PLY round trip, and the
//! command line.

use splat_runtime::checks::bound::Bound;
use splat_runtime::checks::forward::{
    ImageBound, REFERENCE_IMAGE, boxes_hold_every_contributing_pixel,
    forward_matches_reference_within, gpu_forward_matches_cpu,
};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, gpu_gradients_match_cpu, gradients_match_finite_differences,
    gradients_match_reference_adjoint,
};
use splat_runtime::checks::reference;
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::io::ply::{FromStored, ToStored};
use splat_runtime::blend::Blend;
use splat_runtime::{Camera, Flat};
use surfels::surfel::{self, Method, Params};

fn camera(w: f32, h: f32) -> Camera {
    Camera {
        rotation: Mat3::from_rotation_y(0.1),
        translation: Vec3::new(0.1, -0.05, 0.2),
        focal: Vec2::splat(w),
        principal: Vec2::new(w / 2.0, h / 2.0),
        size: Vec2::new(w, h),
        ..Default::default()
    }
}

fn random_rotation(rng: &mut fastrand::Rng) -> Vec4 {
    let q = Quat::from_xyzw(
        rng.f32() - 0.5,
        rng.f32() - 0.5,
        rng.f32() - 0.5,
        rng.f32() + 0.1,
    )
    .normalize();
    Vec4::new(q.w, q.x, q.y, q.z)
}

/// `n` disks in front of the camera, with scales around `log_scale`.
fn disks(seed: u64, n: usize, spread: Vec3, log_scale: f32) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..n)
        .map(|_| Params {
            mean: (Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5) * spread
                + Vec3::new(0.0, 0.0, 4.0),
            log_scale: Vec2::new(rng.f32(), rng.f32()) * 0.8 + log_scale,
            rotation: random_rotation(&mut rng),
            opacity_logit: rng.f32() * 5.0 - 1.0,
            sh: std::array::from_fn(|_| Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5),
        })
        .collect()
}

/// A disk whose plane holds the camera's ray through its centre: seen exactly edge-on.
fn edge_on(cam: &Camera) -> Params {
    let mean = cam.rotation.transpose() * (Vec3::new(0.2, 0.1, 4.0) - cam.translation);
    let towards = (mean - cam.center()).normalize();
    // The disk's normal is perpendicular to the ray: the ray lies in its plane.
    let normal = towards.cross(Vec3::Y).normalize();
    let q = Quat::from_rotation_arc(Vec3::Z, normal);
    Params {
        mean,
        log_scale: Vec2::splat(-1.5),
        rotation: Vec4::new(q.w, q.x, q.y, q.z),
        opacity_logit: 2.0,
        sh: [Vec3::splat(0.4), Vec3::ZERO, Vec3::ZERO, Vec3::ZERO],
    }
}

const GROUPS: [(&str, std::ops::Range<usize>); 5] = [
    ("mean", 0..3),
    ("log_scale", 3..5),
    ("rotation", 5..9),
    ("opacity", 9..10),
    ("sh", 10..22),
];

const CAMERA: [(&str, std::ops::Range<usize>); 4] = [
    ("rotation", 0..9),
    ("translation", 9..12),
    ("focal", 12..14),
    ("principal", 14..16),
];

/// A surfel's alpha comes from where the pixel's ray meets its plane, which divides by the
/// ray's angle to the plane: f32 loses more there than in a Gaussian's footprint. Measured:
/// color and alpha 2.3e-5 off the f64 reference at 0.29 (1.5x the bound measured on the
/// built-in methods, 0.5 of this one).
const IMAGE: ImageBound = ImageBound {
    values: Bound::new(3e-5, 6e-6),
    ..REFERENCE_IMAGE
};

/// For the same reason the gradients: measured 8.8e-4 relative on a small log-scale gradient
/// of the dense scene (1.7x `REFERENCE_ADJOINT`, 0.75 of this bound).
const ADJOINT: Bound = Bound::new(3e-4, 3e-5).with_sum(1e-6);

#[test]
fn renders_match_the_f64_reference_on_cpu_and_gpu() {
    let cam = camera(48.0, 32.0);
    let mut params = disks(1, 16, Vec3::new(2.6, 1.8, 2.0), -1.3);
    params.push(edge_on(&cam));
    let blend = Blend::default();
    let coverage = forward_matches_reference_within::<Method>("2dgs", &params, &cam, blend, IMAGE);
    assert!(
        coverage > 0.2,
        "the scene should cover the image ({coverage})"
    );
    gpu_forward_matches_cpu::<Method>("2dgs", &params, &cam);

    let cam = camera(64.0, 48.0);
    let dense = disks(2, 500, Vec3::new(3.6, 2.8, 3.0), -2.2);
    forward_matches_reference_within::<Method>("2dgs dense", &dense, &cam, blend, IMAGE);
    gpu_forward_matches_cpu::<Method>("2dgs dense", &dense, &cam);
}

#[test]
fn boxes_hold_every_pixel_a_disk_reaches() {
    let cam = camera(48.0, 32.0);
    let mut params = disks(3, 40, Vec3::new(2.6, 1.8, 2.0), -2.0);
    params.push(edge_on(&cam));
    let checked = boxes_hold_every_contributing_pixel::<Method>("2dgs", &params, &cam, 1.0 / 255.0);
    assert!(checked > 10_000, "{checked} pairs outside the boxes");
}

/// Seen edge-on, the disk itself covers no area: the filter keeps it visible at its centre,
/// and its gradients stay finite.
#[test]
fn an_edge_on_disk_shows_through_the_filter() {
    let cam = camera(48.0, 32.0);
    let p = edge_on(&cam);
    let shade = surfel::project(&p, &cam).shade;
    let at_center = surfel::evaluate(shade.center, &shade);
    let opacity = 1.0 / (1.0 + (-p.opacity_logit).exp());
    assert!(at_center.valid && (at_center.alpha - opacity).abs() < 1e-3);
    let (_, d_shade) = surfel::evaluate_adjoint(
        shade.center + Vec2::new(0.3, -0.2),
        &shade,
        splat_runtime::Contribution {
            alpha: 1.0,
            color: Vec3::ONE,
            valid: false,
        },
    );
    assert!(d_shade.is_finite(), "{d_shade:?}");
}

/// Large disks facing the camera cover the whole image, clear of the thresholds (and of the
/// filter, which a large disk never undercuts), as central differences need.
#[test]
fn render_gradients_match_finite_differences() {
    let cam = camera(24.0, 16.0);
    let mut params = disks(4, 5, Vec3::new(0.6, 0.4, 1.0), 0.3);
    for p in &mut params {
        p.opacity_logit = -1.0 + 0.4 * p.opacity_logit.fract().abs();
        let tilt = Quat::from_rotation_x(0.4 * p.mean.x) * Quat::from_rotation_y(0.3 * p.mean.y);
        p.rotation = Vec4::new(tilt.w, tilt.x, tilt.y, tilt.z);
    }
    assert_eq!(Params::LEN, 22);
    let image = reference::render::<Method>(&params, &cam);
    assert!(image.alpha.iter().all(|a| *a < 0.99));
    for p in &params {
        let solo = reference::render::<Method>(std::slice::from_ref(p), &cam);
        let least = solo.alpha.iter().fold(1.0f64, |m, a| m.min(*a));
        assert!(least > 2.0 / 255.0, "each disk covers the image ({least})");
    }
    gradients_match_finite_differences::<Method>(
        "2dgs",
        &params,
        &cam,
        &GROUPS,
        &CAMERA,
        FINITE_DIFFERENCES,
    );
}

/// A dense scene (pairs skipped mid-list, pixels stopped at the T-stop): the backward pass
/// against the reference's analytic adjoint, on the CPU and the GPU.
#[test]
fn dense_gradients_match_the_reference_adjoint_on_cpu_and_gpu() {
    let cam = camera(48.0, 32.0);
    let params = disks(5, 400, Vec3::new(3.0, 2.2, 2.0), -2.0);
    gradients_match_reference_adjoint::<Method>("2dgs", &params, &cam, &GROUPS, &CAMERA, ADJOINT);
    gpu_gradients_match_cpu::<Method>("2dgs", &params, &cam);
}

/// Written as a flat Gaussian and read back, a disk is the same disk (the frame may turn
/// about its normal by a multiple of 90 degrees only if the scales tie, which they do not).
#[test]
fn a_disk_survives_the_ply_round_trip() {
    let cam = camera(48.0, 32.0);
    for p in disks(6, 20, Vec3::new(2.0, 1.5, 1.0), -1.5) {
        let back = Params::from_stored(&p.to_stored());
        let (a, b) = (surfel::project(&p, &cam), surfel::project(&back, &cam));
        let px = a.shade.center + Vec2::new(0.7, -0.4);
        let (ea, eb) = (
            surfel::evaluate(px, &a.shade),
            surfel::evaluate(px, &b.shade),
        );
        assert!(
            (ea.alpha - eb.alpha).abs() < 1e-4,
            "{} vs {}",
            ea.alpha,
            eb.alpha
        );
        assert!((back.log_scale - p.log_scale).abs().max_element() < 1e-5);
    }
}

/// The crate's command line: render the built-in scene and train on the built-in dataset.
#[test]
fn the_command_line_renders_and_trains_surfels() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_owned();
    let run = |args: &[&str]| {
        splat_cli::run_with_args(&[surfels::method()], ["surfels"].iter().chain(args))
    };
    let picture = out("planet.png");
    run(&[
        "render",
        "--backend",
        "cpu",
        "--width",
        "64",
        "--height",
        "48",
        "--out",
        &picture,
    ])
    .unwrap();
    assert!(std::fs::metadata(&picture).unwrap().len() > 0);
    let fit = out("fit");
    run(&[
        "fit",
        "--backend",
        "cpu",
        "--steps",
        "300",
        "--eval-every",
        "0",
        "--out",
        &fit,
    ])
    .unwrap();
    let metrics = std::fs::read_to_string(dir.path().join("fit/metrics.csv")).unwrap();
    let psnr: Vec<f64> = metrics
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(5)?.parse().ok())
        .collect();
    println!("test PSNR {psnr:?}");
    assert!(psnr.len() == 2 && psnr[1] > psnr[0] + 8.0, "{metrics}");
    let scene = splat_runtime::io::ply::read(&dir.path().join("fit/scene.ply")).unwrap();
    assert!(!scene.gaussians.is_empty());
}

/// Against an independent reference: gsplat's 2DGS in float64 (its `_torch_impl_2dgs.py`: the
/// ray transform, the ray-splat intersection, the low-pass filter), written as a fixture by
/// splat's `methods/tests/gsplat/make_fixtures.py`, held the way splat holds its own methods to
/// theirs (`checks::fixture`): images on the clear pixels, gradients per parameter group and
/// camera field, on the CPU and the GPU, within the bounds splat's 3DGS is held to against
/// gsplat. Measured: color and alpha 0.67 of the bound on the CPU, 0.77 on the GPU (lavapipe);
/// depth 0.33; gradients 0.30 (a log scale, CPU), 0.28 on the GPU (a rotation).
#[test]
fn surfels_match_gsplat_2dgs() {
    use splat_runtime::checks::fixture::{Bounds, matches_fixture};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gsplat_2dgs.json");
    let bounds = Bounds {
        image: ImageBound {
            values: Bound::new(2e-6, 1e-6),
            depth: Bound::new(1e-5, 1e-5),
        },
        gradient: Bound::new(1e-4, 1e-5),
    };
    matches_fixture::<Method>(&path, &bounds, &bounds);
}
