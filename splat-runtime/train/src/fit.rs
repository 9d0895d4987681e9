//! The training loop, the same for every method: pick a view, render, loss, backward, Adam
//! step, and every so often adaptive density control. A method takes part by implementing
//! [`Trainable`] (its learning rates, how a primitive starts from a point, and where its
//! shape is) in its own file. This is the CPU loop; [`super::gpu_fit`] runs the same steps on
//! the device.

use super::adam::{Adam, Faults};
use super::batch::{Batch, Scaling, batches};
use super::checkpoint::{Checkpoint, ViewsFootprint};
use super::densify::{Densifier, DensifyOptions, Refinement, screen_gradient};
use super::loss::{self, LossError, LossValue};
use super::mcmc::{Mcmc, McmcOptions};
use super::per_view::{Cameras, Corrections, PerViewOptions, PerViewState};
use super::step_times::StepTimes;
use super::team::{Share, Solo, Team, ViewPass};
use super::trainable::{Rate, Shape, Trainable};
use glam::Vec3;
use splat_core::flat::{Flat, flatten, read_all};
use splat_core::frame::{Frame, FrameGrad, Image, RenderError, RenderOptions};
use splat_core::method::{SplatMethod, param_groups, word_name};
use splat_io::dataset::{Dataset, View};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Each word's rate for `batch` (at its first step) of `steps` as Adam takes it (on both
/// backends), times the batch's `scale` ([`Scaling::learning_rate`]): negative for a word not
/// trained yet, which then neither moves nor gathers moments (they start from zero).
pub(crate) fn step_rates(rates: &[Rate], batch: Batch, steps: usize, scale: f32) -> Vec<f32> {
    let step = batch.first;
    rates
        .iter()
        .map(|r| match step < r.from_step {
            true => -1.0,
            false => r.at(step, steps) * scale,
        })
        .collect()
}

/// The training views of `batch`, drawn at random (their indices), each with its background
/// ([`step_background`]): the same draws on every rank and on both backends.
pub(crate) fn draw_views(
    data: &Dataset,
    batch: Batch,
    opts: &FitOptions,
    rng: &mut fastrand::Rng,
) -> Vec<(usize, Vec3)> {
    (batch.steps())
        .map(|_| {
            let k = rng.usize(..data.train.len());
            (k, step_background(opts, rng))
        })
        .collect()
}

/// Whether the run ends after this batch: `asked` (some rank was asked to stop before the
/// batch's gather: every rank then ends after it), or alone, a request during the batch's
/// evaluation.
pub(crate) fn stops_after(team: &dyn Team, asked: bool, opts: &FitOptions) -> bool {
    asked || (team.ranks() == 1 && opts.stop_requested())
}

#[derive(Clone, Debug)]
pub struct FitOptions {
    /// How many views the run trains on (one per step, or `batch` per Adam step).
    pub steps: usize,
    /// Views per Adam step, their losses summed ([`super::batch`]); every schedule still
    /// counts views.
    pub batch: usize,
    /// λ of `(1 - λ) L1 + λ (1 - SSIM)`.
    pub ssim_weight: f64,
    /// What the images were composited on; the render is composited the same way.
    pub background: Vec3,
    /// How each step renders; its `gradients` are the parameter groups trained, the others
    /// stay frozen ([`frozen_groups`]; the camera is never trained).
    pub render: RenderOptions,
    pub seed: u64,
    /// A random background color per step instead of `background` (the targets' transparent
    /// parts re-composited on it), so that the scene cannot paint the background in.
    pub random_background: bool,
    /// How the primitive set changes, or not at all (the primitive count stays fixed).
    pub densify: Option<Strategy>,
    /// What the run learns per training view besides the scene (its exposure, its pose).
    pub per_view: PerViewOptions,
    /// Evaluate the test views after every this many steps (reported in [`StepReport`]);
    /// `None`: never during training.
    pub eval_every: Option<usize>,
    /// Report the run's state (to save as a checkpoint) after every this many steps and after
    /// the last.
    pub checkpoint_every: Option<usize>,
    /// Hand the scene to the caller after every this many steps ([`StepReport::scene`]):
    /// what a live viewer shows. On the GPU each costs a download of the parameters.
    pub share_every: Option<usize>,
    /// Once set (by a signal handler, another thread), the run ends after the step in
    /// progress: that step's state is reported as a checkpoint (where checkpoints are on) and
    /// left in the loop's `state`, whose `step` then falls short of `steps`.
    pub stop: Option<Arc<AtomicBool>>,
}

