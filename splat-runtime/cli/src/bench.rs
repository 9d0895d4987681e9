//! `splat bench`: the time of a frame, forward and forward + backward, on one scene and camera,
//! as a user's training loop would see it: on the GPU through the device-resident pipeline
//! (scene and buffers kept, nothing read back but the intersection count), on the CPU for each
//! thread count asked. Medians of wall time and of per-stage times (GPU timestamps where the
//! adapter has them), the GPU memory held, and optionally the forward image as raw float32
//! (H x W x 3, what `shared/bench/gsplat_bench.py` compares against gsplat's).

use crate::Backend;
use anyhow::{Context, Result, bail};
use splat_runtime::gpu::entries::Accumulation;
use splat_runtime::gpu::{Gpu, GpuRenderer, GpuScene};
use splat_runtime::io::ply::FromStored;
use splat_runtime::io::{ply, write_atomic};
use splat_runtime::{Camera, Frame, FrameGrad, RenderOptions, SplatMethod};
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct BenchArgs {
    /// INRIA 3DGS PLY scene (default: the built-in one).
    #[arg(long)]
    pub(crate) scene: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) camera: crate::view::CameraArgs,
    #[arg(long)]
    pub(crate) method: String,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub(crate) backend: Backend,
    /// Timed frames per measurement (after 0.3 s of warm-up frames).
    #[arg(long, default_value_t = 20)]
    pub(crate) iters: usize,
    /// Tile size in pixels: 8, 16, 32 or 64 on the CPU; 8 or 16 on the GPU.
    #[arg(long, default_value_t = 16)]
    pub(crate) tile: u32,
    /// CPU thread counts to measure, e.g. 1,2,4,8,16 (default: all cores).
    #[arg(long, value_delimiter = ',')]
    pub(crate) threads: Vec<usize>,
    /// Write the forward image here as raw little-endian float32, H x W x 3.
    #[arg(long)]
    pub(crate) raw_out: Option<PathBuf>,
    /// The built-in camera's width (a camera file gives its own).
    #[arg(long, default_value_t = 800, conflicts_with = "camera")]
    pub(crate) width: u32,
    /// The built-in camera's height (a camera file gives its own).
    #[arg(long, default_value_t = 600, conflicts_with = "camera")]
    pub(crate) height: u32,
    /// Compile the GPU shaders with naga's run-time checks (index clamps, division guards, a
    /// counter bounding each loop), to measure what they cost; off by default.
    #[arg(long)]
    pub(crate) shader_checks: bool,
}

pub struct Bench<'a> {
    pub(crate) args: &'a BenchArgs,
    pub(crate) method: &'a str,
    pub(crate) cloud: &'a ply::GaussianCloud,
    pub(crate) camera: &'a Camera,
    pub(crate) gpu: Option<&'a Gpu>,
}

/// One timed frame: its wall time and its stages' times, in the order of the table's columns.
struct Sample {
    wall: Duration,
    stages: Vec<Duration>,
}

const FORWARD_STAGES: [&str; 3] = ["preprocess", "rasterize", "shade"];
const BACKWARD_STAGES: [&str; 2] = ["backward blend", "project adjoint"];

