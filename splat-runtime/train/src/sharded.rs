//! Sharded training (Grendel-GS's design, Zhao et al. 2024): each rank of a team holds a
//! slice of the scene's primitives, in the scene's order, with their Adam moments and density
//! statistics; no rank holds the whole scene. Per batch each rank projects its slice through
//! every view of the batch and sends the visible records to the view's renderer (the rank
//! whose share of the batch holds it, [`Batch::share`]), which renders the records of every
//! slice together, takes the loss and the backward blend, and sends each record's gradients
//! back to its slice; there `project`'s adjoint, Adam and density control run.
//!
//! The steps are one process's with the same batch, bit for bit at the same thread count per
//! process: the records reach the renderer in the scene's order (slices in rank order), so the
//! frame and every record's gradient are the whole scene's (`splat_cpu::project_visible`); a
//! slice adds its primitives' gradients view by view in the batch's order; density control
//! grows the strongest pulls of the whole scene and draws its splits from the primitives'
//! places in it ([`Draws`]), and a refined primitive's children take its place in the order,
//! so slices refined apart are the scene refined whole. After a refinement the slices are
//! evened out again (primitives move between neighbours, the order kept).
//!
//! What crosses the wire per view is its visible records and their gradients, not the
//! scene's gradient: a rank's memory holds 1/N of the scene's state. Rank 0 gathers the
//! whole state only where it is written (checkpoints, the end of the run) or shown
//! (`FitOptions::share_every`), and hands out the first state (it read it).

use super::adam::{Adam, Faults};
use super::batch::{Batch, Scaling, batches};
use super::checkpoint::Checkpoint;
use super::densify::{Densifier, Draws, Refinement, screen_gradient, strongest};
use super::fit::{
    Evaluation, FitError, FitOptions, StepReport, Strategy, adopt, after_every, composite,
    draw_views, ends_after, for_training, frame_loss, no_target, rates_for, reset_opacities,
    saves_at, step_rates, stops_after,
};
use super::loss::{self, LossValue};
use super::step_times::StepTimes;
use super::team::{Reader, Team, get_words, put_words};
use super::trainable::Trainable;
use glam::Vec3;
use splat_core::flat::{Flat, flatten, read_all};
use splat_core::frame::{Image, RenderOptions};
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, Projected};
use splat_cpu::Visible;
use splat_io::dataset::{Dataset, View};
use std::ops::Range;
use std::path::Path;
use std::time::Instant;

#[cfg(feature = "gpu")]
mod gpu;

/// [`super::fit::fit_shared`] with the scene sharded among the processes of `team`, on the
/// CPU (ADC or a fixed count, not MCMC, whose relocations draw from the whole scene). Rank
/// 0's `state` is the run's first (every other rank's is not read) and ends as the run's
/// state after its last step; every other rank's ends as its slice of it.
pub fn fit_sharded<M: Trainable>(
    team: &dyn Team,
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    let engine = |_: &Slice<M>| Ok(OnCpu::new(opts));
    run::<M, _>(team, data, (state, extent), opts, progress, engine)
}

/// [`fit_sharded`] with each rank's slice, and the views it renders, on its GPU: the
/// records and their gradients cross between ranks through the host. Not bit for bit one
/// process's (a device's gradient sums are in no fixed order).
#[cfg(feature = "gpu")]
pub fn fit_sharded_gpu<M: Trainable>(
    team: &dyn Team,
    gpu: &splat_gpu::Gpu,
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    gpu::OnGpu::<M>::refuse(opts)?;
    let engine = |slice: &Slice<M>| gpu::OnGpu::new(gpu, data, slice, opts);
    run::<M, _>(team, data, (state, extent), opts, progress, engine)
}

