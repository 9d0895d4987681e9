//! The per-pixel values in each storage format (f16, unorm16, unorm8) against f32, on the CPU
//! and on the GPU's tile path: the colors within the format's rounding step (unorm saturating
//! at 1 instead of wrapping); the transmittance and depth sums, which the backward pass walks
//! back from, f16 in every reduced format (a unorm step near 0 would lose a pixel's
//! gradients); the bytes held shrinking accordingly; and the backward pass within f16's
//! rounding of f32's, however the colors are stored. Then the shade data between the
//! preprocess and the blend (each value within its format's step, 2 or 1 bytes each, and
//! both passes reading exactly what is stored), and the gradient sums held in f16.

use crate::common::{camera, gaussian_at};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::checks::bound::Bound;
use splat_runtime::checks::forward::outputs_close;
use splat_runtime::checks::gradients::{GPU_GRADIENTS, groups_match};
use splat_runtime::checks::{adjoint, words};
use splat_runtime::glam::{Vec2, Vec3};
use splat_runtime::precision::Precision;
use splat_runtime::{
    Camera, Frame, FrameGrad, RenderOptions, backward, param_groups, render_for_backward,
};

/// 400 Gaussians over a 48 x 40 image; with `bright`, some push the color past 1.
fn scene(bright: bool) -> (splat_runtime::Camera, Vec<Params>) {
    let mut rng = fastrand::Rng::with_seed(8);
    let cam = camera(48, 40);
    let params = (0..400)
        .map(|i| {
            let px = Vec2::new(rng.f32() * 56.0 - 4.0, rng.f32() * 48.0 - 4.0);
            let z = 2.0 + rng.f32() * 4.0;
            let mut g = gaussian_at(&mut rng, &cam, px, z, -2.0);
            if bright && i % 10 == 0 {
                g.sh[0] = Vec3::splat(4.0);
            }
            g
        })
        .collect();
    (cam, params)
}

/// Color, alpha and depth, stored at `precision`.
fn all_outputs(precision: Precision) -> RenderOptions {
    RenderOptions {
        alpha: true,
        depth: true,
        precision,
        ..RenderOptions::default()
    }
}

/// A fixed random linear loss on color and alpha.
fn loss_gradient(pixels: usize) -> FrameGrad {
    let mut rng = fastrand::Rng::with_seed(2);
    FrameGrad {
        color: (0..pixels * 3).map(|_| rng.f32() - 0.5).collect(),
        alpha: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
        depth: None,
    }
}

/// `grad` with every output gradient times `factor` (a training loss's scale).
fn scaled(grad: &FrameGrad, factor: f32) -> FrameGrad {
    let times = |g: &[f32]| g.iter().map(|v| v * factor).collect::<Vec<_>>();
    FrameGrad {
        color: times(&grad.color),
        alpha: grad.alpha.as_deref().map(times),
        depth: grad.depth.as_deref().map(times),
    }
}

fn flat(ps: &[Params]) -> Vec<f64> {
    ps.iter().flat_map(words).collect()
}

fn all(ps: &[Params]) -> Vec<Vec<f64>> {
    ps.iter().map(words).collect()
}

/// Per Gaussian and word, the magnitude of the terms its gradient adds up (from the f64
/// adjoint): what rounding the sums, or the state the terms are computed from, is relative to.
fn gross(params: &[Params], cam: &Camera, grad: &FrameGrad) -> Vec<Vec<f64>> {
    adjoint::backward_for::<Method>(params, cam, grad).gross_params
}

/// Every element of every parameter group of `got` within `bound` of `want`'s, given the
/// magnitude of its terms `gross`.
fn gradients_match(at: &str, got: &[Params], want: &[Params], gross: &[Vec<f64>], bound: Bound) {
    words_match(at, &all(got), &all(want), gross, bound);
}

fn words_match(at: &str, got: &[Vec<f64>], want: &[Vec<f64>], gross: &[Vec<f64>], bound: Bound) {
    let groups = param_groups::<Method>();
    groups_match(at, got, want, Some(gross), &groups, bound);
}

