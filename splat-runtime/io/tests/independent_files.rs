//! Files other programs wrote (`fixtures/README.md`) read here as the scene they were written
//! from, within each format's quantization; and splat's compressed PLY writer writes
//! splat-transform's file byte for byte.

use glam::Vec3;
use splat_io::formats::{self, compressed_ply};
use splat_io::ply::{self, GaussianCloud};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn source() -> GaussianCloud {
    ply::read(&fixture("small.ply")).unwrap()
}

/// Largest differences, Gaussian by Gaussian in order: position, log scale, DC color (as
/// `0.5 + SH_C0 dc`), opacity (after the sigmoid), unit rotation (q or -q), SH past the DC.
fn largest_differences(a: &GaussianCloud, b: &GaussianCloud) -> [f32; 6] {
    assert_eq!(a.gaussians.len(), b.gaussians.len());
    let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
    let mut most = [0.0f32; 6];
    for (x, y) in a.gaussians.iter().zip(&b.gaussians) {
        let (p, q) = (x.rotation.normalize(), y.rotation.normalize());
        let d = [
            (x.mean - y.mean).abs().max_element(),
            (x.log_scale - y.log_scale).abs().max_element(),
            ((x.sh[0] - y.sh[0]) * 0.282_094_8).abs().max_element(),
            (sigmoid(x.opacity_logit) - sigmoid(y.opacity_logit)).abs(),
            (p - q).abs().max_element().min((p + q).abs().max_element()),
            (1..16)
                .map(|k| (x.sh[k] - y.sh[k]).abs().max_element())
                .fold(0.0, f32::max),
        ];
        for (m, d) in most.iter_mut().zip(d) {
            *m = m.max(d);
        }
    }
    most
}

/// SPZ of versions 4 (splat-transform) and 2 (spz-js, gzip): within half a step of each
/// quantity (positions 1/4096, log scales 1/16, DC color 1/38.25 (times SH_C0), opacity a
/// byte, degree-1 SH buckets of 8/128 after rounding to 1/128; version 2's rotation in 3
/// bytes of 1/127.5).
#[test]
fn spz_of_niantics_lineage_reads_as_its_source() {
    let source = source();
    for (name, rotation) in [("small.v4.spz", 3e-3), ("small.v2.spz", 1.2e-2)] {
        let read = formats::read(&fixture(name)).unwrap();
        assert_eq!(read.sh_degree, 1, "{name}");
        let [pos, scale, color, alpha, rot, sh] = largest_differences(&source, &read);
        println!(
            "{name}: position {pos}, log scale {scale}, color {color}, alpha {alpha}, rotation {rot}, SH {sh}"
        );
        assert!(pos <= 0.5 / 4096.0 + 1e-6, "{name}: {pos}");
        assert!(scale <= 0.5 / 16.0 + 1e-6, "{name}: {scale}");
        assert!(color <= 0.5 / 38.25 * 0.2821 + 1e-6, "{name}: {color}");
        assert!(alpha <= 0.5 / 255.0 + 1e-6, "{name}: {alpha}");
        assert!(rot < rotation, "{name}: {rot}");
        assert!(sh <= 4.5 / 128.0 + 1e-6, "{name}: {sh}");
    }
}

/// splat-transform's `.splat` (it truncates to bytes): positions exact, colors (clamped to
/// [0, 1], as the format holds them) and opacity within a byte step, rotation within 1.5 of
/// 1/128.
#[test]
fn splat_transforms_dot_splat_reads_as_its_source() {
    let read = formats::read(&fixture("small.splat")).unwrap();
    let mut source = source();
    for g in &mut source.gaussians {
        let color = (g.sh[0] * 0.282_094_8 + 0.5).clamp(Vec3::ZERO, Vec3::ONE);
        g.sh[0] = (color - 0.5) / 0.282_094_8;
    }
    let [pos, scale, color, alpha, rot, _] = largest_differences(&source, &read);
    assert_eq!(pos, 0.0);
    assert!(scale < 1e-5, "{scale}");
    assert!(
        color <= 1.0 / 255.0 + 1e-6 && alpha <= 1.0 / 255.0 + 1e-6,
        "{color} {alpha}"
    );
    assert!(rot < 1.5 / 128.0, "{rot}");
}

/// The compressed PLY written here is splat-transform's file past its header's comment; read
/// here, it is the source in Morton order within half a step of each chunk's range.
#[test]
fn compressed_ply_is_splat_transforms_and_reads_as_its_source() {
    let source = source();
    let theirs = std::fs::read(fixture("small.compressed.ply")).unwrap();
    let mut ours = vec![];
    compressed_ply::write_to(&mut ours, &source).unwrap();
    let body =
        |b: &[u8]| b[b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11..].to_vec();
    assert!(body(&ours) == body(&theirs), "the bodies differ");
    let header = |b: &[u8]| String::from_utf8(b[..b.len() - body(b).len()].to_vec()).unwrap();
    let without_comment = |h: String| {
        h.lines()
            .filter(|l| !l.starts_with("comment"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(
        without_comment(header(&ours)),
        without_comment(header(&theirs))
    );

    let read = formats::read(&fixture("small.compressed.ply")).unwrap();
    let means: Vec<Vec3> = source.gaussians.iter().map(|g| g.mean).collect();
    let sorted = GaussianCloud {
        gaussians: (formats::morton::order(&means).iter())
            .map(|&i| source.gaussians[i])
            .collect(),
        ..source
    };
    let [pos, scale, color, alpha, rot, sh] = largest_differences(&sorted, &read);
    println!(
        "compressed PLY: position {pos}, log scale {scale}, color {color}, alpha {alpha}, rotation {rot}, SH {sh}"
    );
    // The scene's whole extent bounds every chunk's: half a step of 1023 (y has 10 bits) for
    // positions and log scales, of 255 for colors.
    let extent = |f: &dyn Fn(&ply::StoredGaussian) -> Vec3| {
        let values = source.gaussians.iter().map(f);
        let (lo, hi) = values.fold((Vec3::MAX, Vec3::MIN), |(l, h), v| (l.min(v), h.max(v)));
        (hi - lo).max_element()
    };
    assert!(pos <= 0.5 * extent(&|g| g.mean) / 1023.0, "{pos}");
    assert!(scale <= 0.5 * extent(&|g| g.log_scale) / 1023.0, "{scale}");
    assert!(
        color <= 0.5 * 0.2821 * extent(&|g| g.sh[0]) / 255.0 + 1e-6,
        "{color}"
    );
    assert!(alpha <= 0.5 / 255.0 + 1e-6 && rot < 2e-3, "{alpha} {rot}");
    // Truncated to 8 / 256, read at the step's middle.
    assert!(sh <= 4.0 / 256.0 + 1e-6, "{sh}");
}

/// splat-transform's SOG (its CPU k-means) reads here as splat-transform reads it (its PLY of
/// it, kept beside it), to f32 rounding.
#[test]
fn splat_transforms_sog_reads_as_it_reads_it() {
    let ours = formats::read(&fixture("small.sog")).unwrap();
    let theirs = ply::read(&fixture("small.sog-read-by-splat-transform.ply")).unwrap();
    assert_eq!(ours.sh_degree, theirs.sh_degree);
    let [pos, scale, color, alpha, rot, sh] = largest_differences(&ours, &theirs);
    assert!(
        pos < 1e-5 && scale == 0.0 && color == 0.0 && sh == 0.0,
        "{pos} {scale} {color} {sh}"
    );
    assert!(alpha < 1e-6 && rot < 1e-6, "{alpha} {rot}");
}
