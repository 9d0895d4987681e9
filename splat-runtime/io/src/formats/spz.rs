//! Niantic's SPZ (`docs/formats-spec.md`, §1): every version read (1 to 3 and an early 4 as
//! one gzip stream, the current 4 as a header, a table of streams and one zstd stream per
//! attribute), version 4 written. Positions in 24-bit fixed point (1/4096), opacity, DC color
//! and log scale in a byte each, rotations in 4 bytes (the three smallest components), SH in
//! a byte each snapped to 5 bits (degree 1) or 4 (higher). Axes are stored as they are (as
//! Niantic's `ply_to_spz` and splat-transform do: the format's RUB convention only applies
//! when a writer names its frame). The antialiasing flag (0x1) is read and written.

use crate::ply::{GaussianCloud, StoredGaussian};
use glam::{Vec3, Vec4};
use std::io::{Read, Write};

const MAGIC: u32 = 0x5053_474E;
/// The version written: per-attribute zstd streams.
const VERSION: u32 = 4;
const FRACTIONAL_BITS: u8 = 12;
/// The header's flag for a scene trained antialiased.
const ANTIALIASED: u8 = 0x1;
/// The zstd level Niantic's writer uses.
const ZSTD_LEVEL: i32 = 12;
/// A DC color byte is `dc 0.15 255 + 127.5` (a scale below SH_C0's, so colors past [0, 1]
/// keep some room).
const COLOR_SCALE: f32 = 0.15;
/// How many times its size a file may unpack to (Niantic's reader's bound on the Gaussians a
/// file may claim, 1024 / 9 a byte, at 9 bytes or more each).
const MOST_RATIO: usize = 1024;
/// The largest |position| 24 bits of 1/4096 hold.
const MOST_POSITION: f32 = (1 << 23) as f32 / (1 << FRACTIONAL_BITS) as f32;

/// SH coefficients per channel past the DC term.
fn rest(degree: u32) -> usize {
    ((degree + 1) * (degree + 1) - 1) as usize
}

/// The attribute blocks of `n` Gaussians of SH degree `degree`, in file order (positions,
/// alphas, colors, scales, rotations, SH): each one's length in bytes.
fn block_lengths(n: usize, degree: u32, version: u32) -> [usize; 6] {
    let position = if version == 1 { 6 } else { 9 };
    let rotation = if version >= 3 { 4 } else { 3 };
    [
        position * n,
        n,
        3 * n,
        3 * n,
        rotation * n,
        3 * rest(degree) * n,
    ]
}

