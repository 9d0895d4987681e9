//! The CPU backend against the GPU backend on the same scene and machine, stage by stage,
//! forward and backward; then the global atomic adds of the GPU backward blend with and
//! without the workgroup reduction (Yuan and He, "Efficient Differentiable Hardware
//! Rasterization for 3D Gaussian Splatting", Table I), with f32 atomics and with the
//! compare-exchange loop; and the wall time of a frame through the one-shot path (upload,
//! build, render, download) against the resident pipeline (scene and renderer kept, nothing
//! read back but the intersection count); last, the GPU stages again from shaders compiled
//! with naga's run-time checks. GPU stage times are GPU timestamps where the adapter has them.
//! Each figure is the best of 3 runs after a warm-up (pipelines compile on first use). On a
//! machine without a GPU the wgpu backend runs on a software adapter (lavapipe): the ratios
//! then compare two CPU implementations, not a GPU.
//!
//! `cargo bench -p splat-methods --bench gpu [-- N WIDTH HEIGHT]`

use splat_methods::gs3d::{Method, Params};
use splat_runtime::gpu::entries::{Accumulation, Reduction};
use splat_runtime::gpu::{Gpu, GpuRenderer, GpuScene, render as gpu_render};
use splat_runtime::{RenderOptions, backward, render_for_backward};
use std::time::{Duration, Instant};

mod common;
use common::{best, camera, ms, random_grad, scene, size_args, warm_up};

