//! Scalar vs eight-lane `evaluate` (and its adjoint) of a generated method, in ns per
//! (pixel, primitive) pair. Prints a table; ratios are against the scalar form in the same
//! run. `cargo bench -p codegen-tests --bench lanes`
//!
//! The lane form is measured twice: as compiled for the default target (SSE2 on x86-64) and
//! inside a function compiled with AVX2 + FMA enabled, chosen at run time.

use splat_examples::isotropic::isotropic::{Method, Shade};
use splat_runtime::glam::{Vec2, Vec3};
use splat_runtime::{Contribution, ContributionLanes, F32x8, M32x8, SplatMethod};
use std::hint::black_box;
use std::time::Instant;

const TILE: usize = 16;
const PRIMS: usize = 256;

struct Scene {
    shades: Vec<Shade>,
    pixels: Vec<Vec2>,
    lanes: Vec<[F32x8; 2]>,
}

fn scene() -> Scene {
    let mut rng = fastrand::Rng::with_seed(1);
    let shades = (0..PRIMS)
        .map(|_| Shade {
            center: Vec2::new(rng.f32() * 16.0, rng.f32() * 16.0),
            inv_sigma2: 0.01 + 0.1 * rng.f32(),
            opacity: 0.5 + 0.5 * rng.f32(),
            color: Vec3::new(rng.f32(), rng.f32(), rng.f32()),
        })
        .collect();
    let pixels: Vec<Vec2> = (0..TILE * TILE)
        .map(|i| Vec2::new((i % TILE) as f32 + 0.5, (i / TILE) as f32 + 0.5))
        .collect();
    let lanes = pixels
        .chunks(8)
        .map(|c| {
            [
                F32x8(std::array::from_fn(|l| c[l].x)),
                F32x8(std::array::from_fn(|l| c[l].y)),
            ]
        })
        .collect();
    Scene {
        shades,
        pixels,
        lanes,
    }
}

fn scalar_forward(s: &Scene) -> f32 {
    let mut acc = 0.0;
    for shade in &s.shades {
        for p in &s.pixels {
            let c = Method::evaluate(p, shade);
            acc += c.alpha + c.color.x;
        }
    }
    acc
}

#[inline(always)]
fn lanes_forward_body(s: &Scene) -> f32 {
    let mut acc = F32x8::splat(0.0);
    for shade in &s.shades {
        for p in &s.lanes {
            let c = Method::evaluate_lanes(p, shade);
            acc = acc + c.alpha + c.color[0];
        }
    }
    acc.masked_sum(M32x8::splat(true))
}

fn lanes_forward(s: &Scene) -> f32 {
    lanes_forward_body(s)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn lanes_forward_avx2(s: &Scene) -> f32 {
    lanes_forward_body(s)
}

fn scalar_adjoint(s: &Scene) -> f32 {
    let d = Contribution {
        alpha: 0.3,
        color: Vec3::new(0.1, 0.2, 0.3),
        valid: true,
    };
    let mut acc = 0.0;
    for shade in &s.shades {
        for p in &s.pixels {
            let g = Method::evaluate_adjoint(p, shade, &d);
            acc += g.center.x + g.inv_sigma2 + g.opacity;
        }
    }
    acc
}

#[inline(always)]
fn lanes_adjoint_body(s: &Scene) -> f32 {
    let d = ContributionLanes {
        alpha: F32x8::splat(0.3),
        color: [F32x8::splat(0.1), F32x8::splat(0.2), F32x8::splat(0.3)],
        valid: M32x8::splat(true),
    };
    let mut acc = 0.0;
    for shade in &s.shades {
        for p in &s.lanes {
            let g = Method::evaluate_adjoint_lanes(p, shade, &d, M32x8::splat(true));
            acc += g.center.x + g.inv_sigma2 + g.opacity;
        }
    }
    acc
}

fn lanes_adjoint(s: &Scene) -> f32 {
    lanes_adjoint_body(s)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn lanes_adjoint_avx2(s: &Scene) -> f32 {
    lanes_adjoint_body(s)
}

/// Best of several runs, in ns per pair.
fn time(s: &Scene, f: &dyn Fn(&Scene) -> f32) -> f64 {
    let pairs = (PRIMS * TILE * TILE) as f64;
    let mut best = f64::INFINITY;
    for _ in 0..15 {
        let t = Instant::now();
        black_box(f(black_box(s)));
        best = best.min(t.elapsed().as_secs_f64() * 1e9 / pairs);
    }
    best
}

fn main() {
    let s = scene();
    let avx2 = cfg!(target_arch = "x86_64")
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma");
    println!(
        "evaluate of `isotropic` (isotropic Gaussian), {PRIMS} primitives x {}x{} pixels",
        TILE, TILE
    );
    println!("{:<28} {:>12} {:>10}", "form", "ns / pair", "speed-up");
    for (label, scalar, lanes, lanes_avx2) in [
        (
            "forward",
            scalar_forward as fn(&Scene) -> f32,
            lanes_forward as fn(&Scene) -> f32,
            {
                #[cfg(target_arch = "x86_64")]
                let f: fn(&Scene) -> f32 = |s| unsafe { lanes_forward_avx2(s) };
                f
            },
        ),
        ("adjoint", scalar_adjoint, lanes_adjoint, {
            #[cfg(target_arch = "x86_64")]
            let f: fn(&Scene) -> f32 = |s| unsafe { lanes_adjoint_avx2(s) };
            f
        }),
    ] {
        let base = time(&s, &scalar);
        println!(
            "{:<28} {:>12.3} {:>10}",
            format!("{label}, scalar"),
            base,
            "1.00x"
        );
        let l = time(&s, &lanes);
        println!(
            "{:<28} {:>12.3} {:>9.2}x",
            format!("{label}, 8 lanes (baseline)"),
            l,
            base / l
        );
        if avx2 {
            let a = time(&s, &lanes_avx2);
            println!(
                "{:<28} {:>12.3} {:>9.2}x",
                format!("{label}, 8 lanes (avx2+fma)"),
                a,
                base / a
            );
        }
    }
}