/// Within `steps` f16 roundings (2^-11) of each term.
fn f16_roundings(steps: f64) -> Bound {
    Bound::new(0.0, 0.0).with_sum(steps * 2f64.powi(-11))
}

/// `frame`'s color and alpha stored at `precision` against `full`'s f32 values: f16 rounds
/// within 2^-11 of the value (its unit roundoff; subnormals within 2^-25); unorm colors
/// saturate to [0, 1] and round within half a step; alpha is 1 - T with T in f16.
fn assert_within_step(precision: Precision, frame: &Frame, full: &Frame) {
    let half = |v: f32| 2f32.powi(-11) * v.abs() + 3e-8;
    let unorm = precision != Precision::F16;
    for (got, f32_value) in frame.color.data.iter().zip(&full.color.data) {
        let (stored, step) = match unorm {
            true => (f32_value.clamp(0.0, 1.0), precision.unit_error()),
            false => (*f32_value, half(*f32_value)),
        };
        assert!(
            (got - stored).abs() <= step,
            "{precision:?}: {got} for {f32_value}"
        );
    }
    let alpha = frame.alpha.as_ref().unwrap().data.iter();
    for (got, f32_value) in alpha.zip(&full.alpha.as_ref().unwrap().data) {
        assert!(
            (got - f32_value).abs() <= half(1.0 - f32_value),
            "{precision:?}: alpha {got} for {f32_value}"
        );
    }
}

/// Gradients within this many f16 unit roundoffs (2^-11) of the magnitude of their terms off
/// f32's (measured: 0.47 of it, CPU and GPU): a rounding of T scales every term of its pixel by
/// as much.
const F16_STEPS: f64 = 1.0;

/// f16 gradient sums added by atomics, in any order and as many adds as pixels: measured 9
/// roundings of the terms (lavapipe).
const ATOMIC_F16_ROUNDINGS: f64 = 32.0;

/// Colors past 1 saturate in the unorm formats; the backward pass does not read them.
#[test]
fn each_format_rounds_the_outputs_within_its_step_and_holds_fewer_bytes() {
    for bright in [false, true] {
        check_formats(bright);
    }
}

fn check_formats(bright: bool) {
    let (cam, params) = scene(bright);
    let opts = all_outputs;
    let (full, full_state) =
        render_for_backward::<Method>(&params, &cam, &opts(Precision::F32)).unwrap();
    let brighter = full.color.data.iter().filter(|c| **c > 1.0).count();
    assert_eq!(brighter > 50, bright, "{brighter} color values past 1");
    let pixels = full.color.data.len() / 3;
    let grad = loss_gradient(pixels);
    let want = backward::<Method>(&full_state, &params, &cam, &grad).unwrap();
    let terms = gross(&params, &cam, &grad);
    for precision in [Precision::F16, Precision::Unorm16, Precision::Unorm8] {
        let (frame, state) =
            render_for_backward::<Method>(&params, &cam, &opts(precision)).unwrap();
        assert_within_step(precision, &frame, &full);
        // T and the depth sums as f16 (the color is not kept for the backward pass).
        let n = pixels as isize;
        assert_eq!(
            full_state.bytes() as isize - state.bytes() as isize,
            (4 - 2) * 2 * n,
            "{precision:?}"
        );
        let got = backward::<Method>(&state, &params, &cam, &grad).unwrap();
        let at = format!("{precision:?}, bright {bright}, off f32's");
        let bound = f16_roundings(F16_STEPS);
        gradients_match(&at, &got.params, &want.params, &terms, bound);
    }
}

