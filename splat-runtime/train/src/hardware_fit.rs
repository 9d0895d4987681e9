//! Training through the hardware path (`splat fit --hardware`): the CPU loop ([`super::fit`]:
//! the loss, Adam and density control on the host) with each view's frame drawn as quads by
//! the GPU's rasterizer with programmable blending and differentiated by the hardware path's
//! own backward pass (`HardwareRenderer::backward`, the draw replayed in fragment shaders).
//! Each view uploads the parameters and reads the frame and the gradients back: a way to train
//! and test that backward, not a fast loop (the device-resident one is [`super::gpu_fit`]).

use super::checkpoint::Checkpoint;
use super::fit::{FitError, FitOptions, Frames, StepReport, fit_with, step_render};
use super::team::{Solo, Team};
use super::trainable::Trainable;
use splat_core::frame::{Frame, FrameGrad, Gradients, RenderOptions};
use splat_core::method::SplatMethod;
use splat_core::types::Camera;
use splat_gpu::raster::{Blending, HardwareRenderer};
use splat_gpu::{Gpu, GpuScene};
use splat_io::dataset::Dataset;

/// Each view's frame and gradients from the hardware path on one device.
pub struct HardwareFrames<'g, M: SplatMethod> {
    gpu: &'g Gpu,
    renderer: HardwareRenderer<'g, M>,
    /// The parameters of the last frame, on the device.
    scene: Option<GpuScene<M>>,
}

impl<'g, M: SplatMethod> HardwareFrames<'g, M> {
    /// Frames rendered as `opts` says on `gpu` (a device from
    /// `splat_gpu::programmable_blend::open`).
    pub fn new(gpu: &'g Gpu, opts: &RenderOptions) -> Result<Self, FitError> {
        let renderer = HardwareRenderer::with_blending(gpu, opts, Blending::Programmable)?;
        Ok(HardwareFrames {
            gpu,
            renderer,
            scene: None,
        })
    }

    /// The frame of `params` through `camera`, kept for [`HardwareFrames::backward`].
    pub fn render(&mut self, params: &[M::Params], camera: &Camera) -> Result<Frame, FitError> {
        // The scene's buffer grows with the count (density control changes it).
        let scene = match &mut self.scene {
            Some(scene) => {
                scene.upload(self.gpu, params)?;
                scene
            }
            none => none.insert(GpuScene::new(self.gpu, params)?),
        };
        self.renderer.forward(scene, camera)?;
        Ok(self.renderer.download_frame()?)
    }

    /// The gradients of the last frame's parameters given its outputs' gradient `grad`.
    pub fn backward(&mut self, grad: &FrameGrad) -> Result<Gradients<M>, FitError> {
        let scene = (self.scene.as_ref()).ok_or_else(|| FitError::Gpu("no frame yet".into()))?;
        self.renderer.backward(scene, grad)?;
        Ok(self.renderer.download_gradients()?.gradients)
    }
}

/// Trains `params` as [`super::fit::fit`] does, each view's frame and gradients from the
/// hardware path on `gpu` (a device from `splat_gpu::programmable_blend::open`).
pub fn fit_hardware<M: Trainable>(
    gpu: &Gpu,
    data: &Dataset,
    params: &mut Vec<M::Params>,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    super::fit::from_params::<M>(params, opts, |state| {
        fit_hardware_shared::<M>(&Solo, gpu, data, state, extent, opts, progress)
    })
}

/// [`super::fit::fit_shared`] with each view's frame and gradients from the hardware path on
/// `gpu` (a device from `splat_gpu::programmable_blend::open`).
pub fn fit_hardware_shared<M: Trainable>(
    team: &dyn Team,
    gpu: &Gpu,
    data: &Dataset,
    state: &mut Checkpoint,
    extent: f32,
    opts: &FitOptions,
    progress: impl FnMut(&StepReport),
) -> Result<(), FitError> {
    let frames = HardwareFrames::new(gpu, &step_render(opts))?;
    fit_with::<M>(
        team,
        data,
        state,
        extent,
        opts,
        Frames::Hardware(Box::new(frames)),
        progress,
    )
}