impl FitOptions {
    /// Whether the run was asked to stop ([`FitOptions::stop`]).
    pub fn stop_requested(&self) -> bool {
        self.stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            steps: 3000,
            batch: 1,
            ssim_weight: 0.2,
            background: Vec3::ZERO,
            render: RenderOptions {
                tile_size: 16,
                alpha: true,
                ..Default::default()
            },
            seed: 0,
            random_background: false,
            densify: Some(Strategy::Adc(DensifyOptions::default())),
            per_view: PerViewOptions::default(),
            eval_every: None,
            checkpoint_every: None,
            share_every: None,
            stop: None,
        }
    }
}

/// How the primitive set changes during training.
#[derive(Clone, Debug)]
pub enum Strategy {
    /// 3DGS's adaptive density control: clone, split, prune, reset opacities.
    Adc(DensifyOptions),
    /// MCMC: relocate dead primitives, grow by a fraction, position noise, opacity and scale
    /// penalties.
    Mcmc(McmcOptions),
}

impl Strategy {
    /// The strategy's name, as the command line spells it (`fixed` for none).
    pub fn name(strategy: Option<&Strategy>) -> &'static str {
        match strategy {
            Some(Strategy::Adc(d)) if !d.opacity_resets => "adc without opacity resets",
            Some(Strategy::Adc(_)) => "adc",
            Some(Strategy::Mcmc(_)) => "mcmc",
            None => "fixed",
        }
    }

    /// The cap on the number of primitives.
    pub fn max_primitives(&self) -> usize {
        match self {
            Strategy::Adc(d) => d.max_primitives,
            Strategy::Mcmc(m) => m.max_primitives,
        }
    }
}

impl FitOptions {
    /// Adaptive density control's options, when that is the strategy.
    pub fn adc(&self) -> Option<&DensifyOptions> {
        match &self.densify {
            Some(Strategy::Adc(d)) => Some(d),
            _ => None,
        }
    }

