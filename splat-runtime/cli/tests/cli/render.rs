//! `splat render`: the default scene, every method on the cameras it supports, every output format,
//! the PLY round trip, the GPU backend, a dataset's view as the camera, and bad scenes, cameras and
//! options refused clearly.

use crate::common::*;

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
    for method in ["3dgut", "3dgeer"] {
        let out = format!("{method}.png");
        let stdout = ok(&render(method, &out));
        for line in [
            format!("method            {method}"),
            "rolling shutter   on (each row seen from the camera's pose at its readout)".into(),
        ] {
            assert!(stdout.contains(&line), "`{line}` is not in:\n{stdout}");
        }
        assert!(dir.path().join(out).exists());
    }
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
