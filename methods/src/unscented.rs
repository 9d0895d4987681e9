//! 3DGUT (Wu et al. 2025; as in XPR, Rhyner et al. 2026, §A.1.2): the 3DGS primitive
//! projected by the unscented transform instead of the EWA Jacobian, and evaluated in 3D along each pixel's camera ray
//! (the Gaussian's maximum response on the ray), so it works with every camera model.

#[splat_macros::splat_method]
pub mod gut {
    use splat_runtime::prelude::*;

    pub const NEAR: f32 = 0.01;
    pub const ALPHA_MIN: f32 = 1.0 / 255.0;

    pub struct Params {
        pub mean: Vec3,
        /// Natural log of the three axis scales.
        pub log_scale: Vec3,
        /// Rotation quaternion (w, x, y, z), normalized here.
        pub rotation: Vec4,
        pub opacity_logit: f32,
        pub sh: [Vec3; 16],
    }

    /// The world-space direction of a pixel's ray (its origin is the camera centre).
    pub struct Ray {
        pub dir: Vec3,
    }

    pub struct Shade {
        /// The camera centre in the Gaussian's canonical (whitened) frame.
        pub origin: Vec3,
        /// World to canonical: S^-1 R^T.
        pub whiten: Mat3,
        pub opacity: f32,
        pub color: Vec3,
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<f32, Shade> {
        let q = Quat::from_xyzw(p.rotation.y, p.rotation.z, p.rotation.w, p.rotation.x).normalize();
        let rot = Mat3::from_quat(q);
        let scale = p.log_scale.exp();
        let mean = cam.rotation * p.mean + cam.translation;
        let centre = cam.project_point(mean);
        // Unscented transform, alpha 1, beta 2, kappa 0: sigma points mean ± sqrt(3) * axis with
        // weights 1/6 each; the centre weighs 0 in the mean and 2 in the covariance. Offsets
        // from the centre's pixel keep the f32 sums small.
        let mut shift = Vec2::ZERO;
        let mut cov = Vec3::ZERO; // xx, xy, yy
        let mut projectable = cam.can_project(mean) && mean.length() > NEAR;
        for i in 0..3 {
            let axis = cam.rotation * rot.col(i) * (scale[i] * 1.7320508);
            for side in 0..2 {
                let point = mean + axis * (1.0 - 2.0 * side as f32);
                projectable = projectable && cam.can_project(point) && point.length() > NEAR;
                let z = cam.project_point(point) - centre;
                shift += z / 6.0;
                cov += Vec3::new(z.x * z.x, z.x * z.y, z.y * z.y) / 6.0;
            }
        }
        cov += Vec3::new(shift.x * shift.x, shift.x * shift.y, shift.y * shift.y);
        // Low-pass filter with the opacity compensation of Mip-Splatting.
        let det_orig = cov.x * cov.z - cov.y * cov.y;
        let (a, b, d) = (cov.x + 0.3, cov.y, cov.z + 0.3);
        let det = a * d - b * b;
        let opacity = sigmoid(p.opacity_logit) * (det_orig.max(0.0) / det).sqrt();
        let max_power = (opacity / ALPHA_MIN).ln();
        let mid = 0.5 * (a + d);
        let lambda = mid + (mid * mid - det).max(0.1).sqrt();
        // The UT footprint only approximates what the 3D evaluation reaches (more so through a
        // fisheye): the box gets a margin of 40% and a pixel.
        let radius = (1.4 * (2.0 * max_power.max(0.0) * lambda).sqrt()).ceil() + 1.0;
        let whiten = Mat3::from_diagonal(Vec3::ONE / scale) * rot.transpose();
        Projected {
            visible: projectable && det > 0.0 && opacity >= ALPHA_MIN,
            depth: mean.length(),
            bbox_min: centre + shift - radius,
            bbox_max: centre + shift + radius,
            cull: 0.0,
            shade: Shade {
                origin: whiten * (cam.center() - p.mean),
                whiten,
                opacity,
                color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5).max(Vec3::ZERO),
            },
        }
    }

    pub fn pixel_info(pixel: Vec2, cam: &Camera) -> Ray {
        Ray {
            dir: cam.rotation.transpose() * cam.pixel_ray(pixel),
        }
    }

    /// alpha = o * G(o + tau_max d): the largest response on the ray, at its point closest to
    /// the centre in the canonical frame. The ray starts at the camera (tau >= 0): a Gaussian
    /// behind it contributes only its tail at the camera, continuously (a hard `tau > 0` test
    /// would jump where rays of a wide camera turn away from a Gaussian).
    pub fn evaluate(ray: Ray, s: &Shade) -> Contribution<Vec3> {
        let d = s.whiten * ray.dir;
        let tau = (-s.origin.dot(d) / d.dot(d)).max(0.0);
        let closest = s.origin + d * tau;
        let alpha = (s.opacity * (-0.5 * closest.dot(closest)).exp()).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= ALPHA_MIN,
        }
    }
}