impl Bench<'_> {
    pub(crate) fn run<M: SplatMethod>(&self) -> Result<()>
    where
        M::Params: FromStored,
    {
        let params: Vec<M::Params> = self.cloud.params();
        let opts = RenderOptions {
            tile_size: self.args.tile,
            ..Default::default()
        };
        // The upstream gradient gsplat_bench.py uses: uniform in [-0.5, 0.5) per color channel.
        let (w, h) = (self.camera.size.x as usize, self.camera.size.y as usize);
        let mut rng = fastrand::Rng::with_seed(1);
        let grad = FrameGrad {
            color: (0..w * h * 3).map(|_| rng.f32() - 0.5).collect(),
            alpha: None,
            depth: None,
        };
        println!(
            "{}: {} primitives (SH degree {}), {w}x{h} {} camera, tile {}, {} timed frames",
            self.method,
            params.len(),
            self.cloud.sh_degree,
            self.camera.model,
            opts.tile_size,
            self.args.iters
        );
        let frame = match self.gpu {
            Some(gpu) => self.gpu_bench::<M>(gpu, &params, &opts, &grad)?,
            None => self.cpu_bench::<M>(&params, &opts, &grad)?,
        };
        println!(
            "{} visible, {} intersections, longest tile list {}",
            frame.stats.visible, frame.stats.intersections, frame.stats.longest_list
        );
        if let Some(path) = &self.args.raw_out {
            write_raw(path, &frame)?;
            crate::wrote(path);
        }
        Ok(())
    }

    fn gpu_bench<M: SplatMethod>(
        &self,
        gpu: &Gpu,
        params: &[M::Params],
        opts: &RenderOptions,
        grad: &FrameGrad,
    ) -> Result<Frame> {
        let checks = match gpu.shader_checks() {
            true => " (shaders with naga's run-time checks)",
            false => "",
        };
        println!("GPU: {}{checks}", gpu.adapter);
        let scene = GpuScene::<M>::new(gpu, params)?;
        let mut renderer = GpuRenderer::<M>::new(gpu, opts)?;
        let acc = Accumulation::default_for(gpu);
        let camera = self.camera;
        // As a training loop runs: nothing read back between frames but the stage times, and
        // the output gradient already on the device (uploaded by a first backward pass).
        let forward = measure(self.args.iters, || {
            let t = Instant::now();
            renderer.forward(&scene, camera)?;
            gpu.wait()?;
            let wall = t.elapsed();
            let s = renderer.stage_times()?;
            Ok(Sample {
                wall,
                stages: vec![s.preprocess, s.rasterize, s.shade],
            })
        })?;
        renderer.forward(&scene, camera)?;
        renderer.backward(&scene, grad, acc)?;
        let both = measure(self.args.iters, || {
            let t = Instant::now();
            renderer.forward(&scene, camera)?;
            renderer.backward_on_device(&scene, acc)?;
            gpu.wait()?;
            let wall = t.elapsed();
            let s = renderer.stage_times()?;
            Ok(Sample {
                wall,
                stages: vec![s.preprocess, s.rasterize, s.shade, s.blend, s.project],
            })
        })?;
        print_table("GPU (device-resident)", &forward, &both);
        if !gpu.timestamps {
            println!("(this adapter has no timestamp queries: stage times are zero)");
        }
        match gpu.device.generate_allocator_report() {
            Some(r) => println!(
                "GPU memory: {:.1} MiB allocated, {:.1} MiB reserved (scene and renderer)",
                r.total_allocated_bytes as f64 / 1048576.0,
                r.total_reserved_bytes as f64 / 1048576.0
            ),
            None => println!("GPU memory: this backend gives no allocator report"),
        }
        renderer.forward(&scene, camera)?;
        Ok(renderer.download_frame()?)
    }

    fn cpu_bench<M: SplatMethod>(
        &self,
        params: &[M::Params],
        opts: &RenderOptions,
        grad: &FrameGrad,
    ) -> Result<Frame> {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = match self.args.threads.as_slice() {
            [] => vec![cores],
            t => t.to_vec(),
        };
        let camera = self.camera;
        let mut rows = Vec::new();
        for &t in &threads {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .context("starting the CPU thread pool")?;
            let (forward, both) = pool.install(|| -> Result<_> {
                let forward = measure(self.args.iters, || {
                    let t = Instant::now();
                    let s = splat_runtime::render::<M>(params, camera, opts)?.stats;
                    Ok(Sample {
                        wall: t.elapsed(),
                        stages: vec![s.preprocess, s.rasterize, s.shade],
                    })
                })?;
                let both = measure(self.args.iters, || {
                    let t = Instant::now();
                    let (f, state) = splat_runtime::render_for_backward::<M>(params, camera, opts)?;
                    let g = splat_runtime::backward::<M>(&state, params, camera, grad)?;
                    let (s, b) = (f.stats, g.stats);
                    Ok(Sample {
                        wall: t.elapsed(),
                        stages: vec![
                            s.preprocess,
                            s.rasterize,
                            s.shade,
                            b.blend + b.reduce,
                            b.project,
                        ],
                    })
                })?;
                Ok((forward, both))
            })?;
            print_table(
                &format!("CPU, {}", crate::count(t, "thread")),
                &forward,
                &both,
            );
            rows.push((t, forward, both));
        }
        if rows.len() > 1 {
            print_scaling(&rows);
        }
        Ok(splat_runtime::render::<M>(params, camera, opts)?)
    }
}

