//! `splat eval`: a scene measured on a dataset's views as `splat fit` measures its result:
//! each view rendered, composited on the background and compared with its picture (PSNR,
//! SSIM); the mean, the worst and best views, and with `--out` the renders and a CSV. For a
//! scene trained by `splat fit` or by another program, in any format splat reads. With
//! `--formats`, what each file format costs it instead ([`crate::format_costs`]).

use crate::Backend;
use crate::commands::render;
use crate::format_costs;
use crate::methods::{self, Method};
use crate::view::{Downscale, Split, undistorted};
use anyhow::{Context, Result};
use splat_runtime::glam::Vec3;
use splat_runtime::io::Outputs;
use splat_runtime::io::dataset::{self, Shot};
use splat_runtime::io::formats::Format;
use splat_runtime::io::image::stage_image;
use splat_runtime::io::ply::GaussianCloud;
use splat_runtime::train::fit::composite;
use splat_runtime::train::loss;
use splat_runtime::{Camera, RenderOptions};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// Dataset folder (Blender, nerfstudio or COLMAP, as `splat fit` reads it).
    dataset: PathBuf,
    /// The scene to measure (.ply, .compressed.ply, .splat, .spz or .sog; `splat fit`
    /// writes scene.ply).
    #[arg(long)]
    scene: PathBuf,
    #[arg(long)]
    method: String,
    /// Which views: the held-out ones or the training ones (the splits `splat fit` uses).
    #[arg(long, value_enum, default_value_t = Split::Test)]
    split: Split,
    /// Composite the renders and pictures on white instead of black (as `splat fit --white`).
    #[arg(long)]
    white: bool,
    #[command(flatten)]
    downscale: Downscale,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// Instead, write the scene in every format splat writes, read each back and measure its
    /// renders: file size against PSNR and SSIM to the pictures and PSNR to the PLY's renders
    /// (with --out: formats.csv and formats.png, no renders).
    #[arg(long)]
    formats: bool,
    /// Output folder: every view's render (`<split>/000.png`, ... in the dataset's order) and
    /// `eval.csv` (view, picture, PSNR, SSIM).
    #[arg(long)]
    out: Option<PathBuf>,
}

/// One view's measures.
struct Measured {
    shot: Shot,
    psnr: f64,
    ssim: f64,
}

