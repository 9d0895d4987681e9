//! Photographs taken through a lens with distortion (COLMAP's SIMPLE_RADIAL, RADIAL, OPENCV
//! and FULL_OPENCV cameras) read as pinhole views: each picture shows a smooth scene of the
//! normalized image plane, placed where COLMAP's own distortion formulas (written out here,
//! inverted in f64) put it; the views read back must show that scene at their pinhole rays,
//! within what 8-bit pictures and bilinear sampling allow, and keep only pixels whose rays the
//! picture saw.

use super::colmap::{Cam, H, Model, W, dataset, model};
use splat_runtime::glam::{DVec2, Vec3};
use splat_runtime::io::dataset::{View, read_shots};
use splat_runtime::{Camera, CameraModel};
use std::path::Path;

/// One camera of each model with distortion: pincushion (cropped), barrel (not), and
/// tangential and rational terms, with principal points off the centre.
fn lensed() -> Vec<Cam> {
    vec![
        Cam {
            id: 1,
            model: 2,
            name: "SIMPLE_RADIAL",
            params: vec![20.0, 16.5, 12.25, 0.08],
        },
        Cam {
            id: 2,
            model: 3,
            name: "RADIAL",
            params: vec![21.0, 15.5, 11.75, -0.12, 0.03],
        },
        Cam {
            id: 3,
            model: 4,
            name: "OPENCV",
            params: vec![20.0, 20.5, 16.0, 12.0, 0.05, -0.01, 0.004, -0.003],
        },
        Cam {
            id: 7,
            model: 6,
            name: "FULL_OPENCV",
            params: vec![
                20.5, 20.0, 16.2, 11.8, 0.06, 0.01, -0.002, 0.003, 0.001, 0.02, -0.004, 0.001,
            ],
        },
    ]
}

/// The focal lengths and principal point of `cam`.
fn pinhole(cam: &Cam) -> (DVec2, DVec2) {
    let p = &cam.params;
    match cam.model {
        2 | 3 => (DVec2::splat(p[0]), DVec2::new(p[1], p[2])),
        _ => (DVec2::new(p[0], p[1]), DVec2::new(p[2], p[3])),
    }
}

/// Where `cam`'s lens puts the normalized point `n`: COLMAP's formulas per model.
fn distorted(cam: &Cam, n: DVec2) -> DVec2 {
    let k = &cam.params[if matches!(cam.model, 2 | 3) { 3 } else { 4 }..];
    let (u, v) = (n.x, n.y);
    let (u2, v2, uv) = (u * u, v * v, u * v);
    let r2 = u2 + v2;
    let tangential = |p1: f64, p2: f64| {
        DVec2::new(
            2.0 * p1 * uv + p2 * (r2 + 2.0 * u2),
            2.0 * p2 * uv + p1 * (r2 + 2.0 * v2),
        )
    };
    match cam.model {
        2 => n * (1.0 + k[0] * r2),
        3 => n * (1.0 + k[0] * r2 + k[1] * r2 * r2),
        4 => n * (1.0 + k[0] * r2 + k[1] * r2 * r2) + tangential(k[2], k[3]),
        6 => {
            let (r4, r6) = (r2 * r2, r2 * r2 * r2);
            let radial = (1.0 + k[0] * r2 + k[1] * r4 + k[4] * r6)
                / (1.0 + k[5] * r2 + k[6] * r4 + k[7] * r6);
            n * radial + tangential(k[2], k[3])
        }
        model => unreachable!("model {model}"),
    }
}

/// The normalized point that `cam`'s lens puts at `d`, by fixed-point iteration in f64.
fn undistorted(cam: &Cam, d: DVec2) -> DVec2 {
    let mut n = d;
    for _ in 0..200 {
        n -= distorted(cam, n) - d;
    }
    assert!(
        (distorted(cam, n) - d).length() < 1e-12,
        "{d} did not invert"
    );
    n
}

/// The scene every picture shows: a smooth color of the normalized image plane.
fn scene(n: DVec2) -> [f64; 3] {
    let s = (2.5 * n.x + 0.7).sin() * (2.0 * n.y - 0.3).cos();
    [
        0.5 + 0.35 * s,
        0.5 - 0.3 * s,
        0.5 + 0.2 * (1.5 * n.x - n.y).sin(),
    ]
}

/// The 8-bit picture `cam` takes of [`scene`], `width` x `height` pixels.
fn photograph(cam: &Cam, width: u32, height: u32) -> image::RgbImage {
    let (f, c) = pinhole(cam);
    let scale = DVec2::new(
        f64::from(width) / f64::from(W),
        f64::from(height) / f64::from(H),
    );
    image::RgbImage::from_fn(width, height, |x, y| {
        let at = DVec2::new(f64::from(x), f64::from(y)) + 0.5;
        let rgb = scene(undistorted(cam, (at / scale - c) / f));
        image::Rgb(rgb.map(|v| (v * 255.0).round() as u8))
    })
}

/// The camera `view` was read with, and its largest difference from [`scene`] at its pixels'
/// pinhole rays.
fn scene_error(view: &View) -> f64 {
    let cam = view.camera;
    let (f, c) = (cam.focal.as_dvec2(), cam.principal.as_dvec2());
    let mut worst = 0.0f64;
    for (p, rgb) in view.image.data.chunks_exact(3).enumerate() {
        let (x, y) = (p as u32 % view.image.width, p as u32 / view.image.width);
        let n = (DVec2::new(f64::from(x), f64::from(y)) + 0.5 - c) / f;
        for (got, want) in rgb.iter().zip(scene(n)) {
            worst = worst.max((f64::from(*got) - want).abs());
        }
    }
    worst
}