fn main() {
    let (n, w, h) = size_args(20_000, 640, 360);
    let gpu = Gpu::new().expect("a wgpu adapter (lavapipe is enough)");
    let params: Vec<Params> = scene(n);
    let camera = camera(w, h);
    let opts = RenderOptions {
        depth: true,
        alpha: true,
        ..RenderOptions::default()
    };
    let pixels = (w * h) as usize;
    let grad = random_grad(pixels);
    println!(
        "3DGS, {n} Gaussians (SH degree 3), {w}x{h}, tile 16; CPU: {} threads; GPU: {}",
        rayon::current_num_threads(),
        gpu.adapter
    );

    let cpu = || {
        let (f, state) = render_for_backward::<Method>(&params, &camera, &opts).unwrap();
        let g = backward::<Method>(&state, &params, &camera, &grad).unwrap();
        let s = f.stats;
        [
            s.preprocess,
            s.rasterize,
            s.shade,
            g.stats.blend + g.stats.reduce,
            g.stats.project,
        ]
    };
    let acc = Accumulation::default_for(&gpu);
    let scene_gpu = GpuScene::<Method>::new(&gpu, &params).unwrap();
    let mut renderer = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    // One frame's stage times and global atomic adds, on the device `scene` lives on.
    let gpu_run =
        |renderer: &mut GpuRenderer<Method>, scene: &GpuScene<Method>, acc: Accumulation| {
            renderer.forward(scene, &camera).unwrap();
            renderer.backward(scene, &grad, acc).unwrap();
            let s = renderer.download_frame().unwrap().stats;
            let g = renderer.download_gradients().unwrap();
            let b = g.gradients.stats;
            (
                [s.preprocess, s.rasterize, s.shade, b.blend, b.project],
                g.atomics,
            )
        };
    let c = best(3, cpu);
    let g = best(3, || gpu_run(&mut renderer, &scene_gpu, acc).0);
    println!("\n| stage | CPU backend (ms) | GPU backend (ms) | GPU / CPU |");
    println!("|---|---:|---:|---:|");
    let names = [
        "preprocess (project)",
        "rasterize (count, scan, emit, sort, ranges, bins)",
        "shade",
        "backward blend",
        "project adjoint",
    ];
    for (k, name) in names.iter().enumerate() {
        ratio_row(name, c[k], g[k]);
    }
    ratio_row("total", c.iter().sum(), g.iter().sum());

    let wait = || gpu.wait().unwrap();
    let timed = |f: &mut dyn FnMut()| {
        best(3, || {
            let t = Instant::now();
            f();
            [t.elapsed()]
        })[0]
    };
    let one_shot_forward = timed(&mut || {
        gpu_render::render::<Method>(&gpu, &params, &camera, &opts).unwrap();
    });
    let one_shot_both = timed(&mut || {
        let (_, mut state) =
            gpu_render::render_for_backward::<Method>(&gpu, &params, &camera, &opts).unwrap();
        gpu_render::backward(&mut state, &grad, acc).unwrap();
    });
    let resident_forward = timed(&mut || {
        renderer.forward(&scene_gpu, &camera).unwrap();
        wait();
    });
    let resident_both = timed(&mut || {
        renderer.forward(&scene_gpu, &camera).unwrap();
        renderer.backward(&scene_gpu, &grad, acc).unwrap();
        wait();
    });
    println!(
        "\nWall time of a GPU frame, one-shot (upload, build, render, download) against resident:"
    );
    println!("| pass | one-shot (ms) | resident (ms) | one-shot / resident |");
    println!("|---|---:|---:|---:|");
    for (name, a, b) in [
        ("forward", one_shot_forward, resident_forward),
        ("forward + backward", one_shot_both, resident_both),
    ] {
        println!(
            "| {name} | {:.1} | {:.1} | {:.2} |",
            ms(a),
            ms(b),
            ms(a) / ms(b)
        );
    }
    if !gpu.timestamps {
        println!("(no GPU timestamps on this adapter: GPU stage times above are zero)");
    }

    println!(
        "\nGlobal atomic adds of the GPU backward blend (each kind in turns with the default, {acc:?}):"
    );
    println!("| reduction | atomics | adds issued | blend (ms) | x default |");
    println!("|---|---|---:|---:|---:|");
    let mut reductions = vec![Reduction::None, Reduction::Workgroup];
    if gpu.subgroups {
        reductions.insert(1, Reduction::Subgroup);
    }
    let mut kinds = vec![false];
    if gpu.float_atomics {
        kinds.insert(0, true);
    }
    for (float_atomics, reduce) in kinds
        .iter()
        .flat_map(|&f| reductions.iter().map(move |&r| (f, r)))
    {
        let kind = Accumulation {
            reduce,
            float_atomics,
        };
        // A frame of this kind, then one of the default's: their ratio holds while the GPU's
        // clock moves with the load.
        let mut round = || {
            let (t, issued) = gpu_run(&mut renderer, &scene_gpu, kind);
            let (d, _) = gpu_run(&mut renderer, &scene_gpu, acc);
            (t[3], ms(t[3]) / ms(d[3]), issued)
        };
        warm_up(&mut round);
        let rounds: Vec<_> = (0..5).map(|_| round()).collect();
        let blend = rounds.iter().map(|r| r.0).min().unwrap();
        let mut ratios: Vec<f64> = rounds.iter().map(|r| r.1).collect();
        ratios.sort_by(f64::total_cmp);
        println!(
            "| {reduce:?} | {} | {} | {:.1} | {:.2} |",
            if float_atomics {
                "f32 atomicAdd"
            } else {
                "u32 compare-exchange"
            },
            rounds[0].2,
            ms(blend),
            ratios[2]
        );
    }

    // The same frames from shaders compiled with naga's run-time checks (a second device on
    // the same adapter): what the checks cost per stage.
    if !gpu.timestamps {
        return;
    }
    let checked = Gpu::new().unwrap().with_shader_checks(true);
    let scene_checked = GpuScene::<Method>::new(&checked, &params).unwrap();
    let mut renderer_checked = GpuRenderer::<Method>::new(&checked, &opts).unwrap();
    let on = best(3, || gpu_run(&mut renderer_checked, &scene_checked, acc).0);
    println!(
        "\nGPU stages with naga's run-time checks (index clamps, division guards, loop counters):"
    );
    println!("| stage | checks off (ms) | checks on (ms) | on / off |");
    println!("|---|---:|---:|---:|");
    for (k, name) in names.iter().enumerate() {
        ratio_row(name, g[k], on[k]);
    }
}

/// A table row: a stage's two times in ms and the second over the first.
fn ratio_row(name: &str, base: Duration, other: Duration) {
    println!(
        "| {name} | {:.1} | {:.1} | {:.2} |",
        ms(base),
        ms(other),
        ms(other) / ms(base)
    );
}
