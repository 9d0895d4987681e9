//! Generalized exponential splats: CPU renders against an f64 brute-force reference built from
//! the method's twin, full-render gradients (β included) against central differences of that
//! reference, and the falloff itself (β = 2 is the Gaussian; a larger β is flatter inside and
//! sharper at the edge; the box holds every pixel the alpha threshold keeps), and the GPU
//! backend against the CPU backend.

use splat_examples::generalized::generalized::{self, Method, Params, Shade};
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::{
    Camera, Contribution, F32x8, Flat, FrameGrad, RenderOptions, backward, render,
    render_for_backward,
};

/// The blend stops before transmittance falls to this (the runtime's rule).
const T_MIN: f64 = 1e-4;

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

fn param_words(p: &Params) -> Vec<f64> {
    let mut w = vec![0.0f32; Params::LEN];
    p.write_words(&mut w);
    w.into_iter().map(f64::from).collect()
}

struct Reference {
    color: Vec<f64>,
    alpha: Vec<f64>,
}

/// Every visible primitive (parameter words) at every pixel in depth order, with the f64 twin
/// of `project` and `evaluate`: no tiles, boxes or tile culls; only the method's thresholds and
/// the blend's stopping rule.
fn reference(params: &[Vec<f64>], cam: &Camera) -> Reference {
    let cam_words = cam.float_slots().map(f64::from);
    let ints = [cam.model as u32];
    let mut prims = vec![];
    for p in params {
        let input: Vec<f64> = p.iter().chain(&cam_words).copied().collect();
        let (out, flags) = generalized::twin::project(input.as_slice().try_into().unwrap(), &ints);
        if flags[0] != 0 {
            // Outputs: depth, box (4), cull data, then the shade.
            prims.push((out[0], out[5 + generalized::Cull::LEN..].to_vec()));
        }
    }
    prims.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (w, h) = (cam.size.x as usize, cam.size.y as usize);
    let mut r = Reference {
        color: vec![0.0; w * h * 3],
        alpha: vec![0.0; w * h],
    };
    for y in 0..h {
        for x in 0..w {
            let mut t = 1.0f64;
            for (_, shade) in &prims {
                let input: Vec<f64> = [x as f64 + 0.5, y as f64 + 0.5]
                    .iter()
                    .chain(shade)
                    .copied()
                    .collect();
                let (o, valid) =
                    generalized::twin::evaluate(input.as_slice().try_into().unwrap(), &[]);
                if valid[0] == 0 {
                    continue;
                }
                let next = t * (1.0 - o[0]);
                if next <= T_MIN {
                    break;
                }
                for ch in 0..3 {
                    r.color[(y * w + x) * 3 + ch] += o[0] * t * o[1 + ch];
                }
                t = next;
            }
            r.alpha[y * w + x] = 1.0 - t;
        }
    }
    r
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

#[test]
fn renders_match_an_f64_reference() {
    let (cam, params) = scene();
    let opts = RenderOptions {
        tile_size: 8,
        alpha: true,
        ..Default::default()
    };
    let frame = render::<Method>(&params, &cam, &opts).unwrap();
    let want = reference(&params.iter().map(param_words).collect::<Vec<_>>(), &cam);
    let got_alpha = &frame.alpha.as_ref().unwrap().data;
    let (mut worst, mut worst_rel) = (0.0f64, 0.0f64);
    for (got, want) in frame
        .color
        .data
        .iter()
        .chain(got_alpha)
        .zip(want.color.iter().chain(&want.alpha))
    {
        let err = (*got as f64 - want).abs();
        assert!(err <= 1e-4 + 0.01 * want.abs(), "{got} vs {want}");
        worst = worst.max(err);
        worst_rel = worst_rel.max(err / want.abs().max(1e-3));
    }
    let covered = want.alpha.iter().filter(|a| **a > 0.1).count();
    println!(
        "forward: worst abs error {worst:.2e} (relative {worst_rel:.2e}), {covered} of {} pixels covered, {} tile intersections",
        want.alpha.len(),
        frame.stats.intersections
    );
    assert!(
        covered > want.alpha.len() / 3,
        "the scene should cover the image"
    );
}

#[test]
fn the_gpu_renders_what_the_cpu_renders() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    let (cam, params) = scene();
    for tile_size in [8, 16] {
        let opts = RenderOptions {
            tile_size,
            alpha: true,
            ..Default::default()
        };
        let cpu = render::<Method>(&params, &cam, &opts).unwrap();
        let g = splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &opts).unwrap();
        assert_eq!(cpu.stats.intersections, g.stats.intersections);
        let cpu_alpha = &cpu.alpha.as_ref().unwrap().data;
        let gpu_alpha = &g.alpha.as_ref().unwrap().data;
        for (a, b) in cpu
            .color
            .data
            .iter()
            .chain(cpu_alpha)
            .zip(g.color.data.iter().chain(gpu_alpha))
        {
            assert!(
                (a - b).abs() <= 1e-4 + 0.01 * a.abs(),
                "tile {tile_size}: cpu {a} gpu {b}"
            );
        }
    }
}

