//! Gradient checks: the backward pass against finite differences of the f64 reference (smooth
//! scenes), against the reference's analytic adjoint (realistic scenes), the no-trace property
//! of invalid pairs, and the GPU backward against the CPU's.

use super::adjoint::{self, ReferenceGrad};
use super::bound::Bound;
use super::reference::{Reference, render_words, render_words_edited};
use super::{camera_words, channels, frame_grad, options, weights, words};
use splat_core::flat::Flat;
use splat_core::method::{GradientSet, SplatMethod};
use splat_core::types::Camera;
use splat_cpu::{backward, render_for_backward};
use std::ops::Range;

/// Named word ranges: of `Params`, or of the camera's float slots.
type Groups<'a> = &'a [(&'a str, Range<usize>)];

/// The random linear loss of the checks: each output (color, alpha, depth) weighted by `w`.
fn linear_loss(r: &Reference, w: &[Vec<f64>; 3]) -> f64 {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    dot(&r.color, &w[0]) + dot(&r.alpha, &w[1]) + dot(&r.depth, &w[2])
}

fn central_difference(f: impl Fn(f64) -> f64, x: f64) -> f64 {
    let h = 1e-5 * x.abs().max(1.0);
    (f(x + h) - f(x - h)) / (2.0 * h)
}

/// Backward-pass gradients of a random linear loss on color, alpha and depth against central
/// differences of the reference render, per parameter group (word ranges of `Params`) and
/// camera group (ranges of the camera's float slots), each element within `bound`. The scene
/// must stay clear of the thresholds (the caller checks).
pub fn gradients_match_finite_differences<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    groups: Groups,
    camera_groups: Groups,
    bound: Bound,
) {
    let n = (cam.size.x * cam.size.y) as usize;
    let w = weights(n, channels::<M>());
    let (_, state) = render_for_backward::<M>(params, cam, &options(8)).unwrap();
    let g = backward::<M>(&state, params, cam, &frame_grad(&w)).unwrap();
    let groups = (groups, camera_groups);
    gradients_match_finite_differences_of::<M>(label, params, cam, &w, &g, groups, bound);
}

/// The hardware path's backward (`HardwareRenderer::backward`: f32 states, the adapter's
/// default reduction) against finite differences, as [`gradients_match_finite_differences`]
/// checks the CPU's. Returns whether it ran (not where the adapter lacks programmable
/// blending, unless `SPLAT_REQUIRE_RASTER_ORDER=1`).
#[cfg(feature = "gpu")]
pub fn hardware_gradients_match_finite_differences<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    groups: Groups,
    camera_groups: Groups,
    bound: Bound,
) -> bool {
    use splat_gpu::raster::{Blending, HardwareRenderer};
    let Some(gpu) = splat_gpu::programmable_blend::open_or_skip() else {
        return false;
    };
    let n = (cam.size.x * cam.size.y) as usize;
    let w = weights(n, channels::<M>());
    let scene = splat_gpu::GpuScene::<M>::new(&gpu, params).unwrap();
    let programmable = Blending::Programmable;
    let mut hw = HardwareRenderer::<M>::with_blending(&gpu, &options(8), programmable).unwrap();
    hw.forward(&scene, cam).unwrap();
    hw.backward(&scene, &frame_grad(&w)).unwrap();
    let g = hw.download_gradients().unwrap().gradients;
    let groups = (groups, camera_groups);
    gradients_match_finite_differences_of::<M>(label, params, cam, &w, &g, groups, bound);
    true
}

/// Gradients `g` of the linear loss of weights `w` against central differences of the
/// reference render, per parameter group, the shade data and camera group, each element
/// within `bound`.
fn gradients_match_finite_differences_of<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    w: &[Vec<f64>; 3],
    g: &splat_core::frame::Gradients<M>,
    (groups, camera_groups): (Groups, Groups),
    bound: Bound,
) {
    let ws: Vec<Vec<f64>> = params.iter().map(words).collect();
    let cw = camera_words(cam);
    let loss = |ps: &[Vec<f64>], c: &[f64]| linear_loss(&render_words::<M>(ps, c, cam.model), w);
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
        let width = range.len();
        bound.check(&format!("{label} {name}"), &got, &want, None, |k| {
            format!("primitive {} word {}", k / width, k % width)
        });
    }
    shade_gradient_matches_finite_differences::<M>(label, &ws, cam, w, &g.shade, bound);
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
        bound.check(&format!("{label} camera {name}"), &got, &want, None, |k| {
            format!("slot {}", range.start + k)
        });
    }
}

