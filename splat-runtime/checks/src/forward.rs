//! Forward checks: the CPU render against the f64 reference, boxes that hold every pixel a
//! primitive reaches, a conservative `tile_cull`, and the GPU render against the CPU's.

use super::bound::Bound;
use super::reference::{Reference, render_with, render_words};
use super::{camera_words, options, options_with, words};
use splat_core::blend::Blend;
use splat_core::frame::{Frame, Image, RenderOptions};
use splat_core::method::SplatMethod;
use splat_core::types::Camera;
use splat_cpu::render;

/// Bounds on an image: on color and alpha, and on the expected depth (divided by alpha, so a
/// faint pixel's depth carries its sums' rounding many times over).
#[derive(Clone, Copy, Debug)]
pub struct ImageBound {
    pub values: Bound,
    pub depth: Bound,
}

/// The CPU's render against the f64 reference. Measured over every check of the workspace
/// (2026-12-06): values 0.82 of the bound (LinPrim's color, 9e-5 relative on a faint value),
/// depth 0.37 (3DGEER, zero quaternions).
pub const REFERENCE_IMAGE: ImageBound = ImageBound {
    values: Bound::new(1e-5, 2e-6),
    depth: Bound::new(1e-5, 1e-5),
};

/// The GPU's render against the CPU's on a pinhole camera. Measured (lavapipe): values 0.27
/// of the bound (LinPrim), depth 0.63 (3DGS with vanishing opacities).
pub const GPU_IMAGE: ImageBound = ImageBound {
    values: Bound::new(1e-5, 4e-6),
    depth: Bound::new(1e-5, 1e-5),
};

/// The GPU's render against the CPU's on the wide camera models, whose projections call the
/// inverse trigonometric functions Vulkan lets be far less exact than the CPU's libm (atan2
/// to 4096 ulp). Measured (lavapipe): values 3.8e-5 relative (GES, equiangular), 0.32 of
/// this bound and 2.1 of the pinhole one; depth 0.72 (3DGS, fisheye).
pub const GPU_IMAGE_WIDE: ImageBound = ImageBound {
    values: Bound::new(1e-4, 1e-5),
    depth: Bound::new(1e-5, 1e-5),
};

/// The most pixels of a check's scene that may sit near a threshold (not clear, see
/// [`Reference::clear`](super::reference::Reference)): a scene where more do tests little.
pub const MOST_UNCLEAR: f64 = 0.02;

/// CPU renders (tiles 8 and 16) against the reference on its clear pixels, per output within
/// [`REFERENCE_IMAGE`]; returns the mean alpha (how much the scene covers).
pub fn forward_matches_reference<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
) -> f64 {
    forward_matches_reference_with::<M>(label, params, cam, Blend::default())
}

/// [`forward_matches_reference`] with the blend's thresholds `blend` on both sides.
pub fn forward_matches_reference_with<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blend: Blend,
) -> f64 {
    forward_matches_reference_within::<M>(label, params, cam, blend, REFERENCE_IMAGE)
}

/// [`forward_matches_reference_with`] within `bound`, for a method whose f32 arithmetic is
/// known to lose more than the bound measured on ours (say how much, and why, where used).
pub fn forward_matches_reference_within<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blend: Blend,
    bound: ImageBound,
) -> f64 {
    let reference = clear_reference::<M>(label, params, cam, blend);
    for tile_size in [8, 16] {
        let frame = render::<M>(params, cam, &options_with(tile_size, blend)).expect("render");
        let at = format!("{label}, tile {tile_size}");
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
        let mut worst = 0.0f64;
        for (what, got, want) in outputs {
            let got: Vec<f64> = got.iter().map(|v| *v as f64).collect();
            worst = worst.max(output_matches(
                &at,
                what,
                &got,
                want,
                &reference.clear,
                bound,
            ));
        }
        println!(
            "{at}: {} visible, {} intersections; worst error {worst:.3} of the bound",
            frame.stats.visible, frame.stats.intersections
        );
    }
    reference.alpha.iter().sum::<f64>() / reference.alpha.len() as f64
}

