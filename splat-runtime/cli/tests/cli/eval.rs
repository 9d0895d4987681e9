//! `splat eval`: a scene measured as `splat fit` measured it.

use crate::common::*;

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

/// `splat eval --formats` writes the scene in every format, reads each back and measures it:
/// the table, `formats.csv` (each size the file `splat convert` writes; the PLY's PSNR a plain
/// `splat eval`'s) and `formats.png`.
#[test]
fn eval_formats_measures_what_each_format_costs() {
    let dir = temp();
    let d = dir.path();
    ok(&splat(&["scene", "--out", "planet.ply"], d));
    let args = ["dataset", "--out", "data", "--views", "16"];
    ok(&splat(&args, d));
    let eval = ["eval", "data", "--scene", "planet.ply", "--backend", "cpu"];
    let plain = ok(&splat(&eval, d));
    let out = ok(&splat(
        &[&eval[..], &["--formats", "--out", "costs"]].concat(),
        d,
    ));
    assert!(out.contains("9400 primitives (SH degree 1)"), "{out}");
    let csv = std::fs::read_to_string(d.join("costs/formats.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let names: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(names, ["ply", "compressed-ply", "splat", "spz", "sog"]);
    // Each size is the file `splat convert` writes.
    let bytes = |k: usize| rows[k][1].parse::<u64>().unwrap();
    for (k, file) in ["a.ply", "a.compressed.ply", "a.splat", "a.spz"]
        .iter()
        .enumerate()
    {
        ok(&splat(&["convert", "planet.ply", file], d));
        assert_eq!(
            bytes(k),
            std::fs::metadata(d.join(file)).unwrap().len(),
            "{file}"
        );
    }
    assert_eq!(bytes(2), 9400 * 32);
    assert!(bytes(3) < bytes(1) && bytes(1) < bytes(0), "{csv}");
    let psnr = |k: usize| rows[k][2].parse::<f64>().unwrap();
    assert!(
        plain.contains(&format!("mean PSNR {:.2} dB", psnr(0))),
        "{plain}\n{csv}"
    );
    assert_eq!(rows[0][4], "", "no PSNR of the PLY to itself");
    for row in &rows[1..] {
        let to_ply: f64 = row[4].parse().unwrap();
        assert!(to_ply > 35.0 && to_ply < 70.0, "{row:?}");
    }
    assert!(image::open(d.join("costs/formats.png")).is_ok());
}
