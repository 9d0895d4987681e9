//! What a training step runs on the device besides the renderer: the photometric loss and its
//! gradient ([`GpuLoss`], `loss.wgsl`), Adam ([`GpuAdam`], `adam.wgsl`), density control's
//! statistics ([`GpuObserver`], `observe.wgsl`), MCMC's per-step terms ([`GpuMcmc`],
//! `mcmc.wgsl`) and a batch's gradient sum ([`GpuBatchSum`], `batch.wgsl`). Each records into the caller's encoder; the
//! data stays on the device, and the host reads back only what it asks for (the loss value,
//! and the state density control refines from every hundred steps).

use crate::adam::AdamState;
use crate::adam::{Faults, bias_corrections, remap_rows};
use crate::loss::{LossValue, WINDOW, window};
use crate::mcmc::Mcmc;
use glam::Vec3;
use splat_core::method::SplatMethod;
use splat_gpu::device::{Grown, Kernel, dispatch};
use splat_gpu::entries::{FINITE, PIXEL_SPAN};
use splat_gpu::{Gpu, GpuError, GpuRenderer, GpuScene};
use splat_io::dataset::View;

const LOSS: &str = include_str!("shaders/loss.wgsl");
const ADAM: &str = include_str!("shaders/adam.wgsl");
const OBSERVE: &str = include_str!("shaders/observe.wgsl");
const MCMC: &str = include_str!("shaders/mcmc.wgsl");
const BATCH: &str = include_str!("shaders/batch.wgsl");

/// The loss of the renderer's frame against one of a set of target images, all kept on the
/// device.
pub struct GpuLoss {
    rows_kernel: Kernel,
    terms_kernel: Kernel,
    spread_kernel: Kernel,
    gradient_kernel: Kernel,
    /// Every target image, each in buffers of its own (so the views together may outgrow the
    /// device's largest binding).
    views: Vec<Target>,
    /// Bound as the coverage of a target without one.
    no_coverage: wgpu::Buffer,
    taps: wgpu::Buffer,
    /// The row-filtered moments, then the column-spread cotangents (`loss.wgsl`).
    rows: Grown,
    terms: Grown,
    sums: Grown,
    info: wgpu::Buffer,
    ssim_weight: f32,
    /// The last loss recorded: its image size (for reading its value back).
    last: Option<(u32, u32)>,
}

#[derive(Debug, thiserror::Error)]
pub enum GpuTrainError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("target {view} is {got:?} pixels, the frame {want:?}")]
    Size {
        view: usize,
        got: (u32, u32),
        want: (u32, u32),
    },
    #[error("the loss needs RGB images of at least {WINDOW} x {WINDOW} pixels; target {0} is not")]
    Target(usize),
    #[error("no loss recorded yet")]
    NoLoss,
}

/// One target image on the device.
struct Target {
    /// 8-bit straight RGBA, a word per pixel, where the view holds 8-bit values
    /// ([`View::rgba8`]: every 8-bit picture, as PNGs and JPEGs usually are), else RGB f32
    /// words.
    words: wgpu::Buffer,
    /// Per pixel, for an RGB f32 target whose picture is not opaque everywhere.
    coverage: Option<wgpu::Buffer>,
    /// Held as 8-bit RGBA words.
    packed: bool,
    width: u32,
    height: u32,
    background: Vec3,
}

impl GpuLoss {
    /// Uploads the views' images and coverages once, each to buffers of its own (8 bits per
    /// channel where that is what a view holds, else f32); the loss weighs D-SSIM by
    /// `ssim_weight`.
    pub fn new(gpu: &Gpu, targets: &[&View], ssim_weight: f32) -> Result<GpuLoss, GpuTrainError> {
        let mut views = Vec::with_capacity(targets.len());
        for (k, view) in targets.iter().enumerate() {
            let (width, height) = view.size();
            if (width as usize) < WINDOW || (height as usize) < WINDOW {
                return Err(GpuTrainError::Target(k));
            }
            let packed = view.rgba8();
            let (words, coverage) = match &packed {
                Some(rgba) => (gpu.buffer_from("target image", rgba)?, None),
                None => {
                    let t = view.image();
                    if t.channels != 3 {
                        return Err(GpuTrainError::Target(k));
                    }
                    let words: Vec<u32> = t.data.iter().map(|v| v.to_bits()).collect();
                    let coverage = view.coverage().map(|a| {
                        let bits: Vec<u32> = a.iter().map(|v| v.to_bits()).collect();
                        gpu.buffer_from("target coverage", &bits)
                    });
                    (
                        gpu.buffer_from("target image", &words)?,
                        coverage.transpose()?,
                    )
                }
            };
            views.push(Target {
                words,
                coverage,
                packed: packed.is_some(),
                width,
                height,
                background: view.background,
            });
        }
        let taps: Vec<u32> = window().iter().map(|g| (*g as f32).to_bits()).collect();
        Ok(GpuLoss {
            rows_kernel: gpu.kernel(LOSS, "ssim_rows")?,
            terms_kernel: gpu.kernel(LOSS, "ssim_terms")?,
            spread_kernel: gpu.kernel(LOSS, "ssim_spread")?,
            gradient_kernel: gpu.kernel(LOSS, "loss_gradient")?,
            views,
            no_coverage: gpu.buffer_from("no target coverage", &[])?,
            taps: gpu.buffer_from("SSIM window", &taps)?,
            rows: Grown::new(gpu, "SSIM row sums", 1)?,
            terms: Grown::new(gpu, "SSIM cotangents", 1)?,
            sums: Grown::new(gpu, "loss partial sums", 1)?,
            info: gpu.uniform_buffer(20),
            ssim_weight,
            last: None,
        })
    }

