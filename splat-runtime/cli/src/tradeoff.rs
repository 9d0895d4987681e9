//! `splat tradeoff`: what each accuracy knob of the renderer costs in time and memory and what
//! it buys in image and gradient accuracy, on one scene, camera and backend.
//!
//! Each knob is swept alone from the defaults. On the CPU two more knobs are how the shade data
//! and the gradient sums are stored between stages. On the GPU one more knob is the forward path:
//! the hardware-rasterized pass (quads blended into render targets, one sort key per visible
//! primitive) at each target precision the adapter can blend into; it has no backward pass.
//! The reference is the f32 render with every knob at its most accurate
//! ([`reference_options`]); the f64 brute-force renderer would take minutes on a real scene. Gradients are those of one fixed random linear loss on the color
//! (uniform in [-0.5, 0.5) per channel, as `splat bench`), compared per parameter group.
//! Each time comes with its ratio to the default's: on the GPU measured beside the default
//! frame, in turns ([`PaceFrame`]), since the GPU's clock moves with its load.

use crate::Backend;
use crate::methods::{self, Method};
use crate::plot;
use anyhow::{Context, Result, bail};
use plotters::prelude::*;
use splat_runtime::gpu::entries::Accumulation;
use splat_runtime::gpu::{Gpu, GpuRenderer, GpuScene, HardwareRenderer};
use splat_runtime::io::ply::FromStored;
use splat_runtime::io::{Outputs, ply};
use splat_runtime::pipeline::precision::Precision;
use splat_runtime::pipeline::shade::Blend;
use splat_runtime::{Camera, FrameGrad, RenderOptions, SplatMethod, param_groups};
use std::cell::RefCell;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct TradeoffArgs {
    /// INRIA 3DGS PLY scene (default: the built-in one).
    #[arg(long)]
    scene: Option<PathBuf>,
    #[command(flatten)]
    camera: crate::view::CameraArgs,
    #[arg(long)]
    method: String,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// Timed frames per setting and pass (after 0.3 s of warm-up frames); the median is reported.
    #[arg(long, default_value_t = 5)]
    iters: usize,
    /// Output folder: tradeoff.csv (one row per setting), gradients.csv (per parameter group
    /// and magnitude range) and tradeoff.png (time against error, with the Pareto front).
    #[arg(long, default_value = "tradeoff")]
    out: PathBuf,

    /// The built-in camera's width (a camera file gives its own).
    #[arg(long, default_value_t = 800, conflicts_with = "camera")]
    width: u32,
    /// The built-in camera's height (a camera file gives its own).
    #[arg(long, default_value_t = 600, conflicts_with = "camera")]
    height: u32,
}

/// One point of the sweep: a knob, its setting as the table and the CSV name it, the options
/// and the forward path.
pub(crate) struct Setting {
    pub knob: &'static str,
    pub value: String,
    pub opts: RenderOptions,
    pub path: Forward,
}

/// How a setting's forward pass rasterizes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Forward {
    /// Per-tile lists blended in compute (or on the CPU), with a backward pass.
    Tiles,
    /// The GPU's rasterizer and blending into render targets of `RenderOptions::precision`;
    /// forward only.
    Hardware,
}

/// The defaults, then each knob alone at its other settings (the tile sizes the backend has,
/// and the hardware path at the precisions in `hardware`).
pub(crate) fn sweep(tile_sizes: &[u32], hardware: &[Precision]) -> Vec<Setting> {
    let base = RenderOptions::default();
    let mut out = vec![Setting {
        knob: "default",
        value: format!(
            "p_max=none tile={} t_min={:e} alpha_min={} precision={}",
            base.tile_size,
            base.blend.t_min,
            base.blend.alpha_min,
            base.precision.name()
        ),
        opts: base,
        path: Forward::Tiles,
    }];
    let mut add = |knob, value: String, opts| {
        out.push(Setting {
            knob,
            value,
            opts,
            path: Forward::Tiles,
        })
    };
    for p in [512, 128, 32, 8] {
        let opts = RenderOptions {
            p_max: Some(p),
            ..base
        };
        add("p_max", p.to_string(), opts);
    }
    for &tile_size in tile_sizes.iter().filter(|&&t| t != base.tile_size) {
        let opts = RenderOptions { tile_size, ..base };
        add("tile", tile_size.to_string(), opts);
    }
    let blend = |t_min, alpha_min| RenderOptions {
        blend: Blend { t_min, alpha_min },
        ..base
    };
    add("t_min", "0".into(), blend(0.0, 0.0));
    for t in [1e-3, 1e-2, 1e-1] {
        add("t_min", format!("{t:e}"), blend(t, 0.0));
    }
    for a in [2, 8, 32] {
        add(
            "alpha_min",
            format!("{a}/255"),
            blend(base.blend.t_min, a as f32 / 255.0),
        );
    }
    let reduced = Precision::ALL.into_iter().filter(|&p| p != Precision::F32);
    for precision in reduced.clone() {
        let opts = RenderOptions { precision, ..base };
        add("precision", precision.name().into(), opts);
    }
    for shade_precision in reduced {
        let opts = RenderOptions {
            shade_precision,
            ..base
        };
        add("shade_precision", shade_precision.name().into(), opts);
    }
    // Sums have no fixed range: f16 is the one reduced format they are held in.
    let opts = RenderOptions {
        gradient_precision: Precision::F16,
        ..base
    };
    add("gradient_precision", "f16".into(), opts);
    for &precision in hardware {
        out.push(Setting {
            knob: "raster",
            value: format!("hardware {}", precision.name()),
            opts: RenderOptions { precision, ..base },
            path: Forward::Hardware,
        });
    }
    out
}

