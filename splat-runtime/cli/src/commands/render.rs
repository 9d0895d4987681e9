//! `splat render` and `splat gallery`: find the method, read the scene and the camera, render
//! through the method's instance (`crate::render::Render`), write the outputs.

use crate::methods::{self, Method};
use crate::render::{Frames, Render, RenderArgs};
use crate::{Backend, Model, pick_gpu, scene};
use anyhow::{Result, bail};
use plotters::prelude::RGBColor;
use splat_runtime::glam::Vec3;
use splat_runtime::gpu::Gpu;
use splat_runtime::io::ply::GaussianCloud;
use splat_runtime::io::{Outputs, image as image_io};
use splat_runtime::{Camera, CameraModel, Frame, Image, RenderOptions};
use std::time::Instant;

/// Renders `cloud` with `method` from `camera` on `gpu`, or on the CPU without one; returns
/// the frame and where it ran.
pub(crate) fn render_method(
    method: &Method,
    cloud: &GaussianCloud,
    camera: &Camera,
    opts: &RenderOptions,
    gpu: Option<&Gpu>,
    hardware: bool,
) -> Result<(Frame, String)> {
    let mut frame = None;
    let cameras = std::slice::from_ref(camera);
    let place = render_views(method, cloud, cameras, (opts, gpu, hardware), &mut |f| {
        frame = Some(f);
        Ok(())
    })?;
    Ok((frame.expect("a frame for the camera"), place))
}

/// [`render_method`] from each of `cameras` in turn, each frame handed to `each` as it is
/// rendered: on the GPU, one renderer and one upload of the scene serve every run of cameras
/// that one instance of the method renders (all of them but where rolling shutters come and
/// go). Returns where they ran.
pub(crate) fn render_views(
    method: &Method,
    cloud: &GaussianCloud,
    cameras: &[Camera],
    (opts, gpu, hardware): (&RenderOptions, Option<&Gpu>, bool),
    each: Frames,
) -> Result<String> {
    let instance = |c: &Camera| method.instance(cloud.sh_degree, c);
    let mut place = String::new();
    for run in cameras.chunk_by(|a, b| std::ptr::eq(instance(a), instance(b))) {
        let next = std::cell::Cell::new(0);
        let cameras = || {
            next.set(next.get() + 1);
            run.get(next.get() - 1).copied()
        };
        let task = Render {
            cloud,
            cameras: &cameras,
            opts,
            gpu,
            hardware,
        };
        place = (instance(&run[0]).render)(&task, &mut *each)?;
    }
    Ok(place)
}

/// The gallery's label margins, pixels: the methods' names on the left, the camera models'
/// on top.
const ROW_LABELS: u32 = 96;
const COLUMN_LABELS: u32 = 26;

/// Every method on every camera model, panels in a labelled grid (PNG); a method that does
/// not support a model gets a dark panel saying so.
pub(crate) fn gallery(
    out: &std::path::Path,
    width: u32,
    height: u32,
    methods: &[Method],
) -> Result<()> {
    let side = 1..=2048;
    if !side.contains(&width) || !side.contains(&height) {
        bail!("panel size {width}x{height} is out of range (1..=2048 per side)");
    }
    let png = out.extension().and_then(|e| e.to_str());
    if !png.is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        bail!(
            "gallery `{}`: the gallery is a labelled picture, write it as .png",
            out.display()
        );
    }
    crate::check_out_file("--out", out)?;
    let cloud = scene::planet();
    let (cols, rows) = (CameraModel::ALL.len() as u32, methods.len() as u32);
    let (grid_width, grid_height) = (ROW_LABELS + width * cols, COLUMN_LABELS + height * rows);
    let mut grid = Image {
        width: grid_width,
        height: grid_height,
        channels: 3,
        data: vec![1.0; (grid_width * grid_height * 3) as usize],
    };
    let mut unsupported = vec![];
    let opts = RenderOptions::default();
    for (r, method) in methods.iter().enumerate() {
        for (c, model) in CameraModel::ALL.into_iter().enumerate() {
            let camera = scene::camera(width, height, model);
            let panel = match render_method(method, &cloud, &camera, &opts, None, false) {
                Ok((frame, _)) => {
                    println!(
                        "{} / {model}: {} visible, {} intersections, shade {:.1} ms",
                        method.name,
                        frame.stats.visible,
                        frame.stats.intersections,
                        frame.stats.shade.as_secs_f64() * 1e3
                    );
                    frame.color.data
                }
                // A pinhole-only method on another model: a dark panel. Any other error is one.
                Err(e)
                    if matches!(
                        e.downcast_ref::<splat_runtime::RenderError>(),
                        Some(splat_runtime::RenderError::CameraModel { .. })
                    ) =>
                {
                    println!("{} / {model}: {e}", method.name);
                    unsupported.push((r as u32, c as u32));
                    vec![0.08; (width * height * 3) as usize]
                }
                Err(e) => return Err(e),
            };
            let (x0, y0) = (
                ROW_LABELS + c as u32 * width,
                COLUMN_LABELS + r as u32 * height,
            );
            let row = (width * 3) as usize;
            for y in 0..height {
                let src = (y * width * 3) as usize;
                let dst = (((y0 + y) * grid.width + x0) * 3) as usize;
                grid.data[dst..dst + row].copy_from_slice(&panel[src..src + row]);
            }
        }
    }
    let mut outputs = Outputs::default();
    crate::plot::png_over(&mut outputs, out, &grid, |area| {
        let err = crate::plot::drawing("gallery's labels".to_string());
        // Labels shrink to fit small panels rather than run into the next one.
        let within = |label: &str, size: u32, room: u32| {
            crate::plot::text_within(area, label, size, room.saturating_sub(8))
        };
        for (c, model) in CameraModel::ALL.into_iter().enumerate() {
            let at = ((ROW_LABELS + c as u32 * width + 6) as i32, 5);
            let label = within(model.name(), 15, width);
            area.draw_text(model.name(), &label, at).map_err(&err)?;
        }
        for (r, method) in methods.iter().enumerate() {
            let at = (
                6,
                (COLUMN_LABELS + r as u32 * height + height / 2 - 8) as i32,
            );
            let label = within(method.name, 15, ROW_LABELS);
            area.draw_text(method.name, &label, at).map_err(&err)?;
        }
        let unsupported_note = "pinhole camera only";
        let note = within(unsupported_note, 13, width).color(&RGBColor(200, 200, 200));
        for (r, c) in &unsupported {
            let at = (
                (ROW_LABELS + c * width + 6) as i32,
                (COLUMN_LABELS + r * height + height / 2 - 8) as i32,
            );
            area.draw_text(unsupported_note, &note, at).map_err(&err)?;
        }
        Ok(())
    })?;
    outputs.commit()?;
    crate::wrote(out);
    Ok(())
}

