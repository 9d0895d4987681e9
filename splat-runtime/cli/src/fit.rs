//! `splat fit`: train a method on posed images (a dataset folder, or the built-in dataset), on
//! the GPU or the CPU, with a progress bar; the held-out views' PSNR and SSIM measured during
//! training; the result written as an INRIA PLY beside the test renders, the metrics as CSV
//! and the training curve as a plot.

use crate::fit_view::FitView;
use crate::interrupt::Listening;
use crate::ranks::Ranks;
use crate::view::Downscale;
use crate::{memory, methods, plot};
use anyhow::{Context, Result, anyhow, bail};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;
use splat_runtime::glam::Vec3;
use splat_runtime::gpu::Gpu;
use splat_runtime::io::Outputs;
use splat_runtime::io::dataset::{Dataset, View};
use splat_runtime::io::formats::{self, Format};
use splat_runtime::io::image::stage_image;
use splat_runtime::io::ply::{GaussianCloud, ToStored};
use splat_runtime::train::batch::batches;
use splat_runtime::train::fit::{
    Evaluation, FitError, FitOptions, StepReport, fit_shared, refuse_other_settings, render_views,
};
use splat_runtime::train::gpu_fit::{fit_gpu_shared, render_views_gpu};
use splat_runtime::train::hardware_fit::fit_hardware_shared;
use splat_runtime::train::loss::LossValue;
use splat_runtime::train::per_view::{Cameras, PerViewOptions};
use splat_runtime::train::sharded::{fit_sharded, fit_sharded_gpu};
use splat_runtime::train::{Checkpoint, McmcOptions, StepTimes, Strategy, Trainable, init};
use splat_runtime::{Effects, Flat, GradientSet, Image, RenderOptions, param_groups};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct FitArgs {
    /// Dataset folder: Blender / NeRF-synthetic (transforms_train.json, transforms_test.json),
    /// nerfstudio (transforms.json; every 8th view held out) or COLMAP (a sparse model in
    /// sparse/0 or sparse, the pictures in images; every 8th view by name held out; training
    /// starts from the model's points). Without one: the built-in dataset, 32 views of the
    /// built-in planet (112x84, rendered by 3DGS), which trains in under a minute on 2 cores.
    pub(crate) dataset: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) downscale: Downscale,
    /// The method to train (one that implements `Trainable`).
    #[arg(long)]
    pub(crate) method: String,
    /// Training steps, one view each [default: 7000; 2000 on the built-in dataset].
    #[arg(long)]
    pub(crate) steps: Option<usize>,
    /// Views per Adam step: their losses' gradients summed, the learning rates times
    /// sqrt(batch) and Adam's betas to the power batch (Grendel-GS's rule). --steps and every
    /// schedule still count views: --steps 7000 --batch 4 takes 1,750 Adam steps. Under
    /// `mpirun` the ranks share each batch's views (docs/distributed.md).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub(crate) batch: u32,
    /// Under `mpirun`, each rank holds a slice of the scene (its primitives, their Adam
    /// moments and density statistics) instead of all of it, and the ranks exchange each
    /// view's visible primitives and their gradients: for scenes past one process's memory.
    /// The same steps as the ranks sharing the views with the whole scene each (on the CPU
    /// bit for bit at the same thread count per rank; on GPUs, whose gradient sums are in no
    /// fixed order, the same training). With --strategy adc or fixed, without --view
    /// (docs/distributed.md).
    #[arg(long)]
    pub(crate) sharded: bool,
    /// Each view drawn by the GPU's rasterizer (quads blended in the fragment shaders, in
    /// rasterization order) and differentiated by the hardware path's own backward pass; the
    /// loss, Adam and density control on the host. Needs a Vulkan adapter with
    /// VK_EXT_rasterization_order_attachment_access (lavapipe has it). Slow: each view uploads
    /// the scene and reads frame and gradients back (docs/accuracy.md).
    #[arg(long)]
    pub(crate) hardware: bool,
    /// How many points to start from: at most this many of the dataset's points (evenly
    /// spaced), or as many random ones in a cube around the cameras' target when it has none
    /// (Blender and nerfstudio scenes) [default: 100000; 2000 on the built-in dataset].
    #[arg(long)]
    pub(crate) points: Option<usize>,
    /// The random points' cube: its half-side in units of the scene's extent (the cameras'
    /// largest distance from their centre, times 1.1 and --global-scale), as gsplat's
    /// `init_extent` [default: 3; 0.5 on the built-in dataset].
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) init_extent: Option<f32>,
    /// Start every primitive at this size (the dataset's world units) instead of
    /// the root mean square distance to its 3 nearest neighbours, as 3DGS sizes them
    /// (shared/bench/gsplat_train.py starts at 0.02).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) init_size: Option<f32>,
    /// Start every primitive with this color, `R,G,B` in [0, 1] as the images store it,
    /// instead of its point's (random ones: a random color; gsplat_train.py starts at
    /// 0.5,0.5,0.5).
    #[arg(long, value_parser = parse_color)]
    pub(crate) init_color: Option<Vec3>,
    /// Multiplies the scene's extent, as gsplat's `global_scale`: the position learning rate,
    /// density control's size thresholds and the random points' cube scale with it. Objects
    /// that fill little of the cameras' sphere train better with less than 1 (a resumed run
    /// must pass the same value).
    #[arg(long, allow_negative_numbers = true, default_value_t = 1.0)]
    pub(crate) global_scale: f32,
    /// Composite the images on white instead of black.
    #[arg(long)]
    pub(crate) white: bool,
    /// Learn each training view's exposure and white balance (a gain per color channel, as
    /// INRIA's exposure compensation), for pictures taken at different settings; from a sixth
    /// of the run on. Held-out views are rendered at the training views' mean exposure; the
    /// gains are written to <out>/exposure.json. On the CPU and --hardware loops, one process.
    #[arg(long)]
    pub(crate) exposure: bool,
    /// Refine each training view's pose (a turn about its camera's centre and a shift along
    /// its axes, as gsplat's pose_opt, from the camera gradient of every backward pass,
    /// through any camera model), for poses from structure from motion. Held-out views keep
    /// their poses, as gsplat's do. On the CPU and --hardware loops, one process.
    #[arg(long)]
    pub(crate) pose_opt: bool,
    /// Refine each camera's intrinsics (focal lengths, principal point, and the lens
    /// coefficients of a fisheye) from the camera gradient of every backward pass, for
    /// cameras calibrated from the pictures themselves (structure from motion is easily 10%
    /// off on few or small pictures). Views of equal intrinsics share a camera, held-out ones
    /// too. The cameras are written to <out>/intrinsics.json. On the CPU and --hardware loops,
    /// one process.
    #[arg(long)]
    pub(crate) intrinsics_opt: bool,
    /// A random background color per step (transparent parts of the images re-composited on
    /// it), so the scene cannot paint the background in; evaluation stays on black or white.
    #[arg(long)]
    pub(crate) random_background: bool,
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// How the primitive set changes.
    #[arg(long, value_enum, default_value_t = StrategyArg::Adc)]
    pub(crate) strategy: StrategyArg,
    /// Density control adds no primitives past this many [default: 4000000 with adc, 1000000
    /// with mcmc; 6000 on the built-in dataset].
    #[arg(long)]
    pub(crate) max_primitives: Option<usize>,
    /// Adaptive density control without its opacity resets (huge primitives are still pruned
    /// after step 3,000), as gsplat 1.5.3 trains: its reset test never passes.
    #[arg(long)]
    pub(crate) no_opacity_reset: bool,
    /// Measure the test views' PSNR and SSIM every this many steps (for the curve and
    /// metrics.csv; they are always measured before the first step and after the last);
    /// 0: only then.
    #[arg(long, default_value_t = 250)]
    pub(crate) eval_every: usize,
    /// Save the run's state to <out>/checkpoint.bin every this many steps (and after the
    /// last); 0: never.
    #[arg(long, default_value_t = 1000)]
    pub(crate) checkpoint_every: usize,
    /// Go on from <out>/checkpoint.bin (and keep <out>/metrics.csv up to it): the same steps
    /// follow as in the run that saved it.
    #[arg(long)]
    pub(crate) resume: bool,
    /// Parameter groups to keep as they start (comma-separated field names of the method's
    /// parameters, e.g. `sh` to fit the geometry alone, or `mean,log_scale,rotation` to fit
    /// colors and opacities on fixed shapes): their gradients are never computed. Freezing a
    /// shape group needs `--strategy fixed`.
    #[arg(long, value_delimiter = ',')]
    pub(crate) freeze: Vec<String>,
    /// Also print the effects each training step simulates (the first training view's camera)
    /// and the gradients its backward pass computes.
    #[arg(long)]
    pub(crate) explain: bool,
    /// Serve `splat view`'s page while training: the scene as it trains (taken every
    /// --view-every steps), the loss and test PSNR curves, the primitive count, pause and
    /// resume. The page goes when the run ends (`splat view OUT` shows the result).
    #[arg(long)]
    pub(crate) view: bool,
    /// With --view: hand the page the scene after every this many steps (on the GPU each is
    /// a download of the parameters).
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) view_every: u32,
    #[command(flatten)]
    pub(crate) serve: crate::commands::view::ServeArgs,
    /// Also write the trained scene in these formats beside scene.ply (comma-separated):
    /// spz, sog, compressed-ply, splat (scene.spz, scene.sog, ...), for the web's viewers;
    /// what each keeps: docs/formats.md.
    #[arg(long, value_delimiter = ',', value_parser = export_format)]
    pub(crate) export: Vec<Format>,
    /// Where to train: the GPU (the device-resident loop), the CPU, or `auto` (a hardware
    /// GPU when there is one).
    #[arg(long, value_enum, default_value_t = crate::Backend::Auto)]
    pub(crate) backend: crate::Backend,
    /// Output folder: the trained scene as an INRIA 3DGS PLY (scene.ply), the test views
    /// rendered (test/<n>.png), the loss and test PSNR / SSIM by step (metrics.csv) and as a
    /// plot (curve.png).
    #[arg(long, default_value = "fit")]
    pub(crate) out: PathBuf,
}