/// Medians over `iters` frames of `frame`, after a warm-up.
fn measure(iters: usize, mut frame: impl FnMut() -> Result<Sample>) -> Result<Sample> {
    crate::warm_up::warm_up(&mut frame)?;
    let samples = (0..iters).map(|_| frame()).collect::<Result<Vec<_>>>()?;
    let median = |mut v: Vec<Duration>| {
        v.sort();
        v[v.len() / 2]
    };
    let columns = samples[0].stages.len();
    Ok(Sample {
        wall: median(samples.iter().map(|s| s.wall).collect()),
        stages: (0..columns)
            .map(|k| median(samples.iter().map(|s| s.stages[k]).collect()))
            .collect(),
    })
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn print_table(title: &str, forward: &Sample, both: &Sample) {
    let names: Vec<&str> = FORWARD_STAGES
        .iter()
        .chain(&BACKWARD_STAGES)
        .copied()
        .collect();
    println!("\n{title}, medians in ms:");
    println!("| pass | wall | {} |", names.join(" | "));
    println!("|---|---:|{}", "---:|".repeat(names.len()));
    for (pass, s) in [("forward", forward), ("forward + backward", both)] {
        let cells: Vec<String> = (0..names.len())
            .map(|k| {
                s.stages
                    .get(k)
                    .map_or("".into(), |d| format!("{:.2}", ms(*d)))
            })
            .collect();
        println!("| {pass} | {:.2} | {} |", ms(s.wall), cells.join(" | "));
    }
}

/// Speed-up of each stage against the first thread count measured.
fn print_scaling(rows: &[(usize, Sample, Sample)]) {
    let (t0, f0, b0) = &rows[0];
    println!("\nCPU speed-up against {t0} thread(s):");
    let names: Vec<&str> = FORWARD_STAGES
        .iter()
        .chain(&BACKWARD_STAGES)
        .copied()
        .collect();
    println!(
        "| threads | forward | forward + backward | {} |",
        names.join(" | ")
    );
    println!("|---:|---:|---:|{}", "---:|".repeat(names.len()));
    let ratio = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64().max(1e-9);
    for (t, f, b) in rows {
        let stages: Vec<String> = (0..names.len())
            .map(|k| format!("{:.2}", ratio(b0.stages[k], b.stages[k])))
            .collect();
        println!(
            "| {t} | {:.2} | {:.2} | {} |",
            ratio(f0.wall, f.wall),
            ratio(b0.wall, b.wall),
            stages.join(" | ")
        );
    }
}

/// The frame's color as raw little-endian float32, row-major H x W x 3.
fn write_raw(path: &std::path::Path, frame: &Frame) -> Result<()> {
    if frame.color.channels != 3 {
        bail!(
            "{}: raw output holds 3 color channels, this method renders {}",
            path.display(),
            frame.color.channels
        );
    }
    write_atomic(path, |w| {
        frame
            .color
            .data
            .iter()
            .try_for_each(|v| w.write_all(&v.to_le_bytes()))
    })
    .with_context(|| format!("writing {}", path.display()))
}
