//! Generalized exponential splats (GES, Hamdi et al. 2024): anisotropic 3D primitives whose
//! response is exp(-0.5 q^(β/2)), q = d^T Σ^-1 d, with a learnable shape β > 0. β = 2 is a
//! Gaussian; a larger β flattens the core and sharpens the edge, so one splat can cover a flat
//! region with a crisp boundary. Projected like 3DGS (EWA 2D covariance, tangent clamp, 0.3 px
//! dilation, near plane 0.01, SH degree 1) and evaluated in pixel space on that covariance.
//!
//! β is parameterized as `2 exp(log_shape_half)`: positive for every value, with the Gaussian
//! at 0, and multiplicative steps (β 1 -> 2 and 4 -> 8 are the same distance).

use splat_macros::splat_method;
use splat_runtime::glam::{Vec2, Vec3, Vec4};
use splat_runtime::train::Shape;

#[splat_method]
pub mod generalized {
    use splat_runtime::prelude::*;

    pub const NEAR: f32 = 0.01;
    pub const ALPHA_MIN: f32 = 1.0 / 255.0;
    /// Below this q a pixel counts as the centre (q^(β/2) = 0), keeping ln(q) and its gradient
    /// finite there.
    pub const Q_MIN: f32 = 1e-20;
    /// Box half-size cap in pixels: for a tiny β the falloff radius leaves the f32 range, and
    /// the runtime drops a non-finite box.
    pub const MAX_RADIUS: f32 = 1e6;

    pub struct Params {
        pub mean: Vec3,
        /// Natural log of the three axis scales.
        pub log_scale: Vec3,
        /// Rotation quaternion (w, x, y, z), normalized here.
        pub rotation: Vec4,
        /// Opacity before the sigmoid.
        pub opacity_logit: f32,
        /// β = 2 exp(log_shape_half).
        pub log_shape_half: f32,
        /// Degree-1 SH coefficients per basis function; `sh[0]` is the DC term.
        pub sh: [Vec3; 4],
    }

    pub struct Cull {
        pub center: Vec2,
        pub conic: Vec3,
        /// The largest q whose alpha still reaches ALPHA_MIN.
        pub q_max: f32,
    }

    pub struct Shade {
        pub center: Vec2,
        /// Inverse 2D covariance (xx, xy, yy).
        pub conic: Vec3,
        pub opacity: f32,
        /// β.
        pub shape: f32,
        pub color: Vec3,
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<Cull, Shade> {
        let t = cam.rotation * p.mean + cam.translation;
        let z = t.z.max(NEAR);
        let (f, c, size) = (cam.focal, cam.principal, cam.size);
        let mean = Vec3::new(t.x, t.y, z);
        // EWA: the projection's Jacobian at the mean (any camera model), on the pinhole at the
        // tangent clamp of 3DGS.
        let lim_pos = (size - c) / f + size * 0.15 / f;
        let lim_neg = c / f + size * 0.15 / f;
        let tx = (t.x / z).clamp(-lim_neg.x, lim_pos.x) * z;
        let ty = (t.y / z).clamp(-lim_neg.y, lim_pos.y) * z;
        let at = select(cam.is_pinhole(), Vec3::new(tx, ty, z), mean);
        let (_, d) = jacobian(|q| cam.project_point(q), at);
        let j = Mat3::from_cols(
            Vec3::new(d[0].x, d[1].x, 0.0),
            Vec3::new(d[0].y, d[1].y, 0.0),
            Vec3::new(d[0].z, d[1].z, 0.0),
        );
        let rot =
            Quat::from_xyzw(p.rotation.y, p.rotation.z, p.rotation.w, p.rotation.x).normalize();
        let m = cam.rotation * Mat3::from_quat(rot) * Mat3::from_diagonal(p.log_scale.exp());
        let cov = j * (m * m.transpose()) * j.transpose();
        let (a, b, d) = (cov.x_axis.x + 0.3, cov.y_axis.x, cov.y_axis.y + 0.3);
        let det = a * d - b * b;
        let opacity = sigmoid(p.opacity_logit);
        let shape = 2.0 * p.log_shape_half.exp();
        // alpha = ALPHA_MIN where q^(β/2) = 2 ln(opacity / ALPHA_MIN); 0.1% slack absorbs the
        // f32 rounding of ln / exp, so the box and the tile cull never drop a kept pixel.
        let power_max = (2.0 * (opacity / ALPHA_MIN).ln()).max(1e-30);
        let q_max = 1.001 * (2.0 / shape * power_max.ln()).exp();
        // Farthest along the major axis (eigenvalue `lambda`, rounded up by the 0.1 floor).
        let mid = 0.5 * (a + d);
        let lambda = mid + (mid * mid - det).max(0.1).sqrt();
        let radius = (q_max * lambda).sqrt().min(MAX_RADIUS).ceil();
        let center = cam.project_point(mean);
        let conic = Vec3::new(d, -b, a) / det;
        Projected {
            visible: t.z > NEAR && det > 0.0 && opacity >= ALPHA_MIN,
            depth: t.z,
            bbox_min: center - radius,
            bbox_max: center + radius,
            cull: Cull {
                center,
                conic,
                q_max,
            },
            shade: Shade {
                center,
                conic,
                opacity,
                shape,
                color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5).max(Vec3::ZERO),
            },
        }
    }