/// A format `--export` names (scene.ply is always written).
fn export_format(name: &str) -> Result<Format, String> {
    match Format::from_name(name)? {
        Format::Ply => Err("scene.ply is always written; name the others".into()),
        format => Ok(format),
    }
}

/// The file the run writes its scene to in `format`: scene.ply, scene.spz, ...
pub(crate) fn scene_file(format: Format) -> String {
    format!("scene{}", format.extension())
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum StrategyArg {
    /// 3DGS's adaptive density control (gsplat's DefaultStrategy): clone and split where the
    /// screen-space position gradient is large, prune faint and huge primitives, reset
    /// opacities every 3,000 steps (not with --no-opacity-reset).
    Adc,
    /// MCMC (gsplat's MCMCStrategy): move faint primitives onto opaque ones, add 5% every 100
    /// steps up to --max-primitives, stir faint ones with noise; starts the primitives at
    /// opacity 0.5 and a tenth of their size, and penalizes opacity and scale.
    Mcmc,
    /// None: the primitive count stays fixed.
    Fixed,
}

/// Steps whose [`Faults`](splat_runtime::train::adam::Faults) are printed; later ones are
/// counted.
pub(crate) const FAULTS_SHOWN: usize = 10;
pub(crate) const FAULTS_AFTER_SHOWN: usize = FAULTS_SHOWN + 1;

/// The names of the files a run writes into its output folder (and `test/` for renders).
pub(crate) const CHECKPOINT: &str = "checkpoint.bin";
pub(crate) const METRICS: &str = "metrics.csv";
pub(crate) const CURVE: &str = "curve.png";
/// The training views' learned exposures (`--exposure`).
pub(crate) const EXPOSURES: &str = "exposure.json";
/// The cameras' learned intrinsics (`--intrinsics-opt`).
pub(crate) const INTRINSICS: &str = "intrinsics.json";

/// A training run, for any method.
pub struct Fit<'a> {
    pub(crate) args: &'a FitArgs,
    /// Every method the command line offers (a page of the run, `--view`, offers them too).
    pub(crate) methods: &'a [crate::methods::Method],
    /// The processes it runs as: rank 0 prints and writes.
    pub(crate) ranks: &'a Ranks,
    /// Where it trains: a GPU, or the CPU.
    pub(crate) gpu: Option<Gpu>,
    pub(crate) data: &'a Dataset,
    /// The checkpoint to go on from, if any.
    pub(crate) resume: Option<Checkpoint>,
    /// How many points to start from.
    pub(crate) points: usize,
    /// The cameras' centre and the scene's radius.
    pub(crate) mid: Vec3,
    pub(crate) extent: f32,
    /// The random points' cube's half-side, in units of `extent`.
    pub(crate) init_extent: f32,
    pub(crate) opts: &'a FitOptions,
}

