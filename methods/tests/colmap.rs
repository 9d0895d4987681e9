//! COLMAP datasets: a small sparse model written in both COLMAP formats (binary and text) from
//! known cameras (pinhole, simple pinhole, distortion-free OPENCV and OPENCV_FISHEYE; lenses
//! with distortion are `lens.rs`'s) and known points, with small pictures, read back with the
//! same poses, intrinsics and points; every 8th view by name is held out; downscaled pictures
//! scale the intrinsics; bad models are refused with errors naming the file and the element.

use splat_runtime::glam::{DQuat, Mat3, Vec2, Vec3, Vec4};
use splat_runtime::io::dataset::colmap::read_colmap;
use splat_runtime::io::dataset::{Dataset, DatasetError, View, read, read_shots};
use splat_runtime::{Camera, CameraModel};
use std::path::Path;

pub(super) const W: u32 = 32;
pub(super) const H: u32 = 24;
const FISHEYE_K: [f64; 4] = [0.05, -0.01, 0.002, -0.0005];

/// A camera of the model: COLMAP id, model id and name, and parameters in COLMAP's order.
pub(super) struct Cam {
    pub id: i32,
    pub model: i32,
    pub name: &'static str,
    pub params: Vec<f64>,
}

/// An image of the model: its pose is `pose`'s rotation and translation.
pub(super) struct Shot {
    id: i32,
    pub camera: i32,
    pub name: String,
    pose: Camera,
}

struct Pt {
    id: u64,
    position: Vec3,
    rgb: [u8; 3],
}

pub(super) struct Model {
    pub cameras: Vec<Cam>,
    pub shots: Vec<Shot>,
    points: Vec<Pt>,
}

fn cameras() -> Vec<Cam> {
    let fisheye = [14.0, 14.5, 16.0, 12.0].into_iter().chain(FISHEYE_K);
    vec![
        Cam {
            id: 1,
            model: 1,
            name: "PINHOLE",
            params: vec![30.0, 31.0, 16.5, 12.25],
        },
        Cam {
            id: 2,
            model: 5,
            name: "OPENCV_FISHEYE",
            params: fisheye.collect(),
        },
        Cam {
            id: 3,
            model: 0,
            name: "SIMPLE_PINHOLE",
            params: vec![28.0, 16.0, 12.0],
        },
        Cam {
            id: 7,
            model: 4,
            name: "OPENCV",
            params: vec![29.0, 29.5, 15.5, 11.5, 0.0, 0.0, 0.0, 0.0],
        },
    ]
}

/// The camera that `cam` should read back as (at the calibrated size, identity pose).
fn intrinsics(cam: &Cam) -> Camera {
    let p: Vec<f32> = cam.params.iter().map(|x| *x as f32).collect();
    let (focal, principal) = if cam.model == 0 {
        (Vec2::splat(p[0]), Vec2::new(p[1], p[2]))
    } else {
        (Vec2::new(p[0], p[1]), Vec2::new(p[2], p[3]))
    };
    let fisheye = cam.model == 5;
    Camera {
        focal,
        principal,
        size: Vec2::new(W as f32, H as f32),
        model: if fisheye {
            CameraModel::KannalaBrandt
        } else {
            CameraModel::Pinhole
        },
        distortion: if fisheye {
            Vec4::from_slice(&p[4..])
        } else {
            Vec4::ZERO
        },
        ..Default::default()
    }
}

/// An OpenCV camera at `eye` looking at the origin.
fn look_at(eye: Vec3) -> Camera {
    let f = (-eye).normalize();
    let r = f.cross(Vec3::Y).normalize();
    let d = f.cross(r);
    let rotation = Mat3::from_cols(r, d, f).transpose();
    Camera {
        rotation,
        translation: -(rotation * eye),
        ..Default::default()
    }
}

/// Ten images named out of order (the ids too), on the four cameras; 20 points with colors.
pub(super) fn model() -> Model {
    let shots = [3, 7, 0, 9, 5, 1, 8, 2, 6, 4]
        .into_iter()
        .map(|k: usize| {
            let a = k as f32 * 0.6;
            Shot {
                id: 50 - k as i32,
                camera: [1, 2, 3, 7][k % 4],
                name: format!("view_{k:02}.png"),
                pose: look_at(Vec3::new(
                    3.0 * a.cos(),
                    0.3 * k as f32 - 1.0,
                    3.0 * a.sin(),
                )),
            }
        })
        .collect();
    let points = (0..20u8)
        .map(|k| Pt {
            id: 1000 + k as u64,
            position: Vec3::new(
                k as f32 * 0.1 - 1.0,
                (k % 3) as f32 * 0.25,
                -(k as f32) / 7.0,
            ),
            rgb: [k * 12, 255 - k, k % 5 * 50],
        })
        .collect();
    Model {
        cameras: cameras(),
        shots,
        points,
    }
}

