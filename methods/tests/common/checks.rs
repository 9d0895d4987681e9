//! The checks every method gets, written once over `SplatMethod`: the CPU render against the
//! f64 brute-force reference, render gradients against its finite differences, and the GPU
//! backend against the CPU backend.

use super::{Twin, camera_words, group_error, render_with, words};
use splat_runtime::gpu::entries::Accumulation;
use splat_runtime::{
    Camera, Flat, FrameGrad, RenderOptions, SplatMethod, backward, render, render_for_backward,
};
use std::ops::Range;

fn options(tile_size: u32) -> RenderOptions {
    RenderOptions {
        tile_size,
        alpha: true,
        depth: true,
        ..Default::default()
    }
}

/// CPU renders (tiles 8 and 16) within 1e-5 absolute + 1% relative of the reference, per
/// element of color, alpha and depth; returns the mean alpha (how much the scene covers).
pub fn forward_matches_reference<M: SplatMethod>(
    label: &str,
    twin: &Twin,
    params: &[M::Params],
    cam: &Camera,
) -> f64 {
    let ws: Vec<Vec<f64>> = params.iter().map(words).collect();
    let reference = render_with(twin, &ws, &camera_words(cam), cam.model);
    for tile_size in [8, 16] {
        let frame = render::<M>(params, cam, &options(tile_size)).expect("render");
        let mut worst = 0.0f64;
        let outputs = [
            ("color", &frame.color.data, &reference.color),
            (
                "alpha",
                &frame.alpha.as_ref().unwrap().data,
                &reference.alpha,
            ),
            (
                "depth",
                &frame.depth.as_ref().unwrap().data,
                &reference.depth,
            ),
        ];
        for (what, got, want) in outputs {
            assert_eq!(got.len(), want.len());
            for (i, (g, w)) in got.iter().zip(want.iter()).enumerate() {
                let err = (*g as f64 - w).abs();
                let bound = 1e-5 + 0.01 * w.abs();
                worst = worst.max(err / bound);
                assert!(
                    err <= bound,
                    "{label}, tile {tile_size}, {what}[{i}] (pixel {}): {g} vs reference {w}",
                    if what == "color" {
                        i / twin.channels
                    } else {
                        i
                    }
                );
            }
        }
        println!(
            "{label}, tile {tile_size}: {} visible, {} intersections; worst error {worst:.3} of the bound",
            frame.stats.visible, frame.stats.intersections
        );
    }
    reference.alpha.iter().sum::<f64>() / reference.alpha.len() as f64
}

/// Every pixel outside a primitive's box gets alpha below `alpha_min` from it (the reference,
/// one primitive at a time): the box, however approximate its construction, cuts nothing off.
/// Returns how many (primitive, pixel) pairs were checked outside the boxes.
pub fn boxes_hold_every_contributing_pixel<M: SplatMethod>(
    label: &str,
    twin: &Twin,
    params: &[M::Params],
    cam: &Camera,
    alpha_min: f64,
) -> usize {
    let (w, h) = (cam.size.x as usize, cam.size.y as usize);
    let mut outside = 0;
    for (i, p) in params.iter().enumerate() {
        let projected = M::project(p, cam);
        if !projected.visible {
            continue;
        }
        let solo = render_with(twin, &[words(p)], &camera_words(cam), cam.model);
        let (lo, hi) = (projected.bbox_min, projected.bbox_max);
        for y in 0..h {
            for x in 0..w {
                let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
                if cx >= lo.x && cx <= hi.x && cy >= lo.y && cy <= hi.y {
                    continue;
                }
                outside += 1;
                let a = solo.alpha[y * w + x];
                assert!(
                    a < alpha_min,
                    "{label}: primitive {i} reaches alpha {a} at ({cx}, {cy}), outside its box {lo} .. {hi}"
                );
            }
        }
    }
    outside
}