    /// Records the loss of the frame of `size` in `pixel_state` (per pixel `state_words` f32
    /// words: 3 colors, T, the depth sum if kept) against target `view`, both composited on
    /// `background`, writing its gradient into `pixel_grad` (per pixel: 3 colors, alpha,
    /// depth).
    pub fn record(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        (view, background, size): (usize, Vec3, (u32, u32)),
        pixel_state: &wgpu::Buffer,
        state_words: u32,
        pixel_grad: &wgpu::Buffer,
    ) -> Result<(), GpuTrainError> {
        let t = &self.views[view];
        let (w, h) = (t.width, t.height);
        if (w, h) != size {
            return Err(GpuTrainError::Size {
                view,
                got: (w, h),
                want: size,
            });
        }
        let (vw, vh) = (w + 1 - WINDOW as u32, h + 1 - WINDOW as u32);
        let (pixels, valid) = (w * h, vw * vh);
        let groups = pixels.div_ceil(64);
        // Per row and valid column: 5 moments per channel, later 3 cotangents.
        let row_cells = vw * h;
        self.rows.ensure(gpu, row_cells as usize * 15)?;
        self.terms.ensure(gpu, valid as usize * 9)?;
        self.sums.ensure(gpu, 2 * groups as usize)?;
        let (b, b0) = (background, t.background);
        let floats = [b.x, b.y, b.z, self.ssim_weight, b0.x, b0.y, b0.z, 0.0].map(f32::to_bits);
        let ints = [
            w,
            h,
            state_words,
            0,
            vw,
            vh,
            valid,
            t.coverage.is_some() as u32,
        ];
        let format = [t.packed as u32, 0, 0, 0];
        gpu.write(&self.info, &[&ints[..], &floats, &format].concat());
        encoder.clear_buffer(&self.sums, 0, None);
        let (state, target) = (("pixel_state", pixel_state), ("target_image", &t.words));
        let (taps, info) = (("taps", &self.taps), ("info", &self.info));
        let (rows, terms) = (("rows", &*self.rows), ("terms", &*self.terms));
        let coverage = ("coverage", t.coverage.as_ref().unwrap_or(&self.no_coverage));
        let sums = ("sums", &*self.sums);
        let passes = [
            (
                &self.rows_kernel,
                vec![state, target, taps, rows, info, coverage],
                row_cells,
            ),
            (
                &self.terms_kernel,
                vec![taps, rows, terms, sums, info],
                valid,
            ),
            (
                &self.spread_kernel,
                vec![taps, rows, terms, info],
                row_cells,
            ),
            (
                &self.gradient_kernel,
                vec![
                    state,
                    target,
                    taps,
                    rows,
                    sums,
                    info,
                    coverage,
                    ("pixel_grad", pixel_grad),
                ],
                pixels,
            ),
        ];
        for (kernel, buffers, invocations) in passes {
            let bind = gpu.bind_named(kernel, &buffers)?;
            dispatch(encoder, &kernel.pipeline, &bind, invocations.div_ceil(64));
        }
        self.last = Some((w, h));
        Ok(())
    }

    /// The partial sums of the last loss recorded, to read back ([`Gpu::read_together`])
    /// for [`GpuLoss::value`].
    pub fn sums(&self) -> Result<(&wgpu::Buffer, usize), GpuTrainError> {
        let (w, h) = self.last.ok_or(GpuTrainError::NoLoss)?;
        Ok((&self.sums, 2 * (w * h).div_ceil(64) as usize))
    }

