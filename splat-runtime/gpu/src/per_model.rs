//! Kernels built on first use, one per camera model a renderer's frames use: each is compiled
//! from the method's functions specialized to that model (the compiler's `{kernel}_{model}`
//! variants), so a frame's kernels hold no other model's code, and a model never used costs
//! no pipeline.

use splat_core::types::CameraModel;

pub(crate) struct PerModel<T>([Option<T>; CameraModel::ALL.len()]);

impl<T: Clone> PerModel<T> {
    pub fn new() -> Self {
        PerModel(std::array::from_fn(|_| None))
    }

    /// The value for `model`, built by `build` the first time.
    pub fn get<E>(
        &mut self,
        model: CameraModel,
        build: impl FnOnce() -> Result<T, E>,
    ) -> Result<T, E> {
        let slot = &mut self.0[model as usize];
        if let Some(v) = slot {
            return Ok(v.clone());
        }
        let v = build()?;
        *slot = Some(v.clone());
        Ok(v)
    }
}
