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
use anyhow::{Context, Result};
use splat_runtime::blend::Blend;
use splat_runtime::gpu::entries::Accumulation;
use splat_runtime::gpu::{Gpu, GpuRenderer, GpuScene, HardwareRenderer};
use splat_runtime::io::ply;
use splat_runtime::io::ply::FromStored;
use splat_runtime::precision::Precision;
use splat_runtime::{Camera, FrameGrad, RenderOptions, SplatMethod, param_groups};
use std::cell::RefCell;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct TradeoffArgs {
    /// INRIA 3DGS PLY scene (default: the built-in one).
    #[arg(long)]
    pub(crate) scene: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) camera: crate::view::CameraArgs,
    #[arg(long)]
    pub(crate) method: String,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub(crate) backend: Backend,
    /// Timed frames per setting and pass (after 0.3 s of warm-up frames); the median is reported.
    #[arg(long, default_value_t = 5)]
    pub(crate) iters: usize,
    /// Output folder: tradeoff.csv (one row per setting), gradients.csv (per parameter group
    /// and magnitude range) and tradeoff.png (time against error, with the Pareto front).
    #[arg(long, default_value = "tradeoff")]
    pub(crate) out: PathBuf,

    /// The built-in camera's width (a camera file gives its own).
    #[arg(long, default_value_t = 800, conflicts_with = "camera")]
    pub(crate) width: u32,
    /// The built-in camera's height (a camera file gives its own).
    #[arg(long, default_value_t = 600, conflicts_with = "camera")]
    pub(crate) height: u32,
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

/// Frames of one method on one scene for each of `options`.
pub struct Tradeoff<'a> {
    pub(crate) cloud: &'a ply::GaussianCloud,
    pub(crate) camera: &'a Camera,
    pub(crate) gpu: Option<&'a Gpu>,
    pub(crate) iters: usize,
    pub(crate) options: Vec<(RenderOptions, Forward)>,
    pub(crate) bar: &'a indicatif::ProgressBar,
    /// The frame each setting is timed beside (GPU only).
    pub(crate) pace: Option<&'a (dyn PaceFrame + 'a)>,
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
    pub(crate) forward: Duration,
    /// None on the hardware path, which has no backward pass.
    pub(crate) backward: Option<Duration>,
    /// The times over the pace frame's, where there is one.
    pub(crate) forward_x: Option<f64>,
    pub(crate) backward_x: Option<f64>,
    /// Bytes the frame holds (CPU: kept for the backward pass; GPU: allocated on the device).
    pub(crate) bytes: usize,
    /// Sorted keys: (primitive, tile) pairs, or visible primitives on the hardware path.
    pub(crate) intersections: usize,
    /// Bytes the GPU's sort held (its keys, values and their scratch copies).
    pub(crate) sort_bytes: Option<usize>,
    pub(crate) color: Vec<f32>,
    /// Parameter gradient words per group (`param_groups`), primitive after primitive.
    pub(crate) gradients: Vec<(String, Vec<f64>)>,
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
                    (name.to_string(), group.collect())
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
