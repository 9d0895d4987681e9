use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(v: Vec3) -> f32 {
        v.magnitude()
    }
}

fn main() {}
