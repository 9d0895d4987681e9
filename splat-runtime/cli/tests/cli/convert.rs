//! `splat convert` and `splat fit --export`: scenes between formats (.splat, SPZ, compressed
//! PLY, SOG), cross-checked against an independent
//! implementation (PlayCanvas's splat-transform from npm: `npm install` in `tests/formats`,
//! which `.ci/run` does); bad input refused with nothing written.

use crate::common::*;
use splat_runtime::io::ply::{GaussianCloud, read};

/// splat-transform, or `None` (an error with `SPLAT_REQUIRE_NPM=1`) when not installed.
fn splat_transform() -> Option<PathBuf> {
    let bin = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/formats/node_modules/.bin/splat-transform");
    let missing = format!("no {}: npm install in tests/formats", bin.display());
    required(bin.exists().then_some(bin), "SPLAT_REQUIRE_NPM", &missing)
}

fn run_splat_transform(bin: &Path, args: &[&str], dir: &Path) {
    let out = Command::new(bin)
        .args(["-q", "-w"])
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "splat-transform {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The largest differences between two clouds' Gaussians, in order: position, log scale, DC
/// color (as `0.5 + SH_C0 dc`, clamped to [0, 1]), opacity (after the sigmoid), unit rotation.
fn largest_differences(a: &GaussianCloud, b: &GaussianCloud) -> [f32; 5] {
    assert_eq!(a.gaussians.len(), b.gaussians.len());
    let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
    let color = |v: splat_runtime::glam::Vec3| {
        (v * 0.282_094_8 + 0.5).clamp(
            splat_runtime::glam::Vec3::ZERO,
            splat_runtime::glam::Vec3::ONE,
        )
    };
    let mut most = [0.0f32; 5];
    for (x, y) in a.gaussians.iter().zip(&b.gaussians) {
        let d = [
            (x.mean - y.mean).abs().max_element(),
            (x.log_scale - y.log_scale).abs().max_element(),
            (color(x.sh[0]) - color(y.sh[0])).abs().max_element(),
            (sigmoid(x.opacity_logit) - sigmoid(y.opacity_logit)).abs(),
            (x.rotation.normalize() - y.rotation.normalize())
                .abs()
                .max_element(),
        ];
        for (m, d) in most.iter_mut().zip(d) {
            *m = m.max(d);
        }
    }
    most
}

/// `.splat` written here reads in splat-transform as the scene it came from (within a byte's
/// step), and splat-transform's `.splat` reads here as its scene; a render of either equals
/// one of ours.
#[test]
fn dot_splat_agrees_with_splat_transform_both_ways() {
    let Some(st) = splat_transform() else { return };
    let dir = temp();
    let d = dir.path();
    ok(&splat(&["scene", "--out", "planet.ply"], d));
    let out = ok(&splat(&["convert", "planet.ply", "ours.splat"], d));
    assert!(
        out.contains("9400 Gaussians") && out.contains("32.0 bytes a Gaussian"),
        "{out}"
    );
    let original = read(&d.join("planet.ply")).unwrap();

    // Ours, read by theirs.
    run_splat_transform(&st, &["ours.splat", "theirs-read.ply"], d);
    let theirs = read(&d.join("theirs-read.ply")).unwrap();
    let [pos, scale, color, alpha, rot] = largest_differences(&original, &theirs);
    println!(
        "ours -> splat-transform: position {pos}, log scale {scale}, color {color}, alpha {alpha}, rotation {rot}"
    );
    assert_eq!(pos, 0.0);
    assert!(scale < 1e-5, "{scale}");
    // Half a byte step, rounded here (and splat-transform's logit clamp at 1e-6).
    assert!(
        color <= 0.5 / 255.0 + 1e-5 && alpha <= 0.5 / 255.0 + 1e-5,
        "{color} {alpha}"
    );
    // splat-transform reads a rotation byte as b / 127.5 - 1 where it was written as
    // q 128 + 128: about 0.004 apart, then renormalized.
    assert!(rot < 0.012, "{rot}");

    // Theirs, read by ours.
    run_splat_transform(&st, &["planet.ply", "theirs.splat"], d);
    ok(&splat(&["convert", "theirs.splat", "ours-read.ply"], d));
    let ours = read(&d.join("ours-read.ply")).unwrap();
    let [pos, scale, color, alpha, rot] = largest_differences(&original, &ours);
    println!(
        "splat-transform -> ours: position {pos}, log scale {scale}, color {color}, alpha {alpha}, rotation {rot}"
    );
    assert_eq!(pos, 0.0);
    assert!(scale < 1e-5, "{scale}");
    // splat-transform truncates: within a whole step.
    assert!(
        color <= 1.0 / 255.0 + 1e-5 && alpha <= 1.0 / 255.0 + 1e-5,
        "{color} {alpha}"
    );
    assert!(rot < 1.5 / 128.0, "{rot}");

    // The same scene, read by either: their reading of our file renders as ours does.
    renders_agree(d, "ours.splat", "theirs-read.ply", 0.002);
}

/// `ours` and `theirs` (scenes in `d`) render alike: a mean difference below `most`.
fn renders_agree(d: &Path, ours: &str, theirs: &str, most: f64) {
    let render = |scene: &str, out: &str| {
        let args = ["render", "--scene", scene, "--out", out, "--backend", "cpu"];
        ok(&splat(&args, d));
        image::open(d.join(out)).unwrap().to_rgb8()
    };
    let (mean, largest) = difference(&render(ours, "a.png"), &render(theirs, "b.png"));
    println!("a render of {ours} against one of {theirs}: mean {mean:.5}, largest {largest:.3}");
    assert!(mean < most, "mean {mean}, largest {largest}");
}

/// The largest difference of two clouds' SH coefficients past the DC term.
fn largest_sh_difference(a: &GaussianCloud, b: &GaussianCloud) -> f32 {
    (a.gaussians.iter().zip(&b.gaussians))
        .flat_map(|(x, y)| (1..16).map(move |k| (x.sh[k] - y.sh[k]).abs().max_element()))
        .fold(0.0, f32::max)
}

/// SPZ written here (version 4) reads in splat-transform as the scene it came from, within
/// SPZ's quantization, and splat-transform's SPZ (through Adobe's build of Niantic's library)
/// reads here the same; renders of either reading agree.
#[test]
fn spz_agrees_with_splat_transform_both_ways() {
    let Some(st) = splat_transform() else { return };
    let dir = temp();
    let d = dir.path();
    ok(&splat(&["scene", "--out", "planet.ply"], d));
    let out = ok(&splat(&["convert", "planet.ply", "ours.spz"], d));
    assert!(out.contains("9400 Gaussians (SH degree 1)"), "{out}");
    let original = read(&d.join("planet.ply")).unwrap();
    // Half a step of each quantity: 1/4096 positions, 1/16 log scales, DC color bytes of 1/38.25
    // (times SH_C0 as compared), opacity bytes, degree-1 SH in buckets of 8/128 after
    // rounding to 1/128.
    let within = |label: &str, got: &GaussianCloud| {
        let [pos, scale, color, alpha, rot] = largest_differences(&original, got);
        let sh = largest_sh_difference(&original, got);
        println!(
            "{label}: position {pos}, log scale {scale}, color {color}, alpha {alpha}, rotation {rot}, SH {sh}"
        );
        assert!(pos <= 0.5 / 4096.0 + 1e-5, "{pos}");
        assert!(scale <= 0.5 / 16.0 + 1e-5, "{scale}");
        assert!(
            color <= 0.5 / 38.25 * 0.2821 + 1e-5 && alpha <= 0.5 / 255.0 + 1e-5,
            "{color} {alpha}"
        );
        assert!(rot < 3e-3, "{rot}");
        assert!(sh <= 4.5 / 128.0 + 1e-5, "{sh}");
    };
    run_splat_transform(&st, &["ours.spz", "theirs-read.ply"], d);
    within(
        "ours -> splat-transform",
        &read(&d.join("theirs-read.ply")).unwrap(),
    );
    run_splat_transform(&st, &["planet.ply", "theirs.spz"], d);
    ok(&splat(&["convert", "theirs.spz", "ours-read.ply"], d));
    within(
        "splat-transform -> ours",
        &read(&d.join("ours-read.ply")).unwrap(),
    );

    // The same scene, read by either: their reading of our file renders as ours does.
    renders_agree(d, "ours.spz", "theirs-read.ply", 0.002);
}

/// The bytes after a PLY file's header.
fn body(path: &Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap();
    bytes[end + 11..].to_vec()
}

/// The compressed PLY written here is splat-transform's, byte for byte past the header's
/// comment (same Morton order, chunk ranges and packing); splat-transform reads it as splat
/// does, to f32 rounding; under a plain `.ply` name it reads the same; and it renders as the
/// PLY it came from.
#[test]
fn compressed_ply_is_splat_transforms_byte_for_byte() {
    let Some(st) = splat_transform() else { return };
    let dir = temp();
    let d = dir.path();
    ok(&splat(&["scene", "--out", "planet.ply"], d));
    let out = ok(&splat(&["convert", "planet.ply", "ours.compressed.ply"], d));
    assert!(out.contains("9400 Gaussians (SH degree 1)"), "{out}");
    run_splat_transform(&st, &["planet.ply", "theirs.compressed.ply"], d);
    let (ours, theirs) = (
        body(&d.join("ours.compressed.ply")),
        body(&d.join("theirs.compressed.ply")),
    );
    // 37 chunks of 18 floats, 9400 Gaussians of 4 words and 9 SH bytes.
    assert_eq!(ours.len(), 37 * 72 + 9400 * (16 + 9));
    assert!(ours == theirs, "the bodies differ");

    run_splat_transform(&st, &["ours.compressed.ply", "theirs-read.ply"], d);
    std::fs::copy(d.join("ours.compressed.ply"), d.join("renamed.ply")).unwrap();
    ok(&splat(&["convert", "renamed.ply", "ours-read.ply"], d));
    let (ours, theirs) = (
        read(&d.join("ours-read.ply")).unwrap(),
        read(&d.join("theirs-read.ply")).unwrap(),
    );
    let [pos, scale, color, alpha, rot] = largest_differences(&ours, &theirs);
    let sh = largest_sh_difference(&ours, &theirs);
    println!(
        "read here and by splat-transform: position {pos}, log scale {scale}, color {color}, alpha {alpha}, rotation {rot}, SH {sh}"
    );
    assert!(
        pos < 1e-5 && scale < 1e-5 && color < 1e-6 && alpha < 1e-6,
        "{pos} {scale} {color} {alpha}"
    );
    assert!(rot < 1e-6 && sh < 1e-6, "{rot} {sh}");
    renders_agree(d, "ours.compressed.ply", "theirs-read.ply", 0.002);
    // What the quantization costs this scene: a mean 0.0036 (0 to 1) from the PLY's render.
    renders_agree(d, "ours.compressed.ply", "planet.ply", 0.005);
}

/// SOG both ways: our `.sog` read by splat-transform is our reading of it (to f32 rounding),
/// splat-transform's `.sog` (its CPU k-means), bundled or unbundled (a folder with meta.json),
/// read here is its own reading of it; each renders near the PLY it came from.
#[test]
fn sog_agrees_with_splat_transform_both_ways() {
    let Some(st) = splat_transform() else { return };
    let dir = temp();
    let d = dir.path();
    ok(&splat(&["scene", "--out", "planet.ply"], d));
    let out = ok(&splat(&["convert", "planet.ply", "ours.sog"], d));
    assert!(out.contains("9400 Gaussians (SH degree 1)"), "{out}");
    run_splat_transform(&st, &["-g", "cpu", "planet.ply", "theirs.sog"], d);
    let same = |label: &str, a: &str, b: &str| {
        let (a, b) = (read(&d.join(a)).unwrap(), read(&d.join(b)).unwrap());
        let [pos, scale, color, alpha, rot] = largest_differences(&a, &b);
        let sh = largest_sh_difference(&a, &b);
        println!(
            "{label}: position {pos}, log scale {scale}, color {color}, alpha {alpha}, rotation {rot}, SH {sh}"
        );
        assert!(
            pos < 1e-4 && scale < 1e-6 && color < 1e-6,
            "{pos} {scale} {color}"
        );
        assert!(
            alpha < 1e-6 && rot < 1e-6 && sh < 1e-6,
            "{alpha} {rot} {sh}"
        );
    };
    // And unbundled: its meta.json and pictures in a folder.
    std::fs::create_dir(d.join("unbundled")).unwrap();
    run_splat_transform(&st, &["-g", "cpu", "planet.ply", "unbundled/meta.json"], d);
    for (file, theirs, ours) in [
        ("ours.sog", "theirs-read-ours.ply", "ours-read-ours.ply"),
        (
            "theirs.sog",
            "theirs-read-theirs.ply",
            "ours-read-theirs.ply",
        ),
        (
            "unbundled/meta.json",
            "theirs-read-folder.ply",
            "ours-read-folder.ply",
        ),
    ] {
        run_splat_transform(&st, &[file, theirs], d);
        ok(&splat(&["convert", file, ours], d));
        same(
            &format!("{file} read by splat-transform and here"),
            theirs,
            ours,
        );
    }
    // What SOG costs this scene, written here and by splat-transform.
    renders_agree(d, "ours.sog", "planet.ply", 0.004);
    renders_agree(d, "theirs.sog", "planet.ply", 0.004);
}

/// `splat fit --export` writes the trained scene in each format beside scene.ply, each reading
/// back as the scene within its quantization (a render near the PLY's); 3DGS-AA's says it is
/// antialiased; a method whose primitives are not Gaussians is refused before training.
#[test]
fn fit_exports_the_scene_in_every_format() {
    let dir = temp();
    let d = dir.path();
    let args = [
        "fit",
        "--backend",
        "cpu",
        "--steps",
        "10",
        "--points",
        "300",
    ];
    let exports = ["--export", "spz,sog,compressed-ply,splat", "--out", "run"];
    ok(&splat(&[&args[..], &exports].concat(), d));
    let scene = read(&d.join("run/scene.ply")).unwrap();
    // Measured: 0.0012, 0.00055, 0.0175 (its SH bytes read 0 as 1/64: 15 coefficients a channel
    // at SH degree 3, a bias where the scene has little view-dependent color yet), 0.0006.
    for (name, most) in [
        ("scene.spz", 0.003),
        ("scene.sog", 0.003),
        ("scene.compressed.ply", 0.025),
        ("scene.splat", 0.003),
    ] {
        let path = d.join("run").join(name);
        let out = ok(&splat(&["convert", path.to_str().unwrap(), "back.ply"], d));
        assert!(out.contains("300 Gaussians"), "{name}: {out}");
        assert_eq!(
            read(&d.join("back.ply")).unwrap().gaussians.len(),
            scene.gaussians.len()
        );
        renders_agree(d, &format!("run/{name}"), "run/scene.ply", most);
    }

    // 3DGS-AA's scene says it is antialiased where the format has the place.
    let aa = ["--method", "3dgs-aa", "--export", "spz", "--out", "aa"];
    ok(&splat(&[&args[..], &aa].concat(), d));
    let render = [
        "render",
        "--scene",
        "aa/scene.spz",
        "--out",
        "aa.png",
        "--backend",
        "cpu",
    ];
    let out = ok(&splat(&render, d));
    assert!(
        out.contains("trained antialiased") && out.contains("3dgs-aa"),
        "{out}"
    );
    let out = ok(&splat(&["convert", "aa/scene.spz", "aa.splat"], d));
    assert!(out.contains(".splat has no place to say so"), "{out}");

    let refused = |extra: &[&str], why: &str| {
        let out = d.join("refused");
        fails(
            &splat(&[&args[..], extra, &["--out", "refused"]].concat(), d),
            why,
            &out,
        );
    };
    refused(
        &["--method", "linprim", "--export", "spz"],
        "linprim's primitives are octahedra",
    );
    refused(&["--export", "ply"], "scene.ply is always written");
    refused(
        &["--export", "obj"],
        "one of compressed-ply, ply, splat, spz",
    );
}

#[test]
fn bad_input_is_refused_with_nothing_written() {
    let dir = temp();
    let d = dir.path();
    ok(&splat(&["scene", "--out", "planet.ply"], d));
    fails(
        &splat(&["convert", "planet.ply", "x.obj"], d),
        "unknown scene format",
        &d.join("x.obj"),
    );
    fails(
        &splat(&["convert", "nothing.ply", "x.splat"], d),
        "nothing.ply",
        &d.join("x.splat"),
    );
    write(d, "odd.splat", &[0; 40]);
    write(d, "junk.spz", b"not an spz file");
    fails(
        &splat(&["convert", "junk.spz", "x.ply"], d),
        "not an SPZ file",
        &d.join("x.ply"),
    );
    fails(
        &splat(&["convert", "odd.splat", "x.ply"], d),
        "40 bytes are not a .splat file",
        &d.join("x.ply"),
    );
    let out = ok(&splat(&["convert", "planet.ply", "p.splat"], d));
    assert!(out.contains("keeps SH to degree 0"), "{out}");
}
