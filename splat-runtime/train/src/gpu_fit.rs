//! The training loop on the GPU, step for step the CPU loop of [`super::fit`]: the scene, the
//! target images, the loss, the gradients and Adam's moments live on the device. A step is
//! the renderer's forward, the loss and backward, Adam, density control's statistics or MCMC's
//! penalties and noise, all recorded without waiting for the frame, and one read-back of the
//! loss value and of the words Adam could not step (a few words), then of the stage times. A
//! frame that did not fit the renderer's buffers holds Adam and the statistics back on the
//! device ([`splat_gpu::GpuRenderer::settle`]), and the step runs again. Every hundred steps
//! density control or MCMC refines on the host: the scene and the moments go down and back up.

use super::adam::Faults;
use super::batch::{Scaling, batches};
use super::checkpoint::Checkpoint;
use super::densify::Densifier;
use super::fit::{
    Evaluation, FitError, FitOptions, StepReport, adopt, after_every, composite, draw_views,
    ends_after, for_training, rates_for, saves_at, step_rates, stops_after,
};
use super::loss::LossValue;
use super::step_times::StepTimes;
use super::team::{Share, Solo, Team, ViewPass, gather_statistics};
use super::trainable::Trainable;
use crate::device::{
    AdamStep, GpuAdam, GpuBatchSum, GpuLoss, GpuMcmc, GpuObserver, GpuTrainError, ScreenSource,
};
use glam::{Vec2, Vec3};
use splat_core::flat::{Flat, flatten};
use splat_core::frame::Image;
use splat_core::method::SplatMethod;
use splat_core::types::Camera;
use splat_gpu::entries::Accumulation;
use splat_gpu::timing::StageTimer;
use splat_gpu::{Gpu, GpuRenderError, GpuRenderer, GpuScene};
use splat_io::dataset::{Dataset, View};
use std::time::Instant;

impl From<GpuTrainError> for FitError {
    fn from(e: GpuTrainError) -> FitError {
        FitError::Gpu(e.to_string())
    }
}

impl From<GpuRenderError> for FitError {
    fn from(e: GpuRenderError) -> FitError {
        FitError::Gpu(e.to_string())
    }
}

impl From<splat_gpu::GpuError> for FitError {
    fn from(e: splat_gpu::GpuError) -> FitError {
        FitError::Gpu(e.to_string())
    }
}

/// Trains `params` as [`super::fit::fit`] does, on `gpu`.
pub fn fit_gpu<M: Trainable>(
    gpu: &Gpu,
    data: &Dataset,
    params: &mut Vec<M::Params>,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    super::fit::from_params::<M>(params, opts, |state| {
        fit_gpu_from::<M>(gpu, data, state, extent, opts, progress)
    })
}

/// Trains from `state` as [`super::fit::fit_from`] does, on `gpu`.
pub fn fit_gpu_from<M: Trainable>(
    gpu: &Gpu,
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    fit_gpu_shared::<M>(&Solo, gpu, data, state, extent, opts, progress)
}

