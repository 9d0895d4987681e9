//! The `splat` command end to end: the default render, every output format, the PLY round
//! trip, and every kind of bad input (clear error, non-zero exit, no output file).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn splat(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_splat"))
        .args(args)
        .current_dir(dir)
        // As on a bare server: no session variables (the Vulkan layers must stay quiet).
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .output()
        .expect("run splat")
}

/// Whether `out` failed for want of a GPU adapter (the test then skips its GPU part); with
/// `SPLAT_REQUIRE_GPU=1` (CI, on lavapipe) that is a failure.
fn no_adapter(out: &Output) -> bool {
    if out.status.success() {
        return false;
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no GPU adapter"), "{stderr}");
    assert!(
        std::env::var("SPLAT_REQUIRE_GPU").map_or(true, |v| v != "1"),
        "{stderr}"
    );
    true
}

fn ok(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "stdout:\n{stdout}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// Asserts a failure whose message contains `needle`, and that `out_file` was not created.
fn fails(out: &Output, needle: &str, out_file: &Path) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "expected failure, got success; stdout: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(
        stderr.contains(needle),
        "stderr does not mention `{needle}`:\n{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        !out_file.exists(),
        "a partial output {} was left behind",
        out_file.display()
    );
}

fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + len]).unwrap();
    assert_eq!((10 + len) % 64, 0, "header padded to 64 bytes");
    let shape_text = header
        .split("'shape': (")
        .nth(1)
        .unwrap()
        .split(')')
        .next()
        .unwrap();
    let shape: Vec<usize> = shape_text
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let data = bytes[10 + len..]
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    (shape, data)
}

fn temp() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

#[test]
fn renders_the_default_scene() {
    let dir = temp();
    let stdout = ok(&splat(
        &["render", "--width", "160", "--height", "120"],
        dir.path(),
    ));
    assert!(
        stdout.contains("primitives")
            && stdout.contains("intersections")
            && stdout.contains("shade")
    );
    assert!(
        stdout.contains("on GPU") || stdout.contains("backend auto: the CPU, since"),
        "auto must say why it chose the CPU:\n{stdout}"
    );
    let png = dir.path().join("render.png");
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
}

#[test]
fn every_method_renders_on_the_cameras_it_supports() {
    let dir = temp();
    for (method, model) in [
        ("3dgut", "kannala_brandt"),
        ("3dgeer", "equiangular"),
        ("linprim", "pinhole"),
        ("3dgs-aa", "pinhole"),
    ] {
        let out = format!("{method}.png");
        let stdout = ok(&splat(
            &[
                "render",
                "--method",
                method,
                "--camera-model",
                model,
                "--width",
                "96",
                "--height",
                "64",
                "--backend",
                "cpu",
                "--out",
                &out,
            ],
            dir.path(),
        ));
        assert!(
            stdout.starts_with(&format!("{method} on the CPU")),
            "{stdout}"
        );
        assert!(stdout.contains(&format!("{model} camera")), "{stdout}");
        assert!(dir.path().join(&out).exists());
    }
    // --explain names the effects and the kernels compiled for the camera model alone.
    let stdout = ok(&splat(
        &[
            "render",
            "--method",
            "3dgut",
            "--camera-model",
            "kannala_brandt",
            "--width",
            "32",
            "--height",
            "24",
            "--backend",
            "cpu",
            "--explain",
            "--out",
            "explained.png",
        ],
        dir.path(),
    ));
    for line in [
        "camera model      kannala_brandt (kernels compiled for it alone: project_kannala_brandt, project_adjoint_kannala_brandt, pixel_info_kannala_brandt",
        "depth output      off (no depth sums, no depth buffer)",
    ] {
        assert!(stdout.contains(line), "`{line}` is not in:\n{stdout}");
    }
    let stdout = ok(&splat(
        &[
            "render",
            "--method",
            "3dgs",
            "--width",
            "32",
            "--height",
            "24",
            "--backend",
            "cpu",
            "--explain",
            "--depth",
            "--out",
            "explained.png",
        ],
        dir.path(),
    ));
    assert!(
        stdout
            .contains("camera model      pinhole (kernels compiled for it alone: project_pinhole"),
        "{stdout}"
    );
    assert!(stdout.contains("depth output      on"), "{stdout}");
    // A pinhole-only method refuses a fisheye by name and writes nothing.
    let out = splat(
        &[
            "render",
            "--method",
            "linprim",
            "--camera-model",
            "kannala_brandt",
            "--out",
            "no.png",
        ],
        dir.path(),
    );
    fails(&out, "pinhole camera only", &dir.path().join("no.png"));
    // A camera file names its own model.
    let out = splat(
        &[
            "render",
            "--camera",
            "cam.json",
            "--camera-model",
            "equiangular",
            "--out",
            "no.png",
        ],
        dir.path(),
    );
    fails(&out, "cannot be used with", &dir.path().join("no.png"));
}

#[test]
fn the_gallery_renders_every_method_and_camera() {
    let dir = temp();
    let stdout = ok(&splat(
        &[
            "gallery", "--width", "48", "--height", "32", "--out", "g.png",
        ],
        dir.path(),
    ));
    assert_eq!(stdout.matches("intersections").count(), 13, "{stdout}");
    assert_eq!(stdout.matches("pinhole camera only").count(), 2, "{stdout}");
    // 5 methods by 3 camera models, with a 96-pixel strip of method names on the left and a
    // 26-pixel strip of model names on top: each row and column has dark text in its strip.
    let g = image::open(dir.path().join("g.png")).unwrap().to_rgb8();
    assert_eq!(g.dimensions(), (96 + 3 * 48, 26 + 5 * 32));
    let inked = |xs: std::ops::Range<u32>, ys: std::ops::Range<u32>| {
        ys.flat_map(|y| xs.clone().map(move |x| (x, y)))
            .any(|(x, y)| g.get_pixel(x, y).0.iter().all(|c| *c < 128))
    };
    for r in 0..5 {
        assert!(
            inked(0..96, 26 + 32 * r..26 + 32 * (r + 1)),
            "row {r} label"
        );
    }
    for c in 0..3 {
        assert!(
            inked(96 + 48 * c..96 + 48 * (c + 1), 0..26),
            "column {c} label"
        );
    }
    fails(
        &splat(&["gallery", "--out", "g.exr"], dir.path()),
        "the gallery is a labelled picture, write it as .png",
        &dir.path().join("g.exr"),
    );
}

#[test]
fn npy_holds_color_then_alpha_then_depth() {
    let dir = temp();
    ok(&splat(
        &[
            "render", "--width", "64", "--height", "48", "--alpha", "--depth", "--out", "f.npy",
        ],
        dir.path(),
    ));
    let (shape, data) = read_npy(&dir.path().join("f.npy"));
    assert_eq!(shape, [48, 64, 5]);
    assert_eq!(data.len(), 48 * 64 * 5);
    // The planet covers the centre: alpha near 1 and a depth near 5 there.
    let centre = (24 * 64 + 32) * 5;
    assert!(
        data[centre + 3] > 0.9 && (4.0..7.0).contains(&data[centre + 4]),
        "{:?}",
        &data[centre..centre + 5]
    );
    ok(&splat(
        &[
            "render", "--width", "64", "--height", "48", "--depth", "--out", "f.exr",
        ],
        dir.path(),
    ));
    assert!(dir.path().join("f.exr").exists() && dir.path().join("f.depth.exr").exists());
}

