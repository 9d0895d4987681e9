//! splat-runtime: the shared pipeline every `#[splat_method]` method plugs into, and the
//! contract ([`SplatMethod`]) between generated code and that pipeline.
//!
//! Code map:
//! - [`method`]: the contract a generated method implements.
//! - [`types`]: built-in values crossing that contract (camera, projected primitive,
//!   contribution of a pair, tile bounds).
//! - [`flat`]: flattening of method data to 32-bit words (GPU buffers, SIMD lanes).
//! - [`lanes`]: eight-lane SIMD value types used by the generated lane form of `evaluate`.
//! - [`math`]: branch-free `exp` / `ln` shared by the scalar and lane code paths.
//! - [`prelude`]: what a method module imports.
//! - [`pipeline`]: the CPU pipeline (preprocess, rasterize, shade, backward).
//! - [`io`]: PLY scenes, JSON cameras, PNG / EXR / NPY outputs (atomic writes).
//! - [`gpu`]: the wgpu backend: the device-resident pipeline, one-shot render and backward, and
//!   a harness running generated WGSL functions on batches.
//! - [`train`]: what training shares across methods: the loss, metrics, Adam.

pub mod cameras;
pub mod checks;
pub mod effects;
pub mod flat;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod io;
pub mod lanes;
pub mod math;
pub mod method;
pub mod pipeline;
pub mod prelude;
pub mod train;
pub mod types;

pub use effects::Effects;
pub use flat::Flat;
pub use glam;
pub use lanes::{F32x8, I32x8, LANES, LaneArray, M32x8, U32x8};
pub use method::{
    GeneratedSource, GradientSet, SplatMethod, WgslFunction, WgslScalar, param_group, param_groups,
    word_name,
};
pub use pipeline::{
    Frame, FrameGrad, Gradients, Image, RenderError, RenderOptions, backward, render,
    render_for_backward,
};
pub use types::{Camera, CameraModel, Contribution, ContributionLanes, Projected, Tile};