/// COLMAP's `qw qx qy qz` of a rotation matrix.
fn quaternion(rotation: Mat3) -> [f64; 4] {
    let q = DQuat::from_mat3(&rotation.as_dmat3()).normalize();
    [q.w, q.x, q.y, q.z]
}

fn translation(cam: &Camera) -> [f64; 3] {
    cam.translation.as_dvec3().to_array()
}

/// Little-endian bytes of a binary model file.
#[derive(Default)]
struct Bytes(Vec<u8>);

impl Bytes {
    fn put(&mut self, b: &[u8]) -> &mut Self {
        self.0.extend_from_slice(b);
        self
    }
    fn f64s(&mut self, xs: &[f64]) -> &mut Self {
        for x in xs {
            self.put(&x.to_le_bytes());
        }
        self
    }
}

fn write_binary(dir: &Path, m: &Model) {
    std::fs::create_dir_all(dir).unwrap();
    let mut b = Bytes::default();
    b.put(&(m.cameras.len() as u64).to_le_bytes());
    for c in &m.cameras {
        b.put(&c.id.to_le_bytes()).put(&c.model.to_le_bytes());
        b.put(&(W as u64).to_le_bytes())
            .put(&(H as u64).to_le_bytes());
        b.f64s(&c.params);
    }
    std::fs::write(dir.join("cameras.bin"), &b.0).unwrap();

    let mut b = Bytes::default();
    b.put(&(m.shots.len() as u64).to_le_bytes());
    for s in &m.shots {
        b.put(&s.id.to_le_bytes());
        b.f64s(&quaternion(s.pose.rotation))
            .f64s(&translation(&s.pose));
        b.put(&s.camera.to_le_bytes())
            .put(s.name.as_bytes())
            .put(&[0]);
        // Two 2D points, one without a 3D point.
        b.put(&2u64.to_le_bytes());
        b.f64s(&[3.5, 4.5]).put(&1000i64.to_le_bytes());
        b.f64s(&[7.0, 1.0]).put(&(-1i64).to_le_bytes());
    }
    std::fs::write(dir.join("images.bin"), &b.0).unwrap();

    let mut b = Bytes::default();
    b.put(&(m.points.len() as u64).to_le_bytes());
    for p in &m.points {
        b.put(&p.id.to_le_bytes());
        b.f64s(&p.position.as_dvec3().to_array())
            .put(&p.rgb)
            .f64s(&[0.7]);
        b.put(&2u64.to_le_bytes());
        for (image, point2d) in [(50i32, 0i32), (49, 1)] {
            b.put(&image.to_le_bytes()).put(&point2d.to_le_bytes());
        }
    }
    std::fs::write(dir.join("points3D.bin"), &b.0).unwrap();
}

fn join(xs: &[f64]) -> String {
    xs.iter().map(f64::to_string).collect::<Vec<_>>().join(" ")
}

fn write_text(dir: &Path, m: &Model) {
    std::fs::create_dir_all(dir).unwrap();
    let mut t = String::from("# Camera list with one line of data per camera:\n\n");
    for c in &m.cameras {
        t += &format!("{} {} {W} {H} {}\n", c.id, c.name, join(&c.params));
    }
    std::fs::write(dir.join("cameras.txt"), t).unwrap();

    let mut t = String::from("# Image list with two lines of data per image:\n#\n");
    for (k, s) in m.shots.iter().enumerate() {
        let pose = [
            quaternion(s.pose.rotation).as_slice(),
            &translation(&s.pose),
        ]
        .concat();
        t += &format!("{} {} {} {}\n", s.id, join(&pose), s.camera, s.name);
        // The 2D points line may be empty.
        t += if k % 2 == 0 {
            "3.5 4.5 1000 7 1 -1\n"
        } else {
            "\n"
        };
    }
    std::fs::write(dir.join("images.txt"), t).unwrap();

    let mut t = String::from("# 3D point list with one line of data per point:\n");
    for p in &m.points {
        let [r, g, b] = p.rgb;
        let xyz = join(&p.position.as_dvec3().to_array());
        t += &format!("{} {xyz} {r} {g} {b} 0.7 50 0 49 1\n", p.id);
    }
    std::fs::write(dir.join("points3D.txt"), t).unwrap();
}

