//! `splat render` and `splat gallery`.

use crate::{Backend, Model};
use anyhow::{Result, bail};
use splat_runtime::gpu::{Gpu, GpuRenderer, GpuScene, HardwareRenderer};
use splat_runtime::io::ply::{FromStored, GaussianCloud};
use splat_runtime::precision::Precision;
use splat_runtime::{Camera, Frame, RenderOptions, SplatMethod, render};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct RenderArgs {
    /// INRIA 3DGS PLY scene.
    #[arg(long)]
    pub(crate) scene: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) camera: crate::view::CameraArgs,
    /// The built-in camera's model (default pinhole; a camera file names its own).
    #[arg(long, value_enum, conflicts_with = "camera")]
    pub(crate) camera_model: Option<Model>,
    #[arg(long)]
    pub(crate) method: String,
    /// Output file: .png, .exr or .npy.
    #[arg(long, default_value = "render.png")]
    pub(crate) out: PathBuf,
    /// Tile size in pixels: 8, 16, 32 or 64 on the CPU; 8 or 16 on the GPU.
    #[arg(long, default_value_t = 16)]
    pub(crate) tile: u32,
    /// Also output the expected depth.
    #[arg(long)]
    pub(crate) depth: bool,
    /// Also output alpha.
    #[arg(long)]
    pub(crate) alpha: bool,
    /// Blend at most this many primitives per tile.
    #[arg(long)]
    pub(crate) p_max: Option<usize>,
    /// How the per-pixel state is stored: f32, f16, unorm16 or unorm8 (with --hardware, the
    /// render targets' format).
    #[arg(long, default_value = "f32", value_parser = parse_precision)]
    pub(crate) precision: Precision,
    /// How the shade data the blend reads per primitive is stored: f32, f16, unorm16 or unorm8
    /// (unorm: each value coded in the range it spans over the frame; not with --hardware).
    #[arg(long, default_value = "f32", value_parser = parse_precision)]
    pub(crate) shade_precision: Precision,
    /// On the GPU, rasterize with the graphics pipeline: quads in depth order, blended by
    /// fixed-function blending (no tile lists; no transmittance stop).
    #[arg(long)]
    pub(crate) hardware: bool,
    /// Also print the effects the frame simulates and the kernel variants that carry them.
    #[arg(long)]
    pub(crate) explain: bool,
    /// Where to render: the CPU backend (rayon + SIMD) or the wgpu backend (any adapter,
    /// software ones included); `auto` picks a hardware GPU when there is one.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub(crate) backend: Backend,
    /// The built-in camera's width (a camera file gives its own).
    #[arg(long, default_value_t = 800, conflicts_with = "camera")]
    pub(crate) width: u32,
    /// The built-in camera's height (a camera file gives its own).
    #[arg(long, default_value_t = 600, conflicts_with = "camera")]
    pub(crate) height: u32,
}

/// Renders a scene from a run of cameras with the chosen method, on the GPU picked or on the
/// CPU.
pub struct Render<'a> {
    pub(crate) cloud: &'a GaussianCloud,
    /// The next camera to render, until `None` (a list's, or a viewer's as they arrive).
    pub(crate) cameras: &'a dyn Fn() -> Option<Camera>,
    pub(crate) opts: &'a RenderOptions,
    pub(crate) gpu: Option<&'a Gpu>,
    /// The hardware-rasterized forward pass (GPU only).
    pub(crate) hardware: bool,
}

/// What receives each frame of a [`Render`], in the cameras' order.
pub(crate) type Frames<'f> = &'f mut dyn FnMut(Frame) -> Result<()>;

/// Where frames render: "the CPU", "GPU, <adapter>" or "GPU (hardware rasterizer), <adapter>".
pub(crate) fn place(gpu: Option<&Gpu>, hardware: bool) -> String {
    match (gpu, hardware) {
        (None, _) => "the CPU".to_string(),
        (Some(gpu), false) => format!("GPU, {}", gpu.adapter),
        (Some(gpu), true) => format!("GPU (hardware rasterizer), {}", gpu.adapter),
    }
}

/// A precision by its name.
pub(crate) fn parse_precision(name: &str) -> Result<Precision, String> {
    let all = Precision::ALL;
    all.into_iter().find(|p| p.name() == name).ok_or_else(|| {
        let names: Vec<&str> = all.iter().map(|p| p.name()).collect();
        format!("expected one of {}", names.join(", "))
    })
}

impl Render<'_> {
    /// Renders each camera in turn, handing its frame to `each` (on the GPU, the scene is
    /// uploaded once and one renderer draws every frame); says where they ran.
    pub(crate) fn run<M: SplatMethod>(&self, each: Frames) -> Result<String>
    where
        M::Params: FromStored,
    {
        let params: Vec<M::Params> = self.cloud.params();
        // Every camera's frame as `draw` renders it, in order.
        let mut frames = |draw: &mut dyn FnMut(&Camera) -> Result<Frame>| {
            while let Some(camera) = (self.cameras)() {
                each(draw(&camera)?)?;
            }
            Ok::<(), anyhow::Error>(())
        };
        Ok(match self.gpu {
            None if self.hardware => {
                bail!("--hardware rasterizes with the GPU: use --backend gpu or auto")
            }
            Some(gpu) if self.hardware => {
                let mut renderer = HardwareRenderer::<M>::new(gpu, self.opts)?;
                let scene = GpuScene::new(gpu, &params)?;
                frames(&mut |camera| {
                    renderer.forward(&scene, camera)?;
                    Ok(renderer.download_frame()?)
                })?;
                place(Some(gpu), true)
            }
            None => {
                frames(&mut |camera| Ok(render::<M>(&params, camera, self.opts)?))?;
                place(None, false)
            }
            Some(gpu) => {
                let mut renderer = GpuRenderer::<M>::new(gpu, self.opts)?;
                let scene = GpuScene::new(gpu, &params)?;
                frames(&mut |camera| {
                    renderer.forward(&scene, camera)?;
                    Ok(renderer.download_frame()?)
                })?;
                place(Some(gpu), false)
            }
        })
    }
}
