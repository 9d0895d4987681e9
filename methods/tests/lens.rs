//! Photographs taken through a lens with distortion (COLMAP's SIMPLE_RADIAL, RADIAL, OPENCV
//! and FULL_OPENCV cameras) read as pinhole views: each picture shows a smooth scene of the
//! normalized image plane, placed where COLMAP's own distortion formulas (written out here,
//! inverted in f64) put it; the views read back must show that scene at their pinhole rays,
//! within what 8-bit pictures and bilinear sampling allow, and keep only pixels whose rays the
//! picture saw. nerfstudio's OPENCV lens is read the same way, and COLMAP's radial fisheyes
//! as our Kannala-Brandt camera.

use super::colmap::{Cam, H, Model, W, dataset, model};
use splat_runtime::glam::{DVec2, Vec2, Vec3, Vec4};
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
                20.5, 20.0, 16.2, 11.8, 0.06, 0.01, -0.002, 0.003, 0.05, 0.02, 0.1, -0.1,
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

/// Where a lens puts a point of the normalized image plane.
type LensFn<'a> = &'a dyn Fn(DVec2) -> DVec2;

/// The normalized point that `lens` puts at `d`, by fixed-point iteration in f64.
fn undistorted(lens: LensFn, d: DVec2) -> DVec2 {
    let mut n = d;
    for _ in 0..200 {
        n -= lens(n) - d;
    }
    assert!((lens(n) - d).length() < 1e-12, "{d} did not invert");
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

/// The 8-bit picture of [`scene`] taken through `lens` by a camera of focal lengths `f` and
/// principal point `c` at W x H pixels, `width` x `height` pixels.
fn photograph(lens: LensFn, (f, c): (DVec2, DVec2), width: u32, height: u32) -> image::RgbImage {
    let scale = DVec2::new(
        f64::from(width) / f64::from(W),
        f64::from(height) / f64::from(H),
    );
    image::RgbImage::from_fn(width, height, |x, y| {
        let at = DVec2::new(f64::from(x), f64::from(y)) + 0.5;
        let rgb = scene(undistorted(lens, (at / scale - c) / f));
        image::Rgb(rgb.map(|v| (v * 255.0).round() as u8))
    })
}

/// `view` is cut from a picture of `size` pixels, seen with focal lengths `f` and principal
/// point `c` through `lens`, with the picture's focal lengths at whole pixels; every ray of
/// its pixels falls between the picture's pixel centres, and no side could take one more row
/// or column of the picture.
fn assert_cut(view: &View, lens: LensFn, (f, c): (DVec2, DVec2), size: (u32, u32)) {
    let got = view.camera;
    assert_eq!(got.model, CameraModel::Pinhole);
    assert_eq!(got.focal, f.as_vec2());
    let (w, h) = view.size();
    assert_eq!(got.size.as_uvec2().to_array(), [w, h]);
    let offset = c.as_vec2() - got.principal;
    assert_eq!(offset, offset.round(), "whole pixels");
    let (ox, oy) = (offset.x as u32, offset.y as u32);
    let seen = |x: u32, y: u32| {
        let ray = (DVec2::new(f64::from(x), f64::from(y)) + 0.5 - c) / f;
        let at = lens(ray) * f + c;
        let last = DVec2::new(f64::from(size.0), f64::from(size.1)) - 0.5;
        at.cmpge(DVec2::splat(0.5)).all() && at.cmple(last).all()
    };
    for y in oy..oy + h {
        for x in ox..ox + w {
            assert!(seen(x, y), "{}: pixel ({x}, {y}) is not seen", view.name);
        }
    }
    let column = |x: u32| (oy..oy + h).all(|y| seen(x, y));
    let row = |y: u32| (ox..ox + w).all(|x| seen(x, y));
    assert!(ox == 0 || !column(ox - 1), "{}: left", view.name);
    assert!(ox + w == size.0 || !column(ox + w), "{}: right", view.name);
    assert!(oy == 0 || !row(oy - 1), "{}: top", view.name);
    assert!(oy + h == size.1 || !row(oy + h), "{}: bottom", view.name);
}

/// The camera `view` was read with, and its largest difference from [`scene`] at its pixels'
/// pinhole rays.
fn scene_error(view: &View) -> f64 {
    let cam = view.camera;
    let (f, c) = (cam.focal.as_dvec2(), cam.principal.as_dvec2());
    let mut worst = 0.0f64;
    let image = view.image();
    for (p, rgb) in image.data.chunks_exact(3).enumerate() {
        let (x, y) = (p as u32 % image.width, p as u32 / image.width);
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
        photograph(&|n| distorted(cam, n), pinhole(cam), W, H)
            .save(path)
            .unwrap();
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
            assert_cut(view, &|n| distorted(cam, n), (f, c), (W, H));
            let size = view.size();
            match cam.name {
                "SIMPLE_RADIAL" => assert!(size.0 < W && size.1 < H, "{size:?}"),
                "RADIAL" => assert_eq!(size, (W, H)),
                _ => {}
            }

            let error = scene_error(view);
            assert!(error < bound, "{}: {error} from the scene", cam.name);
            // What a reader that took the picture as a pinhole view would give.
            let camera = Camera {
                principal: c.as_vec2(),
                ..view.camera
            };
            let picture = image_of(Path::new(&view.name));
            let raw = View::new(view.name.clone(), camera, picture, None, Vec3::ZERO);
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
            let cam = camera_of(&m, view);
            let (f, c) = pinhole(cam);
            assert_cut(
                view,
                &|n| distorted(cam, n),
                (f / 2.0, c / 2.0),
                (W / 2, H / 2),
            );
            let error = scene_error(view);
            assert!(error < bound, "{}: {error} from the scene", view.name);
        }

        // Copies half the size in images_2 are cut through the same lenses: no block means,
        // two 8-bit roundings.
        for shot in &m.shots {
            let cam = m.cameras.iter().find(|c| c.id == shot.camera).unwrap();
            let path = dir.path().join("images_2").join(&shot.name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            photograph(&|n| distorted(cam, n), pinhole(cam), W / 2, H / 2)
                .save(path)
                .unwrap();
        }
        let copies = read_shots(dir.path()).unwrap().downscaled(2).unwrap();
        assert!(copies.train.iter().all(|s| s.downscale == 1));
        let bound = 1.0 / 255.0 + 4.0 * interpolation;
        for view in copies.load(Vec3::ZERO).unwrap().train {
            let cam = camera_of(&m, &view);
            let (f, c) = pinhole(cam);
            assert_cut(
                &view,
                &|n| distorted(cam, n),
                (f / 2.0, c / 2.0),
                (W / 2, H / 2),
            );
            let error = scene_error(&view);
            assert!(error < bound, "{}: {error} from the scene", view.name);
        }
    }
}

/// nerfstudio's OPENCV lens: its radial polynomial runs to k4 r⁸, with the tangential p1, p2.
/// Its views show the scene within the bound of `distorted_pictures_read_as_pinhole_views`.
#[test]
fn nerfstudio_opencv_pictures_read_as_pinhole_views() {
    let [k1, k2, k3, k4, p1, p2] = [0.04, -0.01, 0.02, 0.05, 0.003, -0.002];
    let lens = |n: DVec2| {
        let r2 = n.length_squared();
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)));
        let xy = n.x * n.y;
        n * radial
            + DVec2::new(
                2.0 * p1 * xy + p2 * (r2 + 2.0 * n.x * n.x),
                p1 * (r2 + 2.0 * n.y * n.y) + 2.0 * p2 * xy,
            )
    };
    let (f, c) = (DVec2::new(20.0, 20.5), DVec2::new(16.25, 11.75));
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<_> = (0..3)
        .map(|k| {
            let name = format!("frame_{k}.png");
            photograph(&lens, (f, c), W, H)
                .save(dir.path().join(&name))
                .unwrap();
            let x = 0.3 * k as f64;
            serde_json::json!({
                "file_path": name,
                "transform_matrix": [[1, 0, 0, x], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]],
            })
        })
        .collect();
    let transforms = serde_json::json!({
        "camera_model": "OPENCV", "fl_x": f.x, "fl_y": f.y, "cx": c.x, "cy": c.y, "w": W, "h": H,
        "k1": k1, "k2": k2, "k3": k3, "k4": k4, "p1": p1, "p2": p2,
        "frames": frames,
    });
    std::fs::write(dir.path().join("transforms.json"), transforms.to_string()).unwrap();
    let data = read_shots(dir.path()).unwrap().load(Vec3::ZERO).unwrap();
    let bound = 1.0 / 255.0 + 1.2e-3 * 1.3 * 1.3;
    for view in data.train.iter().chain(&data.test) {
        assert_cut(view, &lens, (f, c), (W, H));
        let error = scene_error(view);
        assert!(error < bound, "{}: {error} from the scene", view.name);
    }
}