/// The color of the picture of image `name`.
fn color(name: &str) -> [u8; 3] {
    let k = name.bytes().map(u32::from).sum::<u32>() as u8;
    [k, 255 - k, 90]
}

/// One-color PNGs of `width` x `height` for every image of `m`, in `dir`.
fn write_pictures(dir: &Path, m: &Model, width: u32, height: u32) {
    std::fs::create_dir_all(dir).unwrap();
    for s in &m.shots {
        let path = dir.join(&s.name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        image::RgbImage::from_pixel(width, height, image::Rgb(color(&s.name)))
            .save(path)
            .unwrap();
    }
}

/// A dataset folder holding `m` (binary or text) in `sparse/0` and its pictures in `images`.
pub(super) fn dataset(m: &Model, binary: bool) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let sparse = dir.path().join("sparse/0");
    if binary {
        write_binary(&sparse, m);
    } else {
        write_text(&sparse, m);
    }
    write_pictures(&dir.path().join("images"), m, W, H);
    dir
}

/// The file names of `views`.
fn names(views: &[View]) -> Vec<String> {
    let file = |v: &View| {
        Path::new(&v.name)
            .file_name()
            .unwrap()
            .to_string_lossy()
            .to_string()
    };
    views.iter().map(file).collect()
}

fn close(a: &[f32], b: &[f32]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6)
}

/// `data` holds `m`'s views sorted by name, every 8th held out, with the cameras and
/// pictures they were written with (intrinsics scaled by `scale`), and `m`'s points.
fn check(data: &Dataset, m: &Model, scale: f32) {
    let mut shots: Vec<&Shot> = m.shots.iter().collect();
    shots.sort_by(|a, b| a.name.cmp(&b.name));
    assert_eq!(names(&data.test), ["view_00.png", "view_08.png"]);
    let train: Vec<String> = [1, 2, 3, 4, 5, 6, 7, 9]
        .map(|k| format!("view_{k:02}.png"))
        .into();
    assert_eq!(names(&data.train), train);

    let views = data.test.iter().chain(&data.train);
    let held_out_first = [0, 8].into_iter().chain([1, 2, 3, 4, 5, 6, 7, 9]);
    for (view, k) in views.zip(held_out_first) {
        let shot = shots[k];
        let cam = m.cameras.iter().find(|c| c.id == shot.camera).unwrap();
        let want = intrinsics(cam);
        let got = view.camera;
        assert!(close(
            &got.rotation.to_cols_array(),
            &shot.pose.rotation.to_cols_array()
        ));
        assert!(close(
            &got.translation.to_array(),
            &shot.pose.translation.to_array()
        ));
        assert_eq!(got.focal, want.focal * scale, "{}", shot.name);
        assert_eq!(got.principal, want.principal * scale);
        assert_eq!(got.size, want.size * scale);
        assert_eq!((got.model, got.distortion), (want.model, want.distortion));
        let rgb = color(&shot.name).map(|c| c as f32 / 255.0);
        assert_eq!(view.image().data[..3], rgb);
        assert_eq!(view.size().0 as f32, W as f32 * scale);
    }

    assert_eq!(data.points.len(), m.points.len());
    for (got, want) in data.points.iter().zip(&m.points) {
        assert_eq!(got.position, want.position);
        assert_eq!(
            got.color,
            Vec3::from_array(want.rgb.map(|c| c as f32 / 255.0))
        );
    }
}

#[test]
fn binary_and_text_models_read_back_as_written() {
    let m = model();
    for binary in [true, false] {
        let dir = dataset(&m, binary);
        check(&read_colmap(dir.path(), Vec3::ZERO, None).unwrap(), &m, 1.0);
        // `read` recognises the layout.
        check(&read(dir.path(), Vec3::ZERO).unwrap(), &m, 1.0);
    }
}

/// Text files saved by an editor that starts them with a byte-order mark read the same.
#[test]
fn text_models_with_a_byte_order_mark_read_back() {
    let m = model();
    let dir = dataset(&m, false);
    for file in ["cameras.txt", "images.txt", "points3D.txt"] {
        let path = dir.path().join("sparse/0").join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, format!("\u{feff}{text}")).unwrap();
    }
    check(&read(dir.path(), Vec3::ZERO).unwrap(), &m, 1.0);
}

/// A model straight in `sparse/` is found too.
#[test]
fn a_model_in_sparse_is_found() {
    let m = model();
    let dir = tempfile::tempdir().unwrap();
    write_binary(&dir.path().join("sparse"), &m);
    write_pictures(&dir.path().join("images"), &m, W, H);
    check(&read(dir.path(), Vec3::ZERO).unwrap(), &m, 1.0);
}