/// The GPU's tile path stores the same formats in packed words (`gpu::state`): its outputs
/// against its own f32 frame within the format's step, its per-pixel buffer smaller, and its
/// backward pass, which walks back from the packed state, within the CPU's bound.
#[test]
fn the_gpu_stores_each_format_within_its_step_in_fewer_bytes() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::gpu::entries::Accumulation;
    use splat_runtime::gpu::render::{backward, render_for_backward};
    let acc = Accumulation::default_for(&gpu);
    // A frame without the depth output keeps no depth sum, backward pass or not.
    let shallow = splat_runtime::gpu::GpuRenderer::<Method>::new(&gpu, &RenderOptions::default());
    assert_eq!(shallow.unwrap().state_layout().words(), 5);
    for bright in [false, true] {
        let (cam, params) = scene(bright);
        let opts = all_outputs;
        let (full, mut full_state) =
            render_for_backward::<Method>(&gpu, &params, &cam, &opts(Precision::F32)).unwrap();
        let grad = loss_gradient(full.color.data.len() / 3);
        let want = backward(&mut full_state, &grad, acc).unwrap().gradients;
        let terms = gross(&params, &cam, &grad);
        let f32_bytes = full_state.renderer.pixel_state().size();
        for precision in [Precision::F16, Precision::Unorm16, Precision::Unorm8] {
            let (frame, mut state) =
                render_for_backward::<Method>(&gpu, &params, &cam, &opts(precision)).unwrap();
            assert_within_step(precision, &frame, &full);
            // 6 words per pixel in f32 (colors, T, depth, the walk's end); 4, 4 and 3 packed.
            let words = state.renderer.state_layout().words() as u64;
            assert_eq!(state.renderer.pixel_state().size(), f32_bytes * words / 6);
            let got = backward(&mut state, &grad, acc).unwrap().gradients;
            let at = format!("GPU {precision:?}, bright {bright}, off f32's");
            let bound = f16_roundings(F16_STEPS);
            gradients_match(&at, &got.params, &want.params, &terms, bound);
        }
    }
}

/// The shade data each format stores: every value within its step of `project`'s (f16: 2^-11
/// of the value, 2^-25 below its normal range; unorm: half a step of the range the word spans over the frame), in 2 or 1
/// bytes per float; and the blend and the backward pass read exactly what is stored: both
/// equal, bit for bit, those of a frame whose `project` had returned the decoded values.
#[test]
fn shade_data_in_each_format_is_what_both_passes_read_in_fewer_bytes() {
    use splat_runtime::pipeline::shade::shade_tile;
    let (cam, params) = scene(false);
    let full = all_outputs(Precision::F32);
    let (reference, _) = render_for_backward::<Method>(&params, &cam, &full).unwrap();
    let grad = loss_gradient(reference.color.data.len() / 3);
    let flat_gross = gross(&params, &cam, &grad).concat();
    for precision in [Precision::F16, Precision::Unorm16, Precision::Unorm8] {
        let opts = RenderOptions {
            shade_precision: precision,
            ..full
        };
        let (frame, mut state) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
        let packed = state
            .pre
            .packed
            .take()
            .expect("reduced shade data is packed");
        // 3DGS's shade data: 9 floats (center, conic, opacity, color), plus a range per word.
        let width = if precision == Precision::Unorm8 { 1 } else { 2 };
        assert_eq!(
            packed.bytes(),
            params.len() * 9 * width + 9 * 8,
            "{precision:?}"
        );
        let mut worst = 0.0f32;
        for (i, p) in state
            .pre
            .projected
            .iter()
            .enumerate()
            .filter(|(_, p)| p.visible)
        {
            let (mut was, mut is) = ([0.0; 9], [0.0; 9]);
            splat_runtime::Flat::write_words(&p.shade, &mut was);
            splat_runtime::Flat::write_words(&packed.get::<splat_methods::gs3d::Shade>(i), &mut is);
            for w in 0..9 {
                let step = match precision {
                    // Relative, down to f16's subnormals (absolute steps of 2^-24).
                    Precision::F16 => (2f32.powi(-11) * was[w].abs()).max(2f32.powi(-25)),
                    // Half a step, plus f32's rounding of the value's place in its range
                    // (2^-24 of 65535 steps: 0.004 of one).
                    _ => packed.step(w) * 0.51,
                };
                let err = (is[w] - was[w]).abs();
                worst = worst.max(err / step);
                assert!(err <= step, "{precision:?} word {w}: {is:?} for {was:?}");
            }
        }
        println!("{precision:?} shade data: worst error {worst:.2} of its step");
        let packed_grads = {
            state.pre.packed = Some(packed);
            let tiles: Vec<_> = (0..state.grid.tile_count() as u32)
                .map(|t| {
                    let list = state.visited(t as usize);
                    shade_tile(&state.grid, &cam, t, list, &state.pre, true, state.blend)
                })
                .collect();
            let grads = backward::<Method>(&state, &params, &cam, &grad).unwrap();
            (tiles, grads.params)
        };
        // The same frame with the decoded values as `project`'s output and nothing packed.
        let packed = state.pre.packed.take().unwrap();
        for (i, p) in state.pre.projected.iter_mut().enumerate() {
            p.shade = packed.get(i);
        }
        for (t, packed_tile) in packed_grads.0.iter().enumerate() {
            let list = state.visited(t);
            let plain = shade_tile(
                &state.grid,
                &cam,
                t as u32,
                list,
                &state.pre,
                true,
                state.blend,
            );
            assert_eq!(plain.color, packed_tile.color, "{precision:?} tile {t}");
            assert_eq!(plain.transmittance, packed_tile.transmittance);
        }
        let plain = backward::<Method>(&state, &params, &cam, &grad).unwrap();
        assert_eq!(flat(&plain.params), flat(&packed_grads.1), "{precision:?}");
        let off = f16_roundings(1.0).fit(
            &flat(&packed_grads.1),
            &flat(&backward_f32(&params, &cam, &grad)),
            Some(&flat_gross),
        );
        println!(
            "{precision:?} shade data: image PSNR {:.1} dB, gradients up to {:.1} f16 roundings of their terms off f32's",
            psnr(&frame.color.data, &reference.color.data),
            off.of_bound
        );
    }
}

