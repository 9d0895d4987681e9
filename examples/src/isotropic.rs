//! Isotropic Gaussians: a complete method in about 60 lines, written as a user would in their
//! own crate (only the public API of splat-macros and splat-runtime). codegen-tests uses it
//! for the snapshot of the generated Rust and to test the `SplatMethod` glue.

use splat_macros::splat_method;

#[splat_method]
pub mod isotropic {
    use splat_runtime::prelude::*;

    pub struct Params {
        pub mean: Vec3,
        pub log_radius: f32,
        pub color: Vec3,
        pub opacity_logit: f32,
    }

    pub struct Cull {
        pub center: Vec2,
        pub radius: f32,
    }

    pub struct Shade {
        pub center: Vec2,
        pub inv_sigma2: f32,
        pub opacity: f32,
        pub color: Vec3,
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<Cull, Shade> {
        let t = cam.rotation * p.mean + cam.translation;
        let z = t.z.max(0.01);
        let center = Vec2::new(cam.focal.x * t.x / z, cam.focal.y * t.y / z) + cam.principal;
        let sigma = cam.focal.x * p.log_radius.exp() / z;
        let opacity = sigmoid(p.opacity_logit);
        // Out to where alpha falls to 1/255: an opaque splat reaches past three sigma.
        let radius = sigma * (2.0 * (255.0 * opacity).ln().max(0.0)).sqrt();
        Projected {
            visible: t.z > 0.01,
            depth: z,
            bbox_min: center - radius,
            bbox_max: center + radius,
            cull: Cull { center, radius },
            shade: Shade {
                center,
                inv_sigma2: 1.0 / (sigma * sigma),
                opacity,
                color: p.color,
            },
        }
    }

    pub fn tile_cull(tile: &Tile, c: &Cull) -> bool {
        let nearest = c.center.clamp(tile.min, tile.max);
        (nearest - c.center).length_squared() <= c.radius * c.radius
    }

    pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<Vec3> {
        let d = px - s.center;
        let alpha = (s.opacity * (-0.5 * d.dot(d) * s.inv_sigma2).exp()).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= 1.0 / 255.0,
        }
    }
}