#[test]
fn downscaled_pictures_scale_the_intrinsics() {
    let m = model();
    let dir = dataset(&m, true);
    write_pictures(&dir.path().join("images_2"), &m, W / 2, H / 2);
    check(
        &read_colmap(dir.path(), Vec3::ZERO, Some("images_2")).unwrap(),
        &m,
        0.5,
    );

    write_pictures(&dir.path().join("images_square"), &m, 16, 16);
    let err = read_colmap(dir.path(), Vec3::ZERO, Some("images_square")).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("images_square") && text.contains("aspect ratio"),
        "{text}"
    );
    assert!(
        text.contains("16x16") && text.contains("cameras.bin"),
        "{text}"
    );
}

/// Image names with folders (`cam0/view_00.png`, as a multi-camera rig gives them) find their
/// copies at the same place in `images_2`; without copies they are averaged.
#[test]
fn copies_of_pictures_in_folders_are_found() {
    let mut m = model();
    for (k, s) in m.shots.iter_mut().enumerate() {
        s.name = format!("cam{}/{}", k % 2, s.name);
    }
    let dir = dataset(&m, false);
    let averaged = read_shots(dir.path()).unwrap().downscaled(2).unwrap();
    assert!(averaged.train.iter().all(|s| s.downscale == 2));
    write_pictures(&dir.path().join("images_2"), &m, W / 2, H / 2);
    let shots = read_shots(dir.path()).unwrap().downscaled(2).unwrap();
    for shot in shots.train.iter().chain(&shots.test) {
        assert_eq!(shot.downscale, 1, "{}", shot.path.display());
        let place = shot.path.strip_prefix(dir.path().join("images_2")).unwrap();
        assert!(
            m.shots.iter().any(|s| Path::new(&s.name) == place),
            "{place:?}"
        );
    }
    let data = shots.load(Vec3::ZERO).unwrap();
    let sizes = data.train.iter().map(|v| v.size());
    assert!(sizes.into_iter().all(|size| size == (W / 2, H / 2)));
}

/// The error of reading `m` (binary or text) after `spoil` changed the dataset folder.
fn error_after(m: &Model, binary: bool, spoil: impl FnOnce(&Path)) -> String {
    let dir = dataset(m, binary);
    spoil(dir.path());
    read_colmap(dir.path(), Vec3::ZERO, None)
        .unwrap_err()
        .to_string()
}

fn assert_mentions(err: &str, needles: &[&str]) {
    for n in needles {
        assert!(err.contains(n), "`{n}` is not in: {err}");
    }
}

#[test]
fn bad_binary_models_are_refused_by_file_and_element() {
    let m = model();
    let bin = |dir: &Path, file: &str| dir.join("sparse/0").join(file);

    let err = error_after(&m, true, |dir| {
        let path = bin(dir, "images.bin");
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 5]).unwrap();
    });
    assert_mentions(&err, &["images.bin", "image 46", "cut short"]);

    // A header claiming 10^12 points is an error, not an allocation.
    let err = error_after(&m, true, |dir| {
        let path = bin(dir, "points3D.bin");
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[..8].copy_from_slice(&1_000_000_000_000u64.to_le_bytes());
        std::fs::write(&path, bytes).unwrap();
    });
    assert_mentions(&err, &["points3D.bin", "point count", "1000000000000"]);

    let mut missing = model();
    missing.shots[4].camera = 9;
    let err = error_after(&missing, true, |_| {});
    assert_mentions(
        &err,
        &["images.bin: image 45 refers to camera 9, which is not in cameras.bin"],
    );

    let mut fov = model();
    fov.cameras[3].model = 7;
    let err = error_after(&fov, true, |_| {});
    assert_mentions(
        &err,
        &["cameras.bin", "camera 7", "FOV (7)", "image_undistorter"],
    );

    let mut prism = model();
    prism.cameras[0].model = 10;
    let err = error_after(&prism, true, |_| {});
    assert_mentions(
        &err,
        &[
            "cameras.bin",
            "camera 1",
            "THIN_PRISM_FISHEYE (10)",
            "image_undistorter",
        ],
    );

    // A lens that folds (k1 < 0) before the rays of a picture far off its principal point.
    let mut blind = model();
    blind.cameras[3].params = vec![29.0, 29.5, -60.0, 11.5, -0.1, 0.0, 0.0, 0.0];
    let err = error_after(&blind, true, |_| {});
    assert_mentions(
        &err,
        &[
            "camera 7's lens (in cameras.bin) finds no rectangle of the 32x24 picture's pixels",
            ".png",
        ],
    );

    let mut unknown = model();
    unknown.cameras[0].model = -3;
    let err = error_after(&unknown, true, |_| {});
    assert_mentions(&err, &["cameras.bin", "camera 1", "model id -3"]);

    let mut nan = model();
    nan.points[2].position.y = f32::NAN;
    let err = error_after(&nan, true, |_| {});
    assert_mentions(&err, &["points3D.bin", "point 1002", "non-finite"]);

    let mut latin1 = model();
    latin1.shots[0].name = "caf\u{e9}.png".into();
    let err = error_after(&latin1, true, |dir| {
        let path = bin(dir, "images.bin");
        let bytes = std::fs::read(&path).unwrap();
        // "é" in Latin-1 (one byte) instead of UTF-8 (two).
        let at = bytes.windows(2).position(|w| w == [0xc3, 0xa9]).unwrap();
        let spoilt = [&bytes[..at], &[0xe9], &bytes[at + 2..]].concat();
        std::fs::write(&path, spoilt).unwrap();
    });
    assert_mentions(&err, &["images.bin", "image 47", "not UTF-8"]);

    let err = error_after(&m, true, |dir| {
        std::fs::remove_file(dir.join("images/view_06.png")).unwrap();
    });
    assert_mentions(&err, &["cannot read", "view_06.png"]);
}

