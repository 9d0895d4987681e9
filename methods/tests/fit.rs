//! Training end to end on the CPU: a Blender-format dataset written from a known scene (RGBA
//! PNGs and `transforms_*.json`, OpenGL camera-to-world), read back (the cameras must be the
//! ones it was written with), and 3DGS fitted to it from points near the true centres; the
//! held-out views must get much closer to the truth. Bad datasets get errors naming the file
//! and the field.

use crate::common::gaussian_at;
use splat_methods::gs3d::{Method, Params};
use splat_runtime::glam::{Mat3, Mat4, Vec2, Vec3, Vec4};
use splat_runtime::io::dataset::{Dataset, DatasetError, read_blender};
use splat_runtime::train::fit::{FitOptions, StepReport, evaluate, fit};
use splat_runtime::train::{Checkpoint, DensifyOptions, Strategy, Trainable};
use splat_runtime::{Camera, CameraModel, RenderOptions, SplatMethod, render};
use std::path::Path;

const SIZE: u32 = 40;
const ANGLE_X: f32 = 0.8;

/// An OpenCV camera at `eye` looking at the origin.
pub(crate) fn look_at(eye: Vec3) -> Camera {
    let f = (-eye).normalize();
    let r = f.cross(Vec3::Y).normalize();
    let d = f.cross(r);
    let rotation = Mat3::from_cols(r, d, f).transpose();
    let focal = 0.5 * SIZE as f32 / (0.5 * ANGLE_X).tan();
    Camera {
        rotation,
        translation: -(rotation * eye),
        focal: Vec2::splat(focal),
        principal: Vec2::splat(SIZE as f32 / 2.0),
        size: Vec2::splat(SIZE as f32),
        ..Default::default()
    }
}

/// Camera-to-world in OpenGL axes, row-major, as Blender datasets store it.
fn blender_matrix(cam: &Camera) -> Vec<Vec<f32>> {
    let w2c = Mat4::from_cols(
        cam.rotation.x_axis.extend(0.0),
        cam.rotation.y_axis.extend(0.0),
        cam.rotation.z_axis.extend(0.0),
        cam.translation.extend(1.0),
    );
    let c2w = w2c.inverse() * Mat4::from_diagonal(Vec4::new(1.0, -1.0, -1.0, 1.0));
    let m = c2w.transpose().to_cols_array_2d();
    m.iter().map(|r| r.to_vec()).collect()
}

pub(crate) fn eye(k: usize, of: usize, height: f32) -> Vec3 {
    let a = k as f32 / of as f32 * std::f32::consts::TAU;
    Vec3::new(3.0 * a.cos(), height, 3.0 * a.sin())
}

/// Renders `params` through `cam` with method `M` into an RGBA PNG at `path` (straight alpha,
/// as Blender writes it).
fn save_view<M: SplatMethod>(path: &Path, params: &[M::Params], cam: &Camera) {
    let opts = RenderOptions {
        alpha: true,
        ..Default::default()
    };
    let frame = render::<M>(params, cam, &opts).unwrap();
    let alpha = frame.alpha.unwrap().data;
    let bytes: Vec<u8> = frame
        .color
        .data
        .chunks_exact(3)
        .zip(&alpha)
        .flat_map(|(c, a)| {
            let un = |v: f32| (v / a.max(1e-6)).clamp(0.0, 1.0);
            [un(c[0]), un(c[1]), un(c[2]), *a].map(|v| (v * 255.0).round() as u8)
        })
        .collect();
    let (w, h) = (cam.size.x as u32, cam.size.y as u32);
    image::RgbaImage::from_raw(w, h, bytes)
        .unwrap()
        .save(path)
        .unwrap();
}

/// Writes the split `name` of views of `scene` into `dir`; returns their cameras.
fn write_split(dir: &Path, name: &str, scene: &[Params], eyes: &[Vec3]) -> Vec<Camera> {
    std::fs::create_dir_all(dir.join(name)).unwrap();
    let mut frames = vec![];
    let mut cams = vec![];
    for (k, e) in eyes.iter().enumerate() {
        let cam = look_at(*e);
        let file = format!("{name}/r_{k}");
        save_view::<Method>(&dir.join(format!("{file}.png")), scene, &cam);
        frames.push(serde_json::json!({
            "file_path": format!("./{file}"),
            "transform_matrix": blender_matrix(&cam),
        }));
        cams.push(cam);
    }
    let json = serde_json::json!({ "camera_angle_x": ANGLE_X, "frames": frames });
    std::fs::write(
        dir.join(format!("transforms_{name}.json")),
        serde_json::to_string_pretty(&json).unwrap(),
    )
    .unwrap();
    cams
}

pub(crate) fn truth() -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(8);
    // Placed through a camera at the origin looking down +z, then moved to the origin.
    let cam = crate::common::camera(SIZE, SIZE);
    (0..40)
        .map(|_| {
            let px = Vec2::new(8.0 + 24.0 * rng.f32(), 8.0 + 24.0 * rng.f32());
            let z = 2.6 + 0.8 * rng.f32();
            let mut g = gaussian_at(&mut rng, &cam, px, z, -2.6);
            g.mean.z -= 3.0;
            g.opacity_logit = 1.0 + rng.f32();
            g
        })
        .collect()
}

/// Writes the known scene's Blender dataset into `dir`: 10 training views on three rings and
/// 3 held-out ones between them; returns the training cameras.
fn write_known_scene(dir: &Path) -> Vec<Camera> {
    let scene = truth();
    let train_eyes: Vec<Vec3> = (0..10)
        .map(|k| eye(k, 10, 0.8 * (k % 3) as f32 - 0.8))
        .collect();
    let test_eyes = [eye(1, 20, 0.3), eye(7, 20, -0.4), eye(13, 20, 0.1)];
    write_split(dir, "test", &scene, &test_eyes);
    write_split(dir, "train", &scene, &train_eyes)
}

/// The known scene's dataset ([`write_known_scene`]) read back, composited on black.
pub(crate) fn known_dataset() -> Dataset {
    let dir = tempfile::tempdir().unwrap();
    write_known_scene(dir.path());
    read_blender(dir.path(), Vec3::ZERO).unwrap()
}

/// The pose read back equals the one written, up to the f32 round trip through the file.
fn assert_same_pose(got: &Camera, want: &Camera) {
    let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4);
    let rotation = (got.rotation.to_cols_array(), want.rotation.to_cols_array());
    assert!(close(&rotation.0, &rotation.1), "{rotation:?}");
    let translation = (got.translation.to_array(), want.translation.to_array());
    assert!(close(&translation.0, &translation.1), "{translation:?}");
}

/// The true centres, moved, as gray isotropic primitives of method `M`.
pub(crate) fn moved_start<M: Trainable>(truth: &[Params]) -> Vec<M::Params> {
    let mut rng = fastrand::Rng::with_seed(3);
    let mut jitter = || Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5;
    truth
        .iter()
        .map(|g| M::from_point(g.mean + 0.1 * jitter(), Vec3::splat(0.5), 0.05))
        .collect()
}

/// `steps` steps at tile 8 (the test images are 40 x 40).
pub(crate) fn options(steps: usize) -> FitOptions {
    FitOptions {
        steps,
        render: RenderOptions {
            tile_size: 8,
            ..FitOptions::default().render
        },
        ..Default::default()
    }
}

#[test]
fn three_dgs_fits_a_blender_dataset_of_a_known_scene() {
    let dir = tempfile::tempdir().unwrap();
    let scene = truth();
    let train_cams = write_known_scene(dir.path());

    let data = read_blender(dir.path(), Vec3::ZERO).unwrap();
    assert_eq!((data.train.len(), data.test.len()), (10, 3));
    for (view, cam) in data.train.iter().zip(&train_cams) {
        assert_same_pose(&view.camera, cam);
        assert_eq!(view.camera.focal, cam.focal);
    }

    let mut params: Vec<Params> = moved_start::<Method>(&scene);
    let opts = options(300);
    let before = evaluate::<Method>(&params, &data.test, &opts).unwrap();
    let mut losses = vec![];
    fit::<Method>(&data, &mut params, 1.0, &opts, |r| losses.push(r.loss.loss)).unwrap();
    let after = evaluate::<Method>(&params, &data.test, &opts).unwrap();
    let mean = |l: &[f64]| l.iter().sum::<f64>() / l.len() as f64;
    let (first, last) = (mean(&losses[..30]), mean(&losses[losses.len() - 30..]));
    println!(
        "test PSNR {:.2} -> {:.2} dB, SSIM {:.3} -> {:.3}; training loss {first:.4} -> {last:.4}",
        before.psnr, after.psnr, before.ssim, after.ssim
    );
    assert!(last < 0.6 * first, "the training loss falls");
    // Measured 14.03 -> 25.40 dB (2026-12-06, 2 threads).
    assert!(after.psnr > 25.0, "held-out views get closer to the truth");
    assert!(after.ssim > before.ssim);
    // 300 steps train only the DC term of the colors: the higher SH bands are still zero.
    assert!(
        params
            .iter()
            .all(|p| p.sh[1..].iter().all(|c| *c == Vec3::ZERO))
    );
    assert!(
        params
            .iter()
            .any(|p| p.sh[0] != Method::from_point(p.mean, Vec3::splat(0.5), 0.05).sh[0])
    );
}

