//! `splat fit`: train a Gaussian method (3DGS, 3DGUT, 3DGEER) on posed images on the CPU,
//! with a progress bar, the held-out views' PSNR and SSIM before and after, and the result
//! written as an INRIA PLY.

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use splat_methods::{ToStored, geer, gs3d, gut};
use splat_runtime::glam::Vec3;
use splat_runtime::io::dataset::{self, Dataset};
use splat_runtime::io::ply::{self, GaussianCloud};
use splat_runtime::train::Trainable;
use splat_runtime::train::fit::{FitOptions, evaluate, fit};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Clone, Copy, clap::ValueEnum, PartialEq, Eq)]
pub enum FitMethod {
    /// 3D Gaussian Splatting; pinhole cameras only.
    #[value(name = "3dgs")]
    Gs3d,
    /// 3DGUT; every camera model (fisheye images train as they are).
    #[value(name = "3dgut")]
    Gut,
    /// 3DGEER; every camera model.
    #[value(name = "3dgeer")]
    Geer,
}

#[derive(clap::Args)]
pub struct FitArgs {
    /// Dataset folder: Blender / NeRF-synthetic (transforms_train.json, transforms_test.json)
    /// or nerfstudio (transforms.json; every 8th view held out).
    #[arg(long)]
    data: PathBuf,
    #[arg(long, value_enum, default_value_t = FitMethod::Gs3d)]
    method: FitMethod,
    #[arg(long, default_value_t = 3000)]
    steps: usize,
    /// Random initial points in a cube around the cameras' target (Blender scenes have no
    /// point cloud).
    #[arg(long, default_value_t = 100_000)]
    points: usize,
    /// Composite the images on white instead of black.
    #[arg(long)]
    white: bool,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// The trained scene, as an INRIA 3DGS PLY.
    #[arg(long, default_value = "fit.ply")]
    out: PathBuf,
}

pub fn fit_cmd(args: &FitArgs) -> Result<()> {
    let background = if args.white { Vec3::ONE } else { Vec3::ZERO };
    if args.points == 0 {
        bail!("--points must be at least 1");
    }
    let t = Instant::now();
    let data = dataset::read(&args.data, background)?;
    if data.train.is_empty() {
        bail!("{}: no training views", args.data.display());
    }
    let first = &data.train[0];
    println!(
        "{}: {} training and {} test views of {}x{}, read in {:.1} s",
        args.data.display(),
        data.train.len(),
        data.test.len(),
        first.image.width,
        first.image.height,
        t.elapsed().as_secs_f64()
    );
    // The cameras' spread sets the scene's extent (3DGS scales position rates by it).
    let centres: Vec<Vec3> = data.train.iter().map(|v| v.camera.center()).collect();
    let mid = centres.iter().copied().sum::<Vec3>() / centres.len() as f32;
    let extent = 1.1 * centres.iter().map(|c| c.distance(mid)).fold(0.0, f32::max);
    let extent = if extent > 0.0 { extent } else { 1.0 };
    let opts = FitOptions {
        steps: args.steps,
        background,
        seed: args.seed,
        ..Default::default()
    };
    match args.method {
        FitMethod::Gs3d => train::<gs3d::Method>(args, &data, mid, extent, &opts),
        FitMethod::Gut => train::<gut::Method>(args, &data, mid, extent, &opts),
        FitMethod::Geer => train::<geer::Method>(args, &data, mid, extent, &opts),
    }
}

fn train<M: Trainable>(
    args: &FitArgs,
    data: &Dataset,
    mid: Vec3,
    extent: f32,
    opts: &FitOptions,
) -> Result<()>
where
    M::Params: ToStored,
{
    let mut params = initial_points::<M>(args.points, mid, extent / 2.0, args.seed);
    let before = evaluate::<M>(&params, &data.test, opts)?;
    let bar = ProgressBar::new(args.steps as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps, {elapsed} (eta {eta}) {msg}")
            .expect("a valid template"),
    );
    let t = Instant::now();
    fit::<M>(data, &mut params, extent, opts, |step, v| {
        bar.inc(1);
        if step % 10 == 0 {
            bar.set_message(format!(
                "loss {:.4} (L1 {:.4}, SSIM {:.3})",
                v.loss, v.l1, v.ssim
            ));
        }
    })?;
    bar.finish();
    let per_step = t.elapsed().as_secs_f64() / args.steps.max(1) as f64;
    let after = evaluate::<M>(&params, &data.test, opts)?;
    println!(
        "{} steps on the CPU, {:.1} ms per step; {} test views: PSNR {:.2} -> {:.2} dB, SSIM {:.3} -> {:.3}",
        args.steps,
        per_step * 1e3,
        after.views,
        before.psnr,
        after.psnr,
        before.ssim,
        after.ssim
    );
    let cloud = GaussianCloud {
        sh_degree: 3,
        gaussians: params.iter().map(ToStored::to_stored).collect(),
    };
    ply::write(&args.out, &cloud).with_context(|| format!("writing {}", args.out.display()))?;
    println!("wrote {}", args.out.display());
    Ok(())
}

/// `n` Gaussians at random points of the cube of half-side `half` around `centre`, random
/// colors, sized to the points' mean spacing.
fn initial_points<M: Trainable>(n: usize, centre: Vec3, half: f32, seed: u64) -> Vec<M::Params> {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut unit = || Vec3::new(rng.f32(), rng.f32(), rng.f32());
    let spacing = 2.0 * half / (n as f32).cbrt();
    (0..n)
        .map(|_| {
            let p = centre + (unit() * 2.0 - 1.0) * half;
            M::from_point(p, unit(), spacing)
        })
        .collect()
}
