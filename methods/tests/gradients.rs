//! Full-render gradients of 3DGS (color, alpha and expected depth, every parameter group and
//! the camera) against central finite differences of the f64 reference renderer, on a scene
//! clear of the thresholds (every Gaussian covers the whole image with alpha well above 1/255
//! and transmittance stays far above 1e-4, so the render is smooth in every parameter); and
//! against the reference's analytic adjoint on realistic scenes, where they are crossed.

use crate::common::{CAMERA_GROUPS, GAUSSIAN_GROUPS, camera, gaussian_at, spread_gaussians};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::CameraModel::Pinhole;
use splat_runtime::checks;
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gpu_gradients_match_cpu,
    gradients_match_reference_adjoint, invalid_pairs_leave_no_trace,
};
use splat_runtime::glam::Vec2;
use splat_runtime::{Flat, FrameGrad, RenderOptions, backward, render_for_backward};

const W: u32 = 24;
const H: u32 = 16;

struct Weights {
    color: Vec<f64>,
    alpha: Vec<f64>,
    depth: Vec<f64>,
}

fn loss(params: &[Vec<f64>], cam: &[f64], w: &Weights) -> f64 {
    let r = checks::reference::render_words::<Method>(params, cam, Pinhole);
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    dot(&r.color, &w.color) + dot(&r.alpha, &w.alpha) + dot(&r.depth, &w.depth)
}

fn fd(f: impl Fn(f64) -> f64, x: f64) -> f64 {
    let h = 1e-5 * x.abs().max(1.0);
    (f(x + h) - f(x - h)) / (2.0 * h)
}

#[test]
fn render_gradients_match_finite_differences() {
    let mut rng = fastrand::Rng::with_seed(9);
    let cam = camera(W, H);
    let params: Vec<Params> = (0..5)
        .map(|i| {
            let px = Vec2::new(6.0 + 3.0 * i as f32, 5.0 + 1.5 * i as f32);
            let mut p = gaussian_at(&mut rng, &cam, px, 3.0 + 0.5 * i as f32, 0.3);
            p.opacity_logit = -1.0 + 0.4 * rng.f32();
            p
        })
        .collect();
    let words: Vec<Vec<f64>> = params.iter().map(checks::words).collect();
    let cam_words = checks::camera_words(&cam);

    // Clear of the thresholds: alpha of every Gaussian above 1/255 at every pixel, T high.
    let reference = checks::reference::render_words::<Method>(&words, &cam_words, Pinhole);
    assert!(
        reference.alpha.iter().all(|a| *a < 0.99),
        "transmittance stays far from 1e-4"
    );
    for p in &words {
        let solo =
            checks::reference::render_words::<Method>(std::slice::from_ref(p), &cam_words, Pinhole);
        let min_alpha = solo.alpha.iter().fold(1.0f64, |m, a| m.min(*a));
        assert!(
            min_alpha > 2.0 / 255.0,
            "each Gaussian covers the image (min alpha {min_alpha})"
        );
    }

    let n = (W * H) as usize;
    let mut wr = fastrand::Rng::with_seed(10);
    let mut random = |k: usize| (0..k).map(|_| wr.f64() * 2.0 - 1.0).collect::<Vec<f64>>();
    let w = Weights {
        color: random(n * 3),
        alpha: random(n),
        depth: random(n),
    };

    let opts = RenderOptions {
        tile_size: 8,
        alpha: true,
        depth: true,
        ..Default::default()
    };
    let (_, state) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
    let f32s = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<f32>>();
    let grad = FrameGrad {
        color: f32s(&w.color),
        alpha: Some(f32s(&w.alpha)),
        depth: Some(f32s(&w.depth)),
    };
    let g = backward::<Method>(&state, &params, &cam, &grad).unwrap();

    // Parameter groups: word ranges of Params.
    let groups = [
        ("mean", 0..3),
        ("log_scale", 3..6),
        ("rotation", 6..10),
        ("opacity", 10..11),
        ("sh", 11..59),
    ];
    for (name, range) in groups {
        let (mut got, mut want) = (vec![], vec![]);
        for (i, p) in g.params.iter().enumerate() {
            let mut gw = vec![0.0f32; Params::LEN];
            p.write_words(&mut gw);
            for k in range.clone() {
                got.push(gw[k] as f64);
                want.push(fd(
                    |x| {
                        let mut ws = words.clone();
                        ws[i][k] = x;
                        loss(&ws, &cam_words, &w)
                    },
                    words[i][k],
                ));
            }
        }
        let width = range.len();
        FINITE_DIFFERENCES.check(name, &got, &want, None, |k| {
            format!("Gaussian {} word {}", k / width, k % width)
        });
    }

    // Camera: rotation (9), translation (3), focal (2), principal (2).
    let cam_grad = checks::camera_words(&g.camera);
    let cam_groups = [
        ("camera rotation", 0..9),
        ("camera translation", 9..12),
        ("focal", 12..14),
        ("principal", 14..16),
    ];
    for (name, range) in cam_groups {
        let start = range.start;
        let got: Vec<f64> = range.clone().map(|k| cam_grad[k]).collect();
        let want: Vec<f64> = range
            .map(|k| {
                fd(
                    |x| {
                        let mut c = cam_words.clone();
                        c[k] = x;
                        loss(&words, &c, &w)
                    },
                    cam_words[k],
                )
            })
            .collect();
        FINITE_DIFFERENCES.check(name, &got, &want, None, |k| format!("slot {}", start + k));
    }
}

