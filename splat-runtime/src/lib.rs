//! splat-runtime: the shared pipeline every `#[splat_method]` method plugs into, and the
//! contract ([`SplatMethod`]) between generated code and that pipeline. This crate is a
//! facade: each layer is its own crate, re-exported here under one name, so the paths the
//! macro emits (`splat_runtime::prelude::*`, `splat_runtime::SplatMethod`) and users' imports
//! stay the same. The layers, and what may depend on what (ARCHITECTURE.md, enforced by
//! `tests/layers.rs`):
//!
//! - splat-core ([`method`], [`types`], [`cameras`], [`flat`], [`lanes`], [`math`],
//!   [`prelude`], [`frame`], [`grid`], [`blend`], [`precision`], [`effects`]): the contract and
//!   what both backends agree on. Depends on no other layer.
//! - splat-cpu ([`pipeline`]): the CPU pipeline (preprocess, rasterize, shade, backward).
//! - splat-gpu ([`gpu`], feature `gpu`): the wgpu backend.
//! - splat-io ([`io`]): PLY scenes, JSON cameras, datasets, PNG / EXR / NPY outputs.
//! - splat-train ([`train`]): loss, metrics, Adam, density control, MCMC, checkpoints, the
//!   training loop on the CPU and (feature `gpu`) the GPU.
//! - splat-checks ([`checks`]): a method's checks (reference renderer, finite differences,
//!   reference adjoint, extremes, fixtures, GPU parity).

pub use splat_core::{
    blend, cameras, effects, flat, frame, grid, lanes, math, method, precision, prelude, types,
    with_camera_model, with_pixel_model,
};
#[cfg(feature = "gpu")]
pub use splat_gpu as gpu;
pub use {splat_checks as checks, splat_cpu as pipeline, splat_io as io, splat_train as train};

pub use splat_core::glam;
pub use splat_core::{
    Camera, CameraModel, Contribution, ContributionLanes, Effects, F32x8, Flat, Frame, FrameGrad,
    GeneratedSource, GradientSet, Gradients, I32x8, Image, LANES, LaneArray, M32x8, Projected,
    RenderError, RenderOptions, SplatMethod, Tile, U32x8, WgslFunction, WgslScalar, param_group,
    param_groups, word_name,
};
pub use splat_cpu::{backward, render, render_for_backward};