    /// The value of the last loss recorded, from its partial sums read back.
    pub fn value(&self, sums: &[u32]) -> Result<LossValue, GpuTrainError> {
        let (w, h) = self.last.ok_or(GpuTrainError::NoLoss)?;
        let total = |slot: usize| -> f64 {
            sums.iter()
                .skip(slot)
                .step_by(2)
                .map(|s| f32::from_bits(*s) as f64)
                .sum()
        };
        let valid = ((w + 1 - WINDOW as u32) * (h + 1 - WINDOW as u32)) as f64;
        let l1 = total(0) / (3.0 * (w * h) as f64);
        let ssim = total(1) / (3.0 * valid);
        let lambda = self.ssim_weight as f64;
        Ok(LossValue {
            loss: (1.0 - lambda) * l1 + lambda * (1.0 - ssim),
            l1,
            ssim,
        })
    }
}

/// What one device Adam step reads and writes.
pub struct AdamStep<'a> {
    pub params: &'a wgpu::Buffer,
    pub grads: &'a wgpu::Buffer,
    pub primitives: usize,
    /// Per word of a primitive; negative for words not trained yet.
    pub rates: &'a [f32],
    /// The key count of the frame the gradients come from
    /// ([`GpuRenderer::frame_keys`]): the step is held back on the device when that frame
    /// was cut ([`GpuAdam::take_back`] then undoes its count). `None`: always taken.
    pub held_by: Option<&'a wgpu::Buffer>,
}