/// LinPrim's octahedra train with 3DGS's declarations (through the Gaussian they are stored
/// as); MCMC, whose per-step terms read a Gaussian's words, refuses them by name.
#[test]
fn linprim_fits_the_known_scene() {
    use splat_methods::linprim;
    let data = known_dataset();
    let mut params = moved_start::<linprim::Method>(&truth());
    let opts = options(300);
    let before = evaluate::<linprim::Method>(&params, &data.test, &opts).unwrap();
    fit::<linprim::Method>(&data, &mut params, 1.0, &opts, |_| {}).unwrap();
    let after = evaluate::<linprim::Method>(&params, &data.test, &opts).unwrap();
    println!(
        "LinPrim: test PSNR {:.2} -> {:.2} dB",
        before.psnr, after.psnr
    );
    assert!(after.psnr > 22.3, "measured 13.65 -> 22.70 dB");
    let mcmc = FitOptions {
        densify: Some(Strategy::Mcmc(Default::default())),
        ..options(1)
    };
    let err = fit::<linprim::Method>(&data, &mut params, 1.0, &mcmc, |_| {}).unwrap_err();
    assert!(err.to_string().contains("linprim: MCMC needs"), "{err}");
}

#[test]
fn sh_bands_unlock_every_thousand_steps() {
    let rates = Method::learning_rates(2.0);
    assert_eq!(rates.len(), 59);
    // Words 11..14: the DC term; then 3 words per coefficient, band floor(sqrt(i)).
    let band_of_word = |k: usize| ((((k - 14) / 3 + 1) as f32).sqrt()) as usize;
    for (k, r) in rates.iter().enumerate().skip(14) {
        assert_eq!(r.from_step, 1000 * band_of_word(k), "word {k}");
        assert_eq!(r.at(r.from_step - 1, 30_000), 0.0);
        assert!(r.at(r.from_step, 30_000) > 0.0);
    }
    let position = rates[0];
    assert!((position.at(0, 100) - 3.2e-4).abs() < 1e-9);
    assert!((position.at(100, 100) - 3.2e-6).abs() < 1e-11);
    // By field name (`like_3dgs!`): log scales, rotation, opacity, the DC term.
    let fixed = |k: usize| (rates[k].first, rates[k].last, rates[k].from_step);
    for (words, lr) in [
        (3..6, 5e-3),
        (6..10, 1e-3),
        (10..11, 5e-2),
        (11..14, 2.5e-3),
    ] {
        for k in words {
            assert_eq!(fixed(k), (lr, lr, 0), "word {k}");
        }
    }
}

#[test]
fn bad_datasets_are_refused_by_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let err = read_blender(dir.path(), Vec3::ZERO).unwrap_err();
    assert!(matches!(err, DatasetError::Io { .. }), "{err}");
    assert!(err.to_string().contains("transforms_train.json"), "{err}");
    let write =
        |json: &str| std::fs::write(dir.path().join("transforms_train.json"), json).unwrap();
    write(r#"{"frames": []}"#);
    let err = read_blender(dir.path(), Vec3::ZERO)
        .unwrap_err()
        .to_string();
    assert!(err.contains("camera_angle_x"), "{err}");
    write(
        r#"{"camera_angle_x": 0.7, "frames": [{"file_path": "./a", "transform_matrix": [[1, 0, 0]]}]}"#,
    );
    let err = read_blender(dir.path(), Vec3::ZERO)
        .unwrap_err()
        .to_string();
    assert!(err.contains("frames[0].transform_matrix"), "{err}");
    let identity = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
    write(&format!(
        r#"{{"camera_angle_x": 0.7, "frames": [{{"file_path": "./missing", "transform_matrix": {identity}}}]}}"#
    ));
    let err = read_blender(dir.path(), Vec3::ZERO)
        .unwrap_err()
        .to_string();
    assert!(err.contains("missing.png"), "{err}");
}

/// The fisheye's distortion coefficients in [`fisheye_dataset`].
pub(crate) const FISHEYE_K: Vec4 = Vec4::new(0.05, -0.01, 0.002, -0.0005);

/// A nerfstudio dataset in `dir` of `scene` seen by `M` through nine fisheye views
/// (OPENCV_FISHEYE, global intrinsics, frame 4 with its own focal length); returns the cameras.
fn fisheye_dataset<M: SplatMethod>(dir: &Path, scene: &[M::Params]) -> Vec<Camera> {
    let fisheye = |eye: Vec3, fl: f32| Camera {
        focal: Vec2::splat(fl),
        model: CameraModel::KannalaBrandt,
        distortion: FISHEYE_K,
        ..look_at(eye)
    };
    std::fs::create_dir_all(dir.join("images")).unwrap();
    let mut frames = vec![];
    let mut cams = vec![];
    for i in 0..9 {
        let fl = if i == 4 { 16.0 } else { 14.0 };
        let cam = fisheye(eye(i, 9, 0.6 * (i % 3) as f32 - 0.6), fl);
        let file = format!("images/frame_{i:03}.png");
        save_view::<M>(&dir.join(&file), scene, &cam);
        let mut frame = serde_json::json!({
            "file_path": file,
            "transform_matrix": blender_matrix(&cam),
        });
        if i == 4 {
            frame["fl_x"] = serde_json::json!(16.0);
            frame["fl_y"] = serde_json::json!(16.0);
        }
        frames.push(frame);
        cams.push(cam);
    }
    let k = FISHEYE_K;
    let json = serde_json::json!({
        "camera_model": "OPENCV_FISHEYE",
        "fl_x": 14.0, "fl_y": 14.0, "cx": 20.0, "cy": 20.0, "w": SIZE, "h": SIZE,
        "k1": k.x, "k2": k.y, "k3": k.z, "k4": k.w,
        "frames": frames,
    });
    std::fs::write(dir.join("transforms.json"), json.to_string()).unwrap();
    cams
}

/// Fits `M` to a fisheye dataset of its own renders of the truth (a method fits the images its
/// own model makes): the held-out views get at least 5 dB closer.
fn fits_fisheye_views<M: Trainable>(label: &str)
where
    M::Params: splat_methods::FromStored,
{
    let dir = tempfile::tempdir().unwrap();
    let scene: Vec<M::Params> = crate::common::as_method(truth());
    fisheye_dataset::<M>(dir.path(), &scene);
    let data = splat_runtime::io::dataset::read(dir.path(), Vec3::ZERO).unwrap();
    fits_views::<M>(&format!("{label} fisheye"), &data);
}

/// Fits `M` to `data` from [`moved_start`]: the held-out views get at least 5 dB closer.
fn fits_views<M: Trainable>(label: &str, data: &splat_runtime::io::dataset::Dataset) {
    let mut params = moved_start::<M>(&truth());
    let opts = options(150);
    let before = evaluate::<M>(&params, &data.test, &opts).unwrap();
    fit::<M>(data, &mut params, 1.0, &opts, |_| {}).unwrap();
    let after = evaluate::<M>(&params, &data.test, &opts).unwrap();
    println!(
        "{label}: test PSNR {:.2} -> {:.2} dB",
        before.psnr, after.psnr
    );
    // Measured +10.5 dB (3DGS fisheye and equiangular), +9.7 (3DGUT fisheye).
    assert!(
        after.psnr > before.psnr + 9.0,
        "{label}: held-out views get closer"
    );
}

/// The fisheye dataset reads back with the Kannala-Brandt cameras it was written with, every
/// 8th frame held out; 3DGUT trains on the fisheye images as they are.
#[test]
fn three_dgut_fits_a_nerfstudio_fisheye_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let scene: Vec<splat_methods::gut::Params> = crate::common::as_method(truth());
    let cams = fisheye_dataset::<splat_methods::gut::Method>(dir.path(), &scene);
    let data = splat_runtime::io::dataset::read(dir.path(), Vec3::ZERO).unwrap();
    assert_eq!(
        (data.train.len(), data.test.len()),
        (7, 2),
        "frames 0 and 8 held out"
    );
    let held_out = [&cams[0], &cams[8]];
    let trained: Vec<&Camera> = cams
        .iter()
        .enumerate()
        .filter(|(i, _)| i % 8 != 0)
        .map(|(_, c)| c)
        .collect();
    for (view, cam) in data
        .test
        .iter()
        .zip(held_out)
        .chain(data.train.iter().zip(trained))
    {
        assert_eq!(view.camera.model, CameraModel::KannalaBrandt);
        assert_eq!(view.camera.distortion, FISHEYE_K);
        assert_eq!(view.camera.focal, cam.focal);
        assert_eq!(view.camera.principal, cam.principal);
        assert_same_pose(&view.camera, cam);
    }
    fits_fisheye_views::<splat_methods::gut::Method>("3DGUT");
}

