//! The hardware path's backward pass (Yuan and He's, backward half): the programmable
//! forward's draw replayed front to back on its state images (cleared; their copy is read
//! back already), each fragment reading the state the forward had before it and adding its
//! primitive's gradient (`entries::raster_backward`); then `project`'s adjoint as on the tile
//! path ([`super::super::adjoint`]). No tile lists here either: the same depth-sorted quads.

use super::{Blending, HardwareRenderer, STOP_MARK, decode, quad_inputs};
use crate::adjoint::interleave;
use crate::programmable_blend::{Order, RasterPass, RasterPassDesc};
use crate::resident::GpuGradients;
use crate::scatter::FragmentReduction;
use crate::{GpuError, GpuRenderError, GpuScene, entries};
use splat_core::frame::{BackwardStats, FrameGrad};
use splat_core::method::SplatMethod;
use splat_core::types::CameraModel;

/// A backward pass built for one camera model, choice of depth gradient and reduction.
pub(super) type BackwardPass = ((CameraModel, bool, FragmentReduction), RasterPass);

impl<M: SplatMethod> HardwareRenderer<'_, M> {
    /// The backward pass of the last frame of `scene` (unchanged since), given the gradient
    /// of each output: gradients stay on the device until
    /// [`HardwareRenderer::download_gradients`]. Needs the frame drawn with
    /// [`Blending::Programmable`], whose state it replays. Waits for the replay. The
    /// fragments' gradients are summed as [`FragmentReduction::default_for`] the adapter.
    pub fn backward(
        &mut self,
        scene: &GpuScene<M>,
        grad: &FrameGrad,
    ) -> Result<(), GpuRenderError> {
        self.backward_with(scene, grad, FragmentReduction::default_for(self.gpu))
    }

    /// [`HardwareRenderer::backward`] with the fragments' gradients summed as `reduce` says
    /// before the atomics (the seed's Table I compares them; all but
    /// [`FragmentReduction::None`] need [`crate::Gpu::subgroups`]).
    pub fn backward_with(
        &mut self,
        scene: &GpuScene<M>,
        grad: &FrameGrad,
        reduce: FragmentReduction,
    ) -> Result<(), GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        if self.blending != Blending::Programmable {
            let why = "the hardware backward replays the blend in the fragments: render with Blending::Programmable";
            return Err(GpuError::Hardware(why.into()).into());
        }
        scene.check_drawn(info.primitives, self.rendered_from)?;
        let gpu = self.gpu;
        if reduce != FragmentReduction::None && !gpu.subgroups {
            let why = format!(
                "{reduce:?} sums need quad and subgroup operations in fragment shaders, which this adapter lacks: use FragmentReduction::None"
            );
            return Err(GpuError::Hardware(why).into());
        }
        let grid = info.grid;
        let (channels, pixels) = (self.channels, (grid.width * grid.height) as usize);
        grad.check(pixels, channels, self.opts.depth)?;
        let want_depth = grad.depth.is_some();

        // Per pixel: the final state, and the output gradients.
        let stride = channels + 2;
        let values = self.state_values()?;
        let mut last = vec![0u32; pixels * stride];
        for (p, out) in last.chunks_exact_mut(stride).enumerate() {
            for (c, o) in out[..channels].iter_mut().enumerate() {
                let per = entries::RASTER_VALUES;
                *o = values[c / per][4 * p + c % per].to_bits();
            }
            out[channels] = (1.0 - values[0][4 * p + 3]).to_bits();
            if self.opts.depth {
                out[channels + 1] = values[self.color_targets][4 * p].to_bits();
            }
        }
        self.pixel_final.ensure(gpu, pixels * stride)?;
        gpu.write(&self.pixel_final, &last);
        let mut words = std::mem::take(&mut self.pixel_grad_host);
        interleave(grad, (pixels, channels), &mut words);
        self.pixel_grad.ensure(gpu, pixels * stride)?;
        gpu.write(&self.pixel_grad, &words);
        self.pixel_grad_host = words;

        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let sizes = (&grid, info.primitives);
        (self.adjoint).record_start::<M>(gpu, &mut enc, sizes, &self.pixel_grad, want_depth)?;
        if M::HAS_PIXEL_INFO {
            // The fragments add to their pixel's cotangent.
            enc.clear_buffer(&self.adjoint.pixel_cotangent, 0, None);
        }
        gpu.queue.submit([enc.finish()]);

        let model = self.front.model;
        let key = (model, want_depth, reduce);
        if self.backward_pass.as_ref().map(|(k, _)| *k) != Some(key) {
            self.backward_pass = None;
            let source = entries::raster_backward::<M>(
                model,
                &self.opts,
                want_depth,
                self.adjoint.sums,
                (reduce, gpu.float_atomics),
            )?;
            let mut states = self.formats.clone();
            states.push(STOP_MARK);
            let desc = RasterPassDesc {
                source: &source,
                vertex: "quad_vertex",
                fragment: "splat_backward",
                states: &states,
                constants: &self.programmable_constants(),
                strips: true,
                order: Order::Rasterization,
                helper_flag: true,
                readback: false, // it draws on the forward's images
            };
            self.backward_pass = Some((key, RasterPass::new(gpu, &desc)?));
        }
        let (_, pass) = self.backward_pass.as_mut().expect("built above");
        // The replay draws on the forward's images: their state is read back already.
        let (_, forward) = (self.programmable.as_ref())
            .ok_or_else(|| GpuError::Readback("no programmable draw yet".into()))?;
        let adjoint = &self.adjoint;
        let mut inputs = quad_inputs::<M>(&self.front);
        inputs.extend([
            ("pixel_final", &*self.pixel_final),
            ("pixel_grad", &*self.pixel_grad),
            ("grads", &*adjoint.grads),
            ("issued", &adjoint.issued),
        ]);
        if let Some(largest) = &adjoint.largest {
            inputs.push(("grad_largest", &largest.bits));
        }
        if M::HAS_PIXEL_INFO && self.opts.gradients.camera() {
            inputs.push(("pixel_cotangent", &*adjoint.pixel_cotangent));
        }
        let instances = info.intersections as u32;
        self.backward_time = pass.draw_on(gpu, forward, 4, instances, &inputs)?;

        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.timer.start(&mut enc, super::ADJOINT);
        (self.adjoint).record(gpu, &mut enc, scene, &self.front, &grid)?;
        self.timer.end(&mut enc, super::ADJOINT);
        self.timer.resolve(&mut enc, super::ADJOINT..super::STAGES);
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// The last backward pass's gradients, read back; the blend's time is the replay's,
    /// measured on the host.
    pub fn download_gradients(&self) -> Result<GpuGradients<M>, GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        let times = self.timer.read(self.gpu)?.unwrap_or_default();
        let stats = BackwardStats {
            blend: self.backward_time,
            reduce: Default::default(),
            project: times
                .get(super::ADJOINT as usize)
                .copied()
                .unwrap_or_default(),
        };
        let sizes = (&info.grid, info.primitives);
        Ok((self.adjoint).download::<M>(self.gpu, sizes, stats)?)
    }

    /// Bytes the last backward pass's per-primitive gradient sums took.
    pub fn gradient_sum_bytes(&self) -> usize {
        (self.adjoint).sum_bytes(self.frame.map_or(0, |f| f.primitives))
    }

    /// Bytes of Vulkan memory the programmable passes hold of their own (the forward's state
    /// images and their readback; the backward draws on them): what wgpu's allocator report
    /// leaves out.
    pub fn pass_memory_bytes(&self) -> u64 {
        let forward = self.programmable.as_ref().map(|(_, p)| p);
        let backward = self.backward_pass.as_ref().map(|(_, p)| p);
        forward
            .into_iter()
            .chain(backward)
            .map(RasterPass::memory_bytes)
            .sum()
    }

    /// The programmable forward's state images as f32 values, four per pixel, row after row
    /// (read back and decoded once per draw).
    pub(super) fn state_values(&self) -> Result<&[Vec<f32>], GpuError> {
        if let Some(values) = self.state.get() {
            return Ok(values);
        }
        let (_, pass) = (self.programmable.as_ref())
            .ok_or_else(|| GpuError::Readback("no programmable draw yet".into()))?;
        let values = (self.formats.iter())
            .enumerate()
            .map(|(k, format)| Ok(decode(*format, &pass.state_bytes(k)?)))
            .collect::<Result<_, GpuError>>()?;
        Ok(self.state.get_or_init(|| values))
    }
}