/// The sharded loop, on the `engine` made for this rank's slice.
fn run<M: Trainable, E: Engine<M>>(
    team: &dyn Team,
    data: &Dataset,
    (state, extent): (&mut Checkpoint, f32),
    opts: &FitOptions,
    mut progress: impl FnMut(&StepReport),
    engine: impl FnOnce(&Slice<M>) -> Result<E, FitError>,
) -> Result<(), FitError> {
    let rates = rates_for::<M>(data, extent, opts)?;
    if let Some(Strategy::Mcmc(_)) = opts.densify {
        return Err(FitError::Unsupported(
            "a sharded run cannot take MCMC: its relocations draw from the whole scene's opacities (shard with adc, or share the views with the whole scene on every rank)".into(),
        ));
    }
    opts.per_view.refuse("a sharded run")?;
    let mut slice = Slice::<M>::scatter(team, state, extent, data, opts)?;
    let mut engine = engine(&slice)?;
    let render = for_training(&opts.render);
    let mut rng = fastrand::Rng::with_seed(slice.head.rng);
    for batch in batches(slice.head.step, opts.steps, opts.batch) {
        let started = Instant::now();
        let mut times = StepTimes::default();
        let draws: Vec<Draw> = (draw_views(data, batch, opts, &mut rng).into_iter())
            .map(|(k, background)| (k, &data.train[k], background))
            .collect();
        let observing = (slice.densifier.as_ref()).is_some_and(|d| batch.first < d.opts.stop);

        // This slice through every view of the batch, to each view's renderer.
        let clock = Instant::now();
        let visible = (draws.iter())
            .map(|(_, view, _)| engine.project(&slice, &view.camera, &render))
            .collect::<Result<Vec<_>, _>>()?;
        times.preprocess += clock.elapsed();
        let clock = Instant::now();
        let (asked_to_stop, records) = send_records(team, batch, &visible, opts.stop_requested())?;
        times.exchange += clock.elapsed();
        let replies = render_views::<M, E>(team, batch, &draws, records, &mut engine, &mut times)?;
        let clock = Instant::now();
        let replies = team.all_to_all(replies)?;
        times.exchange += clock.elapsed();
        let clock = Instant::now();
        let slices = (&mut slice, &mut engine);
        let value = add_gradients(team, batch, &draws, &visible, &replies, observing, slices)?;
        times.project += clock.elapsed();

        let clock = Instant::now();
        let lr = step_rates(&rates, batch, opts.steps, slice.scaling.learning_rate);
        let faults = engine.step(&mut slice, &lr, batch.len)?;
        times.optimizer = clock.elapsed();

        let clock = Instant::now();
        let densifies = slice.densifies(batch);
        if densifies {
            engine.to_host(&mut slice)?;
        }
        let refined = slice.densify(team, batch, extent, &mut rng)?;
        let tally = Tally::gather(team, &slice, faults, refined.as_ref())?;
        if refined.is_some() {
            slice.rebalance(team, &tally.sizes)?;
        }
        if densifies {
            engine.reload(&slice)?;
        }
        times.densify = clock.elapsed();

        let clock = Instant::now();
        let evaluation = match batch.any(|s| after_every(opts.eval_every, s)) {
            true => Some(evaluate_sharded(
                team,
                (&slice, &mut engine),
                &data.test,
                opts,
            )?),
            false => None,
        };
        times.evaluation = clock.elapsed();
        let stops = stops_after(team, asked_to_stop, opts);
        let save = saves_at(opts, batch, stops);
        slice.head.step = batch.last() + 1;
        slice.head.rng = rng.get_seed();
        let whole = match save || ends_after(opts, batch, stops) {
            true => {
                engine.to_host(&mut slice)?;
                slice.gather(team)?
            }
            false => None,
        };
        if let Some(whole) = whole {
            *state = whole;
        }
        let shared = match batch.any(|s| after_every(opts.share_every, s)) {
            true => {
                engine.to_host(&mut slice)?;
                gather_words(team, &slice.flat)?
            }
            false => None,
        };
        progress(&StepReport {
            step: batch.last(),
            views: batch.len,
            loss: &value,
            primitives: tally.sizes.iter().sum(),
            refinement: tally.refinement.as_ref(),
            faults: tally.faults,
            view_faults: Faults::default(),
            evaluation,
            checkpoint: (save && team.rank() == 0).then_some(&*state),
            scene: shared.as_deref(),
            times: StepTimes {
                wall: started.elapsed(),
                ..times
            },
        });
        if !ends_after(opts, batch, stops) && team.rank() == 0 {
            // Written: the whole state waits for the next checkpoint on no rank.
            *state = state.clone_head();
        }
        if stops {
            break;
        }
    }
    if team.rank() != 0 {
        engine.to_host(&mut slice)?;
        *state = slice.state();
    }
    Ok(())
}

/// A view of the batch as a rank draws it: its place among the training views, the view, its
/// background.
type Draw<'a> = (usize, &'a View, Vec3);

/// Where a rank's work runs: `project` of its slice and the adjoint's, Adam's step, the
/// frames of the views it renders. [`OnCpu`], or a GPU (`gpu::OnGpu`). The host's copy of
/// the slice ([`Slice`]'s primitives, moments and statistics) is the engine's to keep
/// current: density control, the evening out and the gathers read and change it there.
trait Engine<M: Trainable> {
    /// The slice's primitives that reach the rasterizer through `camera`, with their records.
    fn project(
        &mut self,
        slice: &Slice<M>,
        camera: &Camera,
        render: &RenderOptions,
    ) -> Result<Visible<M>, FitError>;