/// Every knob at its most accurate: whole lists, no transmittance stop, no alpha skip beyond
/// the method's own threshold.
pub(crate) fn reference_options() -> RenderOptions {
    RenderOptions {
        p_max: None,
        blend: Blend {
            t_min: 0.0,
            alpha_min: 0.0,
        },
        ..RenderOptions::default()
    }
}

/// Gradient magnitude ranges, relative to the group's largest reference gradient (seed 001's
/// Table IV uses absolute ranges; relative ones do not depend on the loss's scale).
const RANGES: [(f64, f64, &str); 3] = [
    (0.1, f64::INFINITY, "[0.1, 1]"),
    (1e-3, 0.1, "[1e-3, 0.1)"),
    (1e-5, 1e-3, "[1e-5, 1e-3)"),
];

pub fn tradeoff_cmd(args: &TradeoffArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    if args.iters == 0 {
        bail!("--iters must be at least 1");
    }
    crate::check_out_folder(&args.out)?;
    // The evaluation-model rows compare every method's render of the same Gaussians with the
    // exact method's most accurate one (or this method's, where none is marked exact).
    let exact = methods.iter().find(|m| m.exact);
    let (cloud, camera) = crate::scene::given_or_built_in(
        args.scene.as_deref(),
        &args.camera,
        (args.width, args.height),
    )?;
    methods::check_camera(method, methods, &camera)?;
    let gpu = crate::pick_gpu(args.backend)?;
    let (w, h) = (camera.size.x as usize, camera.size.y as usize);
    let backend = match &gpu {
        Some(gpu) => format!("GPU, {}", gpu.adapter),
        None => format!(
            "CPU, {}",
            crate::count(
                std::thread::available_parallelism().map_or(1, |n| n.get()),
                "thread"
            )
        ),
    };
    println!(
        "{}: {} primitives (SH degree {}), {w}x{h} {} camera, {backend}, {}",
        method.name,
        cloud.gaussians.len(),
        cloud.sh_degree,
        camera.model,
        match args.iters {
            1 => "one frame".to_string(),
            n => format!("median of {n} frames"),
        }
    );
    println!("reference: the f32 render with no P_max, t_min 0 and no extra alpha skip");
    let settings = match &gpu {
        Some(gpu) => {
            let blendable = Precision::ALL.into_iter();
            let hardware: Vec<Precision> = blendable
                .filter(|p| splat_runtime::gpu::raster::supports(gpu, *p))
                .collect();
            sweep(&splat_runtime::gpu::TILE_SIZES, &hardware)
        }
        None => sweep(&splat_runtime::pipeline::TILE_SIZES, &[]),
    };
    // The other methods the camera allows, for the evaluation-model knob.
    let models: Vec<&Method> = methods
        .iter()
        .filter(|m| methods::check_camera(m, methods, &camera).is_ok())
        .collect();
    let runs = 1 + settings.len() + cloud.sh_degree as usize + models.len() + 1;
    let bar = indicatif::ProgressBar::new(runs as u64);
    // On the GPU every setting is timed beside the method's default frame on this scene.
    let pace_task = Tradeoff {
        cloud: &cloud,
        camera: &camera,
        gpu: gpu.as_ref(),
        iters: args.iters,
        options: vec![],
        bar: &bar,
        pace: None,
    };
    let pace = match &gpu {
        Some(_) => Some((method.instance(cloud.sh_degree, &camera).tradeoff_pace)(
            &pace_task,
        )?),
        None => None,
    };
    let task =
        |method: &Method, cloud: &ply::GaussianCloud, options: Vec<(RenderOptions, Forward)>| {
            let task = Tradeoff {
                cloud,
                camera: &camera,
                gpu: gpu.as_ref(),
                iters: args.iters,
                options,
                bar: &bar,
                pace: pace.as_deref(),
            };
            (method.instance(cloud.sh_degree, &camera).tradeoff)(&task)
        };

    let tiles = |opts| vec![(opts, Forward::Tiles)];
    let mut options = tiles(reference_options());
    options.extend(settings.iter().map(|s| (s.opts, s.path)));
    let mut outcomes = task(method, &cloud, options)?.into_iter();
    let reference = outcomes.next().context("the reference frame")?;
    let mut rows: Vec<Row> = settings
        .iter()
        .zip(outcomes)
        .map(|(s, o)| compare(s.knob, s.value.clone(), &o, &reference))
        .collect();
    // SH degree: the scene's colors truncated to each lower degree, default options.
    for degree in (0..cloud.sh_degree).rev() {
        let lower = truncated(&cloud, degree);
        let o = one(task(method, &lower, tiles(RenderOptions::default()))?)?;
        rows.push(compare("sh_degree", degree.to_string(), &o, &reference));
    }
    // Evaluation model: every method on the same Gaussians, default options.
    let exact_reference = match exact {
        Some(e) => one(task(e, &cloud, tiles(reference_options()))?)?,
        None => reference,
    };
    for m in models {
        let o = one(task(m, &cloud, tiles(RenderOptions::default()))?)?;
        rows.push(compare("model", m.name.to_string(), &o, &exact_reference));
    }
    bar.finish_and_clear();
    if pace.is_none() {
        // The CPU's clock holds: each row against the default row, timed apart.
        let default = (rows.first()).map(|r| (r.forward_ms, r.backward_ms));
        if let Some((forward, backward)) = default {
            for r in &mut rows {
                r.forward_x = Some(r.forward_ms / forward);
                r.backward_x = r.backward_ms.zip(backward).map(|(b, d)| b / d);
            }
        }
    }
    print_table(&rows, pace.is_some());
    if let Some(e) = exact {
        println!("(model rows against {}'s most accurate render)", e.name);
    }
    write_outputs(&args.out, &rows, method.name)
}

