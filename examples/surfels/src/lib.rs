//! 2D Gaussian surfels (2DGS, Huang et al. 2024) for a pinhole camera: flat elliptic disks,
//! each evaluated where the pixel's ray meets its plane (the ray-splat intersection), plus the
//! paper's screen-space low-pass filter, so that a disk seen edge-on still covers a pixel.
//!
//! Written as a user would, in a crate of their own, with only splat's public API: the method
//! module, how it reads and writes PLY scenes, how it trains, and its command line.

use splat_macros::splat_method;
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::io::ply::{FromStored, StoredGaussian, ToStored};
use splat_runtime::train::{Rate, Shape, Trainable};

#[splat_method]
pub mod surfel {
    use splat_runtime::prelude::*;

    pub const NEAR: f32 = 0.01;
    pub const ALPHA_MIN: f32 = 1.0 / 255.0;
    /// The low-pass filter's variance in px² (the paper's σ = √2/2 px).
    pub const FILTER_VAR: f32 = 0.5;
    /// Past this squared disk radius at a pixel, the ray runs (nearly) parallel to the disk and
    /// only the filter can reach the pixel.
    pub const RHO_FAR: f32 = 1e6;

    pub struct Params {
        pub mean: Vec3,
        /// ln of the two tangent scales.
        pub log_scale: Vec2,
        /// Quaternion (w, x, y, z), normalized here; its third axis is the disk's normal.
        pub rotation: Vec4,
        pub opacity_logit: f32,
        /// Degree-1 SH coefficients per basis function; `sh[0]` is the DC term.
        pub sh: [Vec3; 4],
    }

    pub struct Shade {
        /// The disk-to-pixel homography: disk point (u, v) lands at pixel (x, y) = (X, Y) / W
        /// with (X, Y, W) = u a + v b + c.
        pub a: Vec3,
        pub b: Vec3,
        pub c: Vec3,
        /// The projected centre, where the filter sits.
        pub center: Vec2,
        pub opacity: f32,
        pub color: Vec3,
    }

    /// A camera-space point or direction in homogeneous pixel coordinates.
    fn homogeneous(v: Vec3, cam: &Camera) -> Vec3 {
        Vec3::new(
            cam.focal.x * v.x + cam.principal.x * v.z,
            cam.focal.y * v.y + cam.principal.y * v.z,
            v.z,
        )
    }

    fn pixel(h: Vec3) -> Vec2 {
        Vec2::new(h.x, h.y) / h.z
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<f32, Shade> {
        let axes = cam.rotation * blocks::rotation_matrix(p.rotation);
        let scale = p.log_scale.exp();
        let a = homogeneous(axes.x_axis * scale.x, cam);
        let b = homogeneous(axes.y_axis * scale.y, cam);
        let c = homogeneous(cam.rotation * p.mean + cam.translation, cam);
        let opacity = sigmoid(p.opacity_logit);
        // alpha falls to ALPHA_MIN at squared disk radius 2 ln(opacity / ALPHA_MIN), and through
        // the filter at FILTER_VAR times that in px² (0.2% slack for f32 rounding).
        let rho_max = 2.004 * (opacity / ALPHA_MIN).ln().max(0.0);
        let r = rho_max.sqrt();
        // The disk's reach is inside the square |u|, |v| <= r, whose image (all four corners in
        // front) is inside its corners' box.
        let corners = [
            c - (a + b) * r,
            c + (a - b) * r,
            c + (b - a) * r,
            c + (a + b) * r,
        ];
        let center = pixel(c);
        let filter_r = (FILTER_VAR * rho_max).sqrt();
        let (p0, p1, p2, p3) = (
            pixel(corners[0]),
            pixel(corners[1]),
            pixel(corners[2]),
            pixel(corners[3]),
        );
        let lo = p0.min(p1).min(p2.min(p3)).min(center - filter_r);
        let hi = p0.max(p1).max(p2.max(p3)).max(center + filter_r);
        let in_front = corners[0]
            .z
            .min(corners[1].z)
            .min(corners[2].z.min(corners[3].z))
            > NEAR;
        Projected {
            visible: in_front && opacity >= ALPHA_MIN,
            depth: c.z,
            bbox_min: lo,
            bbox_max: hi,
            cull: 0.0,
            shade: Shade {
                a,
                b,
                c,
                center,
                opacity,
                color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5).max(Vec3::ZERO),
            },
        }
    }

    pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<Vec3> {
        // The pixel's ray as two planes, x W - X = 0 and y W - Y = 0, in disk coordinates;
        // they cross at (u, v) = (k.x, k.y) / k.z.
        let hx = Vec3::new(
            px.x * s.a.z - s.a.x,
            px.x * s.b.z - s.b.x,
            px.x * s.c.z - s.c.x,
        );
        let hy = Vec3::new(
            px.y * s.a.z - s.a.y,
            px.y * s.b.z - s.b.y,
            px.y * s.c.z - s.c.y,
        );
        let k = hx.cross(hy);
        let (q, kz2) = (k.x * k.x + k.y * k.y, k.z * k.z);
        let rho_disk = select(q < RHO_FAR * kz2, q / kz2, RHO_FAR);
        let d = px - s.center;
        let rho_filter = d.dot(d) / FILTER_VAR;
        let alpha = (s.opacity * (-0.5 * rho_disk.min(rho_filter)).exp()).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= ALPHA_MIN,
        }
    }
}

/// The command-line entry for this method (`splat_cli::run(&[surfels::method()])`).
pub fn method() -> splat_cli::Method {
    splat_cli::Method::new(
        "2dgs",
        "2D Gaussian surfels: flat disks hit by the pixel's ray",
        splat_cli::Instance::trainable::<surfel::Method>(),
    )
}

/// A surfel stored as a Gaussian is flat: its third scale is this fraction of the smaller one.
const FLAT: f32 = 1e-3;

/// A PLY Gaussian as the disk of its two largest axes (the smallest becomes the normal).
impl FromStored for surfel::Params {
    fn from_stored(g: &StoredGaussian) -> Self {
        let r = g.rotation;
        let axes = Mat3::from_quat(Quat::from_xyzw(r.y, r.z, r.w, r.x).normalize());
        let s = g.log_scale;
        // A cyclic shift that moves the smallest axis last keeps the frame right-handed; on a
        // tie the third axis stays the normal.
        let (axes, s) = if s.z <= s.x && s.z <= s.y {
            (axes, s)
        } else if s.x <= s.y {
            let m = Mat3::from_cols(axes.y_axis, axes.z_axis, axes.x_axis);
            (m, Vec3::new(s.y, s.z, s.x))
        } else {
            let m = Mat3::from_cols(axes.z_axis, axes.x_axis, axes.y_axis);
            (m, Vec3::new(s.z, s.x, s.y))
        };
        let q = Quat::from_mat3(&axes);
        surfel::Params {
            mean: g.mean,
            log_scale: Vec2::new(s.x, s.y),
            rotation: Vec4::new(q.w, q.x, q.y, q.z),
            opacity_logit: g.opacity_logit,
            sh: [g.sh[0], g.sh[1], g.sh[2], g.sh[3]],
        }
    }
}

/// Written as a flat Gaussian, which other viewers draw as the same disk.
impl ToStored for surfel::Params {
    fn to_stored(&self) -> StoredGaussian {
        let flat = self.log_scale.min_element() + FLAT.ln();
        let mut sh = [Vec3::ZERO; 16];
        sh[..4].copy_from_slice(&self.sh);
        StoredGaussian {
            mean: self.mean,
            log_scale: self.log_scale.extend(flat),
            rotation: self.rotation,
            opacity_logit: self.opacity_logit,
            sh,
        }
    }
}

/// How surfels train (`fit`): 3DGS's rates (by field name: two log scales); densification sees
/// each disk as its flat Gaussian.
impl Trainable for surfel::Method {
    fn learning_rates(extent: f32) -> Vec<Rate> {
        splat_runtime::train::like_3dgs::gaussian_rates::<surfel::Method>(extent, &[])
            .expect("a surfel's fields are a Gaussian's")
    }

    /// A disk of radius `scale`, opacity 0.1, facing a direction hashed from the point (a
    /// random start, as the paper's, without a generator to thread through).
    fn from_point(point: Vec3, color: Vec3, scale: f32) -> surfel::Params {
        let hash =
            |k: f32| (point.dot(Vec3::new(12.9898, 78.233, 37.719) * k).sin() * 43758.547).fract();
        let q = Quat::from_xyzw(hash(1.0), hash(2.0), hash(3.0), hash(4.0) + 0.1).normalize();
        let c0 = splat_runtime::prelude::spherical_harmonics([Vec3::ONE], Vec3::Z).x;
        surfel::Params {
            mean: point,
            log_scale: Vec2::splat(scale.max(1e-7).ln()),
            rotation: Vec4::new(q.w, q.x, q.y, q.z),
            opacity_logit: (0.1f32 / 0.9).ln(),
            sh: [(color - 0.5) / c0, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO],
        }
    }

    fn shape(p: &surfel::Params) -> Shape {
        let stored = p.to_stored();
        Shape::from_gaussian(p.mean, stored.log_scale, p.rotation, p.opacity_logit)
    }

    fn with_shape(p: &surfel::Params, s: &Shape) -> surfel::Params {
        let (mean, log_scale, rotation, opacity_logit) = s.to_gaussian();
        surfel::Params {
            mean,
            log_scale: log_scale.truncate(),
            rotation,
            opacity_logit,
            ..*p
        }
    }

    fn position_gradient(g: &surfel::Params) -> Vec3 {
        g.mean
    }
}