    /// Training view `draw` rendered from `records` (every slice's, in rank order), its loss
    /// and backward blend: the loss, each record's shade gradient (`M::Shade::LEN` words
    /// each), each record's depth gradient.
    fn render(
        &mut self,
        records: Vec<Record<M>>,
        draw: Draw,
        times: &mut StepTimes,
    ) -> Result<(LossValue, Vec<f32>, Vec<f32>), FitError>;

    /// `view` rendered from `records` on the run's background.
    fn image(&mut self, records: Vec<Record<M>>, view: &View) -> Result<Image, FitError>;

    /// View `j` of the batch: `project`'s adjoint of the slice's `visible` primitives through
    /// `camera`, from their records' gradients, added to the batch's (the first view starts
    /// it), with density control's statistics when `observing`.
    fn add_view(
        &mut self,
        slice: &mut Slice<M>,
        seen: (&Camera, &Visible<M>),
        gradients: (&[f32], &[f32]),
        j: usize,
        observing: bool,
    ) -> Result<(), FitError>;

    /// Adam's step on the batch's gradient, of `views` views, at the rates `lr`.
    fn step(&mut self, slice: &mut Slice<M>, lr: &[f32], views: usize) -> Result<Faults, FitError>;

    /// The host's copy of `slice` made current.
    fn to_host(&mut self, slice: &mut Slice<M>) -> Result<(), FitError>;

    /// The host's copy of `slice`, changed there, taken up again.
    fn reload(&mut self, slice: &Slice<M>) -> Result<(), FitError>;
}

/// The CPU: the host's copy of the slice is the slice.
struct OnCpu {
    opts: FitOptions,
    /// The batch's gradient of the slice's words.
    grads: Vec<f32>,
    /// The last target image, kept for its buffer.
    target: Image,
}

impl OnCpu {
    fn new(opts: &FitOptions) -> OnCpu {
        OnCpu {
            opts: opts.clone(),
            grads: vec![],
            target: no_target(),
        }
    }
}

impl<M: Trainable> Engine<M> for OnCpu {
    fn project(
        &mut self,
        slice: &Slice<M>,
        camera: &Camera,
        render: &RenderOptions,
    ) -> Result<Visible<M>, FitError> {
        Ok(splat_cpu::project_visible::<M>(
            &slice.params,
            camera,
            render,
        )?)
    }

    fn render(
        &mut self,
        records: Vec<Record<M>>,
        (_, view, background): Draw,
        times: &mut StepTimes,
    ) -> Result<(LossValue, Vec<f32>, Vec<f32>), FitError> {
        let render = for_training(&self.opts.render);
        let (frame, pass) =
            splat_cpu::render_records_for_backward::<M>(records, &view.camera, &render)?;
        times.preprocess += frame.stats.preprocess;
        times.rasterize += frame.stats.rasterize;
        times.shade += frame.stats.shade;
        let clock = Instant::now();
        let (loss, grad, _) = frame_loss(
            frame,
            view,
            background,
            (&self.opts, Default::default()),
            &mut self.target,
        )?;
        times.loss += clock.elapsed();
        let blended = splat_cpu::backward_blend::<M>(&pass, &grad)?;
        times.blend += blended.blend + blended.reduce;
        Ok((loss, blended.shade, blended.depth))
    }

    fn image(&mut self, records: Vec<Record<M>>, view: &View) -> Result<Image, FitError> {
        let render = for_training(&self.opts.render);
        let frame = splat_cpu::render_records::<M>(records, &view.camera, &render)?;
        let background = self.opts.background;
        Ok(composite(frame.color, frame.alpha.as_ref(), background))
    }

    fn add_view(
        &mut self,
        slice: &mut Slice<M>,
        (camera, visible): (&Camera, &Visible<M>),
        (shade, depth): (&[f32], &[f32]),
        j: usize,
        observing: bool,
    ) -> Result<(), FitError> {
        let wanted = for_training(&self.opts.render).gradients;
        let (words, shade_words) = (M::Params::LEN, M::Shade::LEN);
        if j == 0 {
            self.grads = vec![0.0f32; slice.flat.len()];
        }
        let seen = &visible.index;
        let params: Vec<M::Params> = seen.iter().map(|&i| slice.params[i as usize]).collect();
        let (g, _) = splat_cpu::project_adjoints::<M>(&params, camera, shade, depth, wanted);
        let mut param_words = vec![0.0f32; words];
        let mut norms = Vec::with_capacity(if observing { seen.len() } else { 0 });
        for (k, &i) in seen.iter().enumerate() {
            let i = i as usize;
            g[k].write_words(&mut param_words);
            for (sum, x) in self.grads[i * words..][..words]
                .iter_mut()
                .zip(&param_words)
            {
                *sum += x;
            }
            if observing {
                let shade = &shade[k * shade_words..][..shade_words];
                let norm = screen_gradient::<M>(&params[k], &g[k], shade, camera).length();
                norms.push((i, norm));
            }
        }
        if let Some(d) = slice.densifier.as_mut().filter(|_| observing) {
            d.observe(norms);
        }
        Ok(())
    }