/// The gradient of the shade data (`project`'s output that the blend reads, and where density
/// control reads the screen position) against central differences of the reference with that
/// word moved after `project`, for methods whose shade words are all floats.
fn shade_gradient_matches_finite_differences<M: SplatMethod>(
    label: &str,
    params: &[Vec<f64>],
    cam: &Camera,
    weights: &[Vec<f64>; 3],
    got: &[f32],
    bound: Bound,
) {
    let words = <M::Shade as Flat>::LEN;
    if M::ShadeLanes::default().as_ref().len() != words {
        return;
    }
    let cw = camera_words(cam);
    let want: Vec<f64> = (0..params.len() * words)
        .map(|at| {
            let f = |delta: f64| {
                let edit = |i: usize, shade: &mut [f64]| {
                    if i == at / words {
                        shade[at % words] += delta;
                    }
                };
                linear_loss(
                    &render_words_edited::<M>(params, &cw, cam.model, edit),
                    weights,
                )
            };
            // A step far below the parameters' (1e-5): the blend is only piecewise smooth in
            // the shade data (LinPrim's chord is a min / max over slab ends, whose kinks pass
            // within 1e-5 of a row of its inverse Jacobian), and the sums are f64.
            let h = 1e-7;
            (f(h) - f(-h)) / (2.0 * h)
        })
        .collect();
    let got: Vec<f64> = got.iter().map(|g| *g as f64).collect();
    bound.check(&format!("{label} shade data"), &got, &want, None, |k| {
        format!("primitive {} word {}", k / words, k % words)
    });
}

/// Backward-pass gradients of a random linear loss on color, alpha and depth (tiles 8 and 16)
/// against the analytic adjoint of the f64 reference (on the f32 renderer's side of every
/// threshold), per parameter group and camera group, each element within `bound`. Made for
/// realistic scenes, where pairs fall
/// below the method's threshold at the footprints' edges and lists end at the T-stop; the
/// check fails if the scene has neither (returns the reference's counts of both).
pub fn gradients_match_reference_adjoint<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    groups: Groups,
    camera_groups: Groups,
    bound: Bound,
) -> ReferenceGrad {
    let n = (cam.size.x * cam.size.y) as usize;
    let w = weights(n, channels::<M>());
    let reference = adjoint::backward::<M>(params, cam, &w);
    assert!(
        reference.skipped_before_a_take > 0 && reference.stopped_pixels > 0,
        "{label}: the scene should skip pairs mid-list ({}) and stop pixels at the T-stop ({})",
        reference.skipped_before_a_take,
        reference.stopped_pixels
    );
    for tile_size in [8, 16] {
        let (_, state) = render_for_backward::<M>(params, cam, &options(tile_size)).unwrap();
        let g = backward::<M>(&state, params, cam, &frame_grad(&w)).unwrap();
        let got: Vec<Vec<f64>> = g.params.iter().map(words).collect();
        let label = format!("{label}, tile {tile_size}");
        let gross = Some(&reference.gross_params[..]);
        groups_match(&label, &got, &reference.params, gross, groups, bound);
        let got = camera_words(&g.camera);
        let gross = Some(&reference.gross_camera[..]);
        camera_matches(&label, &got, &reference.camera, gross, camera_groups, bound);
    }
    println!(
        "{label}: {} pairs skipped before a later take, {} pixels stopped at the T-stop",
        reference.skipped_before_a_take, reference.stopped_pixels
    );
    reference
}

/// Each parameter group of `got` (per primitive, its words) against `reference`, each element
/// within `bound` (given the magnitude of its terms `gross`, per primitive and word, where
/// known); prints every group's worst element and panics naming it past the bound. Returns
/// the worst element's fraction of the bound.
pub fn groups_match<N: AsRef<str>>(
    label: &str,
    got: &[Vec<f64>],
    reference: &[Vec<f64>],
    gross: Option<&[Vec<f64>]>,
    groups: &[(N, Range<usize>)],
    bound: Bound,
) -> f64 {
    let mut worst = 0.0f64;
    for (name, range) in groups {
        let pick = |ps: &[Vec<f64>]| -> Vec<f64> {
            ps.iter().flat_map(|p| p[range.clone()].to_vec()).collect()
        };
        let width = range.len();
        let fit = bound.check(
            &format!("{label}, {}", name.as_ref()),
            &pick(got),
            &pick(reference),
            gross.map(pick).as_deref(),
            |k| format!("primitive {} word {}", k / width, k % width),
        );
        worst = worst.max(fit.of_bound);
    }
    worst
}