/// The single outcome of a one-setting task.
fn one(outcomes: Vec<Outcome>) -> Result<Outcome> {
    outcomes.into_iter().next().context("no frame measured")
}

/// `cloud` with its colors cut to SH degree `degree`.
fn truncated(cloud: &ply::GaussianCloud, degree: u32) -> ply::GaussianCloud {
    let kept = ply::sh_coefficients(degree);
    let mut lower = ply::GaussianCloud {
        sh_degree: degree,
        ..cloud.clone()
    };
    for g in &mut lower.gaussians {
        g.sh[kept..].fill(Default::default());
    }
    lower
}

/// Frames of one method on one scene for each of `options`.
pub struct Tradeoff<'a> {
    cloud: &'a ply::GaussianCloud,
    camera: &'a Camera,
    gpu: Option<&'a Gpu>,
    iters: usize,
    options: Vec<(RenderOptions, Forward)>,
    bar: &'a indicatif::ProgressBar,
    /// The frame each setting is timed beside (GPU only).
    pace: Option<&'a (dyn PaceFrame + 'a)>,
}

/// The main method's frame at the default options on the scene, run in turn with each
/// setting's frames so that each time comes with a ratio taken at the same clock: a GPU's
/// clock follows its load, and the host's work between settings (building pipelines, comparing
/// the last one) lets it fall. In one H200 run it moved between 345 and 1,980 MHz, and
/// settings timed alone read up to 2.5x slower than the same work timed earlier.
pub(crate) trait PaceFrame {
    fn forward(&self) -> Result<Duration>;
    fn backward(&self) -> Result<Duration>;
    /// What it holds on the device, left out of each setting's memory.
    fn bytes(&self) -> usize;
}

/// A renderer's frames on the GPU, timed by the host's clock around the device's work.
struct GpuFrames<'a, M: SplatMethod> {
    gpu: &'a Gpu,
    camera: &'a Camera,
    renderer: GpuRenderer<'a, M>,
    /// Whether the loss gradient is in the renderer's output gradient buffer already.
    grad_on_device: bool,
}

impl<'a, M: SplatMethod> GpuFrames<'a, M> {
    fn new(gpu: &'a Gpu, camera: &'a Camera, opts: &RenderOptions) -> Result<Self> {
        Ok(GpuFrames {
            gpu,
            camera,
            renderer: GpuRenderer::<M>::new(gpu, opts)?,
            grad_on_device: false,
        })
    }

    fn forward(&mut self, scene: &GpuScene<M>) -> Result<Duration> {
        let t = Instant::now();
        self.renderer.forward(scene, self.camera)?;
        self.gpu.wait()?;
        Ok(t.elapsed())
    }

