// 3D Gaussian Splatting (Kerbl et al. 2023) with EWA splatting and the StopThePop tile cull
// (XPR, Rhyner et al. 2026, Listing 1 and §A.1.1), in the conventions of gsplat's "classic"
// mode: OpenCV camera, pixel centres at +0.5, 0.3 px dilation, tangent clamp,
// near plane 0.01, pairs below 1/255 skipped, SH + 0.5 clamped at 0; but alpha <= 0.99, as
// the original 3DGS rasterizer (gsplat: 0.999; the one rule where trained scenes differ).
//
// The SH degree is a compile-time property of the method: `gaussians_3d!` instantiates one
// method per degree (`gs3d_sh0` .. `gs3d_sh2`, and `gs3d` for degree 3), so a scene without
// view-dependent color carries and evaluates no higher-order coefficients.
//
// So is anti-aliasing (Mip-Splatting's 2D filter, gsplat's `antialiased` mode): the 0.3 px
// dilation that every 3DGS footprint gets also scales the opacity by
// sqrt(det(cov) / det(cov + 0.3 I)), so a Gaussian smaller than a pixel fades instead of
// growing. `gs3d_aa` has it; in the others the constant `ANTIALIASED` is false and the
// compensation folds away.

/// One 3DGS method with `$n` SH coefficients per channel ((degree + 1)^2), with or without
/// anti-aliasing.
macro_rules! gaussians_3d {
    ($name:ident, $called:literal, sh_coefficients = $n:literal) => {
        gaussians_3d!($name, $called, sh_coefficients = $n, antialiased = false);
    };
    ($name:ident, $called:literal, sh_coefficients = $n:literal, antialiased = $aa:literal) => {
        #[splat_macros::splat_method(name = $called)]
        pub mod $name {
            use splat_runtime::prelude::*;

            pub const NEAR: f32 = 0.01;
            pub const ALPHA_MIN: f32 = 1.0 / 255.0;
            /// The screen-space dilation, px^2 on the covariance's diagonal.
            pub const DILATION: f32 = 0.3;
            /// Scale the opacity by the dilation's change of the footprint's area.
            pub const ANTIALIASED: bool = $aa;

            pub struct Params {
                pub mean: Vec3,
                /// Natural log of the three axis scales.
                pub log_scale: Vec3,
                /// Rotation quaternion (w, x, y, z), normalized here.
                pub rotation: Vec4,
                /// Opacity before the sigmoid.
                pub opacity_logit: f32,
                /// SH coefficients per basis function; `sh[0]` is the DC term.
                pub sh: [Vec3; $n],
            }

            pub struct Cull {
                pub center: Vec2,
                pub conic: Vec3,
                /// ln(opacity / ALPHA_MIN): the largest exponent that still reaches ALPHA_MIN.
                pub max_power: f32,
            }

            pub struct Shade {
                pub center: Vec2,
                /// Inverse 2D covariance (xx, xy, yy).
                pub conic: Vec3,
                pub opacity: f32,
                pub color: Vec3,
            }

            pub fn project(p: &Params, cam: &Camera) -> Projected<Cull, Shade> {
                let t = cam.rotation * p.mean + cam.translation;
                let z = t.z.max(NEAR);
                let (f, c, size) = (cam.focal, cam.principal, cam.size);
                let mean = Vec3::new(t.x, t.y, z);
                // EWA: the projection's Jacobian at the mean, derived by the compiler for every
                // camera model; on the pinhole at the tangent clamp of 3DGS / gsplat (a Gaussian
                // far off the image is not stretched without bound).
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
                let q = Quat::from_xyzw(p.rotation.y, p.rotation.z, p.rotation.w, p.rotation.x)
                    .normalize();
                let m = cam.rotation * Mat3::from_quat(q) * Mat3::from_diagonal(p.log_scale.exp());
                let cov = j * (m * m.transpose()) * j.transpose();
                let (a0, b, d0) = (cov.x_axis.x, cov.y_axis.x, cov.y_axis.y);
                let (a, d) = (a0 + DILATION, d0 + DILATION);
                let det = a * d - b * b;
                let conic = Vec3::new(d, -b, a) / det;
                let compensation = if ANTIALIASED {
                    ((a0 * d0 - b * b) / det).max(0.0).sqrt()
                } else {
                    1.0
                };
                // Opacity-aware extent: every pixel where alpha >= ALPHA_MIN lies within `radius` of
                // the centre (0.5 d^T conic d <= max_power along the major axis), so the box culls
                // nothing the threshold would keep.
                let opacity = sigmoid(p.opacity_logit) * compensation;
                let max_power = (opacity / ALPHA_MIN).ln();
                let mid = 0.5 * (a + d);
                let lambda = mid + (mid * mid - det).max(0.1).sqrt();
                let radius = (2.0 * max_power.max(0.0) * lambda).sqrt().ceil();
                let center = cam.project_point(mean);
                Projected {
                    visible: t.z > NEAR && cam.can_project(t) && det > 0.0 && opacity >= ALPHA_MIN,
                    depth: t.z,
                    bbox_min: center - radius,
                    bbox_max: center + radius,
                    cull: Cull {
                        center,
                        conic,
                        max_power,
                    },
                    shade: Shade {
                        center,
                        conic,
                        opacity,
                        color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5)
                            .max(Vec3::ZERO),
                    },
                }
            }

            /// StopThePop: keep the tile iff the Gaussian's largest alpha over the tile's pixel centres
            /// reaches ALPHA_MIN. That maximum is at the centre, or on an edge facing it, where the
            /// 1D minimum of the quadratic form along the edge is clamped to the edge.
            pub fn tile_cull(tile: &Tile, g: &Cull) -> bool {
                let (mu, k) = (g.center, g.conic);
                let dx = mu.x - mu.x.clamp(tile.min.x, tile.max.x);
                let dy1 = mu.y - (mu.y + k.y * dx / k.z).clamp(tile.min.y, tile.max.y);
                let dy = mu.y - mu.y.clamp(tile.min.y, tile.max.y);
                let dx2 = mu.x - (mu.x + k.y * dy / k.x).clamp(tile.min.x, tile.max.x);
                let p1 = k.x * dx * dx + 2.0 * k.y * dx * dy1 + k.z * dy1 * dy1;
                let p2 = k.x * dx2 * dx2 + 2.0 * k.y * dx2 * dy + k.z * dy * dy;
                0.5 * p1.min(p2) <= g.max_power
            }

            pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<Vec3> {
                let d = px - s.center;
                let power =
                    0.5 * (s.conic.x * d.x * d.x + s.conic.z * d.y * d.y) + s.conic.y * d.x * d.y;
                let alpha = (s.opacity * (-power).exp()).min(0.99);
                Contribution {
                    alpha,
                    color: s.color,
                    valid: power >= 0.0 && alpha >= ALPHA_MIN,
                }
            }
        }

        /// 3DGS's learning rates (positions scaled by the scene's extent and decayed 100x, the
        /// higher SH bands 20x slower than the DC term, band b trained from step 1,000 b) and
        /// its initialization: an isotropic Gaussian of opacity 0.1 with the point's color as
        /// the DC term.
        impl splat_runtime::train::Trainable for $name::Method {
            fn learning_rates(extent: f32) -> Vec<splat_runtime::train::Rate> {
                use splat_runtime::train::Rate;
                let fixed = |lr: f32, n: usize| std::iter::repeat_n(Rate::fixed(lr), n);
                let position = Rate {
                    first: 1.6e-4 * extent,
                    last: 1.6e-6 * extent,
                    from_step: 0,
                };
                // Coefficient i (after the DC term) belongs to band floor(sqrt(i)).
                let bands = (1..$n).flat_map(|i: usize| {
                    let band = (i as f32).sqrt() as usize;
                    std::iter::repeat_n(
                        Rate {
                            from_step: 1000 * band,
                            ..Rate::fixed(2.5e-3 / 20.0)
                        },
                        3,
                    )
                });
                std::iter::repeat_n(position, 3)
                    .chain(fixed(5e-3, 3))
                    .chain(fixed(1e-3, 4))
                    .chain(fixed(5e-2, 1))
                    .chain(fixed(2.5e-3, 3))
                    .chain(bands)
                    .collect()
            }

            fn from_point(
                point: splat_runtime::glam::Vec3,
                color: splat_runtime::glam::Vec3,
                scale: f32,
            ) -> $name::Params {
                use splat_runtime::glam::{Vec3, Vec4};
                // The DC basis function's value (constant over directions).
                let c0 = splat_runtime::prelude::spherical_harmonics([Vec3::ONE], Vec3::Z).x;
                let mut sh = [Vec3::ZERO; $n];
                sh[0] = (color - 0.5) / c0;
                $name::Params {
                    mean: point,
                    log_scale: Vec3::splat(scale.max(1e-7).ln()),
                    rotation: Vec4::new(1.0, 0.0, 0.0, 0.0),
                    opacity_logit: (0.1f32 / 0.9).ln(),
                    sh,
                }
            }

            fn shape(p: &$name::Params) -> splat_runtime::train::Shape {
                splat_runtime::train::Shape::from_gaussian(
                    p.mean,
                    p.log_scale,
                    p.rotation,
                    p.opacity_logit,
                )
            }

            fn with_shape(p: &$name::Params, s: &splat_runtime::train::Shape) -> $name::Params {
                let (mean, log_scale, rotation, opacity_logit) = s.to_gaussian();
                $name::Params {
                    mean,
                    log_scale,
                    rotation,
                    opacity_logit,
                    ..*p
                }
            }

            fn position_gradient(g: &$name::Params) -> splat_runtime::glam::Vec3 {
                g.mean
            }

            fn screen_gradient(g: &$name::Shade) -> Option<splat_runtime::glam::Vec2> {
                Some(g.center)
            }
        }
    };
}

gaussians_3d!(gs3d, "3dgs", sh_coefficients = 16);
gaussians_3d!(gs3d_sh0, "3dgs", sh_coefficients = 1);
gaussians_3d!(gs3d_sh1, "3dgs", sh_coefficients = 4);
gaussians_3d!(gs3d_sh2, "3dgs", sh_coefficients = 9);
gaussians_3d!(gs3d_aa, "3dgs-aa", sh_coefficients = 16, antialiased = true);
