//! `splat gallery`: every method on every camera model in one picture.

use crate::common::*;

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
