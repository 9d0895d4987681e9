//! The `splat` command line as a library: a user crate offers its own methods with the same
//! commands (render, bench, tradeoff, fit, eval, inspect, gallery, scene, dataset) in a few
//! lines:
//!
//! ```no_run
//! use splat_cli::{Instance, Method};
//! # mod mine { pub type Method = splat_methods::gut::Method; }
//! fn main() -> std::process::ExitCode {
//!     splat_cli::run(&[Method::new(
//!         "mine",
//!         "my primitive",
//!         Instance::trainable::<mine::Method>(),
//!     )])
//! }
//! ```
//!
//! The project's own `splat` binary is this entry point with the built-in methods.

mod bench;
mod camera_path;
mod commands;
mod cost;
mod fit;
mod fit_view;
mod format_costs;
mod interrupt;
mod memory;
mod methods;
#[cfg(feature = "mpi")]
mod mpi_team;
mod new_crate;
mod orbit;
mod plot;
mod ranks;
mod render;
mod scene;
mod source;
mod tradeoff;
mod tradeoff_report;
mod video;
mod view;
mod viewer;
mod warm_up;

pub use methods::{Instance, Method};

use anyhow::{Context, Result};
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand, ValueEnum};
use splat_runtime::CameraModel;
use splat_runtime::glam::Vec3;
use splat_runtime::gpu::Gpu;
use splat_runtime::io::{Outputs, camera as camera_io, dataset, ply};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

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
    Render(render::RenderArgs),
    /// Write the built-in scene as an INRIA PLY, and its camera as JSON.
    Scene {
        #[arg(long, default_value = "planet.ply")]
        out: PathBuf,
        #[arg(long)]
        camera_out: Option<PathBuf>,
    },
    /// Write the built-in dataset (what `splat fit` trains on without a dataset) as a Blender /
    /// NeRF-synthetic folder, with as many views of any size.
    Dataset {
        #[arg(long, default_value = "planet-dataset")]
        out: PathBuf,
        #[arg(long, default_value_t = scene::DATASET.0)]
        views: usize,
        #[arg(long, default_value_t = scene::DATASET.1)]
        width: u32,
        #[arg(long, default_value_t = scene::DATASET.2)]
        height: u32,
        /// Compose the pictures' color on white (their alpha is written either way).
        #[arg(long)]
        white: bool,
    },
    /// Render the built-in scene with every method and camera model into one labelled PNG
    /// (rows: methods; columns: pinhole, fisheye, equiangular).
    Gallery {
        /// The picture (.png).
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
    /// What each accuracy knob (P_max, tile size, the transmittance stop, the alpha skip)
    /// costs in time and memory and changes in the image and the gradients, against the
    /// most accurate render: a table, CSVs and a plot.
    Tradeoff(tradeoff::TradeoffArgs),
    /// Train a Gaussian method on posed images (Blender, nerfstudio or COLMAP), on the GPU or
    /// the CPU.
    Fit(fit::FitArgs),
    /// Measure a scene on a dataset's views as `splat fit` measures its result: PSNR and SSIM
    /// per view and their mean, with the renders and a CSV in --out.
    Eval(commands::eval::EvalArgs),
    /// Look at a scene in the browser: serves a page on 127.0.0.1 that flies around it, each
    /// frame rendered here as the camera moves.
    View(commands::view::ViewArgs),
    /// Convert a scene between formats (.ply, .compressed.ply, .splat, .spz, .sog), each named by its file's extension.
    Convert(commands::convert::ConvertArgs),
    /// Render a scene along a camera path (an orbit, a dataset's views, or keyframes saved
    /// from `splat view`) into an H.264 MP4 that browsers play.
    Video(commands::video::VideoArgs),
    /// Write a crate for a new method (a 3D Gaussian whose falloff is yours to change) that
    /// builds and passes every check at once, with the whole command line.
    New {
        /// The crate's and the method's name (lowercase letters, digits, `-`, `_`).
        name: String,
        /// Where to write it (default: ./NAME); must not exist.
        #[arg(long)]
        dir: Option<PathBuf>,
        /// The splat checkout to build on (default: the one this binary was built from).
        #[arg(long)]
        splat: Option<PathBuf>,
    },
    /// Print the Rust or WGSL the #[splat_method] compiler generated for a method.
    Inspect {
        #[arg(long)]
        method: String,
        #[arg(long, value_enum, default_value_t = Lang::Rust)]
        lang: Lang,
        /// Instead, count what each kernel computes (exp, ln, pow, trig, sqrt, divisions,
        /// every operation): where a method's time goes, line by line.
        #[arg(long)]
        cost: bool,
    },
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum Model {
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
pub enum Backend {
    /// A hardware GPU if wgpu finds one, else the CPU (a software adapter such as lavapipe is
    /// slower than the CPU backend).
    Auto,
    Cpu,
    Gpu,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum Lang {
    Rust,
    Wgsl,
}

/// Runs the command line (`std::env::args`) offering `methods` (the first is the default):
/// what a `main` returns.
pub fn run(methods: &[Method]) -> ExitCode {
    quiet_device_select_layer();
    end_quietly_on_a_closed_pipe();
    match run_with_args(methods, std::env::args_os()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => match e.downcast::<clap::Error>() {
            // Usage errors, and --help and --version, as clap prints them.
            Ok(usage) => usage.exit(),
            Err(e) if e.is::<ranks::Reported>() => ExitCode::FAILURE,
            Err(e) => {
                eprintln!("error: {e:#}");
                ExitCode::FAILURE
            }
        },
    }
}

/// A reader that stops early (`splat bench | head -1`) ends the program quietly, as it ends
/// other Unix tools: Rust ignores SIGPIPE, so the next `println!` would panic instead.
fn end_quietly_on_a_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: restores the default action of one signal before any thread is started.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Runs the command line `args` (the program's name first) offering `methods`.
pub fn run_with_args<I, T>(methods: &[Method], args: I) -> Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let Some(first) = methods.first() else {
        anyhow::bail!("this command line offers no methods");
    };
    let names: Vec<clap::builder::PossibleValue> = methods
        .iter()
        .map(|m| clap::builder::PossibleValue::new(m.name).help(m.help))
        .collect();
    // The methods are known only now: every `--method` lists them and defaults to the first.
    let mut command = Cli::command();
    for sub in [
        "render", "bench", "tradeoff", "fit", "eval", "inspect", "view",
    ] {
        command = command.mut_subcommand(sub, |s| {
            s.mut_arg("method", |a| {
                a.value_parser(clap::builder::PossibleValuesParser::new(names.clone()))
                    .default_value(first.name)
                    .required(false)
            })
        });
    }
    let args: Vec<T> = args.into_iter().collect();
    if let Some(bin) = (args.first().cloned())
        .map(Into::<std::ffi::OsString>::into)
        .and_then(|a| Some(Path::new(&a).file_stem()?.to_str()?.to_string()))
        .filter(|bin| bin != "splat")
    {
        command = named(command, &bin);
    }
    let cli = Cli::from_arg_matches(&command.try_get_matches_from(args)?)?;
    dispatch(cli, methods)
}

/// `command` as the binary `bin` (a user crate's own command line; clap names it from the
/// arguments already): `splat` in its help texts (`splat fit`) as `bin`.
fn named(command: clap::Command, bin: &str) -> clap::Command {
    let rename =
        |text: &clap::builder::StyledStr| text.to_string().replace("`splat ", &format!("`{bin} "));
    let mut command = command;
    if let Some(about) = command.get_about().map(rename) {
        command = command.about(about);
    }
    if let Some(about) = command.get_long_about().map(rename) {
        command = command.long_about(about);
    }
    let args: Vec<(String, Option<String>, Option<String>)> = (command.get_arguments())
        .map(|a| {
            let id = a.get_id().to_string();
            (id, a.get_help().map(rename), a.get_long_help().map(rename))
        })
        .collect();
    for (id, help, long) in args {
        command = command.mut_arg(id, |a| {
            let a = match help {
                Some(h) => a.help(h),
                None => a,
            };
            match long {
                Some(h) => a.long_help(h),
                None => a,
            }
        });
    }
    let subs: Vec<String> = (command.get_subcommands())
        .map(|s| s.get_name().to_string())
        .collect();
    for sub in subs {
        command = command.mut_subcommand(sub, |s| named(s, bin));
    }
    command
}

fn dispatch(cli: Cli, methods: &[Method]) -> Result<()> {
    match cli.command {
        Command::Render(args) => commands::render::render_cmd(&args, methods),
        Command::Fit(args) => commands::fit::fit_cmd(&args, methods),
        Command::Eval(args) => commands::eval::eval_cmd(&args, methods),
        Command::Bench(args) => commands::bench::bench_cmd(&args, methods),
        Command::Tradeoff(args) => commands::tradeoff::tradeoff_cmd(&args, methods),
        Command::View(args) => commands::view::view_cmd(&args, methods),
        Command::Video(args) => commands::video::video_cmd(&args, methods),
        Command::Convert(args) => commands::convert::convert_cmd(&args),
        Command::Scene { out, camera_out } => {
            let ply = out.extension().and_then(|e| e.to_str());
            if !ply.is_some_and(|e| e.eq_ignore_ascii_case("ply")) {
                anyhow::bail!(
                    "--out `{}`: the scene is written as an INRIA PLY, name it .ply",
                    out.display()
                );
            }
            // The scene and its camera appear together or not at all.
            let mut outputs = Outputs::default();
            let cloud = scene::planet();
            (outputs.stage(&out, |w| ply::write_to(w, &cloud)))
                .with_context(|| format!("writing {}", out.display()))?;
            if let Some(c) = &camera_out {
                let camera = scene::camera(800, 600, CameraModel::Pinhole);
                (outputs.stage(c, |w| camera_io::write_to(w, &camera)))
                    .with_context(|| format!("writing {}", c.display()))?;
            }
            outputs.commit()?;
            crate::wrote(&out);
            camera_out.iter().for_each(|c| crate::wrote(c));
            Ok(())
        }
        Command::Dataset {
            out,
            views,
            width,
            height,
            white,
        } => {
            if views < 2 {
                anyhow::bail!(
                    "--views must be at least 2 (every 8th view, from the first, is a test view)"
                );
            }
            let window = splat_runtime::train::loss::WINDOW as u32;
            if width.min(height) < window {
                anyhow::bail!(
                    "--width and --height must be at least {window}: `splat fit` compares views by SSIM over {window}x{window} windows"
                );
            }
            if let Some(room) = memory::available() {
                memory::check_rendered_views(views, width, height, room)?;
            }
            let background = if white { Vec3::ONE } else { Vec3::ZERO };
            let data = scene::dataset(views, width, height, background)?;
            dataset::write_blender(&out, &data)?;
            println!(
                "{} training and {} of {width}x{height}",
                data.train.len(),
                count(data.test.len(), "test view")
            );
            crate::wrote(&out);
            Ok(())
        }
        Command::Gallery { out, width, height } => {
            commands::render::gallery(&out, width, height, methods)
        }
        Command::New { name, dir, splat } => {
            let dir = new_crate::new_crate(&name, dir.as_deref(), splat.as_deref())?;
            println!(
                "wrote {0}: `cd {0} && cargo test --offline` runs every check, \
                 `cargo run --release -- fit` trains it",
                dir.display()
            );
            Ok(())
        }
        Command::Inspect { method, lang, cost } => {
            let source = methods::find(methods, &method)?.full().source;
            let text = match (cost, lang) {
                (true, _) => &cost::table(&cost::costs(source.wgsl)?),
                (false, Lang::Wgsl) => source.wgsl,
                (false, Lang::Rust) => source.rust,
            };
            // A reader that stops early (`| head`) is not an error.
            match std::io::Write::write_all(&mut std::io::stdout(), text.as_bytes()) {
                Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
                    Err(anyhow::Error::new(e).context("writing the source to standard output"))
                }
                _ => Ok(()),
            }
        }
    }
}

/// Refuses, before any work, an output folder that is a file or would be made inside one.
pub(crate) fn check_out_folder(dir: &std::path::Path) -> Result<()> {
    let Some(existing) = dir.ancestors().find(|a| a.exists()) else {
        return Ok(());
    };
    if !existing.is_dir() {
        anyhow::bail!(
            "--out {}: {} is a file, and the outputs go into a folder",
            dir.display(),
            match existing == dir {
                true => "it".to_string(),
                false => existing.display().to_string(),
            }
        );
    }
    Ok(())
}

/// Refuses `path`, given as `flag`, for a file a command writes at its end, before the work:
/// when it names a folder (one that exists, or a trailing `/`) or lies under a file.
pub(crate) fn check_out_file(flag: &str, path: &std::path::Path) -> Result<()> {
    let shown = path.display();
    let trailing = path
        .as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator);
    if path.is_dir() || trailing {
        anyhow::bail!("{flag} {shown}: it names a folder, and the output is a file");
    }
    let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
    if let Some(file) =
        folder.and_then(|f| f.ancestors().find(|a| a.exists()).filter(|a| !a.is_dir()))
    {
        anyhow::bail!("{flag} {shown}: {} is a file, not a folder", file.display());
    }
    Ok(())
}

/// `n` of `noun`, in the plural unless one: "1 test view", "3 test views".
pub(crate) fn count(n: usize, noun: &str) -> String {
    match n {
        1 => format!("1 {noun}"),
        n => format!("{n} {noun}s"),
    }
}

/// The name of the `k`th render of a run's views in its output folder.
pub(crate) fn render_name(k: usize) -> String {
    format!("{k:03}.png")
}

/// Removes from `dir` the renders numbered `count` and on that an earlier run with more views
/// left: beside this run's they would pass for its own.
pub(crate) fn remove_stale_renders(dir: &std::path::Path, count: usize) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(k) = (name.to_str())
            .and_then(|n| n.strip_suffix(".png"))
            .and_then(|n| n.parse::<usize>().ok())
        else {
            continue;
        };
        // Only the names renders take ("+7.png" and "7.png" parse too).
        if k >= count && render_name(k) == name.to_string_lossy() {
            let path = entry.path();
            std::fs::remove_file(&path)
                .with_context(|| format!("removing an earlier run's {}", path.display()))?;
            removed += 1;
        }
    }
    if removed > 0 {
        println!(
            "removed {removed} renders of an earlier run's views from {} (this run has {count})",
            dir.display()
        );
    }
    Ok(())
}

