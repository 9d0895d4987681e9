//! `splat dataset`: the built-in views as a Blender folder.

use crate::common::*;

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