/// 3DGS trains on fisheye images too: EWA with the compiler's Jacobian of the fisheye.
#[test]
fn three_dgs_fits_a_nerfstudio_fisheye_dataset() {
    fits_fisheye_views::<splat_methods::gs3d::Method>("3DGS");
}

/// ... and through an equiangular camera, from the same source. No dataset format names that
/// model, so the views are made in memory: the fisheye dataset's poses and split.
#[test]
fn three_dgs_fits_equiangular_views() {
    use splat_runtime::io::dataset::View;
    let scene: Vec<Params> = truth();
    let opts = options(0);
    let view = |i: usize| {
        let camera = Camera {
            focal: Vec2::splat(14.0),
            model: CameraModel::Equiangular,
            ..look_at(eye(i, 9, 0.6 * (i % 3) as f32 - 0.6))
        };
        let image = render::<Method>(&scene, &camera, &opts.render)
            .unwrap()
            .color;
        View::new(format!("frame_{i:03}"), camera, image, None, Vec3::ZERO)
    };
    let data = Dataset {
        train: (0..9).filter(|i| i % 8 != 0).map(view).collect(),
        test: [0, 8].map(view).into(),
        points: vec![],
    };
    fits_views::<Method>("3DGS equiangular", &data);
}

/// What would go wrong at some later step is refused before the first: an extent that is not
/// a length (positions would not train, and density control would split or prune everything),
/// a view whose camera and image disagree, a view holding NaN or too few values.
#[test]
fn fit_refuses_a_bad_run_before_its_first_step() {
    use splat_runtime::frame::Image;
    use splat_runtime::io::dataset::View;
    let scene: Vec<Params> = truth();
    let opts = options(5);
    let view = |i: usize| {
        let camera = look_at(eye(i, 9, 0.0));
        let image = render::<Method>(&scene, &camera, &opts.render)
            .unwrap()
            .color;
        View::new(format!("frame_{i:03}"), camera, image, None, Vec3::ZERO)
    };
    let data = |last: View| Dataset {
        train: vec![view(1), view(2), last],
        test: vec![view(0)],
        points: vec![],
    };
    let refused = |data: &Dataset, extent: f32| {
        let mut params = scene.clone();
        let mut steps = 0;
        let e = fit::<Method>(data, &mut params, extent, &opts, |_| steps += 1).unwrap_err();
        assert_eq!(steps, 0, "refused after {steps} steps: {e}");
        e.to_string()
    };
    let good = data(view(3));
    for extent in [0.0, -1.0, f32::NAN] {
        let e = refused(&good, extent);
        assert!(e.contains("extent must be a positive length"), "{e}");
    }
    let mut small = view(3);
    small.camera.size = Vec2::new(20.0, 40.0);
    let e = refused(&data(small), 1.0);
    assert!(
        e.contains("view frame_003: its camera is 20x40, its image 40x40"),
        "{e}"
    );
    let image = view(3).into_image();
    let short = Image {
        data: image.data[..10].to_vec(),
        ..image.clone()
    };
    let mut nan = image.clone();
    nan.data[5] = f32::NAN;
    for (image, why) in [
        (short, "holds 10 values"),
        (nan, "NaN or infinite at value 5"),
    ] {
        let bad = View::new("bad".into(), view(3).camera, image, None, Vec3::ZERO);
        let e = refused(&data(bad), 1.0);
        assert!(e.contains("view bad: its ") && e.contains(why), "{e}");
    }
}

/// Density control on hand-made statistics: a small primitive under a strong screen-space pull
/// is cloned, a large one split into two drawn from it (scales / 1.6), a faint one pruned,
/// a quiet one kept; the cap on the count holds and spends its room on the strongest pull; the
/// opacity reset lowers opacities to twice the pruning threshold.
#[test]
fn density_control_clones_splits_prunes_and_resets_as_3dgs_does() {
    use splat_runtime::train::densify::Densifier;
    let at = |x: f32, scale: f32, opacity: f32| {
        let mut p = Method::from_point(Vec3::new(x, 0.0, 2.0), Vec3::splat(0.5), scale);
        p.opacity_logit = (opacity / (1.0 - opacity)).ln();
        p
    };
    // Extent 1: clone up to scale 0.01, split above.
    let mut params = vec![
        at(-0.2, 0.005, 0.5),  // small, pulled: cloned
        at(0.0, 0.05, 0.5),    // large, pulled: split
        at(0.1, 0.005, 0.001), // faint, quiet: pruned
        at(0.2, 0.005, 0.5),   // quiet: kept
    ];
    // Screen-space pulls (NDC units) far above and far below the threshold of 0.0002.
    let (strong, weak) = (0.01, 1e-6);
    let mut d = Densifier::new(DensifyOptions::default(), params.len());
    d.observe([(0, strong), (1, strong), (2, weak), (3, weak)]);
    let mut rng = fastrand::Rng::with_seed(5);
    let parent = Method::shape(&params[1]);
    let r = d.refine::<Method>(&mut params, 600, 1.0, &mut rng);
    assert_eq!((r.cloned, r.split, r.pruned), (1, 1, 1));
    assert_eq!(r.origin, [Some(0), None, None, None, Some(3)]);
    assert_eq!(params.len(), 5);
    assert_eq!(params[1], params[0], "the clone sits where its original is");
    for child in &params[2..4] {
        let s = Method::shape(child);
        assert!((s.scale - parent.scale / 1.6).abs().max_element() < 1e-6);
        assert!((s.position - parent.position).length() < 5.0 * parent.scale.x);
        assert_eq!(s.opacity.to_bits(), parent.opacity.to_bits());
    }
    assert_ne!(
        params[2].mean, params[3].mean,
        "the two halves are drawn apart"
    );

    // The statistics were cleared: nothing grows at the next refinement.
    let r = d.refine::<Method>(&mut params, 700, 1.0, &mut rng);
    assert_eq!((r.cloned, r.split, r.pruned), (0, 0, 0));

    // The cap: no growth past max_primitives.
    let capped = DensifyOptions {
        max_primitives: 5,
        ..Default::default()
    };
    let mut d = Densifier::new(capped, params.len());
    d.observe((0..params.len()).map(|i| (i, strong)));
    let r = d.refine::<Method>(&mut params, 800, 1.0, &mut rng);
    assert_eq!((r.cloned, r.split, params.len()), (0, 0, 5));
    // Room for one more: the most strongly pulled primitive grows, wherever it comes.
    let one_more = DensifyOptions {
        max_primitives: 6,
        ..Default::default()
    };
    let mut d = Densifier::new(one_more, params.len());
    d.observe((0..params.len()).map(|i| (i, strong * (1.0 + i as f32 / 8.0))));
    let r = d.refine::<Method>(&mut params, 800, 1.0, &mut rng);
    assert_eq!((r.cloned, r.split), (1, 0));
    let kept = [Some(0), Some(1), Some(2), Some(3), Some(4)];
    assert_eq!(
        r.origin,
        [&kept[..], &[None]].concat(),
        "the last one is cloned"
    );
    params.truncate(5);

    // The reset moves the opacity alone: a rotation off the unit sphere and the log scales
    // keep their words (and so their Adam moments).
    params[0].rotation = Vec4::new(2.0, 0.3, 0.0, 0.0);
    let before = params.clone();
    d.reset_opacity::<Method>(&mut params);
    for (p, b) in params.iter().zip(&before) {
        assert!((Method::shape(p).opacity - 0.01).abs() < 1e-6);
        let (mut p, mut b) = (*p, *b);
        (p.opacity_logit, b.opacity_logit) = (0.0, 0.0);
        assert_eq!(p, b);
    }
    assert!(d.refines_at(600) && !d.refines_at(500) && !d.refines_at(650));
    assert!(d.resets_at(3000) && !d.resets_at(0));
    let never = DensifyOptions {
        opacity_resets: false,
        ..Default::default()
    };
    let d = Densifier::new(never, params.len());
    assert!(!d.resets_at(3000) && d.refines_at(3000));
}