pub(crate) fn render_cmd(args: &RenderArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
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
    crate::check_out_file("--out", &args.out)?;
    let t0 = Instant::now();
    let (cloud, source) = match &args.scene {
        Some(path) => (scene::read(path)?, path.display().to_string()),
        None => (scene::planet(), "built-in planet".to_string()),
    };
    method.note_antialiasing(&cloud);
    let (camera, shot) = match args.camera.read()? {
        Some(given) => (given.camera, given.shot),
        None => {
            let model = args.camera_model.unwrap_or(Model::Pinhole);
            let camera = scene::built_in_camera(args.width, args.height, model.into())?;
            (camera, None)
        }
    };
    methods::check_camera(method, methods, &camera)?;
    if let Some(room) = crate::memory::available() {
        crate::memory::check_render(camera.size.x as u32, camera.size.y as u32, room)?;
    }
    // The view's picture, on black as the renderer composites: read before anything is
    // written, so a broken one fails the command with nothing written.
    let picture = match &shot {
        Some(shot) => Some((shot.load(Vec3::ZERO)?.into_image(), shot.path.display())),
        None => None,
    };
    let load = t0.elapsed();
    let opts = RenderOptions {
        tile_size: args.tile,
        p_max: args.p_max,
        alpha: args.alpha,
        depth: args.depth,
        precision: args.precision,
        shade_precision: args.shade_precision,
        ..Default::default()
    };
    // The hardware rasterizer needs a GPU: `auto` takes a software one too.
    let backend = match (args.hardware, args.backend) {
        (true, Backend::Auto) => Backend::Gpu,
        (_, backend) => backend,
    };
    let gpu = pick_gpu(backend)?;
    let (frame, backend) =
        render_method(method, &cloud, &camera, &opts, gpu.as_ref(), args.hardware)?;
    let written = image_io::write_frame(&args.out, &frame)?;
    if args.explain {
        let effects = (method.instance(cloud.sh_degree, &camera).effects)(&camera, &opts);
        println!("{effects}");
    }
    let s = &frame.stats;
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let raster = match args.hardware {
        true => format!("{} render targets", args.precision.name()),
        false => format!("tile {}", args.tile),
    };
    println!(
        "{} on {backend}: {} primitives (SH degree {}) from {source}, {}x{} {} camera, {raster}",
        method.name,
        s.primitives,
        cloud.sh_degree,
        frame.color.width,
        frame.color.height,
        camera.model,
    );
    let pairs = if gpu.is_none() {
        s.pairs.to_string()
    } else {
        "not counted on the GPU".to_string()
    };
    println!(
        "visible {}, intersections {}, pairs evaluated {pairs}",
        s.visible, s.intersections
    );
    let stages = s.preprocess + s.rasterize + s.shade;
    if gpu.is_some() && stages.is_zero() {
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
    if let Some((picture, path)) = &picture {
        let psnr = splat_runtime::train::loss::psnr(&frame.color, picture)?;
        println!("PSNR {psnr:.2} dB against the view's picture {path} (on black)");
    }
    for p in written {
        crate::wrote(&p);
    }
    Ok(())
}
