//! Generalized exponential splats, tested as a method author would with `splat_runtime::checks`:
//! CPU renders against the f64 brute-force reference built from the method's twins, on a
//! simple and a realistic scene; full-render gradients (β included) against central
//! differences of the reference, and on the realistic scene against its analytic adjoint; the
//! GPU against the CPU, forward and backward; and the falloff itself (β = 2 is the Gaussian; a
//! larger β is flatter inside and sharper at the edge; the box holds every pixel the alpha
//! threshold keeps).

use splat_examples::generalized::generalized::{self, Method, Params, Shade};
use splat_runtime::checks::forward::{
    forward_matches_reference, gpu_forward_matches_cpu, tile_cull_is_conservative,
};
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gpu_gradients_match_cpu,
    gradients_match_finite_differences, gradients_match_reference_adjoint,
};
use splat_runtime::checks::reference;
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, CameraModel, Contribution, F32x8, Flat, RenderOptions};

fn camera(w: f32, h: f32, rotation: Mat3, translation: Vec3) -> Camera {
    Camera {
        rotation,
        translation,
        focal: Vec2::splat(w),
        principal: Vec2::new(w / 2.0, h / 2.0),
        size: Vec2::new(w, h),
        ..Default::default()
    }
}

/// A splat of shape `beta` whose centre projects to `pixel` at depth `z` through an
/// identity-pose camera, with a random rotation, scales around `log_scale` and SH color.
fn splat_at(
    rng: &mut fastrand::Rng,
    cam: &Camera,
    pixel: Vec2,
    z: f32,
    log_scale: f32,
    beta: f32,
) -> Params {
    let ndc = (pixel - cam.principal) / cam.focal;
    let q = Quat::from_xyzw(
        rng.f32() - 0.5,
        rng.f32() - 0.5,
        rng.f32() - 0.5,
        rng.f32() + 0.2,
    )
    .normalize();
    Params {
        mean: Vec3::new(ndc.x * z, ndc.y * z, z),
        log_scale: Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 0.6 + log_scale,
        rotation: Vec4::new(q.w, q.x, q.y, q.z),
        opacity_logit: rng.f32() * 4.0 - 1.0,
        log_shape_half: (beta / 2.0).ln(),
        sh: std::array::from_fn(|_| Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 0.6 - 0.3),
    }
}

/// Twelve splats with shapes from 1 to 6 in front of a 48 x 32 camera.
fn scene() -> (Camera, Vec<Params>) {
    let cam = camera(
        48.0,
        32.0,
        Mat3::from_rotation_y(0.1),
        Vec3::new(0.1, -0.05, 0.2),
    );
    let mut rng = fastrand::Rng::with_seed(21);
    let params: Vec<Params> = (0..12)
        .map(|_| {
            let q = Quat::from_xyzw(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5, rng.f32())
                .normalize();
            Params {
                mean: Vec3::new(
                    rng.f32() * 2.4 - 1.2,
                    rng.f32() * 1.6 - 0.8,
                    3.0 + 2.0 * rng.f32(),
                ),
                log_scale: Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 1.2 - 2.0,
                rotation: Vec4::new(q.w, q.x, q.y, q.z),
                opacity_logit: rng.f32() * 5.0 - 1.0,
                log_shape_half: ((1.0 + 5.0 * rng.f32()) / 2.0).ln(),
                sh: std::array::from_fn(|_| Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5),
            }
        })
        .collect();
    (cam, params)
}

/// A realistic scene: 600 splats of shapes 1 to 6 over a 64 x 48 image and past its edges,
/// dense enough that pairs fall below the threshold mid-list and pixels reach the T-stop.
fn realistic_scene() -> (Camera, Vec<Params>) {
    let cam = camera(64.0, 48.0, Mat3::IDENTITY, Vec3::ZERO);
    let mut rng = fastrand::Rng::with_seed(5);
    let params = (0..600)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 72.0 - 4.0, rng.f32() * 56.0 - 4.0);
            let (beta, z) = (1.0 + 5.0 * rng.f32(), 2.0 + 4.0 * rng.f32());
            splat_at(&mut rng, &cam, px, z, -1.8, beta)
        })
        .collect();
    (cam, params)
}