    /// The backward pass alone, after an untimed forward pass. The loss gradient goes up once,
    /// untimed, and the timed passes find it on the device, as `splat fit`'s loss leaves it:
    /// the host's check, interleave and upload of it would be the same for every setting and
    /// hide their differences.
    fn backward(&mut self, scene: &GpuScene<M>, grad: &FrameGrad) -> Result<Duration> {
        self.renderer.forward(scene, self.camera)?;
        let acc = Accumulation::default_for(self.gpu);
        if !self.grad_on_device {
            self.renderer.backward(scene, grad, acc)?;
            self.grad_on_device = true;
        }
        self.gpu.wait()?;
        let t = Instant::now();
        self.renderer.backward_on_device(scene, acc)?;
        self.gpu.wait()?;
        Ok(t.elapsed())
    }
}

/// [`GpuFrames`] with their own scene and loss gradient: a [`PaceFrame`].
struct Pace<'a, M: SplatMethod> {
    frames: RefCell<GpuFrames<'a, M>>,
    scene: GpuScene<M>,
    grad: FrameGrad,
    bytes: usize,
}

impl<M: SplatMethod> PaceFrame for Pace<'_, M> {
    fn forward(&self) -> Result<Duration> {
        self.frames.borrow_mut().forward(&self.scene)
    }

    fn backward(&self) -> Result<Duration> {
        self.frames.borrow_mut().backward(&self.scene, &self.grad)
    }

    fn bytes(&self) -> usize {
        self.bytes
    }
}

/// The fixed random linear loss's gradient on the color (uniform in [-0.5, 0.5) per channel).
fn loss_gradient<M: SplatMethod>(camera: &Camera) -> FrameGrad {
    let (w, h) = (camera.size.x as usize, camera.size.y as usize);
    let mut rng = fastrand::Rng::with_seed(1);
    let channels = <M::Color as splat_runtime::Flat>::LEN;
    FrameGrad {
        color: (0..w * h * channels).map(|_| rng.f32() - 0.5).collect(),
        alpha: None,
        depth: None,
    }
}

/// What one setting's frames gave.
pub(crate) struct Outcome {
    forward: Duration,
    /// None on the hardware path, which has no backward pass.
    backward: Option<Duration>,
    /// The times over the pace frame's, where there is one.
    forward_x: Option<f64>,
    backward_x: Option<f64>,
    /// Bytes the frame holds (CPU: kept for the backward pass; GPU: allocated on the device).
    bytes: usize,
    /// Sorted keys: (primitive, tile) pairs, or visible primitives on the hardware path.
    intersections: usize,
    /// Bytes the GPU's sort held (its keys, values and their scratch copies).
    sort_bytes: Option<usize>,
    color: Vec<f32>,
    /// Parameter gradient words per group (`param_groups`), primitive after primitive.
    gradients: Vec<(String, Vec<f64>)>,
}

/// A setting's errors against the reference.
#[derive(Default)]
struct Row {
    knob: &'static str,
    value: String,
    forward_ms: f64,
    backward_ms: Option<f64>,
    /// The times against the default's: beside the pace frame (GPU) or the default row (CPU).
    forward_x: Option<f64>,
    backward_x: Option<f64>,
    mib: f64,
    intersections: usize,
    sort_mib: Option<f64>,
    psnr: f64,
    max_abs: f64,
    /// Per parameter group: RMSE relative to the reference's RMS, and the mean relative error
    /// per magnitude range (None where the range holds no word). Only the groups the
    /// reference has with the same size (a lower SH degree has a smaller `sh`).
    groups: Vec<(String, f64, Vec<Option<f64>>)>,
}

impl Row {
    /// The worst group's relative RMSE (None without gradients); NaN if any group's is, which
    /// `f64::max` would pass over, reading as exact.
    fn gradient_error(&self) -> Option<f64> {
        let worst = (self.groups.iter().map(|g| g.1)).fold(0.0, |worst: f64, e| {
            if worst >= e || worst.is_nan() {
                worst
            } else {
                e
            }
        });
        (!self.groups.is_empty()).then_some(worst)
    }
}

impl<'a> Tradeoff<'a> {
    /// This method's default frame on the scene, the pace of every GPU setting.
    pub(crate) fn pace<M: SplatMethod>(&self) -> Result<Box<dyn PaceFrame + 'a>>
    where
        M::Params: FromStored,
    {
        let gpu = self.gpu.context("a pace frame needs a GPU")?;
        let before = allocated(gpu);
        let mut frames = GpuFrames::new(gpu, self.camera, &RenderOptions::default())?;
        let scene = GpuScene::<M>::new(gpu, &self.cloud.params::<M::Params>())?;
        let grad = loss_gradient::<M>(self.camera);
        // Its buffers grow to the frame's size on its first frames.
        frames.backward(&scene, &grad)?;
        Ok(Box::new(Pace {
            frames: RefCell::new(frames),
            scene,
            grad,
            bytes: allocated(gpu).saturating_sub(before),
        }))
    }