#[test]
fn ply_round_trip_renders_the_same_image() {
    let dir = temp();
    ok(&splat(
        &["scene", "--out", "planet.ply", "--camera-out", "cam.json"],
        dir.path(),
    ));
    ok(&splat(&["render", "--out", "a.npy"], dir.path()));
    ok(&splat(
        &[
            "render",
            "--scene",
            "planet.ply",
            "--camera",
            "cam.json",
            "--out",
            "b.npy",
        ],
        dir.path(),
    ));
    assert_eq!(
        read_npy(&dir.path().join("a.npy")),
        read_npy(&dir.path().join("b.npy"))
    );
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn bad_scenes_are_refused_clearly() {
    let dir = temp();
    ok(&splat(&["scene", "--out", "good.ply"], dir.path()));
    let good = std::fs::read(dir.path().join("good.ply")).unwrap();
    let out = dir.path().join("out.png");
    fails(
        &splat(&["scene", "--out", "out.png"], dir.path()),
        "--out `out.png`: the scene is written as an INRIA PLY, name it .ply",
        &out,
    );
    let render = |scene: &str| {
        splat(
            &["render", "--scene", scene, "--out", "out.png"],
            dir.path(),
        )
    };

    write(dir.path(), "truncated.ply", &good[..good.len() - 100]);
    fails(&render("truncated.ply"), "truncated.ply: truncated", &out);

    let text = String::from_utf8_lossy(&good).replacen(
        "property float scale_1\n",
        "property float scale_x\n",
        1,
    );
    write(dir.path(), "missing.ply", text.as_bytes());
    fails(&render("missing.ply"), "missing property `scale_1`", &out);

    write(dir.path(), "garbage.ply", b"not a ply at all");
    fails(&render("garbage.ply"), "garbage.ply: not a PLY", &out);
    std::fs::create_dir(dir.path().join("folder.ply")).unwrap();
    fails(&render("folder.ply"), "folder.ply: it is a folder", &out);

    let header_end = good.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let mut nan = good.clone();
    nan[header_end + 4..header_end + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    write(dir.path(), "nan.ply", &nan);
    fails(&render("nan.ply"), "vertex 0: property `y`", &out);

    fails(&render("does-not-exist.ply"), "cannot read", &out);
}

#[test]
fn bad_cameras_and_options_are_refused_clearly() {
    let dir = temp();
    ok(&splat(
        &["scene", "--out", "s.ply", "--camera-out", "cam.json"],
        dir.path(),
    ));
    let cam = std::fs::read_to_string(dir.path().join("cam.json")).unwrap();
    let out = dir.path().join("out.png");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--out", "out.png"];
        args.extend_from_slice(extra);
        splat(&args, dir.path())
    };

    write(
        dir.path(),
        "zero.json",
        cam.replace("\"width\": 800", "\"width\": 0").as_bytes(),
    );
    fails(
        &render(&["--camera", "zero.json"]),
        "zero.json: camera image size 0x600",
        &out,
    );
    write(
        dir.path(),
        "huge.json",
        cam.replace("\"width\": 800", "\"width\": 1000000")
            .as_bytes(),
    );
    fails(
        &render(&["--camera", "huge.json"]),
        "image size 1000000x600",
        &out,
    );
    write(
        dir.path(),
        "fish.json",
        cam.replace("pinhole", "fisheye").as_bytes(),
    );
    fails(
        &render(&["--camera", "fish.json"]),
        "camera model `fisheye`",
        &out,
    );
    write(dir.path(), "broken.json", b"{\"width\": ");
    fails(
        &render(&["--camera", "broken.json"]),
        "not valid JSON",
        &out,
    );
    fails(
        &render(&["--camera", "nope.json"]),
        "cannot read camera",
        &out,
    );
    fails(&render(&["--width", "0"]), "image size 0x600", &out);
    fails(&render(&["--tile", "7"]), "tile size 7", &out);
    fails(&render(&["--p-max", "0"]), "P_max 0", &out);
    write(
        dir.path(),
        "scaled.json",
        cam.replacen("[\n      -1.0,", "[\n      -2.0,", 1)
            .as_bytes(),
    );
    assert_ne!(
        cam,
        std::fs::read_to_string(dir.path().join("scaled.json")).unwrap()
    );
    fails(
        &render(&["--camera", "scaled.json"]),
        "scaled.json: camera world_to_camera is not rigid",
        &out,
    );
    write(
        dir.path(),
        "kb.json",
        cam.replace("\"pinhole\"", "\"kannala_brandt\"").as_bytes(),
    );
    fails(
        &render(&["--camera", "kb.json", "--method", "3dgut"]),
        "needs its coefficients `k`",
        &out,
    );
    // Refused by the name typed, with what works instead; no internal instance names.
    let fisheye = render(&["--camera-model", "kannala_brandt", "--method", "linprim"]);
    fails(&fisheye, "linprim renders with a pinhole camera only", &out);
    let stderr = String::from_utf8_lossy(&fisheye.stderr);
    assert!(
        stderr.contains("--method 3dgs or --method 3dgs-aa or --method 3dgut or --method 3dgeer"),
        "{stderr}"
    );
    assert!(!stderr.contains("linprim::"), "{stderr}");
    // Each error says its cause once.
    let missing = render(&["--scene", "missing.ply"]);
    fails(&missing, "missing.ply", &out);
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert_eq!(stderr.matches("os error 2").count(), 1, "{stderr}");
    let broken = render(&["--camera", "broken.json"]);
    let stderr = String::from_utf8_lossy(&broken.stderr);
    assert_eq!(stderr.matches("EOF while parsing").count(), 1, "{stderr}");
    let bad_ext = dir.path().join("out.bmp");
    fails(
        &splat(&["render", "--out", "out.bmp"], dir.path()),
        "unknown extension",
        &bad_ext,
    );
}

#[test]
fn inspect_prints_the_generated_rust_and_wgsl() {
    let dir = temp();
    let rust = ok(&splat(&["inspect", "--method", "3dgs"], dir.path()));
    assert!(
        rust.contains("pub fn evaluate_adjoint")
            && rust.contains("impl ::splat_runtime::SplatMethod for Method")
    );
    let wgsl = ok(&splat(
        &["inspect", "--method", "3dgs", "--lang", "wgsl"],
        dir.path(),
    ));
    assert!(wgsl.contains("fn evaluate(") && wgsl.contains("fn project_adjoint("));
    let geer = ok(&splat(&["inspect", "--method", "3dgeer"], dir.path()));
    assert!(geer.contains("pub fn pixel_info("));
}

#[test]
fn gpu_backend_renders_when_an_adapter_exists() {
    let dir = temp();
    let out = splat(
        &[
            "render",
            "--backend",
            "gpu",
            "--width",
            "96",
            "--height",
            "64",
            "--out",
            "g.npy",
        ],
        dir.path(),
    );
    if no_adapter(&out) {
        return;
    }
    assert!(String::from_utf8_lossy(&out.stdout).contains("on GPU"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    ok(&splat(
        &[
            "render", "--width", "96", "--height", "64", "--out", "c.npy",
        ],
        dir.path(),
    ));
    let (gs, g) = read_npy(&dir.path().join("g.npy"));
    let (cs, c) = read_npy(&dir.path().join("c.npy"));
    assert_eq!(gs, cs);
    let worst = g
        .iter()
        .zip(&c)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 0.02, "GPU and CPU renders differ by {worst}");

    // The hardware rasterizer, blending into f16 targets (every adapter has them).
    let hardware = [
        "--hardware",
        "--precision",
        "f16",
        "--width",
        "96",
        "--height",
        "64",
    ];
    let stdout = ok(&splat(
        &[&["render", "--out", "h.npy"][..], &hardware].concat(),
        dir.path(),
    ));
    assert!(stdout.contains("hardware rasterizer"), "{stdout}");
    assert!(stdout.contains("f16 render targets"), "{stdout}");
    let (hs, h) = read_npy(&dir.path().join("h.npy"));
    assert_eq!(hs, cs);
    let worst = h
        .iter()
        .zip(&c)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 0.02, "hardware and CPU renders differ by {worst}");
    fails(
        &splat(
            &[
                &["render", "--backend", "cpu", "--out", "x.png"][..],
                &hardware,
            ]
            .concat(),
            dir.path(),
        ),
        "--hardware rasterizes with the GPU",
        &dir.path().join("x.png"),
    );
}

/// A minimal Blender-format dataset: `views` uniform gray RGBA images of 16 x 16 pixels, with
/// cameras on a circle looking at the origin (OpenGL camera-to-world).
fn tiny_dataset(dir: &Path, views: usize) {
    let png = {
        let mut bytes = vec![];
        let img = image::RgbaImage::from_pixel(16, 16, image::Rgba([90, 120, 150, 255]));
        img.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .unwrap();
        bytes
    };
    for split in ["train", "test"] {
        std::fs::create_dir_all(dir.join(split)).unwrap();
        let frames: Vec<String> = (0..views)
            .map(|k| {
                std::fs::write(dir.join(format!("{split}/r_{k}.png")), &png).unwrap();
                let a = k as f32 * 0.6;
                let (s, c) = a.sin_cos();
                // OpenGL camera at radius 3 on the xz circle, its z axis pointing away from
                // the origin.
                format!(
                    r#"{{"file_path": "./{split}/r_{k}", "transform_matrix": [[{c}, 0, {s}, {}], [0, 1, 0, 0], [{}, 0, {c}, {}], [0, 0, 0, 1]]}}"#,
                    3.0 * s,
                    -s,
                    3.0 * c
                )
            })
            .collect();
        std::fs::write(
            dir.join(format!("transforms_{split}.json")),
            format!(
                r#"{{"camera_angle_x": 0.7, "frames": [{}]}}"#,
                frames.join(",")
            ),
        )
        .unwrap();
    }
}

/// What `splat fit --out out` wrote in `dir`: the scene, a render per test view, the metrics
/// (one row per step, and the test views' PSNR where measured) and the curve.
struct FitOutput {
    scene: splat_runtime::io::ply::GaussianCloud,
    /// (step, test PSNR) where measured.
    psnr: Vec<(usize, f64)>,
    /// Rows of metrics.csv after the header.
    rows: usize,
}

fn fit_output(out: &Path, test_views: usize, size: (u32, u32)) -> FitOutput {
    let scene = splat_runtime::io::ply::read(&out.join("scene.ply")).unwrap();
    for k in 0..test_views {
        let png = image::open(out.join(format!("test/{k:03}.png"))).unwrap();
        assert_eq!((png.width(), png.height()), size);
    }
    assert!(!out.join(format!("test/{test_views:03}.png")).exists());
    let curve = image::open(out.join("curve.png")).unwrap();
    assert_eq!((curve.width(), curve.height()), (900, 640));
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("step,loss,l1,ssim,primitives,test_psnr,test_ssim")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().all(|r| r.len() == 7), "{csv}");
    let psnr = rows
        .iter()
        .filter(|r| !r[5].is_empty())
        .map(|r| (r[0].parse().unwrap(), r[5].parse().unwrap()))
        .collect();
    FitOutput {
        scene,
        psnr,
        rows: rows.len(),
    }
}

