use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f64) -> f32 {
        1.0
    }
}

fn main() {}
