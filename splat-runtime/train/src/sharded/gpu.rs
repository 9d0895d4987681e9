//! The sharded loop's engine on a GPU: the slice, its Adam moments and density control's
//! statistics live on the device, as in [`crate::gpu_fit`]. Per view the slice is projected
//! on the device and its visible records are compacted there and read back to be sent; the
//! views this rank renders are drawn from the records that come in (loss and backward blend
//! on the device, each record's gradient read back); `project`'s adjoint runs on the device
//! from the gradients the slice's records come back with. The host's copy of the slice is
//! brought up to date only where density control, the evening out or a gather reads it.

use super::{Draw, Engine, Record, Slice};
use crate::adam::Faults;
use crate::device::{GpuAdam, GpuBatchSum, GpuLoss, GpuObserver, ScreenSource};
use crate::fit::{FitError, FitOptions, composite, for_training};
use crate::gpu_fit::{gpu_training, record_optimizer};
use crate::loss::LossValue;
use crate::step_times::StepTimes;
use crate::trainable::Trainable;
use splat_core::flat::{Flat, flatten};
use splat_core::frame::{Image, RenderOptions};
use splat_core::method::SplatMethod;
use splat_core::precision::Precision;
use splat_core::types::Camera;
use splat_cpu::Visible;
use splat_gpu::entries::{Accumulation, Layout};
use splat_gpu::{Gpu, GpuRenderer, GpuScene};
use splat_io::dataset::{Dataset, View};

pub(super) struct OnGpu<'g, M: SplatMethod> {
    gpu: &'g Gpu,
    renderer: GpuRenderer<'g, M>,
    /// The slice's primitives.
    scene: GpuScene<M>,
    loss: GpuLoss,
    adam: GpuAdam,
    /// The batch's gradient of the slice's words.
    sum: GpuBatchSum,
    observer: GpuObserver,
    source: ScreenSource,
    acc: Accumulation,
    background: glam::Vec3,
}

impl<'g, M: Trainable> OnGpu<'g, M> {
    /// Why `M` under `opts` cannot train sharded on a GPU, if it cannot (every rank says the
    /// same before the first exchange).
    pub fn refuse(opts: &FitOptions) -> Result<(), FitError> {
        gpu_training::<M>(opts)?;
        let unsupported = |why: String| Err(FitError::Unsupported(why));
        if opts.render.gradient_precision != Precision::F32 {
            return unsupported(
                "a sharded run's records cross between ranks with f32 gradients: leave the gradient sums at f32".into(),
            );
        }
        if Layout::of::<M>().shade_floats != M::Shade::LEN {
            return unsupported(format!(
                "{}: sharded GPU training needs all-float shade data",
                M::NAME
            ));
        }
        Ok(())
    }

    /// The engine of `slice` on `gpu`, the training views of `data` its loss's targets.
    pub fn new(
        gpu: &'g Gpu,
        data: &Dataset,
        slice: &Slice<M>,
        opts: &FitOptions,
    ) -> Result<OnGpu<'g, M>, FitError> {
        let source = gpu_training::<M>(opts)?;
        let renderer = GpuRenderer::<M>::new(gpu, &for_training(&opts.render))?;
        let targets: Vec<&View> = data.train.iter().collect();
        let mut adam = GpuAdam::new(gpu, M::Params::LEN)?;
        adam.restore(gpu, &slice.adam.state())?;
        (adam.beta1, adam.beta2) = (slice.adam.beta1, slice.adam.beta2);
        Ok(OnGpu {
            gpu,
            renderer,
            scene: GpuScene::new(gpu, &slice.params)?,
            loss: GpuLoss::new(gpu, &targets, opts.ssim_weight as f32)?,
            adam,
            sum: GpuBatchSum::new(gpu)?,
            observer: GpuObserver::new(gpu)?,
            source,
            acc: Accumulation::default_for(gpu),
            background: opts.background,
        })
    }
}

