//! The hardware path's forward and backward (quads in depth order; programmable blending:
//! the backward replays the draw in fragment shaders, `HardwareRenderer::backward`) beside
//! the tile path's on the same device and scene: times per pass, global atomic adds (Yuan and
//! He's Table I: the replay's fragment gradients added one by one, summed over quads, over
//! cohesive subgroups, and both), and device memory (their Table III: the sorts' and all the
//! path holds for a frame and its backward), for each state format. Each figure is the best of
//! 3 runs after a warm-up. The replay's time is measured on the host around its submission
//! (the raw pass holds no timestamp queries). On a machine without a GPU this runs on
//! lavapipe, whose times compare two CPU implementations, not a GPU's raster hardware.
//!
//! `cargo bench -p splat-methods --bench hardware [-- N WIDTH HEIGHT]`

use splat_methods::gs3d::{Method, Params};
use splat_runtime::RenderOptions;
use splat_runtime::gpu::entries::{Accumulation, FragmentReduction};
use splat_runtime::gpu::raster::{Blending, HardwareRenderer};
use splat_runtime::gpu::{Gpu, GpuRenderer, GpuScene, programmable_blend};
use splat_runtime::precision::Precision;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

mod common;
use common::{best, camera, ms, random_grad, scene, size_args};

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// Bytes wgpu's allocator holds on `gpu`'s device by allocation name (the buffers' labels),
/// after freeing what was dropped.
fn allocations(gpu: &Gpu) -> BTreeMap<String, u64> {
    gpu.wait().unwrap();
    let mut out = BTreeMap::new();
    let report = gpu.device.generate_allocator_report();
    for a in report.map(|r| r.allocations).unwrap_or_default() {
        *out.entry(a.name).or_default() += a.size;
    }
    out
}

/// What was allocated since `before`: in all, and its four largest names.
fn allocated_since(gpu: &Gpu, before: &BTreeMap<String, u64>) -> (u64, String) {
    let mut grown: Vec<(u64, String)> = (allocations(gpu).into_iter())
        .map(|(name, bytes)| {
            (
                bytes.saturating_sub(before.get(&name).copied().unwrap_or(0)),
                name,
            )
        })
        .filter(|(bytes, _)| *bytes > 0)
        .collect();
    grown.sort_unstable_by(|a, b| b.cmp(a));
    let total = grown.iter().map(|(bytes, _)| bytes).sum();
    let largest: Vec<String> = (grown.iter().take(4))
        .map(|(bytes, name)| format!("{name} {:.2}", mib(*bytes)))
        .collect();
    (total, largest.join(", "))
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
    let grad = random_grad((w * h) as usize);
    println!(
        "3DGS, {n} Gaussians (SH degree 3), {w}x{h}; GPU: {}",
        gpu.adapter
    );
    let scene_gpu = GpuScene::<Method>::new(&gpu, &params).unwrap();
    let acc = Accumulation::default_for(&gpu);
    let before = allocations(&gpu);
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
    let (tile_total, tile_largest) = allocated_since(&gpu, &before);
    let mut largest = vec![("tiles".to_string(), tile_largest)];
    let tile_info = tiles.frame().unwrap();
    println!(
        "\nTotal: device memory the renderer holds after a frame and its backward (wgpu's allocator, and the programmable passes' own images)."
    );
    println!(
        "\n| path | forward (ms) | backward (ms) | x tiles (fwd + bwd) | atomics | sort (MiB) | gradient sums (MiB) | total (MiB) | x tiles (total) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let sum = |t: [Duration; 2]| t[0] + t[1];
    println!(
        "| tiles (16 px, {:?}, {} pairs) | {:.1} | {:.1} | 1.00 | {atomics} | {:.2} | {:.2} | {:.2} | 1.00 |",
        acc.reduce,
        tile_info.intersections,
        ms(tile_times[0]),
        ms(tile_times[1]),
        mib(tiles.sort_bytes() as u64),
        mib(tiles.gradient_sum_bytes() as u64),
        mib(tile_total),
    );
    // Every format with the default sums, then f32 states with each other reduction.
    let default = FragmentReduction::default_for(&gpu);
    let others = FragmentReduction::ALL.into_iter().filter(|&r| r != default);
    let runs =
        (Precision::ALL.iter().map(|&p| (p, default))).chain(others.map(|r| (Precision::F32, r)));
    for (precision, reduce) in runs {
        let before = allocations(&gpu);
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
        let (allocated, wgpu_largest) = allocated_since(&gpu, &before);
        let passes = hw.pass_memory_bytes();
        let total = allocated + passes;
        let name = format!("hardware, {} states", precision.name());
        if reduce == default {
            let passes = format!("state images (raw Vulkan) {:.2}", mib(passes));
            largest.push((name.clone(), format!("{passes}, {wgpu_largest}")));
        }
        println!(
            "| {name}, {reduce:?} sums | {:.1} | {:.1} | {:.2} | {atomics} | {:.2} | {:.2} | {:.2} | {:.2} |",
            ms(times[0]),
            ms(times[1]),
            sum(times).as_secs_f64() / sum(tile_times).as_secs_f64(),
            mib(hw.sort_bytes() as u64),
            mib(hw.gradient_sum_bytes() as u64),
            mib(total),
            total as f64 / tile_total as f64,
        );
    }
    println!("\nThe largest allocations of each path's total (MiB):");
    for (path, what) in largest {
        println!("- {path}: {what}");
    }
}
