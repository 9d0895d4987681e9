//! What every backward pass on the GPU shares after its blend, whichever renderer drew the
//! frame (tiles, [`super::resident`]; quads, [`super::raster`]): the per-primitive sums the
//! blend adds its shade and depth gradients into (`grads`, held as [`Sums`] say), `project`'s
//! adjoint per primitive from them, `pixel_info`'s per pixel (ray methods, for the camera's
//! gradient, from the pixel cotangents the blend leaves), and the gradients read back.

use super::device::{Grown, Kernel, dispatch};
use super::entries::{self, Layout};
use super::front::Front;
use super::per_model::PerModel;
use super::resident::GpuGradients;
use super::scene::GpuScene;
use super::sums::{Largest, Sums};
use super::{Gpu, GpuError};
use rayon::prelude::*;
use splat_core::flat::Flat;
use splat_core::frame::{BackwardStats, FrameGrad, Gradients, RenderOptions};
use splat_core::grid::TileGrid;
use splat_core::method::SplatMethod;
use splat_core::types::Camera;

pub(crate) struct Adjoint {
    opts: RenderOptions,
    layout: Layout,
    /// Parameter float slots (gradient words per primitive).
    pub param_floats: usize,
    /// How the per-primitive gradient sums (`grads`) are held.
    pub sums: Sums,
    /// The pass finding the largest output gradient (f16 sums' loss scale).
    pub largest: Option<Largest>,
    /// Per primitive: [`Layout::grad_words`] sums.
    pub grads: Grown,
    /// Global atomic adds the blend issued (low word, high word).
    pub issued: wgpu::Buffer,
    pub param_grads: Grown,
    /// Per pixel: the cotangent of `pixel_info`'s result (ray methods).
    pub pixel_cotangent: Grown,
    project_backward: PerModel<Kernel>,
    pixel_backward: PerModel<Kernel>,
    camera_partials: Grown,
    ray_partials: Grown,
    /// (width, height, 0, 0) for `pixel_backward`.
    pixel_info: wgpu::Buffer,
}

impl Adjoint {
    pub fn new<M: SplatMethod>(gpu: &Gpu, opts: &RenderOptions) -> Result<Adjoint, GpuError> {
        let layout = Layout::of::<M>();
        let sums = Sums::at(opts.gradient_precision);
        let grown = |what, words| Grown::new(gpu, what, words);
        Ok(Adjoint {
            opts: *opts,
            layout,
            param_floats: entries::param_floats::<M>()?,
            sums,
            largest: match sums.half {
                true => Some(Largest::new(gpu, layout.channels + 2)?),
                false => None,
            },
            grads: grown("primitive gradients", 1)?,
            issued: gpu.buffer("atomic count", 2)?,
            param_grads: grown("parameter gradients", 1)?,
            pixel_cotangent: grown("pixel data cotangents", 1)?,
            project_backward: PerModel::new(),
            pixel_backward: PerModel::new(),
            camera_partials: grown("camera gradient partials", 1)?,
            ray_partials: grown("camera ray gradient partials", 1)?,
            pixel_info: gpu.uniform_buffer(4),
        })
    }