/// `bytes` as a cloud; why not, when they are not an SPZ file splat can read.
pub fn parse(bytes: &[u8]) -> Result<GaussianCloud, String> {
    match bytes {
        [0x4E, 0x47, 0x53, 0x50, ..] => parse_streams(bytes),
        [0x1F, 0x8B, ..] => {
            let mut body = vec![];
            let gz = flate2::read::GzDecoder::new(bytes);
            // Niantic's reader takes at most 1024 / 9 Gaussians a byte of the file: a file
            // that unpacks to more is refused before it fills memory.
            let most = bytes.len().saturating_mul(MOST_RATIO) as u64;
            (gz.take(most + 1))
                .read_to_end(&mut body)
                .map_err(|e| format!("gzip: {e}"))?;
            if body.len() as u64 > most {
                return Err(format!("unpacks to more than {MOST_RATIO} times its size"));
            }
            parse_legacy(&body)
        }
        _ => Err("not an SPZ file (it starts with neither NGSP nor gzip's 1f 8b)".to_string()),
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

/// Checks a header's count and degree.
fn check_header(n: u32, degree: u8) -> Result<(usize, u32), String> {
    if n == 0 || n > i32::MAX as u32 {
        return Err(format!("{n} Gaussians (1 to 2^31 - 1)"));
    }
    if degree > 3 {
        return Err(format!("SH degree {degree}: splat keeps SH up to degree 3"));
    }
    Ok((n as usize, degree as u32))
}

/// Versions 1 to 3 (and an early 4): a 16-byte header and the blocks, gzip-decompressed.
fn parse_legacy(body: &[u8]) -> Result<GaussianCloud, String> {
    if body.len() < 16 || u32_at(body, 0) != MAGIC {
        return Err("not an SPZ stream (no NGSP magic after gzip)".to_string());
    }
    let version = u32_at(body, 4);
    if !(1..=4).contains(&version) {
        return Err(format!("SPZ version {version} (1 to 4 are read)"));
    }
    let (n, degree) = check_header(u32_at(body, 8), body[12])?;
    let lengths = block_lengths(n, degree, version);
    let mut blocks = vec![];
    let mut at = 16;
    for len in lengths {
        let block = body.get(at..at + len).ok_or_else(|| {
            format!(
                "truncated: {n} Gaussians need {} bytes after the header, it holds {}",
                lengths.iter().sum::<usize>(),
                body.len() - 16
            )
        })?;
        blocks.push(block);
        at += len;
    }
    decode(&blocks, n, degree, version, [body[13], body[14]])
}

/// Version 4: a 32-byte header, a table of contents, one zstd stream per attribute.
fn parse_streams(file: &[u8]) -> Result<GaussianCloud, String> {
    if file.len() < 32 {
        return Err("truncated: no whole SPZ header".to_string());
    }
    let version = u32_at(file, 4);
    if version != 4 {
        return Err(format!(
            "SPZ version {version} in an NGSP header (4 expected)"
        ));
    }
    let (n, degree) = check_header(u32_at(file, 8), file[12])?;
    if n.saturating_mul(9) > file.len().saturating_mul(MOST_RATIO) {
        return Err(format!(
            "{n} Gaussians in {} bytes: more than SPZ packs",
            file.len()
        ));
    }
    let streams = file[15] as usize;
    let toc = u32_at(file, 16) as usize;
    let lengths = block_lengths(n, degree, version);
    let present: Vec<usize> = lengths.into_iter().filter(|l| *l > 0).collect();
    if streams != present.len() || toc < 32 {
        return Err(format!(
            "{streams} streams for SH degree {degree} ({} expected), table at {toc}",
            present.len()
        ));
    }
    let mut at = toc + 16 * streams;
    let table = file
        .get(toc..at)
        .ok_or("truncated: no whole table of streams")?;
    let mut blocks = vec![];
    for (k, want) in present.iter().enumerate() {
        let entry = &table[16 * k..16 * k + 16];
        let packed = u64::from_le_bytes(entry[..8].try_into().expect("8 bytes")) as usize;
        let unpacked = u64::from_le_bytes(entry[8..].try_into().expect("8 bytes")) as usize;
        if unpacked != *want {
            return Err(format!(
                "stream {k} unpacks to {unpacked} bytes, {want} expected"
            ));
        }
        let end = at.checked_add(packed).filter(|e| *e <= file.len());
        let stream = end
            .map(|e| &file[at..e])
            .ok_or(format!("truncated: stream {k} runs past the file"))?;
        let block =
            zstd::bulk::decompress(stream, unpacked).map_err(|e| format!("stream {k}: {e}"))?;
        if block.len() != unpacked {
            return Err(format!(
                "stream {k} unpacks to {} bytes, {unpacked} expected",
                block.len()
            ));
        }
        blocks.push(block);
        at += packed;
    }
    let mut all: Vec<&[u8]> = blocks.iter().map(Vec::as_slice).collect();
    all.resize(6, &[]);
    decode(&all, n, degree, version, [file[13], file[14]])
}

/// The Gaussians of the six blocks.
fn decode(
    blocks: &[&[u8]],
    n: usize,
    degree: u32,
    version: u32,
    [fractional, flags]: [u8; 2],
) -> Result<GaussianCloud, String> {
    if fractional > 23 {
        return Err(format!("{fractional} fractional bits (at most 23)"));
    }
    let [positions, alphas, colors, scales, rotations, sh] = blocks else {
        unreachable!("six blocks")
    };
    let step = 1.0 / (1u32 << fractional) as f32;
    let per = rest(degree);
    let gaussians = (0..n)
        .map(|i| {
            let mean = Vec3::from_array(std::array::from_fn(|c| match version {
                1 => half::f16::from_le_bytes([
                    positions[6 * i + 2 * c],
                    positions[6 * i + 2 * c + 1],
                ])
                .to_f32(),
                _ => {
                    let b = &positions[9 * i + 3 * c..];
                    let v = i32::from_le_bytes([
                        b[0],
                        b[1],
                        b[2],
                        if b[2] & 0x80 != 0 { 0xFF } else { 0 },
                    ]);
                    v as f32 * step
                }
            }));
            let alpha = (alphas[i] as f32 / 255.0).clamp(0.5 / 255.0, 1.0 - 0.5 / 255.0);
            let mut coefficients = [Vec3::ZERO; 16];
            coefficients[0] = Vec3::from_array(std::array::from_fn(|c| {
                (colors[3 * i + c] as f32 / 255.0 - 0.5) / COLOR_SCALE
            }));
            for k in 0..per {
                let b = &sh[3 * (per * i + k)..];
                coefficients[k + 1] =
                    Vec3::from_array(std::array::from_fn(|c| (b[c] as f32 - 128.0) / 128.0));
            }
            let xyzw = match version {
                ..=2 => first_three(&rotations[3 * i..3 * i + 3]),
                _ => smallest_three(u32_at(rotations, 4 * i)),
            };
            StoredGaussian {
                mean,
                log_scale: Vec3::from_array(std::array::from_fn(|c| {
                    scales[3 * i + c] as f32 / 16.0 - 10.0
                })),
                rotation: Vec4::new(xyzw.w, xyzw.x, xyzw.y, xyzw.z),
                opacity_logit: (alpha / (1.0 - alpha)).ln(),
                sh: coefficients,
            }
        })
        .collect();
    Ok(GaussianCloud {
        antialiased: flags & ANTIALIASED != 0,
        ..GaussianCloud::new(degree, gaussians)
    })
}

/// Versions 1 and 2: x, y, z as `q 127.5 + 127.5` with w >= 0 implied.
fn first_three(b: &[u8]) -> Vec4 {
    let xyz = Vec3::from_array(std::array::from_fn(|c| b[c] as f32 / 127.5 - 1.0));
    xyz.extend((1.0 - xyz.length_squared()).max(0.0).sqrt())
}

/// Versions 3 and 4: the largest component's index (x, y, z, w order) in the top 2 bits, the
/// other three as sign and 9 bits of |q| / (1 / sqrt 2), the largest made positive.
fn smallest_three(mut word: u32) -> Vec4 {
    let largest = (word >> 30) as usize;
    let mut q = [0.0f32; 4];
    for i in (0..4).rev().filter(|i| *i != largest) {
        let magnitude = (word & 0x1FF) as f32 / 511.0 * std::f32::consts::FRAC_1_SQRT_2;
        q[i] = if word & 0x200 != 0 {
            -magnitude
        } else {
            magnitude
        };
        word >>= 10;
    }
    q[largest] = (1.0 - q.iter().map(|v| v * v).sum::<f32>()).max(0.0).sqrt();
    Vec4::from_array(q)
}

fn pack_smallest_three(q: Vec4) -> u32 {
    let q = q.to_array();
    let largest = (1..4).fold(0, |m, i| if q[i].abs() > q[m].abs() { i } else { m });
    let negate = q[largest] < 0.0;
    let mut word = largest as u32;
    for (_, v) in q.iter().enumerate().filter(|(i, _)| *i != largest) {
        let sign = ((*v < 0.0) != negate) as u32;
        let magnitude =
            ((v.abs() / std::f32::consts::FRAC_1_SQRT_2 * 511.0).round() as u32).min(511);
        word = (word << 10) | (sign << 9) | magnitude;
    }
    word
}

/// Writes `cloud` as SPZ version 4. Refused: no Gaussians (no reader loads them), a position
/// past ±2048 (24 bits of 1/4096), a NaN or infinite value.
pub fn write_to(w: &mut dyn Write, cloud: &GaussianCloud) -> std::io::Result<()> {
    let refuse = |why: String| Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, why));
    let n = cloud.gaussians.len();
    if n == 0 || n > i32::MAX as usize {
        return refuse(format!("{n} Gaussians: SPZ holds 1 to 2^31 - 1"));
    }
    cloud.check_finite()?;
    let degree = cloud.sh_degree.min(3);
    let byte = |v: f32| v.round().clamp(0.0, 255.0) as u8;
    let [
        mut positions,
        mut alphas,
        mut colors,
        mut scales,
        mut rotations,
        mut sh,
    ] = block_lengths(n, degree, VERSION).map(Vec::with_capacity);
    for (i, g) in cloud.gaussians.iter().enumerate() {
        if g.mean.abs().max_element() >= MOST_POSITION {
            return refuse(format!(
                "Gaussian {i} at {} is past SPZ's ±{MOST_POSITION}",
                g.mean
            ));
        }
        for v in g.mean.to_array() {
            let fixed = (v * (1 << FRACTIONAL_BITS) as f32).round() as i32;
            positions.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
        alphas.push(byte(255.0 / (1.0 + (-g.opacity_logit).exp())));
        colors.extend(
            g.sh[0]
                .to_array()
                .map(|c| byte(c * COLOR_SCALE * 255.0 + 127.5)),
        );
        scales.extend(g.log_scale.to_array().map(|s| byte((s + 10.0) * 16.0)));
        let q = g.rotation.try_normalize().unwrap_or(Vec4::X);
        rotations
            .extend_from_slice(&pack_smallest_three(Vec4::new(q.y, q.z, q.w, q.x)).to_le_bytes());
        for k in 0..rest(degree) {
            // Degree 1's 3 coefficients in 5 bits, the rest in 4.
            let bucket = if k < 3 { 8 } else { 16 };
            for c in 0..3 {
                let q = (g.sh[k + 1][c] * 128.0).round() as i32 + 128;
                sh.push(((q + bucket / 2) / bucket * bucket).clamp(0, 255) as u8);
            }
        }
    }
    let streams: Vec<Vec<u8>> = [positions, alphas, colors, scales, rotations, sh]
        .into_iter()
        .filter(|b| !b.is_empty())
        .collect();
    let packed: Vec<Vec<u8>> = (streams.iter())
        .map(|s| zstd::bulk::compress(s, ZSTD_LEVEL))
        .collect::<std::io::Result<_>>()?;
    let mut header = Vec::with_capacity(32);
    header.extend_from_slice(&MAGIC.to_le_bytes());
    header.extend_from_slice(&VERSION.to_le_bytes());
    header.extend_from_slice(&(n as u32).to_le_bytes());
    let flags = if cloud.antialiased { ANTIALIASED } else { 0 };
    header.extend_from_slice(&[degree as u8, FRACTIONAL_BITS, flags, streams.len() as u8]);
    header.extend_from_slice(&32u32.to_le_bytes());
    header.resize(32, 0);
    w.write_all(&header)?;
    for (s, p) in streams.iter().zip(&packed) {
        w.write_all(&(p.len() as u64).to_le_bytes())?;
        w.write_all(&(s.len() as u64).to_le_bytes())?;
    }
    for p in &packed {
        w.write_all(p)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(degree: u32) -> GaussianCloud {
        crate::formats::random_cloud(300, degree, 3, [100.0, 5.0, 2.0, 0.5])
    }

    #[test]
    fn a_round_trip_keeps_each_gaussian_within_its_quantization() {
        for degree in 0..=3 {
            let before = cloud(degree);
            let mut bytes = vec![];
            write_to(&mut bytes, &before).unwrap();
            let after = parse(&bytes).unwrap();
            assert_eq!(after.sh_degree, degree);
            let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
            for (a, b) in before.gaussians.iter().zip(&after.gaussians) {
                assert!((a.mean - b.mean).abs().max_element() <= 0.5 / 4096.0 + 1e-5);
                assert!((a.log_scale - b.log_scale).abs().max_element() <= 0.5 / 16.0 + 1e-5);
                let dc = a.sh[0].clamp(Vec3::splat(-127.5 / 38.25), Vec3::splat(127.5 / 38.25));
                assert!((dc - b.sh[0]).abs().max_element() <= 0.5 / 38.25 + 1e-5);
                assert!(
                    (sigmoid(a.opacity_logit) - sigmoid(b.opacity_logit)).abs()
                        <= 0.5 / 255.0 + 1e-5
                );
                let near = crate::formats::rotation_distance(a.rotation, b.rotation);
                assert!(near < 2e-3, "{} {}", a.rotation, b.rotation);
                for k in 1..=rest(degree) {
                    let bucket = if k <= 3 { 8.0 } else { 16.0 };
                    let off = (a.sh[k] - b.sh[k]).abs().max_element();
                    // Half a bucket, after rounding to 1/128.
                    assert!(
                        off <= (0.5 * bucket + 0.5) / 128.0 + 1e-5,
                        "coefficient {k}: {off}"
                    );
                }
            }
        }
    }

    #[test]
    fn smallest_three_packs_as_niantics_writer() {
        // (x, y, z, w) = (0.1, 0.2, 0.3, 0.9), normalized: bytes de 50 a2 c4 (docs/formats-spec.md).
        let q = Vec4::new(0.1, 0.2, 0.3, 0.9).normalize();
        assert_eq!(
            pack_smallest_three(q).to_le_bytes(),
            [0xde, 0x50, 0xa2, 0xc4]
        );
        let back = smallest_three(pack_smallest_three(q));
        assert!((back - q).abs().max_element() < 2e-3);
    }

    #[test]
    fn what_is_not_spz_is_refused() {
        assert!(parse(b"PLY").unwrap_err().contains("not an SPZ file"));
        let mut bytes = vec![];
        write_to(&mut bytes, &cloud(1)).unwrap();
        assert!(
            parse(&bytes[..bytes.len() - 5])
                .unwrap_err()
                .contains("past the file")
        );
        let mut far = cloud(0);
        far.gaussians[7].mean.z = 3000.0;
        let err = write_to(&mut vec![], &far).unwrap_err().to_string();
        assert!(err.contains("Gaussian 7") && err.contains("2048"), "{err}");
        let none = GaussianCloud::new(0, vec![]);
        assert!(write_to(&mut vec![], &none).is_err());
    }
}