impl Fit<'_> {
    pub(crate) fn run<M: Trainable>(&self) -> Result<()>
    where
        M::Params: ToStored,
    {
        let Fit {
            args,
            ranks,
            ref gpu,
            data,
            ..
        } = *self;
        let opts = &trained_groups::<M>(self.opts, &args.freeze, &args.method)?;
        if args.explain {
            explain::<M>(data, opts);
        }
        // The ranks take the same steps only from the same settings (`mpirun`'s MPMD form
        // can pass each its own).
        let settings = FitOptions {
            stop: None,
            ..opts.clone()
        };
        let settings = format!("{} {settings:?} {}", M::NAME, self.extent);
        let same = "give every rank the same command line";
        ranks.agree("run", &Ok(crate::ranks::hash(&settings)), same)?;
        if !ranks.is_root() {
            return self.train_beside_root::<M>(opts);
        }
        let test_images = |params: &[M::Params], test: &[View]| match &gpu {
            Some(gpu) => render_views_gpu::<M>(gpu, params, test, opts),
            None => render_views::<M>(params, test, opts),
        };
        let (mut state, log) = self.begin::<M>(opts, &test_images)?;
        // The other ranks start from this state, bit for bit (each its slice, when sharded).
        if !args.sharded {
            ranks.broadcast(Some(state.to_bytes()?))?;
        }
        // The cap bounds growth (as gsplat's): a start above it is kept, and ADC may prune it
        // below; MCMC never removes primitives.
        if let Some(cap) = opts.densify.as_ref().map(Strategy::max_primitives)
            && state.primitives() > cap
        {
            println!(
                "note: {} primitives at the start, more than --max-primitives {cap}: the cap only stops growth",
                state.primitives()
            );
        }
        let mut progress = Progress::new(opts.steps, state.step, log, &args.out);
        // Ctrl-C or SIGTERM during the steps ends the run after the step in progress, with its
        // checkpoint.
        let listening = crate::interrupt::listen();
        let opts = &FitOptions {
            stop: listening.as_ref().map(Listening::flag),
            ..opts.clone()
        };
        let page = match args.view {
            true => Some(FitView::new::<M>(
                self.methods,
                &args.method,
                gpu.as_ref(),
                &state,
                &args.serve,
            )?),
            false => None,
        };
        let opts = &FitOptions {
            share_every: page.as_ref().map(|_| args.view_every as usize),
            ..opts.clone()
        };
        let report = |r: &StepReport| {
            progress.record::<M>(r);
            if let Some(page) = &page {
                page.step::<M>(r, &|| opts.stop_requested());
            }
        };
        let mut peaks = vec![];
        let place = std::thread::scope(|scope| -> Result<String> {
            if let Some(page) = &page {
                scope.spawn(|| {
                    page.serve()
                        .inspect_err(|e| eprintln!("splat fit --view: {e:#}"))
                });
            }
            let trained = match &gpu {
                Some(gpu) if args.sharded => (|| {
                    let team = ranks.team();
                    fit_sharded_gpu::<M>(team, gpu, data, &mut state, self.extent, opts, report)?;
                    peaks = peak_memory(ranks)?;
                    Ok(match ranks.count() {
                        1 => format!("the GPU ({}), the scene in one slice", gpu.adapter),
                        n => format!(
                            "the GPUs of {n} MPI ranks, each with a slice of the scene (rank 0: {})",
                            gpu.adapter
                        ),
                    })
                })(),
                Some(gpu) if args.hardware => {
                    let team = ranks.team();
                    let (state, extent) = (&mut state, self.extent);
                    fit_hardware_shared::<M>(team, gpu, data, state, extent, opts, report)
                        .map(|()| match ranks.count() {
                            1 => format!("the GPU's rasterizer ({})", gpu.adapter),
                            n => format!(
                                "the GPUs' rasterizers of {n} MPI ranks (rank 0: {})",
                                gpu.adapter
                            ),
                        })
                        .map_err(Into::into)
                }
                Some(gpu) => {
                    let team = ranks.team();
                    fit_gpu_shared::<M>(team, gpu, data, &mut state, self.extent, opts, report)
                        .map(|()| match ranks.count() {
                            1 => format!("the GPU ({})", gpu.adapter),
                            n => format!("the GPUs of {n} MPI ranks (rank 0: {})", gpu.adapter),
                        })
                        .map_err(Into::into)
                }
                None if args.sharded => (|| {
                    let team = ranks.team();
                    fit_sharded::<M>(team, data, &mut state, self.extent, opts, report)?;
                    peaks = peak_memory(ranks)?;
                    Ok(match ranks.count() {
                        1 => "the CPU, the scene in one slice".to_string(),
                        n => format!("the CPUs of {n} MPI ranks, each with a slice of the scene"),
                    })
                })(),
                None => fit_shared::<M>(ranks.team(), data, &mut state, self.extent, opts, report)
                    .map(|()| match ranks.count() {
                        1 => "the CPU".to_string(),
                        n => format!("the CPUs of {n} MPI ranks"),
                    })
                    .map_err(Into::into),
            };
            if let Some(page) = &page {
                page.close();
            }
            trained
        })?;
        // Still listening through the final evaluation: a signal there ends the run with the
        // last step's checkpoint, as one during the steps does.
        let stopped_by = || listening.as_ref().and_then(Listening::stopped_by);
        let kept = || match opts.checkpoint_every {
            Some(_) => format!(
                "its checkpoint and metrics are in {}: the same command with --resume goes on",
                args.out.display()
            ),
            None => "nothing was saved (--checkpoint-every 0)".to_string(),
        };
        let stopped = state.step < opts.steps;
        match stopped {
            true => progress.bar.abandon(),
            false => progress.bar.finish(),
        }
        std::mem::replace(&mut progress.saved, Ok(()))?;
        if stopped {
            // Every rank stopped after this batch: rank 0 says so, without aborting the rest.
            return Err(crate::ranks::on_every_rank(format!(
                "stopped by {} after step {} of {}; {}",
                stopped_by().unwrap_or("a signal"),
                state.step,
                opts.steps,
                kept()
            )));
        }
        if progress.faulty_steps > 0 {
            println!(
                "warning: {} steps left parameter words alone (non-finite gradients or steps); the scene stayed finite",
                progress.faulty_steps
            );
        }
        let params = state.params::<M>();
        let taken = opts.steps - progress.first;
        let per_step = progress.started.elapsed().as_secs_f64() / taken.max(1) as f64;
        // Through the cameras' learned intrinsics, where the run learned them.
        let cameras = &Cameras::of(data.train.iter().map(|v| &v.camera));
        let test = (state.per_view).held_out_views(&opts.per_view, cameras, &data.test);
        let images = test_images(&params, &test)?;
        let after = Evaluation::of(&images, &test)?;
        if let Some(by) = stopped_by() {
            // The other ranks are done: no need to abort them.
            return Err(crate::ranks::on_every_rank(format!(
                "stopped by {by} in the final evaluation, after the run's {} steps; {}",
                opts.steps,
                kept()
            )));
        }
        drop(listening);
        let before = progress.before();
        let log = &mut progress.log;
        if log.evaluations.last().is_none_or(|e| e.0 < opts.steps) {
            log.evaluations.push((opts.steps, after));
        }
        let batches = match opts.batch {
            1 => String::new(),
            b => format!(" in batches of {b}"),
        };
        let pace = match taken {
            0 => format!("no steps to take on {place}"),
            1 => format!("1 step on {place}, {:.1} ms", per_step * 1e3),
            n => format!(
                "{n} steps{batches} on {place}, {:.1} ms per step",
                per_step * 1e3
            ),
        };
        let views = crate::count(after.views, "test view");
        println!(
            "{pace}, {} primitives; {views}: PSNR {:.2} -> {:.2} dB, SSIM {:.3} -> {:.3}",
            params.len(),
            before.psnr,
            after.psnr,
            before.ssim,
            after.ssim
        );
        if taken > 0 {
            print_step_times(&progress.times, progress.batches, gpu.as_ref());
        }
        if let Some(t) = ranks
            .traffic()
            .filter(|_| ranks.count() > 1 && progress.batches > 0)
        {
            let per = |bytes: u64| bytes as f64 / progress.batches as f64 / 1e6;
            let what = match args.sharded {
                true => "the views' visible primitives and their gradients",
                false => "the views' gradients and density statistics",
            };
            println!(
                "rank 0 sent {:.2} MB and received {:.2} MB per batch ({what})",
                per(t.sent),
                per(t.received)
            );
        }
        if peaks.len() > 1 {
            let peaks: Vec<String> = (peaks.iter())
                .map(|p| p.map_or("?".into(), |b| format!("{:.0}", b as f64 / 1e6)))
                .collect();
            println!(
                "each rank held 1/{} of the scene and its moments; peak resident memory by rank: {} MB",
                ranks.count(),
                peaks.join(", ")
            );
        }
        let antialiased = methods::find(self.methods, &args.method)?.antialiased;
        let cloud = GaussianCloud {
            antialiased,
            ..GaussianCloud::new(3, params.iter().map(ToStored::to_stored).collect())
        };
        let learned = [
            (
                EXPOSURES,
                exposure_json(&data.train, cameras, &state, &opts.per_view),
            ),
            (
                INTRINSICS,
                intrinsics_json(&data.train, cameras, &state, &opts.per_view),
            ),
        ];
        let results = Results {
            cloud: &cloud,
            images: &images,
            log: &progress.log,
            learned: learned
                .into_iter()
                .filter_map(|(file, json)| Some((file, json?)))
                .collect(),
        };
        write_results(&args.out, &args.export, results)
    }

    /// A rank past 0 under MPI: the same steps as rank 0, from the state it hands over,
    /// printing and writing nothing.
    fn train_beside_root<M: Trainable>(&self, opts: &FitOptions) -> Result<()> {
        let listening = crate::interrupt::listen();
        let team = self.ranks.team();
        if self.args.sharded {
            // Its slice comes from rank 0; the evaluations take every slice.
            let opts = FitOptions {
                stop: listening.as_ref().map(Listening::flag),
                ..opts.clone()
            };
            let mut slice = Checkpoint::start::<M>(&[], opts.steps, opts.seed);
            let (data, extent) = (self.data, self.extent);
            match &self.gpu {
                Some(gpu) => {
                    fit_sharded_gpu::<M>(team, gpu, data, &mut slice, extent, &opts, |_| {})?
                }
                None => fit_sharded::<M>(team, data, &mut slice, extent, &opts, |_| {})?,
            }
            peak_memory(self.ranks)?;
            return Ok(());
        }
        let path = self.args.out.join(CHECKPOINT);
        let mut state = Checkpoint::parse(&self.ranks.broadcast(None)?, &path)?;
        let opts = FitOptions {
            eval_every: None,
            stop: listening.as_ref().map(Listening::flag),
            ..opts.clone()
        };
        match &self.gpu {
            Some(gpu) if self.args.hardware => {
                let data = self.data;
                fit_hardware_shared::<M>(team, gpu, data, &mut state, self.extent, &opts, |_| {})?
            }
            Some(gpu) => {
                let data = self.data;
                fit_gpu_shared::<M>(team, gpu, data, &mut state, self.extent, &opts, |_| {})?
            }
            None => fit_shared::<M>(team, self.data, &mut state, self.extent, &opts, |_| {})?,
        }
        Ok(())
    }

    /// Where the run starts: the checkpoint it resumes from (refused if it is of another
    /// method or strategy) with the metrics up to it, or the first primitives and the test
    /// views' evaluation before any step.
    fn begin<M: Trainable>(
        &self,
        opts: &FitOptions,
        test_images: &impl Fn(&[M::Params], &[View]) -> Result<Vec<Image>, FitError>,
    ) -> Result<(Checkpoint, Log)> {
        let Fit { args, data, .. } = *self;
        Ok(match &self.resume {
            Some(c) if c.method != M::NAME => bail!(
                "{} is a checkpoint of {}, not of {} (--method {})",
                args.out.join(CHECKPOINT).display(),
                c.method,
                M::NAME,
                args.method
            ),
            Some(c) if c.step > 0 && c.strategy != Strategy::name(opts.densify.as_ref()) => bail!(
                "{} is a checkpoint of a run with --strategy {}, not {}",
                args.out.join(CHECKPOINT).display(),
                c.strategy,
                Strategy::name(opts.densify.as_ref())
            ),
            Some(c) => {
                // Before the metrics, which are read one row per batch of the run's own.
                refuse_other_settings::<M>(c, opts)?;
                let log = Log::read_csv(&args.out.join(METRICS), c.step, opts.batch)?;
                (c.clone(), log)
            }
            None => {
                let half = self.init_extent * self.extent;
                let first = init::Start {
                    size: args.init_size,
                    color: args.init_color,
                };
                let mut params = start::<M>(data, self.points, self.mid, half, first, args.seed)?;
                if let Some(Strategy::Mcmc(_)) = opts.densify {
                    McmcOptions::prepare::<M>(&mut params);
                }
                let before = Evaluation::of(&test_images(&params, &data.test)?, &data.test)?;
                let log = Log {
                    evaluations: vec![(0, before)],
                    ..Default::default()
                };
                (Checkpoint::start::<M>(&params, opts.steps, args.seed), log)
            }
        })
    }
}