/// Rendering with and without the method's `tile_cull` (tiles 8 and 16) gives the same color,
/// alpha and depth within 1e-6: the cull drops only pairs the alpha threshold would skip.
/// Returns the intersection counts (with the cull, without) per tile size.
pub fn tile_cull_is_conservative<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
) -> Vec<(usize, usize)> {
    let mut counts = vec![];
    for tile_size in [8, 16] {
        let opts = |tile_cull| RenderOptions {
            tile_cull,
            ..options(tile_size)
        };
        let culled = render::<M>(params, cam, &opts(true)).unwrap();
        let all = render::<M>(params, cam, &opts(false)).unwrap();
        let outputs = [
            ("color", &culled.color.data, &all.color.data),
            (
                "alpha",
                &culled.alpha.as_ref().unwrap().data,
                &all.alpha.as_ref().unwrap().data,
            ),
            (
                "depth",
                &culled.depth.as_ref().unwrap().data,
                &all.depth.as_ref().unwrap().data,
            ),
        ];
        let mut worst = 0.0f32;
        for (what, a, b) in outputs {
            for (i, (x, y)) in a.iter().zip(b.iter()).enumerate() {
                worst = worst.max((x - y).abs());
                assert!(
                    (x - y).abs() <= 1e-6,
                    "{label}, tile {tile_size}, {what}[{i}]: {x} with the cull, {y} without"
                );
            }
        }
        let (with, without) = (culled.stats.intersections, all.stats.intersections);
        println!(
            "{label}, tile {tile_size}: {with} intersections with the cull, {without} without; largest difference {worst:e}"
        );
        counts.push((with, without));
    }
    counts
}

/// Random loss weights on color, alpha and depth for a `width x height` frame.
fn weights(n: usize, channels: usize) -> [Vec<f64>; 3] {
    let mut rng = fastrand::Rng::with_seed(10);
    let mut random = |k: usize| (0..k).map(|_| rng.f64() * 2.0 - 1.0).collect::<Vec<f64>>();
    [random(n * channels), random(n), random(n)]
}

fn frame_grad(w: &[Vec<f64>; 3]) -> FrameGrad {
    let f32s = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<f32>>();
    FrameGrad {
        color: f32s(&w[0]),
        alpha: Some(f32s(&w[1])),
        depth: Some(f32s(&w[2])),
    }
}

fn central_difference(f: impl Fn(f64) -> f64, x: f64) -> f64 {
    let h = 1e-5 * x.abs().max(1.0);
    (f(x + h) - f(x - h)) / (2.0 * h)
}

/// Backward-pass gradients of a random linear loss on color, alpha and depth against central
/// differences of the reference render, per parameter group (word ranges of `Params`) and
/// camera group (ranges of the camera's float slots): within `tol` of each group's largest
/// gradient. The scene must stay clear of the thresholds (the caller checks).
pub fn gradients_match_finite_differences<M: SplatMethod>(
    label: &str,
    twin: &Twin,
    params: &[M::Params],
    cam: &Camera,
    groups: &[(&str, Range<usize>)],
    camera_groups: &[(&str, Range<usize>)],
    tol: f64,
) {
    let ws: Vec<Vec<f64>> = params.iter().map(words).collect();
    let cw = camera_words(cam);
    let n = (cam.size.x * cam.size.y) as usize;
    let w = weights(n, twin.channels);
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let loss = |ps: &[Vec<f64>], c: &[f64]| {
        let r = render_with(twin, ps, c, cam.model);
        dot(&r.color, &w[0]) + dot(&r.alpha, &w[1]) + dot(&r.depth, &w[2])
    };
    let (_, state) = render_for_backward::<M>(params, cam, &options(8)).unwrap();
    let g = backward::<M>(&state, params, cam, &frame_grad(&w)).unwrap();
    for (name, range) in groups {
        let (mut got, mut want) = (vec![], vec![]);
        for (i, p) in g.params.iter().enumerate() {
            let gw = words(p);
            for k in range.clone() {
                got.push(gw[k]);
                let f = |x| {
                    let mut ps = ws.clone();
                    ps[i][k] = x;
                    loss(&ps, &cw)
                };
                want.push(central_difference(f, ws[i][k]));
            }
        }
        let err = group_error(&got, &want);
        println!("{label} {name}: max error {err:.2e} of the largest gradient");
        assert!(err <= tol, "{label} {name}: {got:?} vs {want:?}");
    }
    let cam_grad = camera_words(&g.camera);
    for (name, range) in camera_groups {
        let got: Vec<f64> = range.clone().map(|k| cam_grad[k]).collect();
        let want: Vec<f64> = range
            .clone()
            .map(|k| {
                let f = |x| {
                    let mut c = cw.clone();
                    c[k] = x;
                    loss(&ws, &c)
                };
                central_difference(f, cw[k])
            })
            .collect();
        let err = group_error(&got, &want);
        println!("{label} camera {name}: max error {err:.2e} of the largest gradient");
        assert!(err <= tol, "{label} camera {name}: {got:?} vs {want:?}");
    }
}

