//! The Blender / NeRF-synthetic layout: `transforms_train.json` and `transforms_test.json`,
//! read and written.

use super::error::{DatasetError, field, image_size};
use super::shots::{Dataset, Shot, Shots};
use super::transforms::{joined, matrix, posed_camera, read_json};
use crate::Outputs;
use crate::picture::View;
use glam::{Mat4, Vec2, Vec3, Vec4};
use splat_core::types::CameraModel;
use std::path::Path;

/// Reads a Blender-format dataset from `dir`, compositing RGBA images on `background`.
pub fn read_blender(dir: &Path, background: Vec3) -> Result<Dataset, DatasetError> {
    shots(dir)?.load(background)
}

pub(super) fn shots(dir: &Path) -> Result<Shots, DatasetError> {
    Ok(Shots {
        train: split_shots(&dir.join("transforms_train.json"))?,
        test: split_shots(&dir.join("transforms_test.json"))?,
        points: Vec::new(),
    })
}

/// Writes `data` as a Blender / NeRF-synthetic dataset in `dir` (what [`read_blender`] reads
/// back): `train/r_<k>.png` and `test/r_<k>.png` as RGBA, straight alpha from each view's
/// coverage, and `transforms_train.json`, `transforms_test.json` with OpenGL camera-to-world
/// matrices. The format says only a horizontal field of view per split, so every view must be
/// a pinhole camera with square pixels, the principal point at the centre, and the split's
/// first view's field of view. The files appear together or not at all.
pub fn write_blender(dir: &Path, data: &Dataset) -> Result<(), DatasetError> {
    let splits = [("train", &data.train), ("test", &data.test)];
    // Everything is checked before anything is written.
    let mut angles = vec![];
    for (name, views) in splits {
        angles.push(blender_angle(
            &dir.join(format!("transforms_{name}.json")),
            views,
        )?);
    }
    let mut outputs = Outputs::default();
    for ((name, views), angle) in splits.into_iter().zip(angles) {
        let mut frames = Vec::with_capacity(views.len());
        for (k, view) in views.iter().enumerate() {
            let file = format!("{name}/r_{k}");
            stage_rgba(&mut outputs, &dir.join(format!("{file}.png")), view)?;
            let c = &view.camera;
            // The inverse of the rigid world-to-camera pose, exactly rigid in its last row.
            let turn = c.rotation.transpose();
            let c2w = Mat4::from_cols(
                turn.x_axis.extend(0.0),
                turn.y_axis.extend(0.0),
                turn.z_axis.extend(0.0),
                (-(turn * c.translation)).extend(1.0),
            );
            // OpenCV camera axes to OpenGL ones: y and z flip.
            let c2w = c2w * Mat4::from_diagonal(Vec4::new(1.0, -1.0, -1.0, 1.0));
            let rows: Vec<[f32; 4]> = (0..4).map(|i| c2w.row(i).to_array()).collect();
            frames.push(serde_json::json!({
                "file_path": format!("./{file}"),
                "transform_matrix": rows,
            }));
        }
        let json_path = dir.join(format!("transforms_{name}.json"));
        let json = serde_json::json!({ "camera_angle_x": angle, "frames": frames });
        let text = serde_json::to_string_pretty(&json).expect("JSON of numbers and strings");
        (outputs.stage(&json_path, |w| w.write_all(text.as_bytes()))).map_err(|error| {
            DatasetError::Write {
                path: json_path.clone(),
                error: error.to_string(),
            }
        })?;
    }
    outputs.commit().map_err(|e| DatasetError::Write {
        path: e.path,
        error: e.error.to_string(),
    })
}

/// The horizontal field of view of a split's views, if the Blender format can hold them
/// (`json_path` names the split in errors).
fn blender_angle(json_path: &Path, views: &[View]) -> Result<f32, DatasetError> {
    let Some(first) = views.first() else {
        return Err(DatasetError::Empty(json_path.to_path_buf()));
    };
    let angle = 2.0 * (0.5 * first.camera.size.x / first.camera.focal.x).atan();
    for (k, view) in views.iter().enumerate() {
        let c = &view.camera;
        let centred = (c.principal - c.size / 2.0).abs().max_element() < 1e-3;
        let same_angle = (2.0 * (0.5 * c.size.x / c.focal.x).atan() - angle).abs() < 1e-5;
        if c.model != CameraModel::Pinhole || c.focal.x != c.focal.y || !centred || !same_angle {
            return Err(field(
                json_path,
                format!("frames[{k}]"),
                format!(
                    "cannot hold {}: the format has pinhole cameras with square pixels, the principal point at the centre and one field of view per split",
                    view.name
                ),
            ));
        }
    }
    Ok(angle)
}

/// A view as an 8-bit RGBA PNG: its coverage as alpha, its color taken off its background
/// (straight alpha, as Blender writes it).
fn stage_rgba(outputs: &mut Outputs, path: &Path, view: &View) -> Result<(), DatasetError> {
    // The image writer's error names the file.
    crate::image::stage_image(outputs, path, &view.straight()).map_err(DatasetError::Output)
}

/// The intrinsics instant-ngp writes into a Blender split beside (or instead of)
/// `camera_angle_x`.
const INTRINSICS: [&str; 6] = ["fl_x", "fl_y", "cx", "cy", "w", "h"];

