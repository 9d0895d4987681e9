//! What a scene's file format costs (`splat eval --formats`): the scene written in every format
//! splat writes and read back, each reading rendered on a dataset's views; its file's size
//! against its renders' PSNR and SSIM to the pictures, and its PSNR to the PLY's renders (what
//! the format alone changes). A table, and with `--out` `formats.csv` and `formats.png`.

use crate::commands::render;
use crate::methods::Method;
use crate::plot;
use anyhow::{Context, Result};
use plotters::prelude::*;
use splat_runtime::gpu::Gpu;
use splat_runtime::io::Outputs;
use splat_runtime::io::formats::{self, Format};
use splat_runtime::io::ply::GaussianCloud;
use splat_runtime::train::fit::composite;
use splat_runtime::train::loss;
use splat_runtime::{Camera, Image, RenderOptions, glam::Vec3};
use std::path::Path;

/// One format's file and renders, measured.
pub(crate) struct Cost {
    pub(crate) format: Format,
    pub(crate) bytes: usize,
    /// Means over the views: against the pictures.
    pub(crate) psnr: f64,
    pub(crate) ssim: f64,
    /// Against the PLY's renders (`None` for the PLY).
    pub(crate) psnr_to_ply: Option<f64>,
}

/// Where and how the views render.
pub(crate) struct Views<'a> {
    pub(crate) method: &'a Method,
    pub(crate) cameras: &'a [Camera],
    pub(crate) pictures: &'a [Image],
    pub(crate) background: Vec3,
    pub(crate) opts: &'a RenderOptions,
    pub(crate) gpu: Option<&'a Gpu>,
}

/// Every format's cost for `cloud`, the PLY first; the progress bar counts renders.
pub(crate) fn measure(
    cloud: &GaussianCloud,
    views: &Views,
    bar: &indicatif::ProgressBar,
) -> Result<Vec<Cost>> {
    let mut costs = Vec::with_capacity(Format::ALL.len());
    let mut ply_renders = vec![];
    let order = [Format::Ply]
        .into_iter()
        .chain(Format::ALL.into_iter().filter(|f| *f != Format::Ply));
    for format in order {
        let mut bytes = vec![];
        formats::write_to(format, &mut bytes, cloud)
            .with_context(|| format!("writing the scene as {}", format.extension()))?;
        let read = formats::parse(format, &bytes)
            .map_err(|why| anyhow::anyhow!("reading back its {}: {why}", format.extension()))?;
        let renders = render_all(&read, views, bar)?;
        let n = renders.len() as f64;
        let (mut psnr, mut ssim, mut to_ply) = (0.0, 0.0, 0.0);
        for (k, image) in renders.iter().enumerate() {
            psnr += loss::psnr(image, &views.pictures[k])? / n;
            ssim += loss::ssim(image, &views.pictures[k])? / n;
            if let Some(ply) = ply_renders.get(k) {
                to_ply += loss::psnr(image, ply)? / n;
            }
        }
        costs.push(Cost {
            format,
            bytes: bytes.len(),
            psnr,
            ssim,
            psnr_to_ply: (format != Format::Ply).then_some(to_ply),
        });
        if format == Format::Ply {
            ply_renders = renders;
        }
    }
    Ok(costs)
}

/// Each view of `cloud` rendered and composited on the background, as `splat fit` measures.
fn render_all(
    cloud: &GaussianCloud,
    views: &Views,
    bar: &indicatif::ProgressBar,
) -> Result<Vec<Image>> {
    let mut renders = Vec::with_capacity(views.cameras.len());
    let mut keep = |frame: splat_runtime::Frame| {
        renders.push(composite(
            frame.color,
            frame.alpha.as_ref(),
            views.background,
        ));
        bar.inc(1);
        Ok(())
    };
    let setting = (views.opts, views.gpu, false);
    render::render_views(views.method, cloud, views.cameras, setting, &mut keep)?;
    Ok(renders)
}

