//! A dataset picture's pixels: decoded as straight RGBA, averaged over blocks when a view is
//! taken smaller, and held by a [`View`] composited on a background. A view read from an
//! 8-bit picture (as PNGs and JPEGs usually are) keeps 8-bit values, averaged or not, and holds
//! them in 4 bytes per pixel instead of 12 or 16 ([`View::rgba8`], what the GPU trainer
//! uploads); the f32 image the CPU reads is made from them when asked for, the same bit for
//! bit.

use super::dataset::error::{DatasetError, image_error};
use glam::Vec3;
use rayon::prelude::*;
use splat_core::frame::Image;
use splat_core::types::Camera;
use std::borrow::Cow;
use std::path::Path;

/// One posed image.
#[derive(Clone, Debug)]
pub struct View {
    /// The image's path, for reports.
    pub name: String,
    pub camera: Camera,
    /// What the pixels are composited on.
    pub background: Vec3,
    pixels: Pixels,
}

/// How a view holds its pixels.
#[derive(Clone, Debug)]
enum Pixels {
    /// RGB composited on the background, and the coverage (alpha) of a picture that is not
    /// opaque everywhere.
    Composited {
        image: Image,
        coverage: Option<Vec<f32>>,
    },
    /// 8-bit straight RGBA, a word per pixel (red in the low byte, alpha in the high one; the
    /// color 0 where the alpha is), composited when read.
    Rgba8 {
        width: u32,
        height: u32,
        words: Vec<u32>,
    },
}

/// The byte of an 8-bit value ([`unorm8`]'s inverse).
fn byte(v: f32) -> u32 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u32
}

/// The coverage of pixel `p` (1 where a view has none).
fn alpha(coverage: &Option<Vec<f32>>, p: usize) -> f32 {
    coverage.as_ref().map_or(1.0, |c| c[p])
}

/// The channel `c` (3: alpha) of an 8-bit RGBA word, in [0, 1].
fn channel(word: u32, c: usize) -> f32 {
    unorm8((word >> (8 * c)) as u8)
}

/// A picture as straight (not premultiplied) RGBA in [0, 1].
#[derive(Debug, PartialEq)]
pub(super) struct Picture {
    pub width: u32,
    pub height: u32,
    samples: Samples,
}

/// Host memory, in bytes, that loading one picture into a view takes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Footprint {
    /// Held by the view, for as long as it lives.
    pub held: u64,
    /// The most held at once while the picture is decoded and made the view, the view's
    /// own bytes included.
    pub decoding: u64,
    /// The view's pixels (of a dataset's views, the largest's).
    pub largest: u64,
}

impl Footprint {
    /// The most held at once by a dataset's views while `threads` pictures are decoded at a
    /// time ([`Footprint::decoding`] of the largest).
    pub fn peak(&self, threads: usize) -> u64 {
        self.held + threads as u64 * self.decoding
    }

    /// The most held at once while training: the views, and a step's buffers on the largest
    /// at `step` bytes per pixel.
    pub fn training(&self, step: u64) -> u64 {
        self.held + step * self.largest
    }
}

/// A picture's values, 4 per pixel, row by row.
#[derive(Debug, PartialEq)]
enum Samples {
    /// 8-bit values ([`unorm8`]), as PNGs and JPEGs usually hold them: a quarter of the memory
    /// of f32, and packed into a view's words as they are.
    Bytes(Vec<u8>),
    /// Any other depth (16-bit, float).
    Floats(Vec<f32>),
}

