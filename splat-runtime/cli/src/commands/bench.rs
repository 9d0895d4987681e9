//! `splat bench`: checks the flags, finds the method, reads the scene and runs its
//! [`Bench`] job.

use crate::bench::{Bench, BenchArgs};
use crate::methods::{self, Method};
use anyhow::{Result, bail};

/// The most threads a pool is timed with (a thread costs its stack and the kernel's bookkeeping,
/// and past the cores only adds switching).
const MAX_THREADS: usize = 1024;

pub fn bench_cmd(args: &BenchArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    if args.iters == 0 {
        bail!("--iters must be at least 1");
    }
    if let Some(&t) = args.threads.iter().find(|&&t| t == 0) {
        bail!("--threads {t}: a thread count must be at least 1");
    }
    if let Some(&t) = args.threads.iter().find(|&&t| t > MAX_THREADS) {
        bail!("--threads {t}: at most {MAX_THREADS} threads");
    }
    if let Some(raw) = &args.raw_out {
        crate::check_out_file("--raw-out", raw)?;
    }
    let (cloud, camera) = crate::scene::given_or_built_in(
        args.scene.as_deref(),
        &args.camera,
        (args.width, args.height),
    )?;
    methods::check_camera(method, methods, &camera)?;
    let gpu = crate::pick_gpu(args.backend)?.map(|g| g.with_shader_checks(args.shader_checks));
    if args.shader_checks && gpu.is_none() {
        bail!("--shader-checks is for the GPU's shaders; this run is on the CPU");
    }
    if let Some(gpu) = gpu.as_ref().filter(|_| !args.threads.is_empty()) {
        bail!(
            "--threads is for the CPU's thread pools; this run is on the GPU ({})",
            gpu.adapter
        );
    }
    let (tiles, backend) = match gpu {
        Some(_) => (&splat_runtime::gpu::TILE_SIZES[..], "GPU"),
        None => (&splat_runtime::frame::TILE_SIZES[..], "CPU"),
    };
    if !tiles.contains(&args.tile) {
        bail!(
            "--tile {}: the {backend} backend takes tile sizes {tiles:?}",
            args.tile
        );
    }
    let task = Bench {
        args,
        method: method.name,
        cloud: &cloud,
        camera: &camera,
        gpu: gpu.as_ref(),
    };
    (method.instance(cloud.sh_degree, &camera).bench)(&task)
}
