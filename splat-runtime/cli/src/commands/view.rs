//! `splat view [PATH]`: serves a scene (a PLY, a `splat fit` output folder, the built-in one,
//! or a dataset's views with `--scene`) to a browser page that flies around it, each frame
//! rendered by the method on the GPU (or the CPU) as the page's camera moves (`crate::viewer`).

use crate::methods::{self, Method};
use crate::view::{Downscale, Split};
use crate::{Backend, pick_gpu, scene, viewer};
use anyhow::{Result, bail};
use splat_runtime::glam::Vec3;
use splat_runtime::io::dataset;
use splat_runtime::io::ply::GaussianCloud;
use splat_runtime::precision::Precision;
use std::net::IpAddr;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct ViewArgs {
    /// An INRIA PLY scene or a `splat fit` output folder (its scene.ply); with --scene, a
    /// dataset (Blender, nerfstudio or COLMAP) whose views the page can snap to, each beside
    /// its picture [default: the built-in scene].
    pub path: Option<PathBuf>,
    /// The scene to show on the dataset PATH's views.
    #[arg(long, requires = "path")]
    pub scene: Option<PathBuf>,
    #[arg(long)]
    pub method: String,
    /// With a dataset: which of its views the page offers (the splits `splat fit` uses).
    #[arg(long, value_enum, default_value_t = Split::Test, requires = "scene")]
    pub split: Split,
    /// With a dataset: compare on white instead of black (as `splat fit --white`).
    #[arg(long, requires = "scene")]
    pub white: bool,
    #[command(flatten)]
    pub downscale: Downscale,
    /// The address to listen on. Anything but the loopback opens the scene to the network:
    /// the page then asks for a random token, printed in its URL.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: IpAddr,
    /// The port (the next free one if taken; 0 for any).
    #[arg(long, default_value_t = 8123)]
    pub port: u16,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

pub(crate) fn view_cmd(args: &ViewArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    let (cloud, views, source) = match (&args.path, &args.scene) {
        (Some(dataset), Some(ply)) => {
            let shots = args.split.of(dataset::read_shots(dataset)?);
            let shots = dataset::downscaled(shots, args.downscale.factor)?;
            if shots.is_empty() {
                bail!("{}: no {} views", dataset.display(), args.split.name());
            }
            let source = format!(
                "{}, {} {} views of {}",
                ply.display(),
                shots.len(),
                args.split.name(),
                dataset.display()
            );
            (scene::read(ply)?, shots, source)
        }
        (Some(path), None) => (read_scene(path)?, vec![], path.display().to_string()),
        (None, _) => (scene::planet(), vec![], "the built-in scene".to_string()),
    };
    let gpu = pick_gpu(args.backend)?;
    let background = if args.white { Vec3::ONE } else { Vec3::ZERO };
    let settings = viewer::Settings::new(method.name, cloud.sh_degree);
    let station = viewer::Station::new(methods, &cloud, gpu.as_ref(), settings, args.white);
    let intro = intro(methods, &cloud, &views);
    let scene = viewer::Scene {
        station,
        views,
        background,
        intro,
    };
    let token = match args.host.is_loopback() {
        true => None,
        false => Some(viewer::new_token()?),
    };
    let listener = viewer::bind(args.host, args.port)?;
    let address = listener.local_addr()?;
    let url = match &token {
        Some(t) => format!("http://{address}/?token={t}"),
        None => format!("http://{address}/"),
    };
    println!(
        "splat view: {url} ({}, {} Gaussians from {source}; Ctrl-C ends it)",
        method.name,
        cloud.gaussians.len()
    );
    if token.is_some() {
        eprintln!(
            "listening on {}: anyone who can reach it and has the token sees the scene",
            args.host
        );
    }
    viewer::serve(&listener, &scene, token.as_deref())
}

/// A PLY, or the scene.ply of a `splat fit` output folder.
fn read_scene(path: &Path) -> Result<GaussianCloud> {
    if path.is_dir() {
        let ply = path.join("scene.ply");
        if !ply.is_file() {
            bail!(
                "{} is a folder without scene.ply (what `splat fit` writes); for a dataset, \
                 give the scene with --scene",
                path.display()
            );
        }
        return scene::read(&ply);
    }
    scene::read(path)
}

/// What a page is told on connecting: the scene, the views it can snap to, the choices of
/// each knob.
fn intro(methods: &[Method], cloud: &GaussianCloud, views: &[dataset::Shot]) -> serde_json::Value {
    let names: Vec<String> = (views.iter().enumerate())
        .map(|(k, s)| match s.path.file_name() {
            Some(n) => format!("{k}: {}", n.to_string_lossy()),
            None => k.to_string(),
        })
        .collect();
    serde_json::json!({
        "primitives": cloud.gaussians.len(),
        "sh_degree": cloud.sh_degree,
        "views": names,
        "orbit": viewer::Scene::orbit(views, cloud.gaussians.iter().map(|g| g.mean)),
        "methods": methods.iter().map(|m| m.name).collect::<Vec<_>>(),
        "precisions": Precision::ALL.iter().map(|p| p.name()).collect::<Vec<_>>(),
    })
}
