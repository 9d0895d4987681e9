//! A method's primitives on the device: the scene every GPU pass reads its parameters from,
//! and the host's words for a device buffer.

use super::device::Grown;
use super::{Gpu, GpuError, GpuRenderError};
use splat_core::flat::Flat;
use splat_core::frame::RenderError;
use splat_core::method::SplatMethod;
use std::marker::PhantomData;

/// Each upload's stamp: a frame knows the parameters it was rendered from by theirs.
static UPLOADS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// A method's primitives on the device: `Params` words per primitive, in order. An optimizer
/// on the device updates [`GpuScene::buffer`] in place between frames.
pub struct GpuScene<M: SplatMethod> {
    params: Grown,
    len: usize,
    /// The stamp of the last upload (changes made in place on the device keep it).
    pub(super) stamp: u64,
    method: PhantomData<M>,
}

impl<M: SplatMethod> GpuScene<M> {
    pub fn new(gpu: &Gpu, params: &[M::Params]) -> Result<GpuScene<M>, GpuRenderError> {
        let mut scene = GpuScene {
            params: Grown::new(gpu, "parameters", params.len() * M::Params::LEN)?,
            len: 0,
            stamp: 0,
            method: PhantomData,
        };
        scene.upload(gpu, params)?;
        Ok(scene)
    }

    /// Replaces the primitives (the buffer grows if there are more; no NaN or infinity).
    pub fn upload(&mut self, gpu: &Gpu, params: &[M::Params]) -> Result<(), GpuRenderError> {
        if let Some(i) = params.iter().position(|p| !p.is_finite()) {
            return Err(RenderError::NonFinite(i).into());
        }
        u32::try_from(params.len()).map_err(|_| GpuError::TooLarge {
            what: "the primitive count",
            bytes: params.len() as u64,
            limit: u32::MAX as u64,
        })?;
        self.params.ensure(gpu, params.len() * M::Params::LEN)?;
        gpu.write(&self.params, &words_of(params));
        self.len = params.len();
        self.stamp = UPLOADS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether this is, unchanged, the scene of `primitives` primitives that the upload
    /// stamped `stamp` held: what works on a drawn frame (its backward, its settling) needs
    /// the scene the frame was drawn from.
    pub(crate) fn check_drawn(&self, primitives: usize, stamp: u64) -> Result<(), GpuRenderError> {
        if self.len != primitives {
            return Err(GpuRenderError::SceneChanged {
                got: self.len,
                want: primitives,
            });
        }
        match self.stamp == stamp {
            true => Ok(()),
            false => Err(GpuRenderError::OtherScene),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The parameter words, `M::Params::LEN` per primitive.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.params
    }

    pub fn download(&self, gpu: &Gpu) -> Result<Vec<M::Params>, GpuError> {
        let words = gpu.read(&self.params, self.len * M::Params::LEN)?;
        let floats: Vec<f32> = words.into_iter().map(f32::from_bits).collect();
        Ok(floats
            .chunks_exact(M::Params::LEN.max(1))
            .take(self.len)
            .map(M::Params::read_words)
            .collect())
    }
}

/// 32-bit words of a sequence of `Flat` values, in order.
pub(crate) fn words_of<T: Flat>(values: &[T]) -> Vec<u32> {
    let mut w = vec![0.0f32; T::LEN * values.len()];
    for (v, out) in values.iter().zip(w.chunks_exact_mut(T::LEN.max(1))) {
        v.write_words(out);
    }
    w.into_iter().map(f32::to_bits).collect()
}
