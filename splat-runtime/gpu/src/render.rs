//! One-shot rendering on the GPU for callers whose parameters live on the host: upload,
//! render, download, over the resident pipeline ([`super::resident`]). A loop over frames
//! (training, a viewer) keeps a [`GpuRenderer`] and a [`GpuScene`] instead.

use super::Gpu;
use super::entries::Accumulation;
use super::resident::{GpuGradients, GpuRenderer};
use super::{GpuRenderError, GpuScene};
use splat_core::frame::{Frame, FrameGrad, RenderOptions};
use splat_core::method::SplatMethod;
use splat_core::types::Camera;

pub fn render<M: SplatMethod>(
    gpu: &Gpu,
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<Frame, GpuRenderError> {
    let mut renderer = GpuRenderer::<M>::new(gpu, opts)?;
    let scene = GpuScene::new(gpu, params)?;
    renderer.forward(&scene, camera)?;
    renderer.download_frame()
}

/// A frame kept on the GPU for [`backward`]: the renderer that drew it and its scene.
pub struct GpuForwardState<'g, M: SplatMethod> {
    pub renderer: GpuRenderer<'g, M>,
    pub scene: GpuScene<M>,
}

/// Renders and keeps what [`backward`] needs (the depth sums only when `opts` asks for
/// depth: a depth gradient needs them).
pub fn render_for_backward<'g, M: SplatMethod>(
    gpu: &'g Gpu,
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<(Frame, GpuForwardState<'g, M>), GpuRenderError> {
    let mut renderer = GpuRenderer::<M>::new(gpu, opts)?;
    let scene = GpuScene::new(gpu, params)?;
    renderer.forward(&scene, camera)?;
    let frame = renderer.download_frame()?;
    Ok((frame, GpuForwardState { renderer, scene }))
}

/// Gradients of the parameters and the camera, given the gradient of each output of the
/// frame `state` kept; `acc` chooses the reduction and the kind of atomics
/// ([`Accumulation::default_for`] the adapter, unless measuring).
pub fn backward<M: SplatMethod>(
    state: &mut GpuForwardState<'_, M>,
    grad: &FrameGrad,
    acc: Accumulation,
) -> Result<GpuGradients<M>, GpuRenderError> {
    state.renderer.backward(&state.scene, grad, acc)?;
    state.renderer.download_gradients()
}