    /// StopThePop as in 3DGS: the smallest q over the tile's pixel centres is at the centre or
    /// on an edge facing it. Alpha falls monotonically with q, so q <= q_max keeps exactly the
    /// tiles that hold a pixel the alpha threshold keeps (plus the slack).
    pub fn tile_cull(tile: &Tile, g: &Cull) -> bool {
        let (mu, k) = (g.center, g.conic);
        let dx = mu.x - mu.x.clamp(tile.min.x, tile.max.x);
        let dy1 = mu.y - (mu.y + k.y * dx / k.z).clamp(tile.min.y, tile.max.y);
        let dy = mu.y - mu.y.clamp(tile.min.y, tile.max.y);
        let dx2 = mu.x - (mu.x + k.y * dy / k.x).clamp(tile.min.x, tile.max.x);
        let p1 = k.x * dx * dx + 2.0 * k.y * dx * dy1 + k.z * dy1 * dy1;
        let p2 = k.x * dx2 * dx2 + 2.0 * k.y * dx2 * dy + k.z * dy * dy;
        p1.min(p2) <= g.q_max
    }

    pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<Vec3> {
        let d = px - s.center;
        let q = s.conic.x * d.x * d.x + 2.0 * s.conic.y * d.x * d.y + s.conic.z * d.y * d.y;
        // q^(β/2) = exp(β/2 ln q); `select` differentiates ln(q) only where q > Q_MIN.
        let power = select(q > Q_MIN, (0.5 * s.shape * q.ln()).exp(), 0.0);
        let alpha = (s.opacity * (-0.5 * power).exp()).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= ALPHA_MIN,
        }
    }
}

/// A PLY scene's Gaussians as splats of shape 2 with their degree-1 colors (how `splat render
/// --scene` reads a scene for this method).
impl splat_runtime::io::ply::FromStored for generalized::Params {
    fn from_stored(g: &splat_runtime::io::ply::StoredGaussian) -> Self {
        generalized::Params {
            mean: g.mean,
            log_scale: g.log_scale,
            rotation: g.rotation,
            opacity_logit: g.opacity_logit,
            log_shape_half: 0.0,
            sh: [g.sh[0], g.sh[1], g.sh[2], g.sh[3]],
        }
    }
}

/// How GES trains (`splat fit`): 3DGS's rates, the shape at 1e-3, the degree-1 band from step
/// 1,000; a primitive starts as a Gaussian (β = 2).
impl splat_runtime::train::Trainable for generalized::Method {
    fn learning_rates(extent: f32) -> Vec<splat_runtime::train::Rate> {
        use splat_runtime::train::Rate;
        let fixed = |lr: f32, n: usize| std::iter::repeat_n(Rate::fixed(lr), n);
        let position = Rate {
            first: 1.6e-4 * extent,
            last: 1.6e-6 * extent,
            from_step: 0,
        };
        let band1 = Rate {
            from_step: 1000,
            ..Rate::fixed(2.5e-3 / 20.0)
        };
        let rates = std::iter::repeat_n(position, 3).chain(fixed(5e-3, 3));
        let rates = rates.chain(fixed(1e-3, 4)).chain(fixed(5e-2, 1));
        let rates = rates.chain(fixed(1e-3, 1)).chain(fixed(2.5e-3, 3));
        rates.chain(std::iter::repeat_n(band1, 9)).collect()
    }

    fn from_point(point: Vec3, color: Vec3, scale: f32) -> generalized::Params {
        let c0 = splat_runtime::prelude::spherical_harmonics([Vec3::ONE], Vec3::Z).x;
        generalized::Params {
            mean: point,
            log_scale: Vec3::splat(scale.max(1e-7).ln()),
            rotation: Vec4::new(1.0, 0.0, 0.0, 0.0),
            opacity_logit: (0.1f32 / 0.9).ln(),
            log_shape_half: 0.0,
            sh: [(color - 0.5) / c0, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO],
        }
    }

    fn shape(p: &generalized::Params) -> Shape {
        Shape::from_gaussian(p.mean, p.log_scale, p.rotation, p.opacity_logit)
    }

    fn with_shape(p: &generalized::Params, s: &Shape) -> generalized::Params {
        let (mean, log_scale, rotation, opacity_logit) = s.to_gaussian();
        generalized::Params {
            mean,
            log_scale,
            rotation,
            opacity_logit,
            ..*p
        }
    }

    fn position_gradient(g: &generalized::Params) -> Vec3 {
        g.mean
    }

    fn screen_gradient(g: &generalized::Shade) -> Option<Vec2> {
        Some(g.center)
    }
}