/// Training from a few large primitives: density control splits and clones them until the
/// held-out views come out clearly better than the same run with a fixed count.
#[test]
fn density_control_beats_a_fixed_count_from_a_sparse_start() {
    let scene = truth();
    let data = known_dataset();
    let start: Vec<Params> = scene
        .iter()
        .step_by(8)
        .map(|g| Method::from_point(g.mean, Vec3::splat(0.5), 0.3))
        .collect();
    let run = |densify: Option<splat_runtime::train::Strategy>| {
        let mut params = start.clone();
        let opts = FitOptions {
            densify,
            ..options(1200)
        };
        let (mut grown, mut split) = (0, 0);
        // The scene's radius as 3DGS takes it: 1.1 times the cameras' distance from the centre.
        fit::<Method>(&data, &mut params, 3.5, &opts, |r| {
            if let Some(r) = r.refinement {
                (grown, split) = (grown + r.cloned, split + r.split);
            }
        })
        .unwrap();
        let e = evaluate::<Method>(&params, &data.test, &opts).unwrap();
        (e.psnr, params.len(), grown, split)
    };
    let fixed = run(None);
    let densified = run(Some(Strategy::Adc(DensifyOptions {
        start: 100,
        every: 100,
        ..Default::default()
    })));
    println!(
        "from {} primitives: fixed count {:.2} dB; density control {:.2} dB with {} primitives ({} cloned, {} split)",
        start.len(),
        fixed.0,
        densified.0,
        densified.1,
        densified.2,
        densified.3
    );
    assert_eq!(fixed.1, start.len());
    assert!(densified.1 > 3 * start.len(), "the count grows");
    assert!(densified.3 > 0, "large primitives split");
    assert!(
        densified.0 > fixed.0 + 3.0,
        "density control fits the held-out views better"
    );
}

/// MCMC finds 3DGS's words, and its penalties' gradients are those of their value (f64
/// central differences).
#[test]
fn mcmc_reads_3dgs_words_and_differentiates_its_penalties() {
    use splat_runtime::Flat;
    use splat_runtime::train::mcmc::{GaussianWords, Mcmc, McmcOptions};
    let layout = GaussianWords::of::<Method>().expect("3DGS's words are a Gaussian's");
    let want = GaussianWords {
        position: 0,
        log_scale: 3,
        rotation: 6,
        opacity: 10,
    };
    assert_eq!(layout, want);
    let mcmc = Mcmc::new::<Method>(McmcOptions::default()).unwrap();
    let words = Params::LEN;
    let mut rng = fastrand::Rng::with_seed(2);
    let flat: Vec<f32> = (0..3 * words).map(|_| 2.0 * rng.f32() - 1.0).collect();
    let mut grads = vec![0.0; flat.len()];
    mcmc.regularize(&flat, &mut grads, words, 1);
    let value = |f: &[f32]| mcmc.regularize(f, &mut vec![0.0; f.len()], words, 1) as f64;
    for k in 0..flat.len() {
        let h = 1e-2;
        let (mut up, mut down) = (flat.clone(), flat.clone());
        up[k] += h;
        down[k] -= h;
        let numeric = (value(&up) - value(&down)) / (2.0 * h as f64);
        let tol = 1e-3 * numeric.abs().max(1e-4);
        assert!(
            (grads[k] as f64 - numeric).abs() <= tol,
            "word {k}: {} vs {numeric}",
            grads[k]
        );
    }
}

/// MCMC's refinement: every dead primitive moves onto a live one drawn by opacity, the copies
/// of a primitive share its opacity so that the stack is as opaque as it was, the set grows by
/// the asked fraction up to the cap, and the drawn primitives and their copies start their
/// optimizer state afresh; the noise moves the faint ones only.
#[test]
fn mcmc_relocates_dead_primitives_grows_and_stirs_the_faint() {
    use splat_runtime::train::mcmc::{Mcmc, McmcOptions};
    let mut rng = fastrand::Rng::with_seed(4);
    let start: Vec<Params> = (0..40)
        .map(|i| {
            let p = Vec3::new(i as f32, 0.0, 0.0);
            let mut g = Method::from_point(p, Vec3::splat(0.5), 0.1);
            // Every fourth one dead (opacity 0.002), the others from 0.2 to 0.9.
            let opacity: f32 = if i % 4 == 0 {
                0.002
            } else {
                0.2 + 0.7 * rng.f32()
            };
            g.opacity_logit = (opacity / (1.0 - opacity)).ln();
            g
        })
        .collect();
    let opacity = |g: &Params| Method::shape(g).opacity;
    let relocate_only = Mcmc::new::<Method>(McmcOptions {
        growth: 0.0,
        ..Default::default()
    })
    .unwrap();
    let mut params = start.clone();
    let r = relocate_only.refine::<Method>(&mut params, &mut rng);
    assert_eq!((r.relocated, r.cloned, params.len()), (10, 0, 40));
    for (i, (g, o)) in params.iter().zip(&r.origin).enumerate() {
        let stack: Vec<&Params> = params.iter().filter(|h| h.mean == g.mean).collect();
        let was = start.iter().find(|h| h.mean == g.mean).unwrap();
        assert!(opacity(was) > 0.005, "{i} sits on a live primitive");
        let kept = 1.0 - stack.iter().map(|h| 1.0 - opacity(h)).product::<f32>();
        assert!(
            (kept - opacity(was)).abs() < 1e-4,
            "{i}: {kept} vs {}",
            opacity(was)
        );
        assert_eq!(
            o.is_none(),
            stack.len() > 1,
            "{i}: fresh state where copied"
        );
    }

    let growing = Mcmc::new::<Method>(McmcOptions {
        max_primitives: 45,
        growth: 0.2,
        ..Default::default()
    })
    .unwrap();
    let mut params = start.clone();
    let r = growing.refine::<Method>(&mut params, &mut rng);
    assert_eq!((r.cloned, params.len(), r.origin.len()), (5, 45, 45));
    assert!(r.origin[40..].iter().all(Option::is_none));

    // The noise: with isotropic scale s a faint primitive moves by s^2 * noise * scaler.
    let words = <Params as splat_runtime::Flat>::LEN;
    let mut flat = vec![0.0; start.len() * words];
    for (g, w) in start.iter().zip(flat.chunks_exact_mut(words)) {
        splat_runtime::Flat::write_words(g, w);
    }
    let before = flat.clone();
    growing.perturb(&mut flat, words, 1e-5, 3);
    for (i, g) in start.iter().enumerate() {
        let at = |f: &[f32]| Vec3::from_slice(&f[i * words..i * words + 3]);
        let moved = at(&flat).distance(at(&before));
        assert_eq!(
            moved > 1e-4,
            opacity(g) < 0.1,
            "{i}: opacity {}, moved {moved}",
            opacity(g)
        );
    }
}

/// The primitives of the MCMC tests: 60 random ones in the cube around the known scene, most
/// of them in empty space at first.
fn random_start() -> Vec<Params> {
    splat_runtime::train::init::in_cube::<Method>(60, Vec3::ZERO, 1.5, Default::default(), 5)
}

/// The MCMC strategy of the tests: from step 100, growing by 30% up to 240 primitives.
fn test_mcmc() -> Strategy {
    Strategy::Mcmc(splat_runtime::train::McmcOptions {
        start: 100,
        growth: 0.3,
        max_primitives: 240,
        ..Default::default()
    })
}

/// From random points MCMC, started as the paper starts it, moves the faint primitives onto
/// the scene and grows to its cap, and the held-out views come out far better than the start.
#[test]
fn mcmc_fits_the_known_scene_from_random_points() {
    use splat_runtime::train::McmcOptions;
    let data = known_dataset();
    let mut params = random_start();
    McmcOptions::prepare::<Method>(&mut params);
    let opts = FitOptions {
        densify: Some(test_mcmc()),
        ..options(1200)
    };
    let before = evaluate::<Method>(&params, &data.test, &opts).unwrap().psnr;
    let mut relocated = 0;
    fit::<Method>(&data, &mut params, 3.5, &opts, |r| {
        relocated += r.refinement.map_or(0, |r| r.relocated);
    })
    .unwrap();
    let after = evaluate::<Method>(&params, &data.test, &opts).unwrap().psnr;
    println!(
        "MCMC from 60 random primitives: held-out PSNR {before:.2} -> {after:.2} dB with {} primitives, {relocated} relocated",
        params.len(),
    );
    assert_eq!(params.len(), 240, "MCMC grows to its cap");
    assert!(relocated > 20, "and relocates");
    assert!(
        after > before + 5.5,
        "and fits the held-out views (measured +6.0 dB)"
    );
}