#[test]
fn fit_trains_on_a_dataset_and_writes_its_outputs() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = ["fit", "data", "--steps", "20", "--points", "200"];
    let stdout = ok(&splat(&[&args[..], &["--out", "out"]].concat(), dir.path()));
    assert!(
        stdout.contains("3 training and 3 test views of 16x16"),
        "{stdout}"
    );
    assert!(stdout.contains("PSNR"), "{stdout}");
    // Not a terminal: a progress line every 10 steps (a twentieth of the run, rounded up
    // to tens) instead of the bar.
    let lines: Vec<&str> = stdout
        .lines()
        .filter(|l| l.contains(" ms per step, loss "))
        .collect();
    assert_eq!(lines.len(), 2, "{stdout}");
    assert!(lines[0].starts_with("step 10/20: ") && lines[1].starts_with("step 20/20: "));
    step_times_add_up(&stdout);
    let fit = fit_output(&dir.path().join("out"), 3, (16, 16));
    assert_eq!((fit.scene.sh_degree, fit.scene.gaussians.len()), (3, 200));
    // Step 0 (before training), then 20 steps; PSNR before and after only.
    assert_eq!(fit.rows, 21);
    assert_eq!(fit.psnr.iter().map(|p| p.0).collect::<Vec<_>>(), [0, 20]);

    // The same on the GPU loop, where there is an adapter (lavapipe in CI).
    let gpu = splat(
        &[&args[..], &["--out", "gpu", "--backend", "gpu"]].concat(),
        dir.path(),
    );
    if !no_adapter(&gpu) {
        let stdout = String::from_utf8_lossy(&gpu.stdout);
        assert!(stdout.contains("20 steps on the GPU"), "{stdout}");
        step_times_add_up(&stdout);
        let fit = fit_output(&dir.path().join("gpu"), 3, (16, 16));
        assert_eq!(fit.scene.gaussians.len(), 200);
    }
}

/// The table of where `splat fit`'s steps spent their time: the forward and backward blends
/// among its rows (lavapipe has timestamps), and its rows add up to the step (to the
/// rounding of their figures).
fn step_times_add_up(stdout: &str) {
    let rows: Vec<(&str, f64)> = stdout
        .lines()
        .skip_while(|l| !l.starts_with("Where a step's time went (mean of 20 steps"))
        .skip(3)
        .map_while(|l| {
            let cells: Vec<&str> = l.split(" | ").collect();
            let stage = cells.first()?.strip_prefix("| ")?;
            Some((stage, cells.get(1)?.parse().ok()?))
        })
        .collect();
    let (last, stages) = rows.split_last().expect(stdout);
    assert_eq!(last.0, "step", "{stdout}");
    for stage in ["shade", "backward blend"] {
        assert!(stages.iter().any(|s| s.0 == stage), "{stdout}");
    }
    let sum: f64 = stages.iter().map(|s| s.1).sum();
    assert!(
        (sum - last.1).abs() <= 0.005 * rows.len() as f64,
        "{stdout}"
    );
}

/// Ctrl-C during `splat fit` ends the run after the step in progress with its checkpoint and
/// metrics saved (and no result written); `--resume` goes on from that step, and SIGTERM (a
/// batch scheduler's stop) ends it as Ctrl-C does. On both loops (the GPU's where there is an
/// adapter); on the CPU's, resumed to the end, the run ends where one never stopped does.
#[cfg(unix)]
#[test]
fn an_interrupted_fit_saves_its_checkpoint_and_resumes_from_it() {
    use std::io::{BufRead, Read};
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    for (backend, steps) in [("cpu", "2000"), ("gpu", "400")] {
        let args = [
            "fit",
            "data",
            "--steps",
            steps,
            "--points",
            "100",
            "--backend",
            backend,
            "--eval-every",
            "0",
            "--checkpoint-every",
            "100000",
            "--out",
            backend,
        ];
        // Runs `fit`, sends `signal` at its first progress line: the step the stop message
        // names, or None where there is no GPU adapter.
        let interrupted = |extra: &[&str], signal: i32| -> Option<usize> {
            use std::os::unix::process::CommandExt;
            let mut command = Command::new(env!("CARGO_BIN_EXE_splat"));
            // SAFETY: only resets a signal's action between fork and exec. A test run
            // started in the background (`cmd &`) ignores SIGINT, and `fit` keeps an
            // ignored SIGINT ignored, as it should: the child gets the default back.
            unsafe {
                command.pre_exec(move || {
                    libc::signal(signal, libc::SIG_DFL);
                    Ok(())
                });
            }
            let mut child = command
                .args(args.iter().chain(extra))
                .current_dir(dir.path())
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap();
            let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
            let first = lines
                .by_ref()
                .map(Result::unwrap)
                .find(|l| l.starts_with("step "));
            if first.is_some() {
                // SAFETY: a plain signal to the child's pid.
                assert_eq!(unsafe { libc::kill(child.id() as i32, signal) }, 0);
            }
            lines.for_each(drop);
            let mut stderr = String::new();
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut stderr)
                .unwrap();
            let status = child.wait().unwrap();
            assert!(
                !status.success() && !stderr.contains("panicked"),
                "{stderr}"
            );
            if first.is_none() && stderr.contains("no GPU adapter") {
                assert!(std::env::var("SPLAT_REQUIRE_GPU").map_or(true, |v| v != "1"));
                return None;
            }
            let name = if signal == libc::SIGTERM {
                "SIGTERM"
            } else {
                "Ctrl-C"
            };
            let stop = format!("stopped by {name} after step ");
            let step: usize = (stderr.split(&stop).nth(1))
                .and_then(|rest| rest.split(' ').next())
                .and_then(|k| k.parse().ok())
                .unwrap_or_else(|| panic!("no stop message in {stderr}"));
            assert!(
                stderr.contains("the same command with --resume goes on"),
                "{stderr}"
            );
            Some(step)
        };
        let out = dir.path().join(backend);
        // The metrics' last step: one row per step from 0.
        let last_row = || {
            let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
            let steps: Vec<usize> = (csv.lines().skip(1))
                .map(|l| l.split(',').next().unwrap().parse().unwrap())
                .collect();
            assert_eq!(steps, (0..steps.len()).collect::<Vec<_>>());
            steps.len() - 1
        };
        let Some(first) = interrupted(&[], libc::SIGINT) else {
            continue;
        };
        assert!(first < steps.parse().unwrap(), "{backend}");
        assert!(out.join("checkpoint.bin").exists());
        assert!(
            !out.join("scene.ply").exists() && !out.join("test").exists(),
            "an interrupted run wrote its result, or left a folder for it"
        );
        assert_eq!(last_row(), first);
        // Resumed, it goes on from there: its metrics continue the first run's, row for row.
        let second = interrupted(&["--resume"], libc::SIGTERM).unwrap();
        assert!(second > first, "{backend}: {second} after {first}");
        assert_eq!(last_row(), second);
        if backend == "cpu" {
            // Resumed to the end, twice stopped, the CPU's run ends on the very scene of a run
            // never stopped (the GPU's adds its gradients in the atomics' order).
            ok(&splat(&[&args[..], &["--resume"]].concat(), dir.path()));
            let whole = [&args[..args.len() - 1], &["whole"]].concat();
            ok(&splat(&whole, dir.path()));
            let scene = |run: &str| std::fs::read(dir.path().join(run).join("scene.ply")).unwrap();
            assert!(
                scene("cpu") == scene("whole"),
                "the resumed run's scene differs"
            );
            assert_eq!(last_row(), steps.parse::<usize>().unwrap());
        }
    }
}

/// `--strategy mcmc` starts the primitives as the MCMC paper does (opacity 0.5, not 3DGS's
/// 0.1) and trains; `--strategy fixed` keeps the count; an unknown strategy is refused.
#[test]
fn fit_takes_a_strategy() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = [
        "fit",
        "data",
        "--steps",
        "5",
        "--points",
        "100",
        "--backend",
        "cpu",
    ];
    let median_opacity = |out: &str| {
        let fit = fit_output(&dir.path().join(out), 3, (16, 16));
        let mut o: Vec<f32> = (fit.scene.gaussians.iter())
            .map(|g| 1.0 / (1.0 + (-g.opacity_logit).exp()))
            .collect();
        o.sort_by(f32::total_cmp);
        (o.len(), o[o.len() / 2])
    };
    for (strategy, out) in [("mcmc", "mcmc"), ("adc", "adc"), ("fixed", "fixed")] {
        let run = [&args[..], &["--strategy", strategy, "--out", out]].concat();
        ok(&splat(&run, dir.path()));
    }
    let (mcmc, adc) = (median_opacity("mcmc"), median_opacity("adc"));
    assert_eq!((mcmc.0, adc.0, median_opacity("fixed").0), (100, 100, 100));
    assert!(
        mcmc.1 > 0.4 && adc.1 < 0.2,
        "median opacity: MCMC {mcmc:?}, ADC {adc:?}"
    );
    let bad = splat(&[&args[..], &["--strategy", "greedy"]].concat(), dir.path());
    assert!(!bad.status.success());
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(
        stderr.contains("possible values: adc, mcmc, fixed"),
        "{stderr}"
    );
}