/// [`fit_gpu_from`] shared among the processes of `team`, each on its own GPU: each renders
/// its share of every batch and sums its views' gradients on its device, the ranks gather
/// those sums (and, where density control refines, its statistics) and add them in rank order,
/// and all take the same Adam step on the same total, so all hold the same scene. (The sums on
/// a device are not in a fixed order: the scene is not one process's bit for bit.) Every rank
/// must start from the same `state`.
pub fn fit_gpu_shared<M: Trainable>(
    team: &dyn Team,
    gpu: &Gpu,
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    mut progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    let rates = rates_for::<M>(data, extent, opts)?;
    opts.per_view.refuse("the GPU's training loop")?;
    adopt::<M>(state, extent, &data.train, opts)?;
    let words = M::Params::LEN;
    let source = gpu_training::<M>(opts)?;
    let renderer = GpuRenderer::<M>::new(gpu, &for_training(&opts.render))?;
    let targets: Vec<_> = data.train.iter().collect();
    let mut scene = GpuScene::<M>::new(gpu, &state.params::<M>())?;
    let mut adam = GpuAdam::new(gpu, words)?;
    adam.restore(gpu, &state.adam)?;
    let scaling = Scaling::for_batch(opts.batch, adam.beta1, adam.beta2);
    (adam.beta1, adam.beta2) = (scaling.beta1, scaling.beta2);
    let mut device = DeviceStep {
        gpu,
        renderer,
        loss: GpuLoss::new(gpu, &targets, opts.ssim_weight as f32)?,
        adam,
        observer: GpuObserver::new(gpu)?,
        sum: match (opts.batch, team.ranks()) {
            (1, 1) => None,
            _ => Some(GpuBatchSum::new(gpu)?),
        },
        mcmc: match opts.mcmc::<M>()? {
            Some(m) => Some(GpuMcmc::new(gpu, m, words)?),
            None => None,
        },
        source,
        acc: Accumulation::default_for(gpu),
        timer: StageTimer::new(gpu, STAGES),
    };
    let mut densifier =
        (opts.adc()).map(|d| Densifier::resume(d.clone(), scene.len(), &state.grad2d, &state.seen));
    let mut rng = fastrand::Rng::with_seed(state.rng);
    for batch in batches(state.step, opts.steps, opts.batch) {
        let started = Instant::now();
        let draws = draw_views(data, batch, opts, &mut rng);
        let lr = step_rates(&rates, batch, opts.steps, scaling.learning_rate);
        let observing = densifier
            .as_ref()
            .is_some_and(|d| batch.first < d.opts.stop);
        let n = scene.len();
        let views: Vec<_> = (draws.iter())
            .map(|&(k, background)| (k, &data.train[k].camera, background))
            .collect();
        let (value, faults, mut times, asked_to_stop) = match team.ranks() {
            1 => {
                let (value, faults, times) = device.take(&scene, &views, &lr, observing)?;
                (value, faults, times, false)
            }
            _ => {
                let mine = &views[batch.share(team.rank(), team.ranks())];
                let (values, mut times) = device.accumulate(&scene, mine, observing)?;
                let clock = Instant::now();
                let stop = opts.stop_requested();
                let (values, stop) = exchange_sums(team, &mut device, n, values, stop)?;
                times.exchange = clock.elapsed();
                let (faults, optimizer) = device.step_on_sum(&scene, &lr, batch.len)?;
                times.optimizer += optimizer;
                (LossValue::mean(values), faults, times, stop)
            }
        };

        let clock = Instant::now();
        let mut refinement = None;
        if let Some(m) = &device.mcmc {
            if batch.any(|s| m.mcmc.opts.refines_at(s)) {
                let mut host = scene.download(gpu)?;
                let r = m.mcmc.refine::<M>(&mut host, &mut rng);
                device.adam.remap(gpu, n, &r.origin, |_| false)?;
                scene.upload(gpu, &host)?;
                refinement = Some(r);
            }
            times.densify = clock.elapsed();
            // A position not trained yet (a negative rate) is not stirred either.
            let (n, lr) = (scene.len(), lr[m.mcmc.words.position].max(0.0));
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            device.timer.start(&mut enc, NOISE);
            m.record_perturb(gpu, &mut enc, scene.buffer(), n, lr, rng.u32(..))?;
            device.timer.end(&mut enc, NOISE);
            device.timer.resolve(&mut enc, NOISE..STAGES);
            gpu.queue.submit([enc.finish()]);
        }
        if let Some(d) = densifier.as_mut().filter(|_| observing)
            && batch.any(|s| d.refines_at(s) || d.resets_at(s))
        {
            let mut host = scene.download(gpu)?;
            let mut origin: Vec<Option<usize>> = (0..n).map(Some).collect();
            if let Some(step) = batch.steps().find(|&s| d.refines_at(s)) {
                let (grad2d, seen) = gather_statistics(team, device.observer.take(gpu, n)?)?;
                d.add_observations(&grad2d, &seen);
                let r = d.refine::<M>(&mut host, step, extent, &mut rng);
                origin = r.origin.clone();
                refinement = Some(r);
            }
            let before = flatten(&host);
            if batch.any(|s| d.resets_at(s)) {
                d.reset_opacity::<M>(&mut host);
            }
            // Only the words the reset moved (opacities) forget their moments.
            let after = flatten(&host);
            device
                .adam
                .remap(gpu, n, &origin, |k| before[k] != after[k])?;
            scene.upload(gpu, &host)?;
            times.densify = clock.elapsed();
        }
        let clock = Instant::now();
        let evaluation = match batch.any(|s| after_every(opts.eval_every, s)) {
            true => {
                let images =
                    render_resident(&mut device.renderer, &scene, &data.test, opts.background)?;
                Some(Evaluation::of(&images, &data.test)?)
            }
            false => None,
        };
        times.evaluation = clock.elapsed();
        let stops = stops_after(team, asked_to_stop, opts);
        let save = saves_at(opts, batch, stops);
        if save || ends_after(opts, batch, stops) {
            let n = scene.len();
            state.step = batch.last() + 1;
            state.params = flatten(&scene.download(gpu)?);
            state.adam = device.adam.download(gpu, n)?;
            (state.grad2d, state.seen) = match densifier.as_mut() {
                Some(d) => {
                    let (grad2d, seen) = gather_statistics(team, device.observer.take(gpu, n)?)?;
                    d.add_observations(&grad2d, &seen);
                    d.statistics()
                }
                None => Default::default(),
            };
            state.rng = rng.get_seed();
        }
        let shared = match batch.any(|s| after_every(opts.share_every, s)) {
            true => Some(flatten(&scene.download(gpu)?)),
            false => None,
        };
        progress(&StepReport {
            step: batch.last(),
            views: batch.len,
            loss: &value,
            primitives: scene.len(),
            refinement: refinement.as_ref(),
            faults,
            view_faults: Faults::default(),
            evaluation,
            checkpoint: save.then_some(&*state),
            scene: shared.as_deref(),
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

// The loop's own timed stages, besides the renderer's (two timestamps each).
const LOSS: u32 = 0;
const OPTIMIZER: u32 = 1;
const STATISTICS: u32 = 2;
/// MCMC's position noise, after the step's read-back (refinement comes first, as on the CPU).
const NOISE: u32 = 3;
const STAGES: u32 = 4;

/// What a step runs on the device: the renderer, the loss, Adam, density control's statistics
/// or MCMC's terms, and the timer of the loop's own stages.
struct DeviceStep<'g, M: SplatMethod> {
    gpu: &'g Gpu,
    renderer: GpuRenderer<'g, M>,
    loss: GpuLoss,
    adam: GpuAdam,
    observer: GpuObserver,
    /// A batch's gradient sum (none with one view per step).
    sum: Option<GpuBatchSum>,
    mcmc: Option<GpuMcmc>,
    source: ScreenSource,
    acc: Accumulation,
    timer: StageTimer,
}

impl<M: SplatMethod> DeviceStep<'_, M> {
    /// One Adam step from `views` (training view `k` through `camera` on `background`, each),
    /// at the learning rates `lr`, with density control's statistics if `observing`: the mean
    /// of the views' loss values, the words Adam could not step, and the stage times.
    ///
    /// A step of one view does not wait for its frame: the loss, the backward pass, the
    /// statistics and Adam are recorded behind it, and the step's one wait reads the loss
    /// value and Adam's faults. A frame with more intersections than the buffers held (its
    /// lists cut short) holds Adam and the statistics back on the device, and the step runs
    /// again with room. A batch adds each view's gradient to its sum on the device as its
    /// frame settles (a cut frame adds nothing and runs again), then takes Adam's step on it.
    fn take(
        &mut self,
        scene: &GpuScene<M>,
        views: &[(usize, &Camera, Vec3)],
        lr: &[f32],
        observing: bool,
    ) -> Result<(LossValue, Faults, StepTimes), FitError> {
        if self.sum.is_none() {
            return self.take_one(scene, views[0], lr, observing);
        }
        let (values, mut times) = self.accumulate(scene, views, observing)?;
        let (faults, optimizer) = self.step_on_sum(scene, lr, views.len())?;
        times.optimizer += optimizer;
        Ok((LossValue::mean(values), faults, times))
    }

    /// A step of one view, Adam on its gradient held back on the device with a cut frame.
    fn take_one(
        &mut self,
        scene: &GpuScene<M>,
        view: (usize, &Camera, Vec3),
        lr: &[f32],
        observing: bool,
    ) -> Result<(LossValue, Faults, StepTimes), FitError> {
        let gpu = self.gpu;
        loop {
            self.record_view(scene, view, observing)?;
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            self.timer.start(&mut enc, OPTIMIZER);
            let (grads, held_by) = (self.renderer.param_gradients(), self.renderer.frame_keys());
            let step = (scene, grads, lr, 1);
            record_optimizer(
                gpu,
                &mut enc,
                &mut self.adam,
                &self.mcmc,
                step,
                Some(held_by),
            )?;
            self.timer.end(&mut enc, OPTIMIZER);
            self.timer.resolve(&mut enc, LOSS..NOISE);
            gpu.queue.submit([enc.finish()]);
            let parts = [self.loss.sums()?, self.adam.fault_words()];
            let [sums, fault_words] = gpu.read_together(parts)?;
            match self.renderer.settle(scene)? {
                Some(_) => {
                    let faults = GpuAdam::faults(&fault_words);
                    return Ok((self.loss.value(&sums)?, faults, self.times()?));
                }
                None => self.adam.take_back(),
            }
        }
    }

    /// Adds each of `views`' gradients to the batch's sum on the device as its frame settles
    /// (a cut frame adds nothing and runs again): the views' loss values and their stage
    /// times. No views leave the sum as it was.
    fn accumulate(
        &mut self,
        scene: &GpuScene<M>,
        views: &[(usize, &Camera, Vec3)],
        observing: bool,
    ) -> Result<(Vec<LossValue>, StepTimes), FitError> {
        let gpu = self.gpu;
        let words = scene.len() * self.renderer.param_floats();
        let (mut values, mut times) = (vec![], StepTimes::default());
        for (j, &view) in views.iter().enumerate() {
            loop {
                self.record_view(scene, view, observing)?;
                let mut enc = gpu.device.create_command_encoder(&Default::default());
                self.timer.start(&mut enc, OPTIMIZER);
                let (grads, keys) = (self.renderer.param_gradients(), self.renderer.frame_keys());
                let sum = self.sum.as_mut().expect("a batch's sum");
                sum.record_add(gpu, &mut enc, (grads, words), j == 0, keys)?;
                self.timer.end(&mut enc, OPTIMIZER);
                self.timer.resolve(&mut enc, LOSS..NOISE);
                gpu.queue.submit([enc.finish()]);
                let [sums] = gpu.read_together([self.loss.sums()?])?;
                if self.renderer.settle(scene)?.is_some() {
                    values.push(self.loss.value(&sums)?);
                    times += self.times()?;
                    break;
                }
            }
        }
        Ok((values, times))
    }

    /// Adam's step on the batch's sum of `views` views' gradients: the words it could not
    /// move, and its time on the device.
    fn step_on_sum(
        &mut self,
        scene: &GpuScene<M>,
        lr: &[f32],
        views: usize,
    ) -> Result<(Faults, std::time::Duration), FitError> {
        let gpu = self.gpu;
        let sum = self.sum.as_ref().expect("a batch's sum");
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        for stage in [LOSS, STATISTICS] {
            self.timer.start(&mut enc, stage);
            self.timer.end(&mut enc, stage);
        }
        self.timer.start(&mut enc, OPTIMIZER);
        let step = (scene, sum.buffer(), lr, views);
        record_optimizer(gpu, &mut enc, &mut self.adam, &self.mcmc, step, None)?;
        self.timer.end(&mut enc, OPTIMIZER);
        self.timer.resolve(&mut enc, LOSS..NOISE);
        gpu.queue.submit([enc.finish()]);
        let [fault_words] = gpu.read_together([self.adam.fault_words()])?;
        Ok((GpuAdam::faults(&fault_words), self.times()?.optimizer))
    }

    /// Records one view's frame of `scene`, its loss, backward pass and (when `observing`)
    /// density control's statistics, which read the positions the frame was drawn with,
    /// before Adam moves them (as the CPU does).
    fn record_view(
        &mut self,
        scene: &GpuScene<M>,
        (k, camera, background): (usize, &Camera, Vec3),
        observing: bool,
    ) -> Result<(), FitError> {
        let (gpu, timer) = (self.gpu, &self.timer);
        let grid = self.renderer.submit(scene, camera)?;
        let renderer = &mut self.renderer;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let grad = renderer.pixel_gradients()?.clone();
        // Words per pixel of the frame's state (not the parameters' per primitive).
        let state_words = renderer.state_layout().words() as u32;
        let target = (k, background, (grid.width, grid.height));
        timer.start(&mut enc, LOSS);
        let state = renderer.pixel_state();
        (self.loss).record(gpu, &mut enc, target, state, state_words, &grad)?;
        timer.end(&mut enc, LOSS);
        gpu.queue.submit([enc.finish()]);
        renderer.backward_on_device(scene, self.acc)?;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        timer.start(&mut enc, STATISTICS);
        if observing {
            (self.observer).record(gpu, &mut enc, renderer, scene, self.source)?;
        }
        timer.end(&mut enc, STATISTICS);
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// The last step's stage times on the GPU: the renderer's and the loop's own (a stage not
    /// recorded yet, MCMC's noise without MCMC or before its first step, reads zero). Zero on
    /// an adapter without timestamps.
    fn times(&self) -> Result<StepTimes, FitError> {
        let r = self.renderer.stage_times()?;
        let own = self.timer.read(self.gpu)?.unwrap_or_default();
        let own = |s: u32| own.get(s as usize).copied().unwrap_or_default();
        Ok(StepTimes {
            preprocess: r.preprocess,
            rasterize: r.rasterize,
            shade: r.shade,
            loss: own(LOSS),
            blend: r.blend,
            project: r.project,
            optimizer: own(OPTIMIZER) + own(NOISE),
            statistics: own(STATISTICS),
            ..Default::default()
        })
    }
}

/// Gathers every rank's sum of its views' gradients (on `device`, `primitives` primitives'
/// words) with its views' loss values and whether it was asked to stop, and leaves the total,
/// added in rank order, as the batch's sum on every rank: the batch's loss values in view
/// order, and whether any rank was asked to stop.
fn exchange_sums<M: SplatMethod>(
    team: &dyn Team,
    device: &mut DeviceStep<M>,
    primitives: usize,
    values: Vec<LossValue>,
    stop: bool,
) -> Result<(Vec<LossValue>, bool), FitError> {
    let (gpu, words) = (device.gpu, primitives * device.renderer.param_floats());
    let sum = device.sum.as_mut().expect("ranks sum their views");
    // A rank without views this batch sends no gradient (its sum holds an earlier batch's).
    let grads = match values.is_empty() {
        true => vec![],
        false => sum.download(gpu, words)?,
    };
    let mut passes: Vec<ViewPass> = (values.into_iter())
        .map(|loss| ViewPass {
            loss,
            grads: vec![],
            seen: vec![],
            view: 0,
            corrections: vec![],
        })
        .collect();
    if let Some(first) = passes.first_mut() {
        first.grads = grads;
    }
    let shares = team.gather(Share { passes, stop })?;
    let mut total = vec![0.0f32; words];
    for (r, share) in shares.iter().enumerate() {
        let grads = share.passes.first().map_or(&[][..], |p| &p.grads[..]);
        if !(grads.is_empty() || grads.len() == words) {
            return Err(FitError::Unsupported(format!(
                "rank {r} sent a gradient of {} words, not {words}",
                grads.len()
            )));
        }
        for (t, g) in total.iter_mut().zip(grads) {
            *t += g;
        }
    }
    sum.upload(gpu, &total)?;
    let stop = shares.iter().any(|s| s.stop);
    let values = shares.into_iter().flat_map(|s| s.passes).map(|p| p.loss);
    Ok((values.collect(), stop))
}

/// Records MCMC's penalties (once per view of the step) added to the step's gradients, then
/// Adam's step on them: `held_by` the frame of a step of one view, or taken whatever the
/// frames were (`None`: a batch, whose frames all settled).
pub(crate) fn record_optimizer<M: SplatMethod>(
    gpu: &Gpu,
    enc: &mut wgpu::CommandEncoder,
    adam: &mut GpuAdam,
    mcmc: &Option<GpuMcmc>,
    (scene, grads, lr, views): (&GpuScene<M>, &wgpu::Buffer, &[f32], usize),
    held_by: Option<&wgpu::Buffer>,
) -> Result<(), FitError> {
    let n = scene.len();
    if let Some(m) = mcmc {
        m.record_regularize(gpu, enc, (scene.buffer(), grads), n, views)?;
    }
    let adam_step = AdamStep {
        params: scene.buffer(),
        grads,
        primitives: n,
        rates: lr,
        held_by,
    };
    adam.record(gpu, enc, adam_step)?;
    Ok(())
}

/// Why `M` cannot train on the GPU under `opts`, if it cannot; otherwise where its steps'
/// screen-space gradients are read ([`screen_source`]).
pub(crate) fn gpu_training<M: Trainable>(opts: &FitOptions) -> Result<ScreenSource, FitError> {
    let source = screen_source::<M>().ok_or_else(|| {
        FitError::Unsupported(format!(
            "{}: its screen position is not two consecutive shade words, or (without one) its position not three consecutive parameter words",
            M::NAME
        ))
    })?;
    // The loss on the device reads the frame as f32 words.
    if opts.render.precision != splat_core::precision::Precision::F32 {
        return Err(FitError::Unsupported(format!(
            "GPU training reads its frames as f32, not {}: render at another precision with `splat render` or `splat tradeoff`",
            opts.render.precision.name()
        )));
    }
    if splat_gpu::entries::param_floats::<M>()? != M::Params::LEN || M::Color::LEN != 3 {
        return Err(FitError::Unsupported(format!(
            "{}: GPU training needs all-float parameters and RGB color",
            M::NAME
        )));
    }
    Ok(source)
}

/// Where a step's screen-space gradients are read on the device, as
/// [`super::densify::screen_gradient`] reads them: for a method with a screen gradient, the
/// two consecutive shade float slots whose unit gradient reads as a unit screen gradient along
/// x then y; otherwise the three consecutive parameter words whose unit gradient reads as a
/// unit position gradient along x, y, z. `None` where they are not consecutive.
pub fn screen_source<M: Trainable>() -> Option<ScreenSource> {
    let slots = M::ShadeLanes::default().as_ref().len();
    let screen = |w: &[f32]| M::screen_gradient(&M::shade_from_float_slots(w));
    if screen(&vec![0.0; slots]).is_some() {
        // The CPU reads the shade gradient: the device must read the same, or refuse.
        let axes = [Vec2::X, Vec2::Y].map(Some);
        return consecutive(slots, |w| screen(w), &axes).map(|slot| ScreenSource::Shade { slot });
    }
    let position = |w: &[f32]| M::position_gradient(&M::Params::read_words(w));
    consecutive(M::Params::LEN, position, &[Vec3::X, Vec3::Y, Vec3::Z])
        .map(|word| ScreenSource::Position { word })
}

/// The first of `axes.len()` consecutive words (of `len`) whose unit vectors `read` reads as
/// `axes`, in order.
fn consecutive<T: PartialEq>(len: usize, read: impl Fn(&[f32]) -> T, axes: &[T]) -> Option<usize> {
    let unit = |k: usize| {
        let mut w = vec![0.0; len];
        w[k] = 1.0;
        read(&w)
    };
    let first = (0..len).find(|&k| unit(k) == axes[0])?;
    let fits = first + axes.len() <= len;
    (fits && axes.iter().enumerate().all(|(j, a)| unit(first + j) == *a)).then_some(first)
}

/// Renders each of `views` with `params` on `gpu`, as [`super::fit::render_views`] does on
/// the CPU.
pub fn render_views_gpu<M: SplatMethod>(
    gpu: &Gpu,
    params: &[M::Params],
    views: &[View],
    opts: &FitOptions,
) -> Result<Vec<Image>, FitError> {
    let mut renderer = GpuRenderer::<M>::new(gpu, &for_training(&opts.render))?;
    let scene = GpuScene::<M>::new(gpu, params)?;
    render_resident(&mut renderer, &scene, views, opts.background)
}

/// Renders each of `views` from the device-resident `scene`, composited on `background`.
fn render_resident<M: SplatMethod>(
    renderer: &mut GpuRenderer<M>,
    scene: &GpuScene<M>,
    views: &[View],
    background: Vec3,
) -> Result<Vec<Image>, FitError> {
    views
        .iter()
        .map(|v| {
            renderer.forward(scene, &v.camera)?;
            let frame = renderer.download_frame()?;
            Ok(composite(frame.color, frame.alpha.as_ref(), background))
        })
        .collect()
}