    fn step(
        &mut self,
        slice: &mut Slice<M>,
        lr: &[f32],
        _views: usize,
    ) -> Result<Faults, FitError> {
        let faults = slice.adam.step(&mut slice.flat, &self.grads, lr);
        read_all(&mut slice.params, &slice.flat);
        Ok(faults)
    }

    fn to_host(&mut self, _: &mut Slice<M>) -> Result<(), FitError> {
        Ok(())
    }

    fn reload(&mut self, _: &Slice<M>) -> Result<(), FitError> {
        Ok(())
    }
}

/// The batch's loss, each view's gradients (the renderers' `replies`, rank order, for the
/// slice's `visible` records of each view) added to the slice's gradient view by view in the
/// batch's order, as one process adds its views; density control's statistics `observing`.
fn add_gradients<M: Trainable, E: Engine<M>>(
    team: &dyn Team,
    batch: Batch,
    draws: &[Draw],
    visible: &[Visible<M>],
    replies: &[Vec<u8>],
    observing: bool,
    (slice, engine): (&mut Slice<M>, &mut E),
) -> Result<LossValue, FitError> {
    let mut losses = Vec::with_capacity(batch.len);
    let mut readers: Vec<Reader> = (replies.iter())
        .map(|b| Reader { bytes: b, at: 0 })
        .collect();
    for (j, (_, view, _)) in draws.iter().enumerate() {
        let r = &mut readers[owner(batch, j, team.ranks())];
        let (loss, shade, depth) = read_gradients::<M>(r, visible[j].index.len())
            .map_err(|e| FitError::Unsupported(format!("a view's gradients: {e}")))?;
        losses.push(loss);
        let seen = (&view.camera, &visible[j]);
        engine.add_view(slice, seen, (&shade, &depth), j, observing)?;
    }
    if readers.iter().any(|r| r.at != r.bytes.len()) {
        return Err(FitError::Unsupported(
            "the renderers sent more gradients than the batch's views take".into(),
        ));
    }
    Ok(LossValue::mean(losses))
}

/// This rank's part of the scene: primitives `first..first + params.len()` of it, their Adam
/// moments and density statistics, and the run's state beside them.
struct Slice<M: Trainable> {
    /// The run's state but the primitives' (step, generator, settings).
    head: Checkpoint,
    first: usize,
    /// The whole scene's primitives.
    total: usize,
    params: Vec<M::Params>,
    flat: Vec<f32>,
    adam: Adam,
    scaling: Scaling,
    densifier: Option<Densifier>,
    opts: FitOptions,
}

/// How rank 0's first message to each rank begins: the rank's slice follows, or why the run
/// cannot start.
const STARTED: u8 = 0;
const REFUSED: u8 = 1;

/// Where a rank's slice is read from in messages: errors name it.
const SLICE: &str = "(a rank's slice of the run's state)";

impl<M: Trainable> Slice<M> {
    /// Primitives `first..` of the scene of `total` from `state` (one of its slices).
    fn new(state: Checkpoint, first: usize, total: usize, opts: &FitOptions) -> Slice<M> {
        let params = state.params::<M>();
        let densifier = (opts.adc())
            .map(|d| Densifier::resume(d.clone(), params.len(), &state.grad2d, &state.seen));
        let head = state.clone_head();
        let mut adam = Adam::resume(M::Params::LEN, state.adam);
        let scaling = Scaling::for_batch(opts.batch, adam.beta1, adam.beta2);
        (adam.beta1, adam.beta2) = (scaling.beta1, scaling.beta2);
        Slice {
            head,
            first,
            total,
            params,
            flat: state.params,
            adam,
            scaling,
            densifier,
            opts: opts.clone(),
        }
    }

    /// This slice as a run's state of its primitives.
    fn state(&self) -> Checkpoint {
        let (grad2d, seen) = (self.densifier.as_ref())
            .map(Densifier::statistics)
            .unwrap_or_default();
        Checkpoint {
            params: self.flat.clone(),
            adam: self.adam.state(),
            grad2d,
            seen,
            ..self.head.clone_head()
        }
    }

