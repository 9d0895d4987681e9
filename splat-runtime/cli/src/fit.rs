//! `splat fit`: train 3DGS on a Blender-format dataset on the CPU, with a progress bar, the
//! held-out views' PSNR and SSIM before and after, and the result written as an INRIA PLY.

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::glam::Vec3;
use splat_runtime::io::dataset::read_blender;
use splat_runtime::io::ply::{self, GaussianCloud, StoredGaussian};
use splat_runtime::train::Trainable;
use splat_runtime::train::fit::{FitOptions, evaluate, fit};
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct FitArgs {
    /// Dataset folder holding transforms_train.json and transforms_test.json (Blender /
    /// NeRF-synthetic layout).
    #[arg(long)]
    data: PathBuf,
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
    let t = Instant::now();
    let data = read_blender(&args.data, background)?;
    if args.points == 0 {
        bail!("--points must be at least 1");
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
    let params = initial_points(args.points, mid, extent / 2.0, args.seed);
    let opts = FitOptions {
        steps: args.steps,
        background,
        seed: args.seed,
        ..Default::default()
    };
    let before = evaluate::<Method>(&params, &data.test, &opts)?;
    let bar = ProgressBar::new(args.steps as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps, {elapsed} (eta {eta}) {msg}")
            .expect("a valid template"),
    );
    let mut params = params;
    let t = Instant::now();
    fit::<Method>(&data, &mut params, extent, &opts, |step, v| {
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
    let after = evaluate::<Method>(&params, &data.test, &opts)?;
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
        gaussians: params.iter().map(stored).collect(),
    };
    ply::write(&args.out, &cloud).with_context(|| format!("writing {}", args.out.display()))?;
    println!("wrote {}", args.out.display());
    Ok(())
}

/// `n` Gaussians at random points of the cube of half-side `half` around `centre`, random
/// colors, sized to the points' mean spacing.
fn initial_points(n: usize, centre: Vec3, half: f32, seed: u64) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut unit = || Vec3::new(rng.f32(), rng.f32(), rng.f32());
    let spacing = 2.0 * half / (n as f32).cbrt();
    (0..n)
        .map(|_| {
            let p = centre + (unit() * 2.0 - 1.0) * half;
            Method::from_point(p, unit(), spacing)
        })
        .collect()
}

fn stored(p: &Params) -> StoredGaussian {
    StoredGaussian {
        mean: p.mean,
        log_scale: p.log_scale,
        rotation: p.rotation,
        opacity_logit: p.opacity_logit,
        sh: p.sh,
    }
}
