//! `splat view [SCENE]`: serves the scene (a PLY, a `splat fit` output folder, or the built-in
//! one) to a browser page that flies around it, each frame rendered by the method on the GPU
//! (or the CPU) as the page's camera moves (`crate::viewer`).

use crate::methods::{self, Method};
use crate::render::Render;
use crate::{Backend, pick_gpu, scene, viewer};
use anyhow::{Result, bail};
use splat_runtime::{CameraModel, RenderOptions};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ViewArgs {
    /// An INRIA PLY scene, or a `splat fit` output folder (its scene.ply) [default: the
    /// built-in scene].
    pub scene: Option<PathBuf>,
    #[arg(long)]
    pub method: String,
    /// The port on 127.0.0.1 (the next free one if taken; 0 for any).
    #[arg(long, default_value_t = 8123)]
    pub port: u16,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

pub(crate) fn view_cmd(args: &ViewArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    let cloud = match &args.scene {
        Some(dir) if dir.is_dir() => {
            let ply = dir.join("scene.ply");
            if !ply.is_file() {
                bail!(
                    "{} is a folder without scene.ply (what `splat fit` writes)",
                    dir.display()
                );
            }
            scene::read(&ply)?
        }
        Some(path) => scene::read(path)?,
        None => scene::planet(),
    };
    let gpu = pick_gpu(args.backend)?;
    let opts = RenderOptions::default();
    // The page's cameras are pinholes with a global shutter: one instance renders them all.
    let pinhole = scene::camera(64, 64, CameraModel::Pinhole);
    let instance = method.instance(cloud.sh_degree, &pinhole);
    let listener = viewer::bind(args.port)?;
    let address = listener.local_addr()?;
    println!(
        "splat view: http://{address}/ ({}, {} Gaussians; Ctrl-C ends it)",
        method.name,
        cloud.gaussians.len()
    );
    viewer::serve(&listener, &|session| {
        let cameras = || session.next_camera();
        let task = Render {
            cloud: &cloud,
            cameras: &cameras,
            opts: &opts,
            gpu: gpu.as_ref(),
            hardware: false,
        };
        let place = match &gpu {
            Some(g) => format!("GPU, {}", g.adapter),
            None => "the CPU".to_string(),
        };
        (instance.render)(&task, &mut |frame| session.send_frame(&frame, &place))?;
        Ok(())
    });
    Ok(())
}
