use splat_macros::splat_method;

#[splat_method]
mod m {
    use splat_runtime::prelude::*;

    pub struct P {
        pub x: Vec3,
    }

    pub fn project(p: &P, cam: &Camera) -> Projected<f32, f32> {
        Projected {
            visible: true,
            depth: 1.0,
            bbox_min: Vec2::ZERO,
            bbox_max: Vec2::ONE,
            cull: 0.0,
            shade: p.x.x,
        }
    }

    pub fn shade(px: Vec2, s: &f32) -> Contribution<Vec3> {
        Contribution {
            alpha: *s,
            color: Vec3::ONE,
            valid: true,
        }
    }
}

fn main() {}
