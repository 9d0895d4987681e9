//! Writing rendered outputs, chosen by extension: `.png` (8-bit, color clamped to [0, 1]),
//! `.exr` (float32), `.npy` (float32, H x W x C: color channels, then alpha, then depth).
//! PNG and EXR hold color (and alpha as a fourth channel when rendered); the depth goes to a
//! sibling file `<stem>.depth.<ext>`. Every file is written atomically.

use super::{CommitError, Outputs};
use splat_core::frame::{Frame, Image};
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("output `{0}`: unknown extension (use .png, .exr or .npy)")]
    Extension(String),
    #[error("{0}-channel color cannot be stored as PNG or EXR (1, 3 or 4 channels): use .npy")]
    Channels(usize),
    #[error("cannot write {path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error(
        "an image of {width}x{height} pixels and {channels} channels holds {values} values, not one per pixel and channel"
    )]
    Malformed {
        width: u32,
        height: u32,
        channels: usize,
        values: usize,
    },
    #[error("images stacked into one must have the same size: {0}x{1} and {2}x{3}")]
    Sizes(u32, u32, u32, u32),
}

/// Refuses an image whose values do not fill its size (its fields are public).
fn check(im: &Image) -> Result<(), ImageError> {
    match im.fills_its_size() {
        true => Ok(()),
        false => Err(ImageError::Malformed {
            width: im.width,
            height: im.height,
            channels: im.channels,
            values: im.data.len(),
        }),
    }
}