    /// Each rank's slice of rank 0's `state` (made the run's, [`adopt`], there first): an
    /// even split in the scene's order. A state rank 0 refuses ends the run on every rank.
    fn scatter(
        team: &dyn Team,
        state: &mut Checkpoint,
        extent: f32,
        data: &Dataset,
        opts: &FitOptions,
    ) -> Result<Slice<M>, FitError> {
        let ranks = team.ranks();
        let mut to_each = vec![vec![]; ranks];
        let mut refused = None;
        if team.rank() == 0 {
            to_each = match adopt::<M>(state, extent, &data.train, opts) {
                Ok(()) => (0..ranks)
                    .map(|r| {
                        let total = state.primitives();
                        let range = even(total, ranks, r);
                        let place = [range.start as u64, total as u64].map(u64::to_le_bytes);
                        let part = state.slice(range).to_bytes().map_err(|e| e.to_string())?;
                        Ok([&[STARTED][..], &place.concat(), &part].concat())
                    })
                    .collect::<Result<_, String>>()
                    .map_err(FitError::Unsupported)?,
                Err(e) => {
                    let why = e.to_string();
                    refused = Some(e);
                    vec![[&[REFUSED][..], why.as_bytes()].concat(); ranks]
                }
            };
            *state = state.clone_head();
        }
        let from_root = team.all_to_all(to_each)?.swap_remove(0);
        if let Some(e) = refused {
            return Err(e);
        }
        match from_root.split_first() {
            Some((&STARTED, bytes)) if bytes.len() >= 16 => {
                let (place, bytes) = bytes.split_at(16);
                let first = u64::from_le_bytes(place[..8].try_into().expect("8 bytes"));
                let total = u64::from_le_bytes(place[8..].try_into().expect("8 bytes"));
                let [part] = parse_slices(&[bytes.to_vec()])?
                    .try_into()
                    .expect("one part");
                Ok(Slice::new(part, first as usize, total as usize, opts))
            }
            Some((&REFUSED, why)) => Err(FitError::Unsupported(format!(
                "rank 0 could not start the run: {}",
                String::from_utf8_lossy(why)
            ))),
            _ => Err(FitError::Unsupported(
                "rank 0 sent no slice of the run's state".into(),
            )),
        }
    }

    /// Whether density control refines or resets opacities in `batch`.
    fn densifies(&self, batch: Batch) -> bool {
        (self.densifier.as_ref()).is_some_and(|d| batch.any(|s| d.refines_at(s) || d.resets_at(s)))
    }

    /// The moments of the slice's words from `state` (the batch's scaled betas kept): the
    /// device optimizer's, read back.
    #[cfg(feature = "gpu")]
    fn adopt_moments(&mut self, state: super::adam::AdamState) {
        let (beta1, beta2) = (self.adam.beta1, self.adam.beta2);
        self.adam = Adam::resume(M::Params::LEN, state);
        (self.adam.beta1, self.adam.beta2) = (beta1, beta2);
    }

    /// Density control's refinement and opacity reset on this slice, where `batch` holds
    /// them, as the whole scene would have them.
    fn densify(
        &mut self,
        team: &dyn Team,
        batch: Batch,
        extent: f32,
        rng: &mut fastrand::Rng,
    ) -> Result<Option<Refinement>, FitError> {
        let Some(d) = self.densifier.as_mut() else {
            return Ok(None);
        };
        let mut refinement = None;
        if let Some(step) = batch.steps().find(|&s| d.refines_at(s)) {
            // The strongest pulls of the whole scene, where the cap leaves room for fewer.
            let mut mine = vec![];
            for (i, mean) in d.pulls() {
                mine.extend(((self.first + i) as u64).to_le_bytes());
                mine.extend(mean.to_le_bytes());
            }
            let mut pulls = vec![];
            for bytes in team.all_gather(mine)? {
                for pull in bytes.chunks_exact(12) {
                    let place = u64::from_le_bytes(pull[..8].try_into().expect("8 bytes"));
                    let mean = f32::from_le_bytes(pull[8..].try_into().expect("4 bytes"));
                    pulls.push((place as usize, mean));
                }
            }
            let room = d.opts.max_primitives.saturating_sub(self.total);
            let mut grows = vec![false; self.params.len()];
            let here = self.first..self.first + self.params.len();
            for place in strongest(pulls, room).filter(|p| here.contains(p)) {
                grows[place - self.first] = true;
            }
            let draws = Draws {
                seed: rng.u32(..),
                first: self.first,
            };
            let r = d.refine_growing::<M>(&mut self.params, &grows, step, extent, draws);
            self.adam.remap(&r.origin);
            self.flat = flatten(&self.params);
            refinement = Some(r);
        }
        if batch.any(|s| d.resets_at(s)) {
            reset_opacities::<M>(d, &mut self.params, &mut self.flat, &mut self.adam);
        }
        Ok(refinement)
    }