/// COLMAP's SIMPLE_RADIAL_FISHEYE and RADIAL_FISHEYE are the Kannala-Brandt polynomial in the
/// angle, k1 (and k2) of it: their pictures are views as they are.
#[test]
fn colmap_radial_fisheyes_read_as_kannala_brandt() {
    let mut m = model();
    m.cameras = vec![
        Cam {
            id: 1,
            model: 8,
            name: "SIMPLE_RADIAL_FISHEYE",
            params: vec![14.0, 16.0, 12.0, 0.05],
        },
        Cam {
            id: 2,
            model: 9,
            name: "RADIAL_FISHEYE",
            params: vec![15.0, 16.5, 11.5, 0.04, -0.01],
        },
    ];
    for (k, shot) in m.shots.iter_mut().enumerate() {
        shot.camera = 1 + k as i32 % 2;
    }
    for binary in [true, false] {
        let dir = dataset(&m, binary);
        let shots = read_shots(dir.path()).unwrap();
        for shot in shots.train.iter().chain(&shots.test) {
            let name = shot.path.file_name().unwrap();
            let id = m.shots.iter().find(|s| *s.name == *name).unwrap().camera;
            let want = match id {
                1 => (
                    Vec2::splat(14.0),
                    Vec2::new(16.0, 12.0),
                    Vec4::new(0.05, 0.0, 0.0, 0.0),
                ),
                _ => (
                    Vec2::splat(15.0),
                    Vec2::new(16.5, 11.5),
                    Vec4::new(0.04, -0.01, 0.0, 0.0),
                ),
            };
            let got = shot.camera;
            assert_eq!(got.model, CameraModel::KannalaBrandt);
            assert_eq!((got.focal, got.principal, got.distortion), want);
            assert!(shot.undistortion.is_none());
        }
    }
}

/// `path`'s pixels as a view's RGB.
fn image_of(path: &Path) -> splat_runtime::frame::Image {
    let rgb = image::open(path).unwrap().into_rgb8();
    splat_runtime::frame::Image {
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