/// max |a - b| / max |b| over a group of gradients.
fn group_error(got: &[f64], want: &[f64]) -> f64 {
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    got.iter()
        .zip(want)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
        / scale
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
    let words: Vec<Vec<f64>> = params.iter().map(param_words).collect();

    // Clear of the thresholds: every splat above 1/255 at every pixel, transmittance high.
    assert!(reference(&words, &cam).alpha.iter().all(|a| *a < 0.99));
    for p in &words {
        let solo = reference(std::slice::from_ref(p), &cam);
        let min_alpha = solo.alpha.iter().fold(1.0f64, |m, a| m.min(*a));
        assert!(
            min_alpha > 2.0 / 255.0,
            "each splat covers the image (min alpha {min_alpha})"
        );
    }

    let n = (cam.size.x * cam.size.y) as usize;
    let mut wr = fastrand::Rng::with_seed(10);
    let mut random = |k: usize| (0..k).map(|_| wr.f64() * 2.0 - 1.0).collect::<Vec<f64>>();
    let (w_color, w_alpha) = (random(n * 3), random(n));
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let loss = |ws: &[Vec<f64>]| {
        let r = reference(ws, &cam);
        dot(&r.color, &w_color) + dot(&r.alpha, &w_alpha)
    };

    let opts = RenderOptions {
        tile_size: 8,
        alpha: true,
        ..Default::default()
    };
    let (_, state) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
    let f32s = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<f32>>();
    let grad = FrameGrad {
        color: f32s(&w_color),
        alpha: Some(f32s(&w_alpha)),
        depth: None,
    };
    let g = backward::<Method>(&state, &params, &cam, &grad).unwrap();

    // Word ranges of Params.
    let groups = [
        ("mean", 0..3),
        ("log_scale", 3..6),
        ("rotation", 6..10),
        ("opacity", 10..11),
        ("shape", 11..12),
        ("sh", 12..24),
    ];
    assert_eq!(Params::LEN, 24);
    for (name, range) in groups {
        let (mut got, mut want) = (vec![], vec![]);
        for (i, p) in g.params.iter().enumerate() {
            let gw = param_words(p);
            for k in range.clone() {
                let x = words[i][k];
                let h = 1e-5 * x.abs().max(1.0);
                let at = |v: f64| {
                    let mut ws = words.clone();
                    ws[i][k] = v;
                    loss(&ws)
                };
                got.push(gw[k]);
                want.push((at(x + h) - at(x - h)) / (2.0 * h));
            }
        }
        let err = group_error(&got, &want);
        println!("gradient {name}: max error {err:.2e} of the largest gradient");
        assert!(err <= 1e-4, "{name}: {got:?} vs {want:?}");
    }
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