/// `--freeze` keeps the named groups as they start and says which are trained; an unknown
/// group, or a frozen shape under density control, is refused by name.
#[test]
fn fit_freezes_the_groups_it_is_told_to() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = ["fit", "data", "--points", "100", "--backend", "cpu"];
    let shapes = ["--freeze", "mean,log_scale,rotation", "--strategy", "fixed"];
    let mut scenes = vec![];
    for steps in ["1", "5"] {
        let out = format!("frozen{steps}");
        let run = [&args[..], &shapes, &["--steps", steps, "--out", &out]].concat();
        let stdout = ok(&splat(&[&run[..], &["--explain"]].concat(), dir.path()));
        assert!(
            stdout.contains("training opacity_logit, sh; frozen: mean, log_scale, rotation"),
            "{stdout}"
        );
        // --explain names the gradients the backward pass computes and those it never does.
        let gradients = "gradients         opacity_logit, sh (never computed: mean, log_scale, rotation)\ncamera gradient   off (no ray adjoint per pixel)\nalpha cotangent   on";
        assert!(stdout.contains(gradients), "{stdout}");
        assert!(stdout.contains("density control   fixed"), "{stdout}");
        scenes.push(
            fit_output(&dir.path().join(&out), 3, (16, 16))
                .scene
                .gaussians,
        );
    }
    for (a, b) in scenes[0].iter().zip(&scenes[1]) {
        assert_eq!(
            (a.mean, a.log_scale, a.rotation),
            (b.mean, b.log_scale, b.rotation)
        );
    }
    assert!(scenes[0].iter().zip(&scenes[1]).any(|(a, b)| a.sh != b.sh));
    // Colors alone: no gradient flows through alpha, so the blend skips its cotangent.
    let colors = [
        &args[..],
        &["--freeze", "mean,log_scale,rotation,opacity_logit"],
        &[
            "--strategy",
            "fixed",
            "--steps",
            "1",
            "--out",
            "colors",
            "--explain",
        ],
    ]
    .concat();
    let stdout = ok(&splat(&colors, dir.path()));
    let alpha = "alpha cotangent   off (no gradient asked for flows through alpha)";
    assert!(stdout.contains(alpha), "{stdout}");
    let refused = |extra: &[&str], message: &str| {
        let run = [&args[..], &["--steps", "1", "--out", "refused"], extra].concat();
        fails(
            &splat(&run, dir.path()),
            message,
            &dir.path().join("refused/scene.ply"),
        );
    };
    refused(
        &["--freeze", "sh,colour"],
        "--freeze colour: 3dgs has no parameter group `colour`; its groups are mean, log_scale, rotation, opacity_logit, sh",
    );
    refused(
        &["--freeze", "log_scale"],
        "log_scale cannot stay frozen under density control (adc)",
    );
    // Checked before the dataset is read: a missing one is not what the error is about.
    let before_reading = ["fit", "nowhere", "--freeze", "colour", "--out", "refused"];
    fails(
        &splat(&before_reading, dir.path()),
        "--freeze colour: 3dgs has no parameter group",
        &dir.path().join("refused/scene.ply"),
    );
    refused(
        &[
            "--strategy",
            "fixed",
            "--freeze",
            "sh,mean,log_scale,rotation,opacity_logit",
        ],
        "--freeze mean,log_scale,rotation,opacity_logit,sh: those are all of 3dgs's parameter groups, which leaves nothing to train",
    );
    refused(
        &["--strategy", "fixed", "--max-primitives", "5"],
        "--max-primitives 5: the cap is on density control's growth, and --strategy fixed keeps the primitives it starts with",
    );
}

/// With no dataset, `splat fit` trains on views of the built-in planet; the test views are
/// measured every `--eval-every` steps, and training brings them closer.
#[test]
fn fit_without_a_dataset_trains_on_the_built_in_one() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "fit",
        "--backend",
        "cpu",
        "--steps",
        "60",
        "--points",
        "400",
        "--eval-every",
        "20",
    ];
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains("the built-in dataset: 28 training and 4 test views of 112x84"),
        "{stdout}"
    );
    let fit = fit_output(&dir.path().join("fit"), 4, (112, 84));
    assert_eq!(fit.rows, 61);
    let steps: Vec<usize> = fit.psnr.iter().map(|p| p.0).collect();
    assert_eq!(steps, [0, 20, 40, 60]);
    let (before, after) = (fit.psnr[0].1, fit.psnr[3].1);
    assert!(after > before + 3.0, "test PSNR {before} -> {after}");
}

/// `--resume` goes on from <out>/checkpoint.bin and keeps the metrics up to it; a checkpoint
/// of another run length, of another method, or damaged is refused by name.
#[test]
fn fit_resumes_from_its_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    tiny_dataset(&dir.path().join("data"), 3);
    let args = ["fit", "data", "--points", "50", "--out", "out"];
    let first = [
        &args[..],
        &[
            "--steps",
            "20",
            "--checkpoint-every",
            "10",
            "--eval-every",
            "10",
        ],
    ]
    .concat();
    ok(&splat(&first, dir.path()));
    let out = dir.path().join("out");
    assert!(out.join("checkpoint.bin").exists());
    let stdout = ok(&splat(&[&args[..], &["--resume"]].concat(), dir.path()));
    assert!(
        stdout.contains("resuming from out/checkpoint.bin after step 20 of 20"),
        "{stdout}"
    );
    assert!(!stdout.contains("warning"), "{stdout}");
    let fit = fit_output(&out, 3, (16, 16));
    assert_eq!(fit.rows, 21);
    let steps: Vec<usize> = fit.psnr.iter().map(|p| p.0).collect();
    assert_eq!(steps, [0, 10, 20]);
    // Metrics cut short (edited since): the run resumes and says what its log misses.
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let cut: Vec<&str> = csv.lines().take(12).collect();
    std::fs::write(out.join("metrics.csv"), cut.join("\n")).unwrap();
    let stdout = ok(&splat(&[&args[..], &["--resume"]].concat(), dir.path()));
    assert!(
        stdout.contains(
            "warning: out/metrics.csv holds 10 of the checkpoint's 20 steps: the resumed run's metrics miss the others"
        ),
        "{stdout}"
    );
    // A start above the cap runs: the cap only stops growth.
    let capped = [
        "fit", "data", "--points", "50", "--out", "capped", "--steps", "2",
    ];
    let stdout = ok(&splat(
        &[&capped[..], &["--max-primitives", "1"]].concat(),
        dir.path(),
    ));
    assert!(
        stdout.contains("more than --max-primitives 1: the cap only stops growth"),
        "{stdout}"
    );

    let scene = std::fs::read(out.join("scene.ply")).unwrap();
    let refused = |extra: &[&str], needle: &str| {
        let out = splat(&[&args[..], &["--resume"], extra].concat(), dir.path());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(stderr.contains(needle), "{stderr}");
    };
    refused(
        &["--steps", "30"],
        "out/checkpoint.bin is a checkpoint of a 20-step run",
    );
    refused(
        &["--method", "3dgut"],
        "out/checkpoint.bin is a checkpoint of gs3d, not of gut",
    );
    refused(
        &["--strategy", "mcmc"],
        "out/checkpoint.bin is a checkpoint of a run with --strategy adc, not mcmc",
    );
    refused(
        &["--no-opacity-reset"],
        "a run with --strategy adc, not adc without opacity resets",
    );
    refused(&["--global-scale", "0.5"], "a run with scene extent");
    // Settings that change the steps: resumed with others, the run would train another way.
    let was = "a run on background 0 0 0, at most 4000000 primitives";
    refused(&["--white"], &format!("{was}, not on background 1 1 1,"));
    refused(
        &["--max-primitives", "1"],
        &format!("{was}, not on background 0 0 0, at most 1 primitives"),
    );
    refused(
        &["--freeze", "sh"],
        "not on background 0 0 0, at most 4000000 primitives, with sh frozen",
    );
    // One bit changed in the parameters, past the header.
    let mut checkpoint = std::fs::read(out.join("checkpoint.bin")).unwrap();
    let at = checkpoint.len() / 2;
    checkpoint[at] ^= 1;
    std::fs::write(out.join("checkpoint.bin"), checkpoint).unwrap();
    refused(
        &[],
        "out/checkpoint.bin is damaged: its bytes do not match the checksum",
    );
    std::fs::write(out.join("checkpoint.bin"), "SPLATCK3 and then nothing").unwrap();
    refused(&[], "out/checkpoint.bin is damaged");
    for older in ["SPLATCK1", "SPLATCK2"] {
        std::fs::write(
            out.join("checkpoint.bin"),
            format!("{older} and then nothing"),
        )
        .unwrap();
        refused(&[], "out/checkpoint.bin was written by an earlier splat");
    }
    std::fs::write(out.join("checkpoint.bin"), "ply").unwrap();
    refused(&[], "out/checkpoint.bin is not a splat checkpoint");
    assert_eq!(
        std::fs::read(out.join("scene.ply")).unwrap(),
        scene,
        "nothing lost"
    );
}