fn backward_f32(params: &[Params], cam: &Camera, grad: &FrameGrad) -> Vec<Params> {
    let opts = all_outputs(Precision::F32);
    let (_, state) = render_for_backward::<Method>(params, cam, &opts).unwrap();
    backward::<Method>(&state, params, cam, grad)
        .unwrap()
        .params
}

fn psnr(got: &[f32], want: &[f32]) -> f64 {
    let mse = got
        .iter()
        .zip(want)
        .map(|(a, b)| ((a - b) as f64).powi(2))
        .sum::<f64>();
    10.0 * (got.len() as f64 / mse).log10()
}

/// Gradient sums held in f16: every add rounds the sum (2^-11 of it), once per tile a
/// primitive covers, then once more when the workers' sums are added, so the gradients stay
/// within that many f16 steps of f32's; the accumulators really are half the size; at a
/// training loss's scale (per-pixel gradients 2^-20 of these) the sums are scaled back up
/// (loss scaling): the gradients are exactly 2^-20 of these, none lost among f16's
/// subnormals; a unorm format, which needs a range sums do not have, is refused.
#[test]
fn gradient_sums_in_f16_stay_within_their_rounding_at_any_loss_scale_and_unorm_is_refused() {
    let (cam, params) = scene(false);
    let grad = loss_gradient(48 * 40);
    let want = backward_f32(&params, &cam, &grad);
    let terms = gross(&params, &cam, &grad);
    let opts = RenderOptions {
        gradient_precision: Precision::F16,
        ..all_outputs(Precision::F32)
    };
    let (_, state) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
    let got = backward::<Method>(&state, &params, &cam, &grad).unwrap();
    // A 48 x 40 frame has 3 x 3 tiles of 16: at most 9 adds, then the workers' sum.
    let roundings = 9 + 1;
    assert_ne!(flat(&got.params), flat(&want), "the sums were not rounded");
    let bound = f16_roundings(roundings as f64);
    gradients_match("f16 gradient sums", &got.params, &want, &terms, bound);

    let tiny = 2f32.powi(-20);
    let small = scaled(&grad, tiny);
    let got_small = backward::<Method>(&state, &params, &cam, &small).unwrap();
    let times_tiny: Vec<f64> = flat(&got.params).iter().map(|v| v * tiny as f64).collect();
    assert_eq!(flat(&got_small.params), times_tiny);

    let acc = splat_runtime::pipeline::backward::Accum::new(1000, 9, Precision::F16, 1.0);
    assert_eq!(acc.shade.bytes(), 1000 * 9 * 2);
    for unorm in [Precision::Unorm16, Precision::Unorm8] {
        let opts = RenderOptions {
            gradient_precision: unorm,
            ..RenderOptions::default()
        };
        let Err(e) = render_for_backward::<Method>(&params, &cam, &opts) else {
            panic!("{unorm:?} gradient sums accepted");
        };
        assert!(e.to_string().contains("no fixed range"), "{e}");
    }
}

