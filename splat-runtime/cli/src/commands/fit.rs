//! `splat fit`: checks the flags, reads the dataset or builds the built-in one, finds the method
//! and where to train, and runs its [`Fit`] job.

use crate::fit::{
    CHECKPOINT, CURVE, Fit, FitArgs, METRICS, StrategyArg, frozen_and_trained, scene_file,
};
use crate::methods::{self, Method};
use crate::ranks::Ranks;
use crate::view::undistorted;
use crate::{memory, scene};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use splat_runtime::frame::MAX_SIDE;
use splat_runtime::glam::Vec3;
use splat_runtime::io::dataset;
use splat_runtime::io::formats::Format;
use splat_runtime::train::fit::{CPU_STEP_BYTES_PER_PIXEL, FitOptions};
use splat_runtime::train::loss::WINDOW;
use splat_runtime::train::per_view::PerViewOptions;
use splat_runtime::train::{Checkpoint, DensifyOptions, McmcOptions, Strategy};
use std::path::Path;
use std::time::Instant;

/// The knobs whose defaults depend on the dataset.
struct Defaults {
    steps: usize,
    points: usize,
    /// `None`: the strategy's own default.
    max_primitives: Option<usize>,
    init_extent: f32,
}

/// For a dataset folder: gsplat's defaults for a 7,000-step run.
const DATASET_DEFAULTS: Defaults = Defaults {
    steps: 7000,
    points: 100_000,
    max_primitives: None,
    init_extent: 3.0,
};

/// The defaults that train the built-in dataset in under a minute on 2 cores.
const BUILT_IN_DEFAULTS: Defaults = Defaults {
    steps: 2000,
    points: 2000,
    max_primitives: Some(6000),
    init_extent: 0.5,
};

/// Refuses an output folder where one of the run's files is a folder: found now, not after
/// hours of training.
fn check_out_files(out: &Path, exports: &[Format]) -> Result<()> {
    let scenes = [Format::Ply].iter().chain(exports).map(|f| scene_file(*f));
    let names = [CHECKPOINT, METRICS, CURVE].map(String::from);
    for name in names.into_iter().chain(scenes) {
        let path = out.join(&name);
        if path.is_dir() {
            bail!(
                "--out {}: {} is a folder, and the run writes its {name} there",
                out.display(),
                path.display()
            );
        }
    }
    Ok(())
}

/// Refuses knobs out of their range before the dataset is read (which can take minutes).
fn check_knobs(args: &FitArgs) -> Result<()> {
    let positive = |v: f32| v > 0.0 && v.is_finite();
    if args.points == Some(0) {
        bail!("--points must be at least 1");
    }
    if let Some(e) = args.init_extent.filter(|e| !positive(*e)) {
        bail!("--init-extent must be a positive number, not {e}");
    }
    if let Some(s) = args.init_size.filter(|s| !positive(*s)) {
        bail!("--init-size must be a positive number, not {s}");
    }
    if args.no_opacity_reset && !matches!(args.strategy, StrategyArg::Adc) {
        bail!("--no-opacity-reset is for --strategy adc, the only one that resets opacities");
    }
    if args.sharded && matches!(args.strategy, StrategyArg::Mcmc) {
        bail!(
            "--sharded cannot take --strategy mcmc: its relocations draw from the whole scene's opacities (shard with adc or fixed)"
        );
    }
    if args.sharded && args.view {
        bail!(
            "--view shows the whole scene as it trains, which a sharded run holds on no rank (view a run without --sharded, or its checkpoints)"
        );
    }
    if args.hardware && args.sharded {
        bail!("--hardware trains the whole scene on each rank: it does not shard (drop one)");
    }
    if args.hardware && matches!(args.backend, crate::Backend::Cpu) {
        bail!("--hardware draws each view with the GPU's rasterizer: use --backend gpu or auto");
    }
    if !positive(args.global_scale) {
        bail!(
            "--global-scale must be a positive number, not {}",
            args.global_scale
        );
    }
    Ok(())
}

/// The device `--hardware` trains on: the first adapter, opened with rasterization-order
/// attachment access.
fn hardware_gpu() -> Result<splat_runtime::gpu::Gpu> {
    match splat_runtime::gpu::programmable_blend::open()? {
        Some(gpu) => Ok(gpu),
        None => bail!(
            "--hardware: this GPU lacks VK_EXT_rasterization_order_attachment_access (its fragments cannot read their pixel in order); train without --hardware"
        ),
    }
}