/// Gaussians spread over the image, dense enough that lists end at the T-stop; most pairs at
/// the footprints' edges fall below 1/255.
fn realistic_scene(cam: &splat_runtime::Camera, count: usize) -> Vec<Params> {
    spread_gaussians(cam, count, 12)
}

#[test]
fn gradients_match_the_reference_adjoint_on_a_realistic_scene() {
    let cam = camera(64, 48);
    gradients_match_reference_adjoint::<Method>(
        "3dgs",
        &realistic_scene(&cam, 1000),
        &cam,
        &GAUSSIAN_GROUPS,
        &CAMERA_GROUPS[..4],
        REFERENCE_ADJOINT,
    );
}

#[test]
fn a_gaussian_leaves_no_trace_where_it_is_invalid() {
    for tile_size in [8, 16] {
        let cam = camera(tile_size, tile_size);
        let params = realistic_scene(&cam, 40);
        let mut rng = fastrand::Rng::with_seed(3);
        let extra = gaussian_at(&mut rng, &cam, Vec2::new(5.0, 4.0), 2.5, -2.8);
        let valid = invalid_pairs_leave_no_trace::<Method>("3dgs", &params, extra, &cam, tile_size);
        println!("tile {tile_size}: the extra Gaussian is valid on {valid} pixels");
    }
}

#[test]
fn gpu_gradients_match_cpu_on_a_realistic_scene() {
    let cam = camera(64, 48);
    gpu_gradients_match_cpu::<Method>("3dgs realistic", &realistic_scene(&cam, 1000), &cam);
}

/// Alpha's cotangent is computed only for the groups it reaches: not for the colors (SH)
/// alone; for every geometry group and for the camera (through the projected mean).
#[test]
fn only_groups_alpha_reaches_need_its_cotangent() {
    use splat_runtime::GradientSet;
    let alone = |name| GradientSet::params::<Method>(&[name]).unwrap();
    assert!(!alone("sh").alpha_cotangent::<Method>());
    for name in ["mean", "log_scale", "rotation", "opacity_logit"] {
        assert!(alone(name).alpha_cotangent::<Method>(), "{name}");
    }
    let camera = GradientSet::params::<Method>(&[])
        .unwrap()
        .with_camera(true);
    assert!(camera.alpha_cotangent::<Method>());
}

/// Each gradient group of 3DGS alone (`mean`, `log_scale`, `rotation`, `opacity_logit`, `sh`),
/// the camera alone and everything but the camera: what they name as in the full pass, the
/// rest zero, on both backends.
#[test]
fn gradient_subsets_match_the_full_pass() {
    let cam = camera(32, 16);
    let params = realistic_scene(&cam, 200);
    splat_runtime::checks::gradients::gradient_subsets_match_the_full_pass::<Method>(
        "3dgs", &params, &cam,
    );
}