    /// The slices evened out again after a refinement changed their `sizes` (every rank's,
    /// in rank order): each rank sends its neighbours the primitives past its even share,
    /// with their moments and statistics, the scene's order kept.
    fn rebalance(&mut self, team: &dyn Team, sizes: &[usize]) -> Result<(), FitError> {
        let (ranks, total) = (team.ranks(), sizes.iter().sum::<usize>());
        self.total = total;
        let target = even(total, ranks, team.rank());
        if (0..ranks).all(|r| even(total, ranks, r).len() == sizes[r]) {
            self.first = target.start;
            return Ok(());
        }
        // Where this slice starts now: the refinement moved every slice's start.
        let here = sizes[..team.rank()].iter().sum::<usize>();
        let state = self.state();
        let to_each = (0..ranks)
            .map(|r| {
                let theirs = even(total, ranks, r);
                let start = theirs.start.clamp(here, here + self.params.len());
                let end = theirs.end.clamp(start, here + self.params.len());
                let part = state.slice(start - here..end - here);
                part.to_bytes()
                    .map_err(|e| FitError::Unsupported(format!("a slice's part: {e}")))
            })
            .collect::<Result<_, _>>()?;
        let parts = parse_slices(&team.all_to_all(to_each)?)?;
        let moved = Checkpoint::join(parts).unwrap_or_else(|| state.clone_head());
        if moved.primitives() != target.len() {
            return Err(FitError::Unsupported(format!(
                "rank {} got {} primitives evening the slices out, not {}",
                team.rank(),
                moved.primitives(),
                target.len()
            )));
        }
        let evened = Slice::new(moved, target.start, total, &self.opts);
        *self = Slice {
            head: self.head.clone_head(),
            ..evened
        };
        Ok(())
    }

    /// The whole run's state on rank 0 (`None` on the others): every slice in order.
    fn gather(&self, team: &dyn Team) -> Result<Option<Checkpoint>, FitError> {
        let bytes = (self.state().to_bytes())
            .map_err(|e| FitError::Unsupported(format!("a slice's state: {e}")))?;
        let Some(parts) = to_root(team, bytes)? else {
            return Ok(None);
        };
        Ok(Checkpoint::join(parse_slices(&parts)?))
    }
}

/// Each view's visible records of this slice (`visible`, one per view of `batch`) sent to
/// the view's renderer, with whether this rank was asked to `stop`; what comes back: whether
/// any rank was, and for each view this rank renders, every slice's records.
fn send_records<M: Trainable>(
    team: &dyn Team,
    batch: Batch,
    visible: &[Visible<M>],
    stop: bool,
) -> Result<(bool, Vec<FromSlices<M>>), FitError> {
    let to_each = (0..team.ranks())
        .map(|r| {
            let mut out = vec![stop as u8];
            for j in batch.share(r, team.ranks()) {
                put_records::<M>(&mut out, &visible[j].records);
            }
            out
        })
        .collect();
    let received = team.all_to_all(to_each)?;
    read_records::<M>(&received, batch.share(team.rank(), team.ranks()).len())
}

/// The views of `batch` this rank renders, each from every slice's `records` (in rank order:
/// the whole scene's frame), with its loss and backward blend: for each rank, each view's loss
/// and the gradients of that rank's records.
fn render_views<M: Trainable, E: Engine<M>>(
    team: &dyn Team,
    batch: Batch,
    draws: &[Draw],
    records: Vec<FromSlices<M>>,
    engine: &mut E,
    times: &mut StepTimes,
) -> Result<Vec<Vec<u8>>, FitError> {
    let mut replies = vec![vec![]; team.ranks()];
    for (j, from) in batch.share(team.rank(), team.ranks()).zip(records) {
        let counts: Vec<usize> = from.iter().map(Vec::len).collect();
        let records = from.into_iter().flatten().collect();
        let (loss, shade, depth) = engine.render(records, draws[j], times)?;
        let words = M::Shade::LEN;
        let mut at = 0;
        for (reply, n) in replies.iter_mut().zip(counts) {
            for x in [loss.loss, loss.l1, loss.ssim] {
                reply.extend(x.to_le_bytes());
            }
            put_words(reply, &shade[at * words..(at + n) * words]);
            put_words(reply, &depth[at..at + n]);
            at += n;
        }
    }
    Ok(replies)
}

/// Primitives `r`'s share of `total` split evenly among `ranks`, in order.
fn even(total: usize, ranks: usize, r: usize) -> Range<usize> {
    let ranks = ranks.max(1);
    (r * total / ranks)..((r + 1) * total / ranks)
}