/// Each camera group of `got` (float slots) against `reference`, each element within `bound`
/// (given the magnitude of its terms `gross` where known). Returns the worst element's
/// fraction of the bound.
pub fn camera_matches<N: AsRef<str>>(
    label: &str,
    got: &[f64],
    reference: &[f64],
    gross: Option<&[f64]>,
    groups: &[(N, Range<usize>)],
    bound: Bound,
) -> f64 {
    let mut worst = 0.0f64;
    for (name, range) in groups {
        let fit = bound.check(
            &format!("{label}, camera {}", name.as_ref()),
            &got[range.clone()],
            &reference[range.clone()],
            gross.map(|g| &g[range.clone()]),
            |k| format!("slot {}", range.start + k),
        );
        worst = worst.max(fit.of_bound);
    }
    worst
}

/// A primitive leaves no trace through the pixels where its pairs are invalid: with the loss
/// weighted only on those pixels, adding `extra` to `params` (as the last primitive) leaves
/// every other primitive's gradient and the camera's bit-identical, and gives `extra` none,
/// even where its valid pixels share a SIMD group with its invalid ones. The image must be a
/// single tile of `tile_size` (more tiles would be reduced in a list-length order the extra
/// primitive changes). Returns how many pixels it is valid on.
pub fn invalid_pairs_leave_no_trace<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    extra: M::Params,
    cam: &Camera,
    tile_size: u32,
) -> usize {
    assert!(
        cam.size.x as u32 <= tile_size && cam.size.y as u32 <= tile_size,
        "{label}: one tile"
    );
    let twin = &M::TWIN;
    let cw = camera_words(cam);
    let ints = [cam.model as u32];
    let (f, b) = (twin.project)(
        &words(&extra).iter().chain(&cw).copied().collect::<Vec<_>>(),
        &ints,
    );
    assert!(b[0] != 0, "{label}: the extra primitive is visible");
    let shade = &f[5 + <M::Cull as Flat>::LEN..];
    let (width, n) = (cam.size.x as usize, (cam.size.x * cam.size.y) as usize);
    let mut w = weights(n, channels::<M>());
    let mut valid_pixels = 0;
    for px in 0..n {
        let centre = [(px % width) as f64 + 0.5, (px / width) as f64 + 0.5];
        let pixel = match twin.pixel_info {
            Some(info) => {
                info(
                    &centre.iter().chain(&cw).copied().collect::<Vec<_>>(),
                    &ints,
                )
                .0
            }
            None => centre.to_vec(),
        };
        let input: Vec<f64> = pixel.iter().chain(shade).copied().collect();
        if (twin.evaluate)(&input, &[]).1[0] != 0 {
            valid_pixels += 1;
            w[0][px * channels::<M>()..(px + 1) * channels::<M>()].fill(0.0);
            w[1][px] = 0.0;
            w[2][px] = 0.0;
        }
    }
    assert!(
        valid_pixels > 0 && valid_pixels < n,
        "{label}: the extra primitive should be valid on some pixels, not all ({valid_pixels} of {n})"
    );
    let opts = options(tile_size);
    let gradients = |ps: &[M::Params]| {
        let (_, state) = render_for_backward::<M>(ps, cam, &opts).unwrap();
        backward::<M>(&state, ps, cam, &frame_grad(&w)).unwrap()
    };
    let without = gradients(params);
    let with_extra: Vec<M::Params> = params.iter().copied().chain([extra]).collect();
    let with = gradients(&with_extra);
    for (i, (a, b)) in without.params.iter().zip(&with.params).enumerate() {
        assert_eq!(
            words(a),
            words(b),
            "{label}: primitive {i}'s gradient changed"
        );
    }
    assert_eq!(
        camera_words(&without.camera),
        camera_words(&with.camera),
        "{label}: the camera's gradient changed"
    );
    assert!(
        words(&with.params[params.len()]).iter().all(|v| *v == 0.0),
        "{label}: the extra primitive got a gradient from pixels it does not reach"
    );
    valid_pixels
}

