//! splat-gpu: the wgpu backend of the runtime (rendering and its backward pass; training's
//! device kernels live in splat-train beside their CPU twins).
//!
//! - [`device`]: the device, its optional features, cached pipelines, buffers within limits.
//! - [`dispatch`] / [`kernel`]: run any generated WGSL function over a batch (tests, tools).
//! - [`sort`]: prefix sum, stable radix sort of u32 keys (depths, then tiles), tile ranges,
//!   trip-count binning.
//! - [`entries`]: the method-specific entry points (project, count/emit with `tile_cull`,
//!   per-tile shading, backward blend, `project`'s adjoint) around the generated WGSL.
//! - [`frame_uniform`]: the frame's uniform, one struct in WGSL and its `#[repr(C)]` Rust twin.
//! - [`resident`]: the device-resident pipeline: [`GpuScene`] (parameters on the device) and
//!   [`GpuRenderer`] (kernels built once, buffers kept across frames, forward and backward).
//! - [`raster`]: the hardware-rasterized forward pass: quads drawn in depth order, blended
//!   by fixed-function blending into render targets of each precision.
//! - [`programmable_blend`]: a fragment's read-modify-write of its pixel in rasterization
//!   order (raw Vulkan inside a wgpu encoder): the footing of a hardware backward.
//! - [`render`]: one-shot render and backward for parameters on the host, over `resident`.
//! - [`state`]: the per-pixel state of the tile path, packed at each precision.
//! - [`sums`]: the backward blend's per-primitive gradient sums, f32 or f16.
//! - [`shade_pack`]: the shade data between the preprocess and the blends, packed at each
//!   precision.
//! - [`timing`]: stage times from GPU timestamps.

mod adjoint;
pub mod device;
pub mod dispatch;
pub mod entries;
pub mod frame_uniform;
mod front;
pub mod kernel;
mod packing;
mod per_model;
pub mod programmable_blend;
mod prune;
pub mod raster;
pub mod render;
pub mod resident;
mod scatter;
mod scene;
pub mod shade_pack;
pub mod sort;
pub mod state;
pub mod sums;
pub mod timing;

pub use device::Gpu;
pub use front::sort_bytes;
pub use raster::HardwareRenderer;
pub use resident::{GpuRenderer, StageTimes};
pub use scene::GpuScene;

/// The tile sizes the GPU backend renders with: one invocation per pixel of a tile.
pub const TILE_SIZES: [u32; 2] = [8, 16];

/// The adapter for tests and tools that can do without one: `None` (with a line on stderr)
/// when there is none, unless `SPLAT_REQUIRE_GPU=1` (set by CI), which makes that a panic.
pub fn adapter_or_skip() -> Option<Gpu> {
    match Gpu::new() {
        Ok(g) => Some(g),
        Err(e) if std::env::var("SPLAT_REQUIRE_GPU").is_ok_and(|v| v == "1") => panic!("{e}"),
        Err(e) => {
            eprintln!("skipping the GPU part: {e}");
            None
        }
    }
}

/// Why a GPU frame or its backward pass failed: the frame's own error or the device's.
#[derive(Debug, thiserror::Error)]
pub enum GpuRenderError {
    #[error(transparent)]
    Render(#[from] splat_core::frame::RenderError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("no finished frame: render one first (or finish the one submitted)")]
    NoFrame,
    #[error("the scene has {got} primitives, the frame was rendered with {want}")]
    SceneChanged { got: usize, want: usize },
    #[error(
        "the scene is not the one the frame was rendered from (another scene, or parameters uploaded since): render the frame again"
    )]
    OtherScene,
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found ({0}); on Linux without a GPU, install Mesa's lavapipe (Debian: mesa-vulkan-drivers)"
    )]
    NoAdapter(String),
    #[error("the GPU device could not be created: {0}")]
    Device(String),
    #[error("shader: {0}")]
    Shader(String),
    #[error("reading results back failed: {0}")]
    Readback(String),
    #[error(
        "{what} needs a {bytes}-byte buffer, over this GPU's limit of {limit} bytes: lower the resolution (`--downscale` for a dataset) or the number of primitives"
    )]
    TooLarge {
        what: &'static str,
        bytes: u64,
        limit: u64,
    },
    #[error(
        "the GPU ran out of memory for {what} ({bytes} bytes): lower the resolution or the number of primitives (`--max-primitives` when training), or use `--backend cpu`"
    )]
    OutOfMemory { what: &'static str, bytes: u64 },
    #[error(
        "the GPU backend supports tile sizes {TILE_SIZES:?} (one invocation per pixel), not {0}"
    )]
    TileSize(u32),
    #[error("the hardware-rasterized forward pass: {0}")]
    Hardware(String),
}