pub fn fit_cmd(args: &FitArgs, methods: &[Method]) -> Result<()> {
    let ranks = Ranks::join()?;
    fit_on(args, methods, &ranks).or_else(|e| ranks.fail(e))
}

/// `splat fit` as one of `ranks` (alone, or one of an MPI launch's).
fn fit_on(args: &FitArgs, methods: &[Method], ranks: &Ranks) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    let Some(train) = method.full().fit else {
        bail!(
            "{} cannot be trained: it does not declare how (splat_runtime::train::Trainable)",
            method.name
        );
    };
    if let (Some(what), false) = (method.not_gaussians, args.export.is_empty()) {
        bail!(
            "--export: {}'s primitives are {what}, which the viewers of the other formats would \
             draw as Gaussians; its scene.ply stores each as the Gaussian closest to it (for \
             splat's methods to read back), and `splat convert` converts that knowingly",
            method.name
        );
    }
    crate::check_out_folder(&args.out)?;
    check_out_files(&args.out, &args.export)?;
    check_knobs(args)?;
    let groups = method.full().param_fields.iter().map(|(name, _)| *name);
    frozen_and_trained(&groups.collect::<Vec<_>>(), &args.freeze, method.name)?;
    // Picked first: the memory a run needs depends on where it trains. Ranks on one machine
    // take one GPU each, in turn.
    let gpu = match args.hardware {
        true => Some(hardware_gpu()?),
        false => crate::pick_gpu_of(args.backend, ranks.local_rank())?,
    };
    let background = if args.white { Vec3::ONE } else { Vec3::ZERO };
    let t = Instant::now();
    let loaded = (|| -> Result<_> {
        Ok(match &args.dataset {
            Some(dir) => {
                let name = dir.display().to_string();
                let full = dataset::read_shots(dir)?;
                let shots = full.clone().downscaled(args.downscale.factor)?;
                if let Some(room) = memory::available() {
                    let demand = memory::Demand {
                        threads: rayon::current_num_threads(),
                        step: gpu.is_none().then_some(CPU_STEP_BYTES_PER_PIXEL),
                    };
                    memory::check_room(
                        &name,
                        (&full, &shots),
                        args.downscale.factor,
                        room,
                        demand,
                    )?;
                }
                let all = || shots.train.iter().chain(&shots.test);
                let pictures = all().map(|s| s.path.as_path());
                crate::check_renders_spare(&args.out.join("test"), shots.test.len(), pictures)?;
                let taken = args.downscale.how(all()) + &undistorted(all());
                let bar = ProgressBar::new(all().count() as u64).with_style(
                    ProgressStyle::with_template(
                        "{bar:40} {pos}/{len} pictures decoded, {elapsed}",
                    )
                    .expect("a valid template"),
                );
                let data = shots.load_counted(background, &|| bar.inc(1))?;
                bar.finish_and_clear();
                (data, name, DATASET_DEFAULTS, taken)
            }
            None if args.downscale.factor != 1 => {
                bail!("--downscale applies to a dataset's pictures, and none was given")
            }
            None => {
                let (views, width, height) = scene::DATASET;
                (
                    scene::dataset(views, width, height, background)?,
                    "the built-in dataset".to_string(),
                    BUILT_IN_DEFAULTS,
                    String::new(),
                )
            }
        })
    })();
    // Every rank trains on the same views: one that cannot read them stops all before the
    // first step.
    let fingerprint = loaded.as_ref().map(|l| l.0.fingerprint());
    let same = "the ranks must read the same files (a folder every node sees, or identical copies)";
    ranks.agree("dataset", &fingerprint.map_err(|e| format!("{e:#}")), same)?;
    let (data, name, defaults, taken) = loaded?;
    let resume = match args.resume {
        true => {
            let path = args.out.join(CHECKPOINT);
            // Rank 0 reads it (the others may not see its folder) and hands it to the others.
            let c = match ranks.is_root() {
                true => Some(Checkpoint::read(&path)?),
                false => None,
            };
            let bytes = ranks.broadcast(c.map(|c| c.to_bytes()).transpose()?)?;
            let c = Checkpoint::parse(&bytes, &path)?;
            if let Some(steps) = args.steps.filter(|s| *s != c.steps) {
                bail!(
                    "{} is a checkpoint of a {}-step run, not {steps} (the learning rates follow the run's length): leave --steps out",
                    path.display(),
                    c.steps
                );
            }
            println!(
                "resuming from {} after step {} of {}",
                path.display(),
                c.step,
                c.steps
            );
            Some(c)
        }
        false => {
            let earlier = args.out.join(CHECKPOINT);
            if earlier.exists() {
                println!(
                    "note: {} is an earlier run's; this run replaces it (--resume goes on from it instead)",
                    earlier.display()
                );
            }
            None
        }
    };
    let steps = (args.steps)
        .or(resume.as_ref().map(|c| c.steps))
        .unwrap_or(defaults.steps);
    let points = args.points.unwrap_or(defaults.points);
    let max_primitives = args.max_primitives.or(defaults.max_primitives);
    let init_extent = args.init_extent.unwrap_or(defaults.init_extent);
    if data.train.is_empty() {
        bail!("{name}: no training views");
    }
    // Refused here, by file, rather than at the first step or evaluation that meets them.
    for view in data.train.iter().chain(&data.test) {
        let (w, h) = view.size();
        let side = WINDOW as u32..=MAX_SIDE;
        if !(side.contains(&w) && side.contains(&h)) {
            // The view, not the picture, where a --downscale or an undistortion made it.
            let what = match taken.is_empty() {
                true => format!("{} is", view.name),
                false => format!("the view of {} is", view.name),
            };
            bail!(
                "{what} {w}x{h} pixels{taken}: training takes views of {WINDOW} (the loss's SSIM window) to {MAX_SIDE} pixels a side"
            );
        }
    }
    let first = &data.train[0];
    methods::check_camera(method, methods, &first.camera)?;
    let (width, height) = first.size();
    println!(
        "{name}: {} training and {} of {width}x{height}{taken}, read in {:.1} s",
        data.train.len(),
        crate::count(data.test.len(), "test view"),
        t.elapsed().as_secs_f64()
    );
    // The cameras' spread sets the scene's extent (3DGS scales position rates by it).
    let centres: Vec<Vec3> = data.train.iter().map(|v| v.camera.center()).collect();
    let mid = centres.iter().copied().sum::<Vec3>() / centres.len() as f32;
    let extent = 1.1 * centres.iter().map(|c| c.distance(mid)).fold(0.0, f32::max);
    let extent = if extent > 0.0 { extent } else { 1.0 } * args.global_scale;
    if let (StrategyArg::Fixed, Some(cap)) = (&args.strategy, args.max_primitives) {
        bail!(
            "--max-primitives {cap}: the cap is on density control's growth, and --strategy fixed keeps the primitives it starts with"
        );
    }
    let opts = FitOptions {
        steps,
        batch: args.batch as usize,
        background,
        seed: args.seed,
        densify: match args.strategy {
            StrategyArg::Adc => {
                let d = DensifyOptions::default();
                Some(Strategy::Adc(DensifyOptions {
                    max_primitives: max_primitives.unwrap_or(d.max_primitives),
                    opacity_resets: !args.no_opacity_reset,
                    ..d
                }))
            }
            StrategyArg::Mcmc => {
                let m = McmcOptions::default();
                Some(Strategy::Mcmc(McmcOptions {
                    max_primitives: max_primitives.unwrap_or(m.max_primitives),
                    ..m
                }))
            }
            StrategyArg::Fixed => None,
        },
        random_background: args.random_background,
        per_view: PerViewOptions {
            exposure: args.exposure,
            pose: args.pose_opt,
            intrinsics: args.intrinsics_opt,
        },
        eval_every: (args.eval_every > 0).then_some(args.eval_every),
        checkpoint_every: (args.checkpoint_every > 0).then_some(args.checkpoint_every),
        ..Default::default()
    };
    // Tried before training, not with the outputs at its end: an output folder that cannot be
    // made fails the command before hours of training. The renders' folder is made again with
    // them, so a run stopped early leaves none empty.
    // Rank 0 alone writes outputs.
    let renders = args.out.join("test");
    let made = !renders.exists();
    if ranks.is_root() {
        std::fs::create_dir_all(&renders)
            .with_context(|| format!("creating {}", renders.display()))?;
        if made {
            std::fs::remove_dir(&renders)
                .with_context(|| format!("removing {} (made to try)", renders.display()))?;
        }
    }
    train(&Fit {
        args,
        methods,
        ranks,
        gpu,
        data: &data,
        resume,
        points,
        mid,
        extent,
        init_extent,
        opts: &opts,
    })
}