/// Batches of views train as well as one view per step at equal views seen (Grendel's
/// scaling), and the GPU loop sums a batch as the CPU loop does: on the known scene, 400 views
/// in batches of 4 (100 Adam steps, with MCMC's penalties and noise, which scale with the
/// batch) reach the held-out PSNR of 400 single views, on both backends alike.
#[test]
fn batches_of_views_train_like_single_views_on_both_loops() {
    let scene = truth();
    let data = known_dataset();
    let start = moved_start::<Method>(&scene);
    let mcmc = Strategy::Mcmc(splat_runtime::train::McmcOptions {
        start: 1000,
        ..Default::default()
    });
    let opts = |batch| FitOptions {
        batch,
        densify: Some(mcmc.clone()),
        ..options(400)
    };
    let cpu = |batch| {
        let mut params = start.clone();
        let mut reports = 0;
        fit::<Method>(&data, &mut params, 1.0, &opts(batch), |_| reports += 1).unwrap();
        let psnr = evaluate::<Method>(&params, &data.test, &opts(1))
            .unwrap()
            .psnr;
        (psnr, reports)
    };
    let (single, batched) = (cpu(1), cpu(4));
    println!(
        "400 views: one per step {:.2} dB, in batches of 4 {:.2} dB",
        single.0, batched.0
    );
    assert_eq!(
        (single.1, batched.1),
        (400, 100),
        "one report per Adam step"
    );
    assert!(batched.0 > single.0 - 0.5, "{batched:?} against {single:?}");

    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    let mut params = start.clone();
    splat_runtime::train::gpu_fit::fit_gpu::<Method>(
        &gpu,
        &data,
        &mut params,
        1.0,
        &opts(4),
        |_| {},
    )
    .unwrap();
    let on_gpu = evaluate::<Method>(&params, &data.test, &opts(1))
        .unwrap()
        .psnr;
    println!("in batches of 4 on the GPU: {on_gpu:.2} dB");
    assert!(
        (on_gpu - batched.0).abs() < 0.2,
        "{on_gpu} against the CPU's {}",
        batched.0
    );
}

/// The GPU loop trains like the CPU loop: on the known scene, the same steps from the same
/// start reach held-out PSNRs within 1 dB of each other; from a sparse start, density control
/// on the device grows the set and beats the fixed count as on the CPU.
#[test]
fn the_gpu_loop_trains_like_the_cpu_loop() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::train::gpu_fit::fit_gpu;
    let scene = truth();
    let data = known_dataset();

    let opts = FitOptions {
        densify: None,
        ..options(300)
    };
    let start = moved_start::<Method>(&scene);
    let before = evaluate::<Method>(&start, &data.test, &opts).unwrap();
    let (mut cpu, mut gpu_params) = (start.clone(), start);
    fit::<Method>(&data, &mut cpu, 1.0, &opts, |_| {}).unwrap();
    let mut losses = vec![];
    fit_gpu::<Method>(&gpu, &data, &mut gpu_params, 1.0, &opts, |r| {
        losses.push(r.loss.loss)
    })
    .unwrap();
    let cpu_psnr = evaluate::<Method>(&cpu, &data.test, &opts).unwrap().psnr;
    let gpu_psnr = evaluate::<Method>(&gpu_params, &data.test, &opts)
        .unwrap()
        .psnr;
    println!(
        "300 steps: held-out PSNR {:.2} -> CPU {cpu_psnr:.2}, GPU {gpu_psnr:.2} dB; GPU loss {:.4} -> {:.4}",
        before.psnr,
        losses[0],
        losses[losses.len() - 1]
    );
    // Measured 14.03 -> CPU 25.40, GPU 25.41 dB.
    assert!(gpu_psnr > 25.0, "the GPU loop trains");
    assert!((gpu_psnr - cpu_psnr).abs() < 0.2, "and like the CPU loop");

    let sparse: Vec<Params> = scene
        .iter()
        .step_by(8)
        .map(|g| Method::from_point(g.mean, Vec3::splat(0.5), 0.3))
        .collect();
    let run = |densify, mut params: Vec<Params>| {
        let opts = FitOptions {
            densify,
            ..options(1200)
        };
        fit_gpu::<Method>(&gpu, &data, &mut params, 3.5, &opts, |_| {}).unwrap();
        let e = evaluate::<Method>(&params, &data.test, &opts).unwrap();
        (e.psnr, params.len())
    };
    let fixed = run(None, sparse.clone());
    let adc = Strategy::Adc(DensifyOptions {
        start: 100,
        every: 100,
        ..Default::default()
    });
    let densified = run(Some(adc), sparse.clone());
    let mut prepared = random_start();
    splat_runtime::train::McmcOptions::prepare::<Method>(&mut prepared);
    let before = evaluate::<Method>(&prepared, &data.test, &options(0)).unwrap();
    let unsampled = run(None, prepared.clone());
    let sampled = run(Some(test_mcmc()), prepared);
    println!(
        "GPU from {} primitives: fixed {fixed:?}, density control {densified:?}; MCMC from 60 random: {:.2} dB before, {unsampled:?} without MCMC, {sampled:?} with",
        sparse.len(),
        before.psnr
    );
    assert!(densified.1 > 3 * sparse.len(), "the count grows");
    assert!(densified.0 > fixed.0 + 3.0, "and the fit improves");
    assert_eq!(sampled.1, 240, "MCMC grows to its cap");
    // What MCMC adds, against the same start trained without it (17.48 dB in every run). With
    // it the result is chaotic in the GPU's atomic order (the gradient sums' last bits steer
    // which primitives are relocated): 19.0 to 21.3 dB over nine runs on lavapipe, so an
    // absolute bound (it was before + 5.5 dB) failed one CI run in several at 19.02.
    assert!(
        sampled.0 > unsampled.0 + 1.0,
        "and fits the held-out views better than the same start without it (measured +1.5 to +3.8 dB)"
    );
}

/// The hardware path (each view drawn by the rasterizer with programmable blending, its
/// gradients from the hardware backward, the loss and Adam on the host) trains as the tile
/// path does: from the same start, in the same steps, to the CPU loop's held-out PSNR within
/// 0.5 dB, with a fixed primitive count and with density control (whose statistics read the
/// hardware path's gradients).
#[test]
fn the_hardware_path_trains_like_the_tile_path() {
    let Some(gpu) = splat_runtime::gpu::programmable_blend::open_or_skip() else {
        return;
    };
    use splat_runtime::train::hardware_fit::fit_hardware;
    let data = known_dataset();
    let start = moved_start::<Method>(&truth());
    let before = evaluate::<Method>(&start, &data.test, &options(0)).unwrap();
    let adc = Strategy::Adc(DensifyOptions {
        start: 100,
        every: 100,
        ..Default::default()
    });
    for densify in [None, Some(adc)] {
        let opts = FitOptions {
            densify,
            ..options(300)
        };
        let (mut cpu, mut hardware) = (start.clone(), start.clone());
        fit::<Method>(&data, &mut cpu, 1.0, &opts, |_| {}).unwrap();
        fit_hardware::<Method>(&gpu, &data, &mut hardware, 1.0, &opts, |_| {}).unwrap();
        let psnr = |p: &[Params]| evaluate::<Method>(p, &data.test, &opts).unwrap().psnr;
        let (cpu_psnr, hardware_psnr) = (psnr(&cpu), psnr(&hardware));
        println!(
            "300 steps, {}: held-out PSNR {:.2} -> CPU {cpu_psnr:.2} ({} primitives), hardware {hardware_psnr:.2} dB ({})",
            if opts.densify.is_some() {
                "ADC"
            } else {
                "fixed"
            },
            before.psnr,
            cpu.len(),
            hardware.len()
        );
        assert!(
            hardware_psnr > before.psnr + 5.0,
            "the hardware path trains"
        );
        assert!(
            (hardware_psnr - cpu_psnr).abs() < 0.5,
            "as the tile path does"
        );
    }
}

