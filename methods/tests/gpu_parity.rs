//! The same 3DGS source on the GPU backend (the full wgpu pipeline: project, count / emit with
//! tile_cull, radix sort, tile ranges, binning, per-tile shading; backward blend and project's
//! adjoint) against the CPU backend, for tile sizes 8 and 16:
//! - forward color, alpha and depth within 1e-4 absolute + 1% relative per element;
//! - gradients of every parameter group and camera field, element by element within
//!   `GPU_GRADIENTS`, for each way of accumulating them (workgroup reduction or not, f32
//!   atomics or a compare-exchange loop).
//!
//! The resident renderer (one renderer and scene across changing frames) equals the one-shot
//! path frame by frame; shaders compiled with naga's run-time checks equal those without.
//!
//! Needs a wgpu adapter (lavapipe is enough); with `SPLAT_REQUIRE_GPU=1` a missing adapter
//! fails the test, otherwise it skips.

use crate::common::{camera, gaussian_at, spread_gaussians};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::checks::adjoint::backward_for;
use splat_runtime::checks::forward::outputs_close;
use splat_runtime::checks::gradients::{ATOMIC_ORDER, GPU_GRADIENTS, camera_matches, groups_match};
use splat_runtime::checks::{CAMERA_GROUPS, camera_words, words};
use splat_runtime::glam::Vec2;
use splat_runtime::gpu::entries::{Accumulation, Reduction};
use splat_runtime::gpu::{Gpu, GpuRenderer, GpuScene, adapter_or_skip};
use splat_runtime::types::Camera;
use splat_runtime::{
    FrameGrad, RenderOptions, backward, param_groups, render, render_for_backward,
};

fn scene(seed: u64, count: usize, cam: &Camera, log_scale: f32) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..count)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 88.0 - 8.0, rng.f32() * 72.0 - 8.0);
            let z = 2.0 + rng.f32() * 6.0;
            gaussian_at(&mut rng, cam, px, z, log_scale)
        })
        .collect()
}

#[test]
fn gpu_forward_matches_cpu() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let cam = camera(72, 56);
    let params = scene(21, 150, &cam, -2.0);
    for tile_size in [8, 16] {
        for p_max in [None, Some(5)] {
            let opts = RenderOptions {
                tile_size,
                p_max,
                alpha: true,
                depth: true,
                ..Default::default()
            };
            let cpu = render::<Method>(&params, &cam, &opts).unwrap();
            let gpu_frame =
                splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &opts).unwrap();
            assert_eq!(cpu.stats.intersections, gpu_frame.stats.intersections);
            assert_eq!(cpu.stats.visible, gpu_frame.stats.visible);
            assert_eq!(cpu.stats.longest_list, gpu_frame.stats.longest_list);
            let alpha = &gpu_frame.alpha.as_ref().unwrap().data;
            let coverage = alpha.iter().sum::<f32>() / alpha.len() as f32;
            assert!(
                coverage > 0.2,
                "the scene should cover the image (mean alpha {coverage})"
            );
            let label = format!("tile {tile_size}, p_max {p_max:?}, cpu / gpu");
            let worst = outputs_close(&label, &cpu, &gpu_frame, 1e-4, 0.01);
            println!(
                "tile {tile_size}, p_max {p_max:?}: worst difference {worst:.3} of the bound ({})",
                gpu.adapter
            );
        }
    }
}

