//! `splat fit`: train a method on posed images, on the GPU or the CPU, with a progress bar, the
//! held-out views' PSNR and SSIM before and after, and the result written as an INRIA PLY.

use crate::methods::{self, Method};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use splat_runtime::glam::Vec3;
use splat_runtime::io::dataset::{self, Dataset};
use splat_runtime::io::ply::{self, GaussianCloud, ToStored};
use splat_runtime::train::fit::{FitOptions, StepReport, evaluate, fit};
use splat_runtime::train::gpu_fit::fit_gpu;
use splat_runtime::train::{Trainable, init};
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct FitArgs {
    /// Dataset folder: Blender / NeRF-synthetic (transforms_train.json, transforms_test.json),
    /// nerfstudio (transforms.json; every 8th view held out) or COLMAP (a sparse model in
    /// sparse/0 or sparse, the pictures in images; every 8th view by name held out; training
    /// starts from the model's points).
    #[arg(long)]
    data: PathBuf,
    /// The method to train (one that implements `Trainable`).
    #[arg(long)]
    method: String,
    #[arg(long, default_value_t = 3000)]
    steps: usize,
    /// How many points to start from: at most this many of the dataset's points (evenly
    /// spaced), or as many random ones in a cube around the cameras' target when it has none
    /// (Blender and nerfstudio scenes).
    #[arg(long, default_value_t = 100_000)]
    points: usize,
    /// Composite the images on white instead of black.
    #[arg(long)]
    white: bool,
    /// A random background color per step (transparent parts of the images re-composited on
    /// it), so the scene cannot paint the background in; evaluation stays on black or white.
    #[arg(long)]
    random_background: bool,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Keep the primitive count fixed (no adaptive density control: cloning, splitting,
    /// pruning, opacity resets).
    #[arg(long)]
    no_densify: bool,
    /// Where to train: the GPU (the device-resident loop), the CPU, or `auto` (a hardware
    /// GPU when there is one).
    #[arg(long, value_enum, default_value_t = crate::Backend::Auto)]
    backend: crate::Backend,
    /// The trained scene, as an INRIA 3DGS PLY.
    #[arg(long, default_value = "fit.ply")]
    out: PathBuf,
}

pub fn fit_cmd(args: &FitArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    let Some(train) = method.full().fit else {
        bail!(
            "{} cannot be trained: it does not declare how (splat_runtime::train::Trainable)",
            method.name
        );
    };
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
    methods::check_camera(method, methods, first.camera.model)?;
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
        densify: (!args.no_densify).then(Default::default),
        random_background: args.random_background,
        ..Default::default()
    };
    train(&Fit {
        args,
        data: &data,
        mid,
        extent,
        opts: &opts,
    })
}

/// A training run, for any method.
pub struct Fit<'a> {
    args: &'a FitArgs,
    data: &'a Dataset,
    /// The cameras' centre and the scene's radius.
    mid: Vec3,
    extent: f32,
    opts: &'a FitOptions,
}

impl Fit<'_> {
    pub(crate) fn run<M: Trainable>(&self) -> Result<()>
    where
        M::Params: ToStored,
    {
        let Fit {
            args,
            data,
            mid,
            extent,
            opts,
        } = *self;
        let mut params = if data.points.is_empty() {
            init::in_cube::<M>(args.points, mid, extent / 2.0, args.seed)
        } else {
            let params = init::from_points::<M>(&data.points, args.points);
            println!(
                "starting from {} of the dataset's {} points",
                params.len(),
                data.points.len()
            );
            params
        };
        let before = evaluate::<M>(&params, &data.test, opts)?;
        let bar = ProgressBar::new(args.steps as u64).with_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} steps, {elapsed} (eta {eta}) {msg}")
                .expect("a valid template"),
        );
        let report = |r: &StepReport| {
            bar.inc(1);
            if r.step.is_multiple_of(10) || r.refinement.is_some() {
                let v = r.loss;
                bar.set_message(format!(
                    "loss {:.4} (L1 {:.4}, SSIM {:.3}), {} primitives",
                    v.loss, v.l1, v.ssim, r.primitives
                ));
            }
        };
        let gpu = crate::pick_gpu(args.backend)?;
        let t = Instant::now();
        let place = match &gpu {
            Some(gpu) => {
                fit_gpu::<M>(gpu, data, &mut params, extent, opts, report)?;
                format!("the GPU ({})", gpu.adapter)
            }
            None => {
                fit::<M>(data, &mut params, extent, opts, report)?;
                "the CPU".to_string()
            }
        };
        bar.finish();
        let per_step = t.elapsed().as_secs_f64() / args.steps.max(1) as f64;
        let after = evaluate::<M>(&params, &data.test, opts)?;
        println!(
            "{} steps on {place}, {:.1} ms per step, {} primitives; {} test views: PSNR {:.2} -> {:.2} dB, SSIM {:.3} -> {:.3}",
            args.steps,
            per_step * 1e3,
            params.len(),
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
        crate::wrote(&args.out);
        Ok(())
    }
}
