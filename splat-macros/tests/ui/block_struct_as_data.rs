use splat_macros::splat_method;

#[splat_method]
mod m {
    use splat_runtime::prelude::*;

    pub struct Params {
        pub mean: Vec3,
        pub log_scale: Vec3,
        pub rotation: Vec4,
    }

    pub struct Shade {
        pub footprint: blocks::Footprint,
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<f32, Shade> {
        let g = blocks::gaussian_footprint(p.mean, p.log_scale, p.rotation, cam, 0.01, 0.3);
        Projected {
            visible: g.visible,
            depth: g.depth,
            bbox_min: g.center - 3.0,
            bbox_max: g.center + 3.0,
            cull: 0.0,
            shade: Shade { footprint: g },
        }
    }

    pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<f32> {
        let q = blocks::conic_distance2(px - s.footprint.center, s.footprint.conic);
        Contribution { alpha: (-0.5 * q).exp() * 0.5, color: 1.0, valid: true }
    }
}

fn main() {}