#[test]
fn gpu_gradients_match_cpu() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let cam = camera(40, 32);
    // Clear of the thresholds: each Gaussian covers the whole image with alpha above 1/255
    // (no pixel sits at the cutoff) and transmittance stays far above 1e-4.
    let mut rng = fastrand::Rng::with_seed(5);
    let params: Vec<Params> = (0..8)
        .map(|i| {
            let px = Vec2::new(12.0 + 2.0 * i as f32, 10.0 + 1.5 * i as f32);
            let mut p = gaussian_at(&mut rng, &cam, px, 3.0 + 0.3 * i as f32, 0.9);
            p.opacity_logit = -1.5 + 0.4 * rng.f32();
            p
        })
        .collect();
    let alpha_opts = RenderOptions {
        alpha: true,
        ..Default::default()
    };
    for p in &params {
        let solo = render::<Method>(std::slice::from_ref(p), &cam, &alpha_opts).unwrap();
        let min = solo
            .alpha
            .unwrap()
            .data
            .iter()
            .fold(1.0f32, |m, a| m.min(*a));
        assert!(
            min > 2.0 / 255.0,
            "each Gaussian covers the image (min alpha {min})"
        );
    }
    let pixels = 40 * 32;
    let mut rng = fastrand::Rng::with_seed(6);
    let mut random = |k: usize| (0..k).map(|_| rng.f32() * 2.0 - 1.0).collect::<Vec<f32>>();
    let grad = FrameGrad {
        color: random(pixels * 3),
        alpha: Some(random(pixels)),
        depth: Some(random(pixels)),
    };
    // Every way of accumulating the gradients the adapter supports.
    let mut reductions = vec![Reduction::Workgroup, Reduction::None];
    if gpu.subgroups {
        reductions.insert(1, Reduction::Subgroup);
    }
    let atomics_kinds: &[bool] = if gpu.float_atomics {
        &[false, true]
    } else {
        &[false]
    };
    let modes: Vec<Accumulation> = reductions
        .iter()
        .flat_map(|&reduce| {
            atomics_kinds
                .iter()
                .map(move |&float_atomics| Accumulation {
                    reduce,
                    float_atomics,
                })
        })
        .collect();
    for tile_size in [8, 16] {
        let opts = RenderOptions {
            tile_size,
            alpha: true,
            depth: true,
            ..Default::default()
        };
        let (frame, state) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
        let min_t = frame
            .alpha
            .as_ref()
            .unwrap()
            .data
            .iter()
            .fold(0.0f32, |m, a| m.max(*a));
        assert!(min_t < 0.99, "transmittance stays far from 1e-4");
        let cpu = backward::<Method>(&state, &params, &cam, &grad).unwrap();
        let (_, mut gstate) =
            splat_runtime::gpu::render::render_for_backward::<Method>(&gpu, &params, &cam, &opts)
                .unwrap();
        let mut atomics = vec![];
        for acc in &modes {
            let g = splat_runtime::gpu::render::backward(&mut gstate, &grad, *acc).unwrap();
            atomics.push(g.atomics);
            let words = |ps: &[Params]| -> Vec<Vec<f64>> { ps.iter().map(words).collect() };
            let at = format!("tile {tile_size}, {acc:?}");
            let (got, want) = (words(&g.gradients.params), words(&cpu.params));
            groups_match(
                &at,
                &got,
                &want,
                None,
                &param_groups::<Method>(),
                GPU_GRADIENTS,
            );
            let (got, want) = (camera_words(&g.gradients.camera), camera_words(&cpu.camera));
            camera_matches(&at, &got, &want, None, &CAMERA_GROUPS, GPU_GRADIENTS);
        }
        println!("tile {tile_size}: atomics issued per mode {atomics:?}");
        // Each reduction issues fewer global atomics than one per pixel, the workgroup's
        // fewest; the kind of atomic does not change the count.
        let issued = |r: Reduction| atomics[modes.iter().position(|m| m.reduce == r).unwrap()];
        assert!(
            issued(Reduction::Workgroup) < issued(Reduction::None),
            "{atomics:?}"
        );
        if gpu.subgroups {
            assert!(issued(Reduction::Workgroup) <= issued(Reduction::Subgroup));
            assert!(issued(Reduction::Subgroup) < issued(Reduction::None));
        }
    }
}

/// Shaders compiled with naga's run-time checks (`Gpu::with_shader_checks`) give the same
/// frame and gradients as the default ones: bit for bit on a software adapter (two 16-px
/// tiles and the workgroup reduction, so each gradient word is `0 + a + b`, the same bits in
/// either order); a hardware driver may contract multiply-adds differently in the two
/// programs, so there within 1e-5 of the largest value.
#[test]
fn shaders_with_run_time_checks_give_the_same_results() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let checked = Gpu::new().unwrap().with_shader_checks(true);
    assert!(!gpu.shader_checks() && checked.shader_checks());
    let cam = camera(32, 16);
    let params = scene(8, 60, &cam, -1.0);
    let opts = RenderOptions {
        alpha: true,
        depth: true,
        ..Default::default()
    };
    let mut rng = fastrand::Rng::with_seed(9);
    let mut random = |k: usize| (0..k).map(|_| rng.f32() * 2.0 - 1.0).collect::<Vec<f32>>();
    let grad = FrameGrad {
        color: random(32 * 16 * 3),
        alpha: Some(random(32 * 16)),
        depth: Some(random(32 * 16)),
    };
    let acc = Accumulation {
        reduce: Reduction::Workgroup,
        float_atomics: false,
    };
    let run = |gpu: &Gpu| -> Vec<f64> {
        let (frame, mut state) =
            splat_runtime::gpu::render::render_for_backward::<Method>(gpu, &params, &cam, &opts)
                .unwrap();
        let g = splat_runtime::gpu::render::backward(&mut state, &grad, acc).unwrap();
        let image = [frame.color, frame.alpha.unwrap(), frame.depth.unwrap()];
        let image = image.iter().flat_map(|i| i.data.iter().map(|&v| v as f64));
        image.chain(flat_words(&g.gradients.params)).collect()
    };
    let (plain, with_checks) = (run(&gpu), run(&checked));
    let moved = flat_words(&params).len();
    let nonzero = plain[plain.len() - moved..].iter().filter(|&&v| v != 0.0);
    assert!(
        nonzero.count() > moved / 4,
        "most gradient words are nonzero"
    );
    if gpu.software {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(
            bits(&plain) == bits(&with_checks),
            "the checks changed a result"
        );
    } else {
        let largest = plain.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = (plain.iter().zip(&with_checks)).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            worst <= 1e-5 * largest,
            "the checks moved a result by {worst}"
        );
    }
}