/// The unorm ranges span the primitives the blend can read: one that `project` keeps but
/// whose box misses the image (its centre 5,000 pixels away) does not widen them.
#[test]
fn unorm_shade_ranges_span_only_what_the_blend_reads() {
    let (cam, mut params) = scene(false);
    let mut rng = fastrand::Rng::with_seed(3);
    params.push(gaussian_at(
        &mut rng,
        &cam,
        Vec2::new(5000.0, 20.0),
        3.0,
        -2.0,
    ));
    let opts = RenderOptions {
        shade_precision: Precision::Unorm16,
        ..RenderOptions::default()
    };
    let (_, state) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
    assert!(state.pre.projected.last().unwrap().visible);
    let packed = state.pre.packed.as_ref().unwrap();
    // The centre's x spans the 48-pixel image and the boxes' overhang (the scene's centres
    // lie within 4 pixels of it): 56 pixels at most.
    let span = packed.step(0) * 65535.0;
    assert!(span <= 56.0, "{span}");
}

/// The GPU packs the shade data as the CPU does (`gpu::shade_pack`): every value of a
/// primitive a blend can read decodes to the CPU's or to its neighbour in the format (the
/// GPU's `project` differs from the CPU's in the last bits, which may round a value near a
/// half step the other way; so may a GPU's division), in 5 or 3 words
/// instead of 9; and both of its passes read it: its image and gradients match the CPU's at
/// the same format as closely as at f32, while they differ from its own f32 frame's.
#[test]
fn the_gpu_packs_shade_data_as_the_cpu_does_and_both_passes_read_it() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::gpu::entries::Accumulation;
    use splat_runtime::gpu::render;
    let acc = Accumulation::default_for(&gpu);
    let (cam, params) = scene(false);
    let grad = loss_gradient(48 * 40);
    let terms = gross(&params, &cam, &grad);
    // The GPU's gradients against the CPU's at the same format, within the GPU's bound at
    // f32; the largest difference of their images.
    let compare = |precision: Precision| {
        let opts = RenderOptions {
            shade_precision: precision,
            ..all_outputs(Precision::F32)
        };
        let (cpu, cpu_state) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
        let (gpu_frame, mut gpu_state) =
            render::render_for_backward::<Method>(&gpu, &params, &cam, &opts).unwrap();
        let cpu_grads = backward::<Method>(&cpu_state, &params, &cam, &grad).unwrap();
        let gpu_grads = render::backward(&mut gpu_state, &grad, acc)
            .unwrap()
            .gradients;
        let at = format!("{precision:?} shade data, GPU / CPU");
        gradients_match(
            &at,
            &gpu_grads.params,
            &cpu_grads.params,
            &terms,
            GPU_GRADIENTS,
        );
        let image = max_difference(&gpu_frame.color.data, &cpu.color.data);
        (cpu_state, gpu_state, gpu_frame, image)
    };
    let (_, _, gpu_f32, f32_off_cpu) = compare(Precision::F32);
    println!("f32 shade data: GPU image off the CPU's by {f32_off_cpu:.2e}");
    for precision in [Precision::F16, Precision::Unorm16, Precision::Unorm8] {
        let (cpu_state, gpu_state, gpu_frame, off_cpu) = compare(precision);
        let packing = gpu_state.renderer.shade_packing().unwrap().clone();
        let words = if precision == Precision::Unorm8 { 3 } else { 5 };
        assert_eq!(packing.words(), words, "{precision:?}");
        let decoded = gpu_state.renderer.download_shade_data().unwrap().unwrap();
        let cpu_packed = cpu_state.pre.packed.as_ref().unwrap();
        let mut moved = 0;
        for (i, _) in &cpu_state.pre.visible {
            let i = *i as usize;
            let mut want = [0.0; 9];
            let shade = cpu_packed.get::<splat_methods::gs3d::Shade>(i);
            splat_runtime::Flat::write_words(&shade, &mut want);
            for (w, (got, want)) in decoded[i * 9..(i + 1) * 9].iter().zip(want).enumerate() {
                let step = match precision {
                    Precision::F16 => (2f32.powi(-10) * want.abs()).max(2f32.powi(-24)),
                    // A step, and a few f32 roundings of the value (the range's ends come
                    // from the GPU's `project` too).
                    _ => cpu_packed.step(w) + 2f32.powi(-20) * want.abs(),
                };
                let err = (got - want).abs();
                assert!(
                    err <= step,
                    "{precision:?} primitive {i} word {w}: {got} for {want}"
                );
                moved += (err > step / 2.0) as usize;
            }
        }
        let values = cpu_state.pre.visible.len() * 9;
        let off_f32 = max_difference(&gpu_frame.color.data, &gpu_f32.color.data);
        println!(
            "{precision:?} shade data: {moved} of {values} GPU values a step off the CPU's; GPU image off the CPU's by {off_cpu:.2e}, off its f32 frame by {off_f32:.2e}"
        );
        // Most values round alike (0.4% moved in unorm16 on lavapipe, fewer in f16 and unorm8).
        assert!(moved * 50 <= values, "{precision:?}: {moved} of {values}");
        // The format changes the image past the bound that the two backends stay within.
        assert!(off_f32 > 1e-4, "{precision:?}: {off_f32}");
        assert!(off_cpu <= 1e-4, "{precision:?}: {off_cpu}");
    }
}