/// The rank whose share of `batch` holds its `j`-th view.
fn owner(batch: Batch, j: usize, ranks: usize) -> usize {
    (0..ranks)
        .find(|&r| batch.share(r, ranks).contains(&j))
        .unwrap_or(0)
}

/// What `project` makes of a visible primitive, as it crosses from its slice to a renderer.
type Record<M> = Projected<<M as SplatMethod>::Cull, <M as SplatMethod>::Shade>;

/// A view's records from every slice, in rank order.
type FromSlices<M> = Vec<Vec<Record<M>>>;

/// Words per projected record on the wire: depth, the box's two corners, then `cull`'s and
/// `shade`'s words.
fn record_words<M: Trainable>() -> usize {
    5 + M::Cull::LEN + M::Shade::LEN
}

/// `records` appended to `out`: their count, then their words.
fn put_records<M: Trainable>(out: &mut Vec<u8>, records: &[Record<M>]) {
    let n = record_words::<M>();
    let cull = M::Cull::LEN;
    let mut words = vec![0.0f32; records.len() * n];
    for (w, r) in words.chunks_exact_mut(n).zip(records) {
        w[0] = r.depth;
        w[1..3].copy_from_slice(&r.bbox_min.to_array());
        w[3..5].copy_from_slice(&r.bbox_max.to_array());
        r.cull.write_words(&mut w[5..5 + cull]);
        r.shade.write_words(&mut w[5 + cull..]);
    }
    out.extend((records.len() as u64).to_le_bytes());
    put_words(out, &words);
}

/// The records [`put_records`] wrote.
fn get_records<M: Trainable>(r: &mut Reader) -> Result<Vec<Record<M>>, String> {
    let n = record_words::<M>();
    let count = r.len(4 * n)?;
    let words: Vec<f32> = get_words(r.slice(4 * n * count)?);
    let cull = M::Cull::LEN;
    Ok((words.chunks_exact(n))
        .map(|w| Projected {
            visible: true,
            depth: w[0],
            bbox_min: glam::Vec2::new(w[1], w[2]),
            bbox_max: glam::Vec2::new(w[3], w[4]),
            cull: M::Cull::read_words(&w[5..5 + cull]),
            shade: M::Shade::read_words(&w[5 + cull..]),
        })
        .collect())
}

/// From every rank's message (rank order): whether any was asked to stop, and for each of
/// this rank's `views` the records of every slice, in rank order.
fn read_records<M: Trainable>(
    received: &[Vec<u8>],
    views: usize,
) -> Result<(bool, Vec<FromSlices<M>>), FitError> {
    let mut stop = false;
    let mut records = vec![Vec::with_capacity(received.len()); views];
    for (rank, bytes) in received.iter().enumerate() {
        let bad = |e: String| FitError::Unsupported(format!("rank {rank}'s records: {e}"));
        let mut r = Reader { bytes, at: 0 };
        stop |= r.take::<1>().map_err(bad)? != [0];
        for view in records.iter_mut() {
            view.push(get_records::<M>(&mut r).map_err(bad)?);
        }
        if r.at != bytes.len() {
            return Err(bad(format!("{} bytes past the views", bytes.len() - r.at)));
        }
    }
    Ok((stop, records))
}

/// A view's loss and the gradients of `n` records' shade data and depth, as the renderer sent
/// them.
fn read_gradients<M: Trainable>(
    r: &mut Reader,
    n: usize,
) -> Result<(LossValue, Vec<f32>, Vec<f32>), String> {
    let [loss, l1, ssim] = [r.f64()?, r.f64()?, r.f64()?];
    let shade = get_words(r.slice(4 * n * M::Shade::LEN)?);
    let depth = get_words(r.slice(4 * n)?);
    Ok((LossValue { loss, l1, ssim }, shade, depth))
}

/// Slices of a run's state as ranks sent them ([`Checkpoint::to_bytes`]).
fn parse_slices(parts: &[Vec<u8>]) -> Result<Vec<Checkpoint>, FitError> {
    (parts.iter())
        .map(|bytes| Checkpoint::parse(bytes, Path::new(SLICE)))
        .collect::<Result<_, _>>()
        .map_err(|e| FitError::Unsupported(e.to_string()))
}

/// Every rank's `bytes` on rank 0, in rank order (`None` on the others).
fn to_root(team: &dyn Team, bytes: Vec<u8>) -> Result<Option<Vec<Vec<u8>>>, FitError> {
    let mut to_each = vec![vec![]; team.ranks()];
    to_each[0] = bytes;
    let got = team.all_to_all(to_each)?;
    Ok((team.rank() == 0).then_some(got))
}

