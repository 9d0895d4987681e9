//! PlayCanvas's SOG, version 2 (`docs/formats-spec.md` §4), as a bundled `.sog`: a ZIP of
//! `meta.json` and lossless WebP pictures, a Gaussian a pixel in Morton order. Positions as
//! 16 bits of `sign(v) ln(1 + |v|)` over its range, rotations as the three smallest components
//! in a byte each, log scales and DC colors as byte indices into 256-entry codebooks, opacity
//! a byte, SH past the DC term as an index into a k-means palette whose values are themselves
//! codebook indices. Written and read here, and read unbundled (a folder: its `meta.json` and
//! the pictures beside it); version 1 is not read.
//! Bytes are rounded to the nearest where splat-transform truncates (positions, rotations,
//! opacity): its readers take them the same way, without the half-step bias.

use super::{morton, quantize};
use crate::ply::{GaussianCloud, StoredGaussian, sh_coefficients};
use glam::{Vec3, Vec4};
use serde_json::{Value, json};
use std::io::{Cursor, Read, Write};

/// The version written and read.
const VERSION: u64 = 2;
/// Palette entries per row of `shN_centroids.webp`.
const PALETTE_ROW: usize = 64;
/// The largest palette written: splat-transform's goes to 65,536, but k-means on the CPU costs
/// N × entries a step (hours for a million Gaussians at 65,536).
const MOST_PALETTE: usize = 4096;
/// k-means steps for the palette (splat-transform's default).
const PALETTE_STEPS: usize = 10;
/// A side's most pixels (WebP's limit).
const MOST_SIDE: usize = 16383;
/// The most Gaussians a file may claim a byte of itself (a SOG takes about 10 bytes each, and
/// pictures of one repeated value compress far below that): a `count` past it is refused
/// before any picture is decoded.
pub const MOST_PER_BYTE: usize = 64;

/// The per-Gaussian pictures' width and height for `n` Gaussians (splat-transform's: both
/// multiples of 4, near square).
fn picture_size(n: usize) -> (usize, usize) {
    let width = ((n as f64).sqrt() / 4.0).ceil() as usize * 4;
    let width = width.max(4);
    (width, n.div_ceil(width).div_ceil(4).max(1) * 4)
}

/// Palette entries for `n` Gaussians: splat-transform's count, at most [`MOST_PALETTE`].
fn palette_size(n: usize) -> usize {
    let k = if n < 1024 {
        1 << n.max(1).ilog2()
    } else {
        (1usize << (n / 1024).ilog2()).min(64) * 1024
    };
    k.min(MOST_PALETTE)
}

fn webp(rgba: &[u8], width: usize, height: usize) -> std::io::Result<Vec<u8>> {
    let mut out = vec![];
    let encoder = image::codecs::webp::WebPEncoder::new_lossless(&mut out);
    (encoder.encode(
        rgba,
        width as u32,
        height as u32,
        image::ExtendedColorType::Rgba8,
    ))
    .map_err(std::io::Error::other)?;
    Ok(out)
}

