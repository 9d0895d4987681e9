//! Cameras as JSON:
//! `{"width": W, "height": H, "fx": .., "fy": .., "cx": .., "cy": ..,
//!   "world_to_camera": [[4 rows of 4]], "model": "pinhole"}` (row-major, OpenCV convention).
//! `model` is `pinhole` (the default), `kannala_brandt` (with `"k": [k1, k2, k3, k4]`, required;
//! zeros are the equidistant fisheye) or `equiangular`; see [`CameraModel`]. The pose must be
//! rigid (a rotation and a translation).
//!
//! A rolling shutter (rows read out top to bottom while the camera moves; `world_to_camera`
//! is the first row's pose) is given by the last row's pose, `"world_to_camera_last_row":
//! [[4 rows of 4]]`, or as the camera stores it, `"shutter_turn": [x, y, z], "shutter_shift":
//! [x, y, z]` (see [`Camera::shutter_turn`]; what `write` writes). Without either the shutter
//! is global.

use glam::{Mat3, Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};
use splat_core::frame::MAX_SIDE;
use splat_core::types::{Camera, CameraModel, NotRotation, rotation_defect};
use std::path::Path;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub world_to_camera: [[f32; 4]; 4],
    #[serde(default = "pinhole")]
    pub model: String,
    /// Kannala-Brandt coefficients; only with `"model": "kannala_brandt"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k: Option<[f32; 4]>,
    /// A rolling shutter's last row pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_to_camera_last_row: Option<[[f32; 4]; 4]>,
    /// A rolling shutter's turn and shift ([`Camera::shutter_turn`], [`Camera::shutter_shift`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shutter_turn: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shutter_shift: Option<[f32; 3]>,
}

fn pinhole() -> String {
    "pinhole".into()
}

#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error("cannot read camera {path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: {error}")]
    In {
        path: String,
        error: Box<CameraError>,
    },
    #[error("camera {path} is not valid JSON for a camera: {error}")]
    Json {
        path: String,
        error: serde_json::Error,
    },
    #[error("camera model `{0}` is not supported (supported: {names})", names = model_names(false))]
    Model(String),
    #[error(
        "camera coefficients `k` are only for models with distortion ({names}), not {0}",
        names = model_names(true)
    )]
    Coefficients(CameraModel),
    #[error("camera image size {0}x{1} is out of range (1..={MAX_SIDE} per side)")]
    Size(u32, u32),
    /// What is wrong with the intrinsics: "focal lengths fx, fy must be finite and positive".
    #[error("camera {0}")]
    Intrinsics(&'static str),
    #[error("camera {0} must be finite with last row [0, 0, 0, 1]")]
    Pose(&'static str),
    #[error(
        "camera rolling shutter: give world_to_camera_last_row or shutter_turn and shutter_shift, not both"
    )]
    Shutter,
    #[error(
        "camera world_to_camera_last_row turns {0:.0}° from world_to_camera: a rolling shutter turns less than 180° during a readout"
    )]
    ShutterTurn(f32),
    #[error(
        "camera {0} is not rigid: its 3x3 part is off a rotation by {1:.2e} (the largest entry of R^T R - I); scale or shear would distort the render"
    )]
    NotRigid(&'static str, f32),
    #[error(
        "camera {0} mirrors the world (its 3x3 part has a negative determinant): a pose is a rotation"
    )]
    Mirrored(&'static str),
    #[error(
        "camera model {0} needs its coefficients `k`: [k1, k2, k3, k4] (for kannala_brandt, [0, 0, 0, 0] is the equidistant fisheye)"
    )]
    NoCoefficients(CameraModel),
}

/// The models' names, all of them or (`distortion`) those with distortion coefficients.
fn model_names(distortion: bool) -> String {
    let names: Vec<&str> = CameraModel::ALL
        .iter()
        .filter(|m| !distortion || m.has_distortion())
        .map(|m| m.name())
        .collect();
    names.join(", ")
}