/// The GPU backward against the CPU's (the device's default accumulation, tiles 8 and 16), for
/// a random linear loss weighted only on the reference's clear pixels (a pair within rounding
/// of a threshold may be decided either way by the two backends), its depth only where that is
/// clear too ([`Reference::depth_clear`](super::reference::Reference::depth_clear): a faint
/// pixel's depth carries 1 - T's rounding many times over): each parameter group and
/// each camera field, element by element, within [`GPU_GRADIENTS`] ([`GPU_GRADIENTS_WIDE`] on
/// the wide camera models).
#[cfg(feature = "gpu")]
pub fn gpu_gradients_match_cpu<M: SplatMethod>(label: &str, params: &[M::Params], cam: &Camera) {
    gpu_gradients_match_cpu_with::<M>(label, params, cam, Default::default());
}

/// The GPU's gradients against the CPU's, the terms' magnitude from the f64 adjoint. Measured
/// over every check of the workspace on lavapipe (2026-12-06): 0.46 of the bound (3DGS's mean
/// on the fisheye); without the sum term the dense extremes scenes reached 14x.
pub const GPU_GRADIENTS: Bound = Bound::new(1e-4, 1e-5).with_sum(1e-6);

/// [`GPU_GRADIENTS`] on the wide camera models, whose projections call the inverse
/// trigonometric functions Vulkan lets be far less exact than the CPU's (atan2 to 4096 ulp).
/// Measured (lavapipe): GES on the fisheye, 2.0e-4 relative on a mean gradient (1.07 of
/// [`GPU_GRADIENTS`]), 0.36 of this bound.
pub const GPU_GRADIENTS_WIDE: Bound = Bound::new(3e-4, 3e-5).with_sum(1e-6);

/// Two runs of the same GPU backward pass whose atomics add in different orders: each element
/// within 1e-6 of its group's largest plus 4e-6 of the magnitude of its terms. The order, and
/// so the rounding, differs from run to run on a multithreaded device: on lavapipe a rotation
/// gradient of 2e-4 (group's largest 1.2) once came out 3e-8 apart, 3.7x what the terms alone
/// allow (the f64 adjoint's per-pixel `gross` does not see what cancels inside a pixel's walk),
/// and 0.03 of this bound; other runs 0.19 of the terms' share alone.
pub const ATOMIC_ORDER: Bound = Bound::new(0.0, 1e-6).with_sum(4e-6);

/// The CPU's gradients against central differences of the f64 reference (scenes clear of the
/// thresholds). Measured: 0.68 of the bound (3DGS's focal length on the fisheye, 7.5e-5
/// relative).
pub const FINITE_DIFFERENCES: Bound = Bound::new(1e-4, 1e-5);

/// The CPU's gradients against the f64 reference's analytic adjoint. Measured: 0.49 of the
/// bound (LinPrim's log scale, 4e-4 relative on a small element).
pub const REFERENCE_ADJOINT: Bound = Bound::new(1e-4, 1e-5).with_sum(1e-6);

/// [`gpu_gradients_match_cpu`] with the blend's thresholds `blend` on both backends.
#[cfg(feature = "gpu")]
pub fn gpu_gradients_match_cpu_with<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blend: splat_core::blend::Blend,
) {
    let bound = match cam.model {
        splat_core::CameraModel::Pinhole => GPU_GRADIENTS,
        _ => GPU_GRADIENTS_WIDE,
    };
    gpu_gradients_match_cpu_within::<M>(label, params, cam, blend, bound);
}

