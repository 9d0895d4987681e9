//! `splat video`: an MP4 that a real browser plays to its last frame, with the frames asked
//! for, whose first frame is `splat render` of the path's first camera within H.264's error;
//! bad input refused with nothing written.

use crate::common::*;
use splat_runtime::Camera;
use splat_runtime::glam::{Mat3, Vec2, Vec3};
use splat_runtime::io::camera::CameraFile;

/// A 160x120 view of the built-in scene from `eye`, looking at its middle.
fn camera(eye: Vec3) -> CameraFile {
    let forward = (-eye).normalize();
    let right = -Vec3::Y.cross(forward).normalize();
    let rotation = Mat3::from_cols(right, forward.cross(right), forward).transpose();
    CameraFile::from_camera(&Camera {
        rotation,
        translation: -(rotation * eye),
        focal: Vec2::splat(130.0),
        principal: Vec2::new(80.0, 60.0),
        size: Vec2::new(160.0, 120.0),
        ..Default::default()
    })
}

/// What Chromium saw of `video` (its first frame written to `dir`/first.png), as the JSON line
/// `tests/browser/video.mjs` prints; `None` without Chromium or `npm install` (an error when
/// `SPLAT_REQUIRE_BROWSER=1`).
fn played_in_chromium(video: &Path, dir: &Path) -> Option<serde_json::Value> {
    let browser = browser()?;
    let run = Command::new("node")
        .arg(browser.join("video.mjs"))
        .args([video, dir])
        .output()
        .unwrap();
    let report = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{report}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    Some(serde_json::from_str(report.trim()).unwrap())
}

#[test]
fn a_keyframed_path_plays_in_chromium_from_its_first_key() {
    let dir = temp();
    let (a, b) = (
        camera(Vec3::new(2.0, 1.0, -5.5)),
        camera(Vec3::new(-3.0, 0.5, -5.0)),
    );
    let keys = serde_json::json!({ "keyframes": [a, b] });
    write(dir.path(), "keys.json", keys.to_string().as_bytes());
    write(
        dir.path(),
        "camera.json",
        serde_json::to_string(&a).unwrap().as_bytes(),
    );
    let args = [
        "video",
        "--method",
        "3dgs",
        "--path",
        "keys.json",
        "--frames",
        "9",
    ];
    let out = ok(&splat(
        &[&args[..], &["--out", "keys.mp4", "--backend", "cpu"]].concat(),
        dir.path(),
    ));
    assert!(out.contains("9 frames of 160x120 at 30 fps"), "{out}");
    let args = [
        "render",
        "--method",
        "3dgs",
        "--camera",
        "camera.json",
        "--out",
        "render.png",
    ];
    ok(&splat(
        &[&args[..], &["--backend", "cpu"]].concat(),
        dir.path(),
    ));

    let Some(seen) = played_in_chromium(&dir.path().join("keys.mp4"), dir.path()) else {
        return;
    };
    assert_eq!(seen["ended"], true, "{seen}");
    assert_eq!(seen["decoded"], 9, "{seen}");
    assert_eq!(
        (seen["width"].as_u64(), seen["height"].as_u64()),
        (Some(160), Some(120))
    );
    assert!(
        (seen["duration"].as_f64().unwrap() - 0.3).abs() < 1e-3,
        "{seen}"
    );
    let shown = image::open(dir.path().join("first.png")).unwrap().to_rgb8();
    let want = image::open(dir.path().join("render.png"))
        .unwrap()
        .to_rgb8();
    let (mean, most) = difference(&shown, &want);
    println!("Chromium's first frame against splat render: mean {mean:.4}, largest {most:.3}");
    assert!(mean < 0.02 && most < 0.4, "mean {mean}, largest {most}");
}

/// A dataset's views, in order, at their own size.
#[test]
fn a_dataset_path_takes_every_view_in_order() {
    let dir = temp();
    let args = [
        "dataset", "--out", "planet", "--views", "6", "--width", "48", "--height", "32",
    ];
    ok(&splat(&args, dir.path()));
    ok(&splat(&["scene", "--out", "planet.ply"], dir.path()));
    let args = [
        "video",
        "planet",
        "--scene",
        "planet.ply",
        "--method",
        "3dgs",
        "--path",
        "dataset",
    ];
    let out = ok(&splat(
        &[&args[..], &["--out", "views.mp4", "--backend", "cpu"]].concat(),
        dir.path(),
    ));
    assert!(out.contains("6 frames of 48x32"), "{out}");
    assert!(out.contains("6 views of planet"), "{out}");
}

#[test]
fn bad_input_is_refused_with_nothing_written() {
    let dir = temp();
    let out = dir.path().join("v.mp4");
    let video = |more: &[&str]| {
        let args = [
            "video",
            "--method",
            "3dgs",
            "--out",
            "v.mp4",
            "--backend",
            "cpu",
        ];
        splat(&[&args[..], more].concat(), dir.path())
    };
    fails(
        &video(&["--width", "161", "--height", "120"]),
        "even sizes",
        &out,
    );
    fails(
        &video(&["--path", "dataset"]),
        "give the dataset as PATH",
        &out,
    );
    fails(
        &video(&["--path", "spiral"]),
        "expected orbit, dataset or a keyframes file",
        &out,
    );
    fails(&video(&["--fps", "0"]), "1 to 240", &out);
    fails(&video(&["--frames", "1"]), "frames", &out);
    write(dir.path(), "one.json", br#"{"keyframes": [{"width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 32, "cy": 24, "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#);
    fails(
        &video(&["--path", "one.json"]),
        "at least 2 keyframes",
        &out,
    );
    write(dir.path(), "junk.json", b"[1, 2]");
    fails(
        &video(&["--path", "junk.json"]),
        "not a keyframes file",
        &out,
    );
    let args = [
        "video",
        "--method",
        "3dgs",
        "--out",
        "v.webm",
        "--backend",
        "cpu",
    ];
    fails(
        &splat(&args, dir.path()),
        "written as .mp4",
        &dir.path().join("v.webm"),
    );
}