/// Refuses to write the `count` renders in `dir` ([`render_name`]) over any of `pictures` (a
/// dataset's own, when `--out` points into the dataset): they are the truth the renders are
/// measured against.
pub(crate) fn check_renders_spare<'a>(
    dir: &std::path::Path,
    count: usize,
    pictures: impl IntoIterator<Item = &'a std::path::Path>,
) -> Result<()> {
    // Where the folder does not exist yet, no render can land on a picture.
    if !dir.is_dir() {
        return Ok(());
    }
    let truth: std::collections::HashSet<_> = (pictures.into_iter())
        .filter_map(|p| p.canonicalize().ok())
        .collect();
    for k in 0..count {
        let render = dir.join(render_name(k));
        if let Some(picture) = render.canonicalize().ok().filter(|r| truth.contains(r)) {
            anyhow::bail!(
                "--out: {} would replace the dataset's picture {}: choose a folder outside the dataset",
                render.display(),
                picture.display()
            );
        }
    }
    Ok(())
}

/// Says where an output went, as a full path (the default names land where `splat` runs).
pub(crate) fn wrote(path: &std::path::Path) {
    let full = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    println!("wrote {}", full.display());
}

/// Mesa's Vulkan device-selection layer looks for a Wayland display to pick the GPU driving
/// it, and without `XDG_RUNTIME_DIR` libwayland prints an error line on stderr. wgpu picks the
/// adapter itself, so the layer has nothing to do here: it is switched off (its documented
/// `NODEVICE_SELECT`) unless the user set either variable.
fn quiet_device_select_layer() {
    let set = |k| std::env::var_os(k).is_some();
    if !set("XDG_RUNTIME_DIR") && !set("NODEVICE_SELECT") {
        // SAFETY: called first thing in `run`, before this program starts any thread.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

/// The GPU `backend` asks for: none for the CPU; for `auto`, a hardware adapter if there is
/// one (and a line saying why not when there is none).
pub(crate) fn pick_gpu(backend: Backend) -> Result<Option<Gpu>> {
    pick_gpu_of(backend, None)
}

/// [`pick_gpu`], taking the machine's `nth` adapter (`None`: wgpu's choice).
pub(crate) fn pick_gpu_of(backend: Backend, nth: Option<usize>) -> Result<Option<Gpu>> {
    let new = || match nth {
        Some(k) => Gpu::nth(k),
        None => Gpu::new(),
    };
    Ok(match backend {
        Backend::Cpu => None,
        Backend::Gpu => Some(new()?),
        Backend::Auto => match new() {
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
