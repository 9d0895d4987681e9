//! A new falloff in a few lines: 3D Student's t splats (after Zhu et al. 2025, "3D Student
//! Splatting and Scooping", with a fixed ν): a Gaussian's footprint, from splat's building
//! blocks, with the heavier-tailed alpha `opacity (1 + q / ν)^(-(ν + 2) / 2)` of the 2D
//! Student's t density (a Gaussian as ν grows). Everything else — the adjoints, the CPU and
//! GPU kernels, the checks, training — comes from the framework.

#[splat_macros::splat_method(name = "student")]
pub mod student {
    use splat_runtime::prelude::*;

    /// Degrees of freedom; (ν + 2) / 2 is the falloff's exponent.
    pub const NU: f32 = 3.0;
    pub const ALPHA_MIN: f32 = 1.0 / 255.0;

    pub struct Params {
        pub mean: Vec3,
        pub log_scale: Vec3,
        pub rotation: Vec4,
        pub opacity_logit: f32,
        pub sh: [Vec3; 4],
    }

    pub struct Splat {
        pub center: Vec2,
        pub conic: Vec3,
        pub q_max: f32,
        pub opacity: f32,
        pub color: Vec3,
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<Splat, Splat> {
        let g = blocks::gaussian_footprint(p.mean, p.log_scale, p.rotation, cam, 0.01, 0.3);
        let opacity = sigmoid(p.opacity_logit);
        // Where alpha falls to ALPHA_MIN (0.1% slack for f32 rounding).
        let q_max = 1.001 * NU * ((opacity / ALPHA_MIN).powf(2.0 / (NU + 2.0)) - 1.0);
        let r = blocks::footprint_radius(g.cov, q_max);
        let color = (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5).max(Vec3::ZERO);
        let s = Splat {
            center: g.center,
            conic: g.conic,
            q_max,
            opacity,
            color,
        };
        let visible = g.visible && opacity >= ALPHA_MIN;
        Projected {
            visible,
            depth: g.depth,
            bbox_min: g.center - r,
            bbox_max: g.center + r,
            cull: s,
            shade: s,
        }
    }

    pub fn tile_cull(tile: &Tile, s: &Splat) -> bool {
        blocks::conic_tile_cull(tile, s.center, s.conic, s.q_max)
    }

    pub fn evaluate(px: Vec2, s: &Splat) -> Contribution<Vec3> {
        let q = blocks::conic_distance2(px - s.center, s.conic);
        let alpha = (s.opacity * (1.0 + q / NU).powf(-0.5 * (NU + 2.0))).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= ALPHA_MIN,
        }
    }
}

// 3DGS's learning rates, initialization, density control and PLY fields; density control
// grows from the projected centre's gradient, as 3DGS's.
splat_runtime::train::like_3dgs!(student, screen: center);
