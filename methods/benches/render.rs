//! 3DGS on the CPU at scale: a procedural scene of 1M Gaussians rendered at 1920x1080.
//! Prints per-stage times, visible primitives, intersections, evaluated (pixel, primitive)
//! pairs, ns per pair per core, peak memory, the backward pass, and the P_max trade-off
//! (time and PSNR against the uncapped render, in the same run).
//!
//! `cargo bench -p splat-methods --bench render [-- N WIDTH HEIGHT]`

use splat_methods::gs3d::Method;
use splat_methods::gs3d_sh0;
use splat_runtime::{FrameGrad, RenderOptions, backward, render, render_for_backward};
use std::time::Instant;

mod common;
use common::{camera, scene, size_args};

fn peak_rss_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| ((x.clamp(0.0, 1.0) - y.clamp(0.0, 1.0)) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / mse).log10()
    }
}

fn main() {
    let (n, w, h) = size_args(1_000_000, 1920, 1080);
    let cores = rayon::current_num_threads();
    let params = scene(n);
    let camera = camera(w, h);
    println!("3DGS, {n} Gaussians (SH degree 3), {w}x{h}, {cores} threads");
    let opts = RenderOptions::default();
    // Warm up (page faults, thread pool).
    let _ = render::<Method>(&params, &camera, &opts).unwrap();
    let t = Instant::now();
    let frame = render::<Method>(&params, &camera, &opts).unwrap();
    let total = t.elapsed();
    let s = &frame.stats;
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    println!(
        "forward: preprocess {:.1} ms | rasterize {:.1} ms | shade {:.1} ms | total {:.1} ms",
        ms(s.preprocess),
        ms(s.rasterize),
        ms(s.shade),
        ms(total)
    );
    println!(
        "visible {} | intersections {} | longest tile list {} | pairs evaluated {}",
        s.visible, s.intersections, s.longest_list, s.pairs
    );
    println!(
        "shade: {:.2} ns per pair per core",
        s.shade.as_secs_f64() * 1e9 * cores as f64 / s.pairs as f64
    );

    let t = Instant::now();
    let (_, state) = render_for_backward::<Method>(&params, &camera, &opts).unwrap();
    let fwd = t.elapsed();
    let pixels = (w * h) as usize;
    let grad = FrameGrad {
        color: vec![1.0 / pixels as f32; pixels * 3],
        alpha: None,
        depth: None,
    };
    let t = Instant::now();
    let g = backward::<Method>(&state, &params, &camera, &grad).unwrap();
    let bwd = t.elapsed();
    std::hint::black_box(&g.params[0]);
    println!(
        "forward+backward: forward (state kept) {:.1} ms | backward {:.1} ms (blend {:.1}, reduce {:.1}, project adjoint {:.1}) | blend {:.2} ns per pair per core",
        ms(fwd),
        ms(bwd),
        ms(g.stats.blend),
        ms(g.stats.reduce),
        ms(g.stats.project),
        g.stats.blend.as_secs_f64() * 1e9 * cores as f64 / s.pairs as f64
    );
    drop(state);
    println!("peak memory {:.0} MiB", peak_rss_mib());

    // The SH degree is compiled in: the same scene with only the DC term, through the degree-0
    // instance of the method, against the degree-3 one.
    let dc_only: Vec<gs3d_sh0::Params> = params
        .iter()
        .map(|p| gs3d_sh0::Params {
            mean: p.mean,
            log_scale: p.log_scale,
            rotation: p.rotation,
            opacity_logit: p.opacity_logit,
            sh: [p.sh[0]],
        })
        .collect();
    let f0 = render::<gs3d_sh0::Method>(&dc_only, &camera, &opts).unwrap();
    let f3 = render::<Method>(&params, &camera, &opts).unwrap();
    println!(
        "SH degree compiled in: preprocess degree 0 {:.1} ms vs degree 3 {:.1} ms ({:.2}x)",
        ms(f0.stats.preprocess),
        ms(f3.stats.preprocess),
        f3.stats.preprocess.as_secs_f64() / f0.stats.preprocess.as_secs_f64()
    );

    println!(
        "{:>10} {:>12} {:>16} {:>10}",
        "P_max", "shade ms", "pairs", "PSNR dB"
    );
    for p_max in [
        None,
        Some(8192),
        Some(4096),
        Some(1024),
        Some(256),
        Some(64),
    ] {
        let opts = RenderOptions {
            p_max,
            ..RenderOptions::default()
        };
        let f = render::<Method>(&params, &camera, &opts).unwrap();
        let label = p_max.map_or("unbounded".to_string(), |p| p.to_string());
        println!(
            "{label:>10} {:>12.1} {:>16} {:>10.2}",
            ms(f.stats.shade),
            f.stats.pairs,
            psnr(&f.color.data, &frame.color.data)
        );
    }
}
