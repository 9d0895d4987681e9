//! A dataset picture's pixels: decoded as straight RGBA, averaged over blocks when a view is
//! taken smaller, and composited on a background into a [`View`]'s image. A view read from an
//! 8-bit picture (as PNGs and JPEGs usually are) keeps 8-bit values, averaged or not, so the
//! GPU trainer can hold it in 4 bytes per pixel instead of 12 or 16 ([`View::rgba8`]).

use super::dataset::{DatasetError, View, image_error};
use crate::pipeline::Image;
use glam::Vec3;
use rayon::prelude::*;
use std::path::Path;

/// A picture as straight (not premultiplied) RGBA in [0, 1].
pub(super) struct Picture {
    pub width: u32,
    pub height: u32,
    /// 4 words per pixel, row by row.
    pub rgba: Vec<f32>,
    /// Every value is an 8-bit one ([`unorm8`]).
    pub eight_bit: bool,
}

/// An 8-bit value in [0, 1], as pictures are decoded and [`View::rgba8`] recovers them.
pub(super) fn unorm8(v: u8) -> f32 {
    v as f32 / 255.0
}

/// A color `c` of coverage `a` composited on background `b`: every view's pixels are this.
fn composited(c: f32, a: f32, b: f32) -> f32 {
    c * a + b * (1.0 - a)
}

/// The color a composited value `v` of coverage `a` had before it was composited on `b` (0
/// where nothing covers the pixel).
fn straight(v: f32, a: f32, b: f32) -> f32 {
    match a > 0.0 {
        true => (v - (1.0 - a) * b) / a,
        false => 0.0,
    }
}

impl Picture {
    /// The picture at `path`, decoded. 8-bit pictures are converted by [`unorm8`], others
    /// (16-bit, float) by the image crate.
    pub fn read(path: &Path) -> Result<Picture, DatasetError> {
        use image::DynamicImage::*;
        let img = image::open(path).map_err(|error| image_error(path, error))?;
        let (width, height) = (img.width(), img.height());
        let eight_bit = matches!(
            img,
            ImageLuma8(_) | ImageLumaA8(_) | ImageRgb8(_) | ImageRgba8(_)
        );
        let rgba = match eight_bit {
            // Converted in place where the picture already is RGBA (no copy of its pixels).
            true => img
                .into_rgba8()
                .into_raw()
                .into_iter()
                .map(unorm8)
                .collect(),
            false => img.into_rgba32f().into_raw(),
        };
        Ok(Picture {
            width,
            height,
            rgba,
            eight_bit,
        })
    }

    /// The picture averaged over blocks of `factor` x `factor` pixels, the right and bottom
    /// pixels that fill no block dropped: each block is its pixels' [`Picture::blend`].
    pub fn downscaled(&self, factor: u32) -> Picture {
        let (f, w) = (factor as usize, self.width as usize);
        let (width, height) = (self.width / factor, self.height / factor);
        let mut rgba = vec![0.0f32; width as usize * height as usize * 4];
        (rgba.par_chunks_exact_mut(width as usize * 4).enumerate()).for_each(|(y, row)| {
            for (x, px) in row.chunks_exact_mut(4).enumerate() {
                let rows = (y * f..(y + 1) * f).map(|sy| sy * w);
                let block = rows.flat_map(|start| (x * f..(x + 1) * f).map(move |sx| start + sx));
                px.copy_from_slice(&self.blend(block.map(|p| (p, 1.0))));
            }
        });
        Picture {
            width,
            height,
            rgba,
            eight_bit: self.eight_bit,
        }
    }

    /// The weighted mean of pixels (each its index and weight), as straight RGBA: its coverage
    /// is the coverages' mean, its color the mean weighted by coverage too (so composited on any
    /// background, it is the mean of the pixels composited on it). An 8-bit picture's means
    /// are rounded to 8 bits, as a copy made by an image program would hold them.
    pub fn blend(&self, pixels: impl IntoIterator<Item = (usize, f32)>) -> [f32; 4] {
        let rounded = |v: f32| match self.eight_bit {
            true => unorm8((v.clamp(0.0, 1.0) * 255.0).round() as u8),
            false => v,
        };
        // Sums of w a c per channel, of w a, and of w.
        let (mut sums, mut weight) = ([0.0f32; 4], 0.0f32);
        for (p, w) in pixels {
            let px = &self.rgba[p * 4..p * 4 + 4];
            let wa = w * px[3];
            for c in 0..3 {
                sums[c] += px[c] * wa;
            }
            sums[3] += wa;
            weight += w;
        }
        let color = |c: usize| match sums[3] > 0.0 {
            true => rounded(sums[c] / sums[3]),
            false => 0.0,
        };
        [color(0), color(1), color(2), rounded(sums[3] / weight)]
    }

    /// RGB composited on `background`, and the coverage unless the picture is opaque.
    pub fn composited(&self, background: Vec3) -> (Image, Option<Vec<f32>>) {
        let b = background.to_array();
        let mut data = Vec::with_capacity(self.rgba.len() / 4 * 3);
        let mut alpha = Vec::with_capacity(self.rgba.len() / 4);
        for p in self.rgba.chunks_exact(4) {
            data.extend((0..3).map(|c| composited(p[c], p[3], b[c])));
            alpha.push(p[3]);
        }
        let image = Image {
            width: self.width,
            height: self.height,
            channels: 3,
            data,
        };
        (image, alpha.iter().any(|a| *a < 1.0).then_some(alpha))
    }
}

impl View {
    /// The coverage of pixel `p` (1 where the view has none).
    fn alpha(&self, p: usize) -> f32 {
        self.coverage.as_ref().map_or(1.0, |c| c[p])
    }

    /// The view as straight RGBA: its colors taken off its background, its coverage as alpha
    /// (as an RGBA picture holds them).
    pub(super) fn straight(&self) -> Image {
        let b = self.background.to_array();
        let mut rgba = Vec::with_capacity(self.image.data.len() / 3 * 4);
        for (p, rgb) in self.image.data.chunks_exact(3).enumerate() {
            let a = self.alpha(p);
            rgba.extend((0..3).map(|c| straight(rgb[c], a, b[c])));
            rgba.push(a);
        }
        Image {
            channels: 4,
            data: rgba,
            ..self.image
        }
    }

    /// The view as 8-bit straight RGBA, one word per pixel (red in the low byte, alpha in the
    /// high one), when that is exactly what it holds: 8-bit colors and coverages composited on
    /// its background as [`Picture::composited`] does, which every view read from an 8-bit
    /// picture is (averaged or not). `None` for any other view (from a 16-bit or float picture,
    /// a render, not RGB), whose values 8 bits would round.
    pub fn rgba8(&self) -> Option<Vec<u32>> {
        if self.image.channels != 3 {
            return None;
        }
        let eight_bit = |v: f32| {
            let k = (v * 255.0).round();
            ((0.0..=255.0).contains(&k) && unorm8(k as u8) == v).then_some(k as u32)
        };
        let b = self.background.to_array();
        (self.image.data.par_chunks_exact(3).enumerate())
            .map(|(p, rgb)| {
                let a = self.alpha(p);
                let mut word = eight_bit(a)? << 24;
                for c in 0..3 {
                    let k = (straight(rgb[c], a, b[c]).clamp(0.0, 1.0) * 255.0).round() as u8;
                    if composited(unorm8(k), a, b[c]) != rgb[c] {
                        return None;
                    }
                    word |= (k as u32) << (8 * c);
                }
                Some(word)
            })
            .collect()
    }
}
