//! `splat tradeoff`: checks the flags, finds the method, reads the scene, runs the sweep
//! through the method's [`Tradeoff`] jobs and writes the report.

use crate::methods::{self, Method};
use crate::tradeoff::{Forward, Outcome, Tradeoff, TradeoffArgs, reference_options, sweep};
use anyhow::{Context, Result, bail};
use splat_runtime::RenderOptions;
use splat_runtime::io::ply;
use splat_runtime::precision::Precision;

use crate::tradeoff_report::{Row, compare, print_table, write_outputs};

pub fn tradeoff_cmd(args: &TradeoffArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    if args.iters == 0 {
        bail!("--iters must be at least 1");
    }
    crate::check_out_folder(&args.out)?;
    // The evaluation-model rows compare every method's render of the same Gaussians with the
    // exact method's most accurate one (or this method's, where none is marked exact).
    let exact = methods.iter().find(|m| m.exact);
    let (cloud, camera) = crate::scene::given_or_built_in(
        args.scene.as_deref(),
        &args.camera,
        (args.width, args.height),
    )?;
    methods::check_camera(method, methods, &camera)?;
    let gpu = crate::pick_gpu(args.backend)?;
    let (w, h) = (camera.size.x as usize, camera.size.y as usize);
    let backend = match &gpu {
        Some(gpu) => format!("GPU, {}", gpu.adapter),
        None => format!(
            "CPU, {}",
            crate::count(
                std::thread::available_parallelism().map_or(1, |n| n.get()),
                "thread"
            )
        ),
    };
    println!(
        "{}: {} primitives (SH degree {}), {w}x{h} {} camera, {backend}, {}",
        method.name,
        cloud.gaussians.len(),
        cloud.sh_degree,
        camera.model,
        match args.iters {
            1 => "one frame".to_string(),
            n => format!("median of {n} frames"),
        }
    );
    println!("reference: the f32 render with no P_max, t_min 0 and no extra alpha skip");
    let settings = match &gpu {
        Some(gpu) => {
            let blendable = Precision::ALL.into_iter();
            let hardware: Vec<Precision> = blendable
                .filter(|p| splat_runtime::gpu::raster::supports(gpu, *p))
                .collect();
            sweep(&splat_runtime::gpu::TILE_SIZES, &hardware)
        }
        None => sweep(&splat_runtime::frame::TILE_SIZES, &[]),
    };
    // The other methods the camera allows, for the evaluation-model knob.
    let models: Vec<&Method> = methods
        .iter()
        .filter(|m| methods::check_camera(m, methods, &camera).is_ok())
        .collect();
    let runs = 1 + settings.len() + cloud.sh_degree as usize + models.len() + 1;
    let bar = indicatif::ProgressBar::new(runs as u64);
    // On the GPU every setting is timed beside the method's default frame on this scene.
    let pace_task = Tradeoff {
        cloud: &cloud,
        camera: &camera,
        gpu: gpu.as_ref(),
        iters: args.iters,
        options: vec![],
        bar: &bar,
        pace: None,
    };
    let pace = match &gpu {
        Some(_) => Some((method.instance(cloud.sh_degree, &camera).tradeoff_pace)(
            &pace_task,
        )?),
        None => None,
    };
    let task =
        |method: &Method, cloud: &ply::GaussianCloud, options: Vec<(RenderOptions, Forward)>| {
            let task = Tradeoff {
                cloud,
                camera: &camera,
                gpu: gpu.as_ref(),
                iters: args.iters,
                options,
                bar: &bar,
                pace: pace.as_deref(),
            };
            (method.instance(cloud.sh_degree, &camera).tradeoff)(&task)
        };

    let tiles = |opts| vec![(opts, Forward::Tiles)];
    let mut options = tiles(reference_options());
    options.extend(settings.iter().map(|s| (s.opts, s.path)));
    let mut outcomes = task(method, &cloud, options)?.into_iter();
    let reference = outcomes.next().context("the reference frame")?;
    let mut rows: Vec<Row> = settings
        .iter()
        .zip(outcomes)
        .map(|(s, o)| compare(s.knob, s.value.clone(), &o, &reference))
        .collect();
    // SH degree: the scene's colors truncated to each lower degree, default options.
    for degree in (0..cloud.sh_degree).rev() {
        let lower = truncated(&cloud, degree);
        let o = one(task(method, &lower, tiles(RenderOptions::default()))?)?;
        rows.push(compare("sh_degree", degree.to_string(), &o, &reference));
    }
    // Evaluation model: every method on the same Gaussians, default options.
    let exact_reference = match exact {
        Some(e) => one(task(e, &cloud, tiles(reference_options()))?)?,
        None => reference,
    };
    for m in models {
        let o = one(task(m, &cloud, tiles(RenderOptions::default()))?)?;
        rows.push(compare("model", m.name.to_string(), &o, &exact_reference));
    }
    bar.finish_and_clear();
    if pace.is_none() {
        // The CPU's clock holds: each row against the default row, timed apart.
        let default = (rows.first()).map(|r| (r.forward_ms, r.backward_ms));
        if let Some((forward, backward)) = default {
            for r in &mut rows {
                r.forward_x = Some(r.forward_ms / forward);
                r.backward_x = r.backward_ms.zip(backward).map(|(b, d)| b / d);
            }
        }
    }
    print_table(&rows, pace.is_some());
    if let Some(e) = exact {
        println!("(model rows against {}'s most accurate render)", e.name);
    }
    write_outputs(&args.out, &rows, method.name)
}

/// The single outcome of a one-setting task.
fn one(outcomes: Vec<Outcome>) -> Result<Outcome> {
    outcomes.into_iter().next().context("no frame measured")
}

/// `cloud` with its colors cut to SH degree `degree`.
fn truncated(cloud: &ply::GaussianCloud, degree: u32) -> ply::GaussianCloud {
    let kept = ply::sh_coefficients(degree);
    let mut lower = ply::GaussianCloud {
        sh_degree: degree,
        ..cloud.clone()
    };
    for g in &mut lower.gaussians {
        g.sh[kept..].fill(Default::default());
    }
    lower
}