/// A Blender split's pinhole: its focal length (in pixels where `fl_x` is given, else from
/// `camera_angle_x` and each picture's width), principal point (the picture's centre unless
/// `cx cy` say otherwise) and size (checked against the pictures where `w h` are given).
struct BlenderPinhole {
    focal: Focal,
    principal: Option<Vec2>,
    size: Option<(u32, u32)>,
}

enum Focal {
    Pixels(Vec2),
    AngleX(f64),
}

fn blender_pinhole(path: &Path, json: &serde_json::Value) -> Result<BlenderPinhole, DatasetError> {
    let number = |name: &str| match json.get(name) {
        None => Ok(None),
        Some(v) => (v.as_f64().filter(|x| x.is_finite()).map(Some))
            .ok_or_else(|| field(path, name, "must be a finite number")),
    };
    let positive = |name: &str| match number(name)? {
        Some(v) if v <= 0.0 => Err(field(path, name, format!("must be positive, not {v}"))),
        v => Ok(v),
    };
    // A lens is nerfstudio's: silently reading its pictures as pinholes would train on a
    // wrong camera.
    let lens = ["camera_model", "k1", "k2", "k3", "k4", "p1", "p2"];
    if let Some(name) = lens.iter().find(|n| json.get(**n).is_some()) {
        return Err(field(
            path,
            *name,
            "describes a lens, and a Blender dataset's cameras are pinholes (a nerfstudio transforms.json reads lenses)",
        ));
    }
    let focal = match (positive("fl_x")?, positive("fl_y")?) {
        (Some(x), y) => Focal::Pixels(Vec2::new(x as f32, y.unwrap_or(x) as f32)),
        (None, Some(_)) => return Err(field(path, "fl_y", "is given without fl_x")),
        (None, None) => match json.get("camera_angle_x") {
            None => {
                return Err(field(
                    path,
                    "camera_angle_x",
                    "is missing (and no fl_x gives the focal length in pixels)",
                ));
            }
            Some(a) => (a.as_f64())
                .filter(|a| a.is_finite() && *a > 0.0 && *a < std::f64::consts::PI)
                .map(Focal::AngleX)
                .ok_or_else(|| {
                    field(
                        path,
                        "camera_angle_x",
                        "must be an angle in (0, pi) radians",
                    )
                })?,
        },
    };
    let principal = match (number("cx")?, number("cy")?) {
        (Some(x), Some(y)) => Some(Vec2::new(x as f32, y as f32)),
        (None, None) => None,
        _ => return Err(field(path, "cx and cy", "must be given together")),
    };
    let side = |name: &str| match positive(name)? {
        Some(v) if v.fract() != 0.0 || v > u32::MAX as f64 => Err(field(
            path,
            name,
            format!("must be a whole number of pixels, not {v}"),
        )),
        v => Ok(v.map(|v| v as u32)),
    };
    let size = match (side("w")?, side("h")?) {
        (Some(w), Some(h)) => Some((w, h)),
        (None, None) => None,
        _ => return Err(field(path, "w and h", "must be given together")),
    };
    Ok(BlenderPinhole {
        focal,
        principal,
        size,
    })
}

fn split_shots(path: &Path) -> Result<Vec<Shot>, DatasetError> {
    let json = read_json(path)?;
    let pinhole = blender_pinhole(path, &json)?;
    let frames = json["frames"]
        .as_array()
        .ok_or_else(|| field(path, "frames", "must be an array"))?;
    if frames.is_empty() {
        return Err(DatasetError::Empty(path.to_path_buf()));
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut shots = Vec::with_capacity(frames.len());
    let mut size = None;
    for (k, frame) in frames.iter().enumerate() {
        let at = |f: &str| format!("frames[{k}].{f}");
        let file = frame["file_path"]
            .as_str()
            .ok_or_else(|| field(path, at("file_path"), "must be a string"))?;
        let mut image_path = joined(dir, file);
        if image_path.extension().is_none() {
            image_path.set_extension("png");
        }
        let c2w = matrix(&frame["transform_matrix"]).ok_or_else(|| {
            field(
                path,
                at("transform_matrix"),
                "must be 4 rows of 4 finite numbers",
            )
        })?;
        if let Some(name) = INTRINSICS.iter().find(|n| frame.get(**n).is_some()) {
            return Err(field(
                path,
                at(name),
                "is given per frame: a Blender dataset's intrinsics are the split's (a nerfstudio transforms.json has them per frame)",
            ));
        }
        let dims = image_size(&image_path)?;
        if let Some(want) = size.filter(|s| *s != dims) {
            return Err(DatasetError::Size {
                path: image_path,
                file: path.to_path_buf(),
                got: dims,
                want,
            });
        }
        size = Some(dims);
        if let Some(want) = pinhole.size.filter(|s| *s != dims) {
            return Err(field(
                path,
                "w and h",
                format!(
                    "say {}x{} pixels, but {} is {}x{}",
                    want.0,
                    want.1,
                    image_path.display(),
                    dims.0,
                    dims.1
                ),
            ));
        }
        let focal = match pinhole.focal {
            Focal::Pixels(f) => f,
            Focal::AngleX(angle) => Vec2::splat(0.5 * dims.0 as f32 / (0.5 * angle as f32).tan()),
        };
        let mut camera = posed_camera(&c2w, focal, dims)
            .map_err(|problem| field(path, at("transform_matrix"), problem))?;
        camera.principal = pinhole.principal.unwrap_or(camera.principal);
        shots.push(Shot::new(image_path, camera));
    }
    Ok(shots)
}