/// The f64 reference with `blend`, refusing a scene with more than [`MOST_UNCLEAR`] of its
/// pixels near a threshold.
pub fn clear_reference<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blend: Blend,
) -> Reference {
    let reference = render_with::<M>(params, cam, blend);
    let (unclear, n) = (reference.unclear(), reference.clear.len());
    assert!(
        unclear as f64 <= MOST_UNCLEAR * n as f64,
        "{label}: {unclear} of {n} pixels near a threshold"
    );
    reference
}

/// One output (H x W x channels, row-major) against its reference on the clear pixels, within
/// `bound`'s depth bound for `what == "depth"`, its value bound otherwise; returns the worst
/// fraction of the bound.
pub fn output_matches(
    at: &str,
    what: &str,
    got: &[f64],
    want: &[f64],
    clear: &[bool],
    bound: ImageBound,
) -> f64 {
    assert_eq!(got.len(), want.len(), "{at}: {what} sizes");
    let channels = got.len() / clear.len().max(1);
    let keep = |i: &usize| clear[i / channels];
    let pick = |v: &[f64]| -> Vec<f64> { (0..v.len()).filter(keep).map(|i| v[i]).collect() };
    let indices: Vec<usize> = (0..got.len()).filter(keep).collect();
    let bound = if what == "depth" {
        bound.depth
    } else {
        bound.values
    };
    let fit = bound.check(
        &format!("{at}, {what}"),
        &pick(got),
        &pick(want),
        None,
        |k| {
            let i = indices[k];
            format!("pixel {} channel {}", i / channels, i % channels)
        },
    );
    fit.of_bound
}

/// Every output of `got` (color, alpha, depth, as far as `want` has them) against `want`'s on
/// the pixels `clear` marks, within `bound`; returns the worst fraction of the bound.
pub fn frames_match(
    label: &str,
    want: &Frame,
    got: &Frame,
    clear: &[bool],
    bound: ImageBound,
) -> f64 {
    let mut worst = 0.0f64;
    for (what, w, g) in outputs_of(label, want, got) {
        let f64s = |v: &[f32]| v.iter().map(|x| *x as f64).collect::<Vec<f64>>();
        worst = worst.max(output_matches(
            label,
            what,
            &f64s(&g.data),
            &f64s(&w.data),
            clear,
            bound,
        ));
    }
    worst
}

/// Every pixel outside a primitive's box gets alpha below `alpha_min` from it (the reference,
/// one primitive at a time): the box, however approximate its construction, cuts nothing off.
/// Returns how many (primitive, pixel) pairs were checked outside the boxes.
pub fn boxes_hold_every_contributing_pixel<M: SplatMethod>(
    label: &str,
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
        let solo = render_words::<M>(&[words(p)], &camera_words(cam), cam.model);
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
        let label = format!("{label}, tile {tile_size}, with the cull / without");
        let worst = outputs_close(&label, &all, &culled, 1e-6, 0.0) * 1e-6;
        let (with, without) = (culled.stats.intersections, all.stats.intersections);
        println!(
            "{label}, tile {tile_size}: {with} intersections with the cull, {without} without; largest difference {worst:e}"
        );
        counts.push((with, without));
    }
    counts
}

/// The GPU backend's forward against the CPU backend's on the reference's clear pixels, within
/// [`GPU_IMAGE`] ([`GPU_IMAGE_WIDE`] on the wide camera models), with equal intersection
/// counts (tiles 8 and 16).
#[cfg(feature = "gpu")]
pub fn gpu_forward_matches_cpu<M: SplatMethod>(label: &str, params: &[M::Params], cam: &Camera) {
    gpu_forward_matches_cpu_with::<M>(label, params, cam, Blend::default());
}

/// [`gpu_forward_matches_cpu`] with the blend's thresholds `blend` on both backends.
#[cfg(feature = "gpu")]
pub fn gpu_forward_matches_cpu_with<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blend: Blend,
) {
    let bound = match cam.model {
        splat_core::CameraModel::Pinhole => GPU_IMAGE,
        _ => GPU_IMAGE_WIDE,
    };
    gpu_forward_matches_cpu_within::<M>(label, params, cam, blend, bound);
}