/// `splat dataset` writes the built-in views as a Blender folder that `splat fit` reads.
#[test]
fn dataset_writes_the_built_in_views_for_fit() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "dataset", "--out", "planet", "--views", "9", "--width", "24", "--height", "18",
    ];
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains("7 training and 2 test views of 24x18"),
        "{stdout}"
    );
    let png = image::open(dir.path().join("planet/train/r_0.png")).unwrap();
    assert_eq!(
        (png.width(), png.height(), png.color().has_alpha()),
        (24, 18, true)
    );
    let stdout = ok(&splat(
        &["fit", "planet", "--steps", "2", "--backend", "cpu"],
        dir.path(),
    ));
    assert!(
        stdout.contains("7 training and 2 test views of 24x18"),
        "{stdout}"
    );
    fails(
        &splat(&["dataset", "--out", "one", "--views", "1"], dir.path()),
        "--views must be at least 2",
        &dir.path().join("one"),
    );
    fails(
        &splat(&["dataset", "--out", "tiny", "--width", "8"], dir.path()),
        "--width and --height must be at least 11",
        &dir.path().join("tiny"),
    );
}

#[test]
fn fit_refuses_a_missing_or_broken_dataset_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit");
    fails(
        &splat(&["fit", "nowhere"], dir.path()),
        "cannot read nowhere: no such folder",
        &out,
    );
    std::fs::create_dir(dir.path().join("empty")).unwrap();
    fails(
        &splat(&["fit", "empty"], dir.path()),
        "neither transforms_train.json (Blender) nor transforms.json (nerfstudio)",
        &out,
    );
    tiny_dataset(&dir.path().join("data"), 2);
    std::fs::write(dir.path().join("data/transforms_test.json"), "{").unwrap();
    fails(
        &splat(&["fit", "data", "--steps", "2"], dir.path()),
        "transforms_test.json is not valid JSON",
        &out,
    );
    write(dir.path(), "file", b"");
    fails(
        &splat(&["fit", "file"], dir.path()),
        "cannot read file: a dataset is a folder, this is a file",
        &out,
    );
    tiny_dataset(&dir.path().join("bent"), 2);
    let json = dir.path().join("bent/transforms_train.json");
    let text = std::fs::read_to_string(&json).unwrap();
    std::fs::write(&json, text.replacen("[0, 1, 0, 0]", "[0, 2, 0, 0]", 1)).unwrap();
    fails(
        &splat(&["fit", "bent", "--steps", "2"], dir.path()),
        "transforms_train.json: frames[0].transform_matrix is not a rigid pose",
        &out,
    );
    tiny_dataset(&dir.path().join("small"), 2);
    let eight = image::RgbaImage::from_pixel(8, 8, image::Rgba([90, 120, 150, 255]));
    for split in ["train", "test"] {
        for k in 0..2 {
            eight
                .save(dir.path().join(format!("small/{split}/r_{k}.png")))
                .unwrap();
        }
    }
    fails(
        &splat(&["fit", "small", "--steps", "2"], dir.path()),
        "r_0.png is 8x8 pixels: training takes views of 11",
        &out,
    );
    tiny_dataset(&dir.path().join("good"), 2);
    fails(
        &splat(&["fit", "good", "--out", "file"], dir.path()),
        "--out file: it is a file",
        &out,
    );
    fails(
        &splat(&["fit", "good", "--out", "file/run"], dir.path()),
        "--out file/run: file is a file",
        &out,
    );
    // Found before training, not when the results are written at its end.
    std::fs::create_dir_all(dir.path().join("run/scene.ply")).unwrap();
    fails(
        &splat(&["fit", "good", "--out", "run"], dir.path()),
        "--out run: run/scene.ply is a folder, and the run writes its scene.ply there",
        &out,
    );
    // Refused before the dataset is read (this one does not exist).
    for (flag, value) in [
        ("--global-scale", "0"),
        ("--init-extent", "nan"),
        ("--init-size", "0"),
    ] {
        fails(
            &splat(&["fit", "missing", "--steps", "2", flag, value], dir.path()),
            &format!("{flag} must be a positive number, not"),
            &out,
        );
    }
    fails(
        &splat(&["fit", "missing", "--points", "0"], dir.path()),
        "--points must be at least 1",
        &out,
    );
    for color in ["0.5,0.5", "0.5,2,0.5", "gray"] {
        fails(
            &splat(&["fit", "good", "--init-color", color], dir.path()),
            &format!("`{color}` is not R,G,B"),
            &out,
        );
    }
    fails(
        &splat(
            &["fit", "good", "--strategy", "mcmc", "--no-opacity-reset"],
            dir.path(),
        ),
        "--no-opacity-reset is for --strategy adc",
        &out,
    );
}

