//! Plots as PNG: drawn by plotters into a pixel buffer (text in DejaVu Sans, embedded, so no
//! system font is needed), staged with the command's other outputs by the runtime's image
//! writer.

use anyhow::{Context, Result, anyhow};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use splat_runtime::Image;
use splat_runtime::io::Outputs;
use std::path::Path;
use std::sync::Once;

const FONT: &str = "sans-serif";

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is compiled in: failing to parse it is a build defect, not an input error.
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular())
            .unwrap_or_else(|_| panic!("the embedded DejaVu Sans font does not parse"));
    });
}

/// Draws with `draw` on a white `width` x `height` canvas and stages it in `outputs` as the
/// PNG `path`.
pub fn png(
    outputs: &mut Outputs,
    path: &Path,
    (width, height): (u32, u32),
    draw: impl FnOnce(&Area) -> Result<()>,
) -> Result<()> {
    let white = Image {
        width,
        height,
        channels: 3,
        data: vec![1.0; (width * height * 3) as usize],
    };
    png_over(outputs, path, &white, draw)
}

/// Draws with `draw` over the RGB picture `base` and stages it in `outputs` as the PNG `path`.
pub fn png_over(
    outputs: &mut Outputs,
    path: &Path,
    base: &Image,
    draw: impl FnOnce(&Area) -> Result<()>,
) -> Result<()> {
    register_font();
    let (width, height) = (base.width, base.height);
    let mut rgb: Vec<u8> = (base.data.iter())
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        draw(&root)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", path.display()))?;
    }
    let image = Image {
        data: rgb.iter().map(|b| *b as f32 / 255.0).collect(),
        ..*base
    };
    splat_runtime::io::image::stage_image(outputs, path, &image)
        .with_context(|| format!("writing {}", path.display()))
}

/// A text style for labels.
pub fn text(size: u32) -> TextStyle<'static> {
    (FONT, size).into_font().into()
}

/// A text style for `label` at `size` pixels, or smaller where that is wider than `room`
/// pixels on `area` (down to 6 pixels, below which a label is left to be cut).
pub fn text_within(area: &Area, label: &str, size: u32, room: u32) -> TextStyle<'static> {
    let fits = |style: &TextStyle| {
        (area.estimate_text_size(label, style)).is_ok_and(|(width, _)| width <= room)
    };
    (6..=size)
        .rev()
        .map(text)
        .find(fits)
        .unwrap_or_else(|| text(6))
}

/// A canvas area of [`png`].
pub type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// How a chart's y axis maps values.
#[derive(Clone, Copy)]
pub enum Scale {
    Linear,
    /// Decades: the chart holds log10 of each value, the labels show the values.
    Log,
}

impl Scale {
    /// Where value `v` sits on the axis.
    pub fn y(self, v: f64) -> f64 {
        match self {
            Scale::Linear => v,
            Scale::Log => v.max(1e-30).log10(),
        }
    }
}

/// A chart of values by training step on `area`: x from 0 to `last`, y over the range of
/// `ys` (padded by 5%) on `scale`, with a caption, a grid and labelled axes. Points drawn on
/// it go through `scale.y`.
pub fn by_step<'a, 'b>(
    area: &'a Area<'b>,
    caption: &str,
    last: usize,
    ys: impl Iterator<Item = f64>,
    scale: Scale,
) -> Result<ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>> {
    let (lo, hi) = ys
        .map(|v| scale.y(v))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
            (lo.min(y), hi.max(y))
        });
    let y = match (lo.is_finite(), hi > lo) {
        (true, true) => (lo - 0.05 * (hi - lo))..(hi + 0.05 * (hi - lo)),
        (true, false) => (lo - 1.0)..(lo + 1.0),
        (false, _) => 0.0..1.0,
    };
    let err = drawing(format!("chart \"{caption}\""));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(20))
        .margin(12)
        .margin_right(30)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..last.max(1) as f64, y)
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc("step")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| match scale {
            Scale::Linear => format!("{y:.1}"),
            Scale::Log => format!("{:.1e}", 10f64.powf(*y)),
        })
        .label_style(text(14))
        .draw()
        .map_err(&err)?;
    Ok(chart)
}

/// plotters' errors carry the backend's error type; as anyhow errors they name the plot.
pub fn drawing<E: std::error::Error + Send + Sync + 'static>(
    what: String,
) -> impl Fn(DrawingAreaErrorKind<E>) -> anyhow::Error {
    move |e| anyhow!("drawing the {what}: {e}")
}
