//! The camera models, each defined once, in the subset `#[splat_method]` accepts: the runtime
//! compiles them as its own code (`splat_runtime::cameras`, through [`camera_models!`]) and the
//! compiler reads them from this file's text ([`SOURCE`]) and compiles each model's functions
//! like a kernel's, so the kernels and the runtime cannot drift apart. A crate of its own so
//! that both packages hold it.
//!
//! A model is a module in [`camera_models!`] with `CODE` (its word in buffers and generated
//! code), `NAME` (the module's name: in camera files, on the command line, in the names of the
//! kernels compiled for it), `DISTORTION` (whether it reads the camera's `distortion`, `k` in
//! camera files) and the three functions; adding one adds a module there and a variant to
//! `splat_runtime::CameraModel`, whose matches the compiler then points at. Methods never name
//! a model's code: they call `cam.project_point(p)`, `cam.pixel_ray(px)`, `cam.can_project(p)`,
//! or test `cam.is_pinhole()` (one `is_` per model).
//!
//! The functions outside the modules hold for every model (the pose, the rolling shutter): a
//! kernel calls them as `cam.center()`, `cam.shutter_time(pixel)`, `cam.rotation_at(t)`, and so
//! do they (each other: the compiler renames them).

#![no_std]

/// This file's text: the compiler parses the models out of [`camera_models!`]'s body.
pub const SOURCE: &str = include_str!("lib.rs");