/// The GPU backend's forward against the CPU backend's: color, alpha and depth within
/// 1e-4 + 1% per element, equal intersection counts (tiles 8 and 16).
pub fn gpu_forward_matches_cpu<M: SplatMethod>(label: &str, params: &[M::Params], cam: &Camera) {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    for tile_size in [8, 16] {
        let opts = options(tile_size);
        let cpu = render::<M>(params, cam, &opts).unwrap();
        let frame = splat_runtime::gpu::render::render::<M>(&gpu, params, cam, &opts).unwrap();
        assert_eq!(
            cpu.stats.intersections, frame.stats.intersections,
            "{label}"
        );
        let mut worst = 0.0f32;
        let outputs = [
            ("color", &cpu.color.data, &frame.color.data),
            (
                "alpha",
                &cpu.alpha.as_ref().unwrap().data,
                &frame.alpha.as_ref().unwrap().data,
            ),
            (
                "depth",
                &cpu.depth.as_ref().unwrap().data,
                &frame.depth.as_ref().unwrap().data,
            ),
        ];
        for (what, c, g) in outputs {
            for (i, (a, b)) in c.iter().zip(g.iter()).enumerate() {
                let bound = 1e-4 + 0.01 * a.abs();
                worst = worst.max((a - b).abs() / bound);
                assert!(
                    (a - b).abs() <= bound,
                    "{label}, tile {tile_size}, {what}[{i}]: cpu {a} gpu {b}"
                );
            }
        }
        println!("{label}, tile {tile_size}: GPU forward worst {worst:.3} of the bound");
    }
}

/// The GPU backward against the CPU backward (the device's default accumulation, tiles 8 and
/// 16): every parameter word and the camera within 1e-3 of the largest gradient. Use a scene
/// clear of the thresholds: a pair at the 1/255 cutoff flips with 1-ulp differences of `exp`.
pub fn gpu_gradients_match_cpu<M: SplatMethod>(label: &str, params: &[M::Params], cam: &Camera) {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    let n = (cam.size.x * cam.size.y) as usize;
    let grad = frame_grad(&weights(n, <M::Color as Flat>::LEN));
    for tile_size in [8, 16] {
        let opts = options(tile_size);
        let (_, state) = render_for_backward::<M>(params, cam, &opts).unwrap();
        let (_, gstate) =
            splat_runtime::gpu::render::render_for_backward::<M>(&gpu, params, cam, &opts).unwrap();
        let want = backward::<M>(&state, params, cam, &grad).unwrap();
        let got = splat_runtime::gpu::backward::backward(
            &gpu,
            &gstate,
            &grad,
            Accumulation::default_for(&gpu),
        )
        .unwrap();
        let flat = |ps: &[M::Params]| -> Vec<f64> { ps.iter().flat_map(words).collect() };
        let err = group_error(&flat(&got.gradients.params), &flat(&want.params));
        let cam_err = group_error(
            &camera_words(&got.gradients.camera),
            &camera_words(&want.camera),
        );
        println!(
            "{label}, tile {tile_size}: GPU gradients {err:.2e}, camera {cam_err:.2e} of the largest"
        );
        assert!(
            err <= 1e-3 && cam_err <= 1e-3,
            "{label}, tile {tile_size}: gradients {err}, camera {cam_err}"
        );
    }
}