/// Adam's moments on the device, for parameters with `words` float words per primitive.
pub struct GpuAdam {
    kernel: Kernel,
    m: Grown,
    v: Grown,
    rates: wgpu::Buffer,
    info: wgpu::Buffer,
    /// The last step's [`Faults`]: two counts and the first word.
    faults: wgpu::Buffer,
    /// `[0, 0]`: what a step not held by a frame reads as its frame's key count.
    uncut: wgpu::Buffer,
    words: usize,
    step: u64,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl GpuAdam {
    /// 3DGS's constants, as `train::adam::Adam`.
    pub fn new(gpu: &Gpu, words: usize) -> Result<GpuAdam, GpuError> {
        Ok(GpuAdam {
            kernel: gpu.kernel(&format!("{FINITE}\n{ADAM}"), "adam_step")?,
            m: Grown::new(gpu, "Adam first moments", 1)?,
            v: Grown::new(gpu, "Adam second moments", 1)?,
            rates: gpu.buffer("learning rates", words)?,
            info: gpu.uniform_buffer(12),
            faults: gpu.buffer("Adam's faults", 3)?,
            uncut: gpu.buffer("a frame key count never cut", 2)?,
            words,
            step: 0,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        })
    }

    /// Records one step of `step.primitives` primitives' words in `step.params` against
    /// `step.grads`.
    pub fn record(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        step: AdamStep,
    ) -> Result<(), GpuError> {
        let AdamStep {
            params,
            grads,
            primitives,
            rates,
            held_by,
        } = step;
        assert_eq!(
            rates.len(),
            self.words,
            "one learning rate per parameter word"
        );
        let total = primitives * self.words;
        self.m.ensure(gpu, total)?;
        self.v.ensure(gpu, total)?;
        self.step += 1;
        let (b1, b2) = (self.beta1, self.beta2);
        let (c1, c2) = bias_corrections(b1, b2, self.step);
        let floats = [b1, b2, c1, c2, self.eps, 0.0, 0.0, 0.0].map(f32::to_bits);
        gpu.write(
            &self.info,
            &[&[total as u32, self.words as u32, 0, 0], &floats[..]].concat(),
        );
        let rate_words: Vec<u32> = rates.iter().map(|r| r.to_bits()).collect();
        gpu.write(&self.rates, &rate_words);
        gpu.write(&self.faults, &[0, 0, u32::MAX]);
        let bind = gpu.bind_named(
            &self.kernel,
            &[
                ("params", params),
                ("grads", grads),
                ("m", &self.m),
                ("v", &self.v),
                ("rates", &self.rates),
                ("info", &self.info),
                ("faults", &self.faults),
                ("frame_keys", held_by.unwrap_or(&self.uncut)),
            ],
        )?;
        dispatch(
            encoder,
            &self.kernel.pipeline,
            &bind,
            (total as u32).div_ceil(256),
        );
        Ok(())
    }

    /// Where the last recorded step says which words it could not move, to read back
    /// Takes back the count of the step recorded last, which its frame held back on the
    /// device ([`AdamStep::held_by`]): the next step's bias corrections are those it would
    /// have had.
    pub fn take_back(&mut self) {
        self.step -= 1;
    }

    /// ([`Gpu::read_together`]) for [`GpuAdam::faults`].
    pub fn fault_words(&self) -> (&wgpu::Buffer, usize) {
        (&self.faults, 3)
    }

    /// The words the last recorded step could not move, from [`GpuAdam::fault_words`] read
    /// back.
    pub fn faults(words: &[u32]) -> Faults {
        Faults {
            gradients: words[0],
            steps: words[1],
            first: (words[2] != u32::MAX).then_some(words[2] as usize),
        }
    }

    /// The step count and the moments of `primitives` primitives, for a checkpoint.
    pub fn download(&self, gpu: &Gpu, primitives: usize) -> Result<AdamState, GpuError> {
        let total = primitives * self.words;
        let read = |b: &wgpu::Buffer| -> Result<Vec<f32>, GpuError> {
            match total {
                0 => Ok(vec![]),
                _ => Ok(gpu
                    .read(b, total)?
                    .into_iter()
                    .map(f32::from_bits)
                    .collect()),
            }
        };
        Ok(AdamState {
            step: self.step,
            m: read(&self.m)?,
            v: read(&self.v)?,
        })
    }

    /// Goes on from a saved state.
    pub fn restore(&mut self, gpu: &Gpu, state: &AdamState) -> Result<(), GpuError> {
        self.step = state.step;
        for (buffer, values) in [(&mut self.m, &state.m), (&mut self.v, &state.v)] {
            buffer.ensure(gpu, values.len())?;
            let words: Vec<u32> = values.iter().map(|x| x.to_bits()).collect();
            gpu.write(buffer, &words);
        }
        Ok(())
    }

    /// Follows a change of the primitive set (see `train::adam::Adam::remap`), from
    /// `primitives` before it; then clears the moments of the words where `forget` is true.
    pub fn remap(
        &mut self,
        gpu: &Gpu,
        primitives: usize,
        origin: &[Option<usize>],
        forget: impl Fn(usize) -> bool,
    ) -> Result<(), GpuError> {
        let old = self.download(gpu, primitives)?;
        let moved = |rows: &[f32]| {
            let mut new = remap_rows(rows, self.words, origin);
            for (k, x) in new.iter_mut().enumerate() {
                if forget(k) {
                    *x = 0.0;
                }
            }
            new
        };
        let new = AdamState {
            step: old.step,
            m: moved(&old.m),
            v: moved(&old.v),
        };
        self.restore(gpu, &new)
    }
}

/// The sum of a batch's views' parameter gradients, on the device.
pub struct GpuBatchSum {
    kernel: Kernel,
    sum: Grown,
    info: wgpu::Buffer,
}

impl GpuBatchSum {
    pub fn new(gpu: &Gpu) -> Result<GpuBatchSum, GpuError> {
        Ok(GpuBatchSum {
            kernel: gpu.kernel(BATCH, "add_gradients")?,
            sum: Grown::new(gpu, "a batch's gradient sum", 1)?,
            info: gpu.uniform_buffer(4),
        })
    }

    /// Records `grads` (`words` words, of the frame whose key count is `frame_keys`) added to
    /// the sum, or starting it when `first`; a cut frame adds nothing.
    pub fn record_add(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        (grads, words): (&wgpu::Buffer, usize),
        first: bool,
        frame_keys: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        self.sum.ensure(gpu, words)?;
        gpu.write(&self.info, &[words as u32, !first as u32, 0, 0]);
        let bind = gpu.bind_named(
            &self.kernel,
            &[
                ("grads", grads),
                ("sum", &self.sum),
                ("info", &self.info),
                ("frame_keys", frame_keys),
            ],
        )?;
        dispatch(
            encoder,
            &self.kernel.pipeline,
            &bind,
            (words as u32).div_ceil(256),
        );
        Ok(())
    }

    /// The sum so far.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.sum
    }

    /// The sum's first `words` words, read back.
    pub fn download(&self, gpu: &Gpu, words: usize) -> Result<Vec<f32>, GpuError> {
        match words {
            0 => Ok(vec![]),
            _ => Ok(gpu
                .read(&self.sum, words)?
                .into_iter()
                .map(f32::from_bits)
                .collect()),
        }
    }

    /// Replaces the sum with `values`.
    pub fn upload(&mut self, gpu: &Gpu, values: &[f32]) -> Result<(), GpuError> {
        self.sum.ensure(gpu, values.len())?;
        let words: Vec<u32> = values.iter().map(|x| x.to_bits()).collect();
        gpu.write(&self.sum, &words);
        Ok(())
    }
}