    /// MCMC for `M`, when that is the strategy.
    pub(crate) fn mcmc<M: Trainable>(&self) -> Result<Option<Mcmc>, FitError> {
        match &self.densify {
            Some(Strategy::Mcmc(o)) => Ok(Some(
                Mcmc::new::<M>(o.clone()).map_err(FitError::Unsupported)?,
            )),
            _ => Ok(None),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Loss(#[from] LossError),
    #[error("the dataset has no training views")]
    NoViews,
    #[error("GPU: {0}")]
    Gpu(String),
    #[error("{0}")]
    Unsupported(String),
}

/// PSNR, SSIM and loss over a set of views.
#[derive(Clone, Copy, Debug, Default)]
pub struct Evaluation {
    pub psnr: f64,
    pub ssim: f64,
    pub views: usize,
}

/// Renders `view` with `params` composited on `opts.background`.
pub fn render_view<M: SplatMethod>(
    params: &[M::Params],
    view: &View,
    opts: &FitOptions,
) -> Result<Image, FitError> {
    render_training_view::<M>(params, view, opts, Corrections::default())
}

/// [`render_view`] through a training view's `corrections` (its and its camera's words of
/// the run's per-view state, [`PerViewState::training`]): the view as training compares it.
pub fn render_training_view<M: SplatMethod>(
    params: &[M::Params],
    view: &View,
    opts: &FitOptions,
    corrections: Corrections,
) -> Result<Image, FitError> {
    let camera = opts.per_view.camera(&view.camera, corrections);
    let frame = splat_cpu::render::<M>(params, &camera, &for_training(&opts.render))?;
    let mut color = frame.color;
    if let Some(e) = opts.per_view.exposure(corrections) {
        e.apply(&mut color);
    }
    Ok(composite(color, frame.alpha.as_ref(), opts.background))
}

/// The render options training renders with: alpha for compositing the background, and no
/// camera gradient.
pub(crate) fn for_training(r: &RenderOptions) -> RenderOptions {
    RenderOptions {
        alpha: true,
        gradients: r.gradients.with_camera(false),
        ..*r
    }
}

/// [`for_training`] for a training step of `opts`: with the camera's gradient where the run
/// learns each view's pose or each camera's intrinsics.
pub(crate) fn step_render(opts: &FitOptions) -> RenderOptions {
    let r = for_training(&opts.render);
    let per_view = &opts.per_view;
    RenderOptions {
        gradients: r
            .gradients
            .with_camera(per_view.pose || per_view.intrinsics),
        ..r
    }
}

/// `color` (rendered on black) composited on `background` through `alpha`, as training and
/// evaluation see a render.
pub fn composite(mut color: Image, alpha: Option<&Image>, background: Vec3) -> Image {
    if let Some(a) = alpha {
        let b = background.to_array();
        for (px, a) in color.data.chunks_exact_mut(3).zip(&a.data) {
            for (c, b) in px.iter_mut().zip(b) {
                *c += (1.0 - a) * b;
            }
        }
    }
    color
}

/// Renders each of `views` with `params`, composited on `opts.background`.
pub fn render_views<M: SplatMethod>(
    params: &[M::Params],
    views: &[View],
    opts: &FitOptions,
) -> Result<Vec<Image>, FitError> {
    views
        .iter()
        .map(|v| render_view::<M>(params, v, opts))
        .collect()
}

impl Evaluation {
    /// Mean PSNR and SSIM of `images` against the pictures of `views`.
    pub fn of(images: &[Image], views: &[View]) -> Result<Evaluation, FitError> {
        if images.len() != views.len() {
            return Err(FitError::Unsupported(format!(
                "an evaluation takes one image per view: {} images, {} views",
                images.len(),
                views.len()
            )));
        }
        let mut e = Evaluation {
            views: views.len(),
            ..Default::default()
        };
        for (img, v) in images.iter().zip(views) {
            let picture = v.image();
            e.psnr += loss::psnr(img, &picture)? / views.len() as f64;
            e.ssim += loss::ssim(img, &picture)? / views.len() as f64;
        }
        Ok(e)
    }
}

/// Mean PSNR and SSIM of `params` over `views`.
pub fn evaluate<M: SplatMethod>(
    params: &[M::Params],
    views: &[View],
    opts: &FitOptions,
) -> Result<Evaluation, FitError> {
    Evaluation::of(&render_views::<M>(params, views, opts)?, views)
}

/// Whether `batch` is the run's last: it holds its final step, or the run `stops` after it
/// ([`FitOptions::stop`]).
pub(crate) fn ends_after(opts: &FitOptions, batch: Batch, stops: bool) -> bool {
    batch.last() + 1 == opts.steps || stops
}

/// Whether a checkpoint is reported after `batch`: every `FitOptions::checkpoint_every` steps
/// and after the run's last ([`ends_after`]).
pub(crate) fn saves_at(opts: &FitOptions, batch: Batch, stops: bool) -> bool {
    batch.any(|s| after_every(opts.checkpoint_every, s))
        || (ends_after(opts, batch, stops) && opts.checkpoint_every.is_some_and(|n| n > 0))
}

/// Whether something done every `every` steps (`FitOptions::eval_every`,
/// `checkpoint_every`) is done after `step` (counted from zero).
pub(crate) fn after_every(every: Option<usize>, step: usize) -> bool {
    every.is_some_and(|n| n > 0 && (step + 1).is_multiple_of(n))
}

/// What a step reports to the caller's progress callback.
pub struct StepReport<'a> {
    /// The last step (view) this Adam step took, counted from zero.
    pub step: usize,
    /// How many views it took (`FitOptions::batch`, fewer in a run's last).
    pub views: usize,
    pub loss: &'a LossValue,
    pub primitives: usize,
    /// Set on the steps that refined the primitive set.
    pub refinement: Option<&'a Refinement>,
    /// The parameter words this step's Adam step could not move (non-finite gradients, or
    /// steps that would have left a non-finite word): they kept their values and the rest of
    /// the scene trained.
    pub faults: Faults,
    /// The per-view and per-camera words ([`FitOptions::per_view`]) it could not move, by
    /// their index in [`Checkpoint::per_view`]'s views' words, then its cameras' past them.
    pub view_faults: Faults,
    /// The test views' PSNR and SSIM after this step, on the steps `FitOptions::eval_every`
    /// asks for.
    pub evaluation: Option<Evaluation>,
    /// The run's state after this step, on the steps `FitOptions::checkpoint_every` asks for
    /// (and the last).
    pub checkpoint: Option<&'a Checkpoint>,
    /// The parameters after this step (`M::Params::LEN` words per primitive), on the steps
    /// `FitOptions::share_every` asks for.
    pub scene: Option<&'a [f32]>,
    /// Where this step's time went.
    pub times: StepTimes,
}

/// Host memory a CPU step takes per pixel of its view, beyond the views themselves: the
/// forward pass's per-tile outputs and the frame they are gathered into (color,
/// transmittance, where each walk ended: 20 bytes each), the alpha, the step's target in f32,
/// the loss's color gradient and the alpha gradient, about 60 bytes, and what the allocator
/// keeps on top. Measured: one step's peak resident memory grew by 74 bytes per pixel
/// between views of 1 and 12 megapixels (`splat fit DATASET --steps 2 --backend cpu`).
pub const CPU_STEP_BYTES_PER_PIXEL: u64 = 80;

/// Trains `params` on the training views of `data` for `opts.steps` steps on the CPU (with
/// density control, `params` grows and shrinks); `extent` is the scene's radius; `progress` is
/// called after every step.
pub fn fit<M: Trainable>(
    data: &Dataset,
    params: &mut Vec<M::Params>,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    from_params::<M>(params, opts, |state| {
        fit_from::<M>(data, state, extent, opts, progress)
    })
}

/// Runs `train` from the first state of a run on `params` ([`Checkpoint::start`]) and leaves
/// the run's last scene in `params`: what each backend's `fit` does around its `fit_from`.
pub(crate) fn from_params<M: Trainable>(
    params: &mut Vec<M::Params>,
    opts: &FitOptions,
    train: impl FnOnce(&mut Checkpoint) -> Result<(), FitError>,
) -> Result<(), FitError> {
    let mut state = Checkpoint::start::<M>(params, opts.steps, opts.seed);
    train(&mut state)?;
    *params = state.params::<M>();
    Ok(())
}

/// Trains on the CPU from `state` (a run's first state, [`Checkpoint::start`], or a checkpoint
/// it reported) to its last step, or to the step in progress when `opts.stop` is set; `state`
/// ends as the run's state after that step. The same steps follow from a checkpoint as in the
/// run that wrote it.
pub fn fit_from<M: Trainable>(
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    fit_shared::<M>(&Solo, data, state, extent, opts, progress)
}

/// [`fit_from`] shared among the processes of `team`: each renders its share of every batch,
/// and all take the same steps (the same scene, bit for bit, as one process with the same
/// batch). Every rank must start from the same `state`.
pub fn fit_shared<M: Trainable>(
    team: &dyn Team,
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    fit_with::<M>(team, data, state, extent, opts, Frames::Cpu, progress)
}

/// Where the CPU loop's views are rendered and differentiated.
pub(crate) enum Frames<'g, M: SplatMethod> {
    /// splat's CPU backend.
    Cpu,
    /// The GPU's hardware path ([`super::hardware_fit`]).
    #[cfg(feature = "gpu")]
    Hardware(Box<super::hardware_fit::HardwareFrames<'g, M>>),
    /// Holds the parameters without the GPU; never made.
    #[cfg(not(feature = "gpu"))]
    #[allow(dead_code)]
    Never(std::marker::PhantomData<&'g M>),
}

/// [`fit_shared`] with each view's frame and gradients from `frames`.
pub(crate) fn fit_with<M: Trainable>(
    team: &dyn Team,
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    mut frames: Frames<M>,
    mut progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    let rates = rates_for::<M>(data, extent, opts)?;
    adopt::<M>(state, extent, &data.train, opts)?;
    let words = M::Params::LEN;
    let mut params = state.params::<M>();
    let mut flat = state.params.clone();
    let mut adam = Adam::resume(words, state.adam.clone());
    let scaling = Scaling::for_batch(opts.batch, adam.beta1, adam.beta2);
    (adam.beta1, adam.beta2) = (scaling.beta1, scaling.beta2);
    let mut grads = vec![0.0f32; flat.len()];
    let mut densifier = (opts.adc())
        .map(|d| Densifier::resume(d.clone(), params.len(), &state.grad2d, &state.seen));
    let mcmc = opts.mcmc::<M>()?;
    let mut rng = fastrand::Rng::with_seed(state.rng);
    let mut target = no_target();
    let cameras = Cameras::of(data.train.iter().map(|v| &v.camera));
    for batch in batches(state.step, opts.steps, opts.batch) {
        let started = Instant::now();
        let draws = draw_views(data, batch, opts, &mut rng);
        let observing = densifier
            .as_ref()
            .is_some_and(|d| batch.first < d.opts.stop);
        let mut times = StepTimes::default();
        let mine = (draws[batch.share(team.rank(), team.ranks())].iter())
            .map(|&(k, background)| {
                let corrections = state.per_view.training(&opts.per_view, &cameras, k);
                let view = (k, &data.train[k], corrections);
                let target = &mut target;
                let frames = &mut frames;
                view_pass::<M>(
                    &params, view, background, opts, observing, target, &mut times, frames,
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let clock = Instant::now();
        let mine = Share {
            passes: mine,
            stop: opts.stop_requested(),
        };
        let shares = team.gather(mine)?;
        times.exchange = clock.elapsed();
        let asked_to_stop = shares.iter().any(|s| s.stop);
        let passes: Vec<ViewPass> = shares.into_iter().flat_map(|s| s.passes).collect();
        let fits = |p: &ViewPass| {
            p.grads.len() == flat.len()
                && p.view < data.train.len()
                && p.corrections.len() == opts.per_view.gradient_words()
        };
        if passes.len() != batch.len || !passes.iter().all(fits) {
            return Err(FitError::Unsupported(format!(
                "the ranks' passes do not fit the batch of {} views and {} words",
                batch.len,
                flat.len()
            )));
        }
        let clock = Instant::now();
        // The batch's views in order: the same sums on every rank and in one process.
        grads.fill(0.0);
        for p in &passes {
            for (a, g) in grads.iter_mut().zip(&p.grads) {
                *a += g;
            }
        }
        let value = LossValue::mean(passes.iter().map(|p| p.loss));
        if let Some(m) = &mcmc {
            m.regularize(&flat, &mut grads, words, batch.len);
        }
        let lr = step_rates(&rates, batch, opts.steps, scaling.learning_rate);
        let faults = adam.step(&mut flat, &grads, &lr);
        let by_view = passes.iter().map(|p| (p.view, &p.corrections[..]));
        let run = (batch.first, opts.steps);
        let view_faults = (state.per_view).step(&opts.per_view, &cameras, by_view, run, extent);
        times.optimizer = clock.elapsed();
        let mut refinement = None;
        if let Some(m) = &mcmc {
            let clock = Instant::now();
            if batch.any(|s| m.opts.refines_at(s)) {
                read_all(&mut params, &flat);
                let r = m.refine::<M>(&mut params, &mut rng);
                adam.remap(&r.origin);
                flat = flatten(&params);
                grads = vec![0.0; flat.len()];
                refinement = Some(r);
            }
            times.densify = clock.elapsed();
            let clock = Instant::now();
            // A position not trained yet (a negative rate) is not stirred either.
            let rate = lr[m.words.position].max(0.0);
            m.perturb(&mut flat, words, rate, rng.u32(..));
            times.optimizer += clock.elapsed();
        }
        read_all(&mut params, &flat);
        if let Some(d) = densifier.as_mut().filter(|_| observing) {
            let clock = Instant::now();
            for p in &passes {
                d.observe(p.seen.iter().map(|&(i, norm)| (i as usize, norm)));
            }
            times.statistics += clock.elapsed();
            let clock = Instant::now();
            if let Some(step) = batch.steps().find(|&s| d.refines_at(s)) {
                let r = d.refine::<M>(&mut params, step, extent, &mut rng);
                adam.remap(&r.origin);
                flat = flatten(&params);
                grads = vec![0.0; flat.len()];
                refinement = Some(r);
            }
            if batch.any(|s| d.resets_at(s)) {
                reset_opacities::<M>(d, &mut params, &mut flat, &mut adam);
            }
            times.densify = clock.elapsed();
        }
        let clock = Instant::now();
        let evaluation = match batch.any(|s| after_every(opts.eval_every, s)) {
            true => {
                let test = state
                    .per_view
                    .held_out_views(&opts.per_view, &cameras, &data.test);
                Some(evaluate::<M>(&params, &test, opts)?)
            }
            false => None,
        };
        times.evaluation = clock.elapsed();
        let stops = stops_after(team, asked_to_stop, opts);
        let save = saves_at(opts, batch, stops);
        if save || ends_after(opts, batch, stops) {
            state.step = batch.last() + 1;
            state.params = flat.clone();
            state.adam = adam.state();
            (state.grad2d, state.seen) = densifier
                .as_ref()
                .map(Densifier::statistics)
                .unwrap_or_default();
            state.rng = rng.get_seed();
        }
        progress(&StepReport {
            step: batch.last(),
            views: batch.len,
            loss: &value,
            primitives: params.len(),
            refinement: refinement.as_ref(),
            faults,
            view_faults,
            evaluation,
            checkpoint: save.then_some(&*state),
            scene: batch
                .any(|s| after_every(opts.share_every, s))
                .then_some(&flat[..]),
            times: StepTimes {
                wall: started.elapsed(),
                ..times
            },
        });
        if stops {
            break;
        }
    }
    Ok(())
}

/// One view of a batch through `params` (training view `k`, its per-view words
/// `corrections`), rendered and differentiated by `frames`: its render on `background`, loss,
/// backward pass, the gradient by its per-view words and (when `observing`) density
/// control's screen-space gradient norms of the primitives `project` keeps; its stage times
/// are added to `times`.
#[allow(clippy::too_many_arguments)]
fn view_pass<M: Trainable>(
    params: &[M::Params],
    (k, view, corrections): (usize, &View, Corrections),
    background: Vec3,
    opts: &FitOptions,
    observing: bool,
    target: &mut Image,
    times: &mut StepTimes,
    frames: &mut Frames<M>,
) -> Result<ViewPass, FitError> {
    let camera = &opts.per_view.camera(&view.camera, corrections);
    let render = step_render(opts);
    let (frame, pass) = match frames {
        Frames::Cpu => {
            let (frame, pass) = splat_cpu::render_for_backward::<M>(params, camera, &render)?;
            (frame, Some(pass))
        }
        #[cfg(feature = "gpu")]
        Frames::Hardware(h) => (h.render(params, camera)?, None),
        #[cfg(not(feature = "gpu"))]
        Frames::Never(_) => unreachable!(),
    };
    times.preprocess += frame.stats.preprocess;
    times.rasterize += frame.stats.rasterize;
    times.shade += frame.stats.shade;
    let clock = Instant::now();
    let (loss, grad, by_exposure) =
        frame_loss(frame, view, background, (opts, corrections), target)?;
    times.loss += clock.elapsed();
    let g = match (frames, &pass) {
        #[cfg(feature = "gpu")]
        (Frames::Hardware(h), _) => h.backward(&grad)?,
        (_, Some(pass)) => splat_cpu::backward::<M>(pass, params, camera, &grad)?,
        (_, None) => unreachable!("the CPU's pass is kept"),
    };
    times.blend += g.stats.blend + g.stats.reduce;
    times.project += g.stats.project;
    let clock = Instant::now();
    let seen = match observing {
        false => vec![],
        true => {
            let visible: Vec<u32> = match &pass {
                Some(pass) => pass.pre.visible.iter().map(|&(i, _)| i).collect(),
                None => (0..params.len() as u32)
                    .filter(|&i| M::project(&params[i as usize], camera).visible)
                    .collect(),
            };
            let shade_words = M::Shade::LEN;
            (visible.into_iter())
                .map(|i| {
                    let k = i as usize;
                    let shade = &g.shade[k * shade_words..(k + 1) * shade_words];
                    let grad = screen_gradient::<M>(&params[k], &g.params[k], shade, camera);
                    (i, grad.length())
                })
                .collect()
        }
    };
    times.statistics += clock.elapsed();
    Ok(ViewPass {
        loss,
        grads: flatten(&g.params),
        seen,
        view: k,
        corrections: (opts.per_view).gradient((corrections, &view.camera), by_exposure, &g.camera),
    })
}

/// Room for a step's target, where a view does not hold it (8-bit views, another
/// background): filled by [`View::on_into`].
pub(crate) fn no_target() -> Image {
    Image {
        width: 0,
        height: 0,
        channels: 3,
        data: vec![],
    }
}

/// Density control's opacity reset on `params` (held as `flat` too), with Adam forgetting
/// the moments of the words it moved (opacities) alone, as gsplat does.
pub(crate) fn reset_opacities<M: Trainable>(
    d: &Densifier,
    params: &mut [M::Params],
    flat: &mut Vec<f32>,
    adam: &mut Adam,
) {
    d.reset_opacity::<M>(params);
    let after = flatten(params);
    adam.forget(|k| flat[k] != after[k]);
    *flat = after;
}

/// The loss of `frame` (rendered on black), mapped by the exposure in the view's
/// `corrections` (its words of `opts.per_view`, [`super::per_view`]; none where the run
/// learns none), composited on `background` against `view`'s picture; its gradient by the
/// frame's color and alpha, and by the exposure's words (none without one).
pub(crate) fn frame_loss(
    frame: Frame,
    view: &View,
    background: Vec3,
    (opts, corrections): (&FitOptions, Corrections),
    target: &mut Image,
) -> Result<(LossValue, FrameGrad, Vec<f32>), FitError> {
    let alpha = frame.alpha.as_ref();
    let mut color = frame.color;
    let exposed = (opts.per_view.exposure(corrections)).map(|e| {
        let rendered = color.clone();
        e.apply(&mut color);
        (e, rendered)
    });
    let image = composite(color, alpha, background);
    let (loss, mut d_color) =
        loss::loss_and_gradient(&image, view.on_into(background, target), opts.ssim_weight)?;
    // The background term (1 - alpha) b: its gradient flows into alpha.
    let b = background.to_array();
    let d_alpha: Vec<f32> = d_color
        .chunks_exact(3)
        .map(|g| -(g[0] * b[0] + g[1] * b[1] + g[2] * b[2]))
        .collect();
    let by_exposure = match exposed {
        Some((e, rendered)) => e.backward(&rendered, &mut d_color).to_vec(),
        None => vec![],
    };
    let grad = FrameGrad {
        color: d_color,
        alpha: Some(d_alpha),
        depth: None,
    };
    Ok((loss, grad, by_exposure))
}

/// Refuses to go on from `state` (once started) with settings that change its steps
/// ([`settings`]: the background, the primitive cap, frozen groups, the batch).
pub fn refuse_other_settings<M: SplatMethod>(
    state: &Checkpoint,
    opts: &FitOptions,
) -> Result<(), FitError> {
    let settings = settings::<M>(opts);
    match state.step > 0 && !state.settings.is_empty() && state.settings != settings {
        true => Err(FitError::Unsupported(format!(
            "the checkpoint is of a run {}, not {settings} (go on with the run's own settings)",
            state.settings
        ))),
        false => Ok(()),
    }
}

/// Makes `state` this run's: refuses a state of another method, run length or (once
/// started) strategy, scene extent or training views, or with a non-finite parameter, and
/// records the strategy, the extent and the views.
pub(crate) fn adopt<M: Trainable>(
    state: &mut Checkpoint,
    extent: f32,
    train: &[View],
    opts: &FitOptions,
) -> Result<(), FitError> {
    if let Some(defect) = state.size_defect() {
        return Err(FitError::Unsupported(format!(
            "the checkpoint is not a run's state: {defect}"
        )));
    }
    if state.method != M::NAME || state.words != M::Params::LEN {
        return Err(FitError::Unsupported(format!(
            "the checkpoint is of {} ({} parameter words), not {} ({})",
            state.method,
            state.words,
            M::NAME,
            M::Params::LEN
        )));
    }
    if state.steps != opts.steps {
        return Err(FitError::Unsupported(format!(
            "the checkpoint is of a {}-step run, not {} steps (the learning rates follow the run's length)",
            state.steps, opts.steps
        )));
    }
    let strategy = Strategy::name(opts.densify.as_ref());
    if state.step > 0 && state.strategy != strategy {
        return Err(FitError::Unsupported(format!(
            "the checkpoint is of a run with strategy {}, not {strategy} (the primitives change otherwise)",
            state.strategy
        )));
    }
    refuse_other_settings::<M>(state, opts)?;
    if state.step > 0 && state.extent.to_bits() != extent.to_bits() {
        return Err(FitError::Unsupported(format!(
            "the checkpoint is of a run with scene extent {}, not {extent} (the cameras' spread times --global-scale: the position rates and density control's sizes follow it)",
            state.extent
        )));
    }
    let views = ViewsFootprint {
        views: train.len() as u64,
        pixels: (train.iter())
            .map(|v| v.size().0 as u64 * v.size().1 as u64)
            .sum(),
    };
    if let Some(was) = state.views.filter(|was| state.step > 0 && *was != views) {
        return Err(FitError::Unsupported(format!(
            "the checkpoint is of a run on {} training views of {} pixels in all, not {} of {} (another dataset, or another --downscale)",
            was.views, was.pixels, views.views, views.pixels
        )));
    }
    if let Some(k) = state.params.iter().position(|x| !x.is_finite()) {
        return Err(FitError::Unsupported(format!(
            "the scene to train is not finite: {} is {}",
            word_name::<M>(k),
            state.params[k]
        )));
    }
    let per_view = &opts.per_view;
    let cameras = Cameras::of(train.iter().map(|v| &v.camera)).len();
    if !state.per_view.fits(per_view, train.len(), cameras) || !per_view.any() {
        match state.step {
            0 => state.per_view = PerViewState::start(per_view, train.len(), cameras),
            _ if per_view.any() => {
                return Err(FitError::Unsupported(format!(
                    "the checkpoint holds no {} for {} training views",
                    per_view.names().join(" or "),
                    train.len()
                )));
            }
            _ => {}
        }
    }
    state.strategy = strategy.to_string();
    state.settings = settings::<M>(opts);
    state.extent = extent;
    state.views = Some(views);
    Ok(())
}

/// The method's learning rates for a run of `opts`, once it can start: the dataset has
/// training views and the method declares one rate per parameter word. The words of the
/// groups `opts.render.gradients` leaves out are frozen (never trained, their gradients never
/// computed); density control, which moves, resizes and fades primitives, refuses frozen
/// shape words.
pub(crate) fn rates_for<M: Trainable>(
    data: &Dataset,
    extent: f32,
    opts: &FitOptions,
) -> Result<Vec<Rate>, FitError> {
    if data.train.is_empty() {
        return Err(FitError::NoViews);
    }
    check_run::<M>(data, extent, opts)?;
    let mut rates = M::learning_rates(extent);
    if rates.len() != M::Params::LEN {
        return Err(FitError::Unsupported(format!(
            "{} declares {} learning rates for {} parameter words",
            M::NAME,
            rates.len(),
            M::Params::LEN
        )));
    }
    let frozen = frozen_groups::<M>(opts);
    for (_, range) in &frozen {
        rates[range.clone()].fill(Rate::FROZEN);
    }
    let shape = shape_words::<M>();
    let frozen_shape: Vec<&str> = (frozen.iter())
        .filter(|(_, r)| r.clone().any(|k| shape.contains(&k)))
        .map(|(name, _)| *name)
        .collect();
    if opts.densify.is_some() && !frozen_shape.is_empty() {
        return Err(FitError::Unsupported(format!(
            "{} cannot stay frozen under density control ({}), which moves, resizes and fades primitives: train with a fixed primitive count",
            frozen_shape.join(", "),
            Strategy::name(opts.densify.as_ref())
        )));
    }
    Ok(rates)
}

/// Refuses, before the first step, what would fail or go wrong at some later one: an extent
/// that is not a length (positions would not train, and density control would split or prune
/// every primitive), a loss weight outside [0, 1], a background that is not a color, and any
/// view that cannot be rendered or compared (its camera, its size, its pixels).
fn check_run<M: SplatMethod>(
    data: &Dataset,
    extent: f32,
    opts: &FitOptions,
) -> Result<(), FitError> {
    let refuse = |why: String| Err(FitError::Unsupported(why));
    if !(extent.is_finite() && extent > 0.0) {
        return refuse(format!(
            "the scene's extent must be a positive length, not {extent}"
        ));
    }
    if !(0.0..=1.0).contains(&opts.ssim_weight) {
        return refuse(format!(
            "the SSIM weight must be in [0, 1], not {}",
            opts.ssim_weight
        ));
    }
    if !opts.background.is_finite() {
        return refuse(format!("the background {} is not a color", opts.background));
    }
    let render = for_training(&opts.render);
    for view in data.train.iter().chain(&data.test) {
        let name = &view.name;
        if let Some(defect) = view.defect() {
            return refuse(format!("view {name}: {defect}"));
        }
        let (w, h) = view.size();
        if view.camera.size != glam::Vec2::new(w as f32, h as f32) {
            return refuse(format!(
                "view {name}: its camera is {}x{}, its image {w}x{h}",
                view.camera.size.x, view.camera.size.y
            ));
        }
        if (w.min(h) as usize) < loss::WINDOW {
            return Err(LossError::TooSmall(w, h).into());
        }
        splat_core::frame::check::<M>(&view.camera, &render)
            .map_err(|e| FitError::Unsupported(format!("view {name}: {e}")))?;
    }
    Ok(())
}

/// The settings of a run that change its steps beyond its method, length, strategy, extent
/// and views (which a checkpoint records apart): the background, whether it is random, the
/// cap on primitives, the frozen groups, the batch, what it learns per view. A run resumed
/// with others would train another way.
pub fn settings<M: SplatMethod>(opts: &FitOptions) -> String {
    let b = opts.background;
    let frozen: Vec<&str> = frozen_groups::<M>(opts).into_iter().map(|g| g.0).collect();
    format!(
        "on background {} {} {}{}{}{}{}{}",
        b.x,
        b.y,
        b.z,
        if opts.random_background {
            " (random where the views are transparent)"
        } else {
            ""
        },
        match &opts.densify {
            Some(s) => format!(", at most {} primitives", s.max_primitives()),
            None => String::new(),
        },
        match frozen.is_empty() {
            true => String::new(),
            false => format!(", with {} frozen", frozen.join(", ")),
        },
        match opts.batch {
            0 | 1 => String::new(),
            b => format!(", in batches of {b} views"),
        },
        match opts.per_view.names()[..] {
            [] => String::new(),
            ref names => format!(", learning each view's {}", names.join(" and ")),
        },
    )
}

/// The parameter groups of `M` that a run of `opts` does not train (`opts.render.gradients`
/// leaves them out).
pub fn frozen_groups<M: SplatMethod>(
    opts: &FitOptions,
) -> Vec<(&'static str, std::ops::Range<usize>)> {
    param_groups::<M>()
        .into_iter()
        .enumerate()
        .filter(|(k, _)| !opts.render.gradients.param(*k))
        .map(|(_, group)| group)
        .collect()
}

/// The parameter words that hold `M`'s shape (what [`Trainable::with_shape`] writes): those
/// that differ between a primitive given two different shapes.
fn shape_words<M: Trainable>() -> Vec<usize> {
    let base = M::Params::read_words(&vec![0.25; M::Params::LEN]);
    let shape = |k: f32| Shape {
        position: Vec3::new(1.0, 2.0, 3.0) * k,
        scale: Vec3::new(0.1, 0.2, 0.3) * k,
        rotation: glam::Quat::from_rotation_y(0.3 * k),
        opacity: 0.2 * k,
    };
    let (a, b) = (
        flatten(&[M::with_shape(&base, &shape(1.0))]),
        flatten(&[M::with_shape(&base, &shape(2.0))]),
    );
    (0..a.len()).filter(|&k| a[k] != b[k]).collect()
}

/// This step's background: `opts.background`, or a random color.
pub(crate) fn step_background(opts: &FitOptions, rng: &mut fastrand::Rng) -> Vec3 {
    match opts.random_background {
        true => Vec3::new(rng.f32(), rng.f32(), rng.f32()),
        false => opts.background,
    }
}
