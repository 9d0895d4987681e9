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
                let g = blocks::gaussian_footprint(
                    p.mean,
                    p.log_scale,
                    p.rotation,
                    cam,
                    NEAR,
                    DILATION,
                );
                let compensation = if ANTIALIASED { g.compensation } else { 1.0 };
                // Opacity-aware extent: every pixel where alpha >= ALPHA_MIN lies within `radius`
                // of the centre (0.5 d^T conic d <= max_power along the major axis), so the box
                // culls nothing the threshold would keep.
                let opacity = sigmoid(p.opacity_logit) * compensation;
                let max_power = (opacity / ALPHA_MIN).ln();
                let radius = blocks::footprint_radius(g.cov, 2.0 * max_power.max(0.0));
                Projected {
                    visible: g.visible && opacity >= ALPHA_MIN,
                    depth: g.depth,
                    bbox_min: g.center - radius,
                    bbox_max: g.center + radius,
                    cull: Cull {
                        center: g.center,
                        conic: g.conic,
                        max_power,
                    },
                    shade: Shade {
                        center: g.center,
                        conic: g.conic,
                        opacity,
                        color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5)
                            .max(Vec3::ZERO),
                    },
                }
            }

            /// StopThePop: keep the tile iff the Gaussian's largest alpha over the tile's pixel
            /// centres reaches ALPHA_MIN.
            pub fn tile_cull(tile: &Tile, g: &Cull) -> bool {
                blocks::conic_tile_cull(tile, g.center, g.conic, 2.0 * g.max_power)
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

        // 3DGS's learning rates, initialization and density control (grown from the projected
        // centre's gradient), and PLY scenes: `splat_runtime::train::like_3dgs`.
        splat_runtime::train::like_3dgs!($name, screen: center);
    };
}

gaussians_3d!(gs3d, "3dgs", sh_coefficients = 16);
gaussians_3d!(gs3d_sh0, "3dgs", sh_coefficients = 1);
gaussians_3d!(gs3d_sh1, "3dgs", sh_coefficients = 4);
gaussians_3d!(gs3d_sh2, "3dgs", sh_coefficients = 9);
gaussians_3d!(gs3d_aa, "3dgs-aa", sh_coefficients = 16, antialiased = true);