/// Whether pictures of `color` are held as their bytes ([`Samples::Bytes`]).
fn eight_bit(color: image::ColorType) -> bool {
    use image::ColorType::*;
    matches!(color, L8 | La8 | Rgb8 | Rgba8)
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
    /// The picture at `path`, decoded. 8-bit pictures keep their bytes; others (16-bit,
    /// float) are converted to f32 by the image crate.
    pub fn read(path: &Path) -> Result<Picture, DatasetError> {
        let error = |error| image_error(path, error);
        let mut reader = (image::ImageReader::open(path).map_err(|e| error(e.into()))?)
            .with_guessed_format()
            .map_err(|e| error(e.into()))?;
        // The decoder's own default (512 MiB) refuses a 12000 x 12000 RGBA picture; `fit`
        // has checked from the headers that the pictures fit in memory.
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(Self::MAX_DECODE_BYTES);
        reader.limits(limits);
        let img = reader.decode().map_err(error)?;
        let (width, height) = (img.width(), img.height());
        let samples = match eight_bit(img.color()) {
            // Taken as they are where the picture already is RGBA (no copy of its pixels).
            true => Samples::Bytes(img.into_rgba8().into_raw()),
            false => Samples::Floats(img.into_rgba32f().into_raw()),
        };
        Ok(Picture {
            width,
            height,
            samples,
        })
    }

    /// The most memory decoding one picture may take (a 16384 x 16384 16-bit RGBA picture
    /// takes 2 GiB): a bound against a header that claims absurd sizes.
    const MAX_DECODE_BYTES: u64 = 4 << 30;

    /// What loading the picture at `path` into a view of `view_pixels` pixels takes in host
    /// memory, from its header alone (no pixel is decoded).
    pub fn footprint(path: &Path, view_pixels: u64) -> Result<Footprint, DatasetError> {
        let error = |error| image_error(path, error);
        let reader = image::ImageReader::open(path).map_err(|e| error(e.into()))?;
        let decoder = (reader.with_guessed_format())
            .map_err(|e| error(e.into()))?
            .into_decoder()
            .map_err(error)?;
        let (w, h) = image::ImageDecoder::dimensions(&decoder);
        let color = image::ImageDecoder::color_type(&decoder);
        // Per pixel: the bytes held, as [`Picture`] and [`View`] hold them (12 of f32 RGB
        // and 4 of coverage where the picture is not 8-bit).
        let per_pixel: u64 = if eight_bit(color) { 4 } else { 16 };
        let picture = u64::from(w) * u64::from(h);
        let held = per_pixel * view_pixels;
        Ok(Footprint {
            held,
            // The decoder's own pixels, converted to RGBA, cut or averaged to the view, then
            // the view.
            decoding: (u64::from(color.bytes_per_pixel()) + per_pixel) * picture + 2 * held,
            largest: view_pixels,
        })
    }

    /// An 8-bit picture of `width` x `height` pixels from its RGBA bytes, row by row.
    #[cfg(test)]
    pub fn from_bytes(width: u32, height: u32, rgba: Vec<u8>) -> Picture {
        assert_eq!(rgba.len(), width as usize * height as usize * 4);
        Picture {
            width,
            height,
            samples: Samples::Bytes(rgba),
        }
    }

    /// A picture of `width` x `height` pixels of the same depth as this one, each made by
    /// `pixel(x, y)` (in parallel by rows; the first error met is returned) and rounded to
    /// 8 bits where this picture is 8-bit, as a copy made by an image program would hold it.
    pub fn made<E: Send>(
        &self,
        (width, height): (u32, u32),
        pixel: impl Fn(usize, usize) -> Result<[f32; 4], E> + Sync,
    ) -> Result<Picture, E> {
        fn fill<T: Copy + Default + Send, E: Send>(
            width: u32,
            height: u32,
            pixel: impl Fn(usize, usize) -> Result<[f32; 4], E> + Sync,
            value: impl Fn(f32) -> T + Sync,
        ) -> Result<Vec<T>, E> {
            let mut values = vec![T::default(); width as usize * height as usize * 4];
            (values.par_chunks_exact_mut(width as usize * 4).enumerate()).try_for_each(
                |(y, row)| {
                    for (x, px) in row.chunks_exact_mut(4).enumerate() {
                        for (out, v) in px.iter_mut().zip(pixel(x, y)?) {
                            *out = value(v);
                        }
                    }
                    Ok(())
                },
            )?;
            Ok(values)
        }
        let samples = match self.samples {
            Samples::Bytes(_) => Samples::Bytes(fill(width, height, pixel, |v| byte(v) as u8)?),
            Samples::Floats(_) => Samples::Floats(fill(width, height, pixel, |v| v)?),
        };
        Ok(Picture {
            width,
            height,
            samples,
        })
    }

    /// Pixel `p`'s straight RGBA.
    fn pixel(&self, p: usize) -> [f32; 4] {
        let at = p * 4..p * 4 + 4;
        match &self.samples {
            Samples::Bytes(v) => std::array::from_fn(|c| unorm8(v[at.start + c])),
            Samples::Floats(v) => v[at].try_into().unwrap(),
        }
    }

    /// The picture averaged over blocks of `factor` x `factor` pixels, the right and bottom
    /// pixels that fill no block dropped: each block is its pixels' [`Picture::blend`].
    pub fn downscaled(&self, factor: u32) -> Picture {
        let (f, w) = (factor as usize, self.width as usize);
        let size = (self.width / factor, self.height / factor);
        let block = |x: usize, y: usize| {
            let rows = (y * f..(y + 1) * f).map(|sy| sy * w);
            let block = rows.flat_map(|start| (x * f..(x + 1) * f).map(move |sx| start + sx));
            Ok::<_, ()>(self.blend(block.map(|p| (p, 1.0))))
        };
        self.made(size, block).unwrap()
    }

    /// The weighted mean of pixels (each its index and weight), as straight RGBA: its coverage
    /// is the coverages' mean, its color the mean weighted by coverage too (so composited on any
    /// background, it is the mean of the pixels composited on it).
    pub fn blend(&self, pixels: impl IntoIterator<Item = (usize, f32)>) -> [f32; 4] {
        // Sums of w a c per channel, of w a, and of w.
        let (mut sums, mut weight) = ([0.0f32; 4], 0.0f32);
        for (p, w) in pixels {
            let px = self.pixel(p);
            let wa = w * px[3];
            for c in 0..3 {
                sums[c] += px[c] * wa;
            }
            sums[3] += wa;
            weight += w;
        }
        let color = |c: usize| match sums[3] > 0.0 {
            true => sums[c] / sums[3],
            false => 0.0,
        };
        [color(0), color(1), color(2), sums[3] / weight]
    }

    /// The view of this picture seen by `camera`, composited on `background` (8-bit words for
    /// an 8-bit picture).
    pub fn view(self, name: String, camera: Camera, background: Vec3) -> View {
        let pixels = match self.samples {
            Samples::Bytes(bytes) => Pixels::Rgba8 {
                width: self.width,
                height: self.height,
                words: (bytes.par_chunks_exact(4))
                    .map(|p| match p[3] {
                        0 => 0,
                        _ => u32::from_le_bytes(p.try_into().unwrap()),
                    })
                    .collect(),
            },
            Samples::Floats(rgba) => {
                let b = background.to_array();
                let mut data = Vec::with_capacity(rgba.len() / 4 * 3);
                let mut alpha = Vec::with_capacity(rgba.len() / 4);
                for p in rgba.chunks_exact(4) {
                    data.extend((0..3).map(|c| composited(p[c], p[3], b[c])));
                    alpha.push(p[3]);
                }
                let image = Image {
                    width: self.width,
                    height: self.height,
                    channels: 3,
                    data,
                };
                Pixels::Composited {
                    image,
                    coverage: alpha.iter().any(|a| *a < 1.0).then_some(alpha),
                }
            }
        };
        View {
            name,
            camera,
            background,
            pixels,
        }
    }
}