/// Writes `cloud` as a bundled SOG (its Gaussians in Morton order). Refused: no Gaussians, a
/// NaN or infinite value, more than WebP's pictures hold.
pub fn write_to(w: &mut dyn Write, cloud: &GaussianCloud) -> std::io::Result<()> {
    cloud.check_finite()?;
    let refuse = |why: String| Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, why));
    let n = cloud.gaussians.len();
    let (width, height) = picture_size(n);
    if n == 0 || height > MOST_SIDE {
        return refuse(format!("{n} Gaussians: SOG holds 1 to about 268 million"));
    }
    let means: Vec<Vec3> = cloud.gaussians.iter().map(|g| g.mean).collect();
    let gaussians: Vec<&StoredGaussian> = (morton::order(&means).into_iter())
        .map(|i| &cloud.gaussians[i])
        .collect();
    let pixels = width * height;
    let mut pictures: Vec<(&str, Vec<u8>, usize, usize)> = vec![];
    let picture = || vec![0u8; 4 * pixels];

    // Positions: 16 bits of the log transform over each axis's range.
    let log = |v: f32| f64::from(v).signum() * f64::from(v).abs().ln_1p();
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for g in &gaussians {
        for a in 0..3 {
            lo[a] = lo[a].min(log(g.mean[a]));
            hi[a] = hi[a].max(log(g.mean[a]));
        }
    }
    let (mut low, mut high) = (picture(), picture());
    for (i, g) in gaussians.iter().enumerate() {
        for a in 0..3 {
            let t = 65535.0 * (log(g.mean[a]) - lo[a]) / (hi[a] - lo[a]);
            let q = if t.is_finite() { t.round() as u32 } else { 0 };
            low[4 * i + a] = q as u8;
            high[4 * i + a] = (q >> 8) as u8;
        }
        low[4 * i + 3] = 255;
        high[4 * i + 3] = 255;
    }
    pictures.push(("means_l.webp", low, width, height));
    pictures.push(("means_u.webp", high, width, height));

    let mut quats = picture();
    for (i, g) in gaussians.iter().enumerate() {
        quats[4 * i..4 * i + 4].copy_from_slice(&pack_rotation(g.rotation));
    }
    pictures.push(("quats.webp", quats, width, height));

    // Log scales and DC colors through codebooks; opacity a byte beside the colors.
    let pooled = |f: fn(&StoredGaussian) -> Vec3| {
        let values: Vec<f32> = gaussians.iter().flat_map(|g| f(g).to_array()).collect();
        quantize::codebook(&values)
    };
    let scale_book = pooled(|g| g.log_scale);
    let color_book = pooled(|g| g.sh[0]);
    let (mut scales, mut colors) = (picture(), picture());
    for (i, g) in gaussians.iter().enumerate() {
        for a in 0..3 {
            scales[4 * i + a] = quantize::nearest(&scale_book, g.log_scale[a]);
            colors[4 * i + a] = quantize::nearest(&color_book, g.sh[0][a]);
        }
        scales[4 * i + 3] = 255;
        let alpha = 1.0 / (1.0 + (-f64::from(g.opacity_logit)).exp());
        colors[4 * i + 3] = (alpha * 255.0).round().clamp(0.0, 255.0) as u8;
    }
    pictures.push(("scales.webp", scales, width, height));
    pictures.push(("sh0.webp", colors, width, height));

    let mut meta = json!({
        "version": VERSION,
        "asset": {"generator": format!("splat {}", env!("CARGO_PKG_VERSION"))},
        "count": n,
        "means": {"mins": lo, "maxs": hi, "files": ["means_l.webp", "means_u.webp"]},
        "scales": {"codebook": scale_book.to_vec(), "files": ["scales.webp"]},
        "quats": {"files": ["quats.webp"]},
        "sh0": {"codebook": color_book.to_vec(), "files": ["sh0.webp"]},
    });

    if cloud.antialiased {
        meta["model"] = json!("antialiased");
    }
    let degree = cloud.sh_degree.min(3);
    if degree > 0 {
        let per_channel = sh_coefficients(degree) - 1;
        let dim = 3 * per_channel;
        // Rows channel-major, as the PLY's f_rest.
        let rows: Vec<f32> = (gaussians.iter())
            .flat_map(|g| (0..3).flat_map(move |c| (1..=per_channel).map(move |k| g.sh[k][c])))
            .collect();
        let entries = palette_size(n);
        let (palette, labels) = quantize::palette(&rows, dim, entries, PALETTE_STEPS);
        let book = quantize::codebook(&palette);
        let (palette_width, palette_height) =
            (PALETTE_ROW * per_channel, entries.div_ceil(PALETTE_ROW));
        let mut centroids = vec![0u8; 4 * palette_width * palette_height];
        for (entry, values) in palette.chunks_exact(dim).enumerate() {
            for j in 0..per_channel {
                let texel = 4 * (entry * per_channel + j);
                for c in 0..3 {
                    centroids[texel + c] = quantize::nearest(&book, values[c * per_channel + j]);
                }
                centroids[texel + 3] = 255;
            }
        }
        let mut label_picture = picture();
        for (i, label) in labels.iter().enumerate() {
            label_picture[4 * i..4 * i + 4].copy_from_slice(&[
                *label as u8,
                (*label >> 8) as u8,
                0,
                255,
            ]);
        }
        pictures.push((
            "shN_centroids.webp",
            centroids,
            palette_width,
            palette_height,
        ));
        pictures.push(("shN_labels.webp", label_picture, width, height));
        meta["shN"] = json!({
            "count": entries,
            "bands": degree,
            "codebook": book.to_vec(),
            "files": ["shN_centroids.webp", "shN_labels.webp"],
        });
    }

    let mut zip = zip::ZipWriter::new(Cursor::new(vec![]));
    // Stored: the pictures are compressed already (as splat-transform bundles them).
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let zipped = |e: zip::result::ZipError| std::io::Error::other(e);
    for (name, rgba, w, h) in &pictures {
        zip.start_file(*name, stored).map_err(zipped)?;
        zip.write_all(&webp(rgba, *w, *h)?)?;
    }
    zip.start_file("meta.json", stored).map_err(zipped)?;
    zip.write_all(meta.to_string().as_bytes())?;
    w.write_all(&zip.finish().map_err(zipped)?.into_inner())
}

