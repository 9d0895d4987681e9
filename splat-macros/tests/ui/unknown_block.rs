use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(d: Vec2, conic: Vec3) -> f32 {
        blocks::mahalanobis(d, conic)
    }
}

fn main() {}
