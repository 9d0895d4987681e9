//! The same 3DGS source on the GPU: forward renders (color, alpha, depth) of the GPU path
//! (`project` and blending in the generated WGSL) against the CPU backend, within 1e-4
//! absolute + 1% relative per element, for tile sizes 8 and 16.
//!
//! Needs a wgpu adapter (lavapipe is enough); with `SPLAT_REQUIRE_GPU=1` a missing adapter
//! fails the test, otherwise it skips.

mod common;

use common::{camera, gaussian_at};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::glam::Vec2;
use splat_runtime::gpu::Gpu;
use splat_runtime::{RenderOptions, render};

#[test]
fn gpu_forward_matches_cpu() {
    let gpu = match Gpu::new() {
        Ok(g) => g,
        Err(e) if std::env::var("SPLAT_REQUIRE_GPU").is_ok_and(|v| v == "1") => panic!("{e}"),
        Err(e) => {
            eprintln!("skipping GPU parity: {e}");
            return;
        }
    };
    let mut rng = fastrand::Rng::with_seed(21);
    let cam = camera(72, 56);
    let params: Vec<Params> = (0..150)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 88.0 - 8.0, rng.f32() * 72.0 - 8.0);
            let z = 2.0 + rng.f32() * 6.0;
            gaussian_at(&mut rng, &cam, px, z, -2.0)
        })
        .collect();
    for tile_size in [8, 16] {
        for p_max in [None, Some(5)] {
            let opts = RenderOptions {
                tile_size,
                p_max,
                alpha: true,
                depth: true,
            };
            let cpu = render::<Method>(&params, &cam, &opts).unwrap();
            let gpu_frame =
                splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &opts).unwrap();
            assert_eq!(cpu.stats.intersections, gpu_frame.stats.intersections);
            let alpha = &gpu_frame.alpha.as_ref().unwrap().data;
            let coverage = alpha.iter().sum::<f32>() / alpha.len() as f32;
            assert!(
                coverage > 0.2,
                "the scene should cover the image (mean alpha {coverage})"
            );
            let mut worst = 0.0f32;
            let outputs = [
                ("color", &cpu.color.data, &gpu_frame.color.data),
                (
                    "alpha",
                    &cpu.alpha.as_ref().unwrap().data,
                    &gpu_frame.alpha.as_ref().unwrap().data,
                ),
                (
                    "depth",
                    &cpu.depth.as_ref().unwrap().data,
                    &gpu_frame.depth.as_ref().unwrap().data,
                ),
            ];
            for (what, c, g) in outputs {
                for (i, (a, b)) in c.iter().zip(g.iter()).enumerate() {
                    let bound = 1e-4 + 0.01 * a.abs();
                    worst = worst.max((a - b).abs() / bound);
                    assert!(
                        (a - b).abs() <= bound,
                        "tile {tile_size}, p_max {p_max:?}, {what}[{i}]: cpu {a} gpu {b}"
                    );
                }
            }
            println!(
                "tile {tile_size}, p_max {p_max:?}: worst difference {worst:.3} of the bound ({})",
                gpu.adapter
            );
        }
    }
}
