//! `splat`: render scenes with a splatting method and inspect the kernels generated for it.

mod bench;
mod fit;
mod scene;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use splat_methods::{FromStored, geer, gs3d, gs3d_sh0, gs3d_sh1, gs3d_sh2, gut, linprim};
use splat_runtime::gpu::Gpu;
use splat_runtime::io::ply::GaussianCloud;
use splat_runtime::io::{camera as camera_io, image as image_io, ply};
use splat_runtime::{Camera, CameraModel, Frame, Image, RenderOptions, SplatMethod, render};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "splat",
    version,
    about = "Point-based differentiable rendering"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (the built-in one when no --scene is given).
    Render(RenderArgs),
    /// Write the built-in scene as an INRIA PLY, and its camera as JSON.
    Scene {
        #[arg(long, default_value = "planet.ply")]
        out: PathBuf,
        #[arg(long)]
        camera_out: Option<PathBuf>,
    },
    /// Render the built-in scene with every method and camera model into one picture (rows:
    /// methods; columns: pinhole, fisheye, equiangular).
    Gallery {
        #[arg(long, default_value = "gallery.png")]
        out: PathBuf,
        /// Size of each panel.
        #[arg(long, default_value_t = 320)]
        width: u32,
        #[arg(long, default_value_t = 240)]
        height: u32,
    },
    /// Time forward and forward + backward frames on one scene (GPU: the device-resident
    /// pipeline; CPU: per thread count), with per-stage medians.
    Bench(bench::BenchArgs),
    /// Train a Gaussian method on posed images (Blender, nerfstudio or COLMAP), on the GPU or
    /// the CPU.
    Fit(fit::FitArgs),
    /// Print the Rust or WGSL the #[splat_method] compiler generated for a method.
    Inspect {
        #[arg(long, value_enum, default_value_t = Method::Gs3d)]
        method: Method,
        #[arg(long, value_enum, default_value_t = Lang::Rust)]
        lang: Lang,
    },
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum Method {
    /// 3D Gaussian Splatting (EWA, SH up to degree 3); pinhole only.
    #[value(name = "3dgs")]
    Gs3d,
    /// 3DGUT: unscented-transform projection, evaluation along camera rays; every camera.
    #[value(name = "3dgut")]
    Gut,
    /// LinPrim: octahedra (each Gaussian of the scene becomes one); pinhole only.
    #[value(name = "linprim")]
    Linprim,
    /// 3DGEER: exact ray integral, particle bounding frustums; every camera.
    #[value(name = "3dgeer")]
    Geer,
}

impl Method {
    const ALL: [Method; 4] = [Method::Gs3d, Method::Gut, Method::Linprim, Method::Geer];

    fn name(self) -> &'static str {
        match self {
            Method::Gs3d => "3dgs",
            Method::Gut => "3dgut",
            Method::Linprim => "linprim",
            Method::Geer => "3dgeer",
        }
    }

    fn source(self) -> splat_runtime::GeneratedSource {
        match self {
            Method::Gs3d => gs3d::Method::SOURCE,
            Method::Gut => gut::Method::SOURCE,
            Method::Linprim => linprim::Method::SOURCE,
            Method::Geer => geer::Method::SOURCE,
        }
    }
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum Model {
    Pinhole,
    #[value(name = "kannala_brandt")]
    KannalaBrandt,
    Equiangular,
}

impl From<Model> for CameraModel {
    fn from(m: Model) -> CameraModel {
        match m {
            Model::Pinhole => CameraModel::Pinhole,
            Model::KannalaBrandt => CameraModel::KannalaBrandt,
            Model::Equiangular => CameraModel::Equiangular,
        }
    }
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum Backend {
    /// A hardware GPU if wgpu finds one, else the CPU (a software adapter such as lavapipe is
    /// slower than the CPU backend).
    Auto,
    Cpu,
    Gpu,
}

#[derive(Clone, Copy, ValueEnum)]
enum Lang {
    Rust,
    Wgsl,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// INRIA 3DGS PLY scene.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Camera JSON (default: the built-in view, at --width x --height, of --camera-model).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// The built-in camera's model (default pinhole; a camera file names its own).
    #[arg(long, value_enum, conflicts_with = "camera")]
    camera_model: Option<Model>,
    #[arg(long, value_enum, default_value_t = Method::Gs3d)]
    method: Method,
    /// Output file: .png, .exr or .npy.
    #[arg(long, default_value = "render.png")]
    out: PathBuf,
    /// Tile size in pixels (8, 16, 32 or 64).
    #[arg(long, default_value_t = 16)]
    tile: u32,
    /// Also output the expected depth.
    #[arg(long)]
    depth: bool,
    /// Also output alpha.
    #[arg(long)]
    alpha: bool,
    /// Blend at most this many primitives per tile.
    #[arg(long)]
    p_max: Option<usize>,
    /// Where to render: the CPU backend (rayon + SIMD) or the wgpu backend (any adapter,
    /// software ones included); `auto` picks a hardware GPU when there is one.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    #[arg(long, default_value_t = 800)]
    width: u32,
    #[arg(long, default_value_t = 600)]
    height: u32,
}

fn main() {
    quiet_device_select_layer();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render(args) => render_cmd(&args),
        Command::Fit(args) => fit::fit_cmd(&args),
        Command::Bench(args) => bench::bench_cmd(&args),
        Command::Scene { out, camera_out } => {
            ply::write(&out, &scene::planet())
                .with_context(|| format!("writing {}", out.display()))?;
            println!("wrote {}", out.display());
            if let Some(c) = camera_out {
                camera_io::write(&c, &scene::camera(800, 600, CameraModel::Pinhole))
                    .with_context(|| format!("writing {}", c.display()))?;
                println!("wrote {}", c.display());
            }
            Ok(())
        }
        Command::Gallery { out, width, height } => gallery(&out, width, height),
        Command::Inspect { method, lang } => {
            let source = method.source();
            print!(
                "{}",
                if let Lang::Wgsl = lang {
                    source.wgsl
                } else {
                    source.rust
                }
            );
            Ok(())
        }
    }
}