#[test]
fn bench_times_both_passes_and_writes_the_raw_image_render_would() {
    let dir = temp();
    let size = ["--width", "64", "--height", "48"];
    let mut args = vec![
        "bench",
        "--backend",
        "cpu",
        "--iters",
        "1",
        "--threads",
        "1,2",
    ];
    args.extend(size);
    args.extend(["--raw-out", "ours.f32"]);
    let stdout = ok(&splat(&args, dir.path()));
    for needle in [
        "CPU, 1 thread",
        "CPU, 2 threads",
        "speed-up",
        "forward + backward",
    ] {
        assert!(stdout.contains(needle), "no `{needle}` in:\n{stdout}");
    }
    let mut args = vec!["render", "--backend", "cpu", "--out", "ref.npy"];
    args.extend(size);
    ok(&splat(&args, dir.path()));
    let raw: Vec<f32> = std::fs::read(dir.path().join("ours.f32"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let (shape, reference) = read_npy(&dir.path().join("ref.npy"));
    assert_eq!(shape, [48, 64, 3]);
    assert_eq!(raw, reference, "bench's raw image differs from render's");

    let out = dir.path().join("never.f32");
    let bad: [(&[&str], &str); 6] = [
        (&["--iters", "0"], "--iters"),
        (
            &["--tile", "7"],
            "--tile 7: the CPU backend takes tile sizes [8, 16, 32, 64]",
        ),
        (
            &["--shader-checks"],
            "--shader-checks is for the GPU's shaders",
        ),
        (&["--threads", "2,0"], "--threads 0"),
        (&["--scene", "missing.ply"], "missing.ply"),
        (&["--width", "0"], "image size 0x600 is out of range"),
    ];
    for (extra, needle) in bad {
        let mut args = vec!["bench", "--backend", "cpu", "--raw-out", "never.f32"];
        args.extend(extra);
        let run = splat(&args, dir.path());
        fails(&run, needle, &out);
        // Refused before any work: nothing printed as if it had started.
        assert!(
            run.stdout.is_empty(),
            "{:?}",
            String::from_utf8_lossy(&run.stdout)
        );
    }
    // Thread counts on the GPU (where there is an adapter, software ones included).
    let gpu = splat(&["bench", "--backend", "gpu", "--threads", "2"], dir.path());
    if !String::from_utf8_lossy(&gpu.stderr).contains("no GPU adapter") {
        fails(&gpu, "--threads is for the CPU's thread pools", &out);
    }
}

/// A dataset's view is a camera: `render` and `bench` take `--camera DATASET --view SPLIT/K`
/// (`tradeoff` reads its camera as `bench` does); `render` measures its image against the
/// view's picture, read before anything is written.
#[test]
fn a_dataset_view_is_a_camera() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "dataset", "--out", "planet", "--views", "9", "--width", "96", "--height", "72",
    ];
    ok(&splat(&args, dir.path()));
    let render = |extra: &[&str], out: &str| {
        let mut args = vec!["render", "--backend", "cpu", "--out", out];
        args.extend(extra);
        splat(&args, dir.path())
    };
    // The planet with its stars against pictures of it without them: close, not equal (about
    // 20 dB); against another view's picture, far (about 11).
    let psnr = |stdout: &str| -> f64 {
        (stdout.split("PSNR ").nth(1))
            .and_then(|s| s.split(' ').next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no PSNR in {stdout}"))
    };
    let picked = ["--camera", "planet", "--view", "test/1"];
    let stdout = ok(&render(&picked, "a.npy"));
    assert!(psnr(&stdout) > 18.0, "{stdout}");
    assert!(stdout.contains("96x72"), "{stdout}");
    // Half the size on each side: the picture averaged over 2x2 blocks against the
    // anti-aliased 3DGS (plain 3DGS's 0.3-pixel dilation thickens this planet's sub-pixel
    // Gaussians at 48x36: 13.7 dB; the same at full size is 20.3): 29.2 dB (27.8 at 96x72).
    let half = [&picked[..], &["--downscale", "2", "--method", "3dgs-aa"]].concat();
    let stdout = ok(&render(&half, "half.npy"));
    assert!(stdout.contains("48x36"), "{stdout}");
    assert!(psnr(&stdout) > 27.0, "{stdout}");
    let planet = dir.path().join("planet/test");
    std::fs::copy(planet.join("r_0.png"), planet.join("r_1.png")).unwrap();
    assert!(psnr(&ok(&render(&picked, "a.npy"))) < 14.0);
    // test/0 by default; another view is another image.
    ok(&render(&["--camera", "planet"], "first.npy"));
    ok(&render(
        &["--camera", "planet", "--view", "test/0"],
        "test0.npy",
    ));
    ok(&render(
        &["--camera", "planet", "--view", "train/0"],
        "train0.npy",
    ));
    let image = |name: &str| read_npy(&dir.path().join(name)).1;
    assert_eq!(image("first.npy"), image("test0.npy"));
    assert_ne!(image("test0.npy"), image("train0.npy"));
    assert_ne!(image("test0.npy"), image("a.npy"));
    let stdout = ok(&splat(
        &[
            "bench",
            "--method",
            "3dgs",
            "--backend",
            "cpu",
            "--iters",
            "1",
            "--camera",
            "planet",
            "--view",
            "train/6",
        ],
        dir.path(),
    ));
    assert!(stdout.contains("96x72"), "{stdout}");

    let out = dir.path().join("b.png");
    let cases: [(&[&str], &str); 8] = [
        (
            &["--camera", "planet", "--width", "10"],
            "the argument '--camera <CAMERA>' cannot be used with '--width <WIDTH>'",
        ),
        (
            &["--camera", "planet", "--view", "test/2"],
            "there is no view test/2: the dataset has 2 test views (test/0 to test/1)",
        ),
        (
            &["--camera", "planet", "--view", "side/0"],
            "expected test/K or train/K",
        ),
        (&["--view", "test/0"], "--camera"),
        (
            &[
                "--camera",
                "planet/transforms_test.json",
                "--view",
                "test/0",
            ],
            "is not a dataset folder",
        ),
        (&["--downscale", "2"], "give one with --camera DATASET"),
        (&["--camera", "planet", "--downscale", "0"], "--downscale"),
        (
            &["--camera", "planet", "--downscale", "97"],
            "96x72 pixels cannot be downscaled 97x",
        ),
    ];
    for (extra, needle) in cases {
        fails(&render(extra, "b.png"), needle, &out);
    }
    // A picture whose header reads but whose pixels do not: refused before the render is
    // written.
    let bytes = std::fs::read(planet.join("r_1.png")).unwrap();
    let idat = bytes.windows(4).position(|w| w == b"IDAT").unwrap();
    std::fs::write(planet.join("r_1.png"), &bytes[..idat + 8]).unwrap();
    fails(&render(&picked, "b.png"), "r_1.png", &out);
}

/// `splat eval` measures a trained scene as `splat fit` measured it: the same mean PSNR and
/// the same renders, bit for bit; on the GPU within rounding of the CPU's.
#[test]
fn eval_measures_a_scene_as_fit_did() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "dataset", "--out", "planet", "--views", "10", "--width", "64", "--height", "48",
    ];
    ok(&splat(&args, dir.path()));
    let args = [
        "fit",
        "planet",
        "--backend",
        "cpu",
        "--steps",
        "30",
        "--points",
        "500",
        "--out",
        "fit",
    ];
    let stdout = ok(&splat(&args, dir.path()));
    let fit_psnr = stdout
        .split(" dB, SSIM")
        .next()
        .and_then(|s| s.rsplit(" -> ").next())
        .unwrap_or_else(|| panic!("no PSNR in {stdout}"))
        .to_string();
    let eval = |extra: &[&str]| {
        let mut args = vec!["eval", "planet", "--scene", "fit/scene.ply"];
        args.extend(extra);
        splat(&args, dir.path())
    };
    // An earlier run's render of a third test view goes; other files stay.
    std::fs::create_dir_all(dir.path().join("eval/test")).unwrap();
    for name in ["002.png", "notes.png"] {
        std::fs::write(dir.path().join("eval/test").join(name), b"earlier").unwrap();
    }
    let stdout = ok(&eval(&["--backend", "cpu", "--out", "eval"]));
    assert!(
        stdout.contains(&format!("mean PSNR {fit_psnr} dB")),
        "fit measured {fit_psnr} dB:\n{stdout}"
    );
    assert!(
        stdout.contains("removed 1 renders of an earlier run's views"),
        "{stdout}"
    );
    assert!(!dir.path().join("eval/test/002.png").exists());
    assert!(dir.path().join("eval/test/notes.png").exists());
    assert!(stdout.contains("2 test views"), "{stdout}");
    for k in 0..2 {
        let render = format!("{k:03}.png");
        let read = |path: PathBuf| std::fs::read(path).unwrap();
        assert_eq!(
            read(dir.path().join("eval/test").join(&render)),
            read(dir.path().join("fit/test").join(&render)),
            "{render}"
        );
    }
    let csv = std::fs::read_to_string(dir.path().join("eval/eval.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    assert!(csv.starts_with("view,picture,psnr,ssim\ntest/0,"), "{csv}");

    // The backend is picked once for all views (`auto` says why it took the CPU once).
    let stdout = ok(&eval(&["--split", "train"]));
    assert!(stdout.contains("8 train views"), "{stdout}");
    assert!(stdout.matches("backend auto").count() <= 1, "{stdout}");
    let gpu = eval(&["--backend", "gpu"]);
    if !no_adapter(&gpu) {
        let stdout = String::from_utf8_lossy(&gpu.stdout);
        let psnr: f64 = (stdout.split("mean PSNR ").nth(1))
            .and_then(|s| s.split(' ').next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("{stdout}"));
        let want: f64 = fit_psnr.parse().unwrap();
        assert!((psnr - want).abs() < 0.02, "GPU {psnr} dB, CPU {want}");
    }
    let missing = ["eval", "planet", "--scene", "nothing.ply", "--out", "bad"];
    fails(
        &splat(&missing, dir.path()),
        "nothing.ply",
        &dir.path().join("bad"),
    );

    // A dataset whose test pictures are named as renders are: --out into it is refused,
    // before anything is rendered over its truth.
    let planet = dir.path().join("planet");
    std::fs::rename(planet.join("test/r_0.png"), planet.join("test/000.png")).unwrap();
    let transforms = planet.join("transforms_test.json");
    let text = std::fs::read_to_string(&transforms).unwrap();
    std::fs::write(&transforms, text.replace("./test/r_0\"", "./test/000\"")).unwrap();
    let truth = std::fs::read(planet.join("test/000.png")).unwrap();
    let into = [
        "eval",
        "planet",
        "--scene",
        "fit/scene.ply",
        "--out",
        "planet",
    ];
    let out = splat(&into, dir.path());
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("would replace the dataset's picture"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(planet.join("test/000.png")).unwrap(), truth);
}

/// A COLMAP dataset in text format: 3 views of 16x16 by a pinhole camera looking down +z
/// from z = -3, and 40 sparse points around the origin.
fn tiny_colmap_dataset(dir: &Path) {
    std::fs::create_dir_all(dir.join("sparse/0")).unwrap();
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::write(
        dir.join("sparse/0/cameras.txt"),
        "# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]\n1 PINHOLE 16 16 20 20 8 8\n",
    )
    .unwrap();
    let mut images = String::from("# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME\n");
    for k in 0..3 {
        let name = format!("frame_{k}.png");
        images += &format!(
            "{} 1 0 0 0 {} 0 3 1 {name}\n\n",
            k + 1,
            0.2 * k as f32 - 0.2
        );
        image::RgbImage::from_pixel(16, 16, image::Rgb([90, 120, 150]))
            .save(dir.join("images").join(name))
            .unwrap();
    }
    std::fs::write(dir.join("sparse/0/images.txt"), images).unwrap();
    let points: String = (0..40)
        .map(|k| {
            let (x, y, z) = (k % 4, k / 4 % 5, k / 20);
            format!(
                "{k} {} {} {} 90 120 150 0.5\n",
                0.2 * x as f32,
                0.2 * y as f32,
                0.2 * z as f32
            )
        })
        .collect();
    std::fs::write(dir.join("sparse/0/points3D.txt"), points).unwrap();
}

#[test]
fn fit_starts_from_a_colmap_datasets_points() {
    let dir = tempfile::tempdir().unwrap();
    tiny_colmap_dataset(&dir.path().join("data"));
    let args = ["fit", "data", "--steps", "5", "--out", "out"];
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains("2 training and 1 test view of 16x16"),
        "{stdout}"
    );
    assert!(
        stdout.contains("starting from 40 of the dataset's 40 points"),
        "{stdout}"
    );
    let cloud = splat_runtime::io::ply::read(&dir.path().join("out/scene.ply")).unwrap();
    assert_eq!(cloud.gaussians.len(), 40);

    // --points caps the count.
    let args = [
        "fit", "data", "--steps", "1", "--points", "10", "--out", "out",
    ];
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains("starting from 10 of the dataset's 40 points"),
        "{stdout}"
    );

    // A lens with distortion: the views are cut from the pictures, and fit says so.
    let cameras = dir.path().join("data/sparse/0/cameras.txt");
    std::fs::write(cameras, "1 SIMPLE_RADIAL 16 16 20 8 8 0.2\n").unwrap();
    let stdout = ok(&splat(&args, dir.path()));
    assert!(
        stdout.contains(
            "1 test view of 14x14 (the lens distortion of 3 pictures taken out, 16x16 cropped to 14x14)"
        ),
        "{stdout}"
    );
}