fn max_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max)
}

/// The GPU holds gradient sums in f16 as the CPU does (`gpu::sums`): with the workgroup
/// reduction every primitive's sum is rounded once per tile it covers (9 here), so the
/// gradients stay within that many f16 steps of f32's; at a training loss's scale (output
/// gradients 2^-20 of these) the loss scale keeps them so; the sums take half the bytes; and
/// a unorm format is refused.
#[test]
fn the_gpu_holds_gradient_sums_in_f16_within_their_rounding_at_any_loss_scale() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::gpu::entries::{Accumulation, Reduction};
    use splat_runtime::gpu::render;
    let (cam, params) = scene(false);
    let grad = loss_gradient(48 * 40);
    let tiles = Accumulation {
        reduce: Reduction::Workgroup,
        float_atomics: false,
    };
    let full = all_outputs(Precision::F32);
    let (_, mut f32_state) =
        render::render_for_backward::<Method>(&gpu, &params, &cam, &full).unwrap();
    let want = render::backward(&mut f32_state, &grad, tiles)
        .unwrap()
        .gradients
        .params;
    let terms = gross(&params, &cam, &grad);
    let f32_bytes = f32_state.renderer.gradient_sum_bytes();
    let opts = RenderOptions {
        gradient_precision: Precision::F16,
        ..full
    };
    let (_, mut state) = render::render_for_backward::<Method>(&gpu, &params, &cam, &opts).unwrap();
    let tiny = 2f32.powi(-20);
    let small = scaled(&grad, tiny);
    let roundings = 9;
    for (name, grad, acc, unscale) in [
        ("workgroup reduction", &grad, tiles, 1.0),
        (
            "workgroup reduction, gradients 2^-20",
            &small,
            tiles,
            1.0 / tiny as f64,
        ),
        (
            "default accumulation",
            &grad,
            Accumulation::default_for(&gpu),
            1.0,
        ),
    ] {
        let got = render::backward(&mut state, grad, acc).unwrap().gradients;
        let unscaled = |p: &Params| words(p).iter().map(|v| v * unscale).collect::<Vec<_>>();
        let got: Vec<Vec<f64>> = got.params.iter().map(unscaled).collect();
        assert_ne!(got, all(&want), "{name}: the sums were not rounded");
        // Atomics add in any order, each add rounding to f16: only the tile reduction's
        // count of roundings is known.
        let bound = match acc == tiles {
            true => f16_roundings(roundings as f64),
            false => f16_roundings(ATOMIC_F16_ROUNDINGS),
        };
        let at = format!("GPU f16 gradient sums, {name}");
        words_match(&at, &got, &all(&want), &terms, bound);
    }
    assert_eq!(2 * state.renderer.gradient_sum_bytes(), f32_bytes);
    assert_eq!(f32_bytes, params.len() * 10 * 4);
    assert!(state.renderer.shade_gradients().is_none());
    let unorm = RenderOptions {
        gradient_precision: Precision::Unorm8,
        ..full
    };
    let Err(e) = render::render_for_backward::<Method>(&gpu, &params, &cam, &unorm) else {
        panic!("unorm8 gradient sums accepted");
    };
    assert!(e.to_string().contains("no fixed range"), "{e}");
}

