//! Posed images for training, in three layouts, read by [`read`] from a folder. Two have
//! camera-to-world `transform_matrix` rows in OpenGL axes (x right, y up, z backwards):
//! - Blender / NeRF-synthetic: `transforms_train.json` and `transforms_test.json`, each with
//!   `camera_angle_x` (horizontal field of view, radians; or instant-ngp's pinhole `fl_x`
//!   `fl_y` `cx` `cy` `w` `h` in pixels, which win where given) and `frames[]` of `file_path`
//!   (relative; `.png` added when it has no extension) and `transform_matrix`.
//! - nerfstudio: one `transforms.json` with intrinsics `fl_x fl_y cx cy w h` given globally or
//!   per frame, and `camera_model` `PINHOLE`, `OPENCV` (`k1..k4 p1 p2`, the distortion taken
//!   out of the pictures on load, [`super::undistort`]) or `OPENCV_FISHEYE` (`k1..k4`: our
//!   Kannala-Brandt camera, so fisheye images train as they are); every 8th frame is held
//!   out for testing.
//!
//! The third is a COLMAP sparse model (`sparse/0/` or `sparse/`, binary or text) with its
//! pictures in `images/`, read by [`colmap::read_colmap`]; it also gives the dataset an
//! initial point cloud.
//!
//! RGBA images are composited on the chosen background. Views can be taken smaller than
//! their pictures ([`Shots::downscaled`]). Every error names the file and the field.

mod blender;
pub mod colmap;
pub(super) mod error;
mod nerfstudio;
mod shots;
mod transforms;

pub use super::picture::{Footprint, View};
pub use blender::{read_blender, write_blender};
pub use error::DatasetError;
pub use nerfstudio::read_nerfstudio;
pub use shots::{Dataset, Point, Shot, Shots, downscaled};

use glam::Vec3;
use std::path::Path;

/// Reads the dataset in `dir` (Blender if it holds `transforms_train.json`, else nerfstudio
/// if it holds `transforms.json`, else COLMAP with the pictures in `images/`), compositing
/// RGBA images on `background`.
pub fn read(dir: &Path, background: Vec3) -> Result<Dataset, DatasetError> {
    read_shots(dir)?.load(background)
}