/// Work generic over a method's types: run by [`with_method`] with the method chosen at run
/// time.
trait MethodTask {
    type Output;
    fn run<M: SplatMethod>(self) -> Result<Self::Output>
    where
        M::Params: FromStored;
}

/// Runs `task` with `method`. 3DGS runs the instance matching the scene's SH degree
/// (higher-order terms cost nothing when the scene has none); the others carry degree 3.
fn with_method<T: MethodTask>(method: Method, sh_degree: u32, task: T) -> Result<T::Output> {
    match (method, sh_degree) {
        (Method::Gs3d, 0) => task.run::<gs3d_sh0::Method>(),
        (Method::Gs3d, 1) => task.run::<gs3d_sh1::Method>(),
        (Method::Gs3d, 2) => task.run::<gs3d_sh2::Method>(),
        (Method::Gs3d, _) => task.run::<gs3d::Method>(),
        (Method::Gut, _) => task.run::<gut::Method>(),
        (Method::Linprim, _) => task.run::<linprim::Method>(),
        (Method::Geer, _) => task.run::<geer::Method>(),
    }
}

/// Mesa's Vulkan device-selection layer looks for a Wayland display to pick the GPU driving
/// it, and without `XDG_RUNTIME_DIR` libwayland prints an error line on stderr. wgpu picks the
/// adapter itself, so the layer has nothing to do here: it is switched off (its documented
/// `NODEVICE_SELECT`) unless the user set either variable.
fn quiet_device_select_layer() {
    let set = |k| std::env::var_os(k).is_some();
    if !set("XDG_RUNTIME_DIR") && !set("NODEVICE_SELECT") {
        // SAFETY: the first statement of main, before any thread exists.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

/// The GPU `backend` asks for: none for the CPU; for `auto`, a hardware adapter if there is
/// one (and a line saying why not when there is none).
fn pick_gpu(backend: Backend) -> Result<Option<Gpu>> {
    Ok(match backend {
        Backend::Cpu => None,
        Backend::Gpu => Some(Gpu::new()?),
        Backend::Auto => match Gpu::new() {
            Ok(g) if !g.software => Some(g),
            Ok(g) => {
                println!(
                    "backend auto: the CPU, since the only GPU adapter is a software one ({}), slower than the CPU backend",
                    g.adapter
                );
                None
            }
            Err(e) => {
                println!("backend auto: the CPU, since there is no GPU ({e})");
                None
            }
        },
    })
}

/// Renders a scene with the chosen method on the chosen backend.
struct Render<'a> {
    cloud: &'a GaussianCloud,
    camera: &'a Camera,
    opts: &'a RenderOptions,
    backend: Backend,
}

impl MethodTask for Render<'_> {
    /// The frame and where it ran.
    type Output = (Frame, String);

    fn run<M: SplatMethod>(self) -> Result<(Frame, String)>
    where
        M::Params: FromStored,
    {
        let params: Vec<M::Params> = self
            .cloud
            .gaussians
            .iter()
            .map(M::Params::from_stored)
            .collect();
        Ok(match pick_gpu(self.backend)? {
            None => (
                render::<M>(&params, self.camera, self.opts)?,
                "CPU".to_string(),
            ),
            Some(gpu) => {
                let frame =
                    splat_runtime::gpu::render::render::<M>(&gpu, &params, self.camera, self.opts)?;
                (frame, format!("GPU, {}", gpu.adapter))
            }
        })
    }
}

/// Renders `cloud` with `method` on `backend`; returns the frame and where it ran.
fn render_method(
    method: Method,
    cloud: &GaussianCloud,
    camera: &Camera,
    opts: &RenderOptions,
    backend: Backend,
) -> Result<(Frame, String)> {
    let task = Render {
        cloud,
        camera,
        opts,
        backend,
    };
    with_method(method, cloud.sh_degree, task)
}