impl CameraFile {
    pub fn to_camera(&self) -> Result<Camera, CameraError> {
        let model = CameraModel::from_name(&self.model)
            .ok_or_else(|| CameraError::Model(self.model.clone()))?;
        if self.k.is_some() && !model.has_distortion() {
            return Err(CameraError::Coefficients(model));
        }
        if self.k.is_none() && model.has_distortion() {
            return Err(CameraError::NoCoefficients(model));
        }
        let k = self.k.unwrap_or_default();
        if !k.iter().all(|v| v.is_finite()) {
            return Err(CameraError::Intrinsics("coefficients k must be finite"));
        }
        let side = |v: u32| (1..=MAX_SIDE).contains(&v);
        if !side(self.width) || !side(self.height) {
            return Err(CameraError::Size(self.width, self.height));
        }
        if !(self.fx.is_finite() && self.fy.is_finite() && self.fx > 0.0 && self.fy > 0.0) {
            return Err(CameraError::Intrinsics(
                "focal lengths fx, fy must be finite and positive",
            ));
        }
        if !(self.cx.is_finite() && self.cy.is_finite()) {
            return Err(CameraError::Intrinsics(
                "principal point cx, cy must be finite",
            ));
        }
        let (rotation, translation) = rigid(&self.world_to_camera, "world_to_camera")?;
        let camera = Camera {
            rotation,
            translation,
            focal: Vec2::new(self.fx, self.fy),
            principal: Vec2::new(self.cx, self.cy),
            size: Vec2::new(self.width as f32, self.height as f32),
            distortion: Vec4::from_array(k),
            shutter_turn: Vec3::from_array(self.shutter_turn.unwrap_or_default()),
            shutter_shift: Vec3::from_array(self.shutter_shift.unwrap_or_default()),
            model,
        };
        if !(camera.shutter_turn.is_finite() && camera.shutter_shift.is_finite()) {
            return Err(CameraError::Intrinsics(
                "rolling shutter turn and shift must be finite",
            ));
        }
        match &self.world_to_camera_last_row {
            None => Ok(camera),
            Some(_) if camera.has_rolling_shutter() => Err(CameraError::Shutter),
            Some(last) => {
                let (r1, t1) = rigid(last, "world_to_camera_last_row")?;
                with_last_row_pose(camera, r1, t1)
            }
        }
    }

    pub fn from_camera(c: &Camera) -> CameraFile {
        let r = c.rotation;
        let t = c.translation;
        let row = |i: usize| [r.x_axis[i], r.y_axis[i], r.z_axis[i], t[i]];
        CameraFile {
            width: c.size.x as u32,
            height: c.size.y as u32,
            fx: c.focal.x,
            fy: c.focal.y,
            cx: c.principal.x,
            cy: c.principal.y,
            world_to_camera: [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]],
            model: c.model.name().into(),
            k: c.model.has_distortion().then(|| c.distortion.to_array()),
            world_to_camera_last_row: None,
            shutter_turn: c.has_rolling_shutter().then(|| c.shutter_turn.to_array()),
            shutter_shift: c.has_rolling_shutter().then(|| c.shutter_shift.to_array()),
        }
    }
}

/// The rotation and translation of a rigid 4x4 world-to-camera matrix (row-major).
fn rigid(m: &[[f32; 4]; 4], name: &'static str) -> Result<(Mat3, Vec3), CameraError> {
    let finite = m.iter().flatten().all(|v| v.is_finite());
    if !finite || m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(CameraError::Pose(name));
    }
    let col = |c: usize| Vec3::new(m[0][c], m[1][c], m[2][c]);
    let rotation = Mat3::from_cols(col(0), col(1), col(2));
    match rotation_defect(&rotation) {
        Some(NotRotation::Off(off)) => Err(CameraError::NotRigid(name, off)),
        Some(NotRotation::Mirror) => Err(CameraError::Mirrored(name)),
        None => Ok((rotation, col(3))),
    }
}