#[test]
fn gpu_handles_empty_scenes_and_refuses_bad_input_clearly() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let cam = camera(24, 16);
    let opts = RenderOptions {
        alpha: true,
        ..Default::default()
    };
    let empty = splat_runtime::gpu::render::render::<Method>(&gpu, &[], &cam, &opts).unwrap();
    assert!(empty.color.data.iter().all(|c| *c == 0.0));
    assert!(empty.alpha.unwrap().data.iter().all(|a| *a == 0.0));
    let mut params = scene(1, 3, &cam, 0.0);
    let wide = RenderOptions {
        tile_size: 32,
        ..opts
    };
    let err = splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &wide)
        .err()
        .unwrap();
    assert!(err.to_string().contains("tile sizes [8, 16]"), "{err}");
    params[2].mean.y = f32::NAN;
    let err = splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &opts)
        .err()
        .unwrap();
    assert_eq!(
        err.to_string(),
        "primitive 2 has a NaN or infinite parameter"
    );
}

/// One renderer and one scene across frames whose parameters, cameras, image sizes and
/// intersection counts change (up and down, so buffers are reused and grown): every frame
/// equals a fresh one-shot render bit for bit, and its gradients equal the one-shot backward's
/// (up to the order of the atomic adds). The second frame outgrows the room the first left
/// for its keys: recorded whole before its count is known, it is cut short on the device and
/// rendered again.
#[test]
fn the_resident_renderer_matches_one_shot_frames_as_scenes_change() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let opts = RenderOptions {
        tile_size: 16,
        alpha: true,
        depth: true,
        ..Default::default()
    };
    let acc = Accumulation::default_for(&gpu);
    let mut renderer = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    let mut scene = GpuScene::<Method>::new(&gpu, &[]).unwrap();
    let frames = [
        (40, 32, 30, 1),
        (72, 56, 300, 2),
        (24, 16, 12, 3),
        (72, 56, 320, 4),
    ];
    let mut last_intersections = 0;
    for (k, (w, h, count, seed)) in frames.into_iter().enumerate() {
        let mut cam = camera(w, h);
        cam.translation.x = 0.05 * k as f32;
        let params = spread_gaussians(&cam, count, seed);
        scene.upload(&gpu, &params).unwrap();
        let info = renderer.forward(&scene, &cam).unwrap();
        let got = renderer.download_frame().unwrap();
        let want =
            splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &opts).unwrap();
        assert_eq!(got.color, want.color, "frame {k}");
        assert_eq!(got.alpha, want.alpha, "frame {k}");
        assert_eq!(got.depth, want.depth, "frame {k}");
        assert_eq!(info.intersections, want.stats.intersections);
        println!(
            "frame {k}: {w}x{h}, {count} Gaussians, {} intersections, redone: {}",
            info.intersections, info.redone
        );
        assert_eq!(info.redone, k == 1, "frame {k}");
        let pixels = (w * h) as usize;
        let mut rng = fastrand::Rng::with_seed(seed);
        let mut random = |n: usize| (0..n).map(|_| rng.f32() - 0.5).collect::<Vec<f32>>();
        let grad = FrameGrad {
            color: random(3 * pixels),
            alpha: Some(random(pixels)),
            depth: Some(random(pixels)),
        };
        renderer.backward(&scene, &grad, acc).unwrap();
        let got = renderer.download_gradients().unwrap().gradients;
        let (_, mut state) =
            splat_runtime::gpu::render::render_for_backward::<Method>(&gpu, &params, &cam, &opts)
                .unwrap();
        let want = splat_runtime::gpu::render::backward(&mut state, &grad, acc)
            .unwrap()
            .gradients;
        // The resident renderer's atomics may add in another order than a fresh one's.
        let terms = backward_for::<Method>(&params, &cam, &grad);
        let at = format!("frame {k}, resident / fresh");
        let groups = splat_runtime::param_groups::<Method>();
        let all = |ps: &[Params]| ps.iter().map(words).collect::<Vec<_>>();
        let (got_params, want_params) = (all(&got.params), all(&want.params));
        let gross = Some(&terms.gross_params[..]);
        groups_match(&at, &got_params, &want_params, gross, &groups, ATOMIC_ORDER);
        let (got, want) = (camera_words(&got.camera), camera_words(&want.camera));
        let gross = Some(&terms.gross_camera[..]);
        camera_matches(&at, &got, &want, gross, &CAMERA_GROUPS, ATOMIC_ORDER);
        if k == 1 || k == 3 {
            assert!(info.intersections > last_intersections, "the frame grows");
        }
        last_intersections = info.intersections;
    }
    // The scene on the device is what was uploaded last.
    let params = spread_gaussians(&camera(72, 56), 320, 4);
    let back = scene.download(&gpu).unwrap();
    assert_eq!(flat_words(&back), flat_words(&params));
}

