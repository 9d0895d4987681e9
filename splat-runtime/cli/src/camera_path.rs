//! The cameras of `splat video`: an orbit around the scene, a dataset's views in order, or a
//! path through keyframes (as `splat view`'s page saves them) interpolated smoothly.

use crate::orbit::Orbit;
use anyhow::{Context, Result, bail};
use serde::Deserialize;
use splat_runtime::Camera;
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::io::camera::CameraFile;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// Which way the camera goes.
#[derive(Clone, Debug)]
pub enum Route {
    /// Once around the scene's orbit.
    Orbit,
    /// A dataset's views, in the order of their pictures' names.
    Dataset,
    /// Through the keyframes of a JSON file: `{"keyframes": [camera, ...]}`.
    Keyframes(PathBuf),
}

impl FromStr for Route {
    type Err = String;

    fn from_str(s: &str) -> Result<Route, String> {
        Ok(match s {
            "orbit" => Route::Orbit,
            "dataset" => Route::Dataset,
            path if path.ends_with(".json") => Route::Keyframes(PathBuf::from(path)),
            _ => return Err("expected orbit, dataset or a keyframes file (.json)".to_string()),
        })
    }
}

/// A keyframes file, as the page's "save path" writes it.
#[derive(Deserialize)]
struct Keyframes {
    keyframes: Vec<CameraFile>,
}

/// `frames` cameras once around `orbit`, `elevation` degrees above its target, seeing `fov`
/// degrees vertically.
pub fn around(
    orbit: &Orbit,
    frames: usize,
    size: (u32, u32),
    fov: f32,
    elevation: f32,
) -> Vec<Camera> {
    (0..frames)
        .map(|k| {
            let azimuth = std::f32::consts::TAU * k as f32 / frames as f32;
            orbit.camera(azimuth, elevation.to_radians(), size, fov)
        })
        .collect()
}

/// `views` at `size`: each one's intrinsics scaled to it.
pub fn resized(views: &[Camera], (width, height): (u32, u32)) -> Vec<Camera> {
    let size = Vec2::new(width as f32, height as f32);
    (views.iter())
        .map(|c| {
            let s = size / c.size;
            Camera {
                focal: c.focal * s,
                principal: c.principal * s,
                size,
                ..*c
            }
        })
        .collect()
}

