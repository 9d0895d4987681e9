//! The procedural benchmark scene shared by the benches.

// Each bench uses part of it.
#![allow(dead_code)]

use splat_methods::FromStored;
use splat_methods::gs3d::Params;
use splat_runtime::Camera;
use splat_runtime::FrameGrad;
use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
use splat_runtime::io::ply::StoredGaussian;
use std::time::{Duration, Instant};

/// `N WIDTH HEIGHT` from the command line, each defaulting when absent.
pub fn size_args(n: usize, width: usize, height: usize) -> (usize, f32, f32) {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    (
        args.first().copied().unwrap_or(n),
        args.get(1).copied().unwrap_or(width) as f32,
        args.get(2).copied().unwrap_or(height) as f32,
    )
}

/// A camera at the origin looking down +z, with a field of view of about 58 degrees.
pub fn camera(w: f32, h: f32) -> Camera {
    Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        focal: Vec2::splat(0.9 * w),
        principal: Vec2::new(w / 2.0, h / 2.0),
        size: Vec2::new(w, h),
        ..Default::default()
    }
}

/// Gaussians filling the view between depth 4 and 30, with 60% of them in a central cluster
/// so that the middle tiles get the deep lists that make `P_max` matter, as in real scenes.
pub fn scene(n: usize) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(42);
    (0..n)
        .map(|i| {
            let cluster = i % 5 < 3;
            let (x, y, z) = if cluster {
                let d = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5) * 4.0;
                (d.x, d.y, 14.0 + d.z)
            } else {
                let z = 4.0 + 26.0 * rng.f32();
                (
                    (rng.f32() - 0.5) * 2.0 * z * 0.55,
                    (rng.f32() - 0.5) * 2.0 * z * 0.32,
                    z,
                )
            };
            let mut sh = [Vec3::ZERO; 16];
            for c in sh.iter_mut() {
                *c = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5) * 0.4;
            }
            // The cluster: larger and fainter, so lists are long and blending goes deep.
            let (s, opacity_logit) = if cluster {
                ((0.04 + 0.08 * rng.f32()).ln(), -4.5 + 3.0 * rng.f32())
            } else {
                (
                    (0.01 + 0.05 * rng.f32() * rng.f32()).ln(),
                    rng.f32() * 4.0 - 2.0,
                )
            };
            Params {
                mean: Vec3::new(x, y, z),
                log_scale: Vec3::new(
                    s + 0.3 * rng.f32(),
                    s + 0.3 * rng.f32(),
                    s + 0.3 * rng.f32(),
                ),
                rotation: Vec4::new(1.0, rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5),
                opacity_logit,
                sh,
            }
        })
        .collect()
}

/// The Gaussians as another method's parameters, through its own `FromStored` (as the CLI
/// converts a PLY scene: LinPrim's octahedra get their vertices at two standard deviations).
pub fn as_method<P: FromStored>(gaussians: &[Params]) -> Vec<P> {
    gaussians
        .iter()
        .map(|g| {
            P::from_stored(&StoredGaussian {
                mean: g.mean,
                log_scale: g.log_scale,
                rotation: g.rotation,
                opacity_logit: g.opacity_logit,
                sh: g.sh,
            })
        })
        .collect()
}

pub fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Runs `f` for 0.3 s before timing it: a GPU left idle while the host worked (the one-shot
/// frames' uploads, say) runs at lower clocks until it has been busy a while (the CLI's
/// `warm_up` says more).
pub fn warm_up<T>(mut f: impl FnMut() -> T) {
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(300) {
        f();
    }
}

/// Element-wise minimum of the per-stage times of `runs` runs of `f`, after a [`warm_up`].
pub fn best<const K: usize>(runs: usize, mut f: impl FnMut() -> [Duration; K]) -> [Duration; K] {
    warm_up(&mut f);
    let mut out = [Duration::MAX; K];
    for _ in 0..runs {
        for (o, t) in out.iter_mut().zip(f()) {
            *o = (*o).min(t);
        }
    }
    out
}

/// Gradients of a frame's color, alpha and depth at `pixels` pixels, uniform in [-0.5, 0.5)
/// (a fixed seed).
pub fn random_grad(pixels: usize) -> FrameGrad {
    let mut rng = fastrand::Rng::with_seed(1);
    FrameGrad {
        color: (0..pixels * 3).map(|_| rng.f32() - 0.5).collect(),
        alpha: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
        depth: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
    }
}