/// What a run leaves: the scene, the test views' renders, the metrics and curve, and what
/// it learned per view or camera (file name, JSON) where it learned any.
struct Results<'a> {
    cloud: &'a GaussianCloud,
    images: &'a [Image],
    log: &'a Log,
    learned: Vec<(&'static str, String)>,
}

/// The training `views`' learned exposures in `state`, as JSON (`None` where the run learned
/// none): each view's name and gains (red, green, blue).
fn exposure_json(
    views: &[View],
    cameras: &Cameras,
    state: &Checkpoint,
    per_view: &PerViewOptions,
) -> Option<String> {
    per_view.exposure.then_some(())?;
    let views: Vec<serde_json::Value> = (views.iter().enumerate())
        .filter_map(|(k, v)| {
            let e = per_view.exposure(state.per_view.training(per_view, cameras, k))?;
            Some(serde_json::json!({ "name": v.name, "gains": e.gains() }))
        })
        .collect();
    let json = serde_json::json!({
        "map": "each channel of the render (before the background) times its gain; held-out views: 1, the training views' geometric mean",
        "views": views,
    });
    Some(serde_json::to_string_pretty(&json).expect("JSON of numbers and names") + "\n")
}

/// The `cameras`' learned intrinsics in `state`, as JSON (`None` where the run learned none):
/// each camera's model, its intrinsics as given and as learned, and its training views.
fn intrinsics_json(
    views: &[View],
    cameras: &Cameras,
    state: &Checkpoint,
    per_view: &PerViewOptions,
) -> Option<String> {
    per_view.intrinsics.then_some(())?;
    let intrinsics = |c: &splat_runtime::Camera| {
        let mut json = serde_json::json!({
            "fx": c.focal.x, "fy": c.focal.y, "cx": c.principal.x, "cy": c.principal.y,
        });
        if c.model.has_distortion() {
            json["k"] = serde_json::json!(c.distortion.to_array());
        }
        json
    };
    let json: Vec<serde_json::Value> = (cameras.intrinsics().iter().enumerate())
        .map(|(k, given)| {
            let learned = per_view.camera(given, state.per_view.held_out(per_view, cameras, given));
            let names: Vec<&str> = (views.iter().enumerate())
                .filter(|&(v, _)| cameras.of_view(v) == k)
                .map(|(_, view)| view.name.as_str())
                .collect();
            serde_json::json!({
                "model": given.model.name(),
                "width": given.size.x,
                "height": given.size.y,
                "given": intrinsics(given),
                "learned": intrinsics(&learned),
                "views": names,
            })
        })
        .collect();
    let json = serde_json::json!({
        "cameras": json,
        "held_out": "a held-out view whose intrinsics equal a camera's as given is rendered through its learned ones",
    });
    Some(serde_json::to_string_pretty(&json).expect("JSON of numbers and names") + "\n")
}