/// A primitive whose gradient is not finite (3DGEER's, at a scale of e^60 whose square
/// overflows f32) is named in each step's report and keeps its values, and the rest of the
/// scene trains, on the CPU and the GPU; a scene that starts non-finite is refused by name.
#[test]
fn non_finite_gradients_are_named_and_skipped() {
    use splat_methods::geer;
    use splat_runtime::train::gpu_fit::fit_gpu;
    use splat_runtime::{Flat, param_group};
    let data = known_dataset();
    let opts = FitOptions {
        densify: None,
        ..options(40)
    };
    let scales = param_group::<geer::Method>("log_scale").unwrap();
    let with_scale = |p: &geer::Params, value: f32| {
        let mut w = vec![0.0; geer::Params::LEN];
        p.write_words(&mut w);
        w[scales.clone()].fill(value);
        geer::Params::read_words(&w)
    };
    let mut start = moved_start::<geer::Method>(&truth());
    start[5] = with_scale(&start[5], 60.0);
    let before = evaluate::<geer::Method>(&start, &data.test, &opts).unwrap();
    let check = |label: &str, params: &[geer::Params], reports: &[String]| {
        let after = evaluate::<geer::Method>(params, &data.test, &opts).unwrap();
        println!(
            "{label}: {} of 40 steps left words alone, first: {:?}; held-out PSNR {:.2} -> {:.2} dB",
            reports.len(),
            reports.first(),
            before.psnr,
            after.psnr
        );
        assert!(!reports.is_empty(), "{label}: the faults are reported");
        for r in reports {
            assert!(r.contains("primitive 5's"), "{label}: {r}");
        }
        let mut w = vec![0.0; geer::Params::LEN];
        for p in params {
            p.write_words(&mut w);
            assert!(w.iter().all(|x| x.is_finite()), "{label}: {w:?}");
        }
        assert!(after.psnr > before.psnr + 1.0, "{label}: the rest trains");
    };
    let describe = |r: &StepReport, reports: &mut Vec<String>| {
        if r.faults.any() {
            reports.push(r.faults.describe::<geer::Method>());
        }
    };
    let (mut params, mut reports) = (start.clone(), vec![]);
    fit::<geer::Method>(&data, &mut params, 1.0, &opts, |r| {
        describe(r, &mut reports)
    })
    .unwrap();
    check("CPU", &params, &reports);
    if let Some(gpu) = splat_runtime::gpu::adapter_or_skip() {
        let (mut params, mut reports) = (start.clone(), vec![]);
        fit_gpu::<geer::Method>(&gpu, &data, &mut params, 1.0, &opts, |r| {
            describe(r, &mut reports)
        })
        .unwrap();
        check("GPU", &params, &reports);
    }

    start[3] = with_scale(&start[3], f32::NAN);
    let err = fit::<geer::Method>(&data, &mut start, 1.0, &opts, |_| {}).unwrap_err();
    assert_eq!(
        err.to_string(),
        "the scene to train is not finite: primitive 3's `log_scale` is NaN"
    );
}

/// Groups left out of `render.gradients` stay as they start, bit for bit, on the CPU and the
/// GPU, while the others train; density control refuses frozen shape groups.
#[test]
fn frozen_groups_stay_as_they_start() {
    use splat_runtime::GradientSet;
    use splat_runtime::train::gpu_fit::fit_gpu;
    let data = known_dataset();
    let colors = GradientSet::params::<Method>(&["opacity_logit", "sh"]).unwrap();
    let opts = FitOptions {
        densify: None,
        render: RenderOptions {
            gradients: colors,
            ..options(100).render
        },
        ..options(100)
    };
    let start = moved_start::<Method>(&truth());
    let before = evaluate::<Method>(&start, &data.test, &opts).unwrap();
    let check = |label: &str, params: &[Params]| {
        let after = evaluate::<Method>(params, &data.test, &opts).unwrap();
        println!(
            "{label}, colors and opacities alone: held-out PSNR {:.2} -> {:.2} dB",
            before.psnr, after.psnr
        );
        for (p, s) in params.iter().zip(&start) {
            assert_eq!(
                (p.mean, p.log_scale, p.rotation),
                (s.mean, s.log_scale, s.rotation)
            );
        }
        assert!(params.iter().zip(&start).all(|(p, s)| p.sh[0] != s.sh[0]));
        assert!(after.psnr > before.psnr + 1.0, "{label}: the colors train");
    };
    let mut params = start.clone();
    fit::<Method>(&data, &mut params, 1.0, &opts, |_| {}).unwrap();
    check("CPU", &params);
    if let Some(gpu) = splat_runtime::gpu::adapter_or_skip() {
        let mut params = start.clone();
        fit_gpu::<Method>(&gpu, &data, &mut params, 1.0, &opts, |_| {}).unwrap();
        check("GPU", &params);
    }
    let adc = FitOptions {
        densify: FitOptions::default().densify,
        ..opts.clone()
    };
    let err = fit::<Method>(&data, &mut params, 1.0, &adc, |_| {}).unwrap_err();
    assert_eq!(
        err.to_string(),
        "mean, log_scale, rotation cannot stay frozen under density control (adc), which moves, resizes and fades primitives: train with a fixed primitive count"
    );
}

/// A dataset read on black, re-composited on white, is the dataset read on white; training on
/// random backgrounds (targets re-composited per step) fits the held-out views.
#[test]
fn random_backgrounds_recomposite_the_targets_and_train() {
    let dir = tempfile::tempdir().unwrap();
    let scene = truth();
    write_known_scene(dir.path());
    let black = read_blender(dir.path(), Vec3::ZERO).unwrap();
    let white = read_blender(dir.path(), Vec3::ONE).unwrap();
    for (b, w) in black.train.iter().zip(&white.train) {
        assert!(b.coverage().is_some(), "the views are partly transparent");
        let moved = b.on(Vec3::ONE);
        let worst = moved
            .data
            .iter()
            .zip(&w.image().data)
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(worst < 1e-6, "{worst}");
    }
    let opts = FitOptions {
        random_background: true,
        densify: None,
        ..options(300)
    };
    let mut params = moved_start::<Method>(&scene);
    let before = evaluate::<Method>(&params, &black.test, &opts).unwrap();
    fit::<Method>(&black, &mut params, 1.0, &opts, |_| {}).unwrap();
    let after = evaluate::<Method>(&params, &black.test, &opts).unwrap();
    println!(
        "random backgrounds: held-out PSNR {:.2} -> {:.2} dB",
        before.psnr, after.psnr
    );
    assert!(after.psnr > 25.0, "measured 14.03 -> 25.42 dB");
}

/// Options for the resume tests: 40 steps, density control every 5 steps from step 5 with an
/// opacity reset at 20, random backgrounds (the generator matters), a checkpoint every 20.
fn resumable_options() -> FitOptions {
    FitOptions {
        random_background: true,
        densify: Some(Strategy::Adc(DensifyOptions {
            start: 5,
            every: 5,
            reset_every: 20,
            ..Default::default()
        })),
        checkpoint_every: Some(20),
        ..options(40)
    }
}

/// A CPU run of `opts` from `start`, recorded: its end state, the checkpoints it saved and the
/// primitive count after each step. Call it on one thread, so sums run in one order.
fn recorded_run(
    data: &splat_runtime::io::dataset::Dataset,
    start: &[Params],
    opts: &FitOptions,
) -> (
    splat_runtime::train::Checkpoint,
    Vec<splat_runtime::train::Checkpoint>,
    Vec<usize>,
) {
    let mut whole = Checkpoint::start::<Method>(start, opts.steps, opts.seed);
    let (mut saved, mut counts) = (vec![], vec![]);
    splat_runtime::train::fit::fit_from::<Method>(data, &mut whole, 1.0, opts, |r| {
        saved.extend(r.checkpoint.cloned());
        counts.push(r.primitives);
    })
    .unwrap();
    (whole, saved, counts)
}

/// `at` written to `dir`, read back (equal to what was written) and run to the end.
fn resumed_from_file(dir: &Path, data: &Dataset, at: &Checkpoint, opts: &FitOptions) -> Checkpoint {
    let path = dir.join("checkpoint.bin");
    at.write(&path).unwrap();
    let mut resumed = Checkpoint::read(&path).unwrap();
    assert_eq!(&resumed, at);
    splat_runtime::train::fit::fit_from::<Method>(data, &mut resumed, 1.0, opts, |_| {}).unwrap();
    resumed
}