/// Every method on every camera model, panels in a grid; a method that does not support a
/// model gets a dark panel.
fn gallery(out: &std::path::Path, width: u32, height: u32) -> Result<()> {
    let side = 1..=2048;
    if !side.contains(&width) || !side.contains(&height) {
        bail!("panel size {width}x{height} is out of range (1..=2048 per side)");
    }
    let cloud = scene::planet();
    let (cols, rows) = (CameraModel::ALL.len() as u32, Method::ALL.len() as u32);
    let mut grid = Image {
        width: width * cols,
        height: height * rows,
        channels: 3,
        data: vec![0.08; (width * cols * height * rows * 3) as usize],
    };
    let opts = RenderOptions::default();
    for (r, method) in Method::ALL.into_iter().enumerate() {
        for (c, model) in CameraModel::ALL.into_iter().enumerate() {
            let camera = scene::camera(width, height, model);
            let frame = match render_method(method, &cloud, &camera, &opts, Backend::Cpu) {
                Ok((frame, _)) => frame,
                // A pinhole-only method on another model: a dark panel. Any other error is one.
                Err(e)
                    if matches!(
                        e.downcast_ref::<splat_runtime::RenderError>(),
                        Some(splat_runtime::RenderError::CameraModel { .. })
                    ) =>
                {
                    println!("{} / {model}: {e}", method.name());
                    continue;
                }
                Err(e) => return Err(e),
            };
            for y in 0..height {
                let src = (y * width * 3) as usize;
                let dst = (((r as u32 * height + y) * grid.width + c as u32 * width) * 3) as usize;
                let row = (width * 3) as usize;
                grid.data[dst..dst + row].copy_from_slice(&frame.color.data[src..src + row]);
            }
            println!(
                "{} / {model}: {} visible, {} intersections, shade {:.1} ms",
                method.name(),
                frame.stats.visible,
                frame.stats.intersections,
                frame.stats.shade.as_secs_f64() * 1e3
            );
        }
    }
    let frame = Frame {
        color: grid,
        alpha: None,
        depth: None,
        stats: Default::default(),
    };
    for p in image_io::write_frame(out, &frame)? {
        println!("wrote {}", p.display());
    }
    Ok(())
}

fn render_cmd(args: &RenderArgs) -> Result<()> {
    let ext = args
        .out
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if !["png", "exr", "npy"].contains(&ext.as_str()) {
        bail!(
            "output `{}`: unknown extension (use .png, .exr or .npy)",
            args.out.display()
        );
    }
    let t0 = Instant::now();
    let (cloud, source) = match &args.scene {
        Some(path) => (ply::read(path)?, path.display().to_string()),
        None => (scene::planet(), "built-in planet".to_string()),
    };
    let camera: Camera = match &args.camera {
        Some(path) => camera_io::read(path)?,
        None => {
            let side = 1..=splat_runtime::pipeline::MAX_SIDE;
            if !side.contains(&args.width) || !side.contains(&args.height) {
                bail!(
                    "image size {}x{} is out of range (1..={} per side)",
                    args.width,
                    args.height,
                    side.end()
                );
            }
            let model = args.camera_model.unwrap_or(Model::Pinhole);
            scene::camera(args.width, args.height, model.into())
        }
    };
    let load = t0.elapsed();
    let opts = RenderOptions {
        tile_size: args.tile,
        p_max: args.p_max,
        alpha: args.alpha,
        depth: args.depth,
        ..Default::default()
    };
    let (frame, backend) = render_method(args.method, &cloud, &camera, &opts, args.backend)?;
    let written = image_io::write_frame(&args.out, &frame)?;
    let s = &frame.stats;
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    println!(
        "{} on {backend}: {} primitives (SH degree {}) from {source}, {}x{} {} camera, tile {}",
        args.method.name(),
        s.primitives,
        cloud.sh_degree,
        frame.color.width,
        frame.color.height,
        camera.model,
        args.tile
    );
    let pairs = if backend == "CPU" {
        s.pairs.to_string()
    } else {
        "not counted on the GPU".to_string()
    };
    println!(
        "visible {}, intersections {}, pairs evaluated {pairs}",
        s.visible, s.intersections
    );
    let stages = s.preprocess + s.rasterize + s.shade;
    if backend != "CPU" && stages.is_zero() {
        println!(
            "load {:.1} ms; no stage times: this adapter has no GPU timestamps",
            ms(load)
        );
    } else {
        println!(
            "load {:.1} ms, preprocess {:.1} ms, rasterize {:.1} ms, shade {:.1} ms",
            ms(load),
            ms(s.preprocess),
            ms(s.rasterize),
            ms(s.shade)
        );
    }
    for p in written {
        println!("wrote {}", p.display());
    }
    Ok(())
}