/// [`gpu_gradients_match_cpu_with`] within `bound`: for scenes whose f32 precision is known to
/// be coarser (the extremes', see [`super::extremes`]).
#[cfg(feature = "gpu")]
pub fn gpu_gradients_match_cpu_within<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blend: splat_core::blend::Blend,
    bound: Bound,
) {
    let Some(gpu) = splat_gpu::adapter_or_skip() else {
        return;
    };
    let reference = super::forward::clear_reference::<M>(label, params, cam, blend);
    let mut w = super::weights_on(&reference.clear, <M::Color as Flat>::LEN);
    reference.weigh_depth_where_clear(&mut w);
    let grad = frame_grad(&w);
    // The scale of each gradient's terms (the reference stops at the default T-stop and
    // takes every pair the method keeps: for other thresholds, an overestimate).
    let terms = adjoint::backward::<M>(params, cam, &w);
    let groups = splat_core::param_groups::<M>();
    for tile_size in [8, 16] {
        let opts = super::options_with(tile_size, blend);
        let (_, state) = render_for_backward::<M>(params, cam, &opts).unwrap();
        let (_, mut gstate) =
            splat_gpu::render::render_for_backward::<M>(&gpu, params, cam, &opts).unwrap();
        let want = backward::<M>(&state, params, cam, &grad).unwrap();
        let got = splat_gpu::render::backward(
            &mut gstate,
            &grad,
            splat_gpu::entries::Accumulation::default_for(&gpu),
        )
        .unwrap()
        .gradients;
        let at = format!("{label}, tile {tile_size}, GPU / CPU");
        let all = |ps: &[M::Params]| -> Vec<Vec<f64>> { ps.iter().map(words).collect() };
        let (got_params, want_params) = (all(&got.params), all(&want.params));
        let gross = Some(&terms.gross_params[..]);
        groups_match(&at, &got_params, &want_params, gross, &groups, bound);
        let (got, want) = (camera_words(&got.camera), camera_words(&want.camera));
        let gross = Some(&terms.gross_camera[..]);
        camera_matches(&at, &got, &want, gross, &super::CAMERA_GROUPS, bound);
    }
}

/// Each [`GradientSet`] computes what it names and nothing else: every parameter group alone,
/// the camera alone, and everything but the camera. The groups a set holds come out equal to
/// the full pass's, word for word (gating skips work, it does not reorder the arithmetic) and the others
/// are zero, on the CPU and, where there is an adapter, on the GPU. The GPU blend adds each
/// tile's sum with a float atomic in whatever order the tiles finish, so the image must have at
/// most two tiles: with one tree reduction per tile (not subgroups, whose atomics race within a
/// tile), every sum is `0 + a + b`, the same bits in either order. (With 12 tiles, identical
/// passes of 3DGS differ by ~1e-6 of the largest gradient.) The full pass must have a non-zero
/// gradient in every group (otherwise the scene does not test it).
pub fn gradient_subsets_match_the_full_pass<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
) {
    let n = (cam.size.x * cam.size.y) as usize;
    const TILE: u32 = 16;
    let tiles = splat_core::grid::TileGrid::new(cam.size.x as u32, cam.size.y as u32, TILE);
    assert!(
        tiles.tile_count() <= 2,
        "{label}: {} tiles of {TILE} px; at most two keep the GPU's sums independent of order",
        tiles.tile_count()
    );
    let grad = frame_grad(&weights(n, <M::Color as Flat>::LEN));
    let groups = splat_core::param_groups::<M>();
    let names: Vec<&str> = groups.iter().map(|(g, _)| *g).collect();
    let mut sets = vec![(
        "everything but the camera".to_string(),
        GradientSet::ALL.with_camera(false),
    )];
    sets.push((
        "the camera alone".into(),
        GradientSet::params::<M>(&[]).unwrap().with_camera(true),
    ));
    for name in &names {
        sets.push((
            format!("`{name}` alone"),
            GradientSet::params::<M>(&[name]).unwrap(),
        ));
    }
    let with = |wanted: GradientSet| splat_core::frame::RenderOptions {
        gradients: wanted,
        ..options(TILE)
    };
    let cpu = |wanted: GradientSet| {
        let opts = with(wanted);
        let (_, state) = render_for_backward::<M>(params, cam, &opts).unwrap();
        backward::<M>(&state, params, cam, &grad).unwrap()
    };
    let runs_of = |pass: &dyn Fn(GradientSet) -> splat_core::frame::Gradients<M>| {
        let full = pass(GradientSet::ALL);
        let subsets: Vec<_> = sets.iter().map(|(what, s)| (what, *s, pass(*s))).collect();
        (full, subsets)
    };
    #[cfg_attr(not(feature = "gpu"), allow(unused_mut))] // the GPU run is pushed
    let mut runs = vec![("CPU", runs_of(&cpu))];
    #[cfg(feature = "gpu")]
    if let Some(gpu) = splat_gpu::adapter_or_skip() {
        let gpu_run = |wanted: GradientSet| {
            let opts = with(wanted);
            let (_, mut state) =
                splat_gpu::render::render_for_backward::<M>(&gpu, params, cam, &opts).unwrap();
            use splat_gpu::entries::{Accumulation, Reduction};
            let acc = Accumulation {
                reduce: Reduction::Workgroup,
                ..Accumulation::default_for(&gpu)
            };
            splat_gpu::render::backward(&mut state, &grad, acc)
                .unwrap()
                .gradients
        };
        runs.push(("GPU", runs_of(&gpu_run)));
    }
    let group_words = |g: &splat_core::frame::Gradients<M>, k: usize| -> Vec<f64> {
        let range = groups[k].1.clone();
        g.params
            .iter()
            .flat_map(|p| words(p)[range.clone()].to_vec())
            .collect()
    };
    let largest = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (backend, (full, subsets)) in runs {
        let at = format!("{label} on the {backend}");
        for (k, name) in names.iter().enumerate() {
            assert!(
                largest(&group_words(&full, k)) > 0.0,
                "{at}: the full pass has no gradient for `{name}`: the scene does not test it"
            );
        }
        let full_camera = camera_words(&full.camera);
        assert!(
            largest(&full_camera) > 0.0,
            "{at}: the full pass should have a camera gradient"
        );
        // The first word unlike what the set should give: the full pass's word where it keeps
        // the group, zero where it does not (NaN is unlike anything).
        let unlike = |keep: bool, full: &[f64], got: &[f64]| {
            let want = |x: f64| if keep { x } else { 0.0 };
            (full.iter().zip(got))
                .find(|(x, y)| want(**x) != **y)
                .map(|(x, y)| format!("{y:e} where {:e} is due", want(*x)))
        };
        let verdict = |keep: bool| match keep {
            true => "not that of the full pass",
            false => "not zero",
        };
        for (what, wanted, got) in &subsets {
            for (k, name) in names.iter().enumerate() {
                let keep = wanted.param(k);
                if let Some(word) = unlike(keep, &group_words(&full, k), &group_words(got, k)) {
                    panic!("{at}, {what}: `{name}` is {}: {word}", verdict(keep));
                }
            }
            let keep = wanted.camera();
            if let Some(word) = unlike(keep, &full_camera, &camera_words(&got.camera)) {
                panic!(
                    "{at}, {what}: the camera gradient is {}: {word}",
                    verdict(keep)
                );
            }
        }
    }
}

