//! What the two JSON layouts share: reading a `transforms` file, its paths and matrices, and
//! the OpenCV camera of an OpenGL camera-to-world pose.

use super::error::DatasetError;
use glam::{Mat3, Mat4, Vec2, Vec4};
use splat_core::types::{Camera, NotRotation, rotation_defect};
use std::path::{Path, PathBuf};

/// A JSON file's value, its errors naming the file.
pub(super) fn read_json(path: &Path) -> Result<serde_json::Value, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|error| DatasetError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    serde_json::from_str(crate::without_bom(&text)).map_err(|error| DatasetError::Json {
        path: path.to_path_buf(),
        error,
    })
}

/// `dir` joined with a frame's `file_path`, without the `./` such paths often start with.
pub(super) fn joined(dir: &Path, file: &str) -> PathBuf {
    dir.join(file).components().collect()
}

pub(super) fn matrix(v: &serde_json::Value) -> Option<Mat4> {
    let rows = v.as_array().filter(|r| r.len() == 4)?;
    let mut m = [[0.0f32; 4]; 4];
    for (i, row) in rows.iter().enumerate() {
        let row = row.as_array().filter(|r| r.len() == 4)?;
        for (j, x) in row.iter().enumerate() {
            m[i][j] = x.as_f64().filter(|x| x.is_finite())? as f32;
        }
    }
    // Row-major in the file; glam takes columns.
    Some(Mat4::from_cols_array_2d(&m).transpose())
}

/// The OpenCV world-to-camera pose of an OpenGL camera-to-world matrix, in a pinhole camera
/// with the principal point at the centre of a picture of `(width, height)` pixels; what is
/// wrong with the matrix if it is not a rigid pose (scale or shear would distort every render
/// against its image).
pub(super) fn posed_camera(
    c2w_gl: &Mat4,
    focal: Vec2,
    (width, height): (u32, u32),
) -> Result<Camera, String> {
    // Written by other programs as the inverse of a pose: within rounding of the unit row.
    if !c2w_gl.row(3).abs_diff_eq(Vec4::W, 1e-4) {
        return Err(format!(
            "must end with the row [0, 0, 0, 1], not {:?}",
            c2w_gl.row(3).to_array()
        ));
    }
    match rotation_defect(&Mat3::from_mat4(*c2w_gl)) {
        Some(NotRotation::Off(off)) => {
            return Err(format!(
                "is not a rigid pose: its 3x3 part is off a rotation by {off:.2e} (the largest entry of R^T R - I)"
            ));
        }
        Some(NotRotation::Mirror) => {
            return Err("mirrors the world (its 3x3 part has a negative determinant)".into());
        }
        None => {}
    }
    // OpenGL to OpenCV camera axes: y and z flip.
    let c2w = *c2w_gl * Mat4::from_diagonal(Vec4::new(1.0, -1.0, -1.0, 1.0));
    let w2c = c2w.inverse();
    let size = Vec2::new(width as f32, height as f32);
    Ok(Camera {
        rotation: Mat3::from_mat4(w2c),
        translation: w2c.w_axis.truncate(),
        focal,
        principal: size / 2.0,
        size,
        ..Default::default()
    })
}