/// `camera` with the rolling shutter that ends at the last row's pose `(rotation,
/// translation)`: the turn from the first row's rotation as [`Camera::shutter_turn`] encodes it
/// (twice the vector part over the scalar part of its quaternion), the centre's move as
/// [`Camera::shutter_shift`].
pub fn with_last_row_pose(
    camera: Camera,
    rotation: Mat3,
    translation: Vec3,
) -> Result<Camera, CameraError> {
    let turn = glam::DQuat::from_mat3(&(rotation * camera.rotation.transpose()).as_dmat3());
    let turn = if turn.w < 0.0 { -turn } else { turn };
    if turn.w < 1e-6 {
        return Err(CameraError::ShutterTurn(
            turn.angle_between(glam::DQuat::IDENTITY).to_degrees() as f32,
        ));
    }
    let center = -(rotation.transpose() * translation);
    Ok(Camera {
        shutter_turn: (2.0 * turn.xyz() / turn.w).as_vec3(),
        shutter_shift: center - camera.center(),
        ..camera
    })
}

/// The largest camera file read: a camera is a few hundred bytes, and a stream that never
/// ends (`/dev/zero`) is not read whole.
const MAX_CAMERA_FILE: u64 = 1 << 20;

pub fn read(path: &Path) -> Result<Camera, CameraError> {
    let io = |error| CameraError::Io {
        path: path.display().to_string(),
        error,
    };
    let mut text = String::new();
    let file = std::fs::File::open(path).map_err(io)?;
    std::io::Read::read_to_string(
        &mut std::io::Read::take(file, MAX_CAMERA_FILE + 1),
        &mut text,
    )
    .map_err(io)?;
    if text.len() as u64 > MAX_CAMERA_FILE {
        return Err(io(std::io::Error::other(format!(
            "it runs past {} MiB, and a camera file is a few hundred bytes",
            MAX_CAMERA_FILE >> 20
        ))));
    }
    let file: CameraFile =
        serde_json::from_str(super::without_bom(&text)).map_err(|error| CameraError::Json {
            path: path.display().to_string(),
            error,
        })?;
    file.to_camera().map_err(|error| CameraError::In {
        path: path.display().to_string(),
        error: Box::new(error),
    })
}

pub fn write(path: &Path, camera: &Camera) -> std::io::Result<()> {
    super::write_atomic(path, |w| write_to(w, camera))
}