/// Word ranges of `Params`.
const GROUPS: [(&str, std::ops::Range<usize>); 6] = [
    ("mean", 0..3),
    ("log_scale", 3..6),
    ("rotation", 6..10),
    ("opacity", 10..11),
    ("shape", 11..12),
    ("sh", 12..24),
];

/// Camera groups (ranges of its float slots).
const CAMERA: [(&str, std::ops::Range<usize>); 4] = [
    ("rotation", 0..9),
    ("translation", 9..12),
    ("focal", 12..14),
    ("principal", 14..16),
];

#[test]
fn renders_match_the_f64_reference_on_cpu_and_gpu() {
    let (cam, params) = scene();
    let coverage = forward_matches_reference::<Method>("ges", &params, &cam);
    assert!(
        coverage > 0.2,
        "the scene should cover the image ({coverage})"
    );
    gpu_forward_matches_cpu::<Method>("ges", &params, &cam);
    let (cam, params) = realistic_scene();
    forward_matches_reference::<Method>("ges realistic", &params, &cam);
    gpu_forward_matches_cpu::<Method>("ges realistic", &params, &cam);
}

#[test]
fn render_gradients_match_finite_differences() {
    let cam = camera(24.0, 16.0, Mat3::IDENTITY, Vec3::ZERO);
    let mut rng = fastrand::Rng::with_seed(9);
    let betas = [1.0, 1.6, 2.0, 2.6, 3.2];
    let params: Vec<Params> = betas
        .iter()
        .enumerate()
        .map(|(i, beta)| {
            let px = Vec2::new(6.0 + 3.0 * i as f32, 5.0 + 1.5 * i as f32);
            let mut p = splat_at(&mut rng, &cam, px, 3.0 + 0.5 * i as f32, 0.5, *beta);
            p.opacity_logit = -1.0 + 0.4 * rng.f32();
            p
        })
        .collect();
    assert_eq!(Params::LEN, 24);
    // Clear of the thresholds: every splat above 1/255 at every pixel, transmittance high.
    assert!(
        reference::render::<Method>(&params, &cam)
            .alpha
            .iter()
            .all(|a| *a < 0.99)
    );
    for p in &params {
        let solo = reference::render::<Method>(std::slice::from_ref(p), &cam);
        let min_alpha = solo.alpha.iter().fold(1.0f64, |m, a| m.min(*a));
        assert!(
            min_alpha > 2.0 / 255.0,
            "each splat covers the image (min alpha {min_alpha})"
        );
    }
    gradients_match_finite_differences::<Method>(
        "ges",
        &params,
        &cam,
        &GROUPS,
        &CAMERA,
        FINITE_DIFFERENCES,
    );
}

/// On a realistic scene (thresholds crossed, T-stops reached) the backward pass matches the
/// reference's analytic adjoint, on the CPU and the GPU.
#[test]
fn realistic_gradients_match_the_reference_adjoint_on_cpu_and_gpu() {
    let (cam, params) = realistic_scene();
    gradients_match_reference_adjoint::<Method>(
        "ges",
        &params,
        &cam,
        &GROUPS,
        &CAMERA,
        REFERENCE_ADJOINT,
    );
    gpu_gradients_match_cpu::<Method>("ges", &params, &cam);
}

fn alpha_at(shade: &Shade, d: Vec2) -> f32 {
    let c = generalized::evaluate(shade.center + d, shade);
    if c.valid { c.alpha } else { 0.0 }
}