/// The whole scene's parameter words on rank 0 (`None` on the others), from every slice's.
fn gather_words(team: &dyn Team, flat: &[f32]) -> Result<Option<Vec<f32>>, FitError> {
    let mut bytes = Vec::with_capacity(4 * flat.len());
    put_words(&mut bytes, flat);
    Ok(to_root(team, bytes)?.map(|parts| parts.iter().flat_map(|b| get_words::<f32>(b)).collect()))
}

/// What every rank's step did, as each rank tells the others: its slice's size after the
/// step, the words Adam could not move, what a refinement did.
struct Tally {
    sizes: Vec<usize>,
    faults: Faults,
    refinement: Option<Refinement>,
}

impl Tally {
    fn gather<M: Trainable>(
        team: &dyn Team,
        slice: &Slice<M>,
        faults: Faults,
        refined: Option<&Refinement>,
    ) -> Result<Tally, FitError> {
        let words = M::Params::LEN;
        let first = faults
            .first
            .map_or(u64::MAX, |w| (slice.first * words + w) as u64);
        let r = refined.cloned().unwrap_or_default();
        let mine: Vec<u8> = [
            slice.params.len() as u64,
            faults.gradients as u64,
            faults.steps as u64,
            first,
            r.cloned as u64,
            r.split as u64,
            r.pruned as u64,
        ]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
        let mut tally = Tally {
            sizes: vec![],
            faults: Faults::default(),
            refinement: refined.map(|_| Refinement::default()),
        };
        for (rank, bytes) in team.all_gather(mine)?.iter().enumerate() {
            if bytes.len() != 56 {
                return Err(FitError::Unsupported(format!(
                    "rank {rank} sent a tally of {} bytes",
                    bytes.len()
                )));
            }
            let v: Vec<u64> = (bytes.chunks_exact(8))
                .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
                .collect();
            tally.sizes.push(v[0] as usize);
            tally.faults.gradients += v[1] as u32;
            tally.faults.steps += v[2] as u32;
            if v[3] != u64::MAX {
                let w = v[3] as usize;
                tally.faults.first = Some(tally.faults.first.map_or(w, |f| f.min(w)));
            }
            if let Some(r) = tally.refinement.as_mut() {
                r.cloned += v[4] as usize;
                r.split += v[5] as usize;
                r.pruned += v[6] as usize;
            }
        }
        Ok(tally)
    }
}

/// Mean PSNR and SSIM of the sharded scene over `views` (every rank takes part with its
/// slice `params`): the views rendered in rounds, one per rank, from every slice's records,
/// and scored where they are rendered; the same [`Evaluation`] as the whole scene's.
fn evaluate_sharded<M: Trainable, E: Engine<M>>(
    team: &dyn Team,
    (slice, engine): (&Slice<M>, &mut E),
    views: &[View],
    opts: &FitOptions,
) -> Result<Evaluation, FitError> {
    let render = for_training(&opts.render);
    let (rank, ranks) = (team.rank(), team.ranks());
    let mut mine = vec![];
    for round in views.chunks(ranks) {
        let to_each = (0..ranks)
            .map(|r| {
                let mut out = vec![];
                if let Some(view) = round.get(r) {
                    let visible = engine.project(slice, &view.camera, &render)?;
                    put_records::<M>(&mut out, &visible.records);
                }
                Ok(out)
            })
            .collect::<Result<_, FitError>>()?;
        let received = team.all_to_all(to_each)?;
        if let Some(view) = round.get(rank) {
            let mut records = vec![];
            for (rank, bytes) in received.iter().enumerate() {
                let mut r = Reader { bytes, at: 0 };
                let bad = |e: String| FitError::Unsupported(format!("rank {rank}'s records: {e}"));
                records.extend(get_records::<M>(&mut r).map_err(bad)?);
            }
            let image = engine.image(records, view)?;
            let picture = view.image();
            mine.push((loss::psnr(&image, &picture)?, loss::ssim(&image, &picture)?));
        }
    }
    let mut bytes = vec![];
    for (psnr, ssim) in mine {
        bytes.extend(psnr.to_le_bytes());
        bytes.extend(ssim.to_le_bytes());
    }
    let scores = team.all_gather(bytes)?;
    let mut e = Evaluation {
        views: views.len(),
        ..Default::default()
    };
    // In the views' order: view k was rendered by rank k % ranks in round k / ranks.
    for k in 0..views.len() {
        let at = 16 * (k / ranks);
        let score = (scores[k % ranks].get(at..at + 16))
            .ok_or_else(|| FitError::Unsupported(format!("no score for test view {k}")))?;
        let [psnr, ssim] =
            [&score[..8], &score[8..]].map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")));
        e.psnr += psnr / views.len() as f64;
        e.ssim += ssim / views.len() as f64;
    }
    Ok(e)
}
