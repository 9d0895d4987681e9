use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    pub fn f(x: f32) -> f32 {
        match x > 0.0 {
            true => x,
            false => -x,
        }
    }
}

fn main() {}
