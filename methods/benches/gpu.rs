//! The CPU backend against the GPU backend on the same scene and machine, stage by stage,
//! forward and backward; then the global atomic adds of the GPU backward blend with and
//! without the workgroup reduction (seed 001 Table I), with f32 atomics and with the
//! compare-exchange loop. Each figure is the best of 3 runs after a warm-up (pipelines
//! compile on first use). On a machine without a GPU the wgpu backend runs on a software
//! adapter (lavapipe): the ratios then compare two CPU implementations, not a GPU.
//!
//! `cargo bench -p splat-methods --bench gpu [-- N WIDTH HEIGHT]`

use splat_methods::gs3d::{Method, Params};
use splat_runtime::gpu::entries::{Accumulation, Reduction};
use splat_runtime::gpu::{Gpu, backward as gpu_backward, render as gpu_render};
use splat_runtime::{FrameGrad, RenderOptions, backward, render_for_backward};
use std::time::Duration;

mod common;
use common::{camera, scene, size_args};

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Element-wise minimum of the per-stage times of `runs` runs of `f`.
fn best<const K: usize>(runs: usize, mut f: impl FnMut() -> [Duration; K]) -> [Duration; K] {
    let mut out = [Duration::MAX; K];
    for _ in 0..runs {
        for (o, t) in out.iter_mut().zip(f()) {
            *o = (*o).min(t);
        }
    }
    out
}

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
    let mut rng = fastrand::Rng::with_seed(1);
    let grad = FrameGrad {
        color: (0..pixels * 3).map(|_| rng.f32() - 0.5).collect(),
        alpha: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
        depth: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
    };
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
    let gpu_run = |acc: Accumulation| {
        let (f, state) =
            gpu_render::render_for_backward::<Method>(&gpu, &params, &camera, &opts).unwrap();
        let g = gpu_backward::backward(&gpu, &state, &grad, acc).unwrap();
        let s = f.stats;
        let b = g.gradients.stats;
        (
            [s.preprocess, s.rasterize, s.shade, b.blend, b.project],
            g.atomics,
        )
    };
    cpu();
    gpu_run(acc);
    let c = best(3, cpu);
    let g = best(3, || gpu_run(acc).0);
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
        println!(
            "| {name} | {:.1} | {:.1} | {:.2} |",
            ms(c[k]),
            ms(g[k]),
            ms(g[k]) / ms(c[k])
        );
    }
    let (ct, gt): (Duration, Duration) = (c.iter().sum(), g.iter().sum());
    println!(
        "| total | {:.1} | {:.1} | {:.2} |",
        ms(ct),
        ms(gt),
        ms(gt) / ms(ct)
    );

    println!("\nGlobal atomic adds of the GPU backward blend:");
    println!("| reduction | atomics | adds issued | blend (ms) |");
    println!("|---|---|---:|---:|");
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
        let acc = Accumulation {
            reduce,
            float_atomics,
        };
        let mut issued = 0;
        let blend = best(3, || {
            let (t, a) = gpu_run(acc);
            issued = a;
            [t[3]]
        });
        println!(
            "| {reduce:?} | {} | {issued} | {:.1} |",
            if float_atomics {
                "f32 atomicAdd"
            } else {
                "u32 compare-exchange"
            },
            ms(blend[0])
        );
    }
}
