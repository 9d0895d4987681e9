//! The orbit around a scene that `splat view`'s page starts from and `splat video --path
//! orbit` flies: about the point a dataset's views look at (or the middle of the primitives),
//! up as the views' pictures have it (or +y). The page (`viewer/page.html`) places its camera
//! from the same target, up and angles.

use splat_runtime::Camera;
use splat_runtime::glam::{Mat3, Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Orbit {
    pub target: Vec3,
    pub up: Vec3,
    pub distance: f32,
}

impl Orbit {
    /// The orbit of a scene whose primitives lie at `means`, seen by `views` (maybe none).
    pub fn of(views: &[Camera], means: &[Vec3]) -> Orbit {
        let median = |axis: usize| {
            let mut v: Vec<f32> = means.iter().map(|m| m[axis]).collect();
            v.sort_by(f32::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(0.0)
        };
        let middle = Vec3::new(median(0), median(1), median(2));
        // The point nearest every view's optical axis (least squares), where two views cross.
        let (mut a, mut b) = (Mat3::ZERO, Vec3::ZERO);
        for c in views {
            let d = c.rotation.row(2);
            let across = Mat3::IDENTITY - Mat3::from_cols(d * d.x, d * d.y, d * d.z);
            a += across;
            b += across * eye(c);
        }
        let target = match a.determinant().abs() > 1e-3 * (views.len() as f32).powi(3) {
            true => a.inverse() * b,
            false => middle,
        };
        let up = -views.iter().map(|c| c.rotation.row(1)).sum::<Vec3>();
        let distance = match views.len() {
            0 => {
                let mut far: Vec<f32> = means.iter().map(|m| (*m - target).length()).collect();
                far.sort_by(f32::total_cmp);
                // Three times the median: outside the bulk of the scene, however far its
                // backdrop (the built-in scene's stars, a capture's sky) reaches.
                3.0 * far.get(far.len() / 2).copied().unwrap_or(1.0)
            }
            n => {
                views
                    .iter()
                    .map(|c| (eye(c) - target).length())
                    .sum::<f32>()
                    / n as f32
            }
        };
        Orbit {
            target,
            up: up.try_normalize().unwrap_or(Vec3::Y),
            distance: distance.max(1e-3),
        }
    }

    /// As the page reads it.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "target": self.target.to_array(),
            "up": self.up.to_array(),
            "distance": self.distance,
        })
    }

    /// A pinhole `width` x `height` camera on the orbit, `azimuth` and `elevation` (radians)
    /// about its up, looking at its target with a vertical field of view of `fov` degrees.
    pub fn camera(
        &self,
        azimuth: f32,
        elevation: f32,
        (width, height): (u32, u32),
        fov: f32,
    ) -> Camera {
        let u = self.up;
        let z = if u.z.abs() < 0.9 { Vec3::Z } else { Vec3::X };
        let ahead = (z - u * z.dot(u)).normalize();
        let across = u.cross(ahead);
        let (sa, ca) = azimuth.sin_cos();
        let (se, ce) = elevation.sin_cos();
        let eye = self.target + (across * (ce * sa) + u * se + ahead * (ce * ca)) * self.distance;
        let forward = (self.target - eye).normalize();
        let right = -u.cross(forward).normalize();
        let down = forward.cross(right);
        let rotation = Mat3::from_cols(right, down, forward).transpose();
        let size = Vec2::new(width as f32, height as f32);
        pinhole(
            rotation,
            eye,
            size,
            0.5 * size.y / (0.5 * fov.to_radians()).tan(),
        )
    }
}

/// A pinhole camera at `eye` turned by `rotation` (world to camera), `size` pixels with focal
/// length `focal` and its principal point in the middle.
pub fn pinhole(rotation: Mat3, eye: Vec3, size: Vec2, focal: f32) -> Camera {
    Camera {
        rotation,
        translation: -(rotation * eye),
        focal: Vec2::splat(focal),
        principal: size / 2.0,
        size,
        ..Default::default()
    }
}

/// Where `camera` is in the world.
pub fn eye(camera: &Camera) -> Vec3 {
    -(camera.rotation.transpose() * camera.translation)
}