/// `bench --backend gpu` times device-resident frames; with `--shader-checks` it says the
/// shaders carry naga's run-time checks (`methods/benches/h200.sh` times both).
#[test]
fn gpu_bench_times_resident_frames_with_or_without_shader_checks() {
    let dir = temp();
    for (extra, checked) in [(None, false), (Some("--shader-checks"), true)] {
        let mut args = vec![
            "bench",
            "--backend",
            "gpu",
            "--iters",
            "1",
            "--width",
            "48",
            "--height",
            "32",
        ];
        args.extend(extra);
        let out = splat(&args, dir.path());
        if no_adapter(&out) {
            return;
        }
        let stdout = ok(&out);
        assert!(stdout.contains("GPU (device-resident)"), "{stdout}");
        assert_eq!(
            stdout.contains("naga's run-time checks"),
            checked,
            "{stdout}"
        );
    }
}

/// `splat inspect | head` stops reading early: the command ends quietly, no panic.
/// A reader that stops early (`| head`) ends a command quietly, as other Unix tools end:
/// stopped by SIGPIPE, never a panic. The pipe is closed before the command starts, so its
/// first line meets it.
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_a_command_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let dir = temp();
    let commands: [&[&str]; 2] = [
        &["inspect", "--method", "3dgeer"],
        &[
            "bench",
            "--backend",
            "cpu",
            "--width",
            "32",
            "--height",
            "24",
            "--iters",
            "1",
        ],
    ];
    for args in commands {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(env!("CARGO_BIN_EXE_splat"))
            .args(args)
            .current_dir(dir.path())
            .stdout(writer)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            out.status.signal(),
            Some(libc::SIGPIPE),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

/// A command's outputs that belong together (a picture and its depth, a scene and its camera)
/// appear together or not at all: a failure leaves what was there.
#[test]
fn outputs_that_belong_together_appear_together_or_not_at_all() {
    let dir = temp();
    let small = ["--width", "32", "--height", "24", "--backend", "cpu"];
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--out", "o.png"];
        args.extend_from_slice(&small);
        args.extend_from_slice(extra);
        splat(&args, dir.path())
    };
    ok(&render(&[]));
    let kept = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    let picture = kept("o.png");
    // What a failed `scene` would write over it is not this.
    let scene = write(dir.path(), "keep.ply", b"what was there");
    let scene = std::fs::read(scene).unwrap();
    let refused = |out: Output, needle: &str| {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && stderr.contains(needle), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    };
    std::fs::create_dir(dir.path().join("o.depth.png")).unwrap();
    refused(
        render(&["--depth", "--method", "3dgut"]),
        "o.depth.png: it is a folder",
    );
    assert_eq!(kept("o.png"), picture, "the picture was replaced");
    // A file output that names a folder, or lies under a file, is refused before the work.
    let before_work = |out: Output, needle: &str| {
        assert!(
            out.stdout.is_empty(),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
        refused(out, needle);
    };
    let bench = |raw: &str| {
        let args = ["bench", "--iters", "1", "--threads", "1", "--raw-out", raw];
        splat(&[&args[..], &small].concat(), dir.path())
    };
    before_work(bench("raw/"), "--raw-out raw/: it names a folder");
    before_work(
        bench("o.png/raw.f32"),
        "--raw-out o.png/raw.f32: o.png is a file",
    );
    before_work(
        splat(&["gallery", "--out", "o.depth.png"], dir.path()),
        "--out o.depth.png: it names a folder",
    );
    let scene_args = |camera: &'static str| ["scene", "--out", "keep.ply", "--camera-out", camera];
    // A camera under a file: no folder can be made there.
    refused(
        splat(&scene_args("o.png/c.json"), dir.path()),
        "writing o.png/c.json",
    );
    for same in ["keep.ply", "./keep.ply"] {
        refused(
            splat(&scene_args(same), dir.path()),
            "another output of the same command goes there",
        );
    }
    assert_eq!(kept("keep.ply"), scene, "the scene was replaced");
    // A fit whose renders cannot be written leaves the previous run's result (its last
    // checkpoint, with the metrics up to it, is written apart, before).
    tiny_dataset(&dir.path().join("data"), 2);
    let fit = [
        "fit",
        "data",
        "--steps",
        "2",
        "--backend",
        "cpu",
        "--out",
        "run",
    ];
    ok(&splat(&fit, dir.path()));
    // What the run would write is not this.
    write(dir.path(), "run/scene.ply", b"the previous result");
    std::fs::remove_file(dir.path().join("run/test/000.png")).unwrap();
    std::fs::create_dir(dir.path().join("run/test/000.png")).unwrap();
    refused(splat(&fit, dir.path()), "000.png: it is a folder");
    assert_eq!(
        kept("run/scene.ply"),
        b"the previous result",
        "the result was replaced"
    );
    let leftovers: Vec<_> = ["", "run", "run/test"]
        .iter()
        .flat_map(|d| std::fs::read_dir(dir.path().join(d)).unwrap())
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(splat_runtime::io::PARTIAL))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// The depth PNG says how it maps depth, with the range, in its text metadata; outputs are
/// reported by their full path.
#[test]
fn the_depth_png_records_its_mapping() {
    let dir = temp();
    let stdout = ok(&splat(
        &[
            "render", "--depth", "--width", "64", "--height", "48", "--out", "d.png",
        ],
        dir.path(),
    ));
    let full = dir.path().canonicalize().unwrap().join("d.depth.png");
    assert!(
        stdout.contains(&format!("wrote {}", full.display())),
        "{stdout}"
    );
    let bytes = std::fs::read(&full).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    assert!(text.contains("tEXtDescription"), "no text chunk");
    assert!(text.contains("(nearest)") && text.contains("0 = nothing hit"));
}

/// The rows of a CSV file after its header, as fields.
/// The rows of a CSV file after its header (fields split at commas outside double quotes).
fn csv_rows(path: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let fields = |line: &str| {
        let (mut out, mut field, mut quoted) = (vec![], String::new(), false);
        for c in line.chars() {
            match c {
                '"' => quoted = !quoted,
                ',' if !quoted => out.push(std::mem::take(&mut field)),
                c => field.push(c),
            }
        }
        out.push(field);
        out
    };
    text.lines().skip(1).map(fields).collect()
}

const TRADEOFF_HEADER: &str = "knob,setting,forward_ms,forward_vs_default,backward_ms,backward_vs_default,memory_mib,intersections,sort_mib,psnr_db,max_abs,gradient_rel_rmse";

/// The index of `tradeoff.csv`'s column `name`.
fn tradeoff_column(name: &str) -> usize {
    TRADEOFF_HEADER.split(',').position(|c| c == name).unwrap()
}

/// `splat tradeoff` end to end on a small view: every knob and setting in the CSV, gradient
/// errors per parameter group and magnitude range, a plot; what the errors must be where the
/// answer is known (a tile size never changes the image; t_min 0 is the reference itself; a
/// short P_max list loses most of the picture; 3DGEER's default render is close to its exact
/// one); on the GPU the same sweep.
#[test]
fn tradeoff_sweeps_every_knob_and_writes_its_table_and_plot() {
    let dir = temp();
    let size = ["--width", "64", "--height", "48", "--iters", "1"];
    let args = [&["tradeoff", "--backend", "cpu", "--out", "cpu"][..], &size].concat();
    let stdout = ok(&splat(&args, dir.path()));
    assert!(stdout.contains("| knob | setting |"), "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("cpu/tradeoff.csv")).unwrap();
    assert_eq!(csv.lines().next(), Some(TRADEOFF_HEADER));
    let rows = csv_rows(&dir.path().join("cpu/tradeoff.csv"));
    let settings: Vec<(&str, &str)> = rows.iter().map(|r| (&*r[0], &*r[1])).collect();
    let want = [
        ("p_max", "512"),
        ("p_max", "128"),
        ("p_max", "32"),
        ("p_max", "8"),
        ("tile", "8"),
        ("tile", "32"),
        ("tile", "64"),
        ("t_min", "0"),
        ("t_min", "1e-3"),
        ("t_min", "1e-2"),
        ("t_min", "1e-1"),
        ("alpha_min", "2/255"),
        ("alpha_min", "8/255"),
        ("alpha_min", "32/255"),
        ("precision", "f16"),
        ("precision", "unorm16"),
        ("precision", "unorm8"),
        ("shade_precision", "f16"),
        ("shade_precision", "unorm16"),
        ("shade_precision", "unorm8"),
        ("gradient_precision", "f16"),
        ("sh_degree", "0"),
        ("model", "3dgs"),
        ("model", "3dgs-aa"),
        ("model", "3dgut"),
        ("model", "linprim"),
        ("model", "3dgeer"),
    ];
    assert_eq!(settings[0].0, "default");
    assert_eq!(settings[1..], want);
    let field = |knob: &str, value: &str, column: usize| -> f64 {
        let row = rows
            .iter()
            .find(|r| r[0] == knob && (r[1] == value || knob == "default"));
        row.unwrap()[column].parse().unwrap()
    };
    let (psnr, gradient) = (
        tradeoff_column("psnr_db"),
        tradeoff_column("gradient_rel_rmse"),
    );
    // On the CPU each time is against the default row's.
    let forward_x = tradeoff_column("forward_vs_default");
    assert_eq!(field("default", "", forward_x), 1.0);
    assert!(
        rows.iter()
            .all(|r| r[forward_x].parse::<f64>().unwrap() > 0.0)
    );
    for tile in ["8", "32", "64"] {
        assert_eq!(field("tile", tile, psnr), field("default", "", psnr));
    }
    assert_eq!(field("t_min", "0", psnr), f64::INFINITY);
    assert_eq!(field("t_min", "0", gradient), 0.0);
    assert!(field("default", "", psnr) > 80.0, "measured 84.0 dB");
    assert!(field("p_max", "8", psnr) < field("p_max", "512", psnr));
    assert!(field("p_max", "8", gradient) > field("default", "", gradient));
    // Gradient sums never change the image; shade data coded in 255 steps of its range does.
    let default_psnr = field("default", "", psnr);
    assert_eq!(field("gradient_precision", "f16", psnr), default_psnr);
    assert!(field("shade_precision", "unorm8", psnr) < field("shade_precision", "unorm16", psnr));
    // The model rows are against 3DGEER's most accurate render: 3DGEER at the defaults is
    // close (measured 86.5 dB), the approximations are not, each by what it approximates
    // (measured: 3DGS 15.8 dB, 3DGS-AA 23.9, 3DGUT 20.7, LinPrim 22.9).
    assert!(field("model", "3dgeer", psnr) > 80.0);
    for (model, measured) in [
        ("3dgs", 15.8),
        ("3dgs-aa", 23.9),
        ("3dgut", 20.7),
        ("linprim", 22.9),
    ] {
        let got = field("model", model, psnr);
        assert!(
            (got - measured).abs() < 1.0,
            "{model}: {got} dB from 3DGEER's render"
        );
    }

    let detail = csv_rows(&dir.path().join("cpu/gradients.csv"));
    assert!(detail.iter().all(|r| r.len() == 6), "{detail:?}");
    let groups: Vec<&str> = detail
        .iter()
        .filter(|r| r[0] == "default")
        .map(|r| &*r[2])
        .collect();
    for g in ["mean", "log_scale", "rotation", "opacity_logit", "sh"] {
        assert_eq!(
            groups.iter().filter(|n| **n == g).count(),
            3,
            "{g}: {groups:?}"
        );
    }
    // Degree 0 has a smaller `sh` than the reference: its gradients compare the other groups.
    let sh0 = detail.iter().filter(|r| r[0] == "sh_degree").count();
    assert_eq!(sh0, 4 * 3);
    let plot = image::open(dir.path().join("cpu/tradeoff.png")).unwrap();
    assert_eq!((plot.width(), plot.height()), (1400, 560));

    let args = [&["tradeoff", "--backend", "gpu", "--out", "gpu"][..], &size].concat();
    let out = splat(&args, dir.path());
    if no_adapter(&out) {
        return;
    }
    // The GPU renders tiles of 8 and 16 only; the hardware path adds a row per target format
    // (all four on lavapipe).
    let gpu = csv_rows(&dir.path().join("gpu/tradeoff.csv"));
    let hardware: Vec<&Vec<String>> = gpu.iter().filter(|r| r[0] == "raster").collect();
    assert_eq!(gpu.len(), rows.len() - 2 + hardware.len());
    let shade = |value: &str| {
        let row = gpu
            .iter()
            .find(|r| r[0] == "shade_precision" && r[1] == value);
        row.unwrap()[psnr].parse::<f64>().unwrap()
    };
    assert!(shade("unorm8") < shade("unorm16"));
    let tile = gpu.iter().find(|r| r[0] == "tile").unwrap();
    assert_eq!(tile[1], "8");
    assert!(tile[psnr].parse::<f64>().unwrap() > 60.0, "{tile:?}");
    let default = &gpu[0];
    let number = |r: &[String], c: usize| r[c].parse::<f64>().unwrap();
    // Every GPU time comes with its ratio to the default frame run beside it.
    let backward_x = tradeoff_column("backward_vs_default");
    assert!(gpu.iter().all(|r| number(r, forward_x) > 0.0), "{gpu:?}");
    let (keys, sort) = (
        tradeoff_column("intersections"),
        tradeoff_column("sort_mib"),
    );
    for r in &hardware {
        // Forward only; one sort key per visible primitive, fewer than the tile pairs.
        let backward = tradeoff_column("backward_ms");
        assert_eq!((&*r[backward], &*r[backward_x]), ("", ""), "{r:?}");
        assert_eq!(&*r[gradient], "", "{r:?}");
        assert!(number(r, keys) < number(default, keys), "{r:?}");
        assert!(number(r, sort) < number(default, sort), "{r:?}");
    }
    let format = |name: &str| hardware.iter().find(|r| r[1] == format!("hardware {name}"));
    let (f16, unorm8) = (format("f16").unwrap(), format("unorm8").unwrap());
    assert!(
        number(f16, psnr) > number(unorm8, psnr),
        "{f16:?} {unorm8:?}"
    );
    if let Some(f32) = format("f32") {
        // Without the transmittance stop, as the reference: the same image up to rounding.
        assert!(number(f32, psnr) > 80.0, "{f32:?}");
    }
    fails(
        &splat(&["tradeoff", "--iters", "0", "--out", "never"], dir.path()),
        "--iters must be at least 1",
        &dir.path().join("never"),
    );
}

/// A camera that moves during its readout renders with the method's rolling-shutter instance,
/// and methods without one refuse it by name, pointing at those with one.
#[test]
fn a_rolling_shutter_camera_needs_a_method_that_renders_it() {
    let dir = temp();
    let camera = r#"{"width": 64, "height": 48, "fx": 60, "fy": 60, "cx": 32, "cy": 24,
        "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 6], [0, 0, 0, 1]],
        "world_to_camera_last_row": [[1, 0, 0, -0.2], [0, 1, 0, 0], [0, 0, 1, 6], [0, 0, 0, 1]]}"#;
    write(dir.path(), "rolling.json", camera.as_bytes());
    let render = |method: &str, out: &str| {
        let args = ["render", "--camera", "rolling.json", "--method", method];
        let args: Vec<&str> = args
            .iter()
            .copied()
            .chain(["--backend", "cpu", "--explain", "--out", out])
            .collect();
        splat(&args, dir.path())
    };
    fails(
        &render("3dgs", "global.png"),
        "3dgs renders global shutters only, and the camera moves during its readout (shutter_turn, shutter_shift): use --method 3dgut or --method 3dgeer",
        &dir.path().join("global.png"),
    );
    for (method, instance) in [("3dgut", "gut_rs"), ("3dgeer", "geer_rs")] {
        let out = format!("{method}.png");
        let stdout = ok(&render(method, &out));
        for line in [
            format!("method            {instance}"),
            "rolling shutter   on (each row seen from the camera's pose at its readout)".into(),
        ] {
            assert!(stdout.contains(&line), "`{line}` is not in:\n{stdout}");
        }
        assert!(dir.path().join(out).exists());
    }
}

/// A run killed while it writes its output leaves the previous file whole: every output goes
/// to a temporary file in the same folder, renamed over the target once complete. The kill
/// comes from the kernel, mid-write and without a race: the run's file size limit (`ulimit
/// -f`, 64 blocks of 512 bytes) is below the new render's size, so the write past it gets
/// SIGXFSZ, which ends the process where it stands.
#[cfg(unix)]
#[test]
fn a_run_killed_while_writing_leaves_the_previous_output_whole() {
    use std::os::unix::process::ExitStatusExt;
    let dir = temp();
    let out = dir.path().join("render.exr");
    let args = |size: [&'static str; 2]| {
        let [w, h] = size;
        [
            "render",
            "--backend",
            "cpu",
            "--out",
            "render.exr",
            "--width",
            w,
            "--height",
            h,
        ]
    };
    ok(&splat(&args(["64", "48"]), dir.path()));
    let before = std::fs::read(&out).unwrap();
    let limit = 64 * 512;
    let run = Command::new("sh")
        .arg("-c")
        .arg("ulimit -c 0; ulimit -f 64; exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_splat"))
        .args(args(["320", "240"]))
        .current_dir(dir.path())
        .output()
        .expect("run splat");
    assert_eq!(
        run.status.signal(),
        Some(25), // SIGXFSZ
        "the run should die writing past its file size limit: {run:?}"
    );
    assert_eq!(
        std::fs::read(&out).unwrap(),
        before,
        "the previous output changed"
    );
    let partial: Vec<PathBuf> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| *p != out)
        .collect();
    assert_eq!(partial.len(), 1, "{partial:?}");
    let name = partial[0].file_name().unwrap().to_string_lossy();
    assert!(
        name.starts_with(".render.exr-") && name.ends_with(".partial"),
        "{name}"
    );
    assert_eq!(
        std::fs::metadata(&partial[0]).unwrap().len(),
        limit,
        "the kill came mid-write"
    );
}
