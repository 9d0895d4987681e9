//! The hardware path's forward and backward (quads in depth order; programmable blending:
//! the backward replays the draw in fragment shaders, `HardwareRenderer::backward`) beside
//! the tile path's on the same device and scene: times per pass, global atomic adds (Yuan and
//! He's Table I: the replay's quad sums against one atomic per fragment and word) and sort and
//! gradient-sum memory (their Table III), for each state format. Each figure is the best of
//! 3 runs after a warm-up. The replay's time is measured on the host around its submission
//! (the raw pass holds no timestamp queries). On a machine without a GPU this runs on
//! lavapipe, whose times compare two CPU implementations, not a GPU's raster hardware.
//!
//! `cargo bench -p splat-methods --bench hardware [-- N WIDTH HEIGHT]`

use splat_methods::gs3d::{Method, Params};
use splat_runtime::gpu::entries::{Accumulation, FragmentReduction};
use splat_runtime::gpu::raster::{Blending, HardwareRenderer};
use splat_runtime::gpu::{GpuRenderer, GpuScene, programmable_blend};
use splat_runtime::precision::Precision;
use splat_runtime::{FrameGrad, RenderOptions};
use std::time::{Duration, Instant};

mod common;
use common::{camera, scene, size_args};

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn mib(bytes: usize) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// Element-wise minimum of `runs` runs of `f` (forward, backward), after one run to compile.
fn best(runs: usize, mut f: impl FnMut() -> [Duration; 2]) -> [Duration; 2] {
    f();
    let mut out = [Duration::MAX; 2];
    for _ in 0..runs {
        for (o, t) in out.iter_mut().zip(f()) {
            *o = (*o).min(t);
        }
    }
    out
}

fn main() {
    let (n, w, h) = size_args(20_000, 320, 180);
    let Some(gpu) = programmable_blend::open().expect("a Vulkan adapter") else {
        println!("this adapter lacks rasterization-order attachment access: nothing to measure");
        return;
    };
    let params: Vec<Params> = scene(n);
    let camera = camera(w, h);
    let opts = RenderOptions {
        depth: true,
        alpha: true,
        ..RenderOptions::default()
    };
    let pixels = (w * h) as usize;
    let mut rng = fastrand::Rng::with_seed(1);
    let grad = FrameGrad {
        color: (0..pixels * 3).map(|_| rng.f32() - 0.5).collect(),
        alpha: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
        depth: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
    };
    println!(
        "3DGS, {n} Gaussians (SH degree 3), {w}x{h}; GPU: {}",
        gpu.adapter
    );
    let scene_gpu = GpuScene::<Method>::new(&gpu, &params).unwrap();
    let acc = Accumulation::default_for(&gpu);
    let mut tiles = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    let mut atomics = 0;
    let tile_times = best(3, || {
        let start = Instant::now();
        tiles.forward(&scene_gpu, &camera).unwrap();
        gpu.wait().unwrap();
        let forward = start.elapsed();
        let start = Instant::now();
        tiles.backward(&scene_gpu, &grad, acc).unwrap();
        atomics = tiles.download_gradients().unwrap().atomics;
        [forward, start.elapsed()]
    });
    let tile_info = tiles.frame().unwrap();
    println!(
        "\n| path | forward (ms) | backward (ms) | x tiles (fwd + bwd) | atomics | sort (MiB) | gradient sums (MiB) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let total = |t: [Duration; 2]| t[0] + t[1];
    println!(
        "| tiles (16 px, {:?}, {} pairs) | {:.1} | {:.1} | 1.00 | {atomics} | {:.2} | {:.2} |",
        acc.reduce,
        tile_info.intersections,
        ms(tile_times[0]),
        ms(tile_times[1]),
        mib(tiles.sort_bytes()),
        mib(tiles.gradient_sum_bytes()),
    );
    let runs = Precision::ALL
        .iter()
        .map(|&p| (p, FragmentReduction::Quad))
        .chain([(Precision::F32, FragmentReduction::None)]);
    for (precision, reduce) in runs {
        let opts = RenderOptions { precision, ..opts };
        let mut hw =
            HardwareRenderer::<Method>::with_blending(&gpu, &opts, Blending::Programmable).unwrap();
        let times = best(3, || {
            let start = Instant::now();
            hw.forward(&scene_gpu, &camera).unwrap();
            let forward = start.elapsed();
            let start = Instant::now();
            hw.backward_with(&scene_gpu, &grad, reduce).unwrap();
            atomics = hw.download_gradients().unwrap().atomics;
            [forward, start.elapsed()]
        });
        let reduction = match reduce {
            FragmentReduction::None => "one atomic per fragment",
            FragmentReduction::Quad => "quad sums",
        };
        println!(
            "| hardware, {} states, {reduction} | {:.1} | {:.1} | {:.2} | {atomics} | {:.2} | {:.2} |",
            precision.name(),
            ms(times[0]),
            ms(times[1]),
            total(times).as_secs_f64() / total(tile_times).as_secs_f64(),
            mib(hw.sort_bytes()),
            mib(hw.gradient_sum_bytes()),
        );
    }
}