/// The table: a format a row, its size as a whole and a Gaussian.
pub(crate) fn print_table(costs: &[Cost], gaussians: usize) {
    println!(
        "{:<16} {:>10} {:>12} {:>10} {:>8} {:>14}",
        "format", "MB", "bytes/Gauss.", "PSNR (dB)", "SSIM", "to PLY (dB)"
    );
    for c in costs {
        let to_ply = c.psnr_to_ply.map_or("-".into(), |p| format!("{p:.2}"));
        println!(
            "{:<16} {:>10.3} {:>12.1} {:>10.2} {:>8.4} {:>14}",
            c.format.extension(),
            c.bytes as f64 / 1e6,
            c.bytes as f64 / gaussians.max(1) as f64,
            c.psnr,
            c.ssim,
            to_ply
        );
    }
}

/// `formats.csv` and `formats.png` in `dir`, staged in `outputs`.
pub(crate) fn stage_outputs(
    outputs: &mut Outputs,
    dir: &Path,
    costs: &[Cost],
    title: &str,
) -> Result<()> {
    let csv = dir.join("formats.csv");
    (outputs.stage(&csv, |w| {
        writeln!(w, "format,bytes,psnr,ssim,psnr_to_ply")?;
        for c in costs {
            let to_ply = c.psnr_to_ply.map_or(String::new(), |p| format!("{p:.4}"));
            let name = c.format.name();
            writeln!(w, "{name},{},{:.4},{:.6},{to_ply}", c.bytes, c.psnr, c.ssim)?;
        }
        Ok(())
    }))
    .with_context(|| format!("writing {}", csv.display()))?;
    draw(outputs, &dir.join("formats.png"), costs, title)
}

/// Three panels against the file's size (MB, in decades): test PSNR, test SSIM, PSNR to the
/// PLY's renders; each format a labelled point.
fn draw(outputs: &mut Outputs, path: &Path, costs: &[Cost], title: &str) -> Result<()> {
    type Measure = fn(&Cost) -> Option<f64>;
    let panels: [(&str, Measure); 3] = [
        ("test PSNR (dB)", |c| Some(c.psnr)),
        ("test SSIM", |c| Some(c.ssim)),
        ("PSNR to the PLY's renders (dB)", |c| c.psnr_to_ply),
    ];
    plot::png(outputs, path, (1500, 520), |root| {
        let (top, rest) = root.split_vertically(34);
        let err = plot::drawing(format!("{title}: sizes"));
        top.titled(title, plot::text(20)).map_err(&err)?;
        for (area, (caption, value)) in rest.split_evenly((1, 3)).iter().zip(panels) {
            let points: Vec<(f64, f64, &str)> = (costs.iter())
                .filter_map(|c| {
                    Some((
                        (c.bytes as f64 / 1e6).log10(),
                        value(c)?,
                        c.format.extension(),
                    ))
                })
                .collect();
            panel(area, caption, &points)?;
        }
        Ok(())
    })
}

fn panel(area: &plot::Area, caption: &str, points: &[(f64, f64, &str)]) -> Result<()> {
    let span = |f: fn(&(f64, f64, &str)) -> f64| {
        let (lo, hi) = (points.iter().map(f))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
        let pad = ((hi - lo) * 0.15).max(1e-3);
        (lo - pad)..(hi + pad)
    };
    let err = plot::drawing(format!("chart \"{caption}\""));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, plot::text(16))
        .margin(12)
        // Room for the rightmost point's label.
        .margin_right(110)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(span(|p| p.0), span(|p| p.1))
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc("file size (MB)")
        .x_label_formatter(&|x| {
            let mb = 10f64.powf(*x);
            format!("{mb:.*}", if mb >= 1.0 { 1 } else { 2 })
        })
        .label_style(plot::text(13))
        .draw()
        .map_err(&err)?;
    let dots = points
        .iter()
        .map(|(x, y, _)| Circle::new((*x, *y), 5, BLUE.filled()));
    chart.draw_series(dots).map_err(&err)?;
    let labels =
        (points.iter()).map(|(x, y, name)| Text::new(name.to_string(), (*x, *y), plot::text(13)));
    chart.draw_series(labels).map_err(&err)?;
    Ok(())
}
