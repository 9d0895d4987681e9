//! What the command-line tests share: running `splat`, reading its outcome, and the small datasets
//! and files they run it on.

pub use std::path::{Path, PathBuf};
pub use std::process::{Command, Output};

pub fn splat(args: &[&str], dir: &Path) -> Output {
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
pub fn no_adapter(out: &Output) -> bool {
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

pub fn ok(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "stdout:\n{stdout}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// Asserts a failure whose message contains `needle`, and that `out_file` was not created.
pub fn fails(out: &Output, needle: &str, out_file: &Path) {
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

pub fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
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

pub fn temp() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// A minimal Blender-format dataset: `views` uniform gray RGBA images of 16 x 16 pixels, with
/// cameras on a circle looking at the origin (OpenGL camera-to-world).
pub fn tiny_dataset(dir: &Path, views: usize) {
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
pub struct FitOutput {
    pub scene: splat_runtime::io::ply::GaussianCloud,
    /// (step, test PSNR) where measured.
    pub psnr: Vec<(usize, f64)>,
    /// Rows of metrics.csv after the header.
    pub rows: usize,
}

pub fn fit_output(out: &Path, test_views: usize, size: (u32, u32)) -> FitOutput {
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

/// A COLMAP dataset in text format: 3 views of 16x16 by a pinhole camera looking down +z
/// from z = -3, and 40 sparse points around the origin.
pub fn tiny_colmap_dataset(dir: &Path) {
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

/// The rows of a CSV file after its header, as fields.
/// The rows of a CSV file after its header (fields split at commas outside double quotes).
pub fn csv_rows(path: &Path) -> Vec<Vec<String>> {
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

/// The mean and the largest difference per channel of two images, in [0, 1].
pub fn difference(got: &image::RgbImage, want: &image::RgbImage) -> (f64, f64) {
    assert_eq!(got.dimensions(), want.dimensions());
    let diffs: Vec<f64> = (got.as_raw().iter().zip(want.as_raw()))
        .map(|(a, b)| (*a as f64 - *b as f64).abs() / 255.0)
        .collect();
    let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
    (mean, diffs.iter().fold(0.0f64, |m, d| m.max(*d)))
}

/// `tests/browser`, where node drives headless Chromium (playwright-core), or `None` without
/// Chromium or `npm install` there (an error when `SPLAT_REQUIRE_BROWSER=1`).
pub fn browser() -> Option<PathBuf> {
    let browser = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/browser");
    let ready = browser.join("node_modules/playwright-core").is_dir()
        && Path::new(&std::env::var("CHROMIUM").unwrap_or("/usr/bin/chromium".into())).exists();
    let missing = format!("no Chromium or `npm install` in {}", browser.display());
    required(ready.then_some(browser), "SPLAT_REQUIRE_BROWSER", &missing)
}

/// `found`, a tool a test needs; where it is `None`, the test skips (saying `missing`), or
/// fails where the environment variable `require` is 1 (CI installs every tool and sets it).
pub fn required<T>(found: Option<T>, require: &str, missing: &str) -> Option<T> {
    if found.is_none() {
        let required = std::env::var(require).is_ok_and(|v| v == "1");
        assert!(!required, "{missing}");
        eprintln!("skipped: {missing}");
    }
    found
}