    pub(crate) fn run<M: SplatMethod>(&self) -> Result<Vec<Outcome>>
    where
        M::Params: FromStored,
    {
        let params: Vec<M::Params> = self.cloud.params();
        let grad = loss_gradient::<M>(self.camera);
        let scene = match self.gpu {
            Some(gpu) => Some(GpuScene::<M>::new(gpu, &params)?),
            None => None,
        };
        let groups = param_groups::<M>();
        let len = <M::Params as splat_runtime::Flat>::LEN;
        let mut out = vec![];
        for (opts, path) in &self.options {
            let (mut outcome, gradients) = match (self.gpu, &scene, path) {
                (Some(gpu), Some(scene), Forward::Hardware) => self.hardware(gpu, scene, opts)?,
                (Some(gpu), Some(scene), _) => self.on_gpu(gpu, scene, opts, &grad)?,
                _ => self.on_cpu::<M>(&params, opts, &grad)?,
            };
            let words: Vec<f64> = gradients
                .iter()
                .flat_map(splat_runtime::checks::words)
                .collect();
            outcome.gradients = groups
                .iter()
                .map(|(name, range)| {
                    let group = words
                        .chunks(len)
                        .flat_map(|p| p[range.clone()].iter().copied());
                    (name.clone(), group.collect())
                })
                .collect();
            out.push(outcome);
            self.bar.inc(1);
        }
        Ok(out)
    }

    fn on_cpu<M: SplatMethod>(
        &self,
        params: &[M::Params],
        opts: &RenderOptions,
        grad: &FrameGrad,
    ) -> Result<(Outcome, Vec<M::Params>)> {
        let camera = self.camera;
        let (forward, _) = paced(self.iters, NO_PACE, || {
            let t = Instant::now();
            splat_runtime::render::<M>(params, camera, opts)?;
            Ok(t.elapsed())
        })?;
        let (frame, state) = splat_runtime::render_for_backward::<M>(params, camera, opts)?;
        let (backward, _) = paced(self.iters, NO_PACE, || {
            let t = Instant::now();
            splat_runtime::backward::<M>(&state, params, camera, grad)?;
            Ok(t.elapsed())
        })?;
        let gradients = splat_runtime::backward::<M>(&state, params, camera, grad)?;
        let outcome = Outcome {
            forward,
            backward: Some(backward),
            forward_x: None,
            backward_x: None,
            bytes: state.bytes(),
            intersections: frame.stats.intersections,
            sort_bytes: None,
            color: frame.color.data,
            gradients: vec![],
        };
        Ok((outcome, gradients.params))
    }

    fn on_gpu<M: SplatMethod>(
        &self,
        gpu: &Gpu,
        scene: &GpuScene<M>,
        opts: &RenderOptions,
        grad: &FrameGrad,
    ) -> Result<(Outcome, Vec<M::Params>)> {
        let mut frames = GpuFrames::new(gpu, self.camera, opts)?;
        let pace_forward = self.pace.map(|p| move || p.forward());
        let (forward, forward_x) = paced(self.iters, pace_forward, || frames.forward(scene))?;
        let pace_backward = self.pace.map(|p| move || p.backward());
        let (backward, backward_x) =
            paced(self.iters, pace_backward, || frames.backward(scene, grad))?;
        let frame = frames.renderer.download_frame()?;
        let gradients = frames.renderer.download_gradients()?.gradients;
        let outcome = Outcome {
            forward,
            backward: Some(backward),
            forward_x,
            backward_x,
            bytes: self.allocated(gpu),
            intersections: frame.stats.intersections,
            sort_bytes: Some(frames.renderer.sort_bytes()),
            color: frame.color.data,
            gradients: vec![],
        };
        Ok((outcome, gradients.params))
    }

    /// The hardware-rasterized forward pass: no backward, so no gradients.
    fn hardware<M: SplatMethod>(
        &self,
        gpu: &Gpu,
        scene: &GpuScene<M>,
        opts: &RenderOptions,
    ) -> Result<(Outcome, Vec<M::Params>)> {
        let mut renderer = HardwareRenderer::<M>::new(gpu, opts)?;
        let pace_forward = self.pace.map(|p| move || p.forward());
        let (forward, forward_x) = paced(self.iters, pace_forward, || {
            let t = Instant::now();
            renderer.forward(scene, self.camera)?;
            gpu.wait()?;
            Ok(t.elapsed())
        })?;
        let frame = renderer.download_frame()?;
        let outcome = Outcome {
            forward,
            backward: None,
            forward_x,
            backward_x: None,
            bytes: self.allocated(gpu),
            intersections: frame.stats.intersections,
            sort_bytes: Some(renderer.sort_bytes()),
            color: frame.color.data,
            gradients: vec![],
        };
        Ok((outcome, vec![]))
    }
}

