use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f32) -> f32 {
        if x < 0.0 {
            return 0.0;
        }
        x
    }
}

fn main() {}