/// (w, x, y, z) as splat-transform packs it: the largest component's slot as 252 + slot in
/// alpha, the others (slot order) as bytes of `q sqrt 2 / 2 + 1/2`, rounded (splat-transform
/// truncates, which lowers each by half a step on average).
fn pack_rotation(q: Vec4) -> [u8; 4] {
    let q = q.as_dvec4();
    let q = if q.length() > 0.0 {
        q / q.length()
    } else {
        glam::DVec4::X
    };
    let q = q.to_array();
    let largest = (1..4).fold(0, |m, i| if q[i].abs() > q[m].abs() { i } else { m });
    let sign = if q[largest] < 0.0 { -1.0 } else { 1.0 };
    let mut out = [0u8; 4];
    for (slot, i) in (0..4).filter(|i| *i != largest).enumerate() {
        out[slot] = (255.0 * (q[i] * sign * std::f64::consts::SQRT_2 * 0.5 + 0.5)).round() as u8;
    }
    out[3] = 252 + largest as u8;
    out
}

fn unpack_rotation(texel: &[u8]) -> Vec4 {
    let Some(largest) = texel[3].checked_sub(252).map(usize::from) else {
        return Vec4::X;
    };
    let mut q = [0.0f32; 4];
    for (slot, i) in (0..4).filter(|i| *i != largest).enumerate() {
        q[i] = (texel[slot] as f32 / 255.0 - 0.5) * std::f32::consts::SQRT_2;
    }
    q[largest] = (1.0 - q.iter().map(|v| v * v).sum::<f32>()).max(0.0).sqrt();
    Vec4::from_array(q)
}

/// `bytes` (a bundled `.sog`) as a cloud; why not, when they are not one splat reads.
pub fn parse(bytes: &[u8]) -> Result<GaussianCloud, String> {
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes))
        .map_err(|e| format!("not a SOG file (a ZIP archive): {e}"))?;
    let entry = |name: &str| -> Result<Vec<u8>, String> {
        let file = zip
            .by_name(name)
            .map_err(|e| format!("no `{name}` in the archive: {e}"))?;
        // Stored or deflated, never more than the archive's size.
        read_at_most(file, bytes.len(), name)
    };
    decode(entry, bytes.len())
}

/// An unbundled SOG: `meta.json` at `path` and the pictures it names beside it (as
/// splat-transform writes to a `meta.json` output); why not, when it is not one.
pub fn read_folder(path: &std::path::Path) -> Result<GaussianCloud, String> {
    let folder = path.parent().unwrap_or(std::path::Path::new("."));
    let open = |name: &str| -> Result<(std::fs::File, usize), String> {
        // The pictures lie beside meta.json: a name that climbs or descends is refused.
        if name.contains(['/', '\\']) || name == ".." {
            return Err(format!(
                "meta.json names `{name}`, which is not a file beside it"
            ));
        }
        let file = std::fs::File::open(folder.join(name)).map_err(|e| format!("`{name}`: {e}"))?;
        let size = file.metadata().map_err(|e| format!("`{name}`: {e}"))?.len();
        Ok((file, usize::try_from(size).unwrap_or(usize::MAX)))
    };
    let meta: Value =
        serde_json::from_slice(&read_at_most(open("meta.json")?.0, 16 << 20, "meta.json")?)
            .map_err(|e| format!("meta.json: {e}"))?;
    // The files' sizes bound what they may claim, as a bundle's size bounds it.
    let mut total = 0usize;
    for part in ["means", "scales", "quats", "sh0", "shN"] {
        for name in meta[part]["files"].as_array().into_iter().flatten() {
            let name = name
                .as_str()
                .ok_or("meta.json: a file name is not a string")?;
            total = total.saturating_add(open(name)?.1);
        }
    }
    let entry = |name: &str| -> Result<Vec<u8>, String> {
        let (file, size) = open(name)?;
        read_at_most(file, size.min(total.max(16 << 20)), name)
    };
    decode(entry, total)
}