/// [`gpu_forward_matches_cpu_with`] within `bound`.
#[cfg(feature = "gpu")]
pub fn gpu_forward_matches_cpu_within<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blend: Blend,
    bound: ImageBound,
) {
    let Some(gpu) = splat_gpu::adapter_or_skip() else {
        return;
    };
    let clear = clear_reference::<M>(label, params, cam, blend).clear;
    for tile_size in [8, 16] {
        let opts = options_with(tile_size, blend);
        let cpu = render::<M>(params, cam, &opts).unwrap();
        let frame = splat_gpu::render::render::<M>(&gpu, params, cam, &opts).unwrap();
        assert_eq!(
            cpu.stats.intersections, frame.stats.intersections,
            "{label}"
        );
        let at = format!("{label}, tile {tile_size}, cpu / gpu");
        let worst = frames_match(&at, &cpu, &frame, &clear, bound);
        println!("{at}: GPU forward worst {worst:.3} of the bound");
    }
}

/// The outputs `want` has (color, alpha, depth), each beside `got`'s, which must have them.
fn outputs_of<'a>(
    label: &str,
    want: &'a Frame,
    got: &'a Frame,
) -> Vec<(&'static str, &'a Image, &'a Image)> {
    let pairs = [
        ("color", Some(&want.color), Some(&got.color)),
        ("alpha", want.alpha.as_ref(), got.alpha.as_ref()),
        ("depth", want.depth.as_ref(), got.depth.as_ref()),
    ];
    pairs
        .into_iter()
        .filter_map(|(what, w, g)| {
            let missing = || panic!("{label}: {what} is missing");
            w.map(|w| (what, w, g.unwrap_or_else(missing)))
        })
        .collect()
}

/// Asserts that every output of `got` (color, alpha, depth, as far as `want` has them) is
/// within `abs + rel * |want|` of `want`'s, naming the output and element that is not; returns
/// the worst difference as a fraction of its bound.
pub fn outputs_close(label: &str, want: &Frame, got: &Frame, abs: f32, rel: f32) -> f32 {
    let mut worst = 0.0f32;
    for (what, w, g) in outputs_of(label, want, got) {
        assert_eq!(w.data.len(), g.data.len(), "{label}: {what} sizes");
        for (i, (a, b)) in w.data.iter().zip(&g.data).enumerate() {
            let bound = abs + rel * a.abs();
            worst = worst.max((a - b).abs() / bound);
            assert!((a - b).abs() <= bound, "{label}, {what}[{i}]: {a} / {b}");
        }
    }
    worst
}

