//! nerfstudio's layout: one `transforms.json`, every 8th frame held out for testing.

use super::error::{DatasetError, field, image_size};
use super::shots::{Dataset, Shot, Shots};
use super::transforms::{joined, matrix, posed_camera, read_json};
use crate::undistort::Lens;
use glam::{DVec4, Vec2, Vec3, Vec4};
use splat_core::types::{Camera, CameraModel};
use std::path::Path;

/// Reads a nerfstudio `transforms.json` in `dir`; every 8th frame (from the first) is a test
/// view.
pub fn read_nerfstudio(dir: &Path, background: Vec3) -> Result<Dataset, DatasetError> {
    shots(dir)?.load(background)
}

pub(super) fn shots(dir: &Path) -> Result<Shots, DatasetError> {
    let path = dir.join("transforms.json");
    let json = read_json(&path)?;
    let frames = json["frames"]
        .as_array()
        .ok_or_else(|| field(&path, "frames", "must be an array"))?;
    if frames.is_empty() {
        return Err(DatasetError::Empty(path));
    }
    let mut shots = Vec::with_capacity(frames.len());
    for (k, frame) in frames.iter().enumerate() {
        let at = |f: &str| format!("frames[{k}].{f}");
        // Where a value comes from, for errors.
        let named = |name: &str| match frame.get(name) {
            Some(_) => at(name),
            None => name.to_string(),
        };
        // A per-frame value overrides the global one.
        let number = |name: &str| -> Result<Option<f64>, DatasetError> {
            match frame.get(name).or_else(|| json.get(name)) {
                None => Ok(None),
                Some(v) => v
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .map(Some)
                    .ok_or_else(|| field(&path, named(name), "must be a finite number")),
            }
        };
        let required = |name: &str| {
            number(name)?
                .ok_or_else(|| field(&path, name, "is missing (globally and in the frame)"))
        };
        let positive = |name: &str| match required(name)? {
            v if v > 0.0 => Ok(v),
            v => Err(field(
                &path,
                named(name),
                format!("must be positive, not {v}"),
            )),
        };
        let side = |name: &str| match required(name)? {
            v if v >= 1.0 && v.fract() == 0.0 && v <= u32::MAX as f64 => Ok(v as u32),
            v => Err(field(
                &path,
                named(name),
                format!("must be a positive whole number of pixels, not {v}"),
            )),
        };
        let file = frame["file_path"]
            .as_str()
            .ok_or_else(|| field(&path, at("file_path"), "must be a string"))?;
        let c2w = matrix(&frame["transform_matrix"]).ok_or_else(|| {
            field(
                &path,
                at("transform_matrix"),
                "must be 4 rows of 4 finite numbers",
            )
        })?;
        let image_path = joined(dir, file);
        let (w, h) = (side("w")?, side("h")?);
        let (width, height) = image_size(&image_path)?;
        if (w, h) != (width, height) {
            return Err(field(
                &path,
                format!("{} and {}", named("w"), named("h")),
                format!(
                    "say {w}x{h} pixels, but {} is {width}x{height}",
                    image_path.display(),
                ),
            ));
        }
        let model = frame
            .get("camera_model")
            .or_else(|| json.get("camera_model"))
            .map_or(Some("PINHOLE"), |m| m.as_str())
            .ok_or_else(|| field(&path, named("camera_model"), "must be a string"))?;
        let coefficient = |name: &str| Ok::<f64, DatasetError>(number(name)?.unwrap_or(0.0));
        let (camera_model, distortion, lens) = match model {
            // nerfstudio's radial polynomial runs to k4 r⁸. It reads the coefficients under
            // any model, so a PINHOLE camera (the default) that has them is OPENCV's.
            "PINHOLE" | "OPENCV" => (
                CameraModel::Pinhole,
                Vec4::ZERO,
                Lens {
                    numerator: [
                        coefficient("k1")?,
                        coefficient("k2")?,
                        coefficient("k3")?,
                        coefficient("k4")?,
                    ],
                    tangential: [coefficient("p1")?, coefficient("p2")?],
                    ..Lens::default()
                },
            ),
            "OPENCV_FISHEYE" => {
                if let Some(p) = ["p1", "p2"]
                    .into_iter()
                    .find(|p| coefficient(p).is_ok_and(|v| v != 0.0))
                {
                    return Err(field(
                        &path,
                        named(p),
                        "is a tangential term, which OPENCV_FISHEYE does not have",
                    ));
                }
                let k = [
                    coefficient("k1")?,
                    coefficient("k2")?,
                    coefficient("k3")?,
                    coefficient("k4")?,
                ];
                (
                    CameraModel::KannalaBrandt,
                    DVec4::from_array(k).as_vec4(),
                    Lens::default(),
                )
            }
            other => {
                return Err(field(
                    &path,
                    named("camera_model"),
                    format!("`{other}` is not supported (PINHOLE, OPENCV, OPENCV_FISHEYE)"),
                ));
            }
        };
        let focal = Vec2::new(positive("fl_x")? as f32, positive("fl_y")? as f32);
        let camera = Camera {
            principal: Vec2::new(required("cx")? as f32, required("cy")? as f32),
            model: camera_model,
            distortion,
            ..posed_camera(&c2w, focal, (width, height))
                .map_err(|problem| field(&path, at("transform_matrix"), problem))?
        };
        let shot = Shot::new(image_path, camera);
        shots.push(match lens.is_identity() {
            true => shot,
            false => shot.through(lens).map_err(|p| {
                field(
                    &path,
                    format!("the lens (k1-k4, p1, p2) of {}", at("file_path")),
                    p,
                )
            })?,
        });
    }
    Ok(Shots::every_8th_held_out(shots, Vec::new()))
}