/// The hardware path's backward (the programmable forward's draw replayed in fragment shaders,
/// `HardwareRenderer::backward_with`, its fragments' gradients summed in each way of
/// `reductions`) against
/// the tile path's on the same device, for every state format the adapter can draw into, for
/// the random linear loss of
/// [`gpu_gradients_match_cpu`] (on the reference's clear pixels; with unorm states, only on
/// pixels whose color stays within [0, 1], as a unorm state saturates): each parameter group
/// and camera field within `bound(precision)` (the terms' magnitude from the f64 adjoint).
/// Both stop each pixel at the default `t_min`. Returns, per format and reduction, the worst
/// group's fraction of the bound, the atomics the replay issued, and the largest error against
/// the f64 reference's gradients, as a fraction of its group's largest element (the tile
/// path's first, with no reduction, as [`Precision::F32`](splat_core::precision::Precision::F32)
/// with no atomics).
#[cfg(feature = "gpu")]
pub fn hardware_gradients_match_tiles<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    reductions: &[splat_gpu::entries::FragmentReduction],
    bound: impl Fn(splat_core::precision::Precision) -> Bound,
) -> Vec<HardwareFit> {
    use splat_core::precision::Precision;
    use splat_gpu::raster::{Blending, HardwareRenderer};
    use splat_gpu::{GpuRenderer, GpuScene};
    let Some(gpu) = splat_gpu::programmable_blend::open_or_skip() else {
        return vec![];
    };
    let blend = splat_core::blend::Blend::default();
    let reference = super::forward::clear_reference::<M>(label, params, cam, blend);
    let channels = <M::Color as Flat>::LEN;
    let mut clear = super::weights_on(&reference.clear, channels);
    reference.weigh_depth_where_clear(&mut clear);
    // Unorm states saturate: their loss leaves out pixels with a channel past 1.
    let mut within = clear.clone();
    let mut saturated = 0;
    for (p, color) in reference.color.chunks_exact(channels).enumerate() {
        if color.iter().any(|c| *c > 1.0) {
            within[0][p * channels..(p + 1) * channels].fill(0.0);
            (within[1][p], within[2][p]) = (0.0, 0.0);
            saturated += 1;
        }
    }
    println!("{label}: {saturated} pixels past 1 left out of the unorm states' loss");
    let groups = splat_core::param_groups::<M>();
    let opts = super::options_with(16, blend);
    let scene = GpuScene::<M>::new(&gpu, params).unwrap();
    let mut tiles = GpuRenderer::<M>::new(&gpu, &opts).unwrap();
    tiles.forward(&scene, cam).unwrap();
    let acc = splat_gpu::entries::Accumulation::default_for(&gpu);
    let all = |ps: &[M::Params]| -> Vec<Vec<f64>> { ps.iter().map(words).collect() };
    let mut out = vec![];
    for precision in Precision::ALL {
        let unorm = matches!(precision, Precision::Unorm16 | Precision::Unorm8);
        let w = if unorm { &within } else { &clear };
        let grad = frame_grad(w);
        let terms = adjoint::backward::<M>(params, cam, w);
        tiles.backward(&scene, &grad, acc).unwrap();
        let want = tiles.download_gradients().unwrap().gradients;
        let opts = splat_core::frame::RenderOptions { precision, ..opts };
        let programmable = Blending::Programmable;
        let mut hw = match HardwareRenderer::<M>::with_blending(&gpu, &opts, programmable) {
            Ok(hw) => hw,
            Err(e) => {
                println!("{label}, {precision:?}: no hardware path ({e})");
                continue;
            }
        };
        hw.forward(&scene, cam).unwrap();
        if out.is_empty() {
            let (want_params, want_camera) = (all(&want.params), camera_words(&want.camera));
            out.push(HardwareFit {
                precision: Precision::F32,
                reduce: None,
                of_bound: 0.0,
                atomics: 0,
                off_f64: off_f64(&want_params, &want_camera, &terms, &groups),
            });
        }
        let bound = bound(precision);
        for &reduce in reductions {
            hw.backward_with(&scene, &grad, reduce).unwrap();
            let got = hw.download_gradients().unwrap();
            let at = format!(
                "{label}, {}, {reduce:?} reduction, hardware / tiles",
                precision.name()
            );
            let (got_params, want_params) = (all(&got.gradients.params), all(&want.params));
            let gross = Some(&terms.gross_params[..]);
            let mut worst = groups_match(&at, &got_params, &want_params, gross, &groups, bound);
            let (got_camera, want_camera) = (
                camera_words(&got.gradients.camera),
                camera_words(&want.camera),
            );
            let gross = Some(&terms.gross_camera[..]);
            let cameras = &super::CAMERA_GROUPS;
            let camera = camera_matches(&at, &got_camera, &want_camera, gross, cameras, bound);
            worst = worst.max(camera);
            out.push(HardwareFit {
                precision,
                reduce: Some(reduce),
                of_bound: worst,
                atomics: got.atomics,
                off_f64: off_f64(&got_params, &got_camera, &terms, &groups),
            });
        }
    }
    out
}