/// The hardware-rasterized forward pass against the tile-based one on the GPU (both without
/// the transmittance stop, which fixed-function blending cannot make), for every precision
/// the adapter can blend into. Each blend rounds the stored color and alpha to the format, so
/// a pixel under n boxes may drift 2n rounding steps u (f32 2^-24, f16 2^-11 of values in
/// [0, 1], unorm half a step) from the tile path's f32, plus 1e-5; the depth sums (f16 in the
/// narrow formats) by 2n u times the farthest depth. Unorm formats are compared with the tile
/// path's values saturated to [0, 1]. Returns each format with its worst error as a fraction
/// of the bound, and asserts the frame holds one key per visible primitive (no tile pass).
/// With `Blending::Programmable` the fragments blend themselves (a device from
/// `programmable_blend::open_or_skip`), into every format, and both paths stop each pixel at
/// the default `t_min`.
#[cfg(feature = "gpu")]
pub fn hardware_forward_matches_tiles<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    blending: splat_gpu::raster::Blending,
) -> Vec<(splat_core::precision::Precision, f32)> {
    use splat_core::precision::Precision;
    use splat_gpu::raster::{Blending, HardwareRenderer, supports};
    use splat_gpu::{GpuRenderer, GpuScene};
    let gpu = match blending {
        Blending::FixedFunction => splat_gpu::adapter_or_skip(),
        Blending::Programmable => splat_gpu::programmable_blend::open_or_skip(),
    };
    let Some(gpu) = gpu else {
        return vec![];
    };
    let rule = match blending {
        Blending::FixedFunction => Blend {
            t_min: 0.0,
            ..Blend::default()
        },
        Blending::Programmable => Blend::default(),
    };
    let opts = options_with(16, rule);
    let scene = GpuScene::<M>::new(&gpu, params).unwrap();
    let mut tiles = GpuRenderer::<M>::new(&gpu, &opts).unwrap();
    tiles.forward(&scene, cam).unwrap();
    let want = tiles.download_frame().unwrap();
    let layers = layers::<M>(params, cam);
    let far = params
        .iter()
        .map(|p| M::project(p, cam))
        .filter(|p| p.visible)
        .map(|p| p.depth)
        .fold(0.0f32, f32::max);
    let mut out = vec![];
    for precision in Precision::ALL {
        if blending == Blending::FixedFunction && !supports(&gpu, precision) {
            println!("{label}: this adapter cannot blend into {precision:?} targets");
            continue;
        }
        let opts = RenderOptions { precision, ..opts };
        let mut hw = HardwareRenderer::<M>::with_blending(&gpu, &opts, blending).unwrap();
        let info = hw.forward(&scene, cam).unwrap();
        assert_eq!(
            info.intersections, want.stats.visible,
            "{label}: one key per visible primitive"
        );
        // The primitives' depth sort (key, index, scratch) and a key and index per visible one:
        // no scratch, as a single tile takes no tile pass.
        let n = scene.len();
        assert_eq!(hw.sort_bytes(), 16 * n + 8 * want.stats.visible, "{label}");
        let got = hw.download_frame().unwrap();
        let (u, depth_u) = match precision {
            Precision::F32 => (2f32.powi(-24), 2f32.powi(-24)),
            Precision::F16 => (2f32.powi(-11), 2f32.powi(-11)),
            p => (p.unit_error(), 2f32.powi(-11)),
        };
        let unorm = matches!(precision, Precision::Unorm16 | Precision::Unorm8);
        let alpha = |f: &Frame, i| f.alpha.as_ref().unwrap().data[i];
        let mut worst = 0.0f32;
        let mut check = |what: &str, i: usize, a: f32, b: f32, bound: f32| {
            worst = worst.max((a - b).abs() / bound);
            assert!(
                (a - b).abs() <= bound,
                "{label}, {precision:?}, {what}[{i}]: tiles {a}, hardware {b}, bound {bound}"
            );
        };
        let channels = want.color.channels;
        for (i, n) in layers.iter().enumerate() {
            let n = *n as f32;
            let bound = 2.0 * n * u + 1e-5;
            for c in 0..channels {
                let k = i * channels + c;
                let w = want.color.data[k];
                check(
                    "color",
                    k,
                    if unorm { w.clamp(0.0, 1.0) } else { w },
                    got.color.data[k],
                    bound,
                );
            }
            check("alpha", i, alpha(&want, i), alpha(&got, i), bound);
            // The depth sums: depth times alpha.
            let sum = |f: &Frame| f.depth.as_ref().unwrap().data[i] * alpha(f, i);
            check(
                "depth sum",
                i,
                sum(&want),
                sum(&got),
                2.0 * n * depth_u * far + 1e-4 * far.max(1.0),
            );
        }
        println!(
            "{label}, {precision:?}: hardware forward worst {worst:.3} of the bound; sort {} keys (tiles {})",
            info.intersections, want.stats.intersections
        );
        out.push((precision, worst));
    }
    out
}

/// Per pixel, how many primitives' boxes hold its centre (the fragments blended there).
#[cfg(feature = "gpu")]
fn layers<M: SplatMethod>(params: &[M::Params], cam: &Camera) -> Vec<u32> {
    let (w, h) = (cam.size.x as usize, cam.size.y as usize);
    let mut n = vec![0u32; w * h];
    for p in params
        .iter()
        .map(|p| M::project(p, cam))
        .filter(|p| p.visible)
    {
        let (lo, hi) = (p.bbox_min, p.bbox_max);
        for y in 0..h {
            for x in 0..w {
                let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
                if cx >= lo.x && cx <= hi.x && cy >= lo.y && cy <= hi.y {
                    n[y * w + x] += 1;
                }
            }
        }
    }
    n
}