/// Where [`GpuObserver`] reads a primitive's screen-space gradient (as
/// [`crate::densify::screen_gradient`] does on the CPU).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScreenSource {
    /// The shade data's gradient, the screen position's x and y at float slots `slot` and
    /// `slot + 1`.
    Shade { slot: usize },
    /// The position's gradient, x, y, z at parameter words `word` .. `word + 2`, through the
    /// pinhole Jacobian.
    Position { word: usize },
}

/// Density control's per-primitive statistics, gathered on the device.
pub struct GpuObserver {
    kernel: Kernel,
    grad2d: Grown,
    seen: Grown,
    info: wgpu::Buffer,
}

impl GpuObserver {
    pub fn new(gpu: &Gpu) -> Result<GpuObserver, GpuError> {
        Ok(GpuObserver {
            kernel: gpu.kernel(&format!("{FINITE}\n{PIXEL_SPAN}\n{OBSERVE}"), "observe")?,
            grad2d: Grown::new(gpu, "screen-space gradient sums", 1)?,
            seen: Grown::new(gpu, "view counts", 1)?,
            info: gpu.uniform_buffer(8),
        })
    }

    /// Records the statistics of the renderer's last frame of `scene` (after its backward
    /// pass): each primitive counted where `project` saw it and its box covers a pixel, its
    /// screen-space gradient read from `source`; none if the frame was cut
    /// ([`GpuRenderer::frame_keys`]).
    pub fn record<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        renderer: &GpuRenderer<M>,
        scene: &GpuScene<M>,
        source: ScreenSource,
    ) -> Result<(), GpuError> {
        let primitives = scene.len();
        // One stride serves the parameters and their gradients (GPU training checks this).
        debug_assert_eq!(
            renderer.param_floats(),
            <M::Params as splat_core::flat::Flat>::LEN
        );
        self.grad2d.ensure(gpu, primitives)?;
        self.seen.ensure(gpu, primitives)?;
        let (projected, stride) = renderer.projected();
        let (shade_grads, grad_words) = renderer.shade_gradients().ok_or_else(|| {
            GpuError::Shader("density statistics read f32 gradient sums, not f16".into())
        })?;
        let (position, slot, from_shade) = match source {
            ScreenSource::Position { word } => (word, 0, 0),
            ScreenSource::Shade { slot } => (0, slot, 1),
        };
        let n = primitives as u32;
        let info = [
            n,
            stride as u32,
            renderer.param_floats() as u32,
            grad_words as u32,
        ];
        let at = [position as u32, slot as u32, from_shade, 0];
        gpu.write(&self.info, &[info, at].concat());
        let bind = gpu.bind_named(
            &self.kernel,
            &[
                ("projected", projected),
                ("params", scene.buffer()),
                ("param_grads", renderer.param_gradients()),
                ("camera_words", renderer.camera_buffer()),
                ("shade_grads", shade_grads),
                ("grad2d", &self.grad2d),
                ("seen", &self.seen),
                ("info", &self.info),
                ("frame_keys", renderer.frame_keys()),
            ],
        )?;
        dispatch(encoder, &self.kernel.pipeline, &bind, n.div_ceil(256));
        Ok(())
    }

    /// The statistics of the `primitives` primitives since the last call, then cleared: zeros
    /// for those no view has been observed for since the buffers last grew (a run resumed past
    /// density control's stop and saved, or grown and saved before its next observed view).
    pub fn take(&mut self, gpu: &Gpu, primitives: usize) -> Result<(Vec<f32>, Vec<u32>), GpuError> {
        if primitives == 0 {
            return Ok((vec![], vec![]));
        }
        self.grad2d.ensure(gpu, primitives)?;
        self.seen.ensure(gpu, primitives)?;
        let grad2d = gpu.read(&self.grad2d, primitives)?;
        let seen = gpu.read(&self.seen, primitives)?;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.grad2d, 0, None);
        enc.clear_buffer(&self.seen, 0, None);
        gpu.queue.submit([enc.finish()]);
        Ok((grad2d.into_iter().map(f32::from_bits).collect(), seen))
    }
}

/// MCMC's per-step terms on the device: the penalties' gradients and the position noise.
pub struct GpuMcmc {
    regularize: Kernel,
    perturb: Kernel,
    /// One uniform per kernel: both are recorded into one submission.
    infos: [wgpu::Buffer; 2],
    /// The strategy, for its options and layout (and its refinements, on the host).
    pub mcmc: Mcmc,
    words: usize,
}