/// The hardware-rasterized path refuses reduced shade data (its fragments read `project`'s),
/// naming it.
#[test]
fn the_hardware_path_refuses_reduced_shade_data() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    let shade = RenderOptions {
        shade_precision: Precision::F16,
        ..RenderOptions::default()
    };
    let Err(e) = splat_runtime::gpu::HardwareRenderer::<Method>::new(&gpu, &shade) else {
        panic!("the hardware path accepted f16 shade data");
    };
    assert!(e.to_string().contains("shade data at f32"), "{e}");
}

/// Every built-in method's shade data packed on the GPU (their layouts: 3DGS-AA's 10 words,
/// LinPrim's, 3DGUT's and 3DGEER's 16-word ray frames on a fisheye): the GPU's frame matches
/// the CPU's at the same format, within the bound the two backends keep at f32.
#[test]
fn every_method_renders_packed_shade_data_on_the_gpu_as_on_the_cpu() {
    use crate::common::{as_method, spread_gaussians, wide_camera};
    use splat_methods::{geer, gs3d_aa, gut, linprim};
    use splat_runtime::CameraModel;
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    fn check<M: splat_runtime::SplatMethod>(
        gpu: &splat_runtime::gpu::Gpu,
        name: &str,
        params: &[M::Params],
        cam: &splat_runtime::Camera,
    ) {
        let full = all_outputs(Precision::F32);
        let f32_image = splat_runtime::render::<M>(params, cam, &full)
            .unwrap()
            .color
            .data;
        for precision in [Precision::F16, Precision::Unorm8] {
            let opts = RenderOptions {
                shade_precision: precision,
                ..full
            };
            let cpu = splat_runtime::render::<M>(params, cam, &opts).unwrap();
            let on_gpu = splat_runtime::gpu::render::render::<M>(gpu, params, cam, &opts).unwrap();
            let label = format!("{name}, shade data {precision:?}, cpu / gpu");
            let worst = outputs_close(&label, &cpu, &on_gpu, 1e-4, 0.01);
            let moved = max_difference(&cpu.color.data, &f32_image);
            println!(
                "{label}: worst difference {worst:.3} of the bound; f32's image {moved:.1e} away"
            );
            if precision == Precision::Unorm8 {
                assert!(
                    moved > 1e-3,
                    "{label}: unorm8 left the image as f32's ({moved})"
                );
            }
        }
    }
    let cam = wide_camera(48, 40, CameraModel::Pinhole);
    let params = spread_gaussians(&cam, 200, 11);
    check::<gs3d_aa::Method>(&gpu, "3dgs-aa", &as_method(params.clone()), &cam);
    check::<linprim::Method>(&gpu, "linprim", &as_method(params), &cam);
    let fisheye = wide_camera(48, 40, CameraModel::KannalaBrandt);
    let params = spread_gaussians(&fisheye, 200, 12);
    check::<gut::Method>(&gpu, "3dgut", &as_method(params.clone()), &fisheye);
    check::<geer::Method>(&gpu, "3dgeer", &as_method(params), &fisheye);
}