impl<M: Trainable> Engine<M> for OnGpu<'_, M> {
    fn project(
        &mut self,
        _: &Slice<M>,
        camera: &Camera,
        _: &RenderOptions,
    ) -> Result<Visible<M>, FitError> {
        let (index, records) = self.renderer.project_visible(&self.scene, camera)?;
        Ok(Visible { index, records })
    }

    fn render(
        &mut self,
        records: Vec<Record<M>>,
        (k, view, background): Draw,
        times: &mut StepTimes,
    ) -> Result<(LossValue, Vec<f32>, Vec<f32>), FitError> {
        let (gpu, camera) = (self.gpu, &view.camera);
        let (loss, grads) = loop {
            let grid = self.renderer.submit_records(&records, camera)?;
            let grad = self.renderer.pixel_gradients()?.clone();
            let state_words = self.renderer.state_layout().words() as u32;
            let state = self.renderer.pixel_state();
            let target = (k, background, (grid.width, grid.height));
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            (self.loss).record(gpu, &mut enc, target, state, state_words, &grad)?;
            gpu.queue.submit([enc.finish()]);
            self.renderer.blend_records(self.acc)?;
            let [sums] = gpu.read_together([self.loss.sums()?])?;
            // A frame whose lists were cut short is drawn again, with room.
            if self.renderer.settle_records()?.is_some() {
                let grads = self.renderer.download_record_gradients()?;
                break (self.loss.value(&sums)?, grads);
            }
        };
        let r = self.renderer.stage_times()?;
        times.preprocess += r.preprocess;
        times.rasterize += r.rasterize;
        times.shade += r.shade;
        times.blend += r.blend;
        // Each record's shade words (all floats), then its depth word.
        let words = M::Shade::LEN;
        let mut shade = Vec::with_capacity(records.len() * words);
        let mut depth = Vec::with_capacity(records.len());
        for g in grads.chunks_exact(words + 1) {
            shade.extend(&g[..words]);
            depth.push(g[words]);
        }
        Ok((loss, shade, depth))
    }

    fn image(&mut self, records: Vec<Record<M>>, view: &View) -> Result<Image, FitError> {
        self.renderer.submit_records(&records, &view.camera)?;
        self.renderer.finish_records(&records, &view.camera)?;
        let frame = self.renderer.download_frame()?;
        Ok(composite(
            frame.color,
            frame.alpha.as_ref(),
            self.background,
        ))
    }

    fn add_view(
        &mut self,
        _: &mut Slice<M>,
        (camera, visible): (&Camera, &Visible<M>),
        (shade, depth): (&[f32], &[f32]),
        j: usize,
        observing: bool,
    ) -> Result<(), FitError> {
        let (gpu, n, words) = (self.gpu, self.scene.len(), M::Shade::LEN);
        // Each record's shade words, then its depth word, as the device sums them.
        let mut grads = Vec::with_capacity(depth.len() * (words + 1));
        for (shade, depth) in shade.chunks_exact(words).zip(depth) {
            grads.extend(shade);
            grads.push(*depth);
        }
        let records = (&visible.index[..], &grads[..]);
        self.renderer.adjoint_from(&self.scene, camera, records)?;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let (param_grads, keys) = (self.renderer.param_gradients(), self.renderer.frame_keys());
        let summed = (param_grads, n * M::Params::LEN);
        self.sum.record_add(gpu, &mut enc, summed, j == 0, keys)?;
        if observing {
            let (renderer, scene) = (&self.renderer, &self.scene);
            (self.observer).record(gpu, &mut enc, renderer, scene, self.source)?;
        }
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    fn step(&mut self, _: &mut Slice<M>, lr: &[f32], views: usize) -> Result<Faults, FitError> {
        let gpu = self.gpu;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let step = (&self.scene, self.sum.buffer(), lr, views);
        record_optimizer(gpu, &mut enc, &mut self.adam, &None, step, None)?;
        gpu.queue.submit([enc.finish()]);
        let [fault_words] = gpu.read_together([self.adam.fault_words()])?;
        Ok(GpuAdam::faults(&fault_words))
    }

    fn to_host(&mut self, slice: &mut Slice<M>) -> Result<(), FitError> {
        let (gpu, n) = (self.gpu, self.scene.len());
        slice.params = self.scene.download(gpu)?;
        slice.flat = flatten(&slice.params);
        slice.adopt_moments(self.adam.download(gpu, n)?);
        if let Some(d) = slice.densifier.as_mut() {
            let (grad2d, seen) = self.observer.take(gpu, n)?;
            d.add_observations(&grad2d, &seen);
        }
        Ok(())
    }

    fn reload(&mut self, slice: &Slice<M>) -> Result<(), FitError> {
        self.scene.upload(self.gpu, &slice.params)?;
        self.adam.restore(self.gpu, &slice.adam.state())?;
        Ok(())
    }
}