/// A run from its checkpoint (written to a file and read back) takes the very steps the
/// uninterrupted run took: the same primitives, moments and generator state, bit for bit, with
/// density control acting on both sides of the checkpoint (CPU, one thread, so sums run in one
/// order).
#[test]
fn a_run_resumed_from_its_checkpoint_takes_the_same_steps() {
    use splat_runtime::Image;
    use splat_runtime::io::dataset::View;
    use splat_runtime::train::fit::fit_from;
    let dir = tempfile::tempdir().unwrap();
    let scene = truth();
    write_known_scene(dir.path());
    let data = read_blender(dir.path(), Vec3::ZERO).unwrap();
    let opts = resumable_options();
    let start: Vec<Params> = scene
        .iter()
        .step_by(4)
        .map(|g| Method::from_point(g.mean, Vec3::splat(0.5), 0.3))
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        let (whole, saved, counts) = recorded_run(&data, &start, &opts);
        assert_eq!(saved.iter().map(|c| c.step).collect::<Vec<_>>(), [20, 40]);
        assert_eq!(saved[1], whole, "the last checkpoint is the run's end");
        let at20 = &saved[0];
        assert_eq!((at20.adam.step, at20.primitives()), (20, counts[19]));
        assert!(
            counts[19] != start.len() && counts[39] != counts[19],
            "{counts:?}"
        );
        assert_eq!(resumed_from_file(dir.path(), &data, at20, &opts), whole);

        // Another run length, method or strategy is refused.
        let mut other = at20.clone();
        let longer = FitOptions {
            steps: 50,
            ..resumable_options()
        };
        let err = fit_from::<Method>(&data, &mut other, 1.0, &longer, |_| {}).unwrap_err();
        assert!(err.to_string().contains("40-step run, not 50"), "{err}");
        let err = fit_from::<splat_methods::gut::Method>(&data, &mut other, 1.0, &opts, |_| {})
            .unwrap_err();
        assert!(err.to_string().contains("not 3dgut"), "{err}");
        let sampled = FitOptions {
            densify: Some(Strategy::Mcmc(Default::default())),
            ..resumable_options()
        };
        let err = fit_from::<Method>(&data, &mut other, 1.0, &sampled, |_| {}).unwrap_err();
        assert!(err.to_string().contains("strategy adc, not mcmc"), "{err}");
        // So are other training views: one fewer (another dataset), or the same ones smaller
        // (another --downscale).
        let fewer = Dataset {
            train: data.train[1..].to_vec(),
            ..data.clone()
        };
        let err = fit_from::<Method>(&fewer, &mut other, 1.0, &opts, |_| {}).unwrap_err();
        let (n, (w, h)) = (data.train.len(), data.train[0].size());
        let want = format!(
            "run on {n} training views of {} pixels in all, not {}",
            n as u32 * w * h,
            n - 1
        );
        assert!(err.to_string().contains(&want), "{err}");
        let smaller = Dataset {
            train: (data.train.iter())
                .map(|v| {
                    let image = Image {
                        width: w / 2,
                        height: h / 2,
                        channels: 3,
                        data: v.image().data[..(w / 2 * h / 2 * 3) as usize].to_vec(),
                    };
                    let camera = Camera {
                        size: v.camera.size / 2.0,
                        focal: v.camera.focal / 2.0,
                        principal: v.camera.principal / 2.0,
                        ..v.camera
                    };
                    View::new(v.name.clone(), camera, image, None, v.background)
                })
                .collect(),
            ..data.clone()
        };
        let err = fit_from::<Method>(&smaller, &mut other, 1.0, &opts, |_| {}).unwrap_err();
        assert!(err.to_string().contains("another --downscale"), "{err}");
        // And a state built by hand whose moments are not the parameters' size.
        let mut built = at20.clone();
        built.adam.m.pop();
        let err = fit_from::<Method>(&data, &mut built, 1.0, &opts, |_| {}).unwrap_err();
        assert!(
            err.to_string()
                .contains("not a run's state: Adam's moments"),
            "{err}"
        );
    });
}

/// With MCMC a resumed run takes the uninterrupted run's steps too, bit for bit: relocation
/// and growth draw from the checkpoint's generator state, and the position noise from the step
/// (CPU, one thread). The sampler acts on both sides of the checkpoint.
#[test]
fn an_mcmc_run_resumed_from_its_checkpoint_takes_the_same_steps() {
    use splat_runtime::train::McmcOptions;
    let dir = tempfile::tempdir().unwrap();
    write_known_scene(dir.path());
    let data = read_blender(dir.path(), Vec3::ZERO).unwrap();
    let opts = FitOptions {
        densify: Some(Strategy::Mcmc(McmcOptions {
            start: 5,
            every: 5,
            growth: 0.2,
            ..Default::default()
        })),
        ..resumable_options()
    };
    let start = moved_start::<Method>(&truth());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        let (whole, saved, counts) = recorded_run(&data, &start, &opts);
        assert!(
            counts[19] > start.len() && counts[39] > counts[19],
            "the sampler grows on both sides of the checkpoint: {counts:?}"
        );
        assert_eq!(saved[0].step, 20);
        assert_eq!(
            resumed_from_file(dir.path(), &data, &saved[0], &opts),
            whole
        );
    });
}

/// On the GPU loop a resumed run goes on from the checkpoint's state (moments and statistics
/// downloaded, uploaded again) and ends as close to the uninterrupted run as two GPU runs of
/// the same steps do (float atomics add in any order): its parameters and moments a thousand
/// times closer to the uninterrupted run's than those of the same resume with Adam's moments
/// zeroed, which is what a resume that forgot to upload them would give. Measured on lavapipe:
/// parameters 5.6e-8 and first moments 9.1e-13 off, against 1.7e-2 and 1.5e-5 zeroed.
#[test]
fn the_gpu_loop_resumes_from_its_checkpoint() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::train::gpu_fit::fit_gpu_from;
    let data = known_dataset();
    let opts = resumable_options();
    let start = moved_start::<Method>(&truth());
    let mut whole = Checkpoint::start::<Method>(&start, opts.steps, opts.seed);
    let mut saved = vec![];
    fit_gpu_from::<Method>(&gpu, &data, &mut whole, 1.0, &opts, |r| {
        saved.extend(r.checkpoint.cloned())
    })
    .unwrap();
    let resume = |edit: &dyn Fn(&mut Checkpoint)| {
        let mut c = saved[0].clone();
        assert_eq!((c.step, c.adam.step), (20, 20));
        edit(&mut c);
        fit_gpu_from::<Method>(&gpu, &data, &mut c, 1.0, &opts, |_| {}).unwrap();
        assert_eq!(c.step, 40);
        c
    };
    assert!(
        saved[0].adam.m.iter().any(|m| *m != 0.0),
        "moments came down"
    );
    let resumed = resume(&|_| {});
    let forgetful = resume(&|c| {
        c.adam.m.fill(0.0);
        c.adam.v.fill(0.0);
    });
    // The largest difference from the uninterrupted run, of the parameters and of the first
    // moments (infinite where density control left another count).
    let apart = |a: &[f32], b: &[f32]| match a.len() == b.len() {
        true => a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs() as f64)
            .fold(0.0, f64::max),
        false => f64::INFINITY,
    };
    let params = |c: &Checkpoint| apart(&c.params, &whole.params);
    let moments = |c: &Checkpoint| apart(&c.adam.m, &whole.adam.m);
    println!(
        "after 40 steps, off the uninterrupted run: resumed at 20 {:.2e} (moments {:.2e}), \
         resumed with zeroed moments {:.2e} (moments {:.2e})",
        params(&resumed),
        moments(&resumed),
        params(&forgetful),
        moments(&forgetful)
    );
    assert!(
        params(&resumed) * 10.0 < params(&forgetful),
        "the parameters"
    );
    assert!(
        moments(&resumed) * 10.0 < moments(&forgetful),
        "the moments"
    );
}

/// Density control's statistics gathered on the device equal the CPU's for one frame: a
/// Gaussian in front of the camera whose box misses the image is not seen (gsplat's radii are
/// 0 there), nor is one behind the camera; those on the image are, with the same
/// screen-space gradient. Before, the device counted every one `project` kept, so off-image
/// views diluted the mean gradient and fewer primitives grew than on the CPU. 3DGS reads the
/// gradient of its projected centre, as gsplat does; 3DGUT, whose shade data holds no screen
/// position, pulls its position gradient back through the pinhole Jacobian.
#[test]
fn device_statistics_count_what_the_image_shows_as_the_cpu_does() {
    use splat_runtime::train::device::ScreenSource;
    device_statistics_match_the_cpu::<Method>(ScreenSource::Shade { slot: 0 });
    device_statistics_match_the_cpu::<splat_methods::gut::Method>(ScreenSource::Position {
        word: 0,
    });
}

