//! A training view's pose correction: a rigid motion of its camera, in its own frame.

use glam::{DMat3, DVec3, Mat3, Vec3};
use splat_core::types::Camera;

/// A rigid motion in a training view's camera frame, `x -> exp([w]x) x + tau` applied after
/// its world-to-camera pose `(R, t)`, which becomes `(exp([w]x) R, exp([w]x) t + tau)`: `w`
/// turns the camera about its own centre and `tau` shifts it along its own axes, the two
/// moves a picture tells apart best (as gsplat's `pose_opt`, which right-multiplies the
/// camera-to-world matrix). A rotation about the world's origin would move a distant camera's
/// centre too, coupling the words Adam steps one by one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseCorrection {
    /// The rotation's axis times its angle (radians), `w`, in the camera's frame.
    pub rotation: Vec3,
    /// `tau`, in world units along the camera's axes.
    pub translation: Vec3,
}

impl PoseCorrection {
    pub const WORDS: usize = 6;

    /// The correction in its 6 words: rotation, then translation.
    pub fn from_words(words: &[f32]) -> PoseCorrection {
        PoseCorrection {
            rotation: Vec3::from_slice(&words[..3]),
            translation: Vec3::from_slice(&words[3..6]),
        }
    }

    /// `camera` with its pose corrected.
    pub fn apply(&self, camera: &Camera) -> Camera {
        let omega = exp_so3(self.rotation.as_dvec3());
        Camera {
            rotation: (omega * camera.rotation.as_dmat3()).as_mat3(),
            translation: (omega * camera.translation.as_dvec3()).as_vec3() + self.translation,
            ..*camera
        }
    }

    /// The gradient by the correction's words, given `camera` (before the correction) and the
    /// cotangent `d` of the corrected camera's rotation and translation.
    pub fn backward(&self, camera: &Camera, d: &Camera) -> [f32; 6] {
        let (r, t) = (camera.rotation.as_dmat3(), camera.translation.as_dvec3());
        let w = self.rotation.as_dvec3();
        // R' = Omega R and t' = Omega t + tau: dL/dOmega = dL/dR' R^T + dL/dt' t^T, and
        // dL/dtau = dL/dt'.
        let d_t = d.translation.as_dvec3();
        let outer = DMat3::from_cols(d_t * t.x, d_t * t.y, d_t * t.z);
        let d_omega = d.rotation.as_dmat3() * r.transpose() + outer;
        let d_tau = d_t;
        let by_w = exp_derivatives(w).map(|dk| frobenius(&d_omega, &dk));
        [by_w[0], by_w[1], by_w[2], d_tau.x, d_tau.y, d_tau.z].map(|x| x as f32)
    }
}

/// `[v]x`, the cross product by `v` as a matrix.
fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// Rodrigues' rotation `exp([w]x)`.
fn exp_so3(w: DVec3) -> DMat3 {
    let theta = w.length();
    let k = skew(w);
    // sin(x)/x and (1 - cos(x))/x^2 by their series near zero.
    let (a, b) = match theta < 1e-4 {
        true => (1.0 - theta * theta / 6.0, 0.5 - theta * theta / 24.0),
        false => (theta.sin() / theta, (1.0 - theta.cos()) / (theta * theta)),
    };
    DMat3::IDENTITY + k * a + k * k * b
}

/// `d exp([w]x) / d w_k` for each k: Gallego and Yezzi's (2015) closed form,
/// `(w_k [w]x + [w x ((I - R) e_k)]x) R / |w|^2`, or `[e_k]x` at (near) zero.
fn exp_derivatives(w: DVec3) -> [DMat3; 3] {
    let axes = [DVec3::X, DVec3::Y, DVec3::Z];
    let theta2 = w.length_squared();
    if theta2 < 1e-16 {
        return axes.map(skew);
    }
    let r = exp_so3(w);
    let k = skew(w);
    std::array::from_fn(|i| {
        let e = axes[i];
        (k * w[i] + skew(w.cross((DMat3::IDENTITY - r) * e))) * r / theta2
    })
}

/// The sum of the entries of `a` times those of `b`.
fn frobenius(a: &DMat3, b: &DMat3) -> f64 {
    a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
}

/// The angle (radians) of the rotation between two rotations.
pub fn angle_between(a: &Mat3, b: &Mat3) -> f32 {
    let m = (a.transpose() * *b).as_dmat3();
    let cos = ((m.x_axis.x + m.y_axis.y + m.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0);
    cos.acos() as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The backward pass against f64 finite differences of `<A, R'> + <b, t'>`, at zero and
    /// away from it.
    #[test]
    fn pose_gradients_match_finite_differences() {
        let camera = Camera {
            rotation: Mat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1),
            translation: Vec3::new(0.5, -1.0, 3.0),
            ..Default::default()
        };
        let a = DMat3::from_cols_array(&[0.3, -1.2, 0.5, 0.9, 0.1, -0.4, 0.7, 0.2, -0.8]);
        let b = DVec3::new(-0.6, 0.25, 1.3);
        let d = Camera {
            rotation: a.as_mat3(),
            translation: b.as_vec3(),
            ..Camera::ZERO
        };
        let loss = |words: &[f64; 6]| {
            let w = DVec3::new(words[0], words[1], words[2]);
            let tau = DVec3::new(words[3], words[4], words[5]);
            let omega = exp_so3(w);
            let r = camera.rotation.as_dmat3();
            frobenius(&a, &(omega * r)) + b.dot(omega * camera.translation.as_dvec3() + tau)
        };
        for at in [
            [0.0; 6],
            [0.02, -0.05, 0.03, 0.1, 0.0, -0.2],
            [0.8, 0.4, -1.1, 0.0, 0.3, 0.1],
        ] {
            let words = at.map(|x| x as f32);
            let got = PoseCorrection::from_words(&words).backward(&camera, &d);
            super::super::tests::assert_finite_differences(&format!("at {at:?}"), at, got, loss);
        }
    }

    #[test]
    fn a_correction_moves_the_camera_in_its_own_frame() {
        let camera = Camera {
            rotation: Mat3::from_rotation_y(0.4),
            translation: Vec3::new(0.0, 0.0, 3.0),
            ..Default::default()
        };
        let c = PoseCorrection {
            rotation: Vec3::new(0.0, 0.0, 0.3),
            translation: Vec3::new(0.1, -0.2, 0.05),
        };
        let moved = c.apply(&camera);
        let p = Vec3::new(0.3, -0.4, 0.2);
        let want =
            Mat3::from_rotation_z(0.3) * (camera.rotation * p + camera.translation) + c.translation;
        let got = moved.rotation * p + moved.translation;
        assert!((got - want).length() < 1e-6, "{got} vs {want}");
        let none = PoseCorrection::from_words(&[0.0; 6]).apply(&camera);
        assert_eq!(none, camera);
        let turned = angle_between(&camera.rotation, &moved.rotation);
        assert!((turned - 0.3).abs() < 1e-5, "{turned}");
    }
}