/// Refused with what [`read`] would say of the file: a camera that is not finite, positive and
/// rigid, or whose size is not whole pixels.
pub fn write_to(w: &mut dyn std::io::Write, camera: &Camera) -> std::io::Result<()> {
    let invalid = |why: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, why);
    if camera.size != camera.size.round() || camera.size.min_element() < 1.0 {
        return Err(invalid(format!(
            "a camera of {}x{} pixels cannot be written: its size must be whole pixels",
            camera.size.x, camera.size.y
        )));
    }
    let file = CameraFile::from_camera(camera);
    file.to_camera()
        .map_err(|e| invalid(format!("the camera cannot be written: {e}")))?;
    let json = serde_json::to_string_pretty(&file).expect("serializable");
    w.write_all(json.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the reader would refuse is not written.
    #[test]
    fn cameras_the_reader_refuses_are_not_written() {
        let good = Camera {
            size: Vec2::new(64.0, 48.0),
            focal: Vec2::splat(50.0),
            principal: Vec2::new(32.0, 24.0),
            ..Default::default()
        };
        write_to(&mut vec![], &good).unwrap();
        let bad = [
            Camera {
                focal: Vec2::NAN,
                ..good
            },
            Camera {
                size: Vec2::new(2.5, 48.0),
                ..good
            },
            Camera {
                rotation: Mat3::from_diagonal(Vec3::splat(3.0)),
                ..good
            },
        ];
        for camera in bad {
            let e = write_to(&mut vec![], &camera).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput, "{e}");
        }
    }

    #[test]
    fn json_round_trip_and_validation() {
        let cam = Camera {
            rotation: Mat3::from_rotation_y(0.3),
            translation: Vec3::new(0.1, -0.2, 3.0),
            focal: Vec2::new(500.0, 510.0),
            principal: Vec2::new(320.0, 240.0),
            size: Vec2::new(640.0, 480.0),
            ..Default::default()
        };
        let file = CameraFile::from_camera(&cam);
        let json = serde_json::to_string(&file).unwrap();
        let back: CameraFile = serde_json::from_str(&json).unwrap();
        assert_eq!(back.to_camera().unwrap(), cam);

        let mut bad = file.clone();
        bad.model = "fisheye".into();
        assert!(bad.to_camera().unwrap_err().to_string().contains("fisheye"));
        let mut bad = file.clone();
        bad.width = 0;
        assert!(matches!(bad.to_camera(), Err(CameraError::Size(0, 480))));
        let mut bad = file.clone();
        bad.fx = f32::NAN;
        assert!(matches!(bad.to_camera(), Err(CameraError::Intrinsics(_))));
        let mut bad = file.clone();
        bad.world_to_camera[3] = [0.0, 0.0, 1.0, 1.0];
        assert!(matches!(bad.to_camera(), Err(CameraError::Pose(_))));
        let mut bad = file;
        bad.k = Some([0.1, 0.0, 0.0, 0.0]);
        assert!(
            bad.to_camera()
                .unwrap_err()
                .to_string()
                .contains("only for models with distortion (kannala_brandt), not pinhole")
        );
    }

    #[test]
    fn rolling_shutters_read_from_the_last_row_pose_and_round_trip() {
        let first = r#"{"width": 64, "height": 48, "fx": 60, "fy": 60, "cx": 32, "cy": 24,
            "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 6], [0, 0, 0, 1]]"#;
        // The last row turned 90° about z and moved.
        let json = format!(
            r#"{first}, "world_to_camera_last_row": [[0, -1, 0, 0.5], [1, 0, 0, 0], [0, 0, 1, 6], [0, 0, 0, 1]]}}"#
        );
        let file: CameraFile = serde_json::from_str(&json).unwrap();
        let cam = file.to_camera().unwrap();
        let last = Mat3::from_cols(Vec3::Y, -Vec3::X, Vec3::Z);
        assert!(cam.rotation_at(1.0).abs_diff_eq(last, 1e-6));
        assert!(
            cam.translation_at(1.0)
                .abs_diff_eq(Vec3::new(0.5, 0.0, 6.0), 1e-6)
        );
        let back = CameraFile::from_camera(&cam);
        assert_eq!(back.to_camera().unwrap(), cam);
        assert!(back.shutter_turn.is_some() && back.world_to_camera_last_row.is_none());

        let mut both = file.clone();
        both.shutter_shift = Some([0.1, 0.0, 0.0]);
        assert!(matches!(both.to_camera(), Err(CameraError::Shutter)));
        let half_turn = format!(
            r#"{first}, "world_to_camera_last_row": [[-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 1, 6], [0, 0, 0, 1]]}}"#
        );
        let file: CameraFile = serde_json::from_str(&half_turn).unwrap();
        assert!(matches!(file.to_camera(), Err(CameraError::ShutterTurn(_))));
    }

    /// A file an editor started with a byte-order mark reads as without it.
    #[test]
    fn a_byte_order_mark_is_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.json");
        let cam = Camera {
            focal: Vec2::splat(50.0),
            principal: Vec2::new(32.0, 24.0),
            size: Vec2::new(64.0, 48.0),
            ..Default::default()
        };
        let mut json = vec![];
        write_to(&mut json, &cam).unwrap();
        std::fs::write(&path, [&[0xef, 0xbb, 0xbf][..], &json].concat()).unwrap();
        assert_eq!(read(&path).unwrap(), cam);
    }

    #[test]
    fn fisheye_and_equiangular_models_round_trip() {
        let json = r#"{"width": 64, "height": 48, "fx": 20, "fy": 20, "cx": 32, "cy": 24,
            "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]],
            "model": "kannala_brandt", "k": [0.05, -0.01, 0.002, 0.0]}"#;
        let file: CameraFile = serde_json::from_str(json).unwrap();
        let cam = file.to_camera().unwrap();
        assert_eq!(cam.model, CameraModel::KannalaBrandt);
        assert_eq!(cam.distortion, Vec4::new(0.05, -0.01, 0.002, 0.0));
        let back = CameraFile::from_camera(&cam).to_camera().unwrap();
        assert_eq!(back, cam);
        let eq = Camera {
            model: CameraModel::Equiangular,
            ..cam
        };
        let back = CameraFile::from_camera(&Camera {
            distortion: Vec4::ZERO,
            ..eq
        });
        assert_eq!(back.model, "equiangular");
        assert_eq!(back.k, None);
    }
}