/// The result of a run in `out`, all appearing together.
fn write_results(out: &Path, exports: &[Format], results: Results) -> Result<()> {
    let Results {
        cloud,
        images,
        log,
        learned,
    } = results;
    let mut outputs = Outputs::default();
    for &format in [Format::Ply].iter().chain(exports) {
        let path = out.join(scene_file(format));
        (outputs.stage(&path, |w| formats::write_to(format, w, cloud)))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    for (k, image) in images.iter().enumerate() {
        let path = out.join("test").join(crate::render_name(k));
        stage_image(&mut outputs, &path, image)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    log.stage_csv(&mut outputs, &out.join(METRICS))?;
    log.plot(&mut outputs, &out.join(CURVE))?;
    for (file, json) in learned {
        let path = out.join(file);
        (outputs.stage(&path, |w| w.write_all(json.as_bytes())))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    outputs.commit()?;
    crate::remove_stale_renders(&out.join("test"), images.len())?;
    crate::wrote(out);
    Ok(())
}

/// What a run shows and keeps as its steps report: the progress bar (or, without a terminal,
/// a line every twentieth of the run), the metrics, the stage times, the steps that left words
/// alone, and each checkpoint with the metrics up to it.
struct Progress {
    bar: ProgressBar,
    log: Log,
    times: StepTimes,
    faulty_steps: usize,
    /// How many reports (Adam steps) came.
    batches: usize,
    /// The first checkpoint that could not be written: it stops nothing then, and the run
    /// reports it at its end.
    saved: Result<()>,
    checkpoint_path: PathBuf,
    metrics: PathBuf,
    /// The step the run started from, and when.
    first: usize,
    started: Instant,
    steps: usize,
    line_every: usize,
}

impl Progress {
    fn new(steps: usize, first: usize, log: Log, out: &Path) -> Progress {
        let bar = ProgressBar::new(steps as u64).with_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} steps, {elapsed} (eta {eta}) {msg}")
                .expect("a valid template"),
        );
        bar.set_position(first as u64);
        Progress {
            bar,
            log,
            times: StepTimes::default(),
            batches: 0,
            faulty_steps: 0,
            saved: Ok(()),
            checkpoint_path: out.join(CHECKPOINT),
            metrics: out.join(METRICS),
            first,
            started: Instant::now(),
            steps,
            line_every: (steps - first).div_ceil(20).next_multiple_of(10),
        }
    }

    /// The test views' evaluation before the first step (the log's first).
    fn before(&self) -> Evaluation {
        self.log
            .evaluations
            .first()
            .map(|e| e.1)
            .unwrap_or_default()
    }

    fn record<M: Trainable>(&mut self, r: &StepReport) {
        self.bar.inc(r.views as u64);
        self.batches += 1;
        self.log.record(r);
        self.times += r.times;
        if r.faults.any() || r.view_faults.any() {
            self.faulty_steps += 1;
            let views = (r.view_faults.gradients + r.view_faults.steps) as usize;
            let what = match (r.faults.any(), views) {
                (true, 0) => r.faults.describe::<M>(),
                (false, n) => {
                    format!("{n} per-view words (exposure, pose, intrinsics) kept their values")
                }
                (true, n) => format!("{}; {n} per-view words too", r.faults.describe::<M>()),
            };
            match self.faulty_steps {
                ..=FAULTS_SHOWN => self
                    .bar
                    .println(format!("warning: step {}: {what}", r.step + 1,)),
                FAULTS_AFTER_SHOWN => self
                    .bar
                    .println("warning: later steps with words left alone are counted, not shown"),
                _ => {}
            }
        }
        // With the checkpoint, the metrics up to it (a resumed run keeps them).
        if let Some(c) = r.checkpoint
            && self.saved.is_ok()
        {
            let mut outputs = Outputs::default();
            self.saved = (outputs.stage(&self.checkpoint_path, |w| c.write_to(w)))
                .with_context(|| format!("writing {}", self.checkpoint_path.display()))
                .and_then(|()| self.log.stage_csv(&mut outputs, &self.metrics))
                .and_then(|()| Ok(outputs.commit()?));
        }
        // The steps (views) this report covers, counted from the run's first.
        let done = (r.step + 1 - r.views - self.first)..(r.step + 1 - self.first);
        let line = self.bar.is_hidden()
            && done
                .clone()
                .any(|d| (d + 1).is_multiple_of(self.line_every));
        let tenth = (r.step + 1 - r.views..=r.step).any(|s| s.is_multiple_of(10));
        if tenth || r.refinement.is_some() || r.evaluation.is_some() || line {
            let v = r.loss;
            // The last measured: the final evaluation comes after the last step's line.
            let (at, test) =
                (self.log.evaluations.last()).map_or((0, self.before().psnr), |e| (e.0, e.1.psnr));
            let status = format!(
                "loss {:.4} (L1 {:.4}, SSIM {:.3}), test PSNR {test:.2} dB at step {at}, {} primitives",
                v.loss, v.l1, v.ssim, r.primitives
            );
            if line {
                let ms = self.started.elapsed().as_secs_f64() * 1e3 / done.end as f64;
                println!(
                    "step {}/{}: {ms:.2} ms per step, {status}",
                    r.step + 1,
                    self.steps
                );
            }
            self.bar.set_message(status);
        }
    }
}

/// Where the run's Adam steps (`steps` of them) spent their time, per stage: a table of the
/// mean per step.
fn print_step_times(total: &StepTimes, steps: usize, gpu: Option<&Gpu>) {
    let clocks = match gpu {
        Some(g) if g.timestamps => {
            "the GPU's stages by its timestamps, the step by the host's clock"
        }
        Some(_) => "this adapter has no timestamp queries: its stages read zero",
        None => "the host's clock",
    };
    println!("\nWhere a step's time went (mean of {steps} steps; {clocks}):");
    println!("| stage | ms per step | share |");
    println!("|---|---:|---:|");
    let per_step = |d: Duration| d.as_secs_f64() * 1e3 / steps.max(1) as f64;
    let wall = per_step(total.wall);
    let other = match gpu {
        Some(_) => "other (host work, submissions, waits for the GPU)",
        None => "other (the loop's own host work)",
    };
    let rows = (total.stages().into_iter()).chain([(other, total.unaccounted())]);
    for (stage, d) in rows.filter(|(_, d)| !d.is_zero()) {
        let ms = per_step(d);
        println!(
            "| {stage} | {ms:.2} | {:.1}% |",
            100.0 * ms / wall.max(1e-12)
        );
    }
    println!("| step | {wall:.2} | 100% |");
}

/// The parameter groups `names` of `method` split into those `freeze` names and the rest;
/// refused where `freeze` names a group the method lacks, or every group.
pub(crate) fn frozen_and_trained<'a>(
    names: &[&'a str],
    freeze: &[String],
    method: &str,
) -> Result<(Vec<&'a str>, Vec<&'a str>)> {
    if let Some(unknown) = freeze.iter().find(|f| !names.contains(&f.as_str())) {
        bail!(
            "--freeze {unknown}: {method} has no parameter group `{unknown}`; its groups are {}",
            names.join(", ")
        );
    }
    let (frozen, trained): (Vec<&str>, Vec<&str>) =
        names.iter().partition(|n| freeze.iter().any(|f| f == *n));
    if trained.is_empty() {
        bail!(
            "--freeze {}: those are all of {method}'s parameter groups, which leaves nothing to train",
            frozen.join(",")
        );
    }
    Ok((frozen, trained))
}

/// `opts` training every parameter group of `M` (`--method method`) but those named in
/// `freeze`; says which are trained and which frozen.
fn trained_groups<M: Trainable>(
    opts: &FitOptions,
    freeze: &[String],
    method: &str,
) -> Result<FitOptions> {
    let groups = param_groups::<M>();
    let names: Vec<&str> = groups.iter().map(|(name, _)| *name).collect();
    let (frozen, trained) = frozen_and_trained(&names, freeze, method)?;
    let gradients = GradientSet::params::<M>(&trained).map_err(|e| anyhow!(e))?;
    if !frozen.is_empty() {
        println!(
            "training {}; frozen: {}",
            trained.join(", "),
            frozen.join(", ")
        );
    }
    Ok(FitOptions {
        render: RenderOptions {
            gradients,
            ..opts.render
        },
        ..opts.clone()
    })
}

/// What `--explain` prints: the effects of a training step's frame, its gradients, and what
/// the loop adds around it.
fn explain<M: Trainable>(data: &Dataset, opts: &FitOptions) {
    if let Some(view) = data.train.first() {
        println!(
            "{}",
            Effects::of::<M>(&view.camera, &opts.render).with_gradients::<M>()
        );
    }
    let background = match opts.random_background {
        true => "random per step (the targets re-composited on it)".to_string(),
        false => format!("{:?}", opts.background.to_array()),
    };
    println!("background        {background}");
    println!(
        "density control   {}",
        Strategy::name(opts.densify.as_ref())
    );
}

/// `R,G,B`, each in [0, 1].
fn parse_color(text: &str) -> Result<Vec3, String> {
    let channels: Vec<f32> = text
        .split(',')
        .map(|c| c.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{text}` is not R,G,B: {e}"))?;
    match channels[..] {
        [r, g, b] if channels.iter().all(|c| (0.0..=1.0).contains(c)) => Ok(Vec3::new(r, g, b)),
        _ => Err(format!("`{text}` is not R,G,B, three numbers in [0, 1]")),
    }
}

/// The primitives a run starts from: the dataset's points, or random ones in the cube of
/// half-side `half` around `mid`, with the size and color `first` gives them.
fn start<M: Trainable>(
    data: &Dataset,
    points: usize,
    mid: Vec3,
    half: f32,
    first: init::Start,
    seed: u64,
) -> Result<Vec<M::Params>> {
    let count = match data.points.len() {
        0 => points,
        n => points.min(n),
    };
    if let Some(room) = memory::available() {
        memory::check_start(count, M::Params::LEN, room)?;
    }
    if data.points.is_empty() {
        return Ok(init::in_cube::<M>(points, mid, half, first, seed));
    }
    let params = init::from_points::<M>(&data.points, points, first);
    println!(
        "starting from {} of the dataset's {} points",
        params.len(),
        data.points.len()
    );
    Ok(params)
}

/// What a run measured: the training loss at every step, the test views' PSNR and SSIM at the
/// evaluated steps (0: before training).
#[derive(Default)]
struct Log {
    steps: Vec<(usize, LossValue, usize)>,
    evaluations: Vec<(usize, Evaluation)>,
}

impl Log {
    fn record(&mut self, r: &StepReport) {
        // Steps are counted from one here: the evaluation after step k reads "k steps".
        let step = r.step + 1;
        self.steps.push((step, *r.loss, r.primitives));
        if let Some(e) = r.evaluation {
            self.evaluations.push((step, e));
        }
    }

    /// The rows of a run's `metrics.csv` up to step `last` (what a resumed run keeps), one
    /// per batch of `batch` views.
    fn read_csv(path: &Path, last: usize, batch: usize) -> Result<Log> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut log = Log::default();
        for (k, line) in text.lines().enumerate().skip(1) {
            let bad = || {
                anyhow!(
                    "{} line {}: not a metrics row: {line}",
                    path.display(),
                    k + 1
                )
            };
            let f: Vec<&str> = line.split(',').collect();
            let [step, loss, l1, ssim, primitives, psnr, test_ssim] = f[..] else {
                return Err(bad());
            };
            let step: usize = step.parse().map_err(|_| bad())?;
            if step > last {
                break;
            }
            let num = |s: &str| s.parse::<f64>().map_err(|_| bad());
            if step > 0 {
                let v = LossValue {
                    loss: num(loss)?,
                    l1: num(l1)?,
                    ssim: num(ssim)?,
                };
                log.steps
                    .push((step, v, primitives.parse().map_err(|_| bad())?));
            }
            if !psnr.is_empty() {
                let e = Evaluation {
                    psnr: num(psnr)?,
                    ssim: num(test_ssim)?,
                    views: 0,
                };
                log.evaluations.push((step, e));
            }
        }
        // Written with the checkpoint, they hold every batch up to it, unless edited since.
        let kept = log.steps.iter().map(|s| s.0);
        if !kept.eq(batches(0, last, batch).map(|b| b.last() + 1)) {
            println!(
                "warning: {} holds {} of the checkpoint's {last} steps: the resumed run's metrics miss the others",
                path.display(),
                log.steps.len()
            );
        }
        Ok(log)
    }

    /// One row per step: the loss, its L1 and SSIM terms, the primitive count, and the test
    /// PSNR and SSIM where measured (step 0: before training).
    fn stage_csv(&self, outputs: &mut Outputs, path: &Path) -> Result<()> {
        let evals: BTreeMap<usize, Evaluation> = self.evaluations.iter().copied().collect();
        let test = |step: usize| match evals.get(&step) {
            Some(e) => format!("{:.4},{:.5}", e.psnr, e.ssim),
            None => ",".to_string(),
        };
        let mut rows = vec!["step,loss,l1,ssim,primitives,test_psnr,test_ssim".to_string()];
        if evals.contains_key(&0) {
            rows.push(format!("0,,,,,{}", test(0)));
        }
        for (step, v, n) in &self.steps {
            rows.push(format!(
                "{step},{:.6},{:.6},{:.6},{n},{}",
                v.loss,
                v.l1,
                v.ssim,
                test(*step)
            ));
        }
        let text = rows.join("\n") + "\n";
        (outputs.stage(path, |w| w.write_all(text.as_bytes())))
            .with_context(|| format!("writing {}", path.display()))
    }

    /// The training loss (a running mean over 50 steps, in decades) above the test PSNR, by
    /// step.
    fn plot(&self, outputs: &mut Outputs, path: &Path) -> Result<()> {
        let last = self.steps.last().map_or(1, |s| s.0);
        let window = 50;
        let smooth: Vec<(f64, f64)> = self
            .steps
            .windows(window.min(self.steps.len()).max(1))
            .map(|w| {
                let mean = w.iter().map(|s| s.1.loss).sum::<f64>() / w.len() as f64;
                (w[w.len() - 1].0 as f64, mean)
            })
            .collect();
        let psnr: Vec<(f64, f64)> = self
            .evaluations
            .iter()
            .map(|(s, e)| (*s as f64, e.psnr))
            .collect();
        plot::png(outputs, path, (900, 640), |root| {
            let err = plot::drawing("training curve".into());
            let (top, bottom) = root.split_vertically(320);
            let caption = "training loss (mean of 50 steps)";
            let (log, linear) = (plot::Scale::Log, plot::Scale::Linear);
            let loss = smooth.iter().map(|p| p.1);
            let mut chart = plot::by_step(&top, caption, last, loss, log)?;
            let line = smooth.iter().map(|(x, y)| (*x, log.y(*y)));
            chart
                .draw_series(LineSeries::new(line, BLUE.stroke_width(2)))
                .map_err(&err)?;
            let test = psnr.iter().map(|p| p.1);
            let mut chart = plot::by_step(&bottom, "test PSNR (dB)", last, test, linear)?;
            let line = LineSeries::new(psnr.iter().copied(), RED.stroke_width(2));
            chart.draw_series(line).map_err(&err)?;
            let dots = psnr.iter().map(|p| Circle::new(*p, 4, RED.filled()));
            chart.draw_series(dots).map_err(&err)?;
            Ok(())
        })
    }
}

/// Every rank's peak resident memory (`None` where the system does not say), in rank order.
fn peak_memory(ranks: &Ranks) -> Result<Vec<Option<u64>>> {
    let mine = memory::peak_resident().unwrap_or(u64::MAX).to_le_bytes();
    (ranks.team().all_gather(mine.to_vec())?.iter())
        .map(|b| {
            let peak = u64::from_le_bytes(b.as_slice().try_into()?);
            Ok((peak != u64::MAX).then_some(peak))
        })
        .collect()
}
