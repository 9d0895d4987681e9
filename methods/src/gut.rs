// 3DGUT (Wu et al. 2025; as in XPR, Rhyner et al. 2026, §A.1.2): the 3DGS primitive
// projected by the unscented transform instead of the EWA Jacobian, and evaluated in 3D along each pixel's camera ray
// (the Gaussian's maximum response on the ray), so it works with every camera model.
//
// A rolling shutter is an instance of its own: `gut_rs` sees each row from the pose the camera
// had when the sensor read it (`cam.shutter_time`, `cam.rotation_at`), so each pixel's ray
// starts where the camera was; `gut`'s constant `ROLLING_SHUTTER` is false and that code folds
// away. Per Gaussian, the box holds the footprints at the first and the last row's pose, and
// the color and opacity are those seen from the first row's pose (they change little over a
// readout).
//
// The SH degree is one instance per degree, as for 3DGS: `gut_sh0` .. `gut_sh2`, and `gut` for
// degree 3 (and the rolling shutter).

/// One 3DGUT method with `$n` SH coefficients per channel, with or without a rolling shutter.
macro_rules! unscented {
    ($name:ident, sh_coefficients = $n:literal, rolling_shutter = $rs:literal) => {
        #[splat_macros::splat_method(name = "3dgut")]
        pub mod $name {
            use splat_runtime::prelude::*;

            pub const NEAR: f32 = 0.01;
            pub const ALPHA_MIN: f32 = 1.0 / 255.0;
            /// See each row from the camera's pose at the row's readout.
            pub const ROLLING_SHUTTER: bool = $rs;

            pub struct Params {
                pub mean: Vec3,
                /// Natural log of the three axis scales.
                pub log_scale: Vec3,
                /// Rotation quaternion (w, x, y, z), normalized here.
                pub rotation: Vec4,
                pub opacity_logit: f32,
                pub sh: [Vec3; $n],
            }

            /// A pixel's ray in world space.
            pub struct Ray {
                pub dir: Vec3,
                /// Where it starts, from the camera centre: the rolling shutter's motion by the row's
                /// time (zero without one).
                pub shift: Vec3,
            }

            pub struct Shade {
                /// The camera centre in the Gaussian's canonical (whitened) frame.
                pub origin: Vec3,
                /// World to canonical: S^-1 R^T.
                pub whiten: Mat3,
                pub opacity: f32,
                pub color: Vec3,
            }

            /// The unscented transform's image of a Gaussian seen from one pose.
            pub struct Footprint {
                /// The pixel of the mean.
                pub centre: Vec2,
                /// The 2D covariance (xx, xy, yy), px^2.
                pub cov: Vec3,
                /// The mean's distance from the camera.
                pub depth: f32,
                /// In front of the camera, and every sigma point projects.
                pub projectable: bool,
            }

            /// The unscented transform, alpha 1, beta 2, kappa 0: sigma points mean ± sqrt(3) * axis
            /// with weights 1/6 each; the centre weighs 0 in the mean and 2 in the covariance. Offsets
            /// from the centre's pixel keep the f32 sums small.
            fn footprint(
                p: &Params,
                rot: Mat3,
                scale: Vec3,
                rotation: Mat3,
                translation: Vec3,
                cam: &Camera,
            ) -> Footprint {
                let mean = rotation * p.mean + translation;
                let centre = cam.project_point(mean);
                let mut shift = Vec2::ZERO;
                let mut cov = Vec3::ZERO; // xx, xy, yy
                let mut projectable = cam.can_project(mean) && mean.length() > NEAR;
                for i in 0..3 {
                    let axis = rotation * rot.col(i) * (scale[i] * 1.7320508);
                    for side in 0..2 {
                        let point = mean + axis * (1.0 - 2.0 * side as f32);
                        projectable =
                            projectable && cam.can_project(point) && point.length() > NEAR;
                        let z = cam.project_point(point) - centre;
                        shift += z / 6.0;
                        cov += Vec3::new(z.x * z.x, z.x * z.y, z.y * z.y) / 6.0;
                    }
                }
                cov += Vec3::new(shift.x * shift.x, shift.x * shift.y, shift.y * shift.y);
                Footprint {
                    centre: centre + shift,
                    cov,
                    depth: mean.length(),
                    projectable,
                }
            }

            /// How far from its centre a footprint (covariance `cov`, low-pass filtered) reaches
            /// `max_power`. The UT only approximates what the 3D evaluation reaches (more so through
            /// a fisheye): a margin of 40% and a pixel.
            fn reach(cov: Vec3, max_power: f32) -> f32 {
                let (a, b, d) = (cov.x + 0.3, cov.y, cov.z + 0.3);
                let mid = 0.5 * (a + d);
                let lambda = mid + (mid * mid - (a * d - b * b)).max(0.1).sqrt();
                (1.4 * (2.0 * max_power.max(0.0) * lambda).sqrt()).ceil() + 1.0
            }

            pub fn project(p: &Params, cam: &Camera) -> Projected<f32, Shade> {
                let rot = blocks::rotation_matrix(p.rotation);
                let scale = p.log_scale.exp();
                let seen = footprint(p, rot, scale, cam.rotation, cam.translation, cam);
                let cov = seen.cov;
                // Low-pass filter with the opacity compensation of Mip-Splatting.
                let det_orig = cov.x * cov.z - cov.y * cov.y;
                let det = (cov.x + 0.3) * (cov.z + 0.3) - cov.y * cov.y;
                let opacity = sigmoid(p.opacity_logit) * (det_orig.max(0.0) / det).sqrt();
                let max_power = (opacity / ALPHA_MIN).ln();
                let radius = reach(cov, max_power);
                let mut bbox_min = seen.centre - radius;
                let mut bbox_max = seen.centre + radius;
                let mut projectable = seen.projectable;
                if ROLLING_SHUTTER {
                    // The box holds the footprints seen from the first and the last row's pose.
                    let (rotation, translation) = (cam.rotation_at(1.0), cam.translation_at(1.0));
                    let last = footprint(p, rot, scale, rotation, translation, cam);
                    let last_radius = reach(last.cov, max_power);
                    bbox_min = bbox_min.min(last.centre - last_radius);
                    bbox_max = bbox_max.max(last.centre + last_radius);
                    projectable = projectable && last.projectable;
                }
                let whiten = Mat3::from_diagonal(Vec3::ONE / scale) * rot.transpose();
                Projected {
                    visible: projectable && det > 0.0 && opacity >= ALPHA_MIN,
                    depth: seen.depth,
                    bbox_min,
                    bbox_max,
                    cull: 0.0,
                    shade: Shade {
                        origin: whiten * (cam.center() - p.mean),
                        whiten,
                        opacity,
                        color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5)
                            .max(Vec3::ZERO),
                    },
                }
            }

            pub fn pixel_info(pixel: Vec2, cam: &Camera) -> Ray {
                let mut rotation = cam.rotation;
                let mut shift = Vec3::ZERO;
                if ROLLING_SHUTTER {
                    let t = cam.shutter_time(pixel);
                    rotation = cam.rotation_at(t);
                    shift = cam.shutter_shift * t;
                }
                Ray {
                    dir: rotation.transpose() * cam.pixel_ray(pixel),
                    shift,
                }
            }

            /// alpha = o * G(o + tau_max d): the largest response on the ray, at its point closest to
            /// the centre in the canonical frame. The ray starts at the camera (tau >= 0): a Gaussian
            /// behind it contributes only its tail at the camera, continuously (a hard `tau > 0` test
            /// would jump where rays of a wide camera turn away from a Gaussian).
            pub fn evaluate(ray: Ray, s: &Shade) -> Contribution<Vec3> {
                let mut origin = s.origin;
                if ROLLING_SHUTTER {
                    origin += s.whiten * ray.shift;
                }
                let d = s.whiten * ray.dir;
                let tau = (-origin.dot(d) / d.dot(d)).max(0.0);
                let closest = origin + d * tau;
                let alpha = (s.opacity * (-0.5 * closest.dot(closest)).exp()).min(0.99);
                Contribution {
                    alpha,
                    color: s.color,
                    valid: alpha >= ALPHA_MIN,
                }
            }
        }
    };
}

unscented!(gut, sh_coefficients = 16, rolling_shutter = false);
unscented!(gut_sh0, sh_coefficients = 1, rolling_shutter = false);
unscented!(gut_sh1, sh_coefficients = 4, rolling_shutter = false);
unscented!(gut_sh2, sh_coefficients = 9, rolling_shutter = false);
unscented!(gut_rs, sh_coefficients = 16, rolling_shutter = true);