fn device_statistics_match_the_cpu<M: Trainable>(source: splat_runtime::train::device::ScreenSource)
where
    M::Params: splat_methods::FromStored,
{
    use splat_methods::{FromStored, ToStored};
    use splat_runtime::gpu::entries::Accumulation;
    use splat_runtime::gpu::{GpuRenderer, GpuScene};
    use splat_runtime::train::densify::{Densifier, screen_gradient};
    use splat_runtime::train::device::GpuObserver;
    use splat_runtime::train::gpu_fit::screen_source;
    use splat_runtime::{Flat, FrameGrad, backward, render_for_backward};
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    assert_eq!(screen_source::<M>(), Some(source), "{}", M::NAME);
    let cam = crate::common::camera(SIZE, SIZE);
    let mut rng = fastrand::Rng::with_seed(8);
    let mut at = |x: f32, y: f32, z: f32| {
        let g = gaussian_at(&mut rng, &cam, Vec2::new(x, y), z, -3.0);
        M::Params::from_stored(&g.to_stored())
    };
    let params = vec![
        at(10.0, 12.0, 2.0),
        at(30.0, 25.0, 3.0),
        at(-400.0, 20.0, 2.0), // in front, its box far left of the image
        at(20.0, 900.0, 2.5),  // in front, far below
        at(20.0, 20.0, -2.0),  // behind the camera
        at(21.0, 19.0, 1.5),
    ];
    let opts = RenderOptions::default();
    let pixels = (SIZE * SIZE) as usize;
    let grad = FrameGrad {
        color: (0..pixels * 3).map(|_| rng.f32() - 0.5).collect(),
        alpha: None,
        depth: None,
    };

    let (_, state) = render_for_backward::<M>(&params, &cam, &opts).unwrap();
    let g = backward::<M>(&state, &params, &cam, &grad).unwrap();
    let mut cpu = Densifier::new(DensifyOptions::default(), params.len());
    let words = <M::Shade as Flat>::LEN;
    cpu.observe(state.pre.visible.iter().map(|&(i, _)| {
        let i = i as usize;
        let shade = &g.shade[i * words..(i + 1) * words];
        let grad = screen_gradient::<M>(&params[i], &g.params[i], shade, &cam);
        (i, grad.length())
    }));
    let (cpu_grad2d, cpu_seen) = cpu.statistics();
    assert_eq!(
        cpu_seen,
        [1, 1, 0, 0, 0, 1],
        "{}: the CPU sees what the image shows",
        M::NAME
    );

    let scene = GpuScene::<M>::new(&gpu, &params).unwrap();
    let mut renderer = GpuRenderer::<M>::new(&gpu, &opts).unwrap();
    renderer.forward(&scene, &cam).unwrap();
    renderer
        .backward(&scene, &grad, Accumulation::default_for(&gpu))
        .unwrap();
    let mut observer = GpuObserver::new(&gpu).unwrap();
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    observer
        .record(&gpu, &mut enc, &renderer, &scene, source)
        .unwrap();
    gpu.queue.submit([enc.finish()]);
    let (grad2d, seen) = observer.take(&gpu, params.len()).unwrap();
    assert_eq!(seen, cpu_seen, "{}", M::NAME);
    // Within gpu_parity's bound for gradients summed by atomics: 1e-3 of the largest.
    let largest = cpu_grad2d.iter().fold(0.0f32, |m, g| m.max(*g));
    for (i, (a, b)) in grad2d.iter().zip(&cpu_grad2d).enumerate() {
        assert!(
            (a - b).abs() <= 1e-3 * largest,
            "{} {i}: {a} vs {b}",
            M::NAME
        );
    }
    assert!(cpu_grad2d[0] > 0.0 && cpu_grad2d[5] > 0.0);
}

/// A GPU training step recorded behind a frame that turns out cut (more intersections than
/// the buffers held; the GPU loop does not wait for its frame) changes nothing: the
/// parameters, Adam's moments and density control's statistics stay as they were. Taken again
/// with room, the step equals that of a renderer that had room from the start.
#[test]
fn a_gpu_step_from_a_cut_frame_is_held_back_and_taken_again() {
    use crate::common::{camera, spread_gaussians};
    use splat_runtime::Flat;
    use splat_runtime::gpu::entries::Accumulation;
    use splat_runtime::gpu::{GpuRenderer, GpuScene};
    use splat_runtime::train::device::{AdamStep, GpuAdam, GpuObserver, ScreenSource};
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    let (small_cam, cam) = (camera(40, 32), camera(72, 56));
    let params = spread_gaussians(&cam, 300, 2);
    let words = <Params as Flat>::LEN;
    let rates = vec![1e-3; words];
    let opts = RenderOptions::default();
    let acc = Accumulation::default_for(&gpu);
    let mut rng = fastrand::Rng::with_seed(5);
    // Per pixel: color, alpha, depth.
    let pixel_grad: Vec<u32> = (0..72 * 56 * 5)
        .map(|_| (rng.f32() - 0.5).to_bits())
        .collect();
    // One step as the GPU loop records it: the frame submitted and not waited for.
    let step = |renderer: &mut GpuRenderer<Method>,
                scene: &GpuScene<Method>,
                adam: &mut GpuAdam,
                observer: &mut GpuObserver| {
        renderer.submit(scene, &cam).unwrap();
        gpu.write(renderer.pixel_gradients().unwrap(), &pixel_grad);
        renderer.backward_on_device(scene, acc).unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let adam_step = AdamStep {
            params: scene.buffer(),
            grads: renderer.param_gradients(),
            primitives: scene.len(),
            rates: &rates,
            held_by: Some(renderer.frame_keys()),
        };
        adam.record(&gpu, &mut enc, adam_step).unwrap();
        let source = ScreenSource::Shade { slot: 0 };
        (observer.record(&gpu, &mut enc, renderer, scene, source)).unwrap();
        gpu.queue.submit([enc.finish()]);
        renderer.settle(scene).unwrap()
    };
    let flat = |ps: &[Params]| -> Vec<f32> {
        let mut out = vec![0.0; ps.len() * words];
        for (p, o) in ps.iter().zip(out.chunks_exact_mut(words)) {
            p.write_words(o);
        }
        out
    };
    let bits = |ps: &[Params]| -> Vec<u32> { flat(ps).into_iter().map(f32::to_bits).collect() };

    // A renderer whose buffers hold the small frame's keys only.
    let mut renderer = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    let mut scene = GpuScene::<Method>::new(&gpu, &spread_gaussians(&small_cam, 30, 1)).unwrap();
    renderer.forward(&scene, &small_cam).unwrap();
    scene.upload(&gpu, &params).unwrap();
    let mut adam = GpuAdam::new(&gpu, words).unwrap();
    let mut observer = GpuObserver::new(&gpu).unwrap();
    let cut = step(&mut renderer, &scene, &mut adam, &mut observer);
    assert!(cut.is_none(), "the frame outgrows the first frame's room");
    let (faults, len) = adam.fault_words();
    assert_eq!(
        gpu.read(faults, len).unwrap(),
        [0, 0, u32::MAX],
        "no word stepped"
    );
    let unchanged = bits(&scene.download(&gpu).unwrap()) == bits(&params);
    assert!(unchanged, "the parameters are as they were");
    let moments = adam.download(&gpu, params.len()).unwrap();
    assert!(moments.m.iter().chain(&moments.v).all(|x| *x == 0.0));
    let (grad2d, seen) = observer.take(&gpu, params.len()).unwrap();
    assert!(grad2d.iter().all(|g| *g == 0.0) && seen.iter().all(|s| *s == 0));
    adam.take_back();
    let taken = step(&mut renderer, &scene, &mut adam, &mut observer).expect("room now");
    assert!(taken.intersections > 0 && !taken.redone);

    let mut roomy = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    let reference = GpuScene::<Method>::new(&gpu, &params).unwrap();
    roomy.forward(&reference, &cam).unwrap();
    let (mut adam_ref, mut observer_ref) = (
        GpuAdam::new(&gpu, words).unwrap(),
        GpuObserver::new(&gpu).unwrap(),
    );
    let want = step(&mut roomy, &reference, &mut adam_ref, &mut observer_ref).unwrap();
    assert_eq!(taken.intersections, want.intersections);
    let (got, want) = (
        adam.download(&gpu, params.len()).unwrap(),
        adam_ref.download(&gpu, params.len()).unwrap(),
    );
    assert_eq!(
        (got.step, want.step),
        (1, 1),
        "the held step was taken back"
    );
    // Gradients summed by atomics, in any order: gpu_parity's bound.
    let largest = want.m.iter().fold(0.0f32, |m, g| m.max(g.abs()));
    assert!(largest > 0.0);
    for (k, (a, b)) in got.m.iter().zip(&want.m).enumerate() {
        assert!((a - b).abs() <= 1e-3 * largest, "m[{k}]: {a} vs {b}");
    }
    // A first Adam step moves each word by its rate times the sign of its gradient.
    let (stepped, stepped_ref) = (
        scene.download(&gpu).unwrap(),
        reference.download(&gpu).unwrap(),
    );
    let moved = |ps: &[Params]| -> Vec<f32> {
        let was = flat(&params);
        flat(ps).iter().zip(&was).map(|(a, b)| a - b).collect()
    };
    let (moved, moved_ref) = (moved(&stepped), moved(&stepped_ref));
    assert!(moved.iter().any(|d| d.abs() > 5e-4), "the step was taken");
    for (k, (a, b)) in moved.iter().zip(&moved_ref).enumerate() {
        assert!((a - b).abs() <= 2.5e-3, "word {k}: moved {a} vs {b}");
    }
    let (seen, seen_ref) = (
        observer.take(&gpu, params.len()).unwrap().1,
        observer_ref.take(&gpu, params.len()).unwrap().1,
    );
    assert_eq!(seen, seen_ref);
    assert!(seen.contains(&1));
}

/// Density control's statistics before any view was observed (a run resumed past ADC's stop,
/// then saved) read as zeros for every primitive, not past the end of the device's buffers.
#[test]
fn an_observer_that_saw_no_view_reads_zero_statistics() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::train::device::GpuObserver;
    let mut observer = GpuObserver::new(&gpu).unwrap();
    let (grad2d, seen) = observer.take(&gpu, 1000).unwrap();
    assert_eq!((grad2d.len(), seen.len()), (1000, 1000));
    assert!(grad2d.iter().all(|g| *g == 0.0) && seen.iter().all(|s| *s == 0));
}