/// The camera models' code, expanded where the runtime's prelude is in scope (`Camera`, glam's
/// types, the intrinsics): `splat_runtime::cameras`.
#[macro_export]
macro_rules! camera_models {
    () => {
        /// The camera centre in world space (at the first row's time, `t = 0`).
        pub fn center(cam: &Camera) -> Vec3 {
            -(cam.rotation.transpose() * cam.translation)
        }

        /// When the sensor reads the row of `pixel` out, from 0 (the top edge) to 1 (the bottom):
        /// rows are read top to bottom at a constant rate.
        pub fn shutter_time(cam: &Camera, pixel: Vec2) -> f32 {
            (pixel.y / cam.size.y).clamp(0.0, 1.0)
        }

        /// The world-to-camera rotation at shutter time `t`: `rotation` turned (in camera space) by
        /// the unit quaternion `normalize(1, t * shutter_turn / 2)`, so by `shutter_turn`'s full turn
        /// at `t = 1` and about one fixed axis in between. With `shutter_turn = 2 tan(angle / 2) *
        /// axis` the turn at `t = 1` is `angle` about `axis`; between, it is off a constant angular
        /// speed by under 1% of the turn for turns up to 30°.
        pub fn rotation_at(cam: &Camera, t: f32) -> Mat3 {
            let half = cam.shutter_turn * (0.5 * t);
            let turn = Quat::from_xyzw(half.x, half.y, half.z, 1.0).normalize();
            Mat3::from_quat(turn) * cam.rotation
        }

        /// The world-to-camera translation at shutter time `t`: the centre moves by `t *
        /// shutter_shift` (in world space) and the camera turns as [`rotation_at`] says.
        pub fn translation_at(cam: &Camera, t: f32) -> Vec3 {
            -(cam.rotation_at(t) * (cam.center() + cam.shutter_shift * t))
        }

        /// `focal * (x / z, y / z) + principal`.
        pub mod pinhole {
            use super::*;

            pub const CODE: u32 = 0;
            pub const NAME: &str = "pinhole";
            pub const DISTORTION: bool = false;

            pub fn project_point(cam: &Camera, p: Vec3) -> Vec2 {
                cam.focal * Vec2::new(p.x, p.y) / p.z + cam.principal
            }

            pub fn pixel_ray(cam: &Camera, pixel: Vec2) -> Vec3 {
                ((pixel - cam.principal) / cam.focal)
                    .extend(1.0)
                    .normalize()
            }

            /// In front of the image plane.
            pub fn can_project(_cam: &Camera, p: Vec3) -> bool {
                p.z > 0.0
            }
        }

        /// OpenCV fisheye: θ = atan2(√(x² + y²), z), r = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸) with
        /// (k1, k2, k3, k4) the camera's `distortion`, pixel = `focal * r * (x, y) / √(x² + y²) +
        /// principal`; valid past 180° field of view.
        pub mod kannala_brandt {
            use super::*;

            pub const CODE: u32 = 1;
            pub const NAME: &str = "kannala_brandt";
            pub const DISTORTION: bool = true;

            pub fn project_point(cam: &Camera, p: Vec3) -> Vec2 {
                let rxy = (p.x * p.x + p.y * p.y).sqrt();
                let theta = rxy.atan2(p.z);
                let k = cam.distortion;
                let t2 = theta * theta;
                let r = theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))));
                // r / rxy -> 1 / z on the optical axis.
                let scale = select(rxy > 1e-20, r / rxy, 1.0 / p.z);
                cam.focal * Vec2::new(p.x, p.y) * scale + cam.principal
            }

            /// Inverts r(θ) by eight Newton steps from θ = r (f32 precision for the usual
            /// coefficients).
            pub fn pixel_ray(cam: &Camera, pixel: Vec2) -> Vec3 {
                let m = (pixel - cam.principal) / cam.focal;
                let r = m.length();
                let k = cam.distortion;
                let mut theta = r;
                for _step in 0..8 {
                    let t2 = theta * theta;
                    let value = theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))));
                    let slope = 1.0
                        + t2 * (3.0 * k.x + t2 * (5.0 * k.y + t2 * (7.0 * k.z + t2 * 9.0 * k.w)));
                    // Past the polynomial's fold (a pixel no ray reaches) the steps would run off:
                    // keep theta a direction.
                    theta = (theta - (value - r) / slope).clamp(0.0, std::f32::consts::PI);
                }
                let dir = select(r > 1e-20, m / r, Vec2::ZERO);
                (dir * theta.sin()).extend(theta.cos())
            }

            /// Where r(θ) still rises: below 3 rad (172°; r / √(x² + y²) grows without bound toward
            /// 180°) and before the polynomial's fold, the first angle where its slope
            /// r'(θ) = 1 + 3 k1 θ² + 5 k2 θ⁴ + 7 k3 θ⁶ + 9 k4 θ⁸ reaches zero. Past the fold a point
            /// lands on a pixel that a nearer ray reaches too: a ghost inside the picture. The slope is
            /// checked at the angle itself and at every sixteenth of 3 rad below it (angles that do not
            /// depend on the point, so calls for several points can share them), so a fold is found
            /// wherever the slope stays negative for longer than 0.19 rad (a single fold always).
            pub fn can_project(cam: &Camera, p: Vec3) -> bool {
                let theta = (p.x * p.x + p.y * p.y).sqrt().atan2(p.z);
                let k = cam.distortion;
                let mut rising = theta < 3.0;
                for i in 0..17 {
                    let t = select(i < 16, 0.1875 * (i + 1) as f32, theta);
                    let t2 = t * t;
                    let slope = 1.0
                        + t2 * (3.0 * k.x + t2 * (5.0 * k.y + t2 * (7.0 * k.z + t2 * 9.0 * k.w)));
                    rising = rising && (slope > 0.0 || t > theta);
                }
                rising
            }
        }

        /// Equiangular (BEAP): `focal * (atan2(x, z), atan2(y, z)) + principal`.
        pub mod equiangular {
            use super::*;

            pub const CODE: u32 = 2;
            pub const NAME: &str = "equiangular";
            pub const DISTORTION: bool = false;

            pub fn project_point(cam: &Camera, p: Vec3) -> Vec2 {
                cam.focal * Vec2::new(p.x.atan2(p.z), p.y.atan2(p.z)) + cam.principal
            }

            pub fn pixel_ray(cam: &Camera, pixel: Vec2) -> Vec3 {
                let m = (pixel - cam.principal) / cam.focal;
                Vec3::new(
                    m.x.sin() * m.y.cos(),
                    m.x.cos() * m.y.sin(),
                    m.x.cos() * m.y.cos(),
                )
                .normalize()
            }

            /// In front of the image plane.
            pub fn can_project(_cam: &Camera, p: Vec3) -> bool {
                p.z > 0.0
            }
        }
    };
}