impl Tradeoff<'_> {
    /// Bytes allocated on the device but for the pace frame's.
    fn allocated(&self, gpu: &Gpu) -> usize {
        allocated(gpu).saturating_sub(self.pace.map_or(0, |p| p.bytes()))
    }
}

/// Bytes allocated on the device (0 where the backend does not report them).
fn allocated(gpu: &Gpu) -> usize {
    gpu.device
        .generate_allocator_report()
        .map_or(0, |r| r.total_allocated_bytes as usize)
}

/// A time in milliseconds, or empty.
fn ms(d: Option<f64>, digits: usize) -> String {
    d.map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn write_outputs(dir: &std::path::Path, rows: &[Row], method: &str) -> Result<()> {
    let mut summary = String::from(
        "knob,setting,forward_ms,forward_vs_default,backward_ms,backward_vs_default,memory_mib,intersections,sort_mib,psnr_db,max_abs,gradient_rel_rmse\n",
    );
    // The ranges hold a comma: quoted, as CSV quotes such fields.
    let mut detail = String::from("knob,setting,group,rel_rmse,range,mre\n");
    for r in rows {
        let empty = |v: Option<String>| v.unwrap_or_default();
        writeln!(
            summary,
            "{},{},{:.4},{},{},{},{:.3},{},{},{:.3},{:.6e},{}",
            r.knob,
            r.value,
            r.forward_ms,
            empty(r.forward_x.map(|v| format!("{v:.4}"))),
            empty(r.backward_ms.map(|v| format!("{v:.4}"))),
            empty(r.backward_x.map(|v| format!("{v:.4}"))),
            r.mib,
            r.intersections,
            empty(r.sort_mib.map(|v| format!("{v:.3}"))),
            r.psnr,
            r.max_abs,
            empty(r.gradient_error().map(|v| format!("{v:.6e}")))
        )?;
        for (group, rmse, mres) in &r.groups {
            for ((_, _, range), mre) in RANGES.iter().zip(mres) {
                let mre = mre.map_or(String::new(), |v| format!("{v:.6e}"));
                writeln!(
                    detail,
                    "{},{},{group},{rmse:.6e},\"{range}\",{mre}",
                    r.knob, r.value
                )?;
            }
        }
    }
    // The tables and their plot appear together.
    let mut outputs = Outputs::default();
    for (name, text) in [("tradeoff.csv", &summary), ("gradients.csv", &detail)] {
        let path = dir.join(name);
        (outputs.stage(&path, |w| w.write_all(text.as_bytes())))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    draw(&mut outputs, &dir.join("tradeoff.png"), rows, method)?;
    outputs.commit()?;
    crate::wrote(dir);
    Ok(())
}

/// No pace frame (the CPU's).
const NO_PACE: Option<fn() -> Result<Duration>> = None;

/// The median time of `iters` runs of `run` after a warm-up and, given a pace frame, the
/// median of each run's time over that of the pace frame run after it.
fn paced(
    iters: usize,
    mut pace: Option<impl FnMut() -> Result<Duration>>,
    mut run: impl FnMut() -> Result<Duration>,
) -> Result<(Duration, Option<f64>)> {
    let mut round = || -> Result<(Duration, Option<f64>)> {
        let t = run()?;
        let x = match &mut pace {
            Some(pace) => Some(t.as_secs_f64() / pace()?.as_secs_f64()),
            None => None,
        };
        Ok((t, x))
    };
    crate::warm_up::warm_up(&mut round)?;
    let rounds = (0..iters).map(|_| round()).collect::<Result<Vec<_>>>()?;
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let time = median(rounds.iter().map(|r| r.0.as_secs_f64()).collect());
    let ratios: Option<Vec<f64>> = rounds.iter().map(|r| r.1).collect();
    Ok((Duration::from_secs_f64(time), ratios.map(median)))
}

fn compare(knob: &'static str, value: String, o: &Outcome, reference: &Outcome) -> Row {
    let diffs = o.color.iter().zip(&reference.color);
    let (sq, max_abs) = diffs.fold((0.0f64, 0.0f64), |(sq, mx), (a, b)| {
        let d = (*a as f64 - *b as f64).abs();
        (sq + d * d, mx.max(d))
    });
    let mse = sq / o.color.len().max(1) as f64;
    let groups = o
        .gradients
        .iter()
        .filter_map(|(name, got)| {
            let (_, want) = reference
                .gradients
                .iter()
                .find(|(n, w)| n == name && w.len() == got.len())?;
            let (rmse, mres) = gradient_errors(got, want);
            Some((name.clone(), rmse, mres))
        })
        .collect();
    Row {
        knob,
        value,
        forward_ms: o.forward.as_secs_f64() * 1e3,
        backward_ms: o.backward.map(|d| d.as_secs_f64() * 1e3),
        forward_x: o.forward_x,
        backward_x: o.backward_x,
        mib: o.bytes as f64 / 1048576.0,
        intersections: o.intersections,
        sort_mib: o.sort_bytes.map(|b| b as f64 / 1048576.0),
        psnr: -10.0 * mse.log10(),
        max_abs,
        groups,
    }
}

/// RMSE relative to the reference's RMS, and the mean relative error of the words whose
/// reference magnitude (relative to the largest) falls in each of [`RANGES`].
fn gradient_errors(got: &[f64], want: &[f64]) -> (f64, Vec<Option<f64>>) {
    let n = want.len().max(1) as f64;
    let rms = (want.iter().map(|w| w * w).sum::<f64>() / n).sqrt();
    // Summed from +0: `sum` starts from -0, and an empty scene's error printed as -0.
    let sq = got
        .iter()
        .zip(want)
        .fold(0.0, |sum, (g, w)| sum + (g - w) * (g - w));
    let rmse = match rms > 0.0 {
        true => (sq / n).sqrt() / rms,
        false => (sq / n).sqrt(),
    };
    let largest = want.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let mres = RANGES
        .iter()
        .map(|&(lo, hi, _)| {
            let errors: Vec<f64> = got
                .iter()
                .zip(want)
                .filter(|(_, w)| {
                    let r = w.abs() / largest;
                    largest > 0.0 && r >= lo && r < hi
                })
                .map(|(g, w)| ((g - w) / w).abs())
                .collect();
            (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
        })
        .collect();
    (rmse, mres)
}

fn print_table(rows: &[Row], paced: bool) {
    println!(
        "\n| knob | setting | forward ms | x default | backward ms | x default | MiB | sorted keys | sort MiB | PSNR dB | max abs | gradient rel. RMSE (worst group) |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        println!(
            "| {} | {} | {:.2} | {} | {} | {} | {:.1} | {} | {} | {:.1} | {:.1e} | {} |",
            r.knob,
            r.value,
            r.forward_ms,
            ms(r.forward_x, 2),
            ms(r.backward_ms, 2),
            ms(r.backward_x, 2),
            r.mib,
            r.intersections,
            ms(r.sort_mib, 1),
            r.psnr,
            r.max_abs,
            r.gradient_error()
                .map_or("-".into(), |e| format!("{e:.1e}"))
        );
    }
    println!("(PSNR and errors against the reference; inf: the same image)");
    println!(
        "(x default: {})",
        match paced {
            true =>
                "each frame's time over the default frame's run after it, the median of the rounds",
            false => "the time over the default row's",
        }
    );
}

/// Errors at or below this (an exact match) are drawn on the floor of the log axis.
const FLOOR: f64 = 1e-9;

/// A color per knob, in the order the sweep first names them.
const COLORS: [RGBColor; 11] = [
    RGBColor(200, 30, 40),
    RGBColor(40, 150, 60),
    RGBColor(30, 90, 200),
    RGBColor(230, 120, 20),
    RGBColor(130, 60, 170),
    RGBColor(90, 90, 90),
    RGBColor(0, 150, 160),
    RGBColor(150, 100, 40),
    RGBColor(220, 60, 150),
    RGBColor(110, 160, 20),
    RGBColor(20, 40, 110),
];

/// Two panels: forward time against image RMSE, forward + backward time against the worst
/// group's gradient error; a color per knob, and the Pareto front of the settings measured
/// against the same reference.
fn draw(outputs: &mut Outputs, path: &std::path::Path, rows: &[Row], method: &str) -> Result<()> {
    let knobs: Vec<&str> = rows.iter().fold(vec![], |mut k, r| {
        if !k.contains(&r.knob) {
            k.push(r.knob);
        }
        k
    });
    // Times as ratios to the default's (`x default`), which hold where a GPU's clock moves; a
    // frame's forward and backward ratios weighed by the default row's times.
    let Some(default) = rows.first() else {
        bail!("no settings to plot");
    };
    let (forward, backward) = (default.forward_ms, default.backward_ms.unwrap_or(0.0));
    let x = |r: &Row| r.forward_x.unwrap_or(f64::NAN);
    let image: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (x(r), 10f64.powf(-r.psnr / 20.0)))
        .collect();
    // Only the settings with a backward pass have a gradient point.
    let with_gradients: Vec<&Row> = rows.iter().filter(|r| r.backward_ms.is_some()).collect();
    // A NaN error has no place on the axis: the tables show it.
    let gradient: Vec<(f64, f64)> = with_gradients
        .iter()
        .map(|r| {
            let b = r.backward_x.unwrap_or(f64::NAN);
            let time = (x(r) * forward + b * backward) / (forward + backward);
            (time, r.gradient_error().unwrap_or(0.0))
        })
        .filter(|(_, e)| !e.is_nan())
        .collect();
    plot::png(outputs, path, (1400, 560), |root| {
        let panels = root.split_evenly((1, 2));
        let all: Vec<&Row> = rows.iter().collect();
        let series = [
            (
                "image against forward time",
                "forward time, x the default's",
                "image RMSE",
                &image,
                &all,
            ),
            (
                "gradients against forward + backward time",
                "forward + backward time, x the default's",
                "gradient rel. RMSE, worst group",
                &gradient,
                &with_gradients,
            ),
        ];
        for (area, (caption, x_desc, y_desc, points, rows)) in panels.iter().zip(series) {
            let caption = format!("{method}: {caption}");
            let axes = (x_desc, y_desc);
            panel(area, &caption, axes, points, rows, &knobs)?;
        }
        Ok(())
    })
}

fn panel(
    area: &plot::Area,
    caption: &str,
    (x_desc, y_desc): (&str, &str),
    points: &[(f64, f64)],
    rows: &[&Row],
    knobs: &[&str],
) -> Result<()> {
    let y = |v: f64| v.max(FLOOR).log10();
    let (x_hi, y_lo, y_hi) = points.iter().fold(
        (0.0f64, f64::INFINITY, f64::NEG_INFINITY),
        |(xh, lo, hi), &(x, v)| (xh.max(x), lo.min(y(v)), hi.max(y(v))),
    );
    let err = plot::drawing(format!("chart \"{caption}\""));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, plot::text(16))
        .margin(12)
        .margin_right(24)
        .x_label_area_size(40)
        .y_label_area_size(76)
        // Room on the right for the legend, past the slowest setting.
        .build_cartesian_2d(0.0..x_hi * 1.45, (y_lo - 0.5)..(y_hi + 0.5))
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(format!("{y_desc} (exact: at {FLOOR:e})"))
        .y_label_formatter(&|v| format!("{:.0e}", 10f64.powf(*v)))
        .label_style(plot::text(13))
        .draw()
        .map_err(&err)?;
    // The Pareto front: the settings no other setting beats in both time and error. The model
    // rows are measured against another reference (the exact method's), so they stay out.
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| rows[i].knob != "model")
        .collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0));
    let mut front = vec![];
    for i in order {
        if front.last().is_none_or(|&(_, e)| y(points[i].1) < e) {
            front.push((points[i].0, y(points[i].1)));
        }
    }
    chart
        .draw_series(LineSeries::new(front, BLACK.mix(0.4).stroke_width(2)))
        .map_err(&err)?
        .label("Pareto front (without model)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.mix(0.4)));
    for (k, knob) in knobs.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let mine: Vec<(f64, f64, &str)> = rows
            .iter()
            .zip(points)
            .filter(|(r, _)| r.knob == *knob)
            .map(|(r, &(x, v))| (x, y(v), r.value.as_str()))
            .collect();
        if mine.is_empty() {
            continue;
        }
        chart
            .draw_series(
                mine.iter()
                    .map(|&(x, v, _)| Circle::new((x, v), 5, color.filled())),
            )
            .map_err(&err)?
            .label(*knob)
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, color.filled()));
        if *knob != "default" {
            chart
                .draw_series(mine.iter().map(|&(x, v, label)| {
                    let style = plot::text(12).color(&color);
                    EmptyElement::at((x, v)) + Text::new(label.to_string(), (7, -14), style)
                }))
                .map_err(&err)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK.mix(0.3))
        .label_font(plot::text(13))
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(&err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The worst group's error is NaN when one group's is.
    #[test]
    fn a_nan_group_is_the_worst() {
        let row = |errors: &[f64]| Row {
            groups: errors.iter().map(|&e| ("g".into(), e, vec![])).collect(),
            ..Row::default()
        };
        assert_eq!(row(&[0.5, 0.25]).gradient_error(), Some(0.5));
        assert!(
            row(&[0.5, f64::NAN, 0.25])
                .gradient_error()
                .unwrap()
                .is_nan()
        );
        assert!(row(&[f64::NAN, 0.5]).gradient_error().unwrap().is_nan());
        assert_eq!(row(&[]).gradient_error(), None);
    }

    /// Exact gradients, and none at all (an empty scene), are 0 off, not -0.
    #[test]
    fn no_error_is_plus_zero() {
        for (got, want) in [(&[][..], &[][..]), (&[1.0, -2.0][..], &[1.0, -2.0][..])] {
            let (rmse, _) = gradient_errors(got, want);
            assert_eq!(format!("{rmse:.6e}"), "0.000000e0");
        }
    }
}
