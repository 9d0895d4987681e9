//! {{name}}: a splatting method made by `splat new`. It starts as a 3D Gaussian (3DGS's
//! projection from splat's building blocks) whose falloff is yours to change: edit `falloff`
//! and `q_max` below, and `cargo test` holds the result to every check splat has (the f64
//! reference, finite differences, the GPU); `cargo run --release -- fit` trains it.

#[splat_macros::splat_method(name = "{{name}}")]
pub mod {{module}} {
    use splat_runtime::prelude::*;

    /// Pairs fainter than this are skipped (3DGS's 1/255).
    pub const ALPHA_MIN: f32 = 1.0 / 255.0;

    /// A Gaussian's fields, as a PLY scene stores them.
    pub struct Params {
        pub mean: Vec3,
        pub log_scale: Vec3,
        /// (w, x, y, z), normalized where used.
        pub rotation: Vec4,
        pub opacity_logit: f32,
        /// Degree-1 spherical harmonics per channel; `sh[0]` is the DC term.
        pub sh: [Vec3; 4],
    }

    /// What the tile cull and the blend read of a projected primitive.
    pub struct Splat {
        pub center: Vec2,
        pub conic: Vec3,
        pub q_max: f32,
        pub opacity: f32,
        pub color: Vec3,
    }

    /// Alpha per unit opacity at squared Mahalanobis distance `q` from the centre: the shape of
    /// the primitive. A Gaussian here; try `(1.0 + q / 3.0).powf(-2.5)` (Student's t).
    fn falloff(q: f32) -> f32 {
        (-0.5 * q).exp()
    }

    /// The `q` where `opacity * falloff(q)` falls to `ALPHA_MIN` (past it, nothing is drawn):
    /// the inverse of `falloff`, a little beyond for f32 rounding.
    fn q_max(opacity: f32) -> f32 {
        1.001 * 2.0 * (opacity / ALPHA_MIN).ln().max(0.0)
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<Splat, Splat> {
        let g = blocks::gaussian_footprint(p.mean, p.log_scale, p.rotation, cam, 0.01, 0.3);
        let opacity = sigmoid(p.opacity_logit);
        let q_max = q_max(opacity);
        let r = blocks::footprint_radius(g.cov, q_max);
        let color = (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5).max(Vec3::ZERO);
        let s = Splat {
            center: g.center,
            conic: g.conic,
            q_max,
            opacity,
            color,
        };
        Projected {
            visible: g.visible && opacity >= ALPHA_MIN,
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
        let alpha = (s.opacity * falloff(q)).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= ALPHA_MIN,
        }
    }
}

// Trains as 3DGS does (its learning rates, start and density control, grown from the
// projected centre's gradient) and reads and writes PLY scenes.
splat_runtime::train::like_3dgs!({{module}}, screen: center);

/// This crate's method on the `splat` command line (`src/main.rs`).
pub fn method() -> splat_cli::Method {
    splat_cli::Method::new(
        "{{name}}",
        "a splatting method made by `splat new`",
        splat_cli::Instance::trainable::<{{module}}::Method>(),
    )
}