/// A COLMAP dataset of `model()`'s images on the [`lensed`] cameras, photographs of the scene.
fn lensed_dataset(binary: bool) -> (Model, tempfile::TempDir) {
    let mut m = model();
    m.cameras = lensed();
    let dir = dataset(&m, binary);
    for shot in &m.shots {
        let cam = m.cameras.iter().find(|c| c.id == shot.camera).unwrap();
        let path = dir.path().join("images").join(&shot.name);
        photograph(cam, W, H).save(path).unwrap();
    }
    (m, dir)
}

/// `view`'s COLMAP camera in `m`.
fn camera_of<'a>(m: &'a Model, view: &View) -> &'a Cam {
    let name = Path::new(&view.name).file_name().unwrap();
    let shot = m.shots.iter().find(|s| *s.name == *name).unwrap();
    m.cameras.iter().find(|c| c.id == shot.camera).unwrap()
}

/// Every view is the pinhole view of its picture, with the picture's focal lengths, cropped
/// to the pixels whose rays the picture saw (a barrel lens sees them all), and shows the scene
/// at its rays: within the picture's and the view's 8-bit rounding (half a step each) and
/// bilinear interpolation over a picture pixel, (h² / 8) (|s_xx| + |s_yy|) < 1.2e-3 for the
/// scene's second derivatives (below 2.2 and 1.4) at h = 0.05 of the plane a pixel, stretched
/// at most 1.3x by these lenses. Ignoring the lenses is over 5x further off.
#[test]
fn distorted_pictures_read_as_pinhole_views() {
    let interpolation = 1.2e-3 * 1.3 * 1.3;
    let bound = 1.0 / 255.0 + interpolation;
    for binary in [true, false] {
        let (m, dir) = lensed_dataset(binary);
        let shots = read_shots(dir.path()).unwrap();
        let data = shots.clone().load(Vec3::ZERO).unwrap();
        let mut ignored = 0.0f64;
        for view in data.train.iter().chain(&data.test) {
            let cam = camera_of(&m, view);
            let (f, c) = pinhole(cam);
            let got = view.camera;
            assert_eq!(got.model, CameraModel::Pinhole);
            assert_eq!(got.focal.as_dvec2(), f.as_vec2().as_dvec2());
            let size = (view.image.width, view.image.height);
            assert_eq!(got.size.as_uvec2().to_array(), [size.0, size.1]);
            // The view's pixel (0, 0) is the picture's `offset`.
            let offset = (c.as_vec2() - got.principal).round();
            assert_eq!(offset, c.as_vec2() - got.principal, "whole pixels");
            let offset = offset.as_dvec2();
            for y in 0..size.1 {
                for x in 0..size.0 {
                    let ray = (DVec2::new(f64::from(x), f64::from(y)) + 0.5 + offset - c) / f;
                    let at = distorted(cam, ray) * f + c;
                    // Between the picture's pixel centres.
                    let inside = at.cmpge(DVec2::splat(0.5)).all()
                        && at.cmple(DVec2::new(f64::from(W), f64::from(H)) - 0.5).all();
                    assert!(inside, "{}: pixel ({x}, {y}) is not seen", cam.name);
                }
            }
            match cam.name {
                "SIMPLE_RADIAL" => assert!(size.0 < W && size.1 < H, "{size:?}"),
                "RADIAL" => assert_eq!(size, (W, H)),
                _ => {}
            }

            let error = scene_error(view);
            assert!(error < bound, "{}: {error} from the scene", cam.name);
            // What a reader that took the picture as a pinhole view would give.
            let raw = View {
                camera: Camera {
                    principal: c.as_vec2(),
                    ..got
                },
                image: image_of(Path::new(&view.name)),
                ..view.clone()
            };
            ignored = ignored.max(scene_error(&raw));
        }
        assert!(ignored > 5.0 * bound, "the lenses matter: {ignored}");

        // Half the size: the pictures averaged, then cut through the same lenses at half the
        // focal length. A 2x2 block's mean is off its centre's value as much as interpolation
        // over a picture pixel, the half-size pixel is twice as wide (4x the interpolation
        // error), and there are three 8-bit roundings.
        let half = shots.downscaled(2).unwrap().load(Vec3::ZERO).unwrap();
        let bound = 1.5 / 255.0 + 5.0 * interpolation;
        for view in half.train.iter().chain(&half.test) {
            let (f, _) = pinhole(camera_of(&m, view));
            assert_eq!(view.camera.focal, (f / 2.0).as_vec2());
            let error = scene_error(view);
            assert!(error < bound, "{}: {error} from the scene", view.name);
        }
    }
}

/// `path`'s pixels as a view's RGB.
fn image_of(path: &Path) -> splat_runtime::pipeline::Image {
    let rgb = image::open(path).unwrap().into_rgb8();
    splat_runtime::pipeline::Image {
        width: rgb.width(),
        height: rgb.height(),
        channels: 3,
        data: rgb
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 255.0)
            .collect(),
    }
}
