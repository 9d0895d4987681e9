//! The methods side by side on one scene (CPU backend): forward and backward time per camera
//! model, what each tile cull saves, and what the approximations cost in accuracy: 3DGS (EWA)
//! and 3DGUT (unscented transform, max response) against 3DGEER's exact ray integral, as PSNR
//! on each camera model (the wide ones about 150 degrees across). Times are best of 3 after a warm-up, ratios against 3DGS on the
//! pinhole camera in the same run.
//!
//! `cargo bench -p splat-methods --bench methods [-- N WIDTH HEIGHT]`

use splat_methods::{geer, gs3d, gut, linprim};
use splat_runtime::glam::Vec2;
use splat_runtime::{
    Camera, CameraModel, Frame, FrameGrad, RenderOptions, SplatMethod, backward, render,
    render_for_backward,
};
use std::time::{Duration, Instant};

mod common;
use common::{as_method, camera, scene, size_args};

fn best_of_3(mut f: impl FnMut()) -> Duration {
    f();
    (0..3)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed()
        })
        .min()
        .unwrap()
}

struct Row {
    forward: Duration,
    backward: Duration,
    frame: Frame,
    culled: Option<usize>,
}

fn run<M: SplatMethod>(params: &[M::Params], cam: &Camera) -> Row {
    let opts = RenderOptions::default();
    let mut frame = None;
    let forward = best_of_3(|| frame = Some(render::<M>(params, cam, &opts).unwrap()));
    let frame = frame.unwrap();
    let (_, state) = render_for_backward::<M>(params, cam, &opts).unwrap();
    let grad = FrameGrad {
        color: vec![1.0; frame.color.data.len()],
        alpha: None,
        depth: None,
    };
    let backward = best_of_3(|| {
        backward::<M>(&state, params, cam, &grad).unwrap();
    });
    let culled = M::HAS_TILE_CULL.then(|| {
        let all = RenderOptions {
            tile_cull: false,
            ..opts
        };
        render::<M>(params, cam, &all).unwrap().stats.intersections
    });
    Row {
        forward,
        backward,
        frame,
        culled,
    }
}

fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| ((x.clamp(0.0, 1.0) - y.clamp(0.0, 1.0)) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (1.0 / mse).log10()
}

fn main() {
    let (n, w, h) = size_args(100_000, 960, 540);
    let gaussians = scene(n);
    let gut_params: Vec<gut::Params> = as_method(&gaussians);
    let lin_params: Vec<linprim::Params> = as_method(&gaussians);
    let geer_params: Vec<geer::Params> = as_method(&gaussians);
    println!(
        "{n} Gaussians (SH degree 3), {w}x{h}, {} threads, tile 16",
        rayon::current_num_threads()
    );
    println!(
        "| method | camera | forward (ms) | backward (ms) | forward vs 3DGS pinhole | intersections | without tile_cull |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|");
    let mut baseline = None;
    // Per camera model: the approximations' frames, then 3DGEER's.
    let mut approx = vec![];
    let mut exact = vec![];
    let mut report = |name: &str, model: CameraModel, r: Row| {
        let base = *baseline.get_or_insert(r.forward.as_secs_f64());
        println!(
            "| {name} | {model} | {:.1} | {:.1} | {:.2} | {} | {} |",
            r.forward.as_secs_f64() * 1e3,
            r.backward.as_secs_f64() * 1e3,
            r.forward.as_secs_f64() / base,
            r.frame.stats.intersections,
            r.culled.map_or("-".into(), |c| c.to_string()),
        );
        r.frame
    };
    for model in CameraModel::ALL {
        let mut cam = camera(w, h);
        cam.model = model;
        if model != CameraModel::Pinhole {
            // About 150 degrees across for the wide models.
            cam.focal = Vec2::splat(w / 2.6);
        }
        let f = report("3DGS", model, run::<gs3d::Method>(&gaussians, &cam));
        approx.push(("3DGS (EWA)", model, f));
        let f = report("3DGUT", model, run::<gut::Method>(&gut_params, &cam));
        approx.push(("3DGUT (UT, max response)", model, f));
        if model == CameraModel::Pinhole {
            report("LinPrim", model, run::<linprim::Method>(&lin_params, &cam));
        }
        let f = report("3DGEER", model, run::<geer::Method>(&geer_params, &cam));
        exact.push((model, f));
    }
    println!("\nAgainst 3DGEER's exact ray integral (same Gaussians, same camera):");
    for (name, model, f) in approx {
        let (_, exact) = exact.iter().find(|(m, _)| *m == model).unwrap();
        println!(
            "  {name}, {model}: PSNR {:.2} dB",
            psnr(&f.color.data, &exact.color.data)
        );
    }
}