/// The GPU's tile lists are the CPU's entry for entry: each tile's primitives front to back,
/// ties in depth by index. Every fourth Gaussian has a twin at the same mean (the same depth
/// bit for bit) later in the scene, so ties are many. 160x120 in tiles of 8 is 300 tiles (the
/// tile sort takes two passes), in tiles of 16 it is 80 (one pass).
#[test]
fn the_gpu_tile_lists_are_the_cpus_entry_for_entry() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let cam = camera(160, 120);
    let mut params = spread_gaussians(&cam, 400, 9);
    let twins: Vec<Params> = params
        .iter()
        .step_by(4)
        .map(|p| Params {
            log_scale: p.log_scale * 0.7,
            ..*p
        })
        .collect();
    params.extend(twins);
    let scene = GpuScene::<Method>::new(&gpu, &params).unwrap();
    for tile_size in [8, 16] {
        let opts = RenderOptions {
            tile_size,
            ..Default::default()
        };
        let (_, cpu) = render_for_backward::<Method>(&params, &cam, &opts).unwrap();
        let mut renderer = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
        renderer.forward(&scene, &cam).unwrap();
        let gpu_lists = renderer.download_tile_lists().unwrap();
        let ties = (0..cpu.lists.ranges.len() - 1)
            .flat_map(|t| cpu.lists.list(t).windows(2).map(|w| (w[0], w[1])))
            .filter(|&(a, b)| params[a as usize].mean == params[b as usize].mean)
            .count();
        assert!(ties > 50, "tile {tile_size}: only {ties} ties");
        assert_eq!(gpu_lists.ranges, cpu.lists.ranges, "tile {tile_size}");
        assert_eq!(gpu_lists.prims, cpu.lists.prims, "tile {tile_size}");
    }
}

fn flat_words(ps: &[Params]) -> Vec<f64> {
    ps.iter().flat_map(words).collect()
}

/// A frame of more than 65,535 tiles (tile 8 at 2056 x 2048: 65,792) is dispatched as rows of
/// 65,535 workgroups, the last row with spare ones that must take no tile. Each pixel blends
/// the same entries in the same order whatever the tile size, so it equals the frame of tile
/// 16 (16,448 tiles, one row) bit for bit; both count the CPU's intersections.
#[test]
fn a_frame_of_more_than_65535_tiles_equals_one_of_fewer() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let cam = camera(2056, 2048);
    let params = spread_gaussians(&cam, 300, 3);
    let frame = |tile_size| {
        let opts = RenderOptions {
            tile_size,
            alpha: true,
            depth: true,
            ..Default::default()
        };
        let cpu = render::<Method>(&params, &cam, &opts).unwrap();
        let got = splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &opts);
        let got = got.unwrap();
        assert_eq!(
            got.stats.intersections, cpu.stats.intersections,
            "tile {tile_size}"
        );
        got
    };
    let (many, few) = (frame(8), frame(16));
    let alpha = &many.alpha.as_ref().unwrap().data;
    let coverage = alpha.iter().sum::<f32>() / alpha.len() as f32;
    assert!(
        coverage > 0.05,
        "the scene covers the image (mean alpha {coverage})"
    );
    assert!(many.color == few.color, "color");
    assert!(
        many.alpha == few.alpha && many.depth == few.depth,
        "alpha and depth"
    );
}

