//! What a tab is shown of a frame: its color, alpha or depth; beside a dataset view's picture
//! or as the difference from it; as a JPEG.

use super::station::Output;
use anyhow::{Result, bail};
use plotters::style::colors::colormaps::{ColorMap, ViridisRGB};
use serde::Deserialize;
use splat_runtime::{Frame, Image};
use std::borrow::Cow;

/// How a dataset view's render is shown beside its picture.
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compare {
    /// The render alone.
    #[default]
    Render,
    /// The render on the left, the picture on the right.
    Side,
    /// |render - picture| per channel, times [`DIFFERENCE_GAIN`].
    Difference,
}

/// How much a difference image is brightened: most errors of a good render are a few percent.
pub const DIFFERENCE_GAIN: f32 = 4.0;

/// The output `output` of `frame` as RGB: color as rendered; alpha as grey; depth colored
/// (viridis, near dark) between the 1st and 99th percentile of the covered pixels' depths, the
/// uncovered black.
pub fn shown(frame: &Frame, output: Output) -> Result<Cow<'_, Image>> {
    let grey = |image: &Image, value: &dyn Fn(usize, f32) -> [f32; 3]| Image {
        width: image.width,
        height: image.height,
        channels: 3,
        data: (image.data.iter().enumerate())
            .flat_map(|(i, v)| value(i, *v))
            .collect(),
    };
    Ok(Cow::Owned(match output {
        Output::Rgb => return Ok(Cow::Borrowed(&frame.color)),
        Output::Alpha => match &frame.alpha {
            Some(alpha) => grey(alpha, &|_, a| [a; 3]),
            None => bail!("the frame has no alpha output"),
        },
        Output::Depth => {
            let Some(depth) = &frame.depth else {
                bail!("the frame has no depth output")
            };
            let covered = |i: usize| frame.alpha.as_ref().is_none_or(|a| a.data[i] > 0.5);
            let mut seen: Vec<f32> = (depth.data.iter().enumerate())
                .filter(|&(i, d)| covered(i) && d.is_finite() && *d > 0.0)
                .map(|(_, d)| *d)
                .collect();
            if seen.is_empty() {
                return Ok(Cow::Owned(grey(depth, &|_, _| [0.0; 3])));
            }
            seen.sort_by(f32::total_cmp);
            let at = |q: f64| seen[((seen.len() - 1) as f64 * q) as usize];
            let (near, far) = (at(0.01), at(0.99).max(at(0.01) + 1e-6));
            grey(depth, &|i, d| {
                if !(covered(i) && d.is_finite() && d > 0.0) {
                    return [0.0; 3];
                }
                let c = ViridisRGB.get_color_normalized(d.clamp(near, far), near, far);
                [c.0, c.1, c.2].map(|v| v as f32 / 255.0)
            })
        }
    }))
}

/// `render` shown against `picture` (same size) as `compare` asks.
pub fn compared(render: Image, picture: &Image, compare: Compare) -> Image {
    match compare {
        Compare::Render => render,
        Compare::Difference => Image {
            data: (render.data.iter().zip(&picture.data))
                .map(|(a, b)| ((a - b).abs() * DIFFERENCE_GAIN).min(1.0))
                .collect(),
            ..render
        },
        Compare::Side => {
            let row = (render.width * 3) as usize;
            let data = (render.data.chunks(row).zip(picture.data.chunks(row)))
                .flat_map(|(a, b)| a.iter().chain(b).copied())
                .collect();
            Image {
                width: render.width * 2,
                data,
                ..render
            }
        }
    }
}

/// `image` (RGB in [0, 1]) as a JPEG of quality 90 (color at full resolution).
pub fn jpeg(image: &Image) -> Result<Vec<u8>> {
    let bytes: Vec<u8> = (image.data.iter())
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let (Ok(width), Ok(height)) = (image.width.try_into(), image.height.try_into()) else {
        bail!(
            "{}x{} is past a JPEG's 65535 a side",
            image.width,
            image.height
        );
    };
    let mut out = Vec::new();
    let encoder = jpeg_encoder::Encoder::new(&mut out, 90);
    encoder.encode(&bytes, width, height, jpeg_encoder::ColorType::Rgb)?;
    Ok(out)
}