/// All of `file`, refused past `most` bytes.
fn read_at_most(file: impl Read, most: usize, name: &str) -> Result<Vec<u8>, String> {
    let mut out = vec![];
    (file.take(most as u64 + 1))
        .read_to_end(&mut out)
        .map_err(|e| format!("`{name}`: {e}"))?;
    if out.len() > most {
        return Err(format!("`{name}` holds more than {most} bytes"));
    }
    Ok(out)
}

/// The cloud from the files `entry` reads by name (`meta.json` and the pictures it names),
/// `total` bytes in all.
fn decode(
    mut entry: impl FnMut(&str) -> Result<Vec<u8>, String>,
    total: usize,
) -> Result<GaussianCloud, String> {
    let meta: Value =
        serde_json::from_slice(&entry("meta.json")?).map_err(|e| format!("meta.json: {e}"))?;
    let version = meta["version"].as_u64();
    if version != Some(VERSION) {
        return Err(format!(
            "meta.json's version is {}: SOG version 2 is read",
            version.map_or("absent (version 1)".into(), |v| v.to_string())
        ));
    }
    let n = meta["count"].as_u64().ok_or("meta.json has no `count`")? as usize;
    let (_, height) = picture_size(n.max(1));
    if n == 0 || height > MOST_SIDE {
        return Err(format!("{n} Gaussians: SOG holds 1 to about 268 million"));
    }
    if n > MOST_PER_BYTE.saturating_mul(total) {
        return Err(format!(
            "meta.json claims {n} Gaussians in {total} bytes: more than {MOST_PER_BYTE} a byte"
        ));
    }
    let floats = |v: &Value, what: &str, len: usize| -> Result<Vec<f32>, String> {
        let values = (v.as_array())
            .filter(|a| a.len() == len)
            .ok_or(format!("meta.json: `{what}` is not {len} numbers"))?;
        (values.iter())
            .map(|x| {
                x.as_f64()
                    .map(|x| x as f32)
                    .ok_or(format!("meta.json: `{what}` holds a non-number"))
            })
            .collect()
    };
    let book = |v: &Value, what: &str| -> Result<[f32; quantize::CODEBOOK], String> {
        Ok(floats(v, what, quantize::CODEBOOK)?
            .try_into()
            .expect("256"))
    };
    // A picture as RGBA, at least `pixels` of them, at most the pixels SOG's pictures hold.
    let mut picture = |file: &Value, pixels: usize| -> Result<(Vec<u8>, usize), String> {
        let name = file
            .as_str()
            .ok_or("meta.json: a file name is not a string")?;
        let webp = entry(name)?;
        let mut reader =
            image::ImageReader::with_format(Cursor::new(webp), image::ImageFormat::WebP);
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MOST_SIDE as u32);
        limits.max_image_height = Some(MOST_SIDE as u32);
        limits.max_alloc = Some(4 * (pixels as u64).max(1 << 16) + (1 << 20));
        reader.limits(limits);
        let image = reader
            .decode()
            .map_err(|e| format!("`{name}`: {e}"))?
            .to_rgba8();
        if ((image.width() * image.height()) as usize) < pixels {
            return Err(format!(
                "`{name}` is {}x{}: fewer pixels than {pixels}",
                image.width(),
                image.height()
            ));
        }
        Ok((image.to_vec(), image.width() as usize))
    };
    let mins = floats(&meta["means"]["mins"], "means.mins", 3)?;
    let maxs = floats(&meta["means"]["maxs"], "means.maxs", 3)?;
    let (low, _) = picture(&meta["means"]["files"][0], n)?;
    let (high, _) = picture(&meta["means"]["files"][1], n)?;
    let (quats, _) = picture(&meta["quats"]["files"][0], n)?;
    let scale_book = book(&meta["scales"]["codebook"], "scales.codebook")?;
    let (scales, _) = picture(&meta["scales"]["files"][0], n)?;
    let color_book = book(&meta["sh0"]["codebook"], "sh0.codebook")?;
    let (colors, _) = picture(&meta["sh0"]["files"][0], n)?;

    let sh = &meta["shN"];
    let degree = if sh.is_null() {
        0
    } else {
        sh["bands"]
            .as_u64()
            .filter(|b| (1..=3).contains(b))
            .ok_or("meta.json: `shN.bands` is not 1, 2 or 3")? as u32
    };
    let per_channel = sh_coefficients(degree) - 1;
    let mut palette = None;
    if degree > 0 {
        let entries = sh["count"]
            .as_u64()
            .filter(|k| (1..=65536).contains(k))
            .ok_or("meta.json: `shN.count` is not 1 to 65536")? as usize;
        let sh_book = book(&sh["codebook"], "shN.codebook")?;
        let (centroids, centroid_width) = picture(&sh["files"][0], entries * per_channel)?;
        if centroid_width != PALETTE_ROW * per_channel {
            return Err(format!(
                "`shN_centroids` is {centroid_width} wide: {} for {degree} bands",
                PALETTE_ROW * per_channel
            ));
        }
        let (labels, _) = picture(&sh["files"][1], n)?;
        palette = Some((entries, sh_book, centroids, labels));
    }

    let value = |i: usize, a: usize| {
        let q = u16::from_le_bytes([low[4 * i + a], high[4 * i + a]]);
        let range = maxs[a] - mins[a];
        let range = if range == 0.0 { 1.0 } else { range };
        let t = mins[a] + range * (q as f32 / 65535.0);
        t.signum() * t.abs().exp_m1()
    };
    let mut gaussians = Vec::with_capacity(n);
    for i in 0..n {
        let mut coefficients = [Vec3::ZERO; 16];
        coefficients[0] = Vec3::from_array(std::array::from_fn(|a| {
            color_book[colors[4 * i + a] as usize]
        }));
        if let Some((entries, book, centroids, labels)) = &palette {
            let label = labels[4 * i] as usize | (labels[4 * i + 1] as usize) << 8;
            // An entry past the palette reads as no view-dependent color (as splat-transform).
            if label < *entries {
                for j in 0..per_channel {
                    let texel = 4 * (label * per_channel + j);
                    coefficients[j + 1] = Vec3::from_array(std::array::from_fn(|c| {
                        book[centroids[texel + c] as usize]
                    }));
                }
            }
        }
        // Half a step in from 0 and 1, so that the logit stays finite.
        let alpha = (colors[4 * i + 3] as f32 / 255.0).clamp(0.5 / 255.0, 1.0 - 0.5 / 255.0);
        let g = StoredGaussian {
            mean: Vec3::from_array(std::array::from_fn(|a| value(i, a))),
            log_scale: Vec3::from_array(std::array::from_fn(|a| {
                scale_book[scales[4 * i + a] as usize]
            })),
            rotation: unpack_rotation(&quats[4 * i..4 * i + 4]),
            opacity_logit: (alpha / (1.0 - alpha)).ln(),
            sh: coefficients,
        };
        if !g.is_finite() {
            return Err(format!(
                "Gaussian {i}: its ranges or codebooks are NaN or infinite"
            ));
        }
        gaussians.push(g);
    }
    Ok(GaussianCloud {
        antialiased: meta["model"] == "antialiased",
        ..GaussianCloud::new(degree, gaussians)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize, degree: u32) -> GaussianCloud {
        crate::formats::random_cloud(n, degree, 9, [20.0, 4.0, 1.0, 1.0])
    }

    #[test]
    fn sizes_are_splat_transforms() {
        assert_eq!(picture_size(300), (20, 16));
        assert_eq!(palette_size(300), 256);
        assert_eq!(palette_size(5972), 4096);
        assert_eq!(palette_size(100_000), MOST_PALETTE);
    }

    /// Each quantity within its encoding's step: positions within 16 bits of the log range,
    /// rotations and opacity within a byte; log scales, DC colors and SH (256 Gaussians: a
    /// palette of 256, each row its own entry) read as the codebook entry nearest each value.
    #[test]
    fn a_round_trip_keeps_each_gaussian_within_its_encoding() {
        for degree in [0, 3] {
            let before = cloud(256, degree);
            let mut bytes = vec![];
            write_to(&mut bytes, &before).unwrap();
            let after = parse(&bytes).unwrap();
            assert_eq!((after.sh_degree, after.gaussians.len()), (degree, 256));
            let pooled = |f: &dyn Fn(&StoredGaussian) -> Vec<f32>| {
                quantize::codebook(&before.gaussians.iter().flat_map(f).collect::<Vec<_>>())
            };
            let scales = pooled(&|g| g.log_scale.to_array().to_vec());
            let colors = pooled(&|g| g.sh[0].to_array().to_vec());
            let rest = |g: &StoredGaussian| -> Vec<f32> {
                (1..sh_coefficients(degree))
                    .flat_map(|k| g.sh[k].to_array())
                    .collect()
            };
            let sh_book = pooled(&rest);
            let coded = |book: &[f32; 256], v: Vec3| {
                v.to_array()
                    .map(|x| book[quantize::nearest(book, x) as usize])
            };
            let means: Vec<Vec3> = before.gaussians.iter().map(|g| g.mean).collect();
            let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
            for (i, &k) in morton::order(&means).iter().enumerate() {
                let (a, b) = (&before.gaussians[k], &after.gaussians[i]);
                // Half of 2 ln 21 over 65,535 steps, times d|v|/dln(1+|v|) = 21 at |v| = 20.
                let step = 0.5 * 2.0 * 21f32.ln() / 65535.0 * 21.0 * 1.001;
                assert!(
                    (a.mean - b.mean).abs().max_element() <= step,
                    "{} {}",
                    a.mean,
                    b.mean
                );
                assert_eq!(b.log_scale.to_array(), coded(&scales, a.log_scale));
                assert_eq!(b.sh[0].to_array(), coded(&colors, a.sh[0]));
                for c in 1..sh_coefficients(degree) {
                    assert_eq!(
                        b.sh[c].to_array(),
                        coded(&sh_book, a.sh[c]),
                        "coefficient {c}"
                    );
                }
                assert!(
                    (sigmoid(a.opacity_logit) - sigmoid(b.opacity_logit)).abs()
                        <= 1.0 / 255.0 + 1e-6
                );
                let near = crate::formats::rotation_distance(a.rotation, b.rotation);
                // Half a step of sqrt 2 / 255 each; the largest, recomputed, up to three of
                // them (it is at least each other's magnitude).
                assert!(
                    near < 1.5 * std::f32::consts::SQRT_2 / 255.0,
                    "{} {}",
                    a.rotation,
                    b.rotation
                );
            }
        }
    }

    /// The bundle's files unpacked into a folder read from its meta.json as the bundle reads;
    /// a meta.json naming a file outside its folder is refused.
    #[test]
    fn an_unbundled_sog_reads_as_its_bundle() {
        let mut bytes = vec![];
        write_to(&mut bytes, &cloud(300, 2)).unwrap();
        let dir = tempfile::tempdir().unwrap();
        zip::ZipArchive::new(Cursor::new(&bytes))
            .unwrap()
            .extract(dir.path())
            .unwrap();
        let meta = dir.path().join("meta.json");
        assert_eq!(read_folder(&meta).unwrap(), parse(&bytes).unwrap());
        let text = std::fs::read_to_string(&meta).unwrap();
        std::fs::write(&meta, text.replace("\"quats.webp\"", "\"../quats.webp\"")).unwrap();
        let e = read_folder(&meta).unwrap_err();
        assert!(
            e.contains("`../quats.webp`, which is not a file beside it"),
            "{e}"
        );
        std::fs::remove_file(dir.path().join("scales.webp")).unwrap();
        assert!(read_folder(&meta).unwrap_err().contains("scales.webp"));
        let e = crate::formats::write(&meta, &cloud(3, 0))
            .unwrap_err()
            .to_string();
        assert!(e.contains("read, not written"), "{e}");
    }

    #[test]
    fn what_is_not_sog_is_refused() {
        assert!(
            parse(b"PK\x03\x04 no")
                .unwrap_err()
                .contains("not a SOG file")
        );
        let mut bytes = vec![];
        write_to(&mut bytes, &cloud(20, 1)).unwrap();
        assert!(parse(&bytes[..bytes.len() - 30]).is_err());
        let empty = GaussianCloud::new(0, vec![]);
        assert!(write_to(&mut vec![], &empty).is_err());
    }
}