    /// Records what comes before a blend over `n` primitives and the pixels of `grid`: the
    /// sums and the atomic count zeroed, the pixel cotangents made room for, and (f16 sums)
    /// the largest of the output gradients in `pixel_grad` (depth's only with `want_depth`).
    pub fn record_start<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        (grid, n): (&TileGrid, usize),
        pixel_grad: &wgpu::Buffer,
        want_depth: bool,
    ) -> Result<(), GpuError> {
        let layout = self.layout;
        let pixels = (grid.width * grid.height) as usize;
        let sum_words = self.sums.words(n * layout.grad_words);
        self.grads.ensure(gpu, sum_words)?;
        if M::HAS_PIXEL_INFO {
            let npx = M::PixelLanes::default().as_ref().len();
            self.pixel_cotangent.ensure(gpu, pixels * npx)?;
            let ray_groups = (pixels as u32).div_ceil(64).max(1) as usize;
            self.ray_partials
                .ensure(gpu, ray_groups * Camera::FLOAT_SLOTS)?;
            gpu.write(&self.pixel_info, &[grid.width, grid.height, 0, 0]);
        }
        enc.clear_buffer(&self.grads, 0, Some(4 * sum_words.max(1) as u64));
        enc.clear_buffer(&self.issued, 0, None);
        if let Some(largest) = &self.largest {
            let read = layout.channels + 1 + want_depth as usize;
            largest.record(gpu, enc, pixel_grad, (pixels, read))?;
        }
        Ok(())
    }

    /// Records [`Adjoint::record_project`], then [`Adjoint::record_pixels`].
    pub fn record<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        scene: &GpuScene<M>,
        front: &Front,
        grid: &TileGrid,
    ) -> Result<(), GpuError> {
        self.record_project(gpu, enc, scene, front)?;
        self.record_pixels::<M>(gpu, enc, front, grid)
    }

    /// Records `project`'s adjoint for `scene`'s primitives, from the shade and depth
    /// gradients in `grads` and `project`'s results in the front, through the front's camera.
    pub fn record_project<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        scene: &GpuScene<M>,
        front: &Front,
    ) -> Result<(), GpuError> {
        let n = scene.len();
        let groups = (n as u32).div_ceil(64).max(1);
        self.param_grads.ensure(gpu, n * self.param_floats)?;
        self.camera_partials
            .ensure(gpu, groups as usize * Camera::FLOAT_SLOTS)?;
        let model = front.model;
        let (gradients, sums) = (self.opts.gradients, self.sums);
        let k = self.project_backward.get(model, || {
            gpu.kernel(
                &entries::project_backward::<M>(model, gradients, sums)?,
                "project_backward",
            )
        })?;
        let mut inputs = vec![
            ("params", scene.buffer()),
            ("camera_words", &front.camera),
            ("projected", &front.projected),
            ("grads", &self.grads),
            ("param_grads", &self.param_grads),
            ("camera_partials", &self.camera_partials),
            ("info", &front.count_info),
        ];
        if let Some(largest) = &self.largest {
            inputs.push(("grad_largest", &largest.bits));
        }
        let bind = gpu.bind_named(&k, &inputs)?;
        dispatch(enc, &k.pipeline, &bind, groups);
        Ok(())
    }

    /// Records `pixel_info`'s adjoint over the pixel cotangents of `grid` (ray methods, when
    /// the options ask for the camera's gradient; otherwise nothing).
    pub fn record_pixels<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        front: &Front,
        grid: &TileGrid,
    ) -> Result<(), GpuError> {
        let model = front.model;
        if M::HAS_PIXEL_INFO && self.opts.gradients.camera() {
            let pixels = grid.width * grid.height;
            let k = self.pixel_backward.get(model, || {
                gpu.kernel(&entries::pixel_backward::<M>(model)?, "pixel_backward")
            })?;
            let bind = gpu.bind_named(
                &k,
                &[
                    ("camera_words", &front.camera),
                    ("pixel_cotangent", &self.pixel_cotangent),
                    ("camera_partials", &self.ray_partials),
                    ("info", &self.pixel_info),
                ],
            )?;
            dispatch(enc, &k.pipeline, &bind, pixels.div_ceil(64));
        }
        Ok(())
    }

    /// The gradients the last [`Adjoint::record`] left for `n` primitives and the pixels of
    /// `grid`, read back, with the stage times `stats`.
    pub fn download<M: SplatMethod>(
        &self,
        gpu: &Gpu,
        (grid, n): (&TileGrid, usize),
        stats: BackwardStats,
    ) -> Result<GpuGradients<M>, GpuError> {
        let npf = self.param_floats;
        let count = gpu.read(&self.issued, 2)?;
        let floats: Vec<f32> = gpu
            .read(&self.param_grads, n * npf)?
            .into_iter()
            .map(f32::from_bits)
            .collect();
        let params = floats
            .chunks_exact(npf.max(1))
            .take(n)
            .map(M::params_from_float_slots)
            .collect();
        let (ng, nsf) = (self.layout.grad_words, self.layout.shade_floats);
        let mut shade = vec![0.0; n * M::Shade::LEN];
        let largest = match &self.largest {
            Some(l) => gpu.read(&l.bits, 1)?[0],
            None => 0,
        };
        let sums = gpu.read(&self.grads, self.sums.words(n * ng))?;
        let slots = self.sums.decode(&sums, n * ng, largest);
        for (g, out) in slots
            .chunks_exact(ng)
            .zip(shade.chunks_exact_mut(M::Shade::LEN))
        {
            M::shade_from_float_slots(&g[..nsf]).write_words(out);
        }
        let groups = (n as u32).div_ceil(64).max(1) as usize;
        let camera = self.opts.gradients.camera();
        let mut partials = match camera {
            true => gpu.read(&self.camera_partials, groups * Camera::FLOAT_SLOTS)?,
            false => vec![],
        };
        if M::HAS_PIXEL_INFO && camera {
            let pixels = grid.width * grid.height;
            let ray_groups = pixels.div_ceil(64).max(1) as usize;
            partials.extend(gpu.read(&self.ray_partials, ray_groups * Camera::FLOAT_SLOTS)?);
        }
        // Summed in f64, in order; the model word (last) stays zero: a cotangent has no model.
        let mut cam = vec![0.0f64; Camera::LEN];
        for group in partials.chunks_exact(Camera::FLOAT_SLOTS) {
            for (c, w) in cam.iter_mut().zip(group) {
                *c += f32::from_bits(*w) as f64;
            }
        }
        let cam: Vec<f32> = cam.into_iter().map(|c| c as f32).collect();
        Ok(GpuGradients {
            gradients: Gradients {
                params,
                shade,
                camera: Camera::read_words(&cam),
                stats,
            },
            atomics: count[0] as u64 | (count[1] as u64) << 32,
        })
    }

    /// Bytes the per-primitive gradient sums of `n` primitives take.
    pub fn sum_bytes(&self, n: usize) -> usize {
        4 * self.sums.words(n * self.layout.grad_words)
    }
}

/// The output gradients `grad` of `pixels` pixels of `channels` colors in `words`, interleaved
/// per pixel as the blends read them (the color channels, alpha, depth: f32 bits, zero where
/// not given), in parallel and into a buffer kept between frames (a fresh one is mostly page
/// faults at 1080p's 41 MB).
pub(crate) fn interleave(
    grad: &FrameGrad,
    (pixels, channels): (usize, usize),
    words: &mut Vec<u32>,
) {
    let stride = channels + 2;
    words.resize(pixels * stride, 0);
    const BLOCK: usize = 4096;
    words
        .par_chunks_mut(BLOCK * stride)
        .enumerate()
        .for_each(|(b, block)| {
            for (i, out) in block.chunks_exact_mut(stride).enumerate() {
                let p = b * BLOCK + i;
                let color = &grad.color[p * channels..(p + 1) * channels];
                for (o, c) in out.iter_mut().zip(color) {
                    *o = c.to_bits();
                }
                out[channels] = grad.alpha.as_ref().map_or(0.0, |a| a[p]).to_bits();
                out[channels + 1] = grad.depth.as_ref().map_or(0.0, |d| d[p]).to_bits();
            }
        });
}