impl From<CommitError> for ImageError {
    fn from(e: CommitError) -> Self {
        io(&e.path)(e.error)
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ImageError + '_ {
    move |error| ImageError::Io {
        path: path.display().to_string(),
        error,
    }
}

/// The extension of `path`, lower case ("" without one).
fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// Writes the frame to `path` (and the depth sibling for PNG / EXR); returns every path written.
pub fn write_frame(path: &Path, frame: &Frame) -> Result<Vec<PathBuf>, ImageError> {
    let ext = extension(path);
    match ext.as_str() {
        "npy" => {
            let mut planes = vec![&frame.color];
            planes.extend(frame.alpha.as_ref());
            planes.extend(frame.depth.as_ref());
            write_npy(path, &stack(&planes)?)?;
            Ok(vec![path.to_path_buf()])
        }
        "png" | "exr" => {
            let color = match (&frame.alpha, frame.color.channels) {
                (Some(a), 3) => stack(&[&frame.color, a])?,
                _ => frame.color.clone(),
            };
            // The picture and its depth appear together or not at all.
            let mut outputs = Outputs::default();
            stage_picture(&mut outputs, path, &ext, &color, false)?;
            let mut written = vec![path.to_path_buf()];
            if let Some(d) = &frame.depth {
                let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("out");
                let depth_path = path.with_file_name(format!("{stem}.depth.{ext}"));
                stage_picture(&mut outputs, &depth_path, &ext, d, true)?;
                written.push(depth_path);
            }
            outputs.commit()?;
            Ok(written)
        }
        _ => Err(ImageError::Extension(path.display().to_string())),
    }
}

/// Depth as an 8-bit PNG over its visible range: nearest 255, farthest 26, no hit 0, with the
/// mapping and the range in a `Description` text chunk (a viewer shows shape, not metres; the
/// EXR and NPY outputs keep the values).
fn stage_depth_png(outputs: &mut Outputs, path: &Path, im: &Image) -> Result<(), ImageError> {
    let (lo, hi) = im
        .data
        .iter()
        .filter(|v| **v > 0.0)
        .fold((f32::INFINITY, 0.0f32), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let span = if hi > lo { hi - lo } else { 1.0 };
    let bytes: Vec<u8> = im
        .data
        .iter()
        .map(|v| match *v > 0.0 {
            true => ((1.0 - 0.9 * (v - lo) / span) * 255.0).round() as u8,
            false => 0,
        })
        .collect();
    let description = match lo.is_finite() {
        true => format!(
            "expected depth (camera z): 255 = {lo} (nearest), 26 = {hi} (farthest), linear between; 0 = nothing hit"
        ),
        false => "expected depth: nothing hit (every pixel 0)".to_string(),
    };
    outputs
        .stage(path, |w| {
            let mut encoder = png::Encoder::new(w, im.width, im.height);
            encoder.set_color(png::ColorType::Grayscale);
            encoder.set_depth(png::BitDepth::Eight);
            encoder
                .add_text_chunk("Description".into(), description)
                .map_err(std::io::Error::other)?;
            let mut writer = encoder.write_header().map_err(std::io::Error::other)?;
            writer
                .write_image_data(&bytes)
                .map_err(std::io::Error::other)?;
            writer.finish().map_err(std::io::Error::other)
        })
        .map_err(io(path))
}

/// Interleaves images of the same size channel-wise (none: an empty image).
pub fn stack(images: &[&Image]) -> Result<Image, ImageError> {
    let (w, h) = images.first().map_or((0, 0), |i| (i.width, i.height));
    for im in images {
        check(im)?;
        if (im.width, im.height) != (w, h) {
            return Err(ImageError::Sizes(w, h, im.width, im.height));
        }
    }
    let channels: usize = images.iter().map(|i| i.channels).sum();
    let mut data = Vec::with_capacity((w * h) as usize * channels);
    for p in 0..(w * h) as usize {
        for im in images {
            data.extend_from_slice(&im.data[p * im.channels..(p + 1) * im.channels]);
        }
    }
    Ok(Image {
        width: w,
        height: h,
        channels,
        data,
    })
}

/// Writes one image (1, 3 or 4 channels) as PNG (8 bits, clamped to [0, 1]) or EXR, by the
/// extension of `path`.
pub fn write_image(path: &Path, im: &Image) -> Result<(), ImageError> {
    let mut outputs = Outputs::default();
    stage_image(&mut outputs, path, im)?;
    Ok(outputs.commit()?)
}

/// [`write_image`] as one of several outputs that appear together.
pub fn stage_image(outputs: &mut Outputs, path: &Path, im: &Image) -> Result<(), ImageError> {
    let ext = extension(path);
    match ext.as_str() {
        "png" | "exr" => stage_picture(outputs, path, &ext, im, false),
        _ => Err(ImageError::Extension(path.display().to_string())),
    }
}

fn stage_picture(
    outputs: &mut Outputs,
    path: &Path,
    ext: &str,
    im: &Image,
    depth: bool,
) -> Result<(), ImageError> {
    if ![1, 3, 4].contains(&im.channels) {
        return Err(ImageError::Channels(im.channels));
    }
    check(im)?;
    if depth && ext == "png" {
        return stage_depth_png(outputs, path, im);
    }
    let data = im.data.clone();
    let (w, h) = (im.width, im.height);
    let dynamic = if ext == "png" {
        let bytes: Vec<u8> = data
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        match im.channels {
            1 => {
                image::DynamicImage::ImageLuma8(image::ImageBuffer::from_raw(w, h, bytes).unwrap())
            }
            3 => image::DynamicImage::ImageRgb8(image::ImageBuffer::from_raw(w, h, bytes).unwrap()),
            _ => {
                image::DynamicImage::ImageRgba8(image::ImageBuffer::from_raw(w, h, bytes).unwrap())
            }
        }
    } else {
        let rgb: Vec<f32> = match im.channels {
            1 => data.iter().flat_map(|v| [*v, *v, *v]).collect(),
            _ => data,
        };
        match im.channels {
            4 => {
                image::DynamicImage::ImageRgba32F(image::ImageBuffer::from_raw(w, h, rgb).unwrap())
            }
            _ => image::DynamicImage::ImageRgb32F(image::ImageBuffer::from_raw(w, h, rgb).unwrap()),
        }
    };
    let format = if ext == "png" {
        image::ImageFormat::Png
    } else {
        image::ImageFormat::OpenExr
    };
    outputs
        .stage(path, |w| {
            let mut buf = std::io::Cursor::new(Vec::new());
            dynamic
                .write_to(&mut buf, format)
                .map_err(std::io::Error::other)?;
            w.write_all(buf.get_ref())
        })
        .map_err(io(path))
}

/// NumPy `.npy` v1.0, little-endian float32, shape (H, W, C).
pub fn write_npy(path: &Path, im: &Image) -> Result<(), ImageError> {
    check(im)?;
    super::write_atomic(path, |w| {
        let dict = format!(
            "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
            im.height, im.width, im.channels
        );
        // Magic (6) + version (2) + length (2) + dict + padding + '\n' is a multiple of 64.
        let unpadded = 10 + dict.len() + 1;
        let pad = unpadded.div_ceil(64) * 64 - unpadded;
        let header = format!("{dict}{}\n", " ".repeat(pad));
        w.write_all(b"\x93NUMPY\x01\x00")?;
        w.write_all(&(header.len() as u16).to_le_bytes())?;
        w.write_all(header.as_bytes())?;
        for v in &im.data {
            w.write_all(&v.to_le_bytes())?;
        }
        Ok(())
    })
    .map_err(io(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An image whose values do not fill its size, or images of other sizes stacked, are
    /// refused before any file is made.
    #[test]
    fn malformed_images_are_refused_before_writing() {
        let dir = std::env::temp_dir().join("splat-never-written");
        let short = Image {
            width: 4,
            height: 4,
            channels: 3,
            data: vec![0.5; 5],
        };
        for name in ["a.png", "a.exr"] {
            let e = write_image(&dir.join(name), &short)
                .unwrap_err()
                .to_string();
            assert!(e.contains("holds 5 values"), "{e}");
        }
        let e = write_npy(&dir.join("a.npy"), &short)
            .unwrap_err()
            .to_string();
        assert!(e.contains("holds 5 values"), "{e}");
        assert!(!dir.exists());
        let gray = |w, h| Image {
            width: w,
            height: h,
            channels: 1,
            data: vec![0.0; (w * h) as usize],
        };
        let e = stack(&[&gray(4, 4), &gray(2, 2)]).unwrap_err().to_string();
        assert!(e.contains("4x4 and 2x2"), "{e}");
        assert_eq!(stack(&[&gray(2, 2), &gray(2, 2)]).unwrap().channels, 2);
        assert_eq!(stack(&[]).unwrap().data.len(), 0);
    }
}