impl View {
    /// Feeds what training reads of this view to `h`: its camera, background and pixels (not
    /// its name, which holds where it was read from), so that processes that read the same
    /// dataset in different places hash the same.
    pub fn fingerprint(&self, h: &mut impl std::hash::Hasher) {
        h.write(format!("{:?} {:?}", self.camera, self.background).as_bytes());
        match &self.pixels {
            Pixels::Composited { image, coverage } => {
                h.write_u32(image.width);
                h.write_u32(image.height);
                image.data.iter().for_each(|x| h.write_u32(x.to_bits()));
                coverage
                    .iter()
                    .flatten()
                    .for_each(|x| h.write_u32(x.to_bits()));
            }
            Pixels::Rgba8 {
                width,
                height,
                words,
            } => {
                h.write_u32(*width);
                h.write_u32(*height);
                words.iter().for_each(|w| h.write_u32(*w));
            }
        }
    }

    /// A view of `image` (RGB composited on `background`, with the coverage of a picture not
    /// opaque everywhere), held as it is given.
    pub fn new(
        name: String,
        camera: Camera,
        image: Image,
        coverage: Option<Vec<f32>>,
        background: Vec3,
    ) -> View {
        View {
            name,
            camera,
            background,
            pixels: Pixels::Composited { image, coverage },
        }
    }