/// A frame split as a sharded run splits it (`splat fit --sharded` on GPUs): the scene's
/// slices projected apart, the primitives the CPU would keep compacted on the device and read
/// back, the frame drawn from every slice's visible records
/// in order, its backward blend read back per record, and `project`'s adjoint of each slice
/// from its records' gradients. The frame is the scene's bit for bit, the parameter gradients
/// the scene's backward's up to the order of the atomic adds.
#[test]
fn a_frame_drawn_from_the_records_of_the_scenes_slices_is_the_scenes() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let opts = RenderOptions {
        tile_size: 16,
        ..Default::default()
    };
    let acc = Accumulation::default_for(&gpu);
    let cam = camera(72, 56);
    let params = spread_gaussians(&cam, 300, 2);
    let pixels = 72 * 56;
    // Per pixel the color's gradient, alpha's, depth's (which a loss on the device leaves
    // out: zero).
    let mut rng = fastrand::Rng::with_seed(9);
    let mut random = |n: usize| (0..n).map(|_| rng.f32() - 0.5).collect::<Vec<f32>>();
    let grad = FrameGrad {
        color: random(3 * pixels),
        alpha: Some(random(pixels)),
        depth: None,
    };
    let alpha = grad.alpha.as_ref().unwrap();
    let pixel_words: Vec<u32> = (0..pixels)
        .flat_map(|p| [&grad.color[3 * p..3 * p + 3], &[alpha[p], 0.0]].concat())
        .map(f32::to_bits)
        .collect();

    let scene = GpuScene::<Method>::new(&gpu, &params).unwrap();
    let mut whole = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    let want_info = whole.forward(&scene, &cam).unwrap();
    let want_frame = whole.download_frame().unwrap();
    gpu.write(&whole.pixel_gradients().unwrap().clone(), &pixel_words);
    whole.backward_on_device(&scene, acc).unwrap();
    let want = whole.download_gradients().unwrap().gradients.params;

    // Three slices, each's visible records to the renderer in order.
    let mut split = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    let slices: Vec<GpuScene<Method>> = [0..100, 100..190, 190..300]
        .map(|r| GpuScene::new(&gpu, &params[r]).unwrap())
        .into();
    let mut records = vec![];
    let mut seen = vec![];
    for slice in &slices {
        let (index, visible) = split.project_visible(slice, &cam).unwrap();
        // What the device keeps is what the CPU's filter keeps.
        let on_cpu = splat_runtime::pipeline::project_visible::<Method>(
            &slice.download(&gpu).unwrap(),
            &cam,
            &opts,
        )
        .unwrap();
        assert_eq!(index, on_cpu.index);
        records.extend(visible);
        seen.push(index);
    }
    split.submit_records(&records, &cam).unwrap();
    let info = split.finish_records(&records, &cam).unwrap();
    let frame = split.download_frame().unwrap();
    assert_eq!(frame.color, want_frame.color);
    assert_eq!(info.intersections, want_info.intersections);
    assert_eq!(info.visible, want_info.visible);
    gpu.write(&split.pixel_gradients().unwrap().clone(), &pixel_words);
    split.blend_records(acc).unwrap();
    let per_record = split.download_record_gradients().unwrap();
    let stride = per_record.len() / records.len();
    let param_words = <Params as splat_runtime::Flat>::LEN;

    let mut got = vec![];
    let mut at = 0;
    for (slice, index) in slices.iter().zip(&seen) {
        let grads = &per_record[at * stride..(at + index.len()) * stride];
        at += index.len();
        split.adjoint_from(slice, &cam, (index, grads)).unwrap();
        let bits = (gpu.read(split.param_gradients(), slice.len() * param_words)).unwrap();
        let floats: Vec<f32> = bits.into_iter().map(f32::from_bits).collect();
        let read = <Params as splat_runtime::Flat>::read_words;
        got.extend(floats.chunks_exact(param_words).map(read));
    }
    let terms = backward_for::<Method>(&params, &cam, &grad);
    let groups = param_groups::<Method>();
    let all = |ps: &[Params]| ps.iter().map(words).collect::<Vec<_>>();
    let gross = Some(&terms.gross_params[..]);
    let at = "slices' records / the scene";
    groups_match(at, &all(&got), &all(&want), gross, &groups, ATOMIC_ORDER);
}