#[test]
fn shape_two_is_gaussian_and_larger_shapes_are_flatter_and_sharper() {
    let gaussian = Shade {
        center: Vec2::new(10.0, 7.0),
        conic: Vec3::new(0.5, 0.1, 0.3),
        opacity: 0.8,
        shape: 2.0,
        color: Vec3::ONE,
    };
    for d in [
        Vec2::ZERO,
        Vec2::new(0.7, -0.2),
        Vec2::new(-1.5, 2.0),
        Vec2::new(2.5, 1.0),
    ] {
        let q = gaussian.conic.x * d.x * d.x
            + 2.0 * gaussian.conic.y * d.x * d.y
            + gaussian.conic.z * d.y * d.y;
        let want = gaussian.opacity * (-0.5 * q).exp();
        let got = alpha_at(&gaussian, d);
        assert!(
            (got - want).abs() <= 1e-6,
            "beta = 2 at {d}: {got} vs Gaussian {want}"
        );
    }

    // Isotropic, sigma = 1 px: inside (r = 0.5) a larger beta keeps more alpha, outside (r = 2)
    // less.
    let iso = Shade {
        conic: Vec3::new(1.0, 0.0, 1.0),
        ..gaussian
    };
    let flat = Shade { shape: 8.0, ..iso };
    let (core, edge) = (Vec2::new(0.5, 0.0), Vec2::new(0.0, 2.0));
    println!(
        "alpha at r = 0.5 / 2: beta 2 {:.4} / {:.4}, beta 8 {:.4} / {:.4}",
        alpha_at(&iso, core),
        alpha_at(&iso, edge),
        alpha_at(&flat, core),
        alpha_at(&flat, edge)
    );
    assert!(alpha_at(&flat, core) > alpha_at(&iso, core) + 0.05);
    assert!(alpha_at(&flat, core) > 0.99 * flat.opacity);
    assert!(alpha_at(&flat, edge) < alpha_at(&iso, edge) - 0.05);

    // Log-shape 0 projects to beta = 2 exactly.
    let cam = camera(32.0, 24.0, Mat3::IDENTITY, Vec3::ZERO);
    let mut rng = fastrand::Rng::with_seed(3);
    let p = splat_at(&mut rng, &cam, Vec2::new(16.0, 12.0), 4.0, -1.5, 2.0);
    assert_eq!(generalized::project(&p, &cam).shade.shape, 2.0);
}

/// Every point just outside the box is below the alpha threshold, for shapes from 0.5 to 16
/// (the falloff radius grows as (2 ln(255 opacity))^(1/β)).
#[test]
fn the_box_holds_every_kept_pixel() {
    let cam = camera(32.0, 24.0, Mat3::IDENTITY, Vec3::ZERO);
    let mut rng = fastrand::Rng::with_seed(4);
    for beta in [0.5, 1.0, 2.0, 4.0, 8.0, 16.0] {
        for logit in [-4.0, 0.0, 5.0] {
            let mut p = splat_at(&mut rng, &cam, Vec2::new(16.0, 12.0), 4.0, -1.8, beta);
            p.opacity_logit = logit;
            let pr = generalized::project(&p, &cam);
            let (lo, hi) = (pr.bbox_min - 1e-3, pr.bbox_max + 1e-3);
            for k in 0..=256 {
                let s = k as f32 / 256.0;
                for px in [
                    Vec2::new(lo.x + s * (hi.x - lo.x), lo.y),
                    Vec2::new(lo.x + s * (hi.x - lo.x), hi.y),
                    Vec2::new(lo.x, lo.y + s * (hi.y - lo.y)),
                    Vec2::new(hi.x, lo.y + s * (hi.y - lo.y)),
                ] {
                    let c = generalized::evaluate(px, &pr.shade);
                    assert!(
                        !c.valid,
                        "beta {beta}: alpha {} at {px}, box {lo}..{hi}",
                        c.alpha
                    );
                }
            }
        }
    }
}

/// The cull (the falloff's ellipse against each tile, like StopThePop's) drops only pairs the
/// 1/255 threshold would skip, and drops some.
#[test]
fn the_tile_cull_is_conservative() {
    for (label, (cam, params)) in [("ges", scene()), ("ges realistic", realistic_scene())] {
        for (with, without) in tile_cull_is_conservative::<Method>(label, &params, &cam) {
            assert!(
                with < without,
                "{label}: the cull dropped nothing ({with} of {without})"
            );
        }
    }
}