    /// What is wrong with the view's pixels, if anything: values that do not fill its size
    /// (three channels, a coverage per pixel), NaN or infinite colors, coverage outside
    /// [0, 1]. ([`View::new`] holds what it is given.)
    pub fn defect(&self) -> Option<String> {
        let (width, height) = self.size();
        let pixels = width as usize * height as usize;
        match &self.pixels {
            Pixels::Composited { image, coverage } => {
                if image.channels != 3 || !image.fills_its_size() {
                    return Some(format!(
                        "its image holds {} values in {} channels, where {width}x{height} RGB takes {}",
                        image.data.len(),
                        image.channels,
                        pixels * 3
                    ));
                }
                if let Some(i) = image.data.iter().position(|v| !v.is_finite()) {
                    return Some(format!("its image is NaN or infinite at value {i}"));
                }
                let coverage = coverage.as_deref()?;
                if coverage.len() != pixels {
                    return Some(format!(
                        "its coverage holds {} values for {pixels} pixels",
                        coverage.len()
                    ));
                }
                let i = coverage.iter().position(|a| !(0.0..=1.0).contains(a))?;
                Some(format!("its coverage is outside [0, 1] at pixel {i}"))
            }
            Pixels::Rgba8 { words, .. } => (words.len() != pixels)
                .then(|| format!("it holds {} pixels, not {pixels}", words.len())),
        }
    }

    /// The bytes its pixels take in memory ([`Footprint::held`]).
    pub fn held_bytes(&self) -> u64 {
        let floats = |v: &[f32]| std::mem::size_of_val(v) as u64;
        match &self.pixels {
            Pixels::Composited { image, coverage } => {
                floats(&image.data) + coverage.as_deref().map_or(0, floats)
            }
            Pixels::Rgba8 { words, .. } => std::mem::size_of_val(&words[..]) as u64,
        }
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        match &self.pixels {
            Pixels::Composited { image, .. } => (image.width, image.height),
            Pixels::Rgba8 { width, height, .. } => (*width, *height),
        }
    }