/// Whatever the bytes, reading is an answer, never a panic: every truncation of every binary
/// file is an error naming it, and no byte set to 0xff panics.
#[test]
fn cut_or_corrupt_binary_files_never_panic() {
    let dir = dataset(&model(), true);
    for file in ["cameras.bin", "images.bin", "points3D.bin"] {
        let path = dir.path().join("sparse/0").join(file);
        let bytes = std::fs::read(&path).unwrap();
        for len in 0..bytes.len() {
            std::fs::write(&path, &bytes[..len]).unwrap();
            let err = read_colmap(dir.path(), Vec3::ZERO, None).unwrap_err();
            assert_mentions(&err.to_string(), &[file]);
        }
        for at in 0..bytes.len() {
            let mut spoilt = bytes.clone();
            spoilt[at] = 0xff;
            std::fs::write(&path, spoilt).unwrap();
            let _ = read_colmap(dir.path(), Vec3::ZERO, None);
        }
        std::fs::write(&path, bytes).unwrap();
    }
}

#[test]
fn bad_text_models_are_refused_by_file_element_and_line() {
    let mut missing = model();
    missing.shots[0].camera = 4;
    let err = error_after(&missing, false, |_| {});
    assert_mentions(
        &err,
        &["images.txt: image 47 refers to camera 4, which is not in cameras.txt"],
    );

    let mut fov = model();
    fov.cameras[3].name = "FOV";
    let err = error_after(&fov, false, |_| {});
    assert_mentions(
        &err,
        &[
            "cameras.txt",
            "camera 7 (line 6)",
            "FOV (7)",
            "image_undistorter",
        ],
    );

    let err = error_after(&model(), false, |dir| {
        let path = dir.join("sparse/0/points3D.txt");
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, text.replace("\n1003 ", "\n1003 inf ")).unwrap();
    });
    assert_mentions(&err, &["points3D.txt", "point 1003 (line 5)", "non-finite"]);

    // One line per image, without the 2D points' lines: every other image would be lost.
    let err = error_after(&model(), false, |dir| {
        let path = dir.join("sparse/0/images.txt");
        let text = std::fs::read_to_string(&path).unwrap();
        let firsts: Vec<&str> = text.lines().filter(|l| l.ends_with(".png")).collect();
        std::fs::write(&path, firsts.join("\n")).unwrap();
    });
    assert_mentions(
        &err,
        &[
            "images.txt",
            "line 2",
            "2D points",
            "of the image on line 1",
        ],
    );

    let err = error_after(&model(), false, |dir| {
        std::fs::write(dir.join("sparse/0/cameras.txt"), "1 PINHOLE 32 24 30 31\n").unwrap();
    });
    assert_mentions(
        &err,
        &[
            "cameras.txt",
            "camera 1 (line 1)",
            "2 parameters",
            "PINHOLE (1) has 4",
        ],
    );
}

/// A folder without a model is not a dataset, and the message names all three layouts.
#[test]
fn a_folder_without_a_model_is_not_a_dataset() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("sparse")).unwrap();
    let err = read(dir.path(), Vec3::ZERO).unwrap_err();
    assert!(matches!(err, DatasetError::NotADataset(_)), "{err}");
    assert_mentions(
        &err.to_string(),
        &["Blender", "nerfstudio", "COLMAP", "sparse/0"],
    );
}
