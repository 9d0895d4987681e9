//! Plots as PNG: drawn by plotters into a pixel buffer (text in DejaVu Sans, embedded, so no
//! system font is needed), written atomically by the runtime's image writer.

use anyhow::{Context, Result, anyhow};
use plotters::prelude::*;
use splat_runtime::Image;
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

/// Draws with `draw` on a `width` x `height` canvas and writes it to `path` as PNG.
pub fn png(
    path: &Path,
    (width, height): (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<()>,
) -> Result<()> {
    register_font();
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        draw(&root)?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", path.display()))?;
    }
    let image = Image {
        width,
        height,
        channels: 3,
        data: rgb.iter().map(|b| *b as f32 / 255.0).collect(),
    };
    splat_runtime::io::image::write_image(path, &image)
        .with_context(|| format!("writing {}", path.display()))
}

/// A text style for labels.
pub fn text(size: u32) -> TextStyle<'static> {
    (FONT, size).into_font().into()
}

/// plotters' errors carry the backend's error type; as anyhow errors they name the plot.
pub fn drawing<E: std::error::Error + Send + Sync + 'static>(
    what: &'static str,
) -> impl Fn(DrawingAreaErrorKind<E>) -> anyhow::Error {
    move |e| anyhow!("drawing the {what}: {e}")
}