    /// The image, composited on the view's background.
    pub fn image(&self) -> Cow<'_, Image> {
        self.on(self.background)
    }

    /// [`View::image`], without a copy where the view holds it.
    pub fn into_image(self) -> Image {
        match self.pixels {
            Pixels::Composited { image, .. } => image,
            _ => self.image().into_owned(),
        }
    }

    /// The image composited on `background` instead (the same image when it is opaque or the
    /// background is the same).
    pub fn on(&self, background: Vec3) -> Cow<'_, Image> {
        let mut scratch = Image {
            width: 0,
            height: 0,
            channels: 3,
            data: vec![],
        };
        match self.held_or_composited(background, &mut scratch) {
            Some(held) => Cow::Borrowed(held),
            None => Cow::Owned(scratch),
        }
    }

    /// [`View::on`] into `scratch` (its memory reused) where the view does not hold the image:
    /// what a loop over views asks for at every step, without an allocation per step.
    pub fn on_into<'a>(&'a self, background: Vec3, scratch: &'a mut Image) -> &'a Image {
        match self.held_or_composited(background, scratch) {
            Some(held) => held,
            None => scratch,
        }
    }

    /// The image the view holds, if it is the one on `background`; else `None`, the image
    /// composited into `scratch`.
    fn held_or_composited(&self, background: Vec3, scratch: &mut Image) -> Option<&Image> {
        let b = background.to_array();
        let (width, height) = self.size();
        let fill = |scratch: &mut Image| {
            scratch.width = width;
            scratch.height = height;
            scratch.channels = 3;
            scratch
                .data
                .resize(width as usize * height as usize * 3, 0.0);
        };
        // In blocks of pixels, in parallel.
        const BLOCK: usize = 4096;
        match &self.pixels {
            Pixels::Rgba8 { words, .. } => {
                fill(scratch);
                let blocks = scratch
                    .data
                    .par_chunks_mut(3 * BLOCK)
                    .zip(words.par_chunks(BLOCK));
                blocks.for_each(|(out, words)| {
                    for (px, w) in out.chunks_exact_mut(3).zip(words) {
                        let a = channel(*w, 3);
                        for (c, v) in px.iter_mut().enumerate() {
                            *v = composited(channel(*w, c), a, b[c]);
                        }
                    }
                });
                None
            }
            Pixels::Composited { image, coverage } => {
                let Some(alpha) = coverage.as_ref().filter(|_| background != self.background)
                else {
                    return Some(image);
                };
                fill(scratch);
                let shift = (background - self.background).to_array();
                let pixels = image.data.chunks_exact(3).zip(alpha);
                for (out, (px, a)) in scratch.data.chunks_exact_mut(3).zip(pixels) {
                    for c in 0..3 {
                        out[c] = px[c] + (1.0 - a) * shift[c];
                    }
                }
                None
            }
        }
    }

    /// Per pixel, the coverage of a picture that is not opaque everywhere.
    pub fn coverage(&self) -> Option<Cow<'_, [f32]>> {
        match &self.pixels {
            Pixels::Composited { coverage, .. } => coverage.as_deref().map(Cow::Borrowed),
            Pixels::Rgba8 { words, .. } => (words.iter().any(|w| w >> 24 < 255))
                .then(|| Cow::Owned(words.iter().map(|w| channel(*w, 3)).collect())),
        }
    }

    /// The view as straight RGBA: its colors taken off its background, its coverage as alpha
    /// (as an RGBA picture holds them).
    pub(super) fn straight(&self) -> Image {
        let (width, height) = self.size();
        let data = match &self.pixels {
            Pixels::Rgba8 { words, .. } => (words.iter())
                .flat_map(|w| (0..4).map(|c| channel(*w, c)))
                .collect(),
            Pixels::Composited { image, coverage } => {
                let b = self.background.to_array();
                let mut rgba = Vec::with_capacity(image.data.len() / 3 * 4);
                for (p, rgb) in image.data.chunks_exact(3).enumerate() {
                    let a = alpha(coverage, p);
                    rgba.extend((0..3).map(|c| straight(rgb[c], a, b[c])));
                    rgba.push(a);
                }
                rgba
            }
        };
        Image {
            width,
            height,
            channels: 4,
            data,
        }
    }

    /// The view as 8-bit straight RGBA, one word per pixel (red in the low byte, alpha in the
    /// high one, the color 0 where the alpha is), when that is exactly what it holds: every
    /// view read from an 8-bit picture (averaged or not), and a view given 8-bit colors and
    /// coverages composited on its background as a picture's are. `None` for any other view
    /// (from a 16-bit or float picture, a render, not RGB), whose values 8 bits would round.
    pub fn rgba8(&self) -> Option<Cow<'_, [u32]>> {
        let (image, coverage) = match &self.pixels {
            Pixels::Rgba8 { words, .. } => return Some(Cow::Borrowed(words)),
            Pixels::Composited { image, coverage } => (image, coverage),
        };
        if image.channels != 3 {
            return None;
        }
        let eight_bit = |v: f32| {
            let k = byte(v);
            (unorm8(k as u8) == v).then_some(k)
        };
        let b = self.background.to_array();
        (image.data.par_chunks_exact(3).enumerate())
            .map(|(p, rgb)| {
                let a = alpha(coverage, p);
                let mut word = eight_bit(a)? << 24;
                for c in 0..3 {
                    let k = byte(straight(rgb[c], a, b[c]));
                    if composited(unorm8(k as u8), a, b[c]) != rgb[c] {
                        return None;
                    }
                    word |= k << (8 * c);
                }
                Some(word)
            })
            .collect::<Option<Vec<u32>>>()
            .map(Cow::Owned)
    }
}