/// At the centre (q = 0) the scalar, lane and f64 adjoints are all finite.
#[test]
fn gradients_at_the_centre_are_finite() {
    for shape in [0.5, 1.0, 2.0, 8.0] {
        let s = Shade {
            center: Vec2::new(3.5, 2.5),
            conic: Vec3::new(0.5, 0.1, 0.3),
            opacity: 0.6,
            shape,
            color: Vec3::ONE,
        };
        let d_out = Contribution {
            alpha: 1.0,
            color: Vec3::ONE,
            valid: false,
        };
        let (d_px, d_s) = generalized::evaluate_adjoint(s.center, &s, d_out);
        assert!(
            d_px.is_finite() && d_s.is_finite(),
            "beta {shape}: {d_px} {d_s:?}"
        );

        let mut words = [0.0f32; 2 + Shade::LEN];
        words[..2].copy_from_slice(&s.center.to_array());
        s.write_words(&mut words[2..]);
        let lanes = generalized::lanes::evaluate_adjoint(
            &words.map(F32x8::splat),
            &[],
            &[F32x8::splat(1.0); 4],
        );
        assert!(
            lanes.iter().all(|l| l.0.iter().all(|v| v.is_finite())),
            "lanes, beta {shape}"
        );
        let twin = generalized::twin::evaluate_adjoint(&words.map(f64::from), &[], &[1.0; 4]);
        assert!(twin.iter().all(|v| v.is_finite()), "twin, beta {shape}");
    }
}

/// GES trains through the same loop as the built-in methods (its `Trainable` declarations in
/// its own file): views of a known GES scene, a moved start of Gaussians (β = 2), and the
/// held-out views get much closer; the shapes move off 2.
#[test]
fn ges_trains_with_the_shared_loop() {
    fits_views_of_a_known_scene(CameraModel::Pinhole);
}

/// The same source trains on a wide fisheye: the EWA Jacobian of its projection comes from
/// the compiler.
#[test]
fn ges_trains_on_a_fisheye() {
    fits_views_of_a_known_scene(CameraModel::KannalaBrandt);
}

/// ... and on the equiangular camera.
#[test]
fn ges_trains_on_an_equiangular_camera() {
    fits_views_of_a_known_scene(CameraModel::Equiangular);
}

/// Fits GES to 8 views (40x40) of [`scene`]'s splats through `model` and checks two held-out
/// views: at least 4 dB closer, and some shape moved off the Gaussian's β = 2.
fn fits_views_of_a_known_scene(model: CameraModel) {
    use splat_runtime::io::dataset::{Dataset, View};
    use splat_runtime::train::Trainable;
    use splat_runtime::train::fit::{FitOptions, evaluate, fit};
    let (_, truth) = scene();
    let look_at = |a: f32, y: f32| {
        let eye = Vec3::new(4.0 * a.sin(), y, 4.0 - 4.0 * a.cos());
        let target = Vec3::new(0.0, 0.0, 4.0);
        let f = (target - eye).normalize();
        let r = f.cross(Vec3::Y).normalize();
        let rotation = Mat3::from_cols(r, f.cross(r), f).transpose();
        let pinhole = camera(40.0, 40.0, rotation, -(rotation * eye));
        match model {
            CameraModel::Pinhole => pinhole,
            // Half the pinhole's focal: about 57 degrees from the axis to the image's side.
            _ => Camera {
                model,
                focal: Vec2::splat(20.0),
                distortion: match model {
                    CameraModel::KannalaBrandt => FISHEYE_K,
                    _ => Vec4::ZERO,
                },
                ..pinhole
            },
        }
    };
    let view = |cam: Camera| {
        let opts = RenderOptions {
            tile_size: 8,
            ..Default::default()
        };
        let image = splat_runtime::render::<Method>(&truth, &cam, &opts)
            .unwrap()
            .color;
        View::new("view".into(), cam, image, None, Vec3::ZERO)
    };
    let data = Dataset {
        train: (0..8)
            .map(|k| view(look_at(0.15 * k as f32 - 0.5, 0.1 * (k % 3) as f32)))
            .collect(),
        test: vec![view(look_at(0.07, 0.05)), view(look_at(-0.3, 0.15))],
        points: vec![],
    };
    let mut rng = fastrand::Rng::with_seed(3);
    let mut params: Vec<Params> = truth
        .iter()
        .map(|g| {
            let jitter = Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5;
            Method::from_point(g.mean + 0.1 * jitter, Vec3::splat(0.5), 0.1)
        })
        .collect();
    let opts = FitOptions {
        steps: 300,
        densify: None,
        render: RenderOptions {
            tile_size: 8,
            alpha: true,
            ..Default::default()
        },
        ..Default::default()
    };
    let before = evaluate::<Method>(&params, &data.test, &opts).unwrap();
    fit::<Method>(&data, &mut params, 1.0, &opts, |_| {}).unwrap();
    let after = evaluate::<Method>(&params, &data.test, &opts).unwrap();
    let shapes: Vec<f32> = params
        .iter()
        .map(|p| 2.0 * p.log_shape_half.exp())
        .collect();
    println!(
        "GES {model}: held-out PSNR {:.2} -> {:.2} dB; shapes {shapes:?}",
        before.psnr, after.psnr
    );
    assert!(
        // Measured +15.3 dB (pinhole), +14.4 (fisheye and equiangular).
        after.psnr > before.psnr + 13.5,
        "{model}: held-out views get closer"
    );
    assert!(
        shapes.iter().any(|b| (b - 2.0).abs() > 0.05),
        "{model}: the shape is trained"
    );
}