/// The posed pictures of the dataset in `dir` (as [`read`] finds it), without their pixels.
pub fn read_shots(dir: &Path) -> Result<Shots, DatasetError> {
    if !dir.is_dir() {
        use std::io::{Error, ErrorKind};
        let error = match dir.exists() {
            true => Error::new(
                ErrorKind::NotADirectory,
                "a dataset is a folder, this is a file",
            ),
            false => Error::new(ErrorKind::NotFound, "no such folder"),
        };
        return Err(DatasetError::Io {
            path: dir.to_path_buf(),
            error,
        });
    }
    if dir.join("transforms_train.json").exists() {
        blender::shots(dir)
    } else if dir.join("transforms.json").exists() {
        nerfstudio::shots(dir)
    } else if colmap::is_colmap(dir) {
        colmap::shots(dir, None)
    } else {
        Err(DatasetError::NotADataset(dir.to_path_buf()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Vec2};
    use splat_core::frame::Image;
    use splat_core::types::{Camera, CameraModel};

    /// A pinhole camera at `eye` looking at the origin, 30 x 20 pixels.
    fn looking_from(eye: Vec3) -> Camera {
        let f = (-eye).normalize();
        let r = f.cross(Vec3::Y).normalize();
        let rotation = Mat3::from_cols(r, f.cross(r), f).transpose();
        Camera {
            rotation,
            translation: -(rotation * eye),
            focal: Vec2::splat(24.0),
            principal: Vec2::new(15.0, 10.0),
            size: Vec2::new(30.0, 20.0),
            ..Default::default()
        }
    }

    /// A view whose color and coverage vary over the image, composited on `background`.
    fn view(eye: Vec3, background: Vec3) -> View {
        let pixels = 30 * 20;
        let coverage: Vec<f32> = (0..pixels).map(|p| (p % 7) as f32 / 6.0).collect();
        let mut data = Vec::with_capacity(pixels * 3);
        for (p, a) in coverage.iter().enumerate() {
            let straight = Vec3::new((p % 30) as f32 / 29.0, (p / 30) as f32 / 19.0, 0.5);
            data.extend((straight * *a + background * (1.0 - a)).to_array());
        }
        let image = Image {
            width: 30,
            height: 20,
            channels: 3,
            data,
        };
        let name = format!("view from {eye}");
        View::new(name, looking_from(eye), image, Some(coverage), background)
    }

    /// Written as Blender and read back (on another background): the same poses and focal
    /// lengths, the same pictures up to 8-bit rounding, re-composited.
    #[test]
    fn a_dataset_survives_the_blender_format() {
        let dir = tempfile::tempdir().unwrap();
        let white = Vec3::ONE;
        let eyes = [Vec3::new(3.0, 1.0, -2.0), Vec3::new(-2.5, -0.5, 2.0)];
        let data = Dataset {
            train: eyes.iter().map(|e| view(*e, white)).collect(),
            test: vec![view(Vec3::new(0.5, 2.0, 3.0), white)],
            points: vec![],
        };
        write_blender(dir.path(), &data).unwrap();
        let back = read_blender(dir.path(), Vec3::ZERO).unwrap();
        let pairs = data.train.iter().chain(&data.test);
        for (want, got) in pairs.zip(back.train.iter().chain(&back.test)) {
            let (a, b) = (want.camera, got.camera);
            assert!(
                (a.focal - b.focal).abs().max_element() < 1e-4,
                "{a:?} {b:?}"
            );
            assert_eq!((a.principal, a.size), (b.principal, b.size));
            let pose = |c: &Camera| {
                [
                    c.rotation.to_cols_array().to_vec(),
                    c.translation.to_array().to_vec(),
                ]
                .concat()
            };
            for (x, y) in pose(&a).iter().zip(pose(&b)) {
                assert!((x - y).abs() < 1e-5, "{a:?} {b:?}");
            }
            let on_black = want.on(Vec3::ZERO);
            let worst = (on_black.data.iter().zip(&got.image().data))
                .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
            assert!(worst < 1.5 / 255.0, "{worst}");
        }
    }

    /// instant-ngp's intrinsics in a Blender split are read (focal lengths, principal point,
    /// size checked against the pictures); a lens, per-frame intrinsics, or a size that is not
    /// the pictures' are refused.
    #[test]
    fn instant_ngp_intrinsics_in_a_blender_split_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let data = written_blender(dir.path());
        let (w, h) = data.train[0].size();
        let path = dir.path().join("transforms_train.json");
        let original: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let edited = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut json = original.clone();
            edit(&mut json);
            std::fs::write(&path, json.to_string()).unwrap();
            read(dir.path(), Vec3::ZERO).map_err(|e| e.to_string())
        };
        let got = edited(&|j| {
            j.as_object_mut().unwrap().remove("camera_angle_x");
            for (k, v) in [("fl_x", 30.0), ("fl_y", 31.0), ("cx", 10.0), ("cy", 12.0)] {
                j[k] = v.into();
            }
            (j["w"], j["h"]) = (w.into(), h.into());
        })
        .unwrap();
        for view in &got.train {
            assert_eq!(view.camera.focal, Vec2::new(30.0, 31.0));
            assert_eq!(view.camera.principal, Vec2::new(10.0, 12.0));
        }
        // The test split keeps its field of view.
        assert_eq!(got.test[0].camera.focal, data.test[0].camera.focal);
        let refused = [
            (edited(&|j| j["k1"] = 0.1.into()), "k1 describes a lens"),
            (
                edited(&|j| j["frames"][1]["fl_x"] = 30.0.into()),
                "frames[1].fl_x is given per frame",
            ),
            (
                edited(&|j| (j["w"], j["h"]) = ((w + 1).into(), h.into())),
                &format!("w and h say {}x{h} pixels", w + 1),
            ),
            (
                edited(&|j| {
                    j.as_object_mut().unwrap().remove("camera_angle_x");
                }),
                "camera_angle_x is missing (and no fl_x",
            ),
            (
                edited(&|j| j["cx"] = 3.0.into()),
                "cx and cy must be given together",
            ),
        ];
        for (got, want) in refused {
            let err = got.unwrap_err();
            assert!(err.contains(want), "`{want}` not in: {err}");
        }
    }

    /// Two training views and a test view written in `dir` as a Blender dataset, read back.
    fn written_blender(dir: &Path) -> Dataset {
        let eyes = [Vec3::new(3.0, 1.0, -2.0), Vec3::new(-2.5, -0.5, 2.0)];
        let data = Dataset {
            train: eyes.iter().map(|e| view(*e, Vec3::ZERO)).collect(),
            test: vec![view(Vec3::new(0.5, 2.0, 3.0), Vec3::ZERO)],
            points: vec![],
        };
        write_blender(dir, &data).unwrap();
        read(dir, Vec3::ZERO).unwrap()
    }

    /// A `width` x `height` picture of one gray.
    fn gray(width: u32, height: u32, value: f32) -> Image {
        Image {
            width,
            height,
            channels: 3,
            data: vec![value; (width * height * 3) as usize],
        }
    }

    /// The posed pictures are read from the files' headers, their pixels only when loaded:
    /// the same cameras as a full read, and a picture whose pixels are broken past its header
    /// fails on loading, by name.
    #[test]
    fn shots_are_read_without_their_pixels() {
        let dir = tempfile::tempdir().unwrap();
        let full = written_blender(dir.path());
        let shots = read_shots(dir.path()).unwrap();
        let cameras = |views: &[View]| views.iter().map(|v| v.camera).collect::<Vec<_>>();
        let shot_cameras = |shots: &[Shot]| shots.iter().map(|s| s.camera).collect::<Vec<_>>();
        assert_eq!(shot_cameras(&shots.train), cameras(&full.train));
        assert_eq!(shot_cameras(&shots.test), cameras(&full.test));
        // The PNG cut a few bytes into its pixel data (the first IDAT chunk).
        let png = dir.path().join("train/r_1.png");
        let bytes = std::fs::read(&png).unwrap();
        let idat = bytes.windows(4).position(|w| w == b"IDAT").unwrap();
        std::fs::write(&png, &bytes[..idat + 8]).unwrap();
        let shots = read_shots(dir.path()).unwrap();
        assert_eq!(shots.train[1].camera, full.train[1].camera);
        assert!(shots.train[0].load(Vec3::ZERO).is_ok());
        let err = shots.load(Vec3::ZERO).unwrap_err().to_string();
        assert!(err.contains("r_1.png"), "{err}");
        // A picture replaced by one of another size after the dataset was read.
        let shots = read_shots(dir.path()).unwrap();
        let other = gray(12, 8, 0.5);
        super::super::image::write_image(&dir.path().join("test/r_0.png"), &other).unwrap();
        let err = shots.test[0].load(Vec3::ZERO).unwrap_err().to_string();
        assert!(
            err.contains("r_0.png: size decodes to 12x8 pixels, but its camera is 30x20"),
            "{err}"
        );
    }

    /// `Shots::downscaled`: box averages of the composited picture and its coverage, the
    /// intrinsics over the factor, the pixels that fill no block dropped; a copy in
    /// `<folder>_<factor>` taken instead where there is one, and refused when its size is not
    /// the factor's.
    #[test]
    fn views_are_downscaled_by_box_averages_or_taken_from_their_copies() {
        let dir = tempfile::tempdir().unwrap();
        let full = written_blender(dir.path());
        let (big, f) = (&full.train[1], 4usize);
        let shot = read_shots(dir.path()).unwrap().downscaled(4).unwrap().train[1].clone();
        let small = shot.load(Vec3::ZERO).unwrap();
        // 30 x 20 over 4: 7 x 5, the last two columns dropped.
        assert_eq!(small.size(), (7, 5));
        assert_eq!(small.camera.size, Vec2::new(7.0, 5.0));
        assert_eq!(small.camera.focal, big.camera.focal / 4.0);
        assert_eq!(small.camera.principal, big.camera.principal / 4.0);
        assert_eq!(small.camera.rotation, big.camera.rotation);
        let block_mean = |values: &[f32], channels: usize, x: usize, y: usize, c: usize| {
            let mut sum = 0.0f64;
            for dy in 0..f {
                for dx in 0..f {
                    sum += values[((y * f + dy) * 30 + x * f + dx) * channels + c] as f64;
                }
            }
            sum / (f * f) as f64
        };
        // The means rounded to 8 bits, as the pictures are: the coverage within half a step,
        // the composited color within one (half a step of the color, half of the coverage).
        assert!(big.rgba8().is_some() && small.rgba8().is_some());
        let step = 1.0 / 255.0;
        let big_coverage = big.coverage().unwrap();
        let small_coverage = small.coverage().unwrap();
        let (big_image, small_image) = (big.image(), small.image());
        for y in 0..5 {
            for x in 0..7 {
                for c in 0..3 {
                    let got = small_image.data[(y * 7 + x) * 3 + c] as f64;
                    let want = block_mean(&big_image.data, 3, x, y, c);
                    assert!((got - want).abs() < step, "({x}, {y}) {c}: {got} vs {want}");
                }
                let got = small_coverage[y * 7 + x] as f64;
                let want = block_mean(&big_coverage, 1, x, y, 0);
                assert!(
                    (got - want).abs() < 0.5 * step + 1e-6,
                    "({x}, {y}) coverage: {got} vs {want}"
                );
            }
        }
        // Averaging commutes with compositing: loaded on white is the black one moved to white.
        let white = shot.load(Vec3::ONE).unwrap();
        for (a, b) in white.image().data.iter().zip(&small.on(Vec3::ONE).data) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        // A copy half the size in train_2 is taken as it is, for the view it copies only.
        let copy = gray(15, 10, 0.25);
        let copy_path = dir.path().join("train_2/r_0.png");
        std::fs::create_dir(dir.path().join("train_2")).unwrap();
        super::super::image::write_image(&copy_path, &copy).unwrap();
        let shots = read_shots(dir.path()).unwrap().downscaled(2).unwrap();
        let (taken, averaged) = (&shots.train[0], &shots.train[1]);
        assert_eq!((&taken.path, taken.downscale), (&copy_path, 1));
        assert_eq!(taken.camera.focal, full.train[0].camera.focal / 2.0);
        assert_eq!(taken.camera.size, Vec2::new(15.0, 10.0));
        assert!(
            taken
                .load(Vec3::ZERO)
                .unwrap()
                .image()
                .data
                .iter()
                .all(|v| (v - 0.25).abs() < 0.01)
        );
        assert_eq!(averaged.downscale, 2);
        assert_eq!(averaged.load(Vec3::ZERO).unwrap().size().0, 15);
        // A copy of another size is refused by name.
        let wrong = gray(12, 8, 0.25);
        super::super::image::write_image(&copy_path, &wrong).unwrap();
        let err = read_shots(dir.path())
            .unwrap()
            .downscaled(2)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("train_2/r_0.png: size 12x8 is not") && err.contains("(about 15x10)"),
            "{err}"
        );
        // A factor larger than the picture.
        let err = read_shots(dir.path())
            .unwrap()
            .downscaled(32)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("30x20 pixels cannot be downscaled 32x"),
            "{err}"
        );
        // A picture that shrank after the dataset was read to less than a block.
        let shot = read_shots(dir.path()).unwrap().downscaled(4).unwrap().train[1].clone();
        let tiny = gray(2, 2, 0.5);
        super::super::image::write_image(&dir.path().join("train/r_1.png"), &tiny).unwrap();
        let err = shot.load(Vec3::ZERO).unwrap_err().to_string();
        assert!(
            err.contains("decodes to 2x2 pixels (0x0 downscaled 4x), but its camera is 7x5"),
            "{err}"
        );
    }

    /// A view read from an 8-bit RGBA picture gives back its bytes exactly, on any background
    /// (colors of uncovered pixels as 0), and its image is them composited, bit for bit, on its
    /// background or another; one from a 16-bit picture has no 8-bit form.
    #[test]
    fn eight_bit_pictures_keep_their_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (9u32, 7u32);
        let mut rng = fastrand::Rng::with_seed(5);
        let mut bytes: Vec<u8> = (0..w * h * 4).map(|_| rng.u8(..)).collect();
        bytes[3] = 0; // one uncovered pixel
        bytes[7] = 255; // and one opaque
        let path = dir.path().join("rgba.png");
        image::RgbaImage::from_raw(w, h, bytes.clone())
            .unwrap()
            .save(&path)
            .unwrap();
        let camera = Camera {
            size: Vec2::new(w as f32, h as f32),
            ..Default::default()
        };
        let want: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|p| match p[3] {
                0 => 0,
                _ => u32::from_le_bytes([p[0], p[1], p[2], p[3]]),
            })
            .collect();
        // The f32 image made from the words: each byte / 255, composited as c a + b (1 - a).
        let composited = |b: Vec3| -> Vec<f32> {
            let unorm = |k: u8| k as f32 / 255.0;
            (bytes.chunks_exact(4))
                .flat_map(|p| (0..3).map(move |c| (p, c)))
                .map(|(p, c)| unorm(p[c]) * unorm(p[3]) + b[c] * (1.0 - unorm(p[3])))
                .collect()
        };
        let mut scratch = Image {
            width: 0,
            height: 0,
            channels: 3,
            data: vec![],
        };
        for background in [Vec3::ZERO, Vec3::ONE, Vec3::new(0.3, 0.6, 0.9)] {
            let view = Shot::new(path.clone(), camera).load(background).unwrap();
            assert_eq!(view.rgba8().unwrap(), want, "on {background}");
            assert_eq!(view.image().data, composited(background));
            // On another background, into a reused image.
            let other = Vec3::new(0.8, 0.1, 0.5);
            assert_eq!(view.on_into(other, &mut scratch).data, composited(other));
        }
        let path = dir.path().join("rgb16.png");
        let values: Vec<u16> = (0..w * h * 3).map(|_| rng.u16(..)).collect();
        image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, values)
            .unwrap()
            .save(&path)
            .unwrap();
        let view = Shot::new(path, camera).load(Vec3::ZERO).unwrap();
        assert!(view.rgba8().is_none());
    }

    /// A dataset's footprint, read from headers, is what its loaded views hold: 4 bytes per
    /// pixel of 8-bit pictures (PNG, with alpha or not, and JPEG), 16 of others, taken smaller
    /// or not; an opaque 16-bit picture's view holds no coverage, 4 bytes per pixel less.
    #[test]
    fn a_footprint_is_what_the_views_hold() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (12u32, 8u32);
        let mut rng = fastrand::Rng::with_seed(3);
        let mut bytes = |n: u32| -> Vec<u8> { (0..w * h * n).map(|_| rng.u8(..)).collect() };
        let path = |name: &str| dir.path().join(name);
        image::RgbImage::from_raw(w, h, bytes(3))
            .unwrap()
            .save(path("rgb.png"))
            .unwrap();
        image::RgbImage::from_raw(w, h, bytes(3))
            .unwrap()
            .save(path("rgb.jpg"))
            .unwrap();
        image::RgbaImage::from_raw(w, h, bytes(4))
            .unwrap()
            .save(path("rgba.png"))
            .unwrap();
        let deep: Vec<u16> = (0..w * h * 4).map(|k| (k * 997 % 65536) as u16).collect();
        image::ImageBuffer::<image::Rgba<u16>, _>::from_raw(w, h, deep)
            .unwrap()
            .save(path("rgba16.png"))
            .unwrap();
        let camera = Camera {
            size: Vec2::new(w as f32, h as f32),
            ..Default::default()
        };
        let shots = |names: &[&str]| Shots {
            train: names.iter().map(|n| Shot::new(path(n), camera)).collect(),
            test: vec![],
            points: vec![],
        };
        let held = |shots: Shots| -> u64 {
            let data = shots.load(Vec3::ZERO).unwrap();
            data.train.iter().map(View::held_bytes).sum()
        };
        for shots in [
            shots(&["rgb.png", "rgb.jpg", "rgba.png", "rgba16.png"]),
            shots(&["rgb.png", "rgba16.png"]).downscaled(2).unwrap(),
        ] {
            let footprint = shots.footprint().unwrap();
            assert!(footprint.decoding > footprint.held / shots.train.len() as u64);
            let size = shots.train[0].camera.size;
            assert_eq!(footprint.largest, (size.x * size.y) as u64);
            assert_eq!(footprint.held, held(shots));
        }
        let opaque = path("rgb16.png");
        let deep: Vec<u16> = (0..w * h * 3).map(|k| (k * 991 % 65536) as u16).collect();
        image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, deep)
            .unwrap()
            .save(&opaque)
            .unwrap();
        let footprint = shots(&["rgb16.png"]).footprint().unwrap();
        assert_eq!(
            footprint.held,
            held(shots(&["rgb16.png"])) + 4 * (w * h) as u64
        );
        let missing = shots(&["none.png"]).footprint().unwrap_err().to_string();
        assert!(missing.contains("none.png"), "{missing}");
    }

    /// What the format cannot say is refused by file and frame.
    #[test]
    fn views_the_blender_format_cannot_hold_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut fisheye = view(Vec3::new(3.0, 1.0, -2.0), Vec3::ZERO);
        fisheye.camera.model = CameraModel::KannalaBrandt;
        let plain = view(Vec3::new(-3.0, 1.0, -2.0), Vec3::ZERO);
        let data = Dataset {
            train: vec![plain.clone(), fisheye],
            test: vec![plain],
            points: vec![],
        };
        let err = write_blender(dir.path(), &data).unwrap_err().to_string();
        assert!(
            err.contains("transforms_train.json: frames[1] cannot hold"),
            "{err}"
        );
        let written = std::fs::read_dir(dir.path()).unwrap().count();
        assert_eq!(written, 0, "nothing is written");
    }

    /// A failed write leaves no view and no transforms behind.
    #[test]
    fn a_dataset_is_written_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let eyes = [Vec3::new(3.0, 1.0, -2.0), Vec3::new(-2.5, -0.5, 2.0)];
        let data = Dataset {
            train: eyes.iter().map(|e| view(*e, Vec3::ZERO)).collect(),
            test: vec![view(Vec3::new(0.5, 2.0, 3.0), Vec3::ZERO)],
            points: vec![],
        };
        std::fs::create_dir_all(dir.path().join("test/r_0.png")).unwrap();
        let err = write_blender(dir.path(), &data).unwrap_err().to_string();
        assert!(err.contains("r_0.png: it is a folder"), "{err}");
        for written in [
            "train",
            "train/r_0.png",
            "transforms_train.json",
            "transforms_test.json",
        ] {
            assert!(!dir.path().join(written).exists(), "{written} was written");
        }
    }

    /// A one-view nerfstudio dataset (a 30 x 20 picture) whose `transforms.json` has `fields`
    /// over good ones (a `frame` field overrides its frame's), read back.
    fn nerfstudio(fields: serde_json::Value, frame: serde_json::Value) -> String {
        let dir = tempfile::tempdir().unwrap();
        let picture = view(Vec3::new(3.0, 1.0, -2.0), Vec3::ZERO).into_image();
        super::super::image::write_image(&dir.path().join("a.png"), &picture).unwrap();
        let mut json = serde_json::json!({
            "fl_x": 24.0, "fl_y": 24.0, "cx": 15.0, "cy": 10.0, "w": 30, "h": 20,
            "frames": [{
                "file_path": "a.png",
                "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]],
            }],
        });
        json.as_object_mut()
            .unwrap()
            .extend(fields.as_object().unwrap().clone());
        let first = json["frames"][0].as_object_mut().unwrap();
        first.extend(frame.as_object().unwrap().clone());
        std::fs::write(dir.path().join("transforms.json"), json.to_string()).unwrap();
        match read_nerfstudio(dir.path(), Vec3::ZERO) {
            Ok(data) => format!("read {} view", data.test.len()),
            Err(e) => e.to_string(),
        }
    }

    /// Intrinsics and poses that would render something else than the picture are refused by
    /// field (the frame's where it has one).
    #[test]
    fn nerfstudio_values_are_checked_by_field() {
        use serde_json::json;
        let none = json!({});
        assert_eq!(nerfstudio(none.clone(), none.clone()), "read 1 view");
        let opencv = json!({"camera_model": "OPENCV", "k1": 0.05, "k4": -0.01, "p1": 0.002});
        assert_eq!(nerfstudio(opencv, none.clone()), "read 1 view");
        let cases = [
            (
                json!({"fl_x": 0.0}),
                none.clone(),
                "fl_x must be positive, not 0",
            ),
            (
                none.clone(),
                json!({"fl_y": -5.0}),
                "frames[0].fl_y must be positive",
            ),
            (
                json!({"w": 30.5}),
                none.clone(),
                "w must be a positive whole number of pixels",
            ),
            (
                json!({"h": -1}),
                none.clone(),
                "h must be a positive whole number of pixels",
            ),
            (
                json!({"w": 31}),
                none.clone(),
                "w and h say 31x20 pixels, but",
            ),
            (
                none.clone(),
                json!({"transform_matrix": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]}),
                "frames[0].transform_matrix is not a rigid pose",
            ),
            (
                none.clone(),
                json!({"transform_matrix": [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]}),
                "frames[0].transform_matrix mirrors the world",
            ),
            (
                none.clone(),
                json!({"transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0.1, 0, 0, 1]]}),
                "frames[0].transform_matrix must end with the row [0, 0, 0, 1]",
            ),
            (
                // A lens that folds (k1 < 0) before the rays of a picture far off its centre.
                json!({"camera_model": "OPENCV", "k1": -0.1}),
                json!({"cx": -60.0}),
                "the lens (k1-k4, p1, p2) of frames[0].file_path finds no rectangle of the 30x20 picture's pixels",
            ),
            (
                // The same lens without a camera_model: PINHOLE, and the lens still applies.
                json!({"k1": -0.1}),
                json!({"cx": -60.0}),
                "the lens (k1-k4, p1, p2) of frames[0].file_path finds no rectangle",
            ),
            (
                json!({"camera_model": "OPENCV_FISHEYE", "k1": 0.01, "p2": 0.001}),
                none.clone(),
                "p2 is a tangential term, which OPENCV_FISHEYE does not have",
            ),
        ];
        for (fields, frame, want) in cases {
            let got = nerfstudio(fields, frame);
            assert!(got.contains("transforms.json: "), "{got}");
            assert!(got.contains(want), "{want}: {got}");
        }
    }
}
