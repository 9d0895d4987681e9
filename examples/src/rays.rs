//! Isotropic Gaussians evaluated along camera rays: `pixel_info` casts a world-space ray per
//! pixel and `evaluate` takes the Gaussian's maximum response along it (the 3DGUT-style
//! evaluation, for spheres). Exercises the per-pixel stage of the interface.

use splat_macros::splat_method;

#[splat_method]
pub mod rays {
    use splat_runtime::prelude::*;

    pub struct Params {
        pub mean: Vec3,
        pub log_radius: f32,
        pub color: Vec3,
        pub opacity_logit: f32,
    }

    pub struct Ray {
        pub origin: Vec3,
        /// Unit direction.
        pub dir: Vec3,
    }

    pub struct Shade {
        pub center: Vec3,
        pub inv_sigma2: f32,
        pub opacity: f32,
        pub color: Vec3,
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<f32, Shade> {
        let t = cam.rotation * p.mean + cam.translation;
        let z = t.z.max(0.01);
        let center = Vec2::new(cam.focal.x * t.x / z, cam.focal.y * t.y / z) + cam.principal;
        let sigma = p.log_radius.exp();
        let opacity = sigmoid(p.opacity_logit);
        // Rays farther than `reach` from the centre stay below 1/255; its projection, with a
        // margin for perspective, bounds the footprint (sphere well in front of the camera).
        let reach = sigma * (2.0 * (opacity * 255.0).ln().max(0.0)).sqrt();
        let radius = 1.5 * cam.focal.max_element() * reach / z + 1.0;
        Projected {
            visible: t.z > reach + 0.01 && opacity >= 1.0 / 255.0,
            depth: t.z,
            bbox_min: center - radius,
            bbox_max: center + radius,
            cull: 0.0,
            shade: Shade {
                center: p.mean,
                inv_sigma2: 1.0 / (sigma * sigma),
                opacity,
                color: p.color,
            },
        }
    }

    pub fn pixel_info(pixel: Vec2, cam: &Camera) -> Ray {
        let d = Vec3::new(
            (pixel.x - cam.principal.x) / cam.focal.x,
            (pixel.y - cam.principal.y) / cam.focal.y,
            1.0,
        );
        let to_world = cam.rotation.transpose();
        Ray {
            origin: -(to_world * cam.translation),
            dir: (to_world * d).normalize(),
        }
    }

    pub fn evaluate(ray: Ray, s: &Shade) -> Contribution<Vec3> {
        let v = s.center - ray.origin;
        let c = v.cross(ray.dir);
        let alpha = (s.opacity * (-0.5 * c.dot(c) * s.inv_sigma2).exp()).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= 1.0 / 255.0 && v.dot(ray.dir) > 0.0,
        }
    }
}
