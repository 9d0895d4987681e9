//! `splat video [PATH] --path orbit|dataset|KEYS.json --out X.mp4`: a scene rendered along a
//! camera path (`crate::camera_path`) by the method, on the GPU or the CPU, into an H.264 MP4
//! that browsers play (`crate::video`), with a progress bar.

use crate::camera_path::{self, Route};
use crate::commands::render::render_views;
use crate::methods::{self, Method};
use crate::orbit::Orbit;
use crate::source::{Source, SourceArgs};
use crate::video::Video;
use crate::{Backend, pick_gpu};
use anyhow::{Result, bail};
use splat_runtime::RenderOptions;
use splat_runtime::io::Outputs;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct VideoArgs {
    #[command(flatten)]
    pub source: SourceArgs,
    #[arg(long)]
    pub method: String,
    /// The camera's way: `orbit` (once around the scene), `dataset` (the views of the dataset
    /// PATH, in the order of their pictures' names; needs --scene) or a keyframes file saved
    /// by `splat view`'s page (`{"keyframes": [camera, ...]}`, passed through smoothly).
    #[arg(long = "path", default_value = "orbit")]
    pub route: Route,
    /// How many frames (orbit and keyframes; a dataset has one per view).
    #[arg(long, default_value_t = 120, value_parser = clap::value_parser!(u32).range(2..=100_000))]
    pub frames: u32,
    #[arg(long, default_value_t = 30)]
    pub fps: u32,
    /// Frame width (even) [default: 1280; a dataset's views' own].
    #[arg(long)]
    pub width: Option<u32>,
    /// Frame height (even) [default: 720; a dataset's views' own].
    #[arg(long)]
    pub height: Option<u32>,
    /// The orbit's vertical field of view, degrees.
    #[arg(long, default_value_t = 50.0)]
    pub fov: f32,
    /// How far above its target the orbit goes round, degrees.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub elevation: f32,
    /// The video (.mp4).
    #[arg(long, default_value = "video.mp4")]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

pub(crate) fn video_cmd(args: &VideoArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    let mp4 = args.out.extension().and_then(|e| e.to_str());
    if !mp4.is_some_and(|e| e.eq_ignore_ascii_case("mp4")) {
        bail!("--out {}: a video is written as .mp4", args.out.display());
    }
    crate::check_out_file("--out", &args.out)?;
    if !(1.0..=170.0).contains(&args.fov) {
        bail!("--fov {}: give 1 to 170 degrees", args.fov);
    }
    let Source { cloud, views, name } = args.source.read(None)?;
    let frames = args.frames as usize;
    let given =
        |w: Option<u32>, h: Option<u32>, (dw, dh): (u32, u32)| (w.unwrap_or(dw), h.unwrap_or(dh));
    let cameras = match &args.route {
        Route::Orbit => {
            let views: Vec<_> = views.iter().map(|s| s.camera).collect();
            let means: Vec<_> = cloud.gaussians.iter().map(|g| g.mean).collect();
            let orbit = Orbit::of(&views, &means);
            let size = given(args.width, args.height, (1280, 720));
            camera_path::around(&orbit, frames, size, args.fov, args.elevation)
        }
        Route::Dataset => {
            let Some(first) = views.first() else {
                bail!(
                    "--path dataset flies through a dataset's views: give the dataset as PATH and the scene with --scene"
                );
            };
            let own = (first.camera.size.x as u32, first.camera.size.y as u32);
            // H.264 wants even sides: a view's odd side loses its last pixel.
            let size = given(args.width, args.height, (own.0 & !1, own.1 & !1));
            let cameras: Vec<_> = views.iter().map(|s| s.camera).collect();
            camera_path::resized(&cameras, size)
        }
        Route::Keyframes(path) => {
            let keys = camera_path::read_keyframes(path)?;
            let own = (keys[0].size.x as u32, keys[0].size.y as u32);
            let size = given(args.width, args.height, (own.0 & !1, own.1 & !1));
            camera_path::through(&keys, frames, size)
        }
    };
    for camera in &cameras {
        methods::check_camera(method, methods, camera)?;
    }
    let (width, height) = (cameras[0].size.x as u32, cameras[0].size.y as u32);
    let mut video = Video::new(width, height, args.fps)?;
    let gpu = pick_gpu(args.backend)?;
    let bar = indicatif::ProgressBar::new(cameras.len() as u64).with_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames, {eta} left")?,
    );
    let opts = RenderOptions::default();
    let place = render_views(
        method,
        &cloud,
        &cameras,
        (&opts, gpu.as_ref(), false),
        &mut |frame| {
            video.push(&frame.color)?;
            bar.inc(1);
            Ok(())
        },
    )?;
    bar.finish_and_clear();
    let count = video.frames();
    let bytes = video.finish()?;
    let mut outputs = Outputs::default();
    outputs.stage(&args.out, |w| w.write_all(&bytes))?;
    outputs.commit()?;
    println!(
        "{} on {place}: {count} frames of {width}x{height} at {} fps ({:.1} s, {:.1} MB) from {name}",
        method.name,
        args.fps,
        count as f64 / args.fps as f64,
        bytes.len() as f64 / 1e6,
    );
    crate::wrote(&args.out);
    Ok(())
}