pub(crate) fn eval_cmd(args: &EvalArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    let cloud = crate::scene::read(&args.scene)?;
    method.note_antialiasing(&cloud);
    let shots = args.split.of(dataset::read_shots(&args.dataset)?);
    let shots = dataset::downscaled(shots, args.downscale.factor)?;
    let taken = args.downscale.how(&shots) + &undistorted(&shots);
    let split = args.split.name();
    if shots.is_empty() {
        anyhow::bail!("{}: no {split} views", args.dataset.display());
    }
    for shot in &shots {
        methods::check_camera(method, methods, &shot.camera)?;
    }
    if let Some(out) = &args.out.as_ref().filter(|_| !args.formats) {
        let pictures = shots.iter().map(|s| s.path.as_path());
        crate::check_renders_spare(&out.join(split), shots.len(), pictures)?;
    }
    let background = if args.white { Vec3::ONE } else { Vec3::ZERO };
    // As `splat fit` renders its test views: alpha for the background, the default knobs.
    let opts = RenderOptions {
        alpha: true,
        ..Default::default()
    };
    let gpu = crate::pick_gpu(args.backend)?;
    if args.formats {
        let pictures = (shots.iter())
            .map(|s| Ok(s.load(background)?.into_image()))
            .collect::<Result<Vec<_>>>()?;
        let cameras: Vec<_> = shots.iter().map(|s| s.camera).collect();
        let views = format_costs::Views {
            method,
            cameras: &cameras,
            pictures: &pictures,
            background,
            opts: &opts,
            gpu: gpu.as_ref(),
        };
        let bar = indicatif::ProgressBar::new((Format::ALL.len() * shots.len()) as u64);
        let costs = format_costs::measure(&cloud, &views, &bar)?;
        bar.finish_and_clear();
        let what = format!("{} in every format", method.name);
        println!("{}", heading(&what, &cloud, args, &cameras, &taken));
        format_costs::print_table(&costs, cloud.gaussians.len());
        if let Some(out) = &args.out {
            let mut outputs = Outputs::default();
            let title = format!(
                "{} on {} {split} views of {}",
                args.scene.display(),
                shots.len(),
                args.dataset.display()
            );
            format_costs::stage_outputs(&mut outputs, out, &costs, &title)?;
            outputs.commit()?;
            crate::wrote(out);
        }
        return Ok(());
    }
    let bar = indicatif::ProgressBar::new(shots.len() as u64);
    let mut measured = Vec::with_capacity(shots.len());
    let mut outputs = Outputs::default();
    let cameras: Vec<_> = shots.iter().map(|s| s.camera).collect();
    let mut shots = shots.into_iter();
    let mut measure = |frame: splat_runtime::Frame| {
        let (k, shot) = (measured.len(), shots.next().expect("a shot per camera"));
        let picture = shot.load(background)?.into_image();
        let image = composite(frame.color, frame.alpha.as_ref(), background);
        let psnr = loss::psnr(&image, &picture)?;
        let ssim = loss::ssim(&image, &picture)?;
        if let Some(out) = &args.out {
            let path = out.join(split).join(crate::render_name(k));
            stage_image(&mut outputs, &path, &image)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        measured.push(Measured { shot, psnr, ssim });
        bar.inc(1);
        Ok(())
    };
    let place = render::render_views(
        method,
        &cloud,
        &cameras,
        (&opts, gpu.as_ref(), false),
        &mut measure,
    )?;
    bar.finish_and_clear();

    // Summed as `splat fit` sums its evaluation (`train::fit::Evaluation`), to the last bit.
    let n = measured.len() as f64;
    let mean = |f: fn(&Measured) -> f64| measured.iter().map(|m| f(m) / n).sum::<f64>();
    let what = format!("{} on {place}", method.name);
    println!("{}", heading(&what, &cloud, args, &cameras, &taken));
    println!(
        "mean PSNR {:.2} dB, SSIM {:.4} (on {})",
        mean(|m| m.psnr),
        mean(|m| m.ssim),
        if args.white { "white" } else { "black" }
    );
    let by_psnr = |a: &&Measured, b: &&Measured| a.psnr.total_cmp(&b.psnr);
    let worst = measured.iter().min_by(by_psnr).expect("at least one view");
    let best = measured.iter().max_by(by_psnr).expect("at least one view");
    for (what, m) in [("worst", worst), ("best", best)] {
        println!(
            "{what}: {:.2} dB, SSIM {:.4}, {}",
            m.psnr,
            m.ssim,
            m.shot.path.display()
        );
    }
    if let Some(out) = &args.out {
        let csv = out.join("eval.csv");
        (outputs.stage(&csv, |w| {
            writeln!(w, "view,picture,psnr,ssim")?;
            for (k, m) in measured.iter().enumerate() {
                let picture = m.shot.path.display().to_string().replace('"', "\"\"");
                writeln!(w, "{split}/{k},\"{picture}\",{:.4},{:.6}", m.psnr, m.ssim)?;
            }
            Ok(())
        }))
        .with_context(|| format!("writing {}", csv.display()))?;
        outputs.commit()?;
        crate::remove_stale_renders(&out.join(split), measured.len())?;
        crate::wrote(out);
    }
    Ok(())
}

/// The views' size, or the range of their sizes when they differ.
/// What an evaluation measures, before its figures: `what` (the method, where it ran), the
/// scene, and the views (their count, sizes and how they were taken).
fn heading(
    what: &str,
    cloud: &GaussianCloud,
    args: &EvalArgs,
    cameras: &[Camera],
    taken: &str,
) -> String {
    format!(
        "{what}: {} primitives (SH degree {}) from {}, {} {} views of {}, {}{taken}",
        cloud.gaussians.len(),
        cloud.sh_degree,
        args.scene.display(),
        cameras.len(),
        args.split.name(),
        args.dataset.display(),
        sizes(cameras),
    )
}

fn sizes(cameras: &[Camera]) -> String {
    let size = |c: &Camera| (c.size.x as u32, c.size.y as u32);
    let (smallest, largest) = (
        cameras.iter().map(size).min(),
        cameras.iter().map(size).max(),
    );
    match (smallest, largest) {
        (Some(a), Some(b)) if a == b => format!("{}x{}", a.0, a.1),
        (Some(a), Some(b)) => format!("{}x{} to {}x{}", a.0, a.1, b.0, b.1),
        _ => String::new(),
    }
}
