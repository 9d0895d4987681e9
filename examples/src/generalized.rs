//! Generalized exponential splats (GES, Hamdi et al. 2024): anisotropic 3D primitives whose
//! response is exp(-0.5 q^(β/2)), q = d^T Σ^-1 d, with a learnable shape β > 0. β = 2 is a
//! Gaussian; a larger β flattens the core and sharpens the edge, so one splat can cover a flat
//! region with a crisp boundary. Projected like 3DGS (EWA 2D covariance, tangent clamp, 0.3 px
//! dilation, near plane 0.01, SH degree 1) and evaluated in pixel space on that covariance.
//!
//! β is parameterized as `2 exp(log_shape_half)`: positive for every value, with the Gaussian
//! at 0, and multiplicative steps (β 1 -> 2 and 4 -> 8 are the same distance).

use splat_macros::splat_method;

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
        let g = blocks::gaussian_footprint(p.mean, p.log_scale, p.rotation, cam, NEAR, 0.3);
        let opacity = sigmoid(p.opacity_logit);
        let shape = 2.0 * p.log_shape_half.exp();
        // alpha = ALPHA_MIN where q^(β/2) = 2 ln(opacity / ALPHA_MIN); 0.1% slack absorbs the
        // f32 rounding of ln / exp, so the box and the tile cull never drop a kept pixel.
        let power_max = (2.0 * (opacity / ALPHA_MIN).ln()).max(1e-30);
        let q_max = 1.001 * (2.0 / shape * power_max.ln()).exp();
        let radius = blocks::footprint_radius(g.cov, q_max).min(MAX_RADIUS);
        Projected {
            visible: g.visible && opacity >= ALPHA_MIN,
            depth: g.depth,
            bbox_min: g.center - radius,
            bbox_max: g.center + radius,
            cull: Cull {
                center: g.center,
                conic: g.conic,
                q_max,
            },
            shade: Shade {
                center: g.center,
                conic: g.conic,
                opacity,
                shape,
                color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5).max(Vec3::ZERO),
            },
        }
    }

    pub fn tile_cull(tile: &Tile, g: &Cull) -> bool {
        blocks::conic_tile_cull(tile, g.center, g.conic, g.q_max)
    }

    pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<Vec3> {
        let q = blocks::conic_distance2(px - s.center, s.conic);
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

// How GES reads a PLY scene (its Gaussians as splats of shape 2) and trains (`splat fit`):
// 3DGS's rates, initialization and density control, the shape at 1e-3 from β = 2.
splat_runtime::train::like_3dgs!(
    generalized,
    own: { log_shape_half: splat_runtime::train::Rate::fixed(1e-3) => 0.0 },
    screen: center,
);