/// The keyframes in the file at `path`.
pub fn read_keyframes(path: &Path) -> Result<Vec<Camera>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let file: Keyframes = serde_json::from_str(&text).with_context(|| {
        format!(
            "{}: not a keyframes file ({{\"keyframes\": [camera, ...]}})",
            path.display()
        )
    })?;
    let keys = (file.keyframes.iter().enumerate())
        .map(|(k, c)| {
            c.to_camera()
                .with_context(|| format!("{}: keyframe {k}", path.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    if keys.len() < 2 {
        bail!(
            "{}: a path needs at least 2 keyframes, it has {}",
            path.display(),
            keys.len()
        );
    }
    Ok(keys)
}

/// `frames` cameras (at least 2) through `keys`, the first and last on the first and last
/// key: positions and rotations on Catmull-Rom splines (rotations as unit quaternions, each
/// turned to the same side as the one before), the vertical field of view linear, each frame
/// `size` with its principal point in the middle. The model and lens are the first key's.
pub fn through(keys: &[Camera], frames: usize, (width, height): (u32, u32)) -> Vec<Camera> {
    let size = Vec2::new(width as f32, height as f32);
    let eyes: Vec<Vec3> = keys.iter().map(crate::orbit::eye).collect();
    let mut turns: Vec<Vec4> = vec![];
    for c in keys {
        let q = Vec4::from(Quat::from_mat3(&c.rotation).normalize());
        let q = match turns.last() {
            Some(last) if last.dot(q) < 0.0 => -q,
            _ => q,
        };
        turns.push(q);
    }
    // Vertical field of view as tan(fov / 2).
    let spans: Vec<f32> = keys.iter().map(|c| 0.5 * c.size.y / c.focal.y).collect();
    let last = keys.len() - 1;
    (0..frames)
        .map(|k| {
            let u = k as f32 / (frames - 1).max(1) as f32 * last as f32;
            let i = (u.floor() as usize).min(last - 1);
            let t = u - i as f32;
            let at = |j: isize| (j.clamp(0, last as isize)) as usize;
            let four = |j: isize| [at(j - 1), at(j), at(j + 1), at(j + 2)];
            let [a, b, c, d] = four(i as isize);
            let eye = catmull_rom(eyes[a], eyes[b], eyes[c], eyes[d], t);
            let turn = catmull_rom(turns[a], turns[b], turns[c], turns[d], t).normalize();
            let rotation = Mat3::from_quat(Quat::from_vec4(turn));
            let span = spans[b] + (spans[c] - spans[b]) * t;
            Camera {
                distortion: keys[0].distortion,
                model: keys[0].model,
                ..crate::orbit::pinhole(rotation, eye, size, 0.5 * size.y / span)
            }
        })
        .collect()
}

/// The uniform Catmull-Rom spline through `p1` (t = 0) and `p2` (t = 1).
fn catmull_rom<V>(p0: V, p1: V, p2: V, p3: V, t: f32) -> V
where
    V: Copy
        + std::ops::Add<Output = V>
        + std::ops::Sub<Output = V>
        + std::ops::Mul<f32, Output = V>,
{
    let (t2, t3) = (t * t, t * t * t);
    (p1 * 2.0
        + (p2 - p0) * t
        + (p0 * 2.0 - p1 * 5.0 + p2 * 4.0 - p3) * t2
        + (p1 * 3.0 - p0 - p2 * 3.0 + p3) * t3)
        * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(eye: Vec3, fov: f32) -> Camera {
        Orbit {
            target: Vec3::ZERO,
            up: Vec3::Y,
            distance: eye.length(),
        }
        .camera(eye.x.atan2(eye.z), 0.0, (64, 48), fov)
    }

    #[test]
    fn a_path_starts_and_ends_on_its_keys_and_passes_through_them() {
        let keys = [
            key(Vec3::new(0.0, 0.0, 4.0), 50.0),
            key(Vec3::new(4.0, 0.0, 0.0), 60.0),
            key(Vec3::new(0.0, 0.0, -4.0), 40.0),
        ];
        let path = through(&keys, 33, (64, 48));
        assert_eq!(path.len(), 33);
        for (frame, key) in [(0, 0), (16, 1), (32, 2)] {
            let (a, b) = (&path[frame], &keys[key]);
            assert!(a.rotation.abs_diff_eq(b.rotation, 1e-5), "frame {frame}");
            assert!(
                a.translation.abs_diff_eq(b.translation, 1e-4),
                "frame {frame}"
            );
            assert!(a.focal.abs_diff_eq(b.focal, 1e-3), "frame {frame}");
        }
        // A curve, not chords: off the chord between keys, and no kink at a key (chords
        // through these keys turn by 90 degrees there; the spline, measured, 17 between
        // frames a sixteenth of the way apart).
        let eye = |k: usize| crate::orbit::eye(&path[k]);
        assert!(eye(8).length() > 3.0, "{}", eye(8).length());
        let turn = (eye(16) - eye(15))
            .angle_between(eye(17) - eye(16))
            .to_degrees();
        assert!(turn < 30.0, "the path turns {turn} degrees at a key");
    }

    #[test]
    fn an_orbit_goes_once_around_looking_at_its_target() {
        let orbit = Orbit {
            target: Vec3::new(1.0, 2.0, 3.0),
            up: Vec3::Z,
            distance: 5.0,
        };
        let cams = around(&orbit, 8, (64, 48), 50.0, 20.0);
        for c in &cams {
            let to_target = (orbit.target - crate::orbit::eye(c)).normalize();
            assert!((c.rotation.row(2) - to_target).length() < 1e-5);
            assert!(((crate::orbit::eye(c) - orbit.target).length() - 5.0).abs() < 1e-4);
            // Up in the world is up in the picture (image y points down).
            assert!(c.rotation.row(1).dot(Vec3::Z) < 0.0);
        }
    }
}