impl GpuMcmc {
    pub fn new(gpu: &Gpu, mcmc: Mcmc, words: usize) -> Result<GpuMcmc, GpuError> {
        Ok(GpuMcmc {
            regularize: gpu.kernel(MCMC, "regularize")?,
            perturb: gpu.kernel(MCMC, "perturb")?,
            infos: [gpu.uniform_buffer(12), gpu.uniform_buffer(12)],
            mcmc,
            words,
        })
    }

    /// Records `kernel` (0: regularize, 1: perturb) over `buffers` and the primitives.
    fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        kernel: usize,
        buffers: &[(&str, &wgpu::Buffer)],
        primitives: usize,
        (seed, noise_scale, views): (u32, f32, usize),
    ) -> Result<(), GpuError> {
        let (o, l) = (&self.mcmc.opts, self.mcmc.words);
        let n = primitives.max(1) as f32;
        let size = [primitives as u32, self.words as u32, seed, 0];
        let layout = [l.position, l.log_scale, l.rotation, l.opacity].map(|w| w as u32);
        let weights = [
            o.opacity_reg * views as f32 / n,
            o.scale_reg * views as f32 / (3.0 * n),
            noise_scale,
            0.0,
        ];
        let info = &self.infos[kernel];
        gpu.write(
            info,
            &[&size[..], &layout[..], &weights.map(f32::to_bits)[..]].concat(),
        );
        let kernel = [&self.regularize, &self.perturb][kernel];
        let bind = gpu.bind_named(kernel, &[buffers, &[("info", info)]].concat())?;
        let groups = (primitives as u32).div_ceil(256);
        dispatch(encoder, &kernel.pipeline, &bind, groups);
        Ok(())
    }

    /// Records the penalties' gradients added to `grads` (before Adam), once per view of the
    /// step (`views`, as `Mcmc::regularize`).
    pub fn record_regularize(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        (params, grads): (&wgpu::Buffer, &wgpu::Buffer),
        primitives: usize,
        views: usize,
    ) -> Result<(), GpuError> {
        let buffers = [("params", params), ("grads", grads)];
        self.record(gpu, encoder, 0, &buffers, primitives, (0, 0.0, views))
    }

    /// Records the noise of `seed` added to the positions in `params` (after Adam), with the
    /// position's learning rate `position_lr`.
    pub fn record_perturb(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        params: &wgpu::Buffer,
        primitives: usize,
        position_lr: f32,
        seed: u32,
    ) -> Result<(), GpuError> {
        let scale = self.mcmc.opts.noise_lr * position_lr;
        self.record(
            gpu,
            encoder,
            1,
            &[("params", params)],
            primitives,
            (seed, scale, 1),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adam::Adam;
    use crate::loss::loss_and_gradient;
    use splat_core::frame::Image;

    fn image(w: u32, h: u32, data: Vec<f32>) -> Image {
        Image {
            width: w,
            height: h,
            channels: 3,
            data,
        }
    }

    fn view(image: Image, coverage: Option<Vec<f32>>, background: Vec3) -> View {
        View::new(
            "target".into(),
            Default::default(),
            image,
            coverage,
            background,
        )
    }

    /// The device loss and gradient against the CPU's (f64) on a random frame composited on a
    /// colored background, the target (partly transparent, stored on another background)
    /// re-composited on it: value within 1e-5, gradient within 1e-4 of its largest word,
    /// alpha's included. A target of f32 values is held as f32, one of 8-bit values (as every
    /// picture read from a PNG is) in a word per pixel.
    #[test]
    fn the_device_loss_and_gradient_match_the_cpu() {
        let Some(gpu) = splat_gpu::adapter_or_skip() else {
            return;
        };
        let (w, h) = (23u32, 17u32);
        let pixels = (w * h) as usize;
        let mut rng = fastrand::Rng::with_seed(2);
        let state: Vec<f32> = (0..pixels * 5).map(|_| rng.f32()).collect();
        let stored = Vec3::new(1.0, 0.9, 0.0);
        let other = view(image(w, h, vec![0.5; pixels * 3]), None, Vec3::ZERO);
        // Random f32 values, and random 8-bit ones composited as a picture's are.
        let coverage: Vec<f32> = (0..pixels).map(|_| rng.f32()).collect();
        let colors = (0..pixels * 3).map(|_| rng.f32()).collect();
        let float = view(image(w, h, colors), Some(coverage), stored);
        let byte = |rng: &mut fastrand::Rng| rng.u8(..) as f32 / 255.0;
        let coverage: Vec<f32> = (0..pixels).map(|_| byte(&mut rng)).collect();
        let colors = (0..pixels * 3)
            .map(|i| byte(&mut rng) * coverage[i / 3] + stored[i % 3] * (1.0 - coverage[i / 3]))
            .collect();
        let eight_bit = view(image(w, h, colors), Some(coverage), stored);
        // Together they are larger than a binding may be: each is held on its own.
        let mut small = splat_gpu::adapter_or_skip().unwrap();
        small.set_binding_limit(12 * pixels as u64);
        GpuLoss::new(&small, &[&other, &float, &eight_bit], 0.2).unwrap();
        let mut loss = GpuLoss::new(&gpu, &[&other, &float, &eight_bit], 0.2).unwrap();
        let packed: Vec<bool> = loss.views.iter().map(|t| t.packed).collect();
        assert_eq!(packed, [false, false, true], "0.5 is no 8-bit value");
        // Each in buffers of its own: 4 bytes per pixel for the packed target, 12 for the
        // others, and 4 of coverage for the one that has it.
        let sizes: Vec<(u64, Option<u64>)> = (loss.views.iter())
            .map(|t| (t.words.size(), t.coverage.as_ref().map(|c| c.size())))
            .collect();
        let bytes = |n: usize| 4 * (n * pixels) as u64;
        assert_eq!(
            sizes,
            [
                (bytes(3), None),
                (bytes(3), Some(bytes(1))),
                (bytes(1), None)
            ]
        );
        let words = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
        let state_buf = gpu.buffer_from("state", &words(&state)).unwrap();
        let grad_buf = gpu.buffer("grad", pixels * 5).unwrap();
        let bg = Vec3::new(0.2, 0.7, 0.4);
        for (k, target) in [(1, &float), (2, &eight_bit)] {
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            loss.record(&gpu, &mut enc, (k, bg, (w, h)), &state_buf, 5, &grad_buf)
                .unwrap();
            gpu.queue.submit([enc.finish()]);
            let (sums, len) = loss.sums().unwrap();
            let got = loss.value(&gpu.read(sums, len).unwrap()).unwrap();
            let grad: Vec<f32> = gpu
                .read(&grad_buf, pixels * 5)
                .unwrap()
                .into_iter()
                .map(f32::from_bits)
                .collect();

            let composited: Vec<f32> = state
                .chunks_exact(5)
                .flat_map(|s| [0, 1, 2].map(|c| s[c] + s[3] * bg[c]))
                .collect();
            let (want, d) =
                loss_and_gradient(&image(w, h, composited), &target.on(bg), 0.2).unwrap();
            assert!(
                (got.loss - want.loss).abs() < 1e-5,
                "{k}: {got:?} vs {want:?}"
            );
            assert!(
                (got.ssim - want.ssim).abs() < 1e-5,
                "{k}: {got:?} vs {want:?}"
            );
            let largest = d.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            for p in 0..pixels {
                let dc = &d[p * 3..p * 3 + 3];
                let alpha = -(dc[0] * bg.x + dc[1] * bg.y + dc[2] * bg.z);
                for (i, want) in dc.iter().chain([&alpha, &0.0]).enumerate() {
                    let g = grad[p * 5 + i];
                    assert!(
                        (g - want).abs() <= 1e-4 * largest,
                        "target {k} pixel {p} word {i}: {g} vs {want}"
                    );
                }
            }
        }
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let err = loss
            .record(
                &gpu,
                &mut enc,
                (0, bg, (w + 1, h)),
                &state_buf,
                5,
                &grad_buf,
            )
            .unwrap_err();
        assert!(matches!(err, GpuTrainError::Size { view: 0, .. }), "{err}");
    }

    /// Three device Adam steps equal the CPU's, a word not trained yet (negative rate) and its
    /// moments stay put, words it cannot step are left and counted alike; after a remap the
    /// moments follow the rows.
    #[test]
    fn device_adam_matches_the_cpu() {
        let Some(gpu) = splat_gpu::adapter_or_skip() else {
            return;
        };
        let (prims, words) = (70, 3);
        let mut rng = fastrand::Rng::with_seed(4);
        let mut cpu: Vec<f32> = (0..prims * words).map(|_| rng.f32()).collect();
        let to_words = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
        let params = gpu.buffer_from("params", &to_words(&cpu)).unwrap();
        let mut adam = GpuAdam::new(&gpu, words).unwrap();
        let mut host = Adam::new(prims, words);
        let rates = [0.01, 0.05, -1.0];
        for step in 0..3 {
            let mut g: Vec<f32> = (0..prims * words).map(|_| rng.f32() - 0.5).collect();
            // The last step meets a non-finite gradient and one that overflows Adam.
            if step == 2 {
                (g[40], g[7], g[9]) = (f32::INFINITY, 1e30, f32::NAN);
            }
            let grads = gpu.buffer_from("grads", &to_words(&g)).unwrap();
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            let adam_step = AdamStep {
                params: &params,
                grads: &grads,
                primitives: prims,
                rates: &rates,
                held_by: None,
            };
            adam.record(&gpu, &mut enc, adam_step).unwrap();
            gpu.queue.submit([enc.finish()]);
            let locked: Vec<f32> = g
                .iter()
                .enumerate()
                .map(|(k, g)| if k % words == 2 { 0.0 } else { *g })
                .collect();
            let want = host.step(&mut cpu, &locked, &rates.map(|r: f32| r.max(0.0)));
            let (faults, len) = adam.fault_words();
            let got = GpuAdam::faults(&gpu.read(faults, len).unwrap());
            assert_eq!(got, want, "step {step}");
        }
        let got: Vec<f32> = gpu
            .read(&params, prims * words)
            .unwrap()
            .into_iter()
            .map(f32::from_bits)
            .collect();
        for (k, (a, b)) in got.iter().zip(&cpu).enumerate() {
            assert!((a - b).abs() <= 1e-6, "word {k}: {a} vs {b}");
        }
        // Keep row 5 as row 0 and add a fresh row: the moments move with them.
        adam.remap(&gpu, prims, &[Some(5), None], |_| false)
            .unwrap();
        let m: Vec<f32> = gpu
            .read(&adam.m, 2 * words)
            .unwrap()
            .into_iter()
            .map(f32::from_bits)
            .collect();
        assert!(m[0] != 0.0 && m[words..].iter().all(|v| *v == 0.0), "{m:?}");
    }

    /// The device's penalties and noise equal the host's on Gaussians of every opacity (the
    /// faint ones move, with the same hashed draws).
    #[test]
    fn device_mcmc_terms_match_the_cpu() {
        use crate::mcmc::{GaussianWords, Mcmc, McmcOptions};
        let Some(gpu) = splat_gpu::adapter_or_skip() else {
            return;
        };
        // Position, log scales, (w, x, y, z) rotation, opacity logit, one color word.
        let (prims, words) = (300, 12);
        let layout = GaussianWords {
            position: 0,
            log_scale: 3,
            rotation: 6,
            opacity: 10,
        };
        let mcmc = Mcmc {
            opts: McmcOptions::default(),
            words: layout,
        };
        let mut rng = fastrand::Rng::with_seed(6);
        let mut params: Vec<f32> = (0..prims * words).map(|_| rng.f32() - 0.5).collect();
        for (i, p) in params.chunks_exact_mut(words).enumerate() {
            p[10] = -12.0 + 0.05 * i as f32; // opacities from 6e-6 to 0.95
        }
        let grads: Vec<f32> = (0..prims * words).map(|_| rng.f32() - 0.5).collect();
        let to_words = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
        let on_device = (
            gpu.buffer_from("params", &to_words(&params)).unwrap(),
            gpu.buffer_from("grads", &to_words(&grads)).unwrap(),
        );
        let device = GpuMcmc::new(&gpu, mcmc.clone(), words).unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        device
            .record_regularize(&gpu, &mut enc, (&on_device.0, &on_device.1), prims, 1)
            .unwrap();
        device
            .record_perturb(&gpu, &mut enc, &on_device.0, prims, 1e-5, 77)
            .unwrap();
        gpu.queue.submit([enc.finish()]);

        let (mut want_params, mut want_grads) = (params.clone(), grads.clone());
        mcmc.regularize(&want_params, &mut want_grads, words, 1);
        mcmc.perturb(&mut want_params, words, 1e-5, 77);
        let read = |b: &wgpu::Buffer| -> Vec<f32> {
            let w = gpu.read(b, prims * words).unwrap();
            w.into_iter().map(f32::from_bits).collect()
        };
        for (what, got, want) in [
            ("gradient", read(&on_device.1), &want_grads),
            ("parameter", read(&on_device.0), &want_params),
        ] {
            for (k, (a, b)) in got.iter().zip(want.iter()).enumerate() {
                let tol = 1e-5 * b.abs().max(1.0);
                assert!((a - b).abs() <= tol, "{what} word {k}: {a} vs {b}");
            }
        }
        let moved = (0..prims).filter(|i| want_params[i * words] != params[i * words]);
        assert!(moved.count() > 50, "the faint primitives move");
    }
}
