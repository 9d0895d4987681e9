//! `splat tradeoff`: every knob swept, its table and plot.

use crate::common::*;

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
