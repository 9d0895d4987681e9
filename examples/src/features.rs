//! Isotropic Gaussians carrying a 16-channel feature vector instead of a color: the runtime
//! blends any channel count a method declares (feature-map rendering, e.g. for distillation).

use splat_macros::splat_method;

#[splat_method]
pub mod features {
    use splat_runtime::prelude::*;

    pub struct Params {
        pub mean: Vec3,
        pub log_radius: f32,
        pub opacity_logit: f32,
        pub feature: [f32; 16],
    }

    pub struct Shade {
        pub center: Vec2,
        pub inv_sigma2: f32,
        pub opacity: f32,
        pub feature: [f32; 16],
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<f32, Shade> {
        let t = cam.rotation * p.mean + cam.translation;
        let z = t.z.max(0.01);
        let center = Vec2::new(cam.focal.x * t.x / z, cam.focal.y * t.y / z) + cam.principal;
        let sigma = cam.focal.x * p.log_radius.exp() / z;
        let opacity = sigmoid(p.opacity_logit);
        // Where alpha falls below 1/255: opacity * exp(-r^2 / (2 sigma^2)) = 1/255.
        let radius = sigma * (2.0 * (opacity * 255.0).ln().max(0.0)).sqrt();
        Projected {
            visible: t.z > 0.01 && opacity >= 1.0 / 255.0,
            depth: z,
            bbox_min: center - radius,
            bbox_max: center + radius,
            cull: 0.0,
            shade: Shade {
                center,
                inv_sigma2: 1.0 / (sigma * sigma),
                opacity,
                feature: p.feature,
            },
        }
    }

    pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<[f32; 16]> {
        let d = px - s.center;
        let alpha = (s.opacity * (-0.5 * d.dot(d) * s.inv_sigma2).exp()).min(0.99);
        Contribution {
            alpha,
            color: s.feature,
            valid: alpha >= 1.0 / 255.0,
        }
    }
}