/// One format and reduction's result in [`hardware_gradients_match_tiles`].
#[cfg(feature = "gpu")]
#[derive(Clone, Copy, Debug)]
pub struct HardwareFit {
    pub precision: splat_core::precision::Precision,
    /// How the fragments' gradients were summed; `None` for the tile path.
    pub reduce: Option<splat_gpu::entries::FragmentReduction>,
    /// The worst group's fraction of the bound against the tile path.
    pub of_bound: f64,
    /// Global atomic adds the replay issued.
    pub atomics: u64,
    /// The largest error against the f64 reference's gradient, as a fraction of its group's
    /// largest element (parameter groups and camera fields).
    pub off_f64: f64,
}

/// The largest |got - f64| over `reference`'s parameter groups and camera fields, each as a
/// fraction of its group's largest f64 element.
#[cfg(feature = "gpu")]
fn off_f64(params: &[Vec<f64>], camera: &[f64], reference: &ReferenceGrad, groups: Groups) -> f64 {
    let relative = Bound::new(0.0, 1.0);
    let mut worst = 0.0f64;
    for (_, range) in groups {
        let pick = |ps: &[Vec<f64>]| -> Vec<f64> {
            ps.iter().flat_map(|p| p[range.clone()].to_vec()).collect()
        };
        let fit = relative.fit(&pick(params), &pick(&reference.params), None);
        worst = worst.max(fit.of_bound);
    }
    for (_, range) in super::CAMERA_GROUPS {
        let fit = relative.fit(&camera[range.clone()], &reference.camera[range], None);
        worst = worst.max(fit.of_bound);
    }
    worst
}
