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
//!
//! # Rendering and its gradients
//!
//! Three Gaussians rendered with 3DGS on the CPU, then the gradient of the image's red sum with
//! respect to every parameter:
//!
//! ```
//! use splat_methods::gs3d::{Method, Params};
//! use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
//! use splat_runtime::{Camera, FrameGrad, RenderOptions, backward, render_for_backward};
//!
//! let gaussian = |x: f32, color: Vec3| Params {
//!     mean: Vec3::new(x, 0.0, 4.0),
//!     log_scale: Vec3::splat(-1.5),
//!     rotation: Vec4::new(1.0, 0.0, 0.0, 0.0), // (w, x, y, z)
//!     opacity_logit: 2.0,
//!     sh: std::array::from_fn(|i| if i == 0 { color } else { Vec3::ZERO }),
//! };
//! let params = [gaussian(-0.6, Vec3::X), gaussian(0.0, Vec3::Y), gaussian(0.6, Vec3::Z)];
//! let camera = Camera {
//!     rotation: Mat3::IDENTITY, // world to camera, OpenCV axes: looking down +z
//!     translation: Vec3::ZERO,
//!     focal: Vec2::splat(64.0),
//!     principal: Vec2::new(32.0, 24.0),
//!     size: Vec2::new(64.0, 48.0),
//!     ..Default::default()
//! };
//! let opts = RenderOptions::default();
//! let (frame, state) = render_for_backward::<Method>(&params, &camera, &opts)?;
//! let image = &frame.color; // 64 x 48 x RGB, rows top to bottom
//! assert_eq!((image.width, image.height, image.channels), (64, 48, 3));
//!
//! // d(sum of red) / d(red value) is one at every pixel.
//! let red = (0..image.data.len()).map(|i| (i % 3 == 0) as u32 as f32).collect();
//! let grad = FrameGrad { color: red, alpha: None, depth: None };
//! let gradients = backward::<Method>(&state, &params, &camera, &grad)?;
//! // More red DC coefficient, more red.
//! assert!(gradients.params[0].sh[0].x > 0.0);
//! # Ok::<(), splat_runtime::RenderError>(())
//! ```
//!
//! The same on the GPU, with the scene uploaded once and the renderer's buffers kept across
//! frames ([`gpu::GpuRenderer`]):
//!
//! ```
//! # use splat_methods::gs3d::{Method, Params};
//! # use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
//! # use splat_runtime::{Camera, RenderOptions};
//! use splat_runtime::gpu::{GpuRenderer, GpuScene};
//! # let params = [Params {
//! #     mean: Vec3::new(0.0, 0.0, 4.0),
//! #     log_scale: Vec3::splat(-1.5),
//! #     rotation: Vec4::new(1.0, 0.0, 0.0, 0.0),
//! #     opacity_logit: 2.0,
//! #     sh: [Vec3::ONE; 16],
//! # }];
//! # let camera = Camera {
//! #     focal: Vec2::splat(64.0),
//! #     principal: Vec2::new(32.0, 24.0),
//! #     size: Vec2::new(64.0, 48.0),
//! #     ..Default::default()
//! # };
//! // `None` without an adapter (set SPLAT_REQUIRE_GPU=1 to make that an error).
//! let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else { return Ok(()) };
//! let scene = GpuScene::<Method>::new(&gpu, &params)?;
//! let mut renderer = GpuRenderer::<Method>::new(&gpu, &RenderOptions::default())?;
//! let info = renderer.forward(&scene, &camera)?;
//! assert_eq!(info.visible, 1);
//! let frame = renderer.download_frame()?;
//! assert_eq!(frame.color.data.len(), 64 * 48 * 3);
//! # Ok::<(), splat_runtime::gpu::GpuRenderError>(())
//! ```

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