/// Kannala-Brandt coefficients of a mild fisheye, shared by the tests on wide cameras.
const FISHEYE_K: Vec4 = Vec4::new(0.02, -0.002, 0.0002, -0.00001);

/// The same source on the wide camera models: `project` takes the projection's Jacobian from
/// the compiler (`jacobian(|q| cam.project_point(q), at)`), so the fisheye and equiangular
/// cameras need nothing more. Renders against the f64 reference, gradients against its
/// analytic adjoint, the GPU's render and gradients against the CPU's (the gradients summed
/// over many pixels whose terms cancel, held to the rounding of their terms).
#[test]
fn every_camera_model_renders_and_differentiates() {
    for model in [CameraModel::KannalaBrandt, CameraModel::Equiangular] {
        let cam = Camera {
            focal: Vec2::splat(64.0 / 3.0),
            distortion: match model {
                CameraModel::KannalaBrandt => FISHEYE_K,
                _ => Vec4::ZERO,
            },
            model,
            ..camera(64.0, 48.0, Mat3::IDENTITY, Vec3::ZERO)
        };
        let mut rng = fastrand::Rng::with_seed(8);
        let params: Vec<Params> = (0..300)
            .map(|_| {
                let px = Vec2::new(rng.f32() * 72.0 - 4.0, rng.f32() * 56.0 - 4.0);
                let (beta, d) = (1.0 + 5.0 * rng.f32(), 2.0 + 4.0 * rng.f32());
                let mut p = splat_at(&mut rng, &cam, px, d, -1.2, beta);
                p.mean = cam.pixel_ray(px) * d;
                p
            })
            .collect();
        let label = format!("ges {model}");
        let coverage = forward_matches_reference::<Method>(&label, &params, &cam);
        assert!(coverage > 0.2, "{label}: coverage {coverage}");
        gradients_match_reference_adjoint::<Method>(
            &label,
            &params,
            &cam,
            &GROUPS,
            &CAMERA,
            REFERENCE_ADJOINT,
        );
        gpu_forward_matches_cpu::<Method>(&label, &params, &cam);
        gpu_gradients_match_cpu::<Method>(&label, &params, &cam);
    }
}

/// GES's shape is a field 3DGS does not train: `gaussian_rates` names it unless given its rate
/// (as `like_3dgs!` gives it, 1e-3, after the opacity).
#[test]
fn the_shape_needs_a_rate_of_its_own() {
    use splat_runtime::train::Rate;
    use splat_runtime::train::like_3dgs::gaussian_rates;
    let err = gaussian_rates::<Method>(1.0, &[]).unwrap_err();
    assert!(err.contains("`log_shape_half`"), "{err}");
    let rates = gaussian_rates::<Method>(1.0, &[("log_shape_half", Rate::fixed(0.5))]).unwrap();
    assert_eq!(
        (rates.len(), rates[11].first, rates[12].first),
        (24, 0.5, 2.5e-3)
    );
}
